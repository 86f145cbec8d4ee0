#!/usr/bin/env bash
# The checks of interop/checks (npm ci there first; scripts/setup.sh does it) on files the tools write:
#   tests/interop_checks.sh validate BIN_DIR   every glTF variant mtextract writes and a 3D Tiles export,
#                                              through the Khronos glTF-Validator (no error, no warning)
#                                              and the tileset rules (interop/checks/validate.mjs); meshopt
#                                              files also decoded and validated again
#   tests/interop_checks.sh cesium BIN_DIR     a scan at UTM-like coordinates, built with a CRS and exported
#                                              to 3D Tiles, drawn by CesiumJS in headless Chromium where the
#                                              MT file says it is (interop/checks/cesium_check.mjs); the
#                                              screenshot is BIN_DIR/../interop-cesium.png
set -euo pipefail
mode="$1" bin="$2"
checks="$(cd "$(dirname "$0")/../interop/checks" && pwd)"
[[ -d "$checks/node_modules/gltf-validator" ]] || { echo "interop_checks: run 'npm ci' in $checks (scripts/setup.sh does)" >&2; exit 1; }
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
case "$mode" in
  validate)
    "$bin/mtgen" -o "$t/scan.ply" --triangles 20k --normals --colors >/dev/null 2>&1
    "$bin/mtbuild" "$t/scan.ply" -o "$t/scan.mt" --normals --crs EPSG:32633 -q --patch-triangles 500
    "$bin/mtgen" -o "$t/geo.ply" --triangles 20k --offset 500000,4000000,100 >/dev/null 2>&1
    "$bin/mtbuild" "$t/geo.ply" -o "$t/geo.mt" -q --patch-triangles 500
    files=()
    for mt in scan geo; do
      "$bin/mtextract" "$t/$mt.mt" --error 0 -o "$t/$mt-full.glb" 2>/dev/null
      "$bin/mtextract" "$t/$mt.mt" --triangles 5000 -o "$t/$mt-coarse.gltf" 2>/dev/null
      "$bin/mtextract" "$t/$mt.mt" --error 0 --quantize -o "$t/$mt-quantized.glb" 2>/dev/null
      "$bin/mtextract" "$t/$mt.mt" --error 0 --meshopt -o "$t/$mt-meshopt.glb" 2>/dev/null
      "$bin/mtextract" "$t/$mt.mt" --triangles 5000 --quantize --meshopt -o "$t/$mt-qm.gltf" 2>/dev/null
      "$bin/mtexport" tiles "$t/$mt.mt" "$t/$mt-tiles" 2>/dev/null
      "$bin/mtexport" tiles "$t/$mt.mt" "$t/$mt-tiles-meshopt" --meshopt 2>/dev/null
      files+=("$t/$mt-full.glb" "$t/$mt-coarse.gltf" "$t/$mt-quantized.glb" "$t/$mt-meshopt.glb" "$t/$mt-qm.gltf"
              "$t/$mt-tiles" "$t/$mt-tiles-meshopt")
    done
    node "$checks/validate.mjs" "${files[@]}"
    ;;
  cesium)
    "$bin/mtgen" -o "$t/geo.ply" --triangles 20k --offset 500000,4000000,100 >/dev/null 2>&1
    "$bin/mtbuild" "$t/geo.ply" -o "$t/geo.mt" -q --crs EPSG:32633 --patch-triangles 500
    "$bin/mtexport" tiles "$t/geo.mt" "$t/tiles" 2>/dev/null
    # Where the model must be, from the MT file's bounding box (not from the tileset).
    read -r center radius < <("$bin/mtinfo" "$t/geo.mt" --json | node -e '
      const j = JSON.parse(require("fs").readFileSync(0, "utf8"));
      const c = j.boundsMin.map((v, i) => (v + j.boundsMax[i]) / 2);
      const r = Math.hypot(...j.boundsMin.map((v, i) => j.boundsMax[i] - v)) / 2;
      console.log(c.join(","), r);')
    node "$checks/cesium_check.mjs" "$t/tiles" "$center" "$radius" "$bin/../interop-cesium.png"
    ;;
  *) echo "usage: $0 validate|cesium BIN_DIR" >&2; exit 2 ;;
esac
