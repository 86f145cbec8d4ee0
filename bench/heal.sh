#!/usr/bin/env bash
# Healing benchmark: generates an mtgen scan with many holes (default 53M triangles,
# --holes 300, shuffled faces), ingests it, runs `mtstore heal STORE --fill-holes 200 --memory 512M`
# under /usr/bin/time -v and prints wall time and peak RSS; then verifies that no hole of at most
# 200 edges is left (a second fill pass must find only larger ones) and that the store checks.
# Usage: bench/heal.sh [TRIANGLES=53M] [MAXEDGES=200] [MEMORY=512M] [WORKDIR=out/bench-heal] [BINDIR=build/bin]
set -euo pipefail
cd "$(dirname "$0")/.."
triangles="${1:-53M}"; maxedges="${2:-200}"; memory="${3:-512M}"; work="${4:-out/bench-heal}"; bin="${5:-build/bin}"
mkdir -p "$work"
mesh="$work/scan-$triangles-holes300.ply"
[[ -f "$mesh" ]] || "$bin/mtgen" -o "$mesh" --triangles "$triangles" --holes 300 --shuffle --seed 7
rm -rf "$work/store"
"$bin/mtstore" ingest "$mesh" -o "$work/store" --memory "$memory" -q
/usr/bin/time -v "$bin/mtstore" heal "$work/store" --fill-holes "$maxedges" --memory "$memory" -q \
  > "$work/heal.out" 2> "$work/heal.log" || { cat "$work/heal.out" "$work/heal.log"; exit 1; }
cat "$work/heal.out"
secs=$(grep -E "Elapsed \(wall" "$work/heal.log" | awk '{print $NF}' | awk -F: '{ if (NF==3) print $1*3600+$2*60+$3; else print $1*60+$2 }')
rss=$(grep -E "Maximum resident" "$work/heal.log" | awk '{print $NF}')
awk -v s="$secs" -v r="$rss" -v m="$memory" -v t="$triangles" 'BEGIN {
  printf "heal --fill-holes: %s triangles, %.1f s wall, peak RSS %.1f MiB (cap %s)\n", t, s, r / 1024, m }'
# Verification: a second pass finds no hole of at most MAXEDGES edges (filled 0, holes == larger).
"$bin/mtstore" heal "$work/store" --fill-holes "$maxedges" --memory "$memory" -q > "$work/verify.out" 2>/dev/null
cat "$work/verify.out"
awk '/^fill-holes:/ { gsub(",", ""); for (i = 2; i < NF; i += 2) v[$i] = $(i + 1) }
     END { if (v["filled"] != 0 || v["holes"] != v["larger"] + v["skipped"]) { print "FAIL: small holes left"; exit 1 }
           print "verified: every hole of at most the limit is closed (" v["larger"] " larger ones stay open)" }' "$work/verify.out"
"$bin/mtstore" check "$work/store" | tail -1
