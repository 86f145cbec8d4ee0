#!/usr/bin/env bash
# Ingest benchmark. Generates an mtgen scan (default 53M triangles, ~1 GB of
# PLY, with holes and shuffled faces), ingests it with a memory cap, and prints throughput (input
# triangles/s), peak RSS (/usr/bin/time -v) and store size; then exports and checks the round trip
# size, with per-stage wall/CPU seconds. Usage: bench/ingest.sh [TRIANGLES=53M] [MEMORY=256M] [WORKDIR=out/bench-ingest]
set -euo pipefail
cd "$(dirname "$0")/.."
triangles="${1:-53M}"; memory="${2:-256M}"; work="${3:-out/bench-ingest}"
bin=build/bin
mkdir -p "$work"
mesh="$work/scan-$triangles.ply"
[[ -f "$mesh" ]] || "$bin/mtgen" -o "$mesh" --triangles "$triangles" --holes 100 --shuffle --seed 7
rm -rf "$work/store"
/usr/bin/time -v "$bin/mtstore" ingest "$mesh" -o "$work/store" --memory "$memory" 2> "$work/ingest.log" || { cat "$work/ingest.log"; exit 1; }
grep -E "^ingest: [a-z]+: [0-9.]+ M" "$work/ingest.log" || true
# Per-stage wall and CPU seconds (CPU is what to compare on a shared machine).
grep -E "^ingest: stage " "$work/ingest.log" || true
cpu=$(awk '/User time|System time/ {s += $NF} END {print s}' "$work/ingest.log")
echo "ingest: total CPU ${cpu} s (user + system)"
tris=$(grep -oE "ingested [0-9]+" "$work/ingest.log" | grep -oE "[0-9]+")
secs=$(grep -E "Elapsed \(wall" "$work/ingest.log" | awk '{print $NF}' | awk -F: '{ if (NF==3) print $1*3600+$2*60+$3; else print $1*60+$2 }')
rss=$(grep -E "Maximum resident" "$work/ingest.log" | awk '{print $NF}')
store=$(du -sb "$work/store" | cut -f1)
input=$(stat -c %s "$mesh")
awk -v t="$tris" -v s="$secs" -v r="$rss" -v b="$store" -v i="$input" -v m="$memory" 'BEGIN {
  printf "ingest: %d triangles, %.1f s wall, %.2f M triangles/s, peak RSS %.1f MiB (cap %s), input %.1f MB, store %.1f MB (%.2f B/tri)\n",
         t, s, t / s / 1e6, r / 1024, m, i / 1e6, b / 1e6, b / t }'
"$bin/mtstore" check "$work/store" | tail -1
/usr/bin/time -f "export: %e s, peak RSS %M KB" "$bin/mtstore" export "$work/store" -o "$work/export.ply" -q
ls -l "$mesh" "$work/export.ply" | awk '{print $5, $9}'
