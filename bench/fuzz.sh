#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ (clang, ASan+UBSan, in build-fuzz/) and runs each for
# SECONDS, two at a time under nice, from its committed seeds (fuzz/corpus/TARGET) plus a work
# corpus in build-fuzz/corpus/TARGET (new inputs land there, the committed seeds stay as they are).
# Prints one line per target: seconds, executions/s, coverage (libFuzzer's cov = edges, ft =
# features), corpus size and findings (crash/leak/timeout/oom files left in build-fuzz/findings/).
#   bench/fuzz.sh SECONDS [TARGET...]      e.g. bench/fuzz.sh 600; bench/fuzz.sh 60 mt_file reader_ply
#   bench/fuzz.sh --seeds                  remakes the MT-file, payload and store seeds (needs build/bin)
#   MT_FUZZ_NO_BUILD=1 bench/fuzz.sh ...   runs what build-fuzz/bin has, without building
# Exit 1 when any target found something.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=$ROOT/build-fuzz
ALL=(reader_ply reader_obj reader_off reader_stl reader_gltf mt_file patch_meshopt patch_draco store_manifest store_segment camera_path)

configure_and_build() {
  [[ ${MT_FUZZ_NO_BUILD:-0} == 1 ]] && return 0
  # clang-14 and its libFuzzer runtime (Debian's); only the fuzzers need them, so not setup.sh.
  if ! command -v clang++-14 >/dev/null || ! dpkg-query -W libclang-rt-14-dev >/dev/null 2>&1; then
    apt-get install -y -qq --no-install-recommends clang-14 libclang-rt-14-dev >/dev/null
  fi
  if [[ ! -f $BUILD/build.ninja ]]; then
    local launcher=()
    command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
    cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DMT_FUZZ=ON \
      -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_C_COMPILER=clang-14 "${launcher[@]}" >/dev/null
  fi
  cmake --build "$BUILD" --parallel "$(nproc)" --target fuzz_all >/dev/null
}

if [[ ${1:-} == --seeds ]]; then
  # Small MT files of both codecs, list and strip index coding, with and without normals and
  # colours; their payloads; a small store. Kept small: the whole corpus stays well under 1 MB.
  configure_and_build
  B=$ROOT/build/bin; T=$(mktemp -d); trap 'rm -rf "$T"' EXIT
  "$B/mtgen" -o "$T/small.ply" -t 2k --colors -s 3 >/dev/null 2>&1
  "$B/mtgen" -o "$T/mid.ply" -t 6k -s 5 >/dev/null 2>&1
  "$B/mtgen" -o "$T/tiny.ply" -t 300 -s 4 >/dev/null 2>&1
  "$B/mtbuild" "$T/small.ply" -o "$T/small_strip.mt" --index-order strip --normals --patch-triangles 200 --threads 1 -q
  "$B/mtbuild" "$T/small.ply" -o "$T/small_draco_n.mt" --codec draco --normals --patch-triangles 200 --threads 1 -q
  "$B/mtbuild" "$T/mid.ply" -o "$T/mid_meshopt.mt" --patch-triangles 100 --threads 1 -q
  "$B/mtbuild" "$T/mid.ply" -o "$T/mid_draco.mt" --codec draco --patch-triangles 100 --threads 1 -q
  "$B/mtbuild" "$T/tiny.ply" -o "$T/tiny.mt" --normals --patch-triangles 100 --threads 1 -q
  rm -rf fuzz/corpus/mt_file fuzz/corpus/patch_meshopt fuzz/corpus/patch_draco fuzz/corpus/store_* fuzz/store
  mkdir -p fuzz/corpus/mt_file fuzz/corpus/patch_meshopt fuzz/corpus/patch_draco fuzz/corpus/store_manifest fuzz/corpus/store_segment
  # glTF: our writer's meshopt and quantized outputs (a cut of the tiny MT), Draco primitives.
  mkdir -p fuzz/corpus/reader_gltf
  "$B/mtextract" "$T/tiny.mt" -o fuzz/corpus/reader_gltf/extract_meshopt.glb --meshopt --triangles 120 >/dev/null
  "$B/mtextract" "$T/tiny.mt" -o fuzz/corpus/reader_gltf/extract_quantized.glb --quantize --triangles 120 >/dev/null
  "$BUILD/bin/fuzz_seed_gltf" fuzz/corpus/reader_gltf
  cp "$T/small_strip.mt" "$T/small_draco_n.mt" "$T/mid_meshopt.mt" fuzz/corpus/mt_file/
  for f in small_strip mid_meshopt; do "$BUILD/bin/fuzz_seed_payloads" "$T/$f.mt" fuzz/corpus/patch_meshopt 12; done
  for f in small_draco_n mid_draco; do "$BUILD/bin/fuzz_seed_payloads" "$T/$f.mt" fuzz/corpus/patch_draco 12; done
  "$B/mtstore" ingest "$T/tiny.ply" -o fuzz/store --patch-triangles 64 -q
  cp fuzz/store/MANIFEST-* fuzz/corpus/store_manifest/
  cp fuzz/store/SEG-* fuzz/corpus/store_segment/
  python3 fuzz/make_seeds.py
  du -sh fuzz/corpus fuzz/store
  exit 0
