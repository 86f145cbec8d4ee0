#!/usr/bin/env bash
# Cluster identity: mtcluster with -np 1, 2, 4 (oversubscribed here) writes the same bytes as
# mtbuild, on three different mtgen scans (one with holes). Prints one line per run and a verdict;
# exit status 0 only if every file is byte-identical to mtbuild's.
#   bench/cluster_identity.sh [BUILD_DIR] [TRIANGLES]   (defaults: build, 200k)
set -euo pipefail
BUILD=${1:-build}
TRI=${2:-200k}
BIN=$(cd "$BUILD/bin" && pwd)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
MPIRUN=(mpirun --allow-run-as-root --oversubscribe)
status=0
scans=(
  "closed|--triangles $TRI --seed 41"
  "holes|--triangles $TRI --holes 40 --shuffle --seed 42"
  "components|--triangles $TRI --components 5 --density varying --seed 43"
)
for entry in "${scans[@]}"; do
  name=${entry%%|*}
  gen=${entry#*|}
  "$BIN/mtgen" -o "$TMP/$name.ply" $gen > /dev/null 2>&1
  t0=$(date +%s.%N)
  "$BIN/mtbuild" "$TMP/$name.ply" -o "$TMP/$name.mtbuild.mt" -q > /dev/null 2>&1
  t1=$(date +%s.%N)
  ref=$(sha256sum < "$TMP/$name.mtbuild.mt" | cut -c1-16)
  printf '%-11s mtbuild     %8d bytes  sha256 %s  %.1f s\n' "$name" "$(stat -c %s "$TMP/$name.mtbuild.mt")" "$ref" "$(awk "BEGIN{print $t1 - $t0}")"
  for np in 1 2 4; do
    out="$TMP/$name.np$np.mt"
    t0=$(date +%s.%N)
    "${MPIRUN[@]}" -np "$np" "$BIN/mtcluster" "$TMP/$name.ply" -o "$out" -q --stats-json "$out.json" > "$out.log" 2>&1 || true
    t1=$(date +%s.%N)
    if [[ -f $out ]] && cmp -s "$out" "$TMP/$name.mtbuild.mt"; then verdict=identical; else verdict=DIFFERENT; status=1; fi
    eff=$(grep -o '"parallel_efficiency": [0-9.e-]*' "$out.json" 2>/dev/null | cut -d' ' -f2 || echo "?")
    printf '%-11s mtcluster %d %8d bytes  sha256 %s  %.1f s  efficiency %s  %s\n' "$name" "$np" \
      "$(stat -c %s "$out" 2>/dev/null || echo 0)" "$(sha256sum < "$out" 2>/dev/null | cut -c1-16)" "$(awk "BEGIN{print $t1 - $t0}")" "$eff" "$verdict"
  done
done
if ((status == 0)); then echo "cluster identity: all files identical to mtbuild"; else echo "cluster identity: MISMATCH"; fi
exit $status
