#!/usr/bin/env bash
# scripts/scan_bases.sh DIR: the base models of the scan-derived test meshes (real scanned models
# shipped by Debian's libcgal-demo: ChineseDragon-10kv, elephant, camel, lion-head, man, bull,
# armadillo and more) as DIR/*.off. Idempotent: does nothing when DIR is complete. Needs apt-get
# (it runs `apt-get update` once if the download fails, which needs root) and network access.
set -euo pipefail
dir=${1:?usage: scripts/scan_bases.sh DIR}
wanted=(ChineseDragon-10kv elephant camel lion-head man bull armadillo mech-holes-shark boeing joint ALSTOM_TEST4 pipe)
complete() {
  [ -f "$dir/.complete" ] || return 1
  for name in "${wanted[@]}"; do [ -s "$dir/$name.off" ] || return 1; done
}
if complete; then exit 0; fi
mkdir -p "$dir"
# Callers at once (ctest -j runs the scan tests side by side, each asking for the models): one
# fetches under a lock on the folder, the others wait for it and find the folder complete.
exec 9>"$dir/.lock"
flock 9
if complete; then exit 0; fi
work=$(mktemp -d "${TMPDIR:-/tmp}/scan-bases.XXXXXX")
trap 'rm -rf "$work"' EXIT
(
  cd "$work"
  if ! apt-get download libcgal-demo >download.log 2>&1; then
    apt-get update >update.log 2>&1 || { echo "scan_bases.sh: apt-get update failed:" >&2; tail -3 update.log >&2; exit 1; }
    apt-get download libcgal-demo >download.log 2>&1 || { echo "scan_bases.sh: apt-get download libcgal-demo failed:" >&2; tail -3 download.log >&2; exit 1; }
  fi
)
deb=$(ls "$work"/libcgal-demo_*.deb)
dpkg -x "$deb" "$work/x"
tar xzf "$work/x/usr/share/doc/libcgal-dev/data.tar.gz" -C "$work" data/meshes
for name in "${wanted[@]}"; do
  [ -s "$work/data/meshes/$name.off" ] || { echo "scan_bases.sh: $deb has no data/meshes/$name.off" >&2; exit 1; }
done
# Each file is copied under a temporary name and renamed, so an interrupted run leaves no partial
# model behind; the stamp comes last.
for f in "$work"/data/meshes/*.off; do
  cp "$f" "$dir/.$(basename "$f").tmp"
  mv "$dir/.$(basename "$f").tmp" "$dir/$(basename "$f")"
done
touch "$dir/.complete"
echo "scan_bases.sh: $(ls "$dir"/*.off | wc -l) base models in $dir"
