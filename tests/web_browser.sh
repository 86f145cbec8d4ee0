#!/usr/bin/env bash
# Web.Browser: the web viewer in headless Chromium (web/test/browser.mjs says what each test checks)
# on a 200k-triangle build served by mtserve, and on a textured scan (version 6). Needs /usr/bin/chromium (scripts/setup.sh installs it)
# and web/node_modules (`npm ci` in web/, scripts/test.sh runs it).
# Usage: web_browser.sh BIN_DIR SOURCE_DIR
set -euo pipefail
bin=$1 src=$2
command -v node >/dev/null || { echo "web_browser: node is not installed (scripts/setup.sh installs nodejs)" >&2; exit 1; }
[[ -x /usr/bin/chromium ]] || { echo "web_browser: /usr/bin/chromium is missing (scripts/setup.sh installs Debian's chromium)" >&2; exit 1; }
[[ -d $src/web/node_modules/playwright-core ]] || { echo "web_browser: run 'npm ci' in $src/web first (scripts/test.sh does)" >&2; exit 1; }
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
run() { "$@" >"$t/log" 2>&1 || { cat "$t/log" >&2; echo "web_browser: failed: $*" >&2; exit 1; }; }
# The golden image (web/test/golden/torus.png) is of this file: same options, same bytes.
run "$bin/mtgen" -o "$t/t.ply" --triangles 200k
run "$bin/mtbuild" "$t/t.ply" -o "$t/t.mt" --threads 2
run "$bin/mtbuild" "$t/t.ply" -o "$t/t-draco.mt" --threads 2 --codec draco
# Per-vertex colours (the colours test): a coloured scan with holes.
run "$bin/mtgen" -o "$t/c.ply" --triangles 60k --colors --holes 10 --seed 3
run "$bin/mtbuild" "$t/c.ply" -o "$t/c.mt" --threads 2
# The same kind of scan without colours (the back-faces test: the lit back pass).
run "$bin/mtgen" -o "$t/h.ply" --triangles 60k --holes 10 --seed 3
run "$bin/mtbuild" "$t/h.ply" -o "$t/h.mt" --threads 2
# The same scan in small patches (the occlusion test: patches hidden behind others at a still view).
run "$bin/mtbuild" "$t/h.ply" -o "$t/o.mt" --threads 2 --patch-triangles 300
# A textured scan (version 6; the textured tests, and web/test/golden/textured.png is of this file).
run "$bin/mtgen" -o "$t/x.ply" --triangles 60k --holes 3 --seed 5 --texture charts
run "$bin/mtbuild" "$t/x.ply" -o "$t/x.mt" --threads 2 --patch-triangles 500
run "$bin/mtbuild" "$t/x.ply" -o "$t/x-draco.mt" --threads 2 --patch-triangles 500 --codec draco
rm -f "$t/t.ply" "$t/c.ply" "$t/h.ply" "$t/x.ply" "$t"/x_tex*.jpg
node "$src/web/test/browser.mjs" "$bin" "$t"
