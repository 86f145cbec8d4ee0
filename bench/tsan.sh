#!/usr/bin/env bash
# ThreadSanitizer run of the tests that run threads: the ingest stages and the store
# (test_patchstore), the level loop and resume (test_mtbuild, test_build_safety), PatchServer and
# ExtractRender (test_mtrender), the cluster ranks (test_cluster, rank 0 commits on a second
# thread), and the tools they drive, all built with -fsanitize=thread in build-tsan/.
#   bench/tsan.sh [GTEST_FILTER]     e.g. bench/tsan.sh 'Mtbuild.*'
# Exit 1 when any test fails or TSan reports a race (TSan's reports fail the process: exitcode=66).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=build-tsan
FILTER=${1:-*}
TESTS=(test_patchstore test_mtbuild test_build_safety test_mtrender test_cluster)
TOOLS=(mtgen mtstore mtbuild mtcluster mtinfo mtverify mtextract mtrender)
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DMT_SANITIZE=thread -DMT_BENCH=OFF "${launcher[@]}" >/dev/null
nice cmake --build "$BUILD" --parallel "$(nproc)" --target "${TESTS[@]}" "${TOOLS[@]}"
# TBB, Mesa and Open MPI are not instrumented: their internal synchronisation is invisible to TSan,
# so reports whose every racing frame is inside them are suppressed (bench/tsan.supp says which).
export TSAN_OPTIONS="suppressions=$PWD/bench/tsan.supp:halt_on_error=0:exitcode=66:second_deadlock_stack=1"
status=0
for t in "${TESTS[@]}"; do
  start=$(date +%s)
  if "$BUILD/bin/$t" --gtest_filter="$FILTER" >"$BUILD/$t.log" 2>&1; then r=ok; else r=FAILED; status=1; fi
  races=$(grep -c '^WARNING: ThreadSanitizer' "$BUILD/$t.log" || true)
  printf '%-20s %-6s %4s s  %s TSan reports  (%s)\n' "$t" "$r" "$(($(date +%s) - start))" "$races" "$BUILD/$t.log"
  ((races)) && status=1
done
exit $status
