#!/usr/bin/env bash
# ThreadSanitizer run of the tests that run threads: the ingest stages and the store
# (test_patchstore), the level loop and resume (test_mtbuild, test_build_safety), PatchServer and
# ExtractRender (test_mtrender), the cluster ranks (test_cluster, rank 0 commits on a second
# thread), and the tools they drive, all built with -fsanitize=thread in build-tsan/.
#   bench/tsan.sh [GTEST_FILTER]     e.g. bench/tsan.sh 'Mtbuild.*'
#   MT_TSAN_TBB_LIBDIR=DIR bench/tsan.sh   uses the TSan-instrumented libtbb.so.12 of DIR
# Exit 1 when any test fails or TSan reports a race (TSan's reports fail the process: exitcode=66).
#
# TBB must be instrumented too: Debian's libtbb12 is not, so TSan sees none of its hand-offs (a
# task's start, a parallel_for's end, a pipeline's batches) and reports every object handed
# between TBB threads, down to TBB's own inline code. So the script builds libtbb from Debian's
# source of the installed version (`apt-get source onetbb`, with a private source list under
# build-tsan/tbb; oneTBB's own -DTBB_SANITIZE=thread) once, and runs everything with it
# (LD_LIBRARY_PATH; the tools the tests start inherit it). bench/tsan_tbb_probe.cpp, a race-free
# program using TBB as the project does, checks that: 0 reports with the instrumented library,
# ~50 with Debian's (docs/hardening.md, "Sanitizers").
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
# libtbb with -fsanitize=thread, from Debian's source of the installed libtbb12.
tbb_dir=${MT_TSAN_TBB_LIBDIR:-}
if [[ -z "$tbb_dir" ]]; then
  root=$PWD/$BUILD/tbb
  version=$(dpkg-query -W -f='${source:Version}' libtbb12)
  if [[ ! -f "$root/built-$version" ]]; then
    rm -rf "$root" && mkdir -p "$root/lists/partial" "$root/cache/archives/partial" "$root/parts" "$root/src"
    codename=$(. /etc/os-release && echo "$VERSION_CODENAME")
    for suite in "debian $codename $codename-updates" "debian-security $codename-security"; do
      set -- $suite
      printf 'Types: deb-src\nURIs: http://deb.debian.org/%s\nSuites: %s\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n\n' \
        "$1" "${*:2}" >>"$root/parts/src.sources"
    done
    apt_opts=(-o Dir::Etc::SourceList=/dev/null -o Dir::Etc::SourceParts="$root/parts"
              -o Dir::State::Lists="$root/lists" -o Dir::Cache="$root/cache")
    apt-get "${apt_opts[@]}" update >/dev/null
    (cd "$root/src" && apt-get "${apt_opts[@]}" source --download-only "onetbb=$version" >/dev/null &&
     dpkg-source -x ./*.dsc tbb >/dev/null 2>&1)
    cmake -S "$root/src/tbb" -B "$root/build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DTBB_TEST=OFF -DTBB_EXAMPLES=OFF \
      -DTBB_STRICT=OFF -DTBB_SANITIZE=thread "${launcher[@]}" >/dev/null
    nice cmake --build "$root/build" --parallel "$(nproc)" --target tbb >/dev/null
    touch "$root/built-$version"
  fi
  tbb_dir=$(dirname "$(find "$root/build" -name 'libtbb.so.12' | head -1)")
fi
export LD_LIBRARY_PATH="$tbb_dir${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# Mesa and Open MPI are not instrumented either: reports with a frame inside them are suppressed
# (bench/tsan.supp).
export TSAN_OPTIONS="suppressions=$PWD/bench/tsan.supp:halt_on_error=0:exitcode=66:second_deadlock_stack=1"
status=0
nice g++ -std=c++17 -O1 -g -fsanitize=thread bench/tsan_tbb_probe.cpp -o "$BUILD/tsan_tbb_probe" -ltbb
probe=$("$BUILD/tsan_tbb_probe" 2>&1 | grep -c '^WARNING: ThreadSanitizer' || true)
printf '%-20s %4s TSan reports on a race-free TBB program (%s)%s\n' tsan_tbb_probe "$probe" "$tbb_dir" \
  "$( ((probe)) && echo ': this TBB is not instrumented, the reports below are not to be trusted')"
((probe)) && status=1
for t in "${TESTS[@]}"; do
  start=$(date +%s)
  if "$BUILD/bin/$t" --gtest_filter="$FILTER" >"$BUILD/$t.log" 2>&1; then r=ok; else r=FAILED; status=1; fi
  races=$(grep -c '^WARNING: ThreadSanitizer' "$BUILD/$t.log" || true)
  printf '%-20s %-6s %4s s  %s TSan reports  (%s)\n' "$t" "$r" "$(($(date +%s) - start))" "$races" "$BUILD/$t.log"
  ((races)) && status=1
done
exit $status
