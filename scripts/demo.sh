#!/usr/bin/env bash
# The main job on a built-in default input: set up, generate a scan-like mesh, ingest it into a
# patch store, print the store's statistics, check it, and export it back.
# Usage: scripts/demo.sh [TRIANGLES]   (default 2M; e.g. scripts/demo.sh 53M for the benchmark size)
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
triangles="${1:-2M}"
out=out/demo
rm -rf "$out" && mkdir -p "$out"
bin=build/bin
echo "== mtgen: a ${triangles}-triangle scan-like mesh with holes, shuffled faces"
"$bin/mtgen" -o "$out/scan.ply" --triangles "$triangles" --holes 40 --shuffle --seed 1
echo "== mtstore ingest (memory cap 256M)"
"$bin/mtstore" ingest "$out/scan.ply" -o "$out/scan.store" --memory 256M
echo "== mtstore info"
"$bin/mtstore" info "$out/scan.store"
echo "== mtstore check"
"$bin/mtstore" check "$out/scan.store"
echo "== mtstore export"
"$bin/mtstore" export "$out/scan.store" -o "$out/export.ply"
ls -l "$out"
