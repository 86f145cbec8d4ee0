#!/usr/bin/env bash
# Installs every Debian package the project uses (non-interactive, idempotent, waits for the apt
# lock; clang-14 and the wasm32 libraries build the web viewer's decoder, web/wasm/; clang-14 and
# its sanitizer runtimes, libclang-rt-14-dev, build scripts/test.sh's sanitizer stage),
# then configures and builds a Release build into build/ (executables in build/bin/).
# Usage: scripts/setup.sh [--no-build]
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  build-essential cmake ninja-build pkg-config
  libopenmesh-dev libcgal-dev libeigen3-dev libdraco-dev libmeshoptimizer-dev
  libglfw3-dev libglm-dev libegl-dev libgl-dev libegl-mesa0 libgl1-mesa-dri
  libopenmpi-dev openmpi-bin libtbb-dev libzstd-dev liblz4-dev libxxhash-dev
  libcli11-dev libgtest-dev libgmock-dev libbenchmark-dev libnanoflann-dev
  xvfb xauth gnuplot-nox time
  libimgui-dev libpng-dev libjpeg62-turbo-dev libopengl-dev
  nlohmann-json3-dev nodejs chromium libproj-dev proj-bin
  clang-14 lld-14 wasi-libc libc++-14-dev-wasm32 libc++abi-14-dev-wasm32 libclang-rt-14-dev-wasm32
  libclang-rt-14-dev
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# npm: Debian's package, unless the installed nodejs brings its own (NodeSource's conflicts with it).
command -v npm >/dev/null || missing+=(npm)

apt_wait() {
  # Another apt/dpkg (unattended-upgrades, a parallel setup) may hold the lock: wait, do not fail.
  local waited=0
  while fuser /var/lib/dpkg/lock-frontend /var/lib/dpkg/lock /var/lib/apt/lists/lock >/dev/null 2>&1; do
    ((waited % 10 == 0)) && echo "setup: waiting for the apt lock (${waited}s)..." >&2
    sleep 1; waited=$((waited + 1))
  done
}

if ((${#missing[@]})); then
  echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}" >&2
  SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  command -v fuser >/dev/null || { apt_wait; $SUDO apt-get update -qq; $SUDO apt-get install -y -qq psmisc >/dev/null; }
  apt_wait
  $SUDO apt-get update -qq -o DPkg::Lock::Timeout=600
  apt_wait
  $SUDO apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=600 "${missing[@]}" >/dev/null
fi

# The interop checks' npm project (glTF-Validator, CesiumJS, playwright-core driving Debian's chromium):
# from its lockfile, never a browser download.
if [[ -f interop/checks/package-lock.json ]]; then
  if ! command -v npm >/dev/null; then  # Debian's nodejs comes without npm (NodeSource's has it)
    SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO="sudo"
    apt_wait
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=600 npm >/dev/null
  fi
  (cd interop/checks && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi

[[ "${1:-}" == "--no-build" ]] && exit 0

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build --parallel "$(nproc)"
