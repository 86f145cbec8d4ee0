#!/usr/bin/env bash
# The web viewer's figures (web/test/bench.mjs): an MT file served by mtserve, headless Chromium
# (SwiftShader WebGL) at 1280x720 on a 600-frame orbit path whose last 15% holds still. Prints the
# time to the first image after page load, the share of frames within the page's budget, the cache
# against its cap, the bytes fetched per frame and in total against the file size, and the time the
# screen error takes to reach the tolerance after the camera stops.
#   bench/web.sh [FILE.mt] [--budget MS=50] [--tol PX=1] [--cache MIB=256] [--frames N=600] [--shots DIR]
#                [--first-only] [--threads] [--web DIR] [--query K=V&...] (web/test/bench.mjs lists all its options;
#                --web DIR serves another copy of web/, e.g. `git archive main web`, for interleaved A/B runs)
# FILE.mt defaults to a 53M-triangle mtgen build (WORKDIR=out/bench-web, made once:
# mtgen --triangles 53M, mtbuild --threads 2 --memory 512M). BIN=dir/bin picks the build dir.
# Needs /usr/bin/chromium and web/node_modules (scripts/setup.sh, then `npm ci` in web/).
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${BIN:-build/bin}"
work="${WORKDIR:-out/bench-web}"
file=""
if [[ $# -gt 0 && $1 != --* ]]; then file=$1; shift; fi
if [[ -z $file ]]; then
  mkdir -p "$work"
  file="$work/m53M.mt"
  if [[ ! -f $file ]]; then
    "$bin/mtgen" -o "$work/m53M.ply" --triangles 53M
    "$bin/mtbuild" "$work/m53M.ply" -o "$file" --threads 2 --memory 512M
    rm -f "$work/m53M.ply"
  fi
fi
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
node web/test/bench.mjs "$bin" "$file" "$@"
