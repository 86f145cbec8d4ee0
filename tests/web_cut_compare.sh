#!/usr/bin/env bash
# Web.CutMatchesExtractRender: for the same file, view and tolerance the web viewer's cut
# (web/src/extract.js, run in node by web/test/cut_nodes.mjs) is ExtractRender's (mtrender/extract.h,
# printed by web_cut_nodes), node for node, both run to convergence. 6 files x 8 views x 2 tolerances
# (x.mt textured, version 6). And the web decoder decodes every patch of the meshopt files to the C++
# decoder's grid coordinates (and x.mt's texture coordinates and images to the C++ reader's). And a
# still view's one update asks for all the loads its tolerance needs (still_loads.mjs).
# Usage: web_cut_compare.sh BIN_DIR SOURCE_DIR
set -euo pipefail
bin=$1 src=$2
command -v node >/dev/null || { echo "web_cut_compare: node is not installed (scripts/setup.sh installs nodejs)" >&2; exit 1; }
[[ -d $src/web/node_modules/xxhash-wasm ]] || { echo "web_cut_compare: run 'npm ci' in $src/web first (scripts/test.sh does)" >&2; exit 1; }
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
run() { "$@" >"$t/log" 2>&1 || { cat "$t/log" >&2; echo "web_cut_compare: failed: $*" >&2; exit 1; }; }
run "$bin/mtgen" -o "$t/a.ply" --triangles 300k --density varying
run "$bin/mtbuild" "$t/a.ply" -o "$t/a.mt" --threads 2
run "$bin/mtgen" -o "$t/b.ply" --triangles 100k --colors --holes 4 --seed 3
run "$bin/mtbuild" "$t/b.ply" -o "$t/b.mt" --threads 2 --codec draco
run "$bin/mtgen" -o "$t/c.ply" --triangles 200k --components 3 --seed 5
run "$bin/mtbuild" "$t/c.ply" -o "$t/c.mt" --threads 2 --partition regular
# Smooth spheres (narrow normal cones, so cone culling moves the cut; mtgen's noise makes cones too
# wide to cull): d closed, e with 6 holes (no cone may cull it, closed_surface.h).
run node "$src/web/test/sphere_ply.mjs" "$t/d.ply" 120
run node "$src/web/test/sphere_ply.mjs" "$t/e.ply" 120 6
run "$bin/mtbuild" "$t/d.ply" -o "$t/d.mt" --threads 2 --patch-triangles 300
run "$bin/mtbuild" "$t/e.ply" -o "$t/e.mt" --threads 2 --patch-triangles 300
# A textured scan (version 6: TextureRecords after the patch index, texture payloads between the
# patches' payloads; the byte bounds of its patches include their atlases).
run "$bin/mtgen" -o "$t/x.ply" --triangles 100k --seed 9 --texture charts
run "$bin/mtbuild" "$t/x.ply" -o "$t/x.mt" --threads 2 --patch-triangles 500
# A scan: scangen's bunny (Stanford's scanned bunny of Debian's libcgal-demo, subdivided once and
# displaced, with scan-like holes: 0.3 M triangles), as test_real_scans fetches its base models.
files="a b c d e x"
if [[ -x $bin/scangen ]]; then
  bases=$bin/../scan-bases
  run bash "$src/scripts/scan_bases.sh" "$bases"
  run "$bin/scangen" "$bases/bunny00.off" 1 "$t/s.ply" --holes 0.45 --shuffle 3
  run "$bin/mtbuild" "$t/s.ply" -o "$t/s.mt" --threads 2
  files="$files s"
else
  echo "web_cut_compare: no scangen in $bin (MT_REAL_SCANS=OFF or ../shared missing): the scan left out" >&2
