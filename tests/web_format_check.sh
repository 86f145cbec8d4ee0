#!/usr/bin/env bash
# Web.FormatVersions: the web module (web/src) on what the file format allows beyond today's
# default build: version-2 and version-3 payloads (the C++ fixtures of tests/test_mt_codec.cpp),
# damaged version-4 payloads (BadPayload or valid indices, never another error), the metadata block
# (mtbuild --crs: the crs on the opened scene; every rule of the block broken once is refused), and
# the version-4 decode of a file with colours against the C++ decoder (web_cut_nodes --decode), and
# the C++ reader (mtinfo) accepting or refusing every metadata variant as the JS reader does; a
# textured (version 6) file: its decoded patches, coordinates and images against the C++ decoder
# (web_cut_nodes --decode), and broken copies of it (web/test/texture_check.mjs: truncated, bad
# checksums, bad counts and records, damaged texture payloads) with the verdicts of mtinfo --check
# (refused, or opens with the same damaged patches).
# Usage: web_format_check.sh BIN_DIR SOURCE_DIR
set -euo pipefail
bin=$1 src=$2
command -v node >/dev/null || { echo "web_format_check: node is not installed (scripts/setup.sh installs nodejs)" >&2; exit 1; }
[[ -d $src/web/node_modules/xxhash-wasm ]] || { echo "web_format_check: run 'npm ci' in $src/web first (scripts/test.sh does)" >&2; exit 1; }
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
run() { "$@" >"$t/log" 2>&1 || { cat "$t/log" >&2; echo "web_format_check: failed: $*" >&2; exit 1; }; }
run "$bin/mtgen" -o "$t/g.ply" --triangles 60k --colors --density varying --seed 7
run "$bin/mtbuild" "$t/g.ply" -o "$t/g.mt" --threads 2
run "$bin/mtbuild" "$t/g.ply" -o "$t/g-crs.mt" --threads 2 --crs EPSG:32633
fail=0
wasm=$src/web/dist/mt_decode.wasm
[[ -f $wasm ]] || { echo "web_format_check: $wasm is missing (cmake --build builds it, web/wasm/)" >&2; exit 1; }
"$bin/web_cut_nodes" --decode "$t/g-crs.mt" >"$t/cpp"
node "$src/web/test/decode_check.mjs" "$t/g-crs.mt" --require-connectivity >"$t/js"
diff "$t/cpp" "$t/js" >&2 || { echo "DIFFERENT: g-crs.mt decoded patches" >&2; fail=1; }
echo "g-crs.mt decoded: $(cat "$t/js")"
node "$src/web/test/payload_check.mjs" "$src" "$t/g.mt" --wasm "$wasm" || fail=1
mkdir "$t/variants"
node "$src/web/test/metadata_check.mjs" "$t/g-crs.mt" EPSG:32633 "$t/g.mt" --dump "$t/variants" || fail=1
# The C++ reader (mtinfo) agrees on every variant: opens it with the same crs, or refuses it.
agreed=0
while read -r name what want; do
  if "$bin/mtinfo" "$t/variants/$name" >"$t/info" 2>&1; then got=opens; else got=refused; fi
  gotCrs=$(awk '$1 == "crs" && $2 != "(none)" {print $2}' "$t/info")
  if [[ $got != "$what" || ($what == opens && "$gotCrs" != "${want:-}") ]]; then
    echo "DIFFERENT: metadata variant $name: JS $what ${want:-}, mtinfo $got $gotCrs: $(head -c 300 "$t/info")" >&2
    fail=1
  else
    agreed=$((agreed + 1))
  fi
done <"$t/variants/expect"
echo "metadata variants: mtinfo agrees with the JS reader on $agreed of $(wc -l <"$t/variants/expect")"
# Version 6: a textured scan (mtgen's charts), its payloads decoded by both, then its broken copies.
run "$bin/mtgen" -o "$t/x.ply" --triangles 30k --holes 3 --seed 5 --texture charts
run "$bin/mtbuild" "$t/x.ply" -o "$t/x.mt" --threads 2 --patch-triangles 500
"$bin/web_cut_nodes" --decode "$t/x.mt" >"$t/cpp"
node "$src/web/test/decode_check.mjs" "$t/x.mt" >"$t/js"
grep -q ' textures [1-9]' "$t/js" || { echo "web_format_check: x.mt: no texture decoded: $(cat "$t/js")" >&2; fail=1; }
diff "$t/cpp" "$t/js" >&2 || { echo "DIFFERENT: x.mt decoded patches and textures" >&2; fail=1; }
echo "x.mt decoded: $(cat "$t/js")"
mkdir "$t/v6"
node "$src/web/test/texture_check.mjs" "$t/x.mt" "$t/v6" || fail=1
agreed=0
while read -r name want; do
  # mtinfo --check: exit 0 (opens, nothing damaged); or the damaged patches named, then "checked N
  # payloads, K damaged"; or refused at open (no "checked" line).
  "$bin/mtinfo" "$t/v6/$name" --check >/dev/null 2>"$t/info" && code=0 || code=$?
  if grep -q 'checked [0-9]* payloads' "$t/info"; then
    got="opens$({ grep -v 'checked [0-9]* payloads' "$t/info" || true; } | sed -n 's/.*: \(texture of \)\{0,1\}patch \([0-9]*\).*/ \2/p' | sort -n | tr -d '\n')"
  else
    got=refused
  fi
  # exit 0 exactly when it opens with nothing damaged
  clean=no; [[ $got == opens ]] && clean=yes
  exited=no; [[ $code == 0 ]] && exited=yes
  if [[ $got != "$want" || $clean != "$exited" ]]; then
    echo "DIFFERENT: v6 copy $name: JS '$want', mtinfo --check '$got' (exit $code): $(head -c 300 "$t/info")" >&2
    fail=1
  else
    agreed=$((agreed + 1))
  fi
done <"$t/v6/expect"
echo "version-6 copies: mtinfo --check agrees with the JS reader on $agreed of $(wc -l <"$t/v6/expect")"
exit $fail
