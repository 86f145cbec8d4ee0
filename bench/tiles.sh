#!/usr/bin/env bash
# bench/tiles.sh [MT_FILE]: the 3D Tiles export's figures (mtexport tiles, docs/interop.md).
#
# For the MT file (default: a 53M mtgen scan built here first, which takes a while), once per codec of
# the GLB contents (--codec none: KHR_mesh_quantization only; meshopt; draco, the default): wall time, CPU time
# (user+sys) and peak RSS (GNU time), tiles, leaf copies, GLB contents, tree depth, triangles, and
# the tileset's size against the MT file's. With GEO=1 the default MT is a scan at UTM-like
# coordinates (mtgen --offset 500000,4000000,100, mtbuild --crs EPSG:32633), exported placed on the
# globe, and CESIUM=1 then also draws it in CesiumJS with the camera flown to where PROJ puts it
# (tests/interop_checks.sh cesium-show, interop/checks/cesium_check.mjs).
#
# Environment: OUT (a fresh directory under /tmp), BIN (build/bin), TRIANGLES (53M), MEMORY (4G).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${BIN:-$root/build/bin}"
OUT="${OUT:-$(mktemp -d /tmp/bench-tiles.XXXXXX)}"
TRIANGLES="${TRIANGLES:-53M}" MEMORY="${MEMORY:-4G}"
mkdir -p "$OUT"
mt="${1:-}"
if [[ -z "$mt" ]]; then
  mt="$OUT/scan.mt"
  offset=() crs=()
  [[ "${GEO:-0}" == 1 ]] && offset=(--offset 500000,4000000,100) crs=(--crs EPSG:32633)
  echo "tiles: generating and building a $TRIANGLES scan in $OUT" >&2
  "$BIN/mtgen" -o "$OUT/scan.ply" --triangles "$TRIANGLES" "${offset[@]}" >&2
  /usr/bin/time -f "mtbuild: %e s wall, %U+%S s CPU, %M KiB peak RSS" "$BIN/mtbuild" "$OUT/scan.ply" -o "$mt" --memory "$MEMORY" -q "${crs[@]}"
  rm -f "$OUT/scan.ply"
fi
mtBytes=$(stat -c %s "$mt")
echo "MT file: $mt, $mtBytes bytes"
printf '%-10s %8s %8s %8s %6s %9s %9s %8s %12s %14s %8s\n' variant wall_s cpu_s rss_MiB tiles copies contents depth triangles tileset_bytes x_MT
for variant in none meshopt draco; do
  dir="$OUT/tiles-$variant"
  rm -rf "$dir"
  flags=()
  flags=(--codec "$variant")
  /usr/bin/time -f "%e %U %S %M" -o "$OUT/time-$variant" "$BIN/mtexport" tiles "$mt" "$dir" "${flags[@]}" 2>"$OUT/log-$variant"
  read -r wall user sys rss < "$OUT/time-$variant"
  line=$(grep "tiles (" "$OUT/log-$variant")
  tiles=$(sed -E 's/.*: ([0-9]+) tiles.*/\1/' <<<"$line")
  copies=$(sed -E 's/.*\(([0-9]+) leaf copies\).*/\1/' <<<"$line")
  contents=$(sed -E 's/.* ([0-9]+) GLB contents.*/\1/' <<<"$line")
  depth=$(sed -E 's/.*depth ([0-9]+).*/\1/' <<<"$line")
  tris=$(sed -E 's/.*depth [0-9]+, ([0-9]+) triangles.*/\1/' <<<"$line")
  bytes=$(du -sb "$dir" | cut -f1)
  awk -v v="$variant" -v w="$wall" -v u="$user" -v s="$sys" -v r="$rss" -v t="$tiles" -v c="$copies" -v n="$contents" \
    -v d="$depth" -v tr="$tris" -v b="$bytes" -v m="$mtBytes" \
    'BEGIN { printf "%-10s %8.1f %8.1f %8.0f %6d %9d %9d %8d %12d %14d %8.2f\n", v, w, u + s, r / 1024, t, c, n, d, tr, b, b / m }' 
done
if [[ "${CESIUM:-0}" == 1 ]]; then
  # The default tileset in CesiumJS, the camera flown to where PROJ puts the model (the MT file's CRS).
  crs=$("$BIN/mtinfo" "$mt" --json | node -e 'console.log(JSON.parse(require("fs").readFileSync(0, "utf8")).crs || "")')
  [[ -n "$crs" ]] || { echo "tiles: CESIUM=1 needs an MT file with a CRS (mtbuild --crs; GEO=1)" >&2; exit 1; }
  bash "$root/tests/interop_checks.sh" cesium-show "$BIN" "$mt" "$crs" "$OUT/tiles-draco" "$OUT/cesium.png"
fi
echo "tiles: outputs in $OUT (remove when done)" >&2