fi
# Unit-space views (eye, target): the default view, close-ups grazing the surface, views from
# inside the sphere, from above and below, one looking away from most of the model.
cat > "$t/views" <<'VIEWS'
0 -2.2 1.1 0 0 0
0.3 -0.8 0.4 0 0 0
1.5 0.2 0.3 0 0 0
0.1 -0.5 0.05 0.5 0.5 0
0 0 3 0 0 0
-0.4 -0.4 0.1 1 1 0.2
0.2 0.1 -1.2 0 0 0
0.6 0 0.1 2 0 0.1
VIEWS
fail=0 compared=0
for f in $files; do
  for tol in 1 3; do
    "$bin/web_cut_nodes" "$t/$f.mt" "$t/views" $tol 1280 720 >"$t/cpp"
    node "$src/web/test/cut_nodes.mjs" "$t/$f.mt" "$t/views" $tol 1280 720 >"$t/js" 2>"$t/jserr" || { cat "$t/jserr" >&2; exit 1; }
    # Normal cones cull only a closed surface (closed_surface.js): a, c, d and x are closed, b, e and s have holes.
    want=true; [[ $f == b || $f == e || $f == s ]] && want=false
    grep -q "closed $want" "$t/jserr" || { echo "web_cut_compare: $f.mt: expected closed $want: $(cat "$t/jserr")" >&2; exit 1; }
    n=$(wc -l <"$t/cpp")
    [[ $n -eq 8 ]] || { echo "web_cut_compare: $f.mt: web_cut_nodes printed $n views, expected 8" >&2; exit 1; }
    if ! diff -q "$t/cpp" "$t/js" >/dev/null; then
      echo "DIFFERENT: $f.mt tolerance $tol:" >&2
      diff "$t/cpp" "$t/js" | head -6 >&2
      fail=1
    fi
    compared=$((compared + n))
    echo "$f.mt tolerance $tol: $n views, cut sizes $(awk '{printf "%d ", NF - 2}' "$t/cpp")"
  done
done
# The views differ: they must have moved the cuts to different node sets.
nodes=$(awk '{print NF - 2}' "$t/cpp" | sort -n | uniq | wc -l)
[[ $nodes -ge 2 ]] || { echo "web_cut_compare: every view gave the same cut size: the views test nothing" >&2; exit 1; }
# A still view asks in one update for the patches of the cut its tolerance ends with, however many
# levels below the cut, and for no others: it refines through the levels between without loading
# them (web/test/still_loads.mjs), and settles on the converged cut.
for f in a c d; do
  node "$src/web/test/still_loads.mjs" "$t/$f.mt" "$t/views" 1 1280 720 >"$t/js" 2>"$t/jserr" || { cat "$t/js" "$t/jserr" >&2; fail=1; }
  echo "$f.mt still loads: $(awk '/target.s cut holds/ {s += $7; v += 1} /all loads:/ {u += $7} END {print s " patches needed over " v " views, all asked at once; settled in " u " updates in all"}' "$t/js")"
done
# The web decoder (range coder, position prediction, meshopt and zstd from npm, checksums) gives
# the C++ decoder's grid coordinates on every patch of the meshopt files: its JavaScript port, and
# with the C++ decoder compiled to WebAssembly (web/wasm/, built by CMake) in its place.
wasm=$src/web/dist/mt_decode.wasm
[[ -f $wasm ]] || { echo "web_cut_compare: $wasm is missing (cmake --build builds it, web/wasm/)" >&2; exit 1; }
for f in a c x; do
  "$bin/web_cut_nodes" --decode "$t/$f.mt" >"$t/cpp"
  for how in js wasm; do
    opt=(); [[ $how == wasm ]] && opt=(--wasm "$wasm")
    node "$src/web/test/decode_check.mjs" "$t/$f.mt" --require-connectivity "${opt[@]}" >"$t/js"
    diff "$t/cpp" "$t/js" >&2 || { echo "DIFFERENT: $f.mt decoded patches ($how)" >&2; fail=1; }
    echo "$f.mt decoded ($how): $(cat "$t/js")"
  done
done
grep -q ' textures [1-9]' "$t/js" || { echo "web_cut_compare: x.mt: no texture decoded" >&2; fail=1; }
echo "web_cut_compare: $compared (file, view, tolerance) cuts compared"
exit $fail
