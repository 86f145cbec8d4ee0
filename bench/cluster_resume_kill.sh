#!/usr/bin/env bash
# --resume under kills at arbitrary moments: builds IN once cleanly, then
# K times starts the build, kills it with SIGKILL from outside after a random delay (ingest,
# mid-level, mid-commit, mid-checkpoint: wherever it happens to be), resumes and compares the
# bytes. NP=1: mtbuild is killed; NP>1: mtcluster under mpirun, one random rank is killed (mpirun
# then stops the job). Prints one line per kill.
#   bench/cluster_resume_kill.sh [BUILD_DIR] [IN] [K] [NP]   (defaults: build, a 300k mtgen scan, 5, 1)
set -uo pipefail
BUILD=${1:-build}
BIN=$(cd "$BUILD/bin" && pwd)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
IN=${2:-}
K=${3:-5}
NP=${4:-1}
if [[ -z $IN ]]; then IN=$TMP/scan.ply; "$BIN/mtgen" -o "$IN" --triangles 300k --holes 20 --seed 61 > /dev/null 2>&1; fi
run() {  # run OUT [--resume]; exec, so that $! is the tool (or mpirun) itself
  if ((NP == 1)); then exec "$BIN/mtbuild" "$IN" -o "$@"
  else exec mpirun --allow-run-as-root --oversubscribe -np "$NP" "$BIN/mtcluster" "$IN" -o "$@"; fi
}
t0=$(date +%s.%N)
"$BIN/mtbuild" "$IN" -o "$TMP/ref.mt" -q > /dev/null 2>&1
clean=$(awk "BEGIN{print $(date +%s.%N) - $t0}")
echo "clean build: $clean s"
fail=0
for ((i = 1; i <= K; i++)); do
  rm -rf "$TMP/k.mt" "$TMP"/k.mt.tmp* "$TMP/k.mt.work"
  delay=$(awk -v s="$RANDOM" -v c="$clean" 'BEGIN{srand(s); print 0.1 + rand() * c * 0.9}')
  run "$TMP/k.mt" > "$TMP/kill.log" 2>&1 &
  pid=$!
  sleep "$delay"
  victim=$pid
  if ((NP > 1)); then
    ranks=($(pgrep -P "$pid"))
    ((${#ranks[@]})) && victim=${ranks[$((RANDOM % ${#ranks[@]}))]}
  fi
  kill -KILL "$victim" 2>/dev/null
  wait "$pid" 2>/dev/null
  sleep 0.2
  where=$( [[ -d $TMP/k.mt.work ]] && echo "work kept" || echo "no work dir")
  (run "$TMP/k.mt" --resume) > "$TMP/resume.log" 2>&1
  note=$(grep -o "continuing after level [0-9]*\|starting from the input\|has no checkpoint yet" "$TMP/resume.log" | head -1)
  if cmp -s "$TMP/k.mt" "$TMP/ref.mt"; then verdict=identical; else verdict=DIFFERENT; fail=1; fi
  printf 'kill %d (pid %s) after %.2f s (%s): resume %s -> %s\n' "$i" "$victim" "$delay" "$where" "${note:-?}" "$verdict"
done
exit $fail
