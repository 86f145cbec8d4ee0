#!/usr/bin/env bash
# The checks of interop/checks (npm ci there first; scripts/setup.sh does it) on files the tools write:
#   tests/interop_checks.sh validate BIN_DIR   every glTF variant mtextract writes (of a textured scan too)
#                                              and a 3D Tiles export,
#                                              through the Khronos glTF-Validator (no error, no warning)
#                                              and the tileset rules (interop/checks/validate.mjs); meshopt
#                                              and Draco files also decoded and validated again; CesiumGS's
#                                              3d-tiles-validator too where MT_TILES_VALIDATOR names one
#   tests/interop_checks.sh cesium BIN_DIR     a scan at UTM zone 33N coordinates, built with its CRS and
#                                              exported to 3D Tiles (placed on the WGS84 globe), drawn by
#                                              CesiumJS in headless Chromium with the camera flown to the
#                                              longitude/latitude PROJ's cs2cs gives for the MT file's box
#                                              (interop/checks/cesium_check.mjs); the screenshot is
#                                              BIN_DIR/../interop-cesium.png
#   tests/interop_checks.sh cesium-show BIN_DIR MT CRS TILESET_DIR SCREENSHOT   the same check of a given
#                                              export (bench/tiles.sh)
set -euo pipefail
mode="$1" bin="$2"
checks="$(cd "$(dirname "$0")/../interop/checks" && pwd)"
[[ -d "$checks/node_modules/gltf-validator" ]] || { echo "interop_checks: run 'npm ci' in $checks (scripts/setup.sh does)" >&2; exit 1; }
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
# show_in_cesium MT CRS TILESET_DIR SCREENSHOT: where the model must be is the MT file's box (mtinfo),
# its centre and 8 corners taken to WGS84 longitude, latitude, height by PROJ's cs2cs (not by our code,
# not from the tileset); cesium_check.mjs flies the camera there and puts the 9 points through the
# tileset's root transform as Cesium composes it.
show_in_cesium() {
  local mt="$1" crs="$2" tiles="$3" shot="$4"
  command -v cs2cs >/dev/null || { echo "interop_checks: PROJ's cs2cs is missing (Debian proj-bin; scripts/setup.sh installs it)" >&2; exit 1; }
  "$bin/mtinfo" "$mt" --json > "$t/info.json"
  node -e '
    const j = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
    const c = j.boundsMin.map((v, i) => (v + j.boundsMax[i]) / 2);
    const pts = [c];
    for (let k = 0; k < 8; ++k) pts.push([0, 1, 2].map((a) => ((k >> a) & 1 ? j.boundsMax : j.boundsMin)[a]));
    for (const p of pts) console.log(p.map((v) => v.toFixed(9)).join(" "));' "$t/info.json" > "$t/points.txt"
  cs2cs -f %.12f "$crs" EPSG:4979 < "$t/points.txt" > "$t/geodetic.txt"
  node -e '
    const fs = require("fs");
    const [info, pts, geo, dir, shot, out] = process.argv.slice(1);
    const j = JSON.parse(fs.readFileSync(info, "utf8"));
    const p = fs.readFileSync(pts, "utf8").trim().split("\n").map((l) => l.trim().split(/\s+/).map(Number));
    // cs2cs prints EPSG:4979 in its axis order: latitude, longitude, height.
    const g = fs.readFileSync(geo, "utf8").trim().split("\n").map((l) => { const [lat, lon, h] = l.trim().split(/\s+/).map(Number); return [lon, lat, h]; });
    const radius = Math.hypot(...j.boundsMin.map((v, i) => j.boundsMax[i] - v)) / 2;
    const spec = { tileset: dir, screenshot: shot, radius, geodetic: g[0], tolerance: 1e-3,
      points: p.map((q, k) => ({ local: q.map((v, a) => v - j.gridOrigin[a]), geodetic: g[k] })) };
    fs.writeFileSync(out, JSON.stringify(spec));' "$t/info.json" "$t/points.txt" "$t/geodetic.txt" "$tiles" "$shot" "$t/spec.json"
  node "$checks/cesium_check.mjs" "$t/spec.json"
}

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
      "$bin/mtexport" tiles "$t/$mt.mt" "$t/$mt-tiles" --codec none 2>/dev/null
      "$bin/mtexport" tiles "$t/$mt.mt" "$t/$mt-tiles-meshopt" --codec meshopt 2>/dev/null
      "$bin/mtexport" tiles "$t/$mt.mt" "$t/$mt-tiles-draco" 2>/dev/null
      files+=("$t/$mt-full.glb" "$t/$mt-coarse.gltf" "$t/$mt-quantized.glb" "$t/$mt-meshopt.glb" "$t/$mt-qm.gltf"
              "$t/$mt-tiles" "$t/$mt-tiles-meshopt" "$t/$mt-tiles-draco")
    done
    # A textured scan (format v6): its cuts and tiles carry TEXCOORD_0 and one material per patch atlas.
    "$bin/mtgen" -o "$t/tex.ply" --triangles 20k --texture charts >/dev/null 2>&1
    "$bin/mtbuild" "$t/tex.ply" -o "$t/tex.mt" -q --patch-triangles 500
    "$bin/mtextract" "$t/tex.mt" --error 0 -o "$t/tex-full.glb" 2>/dev/null
    "$bin/mtextract" "$t/tex.mt" --triangles 5000 -o "$t/tex-coarse.gltf" 2>/dev/null
    "$bin/mtextract" "$t/tex.mt" --error 0 --quantize -o "$t/tex-quantized.glb" 2>/dev/null
    "$bin/mtextract" "$t/tex.mt" --error 0 --meshopt -o "$t/tex-meshopt.glb" 2>/dev/null
    "$bin/mtextract" "$t/tex.mt" --triangles 5000 --quantize --meshopt -o "$t/tex-qm.gltf" 2>/dev/null
    "$bin/mtexport" tiles "$t/tex.mt" "$t/tex-tiles" --codec none 2>/dev/null
    "$bin/mtexport" tiles "$t/tex.mt" "$t/tex-tiles-default" 2>/dev/null
    files+=("$t/tex-full.glb" "$t/tex-coarse.gltf" "$t/tex-quantized.glb" "$t/tex-meshopt.glb" "$t/tex-qm.gltf"
            "$t/tex-tiles" "$t/tex-tiles-default")
    node "$checks/validate.mjs" "${files[@]}"
    # CesiumGS's 3d-tiles-validator is not in the npm registry this project installs from (docs/interop.md
    # "Tileset validation"): where one is built by hand, MT_TILES_VALIDATOR names its bin/main and it
    # runs on every tileset too (no error, no warning).
    if [[ -n "${MT_TILES_VALIDATOR:-}" ]]; then
      for f in "${files[@]}"; do
        [[ -d "$f" ]] || continue
        node "$MT_TILES_VALIDATOR" -t "$f/tileset.json" -r "$f.report.json" >/dev/null
        node -e '
          const r = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
          console.log(`${process.argv[2]}: 3d-tiles-validator: ${r.numErrors} errors, ${r.numWarnings} warnings, ${r.numInfos} infos`);
          if (r.numErrors || r.numWarnings) { console.error(JSON.stringify(r.issues, null, 1).slice(0, 4000)); process.exit(1); }' "$f.report.json" "$f"
      done
    fi
    ;;
  cesium)
    # A scan at UTM zone 33N coordinates, built with its CRS: the tileset is placed on the globe.
    "$bin/mtgen" -o "$t/geo.ply" --triangles 20k --offset 500000,4000000,100 >/dev/null 2>&1
    "$bin/mtbuild" "$t/geo.ply" -o "$t/geo.mt" -q --crs EPSG:32633 --patch-triangles 500
    "$bin/mtexport" tiles "$t/geo.mt" "$t/tiles" 2>/dev/null
    show_in_cesium "$t/geo.mt" EPSG:32633 "$t/tiles" "$bin/../interop-cesium.png"
    ;;
  cesium-show)
    show_in_cesium "$3" "$4" "$5" "$6"
    ;;
  *) echo "usage: $0 validate|cesium BIN_DIR | cesium-show BIN_DIR MT CRS TILESET_DIR SCREENSHOT" >&2; exit 2 ;;
esac
