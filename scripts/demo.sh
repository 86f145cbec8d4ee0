#!/usr/bin/env bash
# The main job on a built-in default input: set up, generate a scan-like mesh, build its
# multiresolution MT file, print mtinfo, run mtverify, extract a cut as PLY, and render a camera
# path headless (EGL, no X) under a frame-time budget.
# Usage: scripts/demo.sh [TRIANGLES]   (default 2M; e.g. 53M for the benchmark size)
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
triangles="${1:-2M}"
out=out/demo
rm -rf "$out" && mkdir -p "$out"
bin=build/bin
echo "== mtgen: a ${triangles}-triangle scan-like mesh with 40 holes and shuffled faces"
"$bin/mtgen" -o "$out/scan.ply" --triangles "$triangles" --holes 40 --shuffle --seed 1
echo "== mtbuild (memory cap 512M)"
"$bin/mtbuild" "$out/scan.ply" -o "$out/scan.mt" --memory 512M --stats-json "$out/build.json"
echo "== mtinfo"
"$bin/mtinfo" "$out/scan.mt"
echo "== mtverify (checksums, monotone errors, nested spheres, crack-free random cuts)"
"$bin/mtverify" "$out/scan.mt" --cuts 8
echo "== mtextract: the best cut of 200k triangles, and a view from the +x side"
"$bin/mtextract" "$out/scan.mt" --triangles 200000 -o "$out/cut-200k.ply"
"$bin/mtextract" "$out/scan.mt" --eye 4,0,1 --target 0,0,0 --fov 50 --width 1280 -o "$out/cut-view.ply"
echo "== mtrender --headless: 200 frames of the built-in orbit path, 1280x720, 50 ms budget, 64 MiB cache"
"$bin/mtrender" "$out/scan.mt" --headless --quiet --camera-path orbit --frames 200 --budget-ms 50 --cache 64M \
  --stats "$out/frames.csv" --screenshots "$out/frames" --screenshot-every 50 |
  grep -E "^(within_budget_pct|frame_ms_median|extract_ms_median|first_frame_ms|cache_max_bytes|cache_cap_bytes|miss_rate|settle_ms) "
ls -l "$out"