fi

SECONDS_EACH=${1:?usage: bench/fuzz.sh SECONDS [TARGET...] | --seeds}
shift
TARGETS=("$@")
((${#TARGETS[@]})) || TARGETS=("${ALL[@]}")
configure_and_build
mkdir -p "$BUILD/findings" "$BUILD/logs"

run_one() {
  local t=$1 s=$2 root=$3 build=$4
  local dict=() name=${t#reader_}
  [[ -f $root/fuzz/dict/$name.dict ]] && dict=(-dict="$root/fuzz/dict/$name.dict")
  mkdir -p "$build/corpus/$t"
  # -rss_limit_mb: a reader must stay within its memory bound on any input; -timeout: and finish.
  local start=$(date +%s)
  nice -n 10 "$build/bin/fuzz_$t" "$build/corpus/$t" "$root/fuzz/corpus/$t" "${dict[@]}" \
    -max_total_time="$s" -rss_limit_mb=2048 -timeout=20 -print_final_stats=1 \
    -artifact_prefix="$build/findings/$t-" >"$build/logs/$t.log" 2>&1 || true
  # How long it ran (less than SECONDS when it stopped at a finding).
  echo "fuzz.sh: ran $(($(date +%s) - start)) s" >>"$build/logs/$t.log"
}
export -f run_one
printf '%s\n' "${TARGETS[@]}" | xargs -P 2 -I{} bash -c 'run_one "$@"' _ {} "$SECONDS_EACH" "$ROOT" "$BUILD"

status=0
printf '%-16s %8s %10s %8s %8s %8s %s\n' target seconds exec/s cov ft corpus findings
for t in "${TARGETS[@]}"; do
  log=$BUILD/logs/$t.log
  last=$(grep -E '^#[0-9]+' "$log" | tail -1 || true)
  cov=$(sed -nE 's/.* cov: ([0-9]+).*/\1/p' <<<"$last")
  ft=$(sed -nE 's/.* ft: ([0-9]+).*/\1/p' <<<"$last")
  corp=$(sed -nE 's/.* corp: ([0-9]+)\/.*/\1/p' <<<"$last")
  execs=$(sed -nE 's/^stat::average_exec_per_sec: *([0-9]+)/\1/p' "$log" | tail -1)
  secs=$(sed -nE 's/^fuzz.sh: ran ([0-9]+) s$/\1/p' "$log" | tail -1)
  found=$(ls "$BUILD/findings" 2>/dev/null | grep -c "^$t-" || true)
  if grep -qE '^==[0-9]+==ERROR|^SUMMARY: |runtime error|deadly signal' "$log"; then found=$((found > 0 ? found : 1)); fi
  ((found)) && status=1
  printf '%-16s %8s %10s %8s %8s %8s %s\n' "$t" "${secs:-$SECONDS_EACH}" "${execs:-?}" "${cov:-?}" "${ft:-?}" "${corp:-?}" "$found"
done
exit $status
