#!/usr/bin/env bash
# Real scans against our own generator: builds a scan-derived mesh (../shared/tools/scangen.cpp on
# a real scanned model from Debian's libcgal-demo) and an mtgen mesh of the same triangle count,
# and prints for each build: wall and CPU (user+sys, the honest figure on a shared machine) time,
# M input triangles/s, peak RSS (/usr/bin/time -v), bytes per input triangle, the grid weld's
# merged vertices, and the `mtverify --cuts 32` verdict; then the mean per mesh and the CPU ratio.
#
#   bench/scans.sh [SIZE] [--rounds N] [--memory 512M] [--threads 2] [--codec meshopt|draco]
#                  [--partition irregular|regular] [--simplifier quadric|meshopt] [--work DIR] [--keep]
#
# SIZE (default 13M; e.g. 3M, 53M) picks the base model and scangen LEVELS whose size (base
# triangles x 4^LEVELS) is nearest; the mtgen mesh then gets exactly the scan's triangle count.
# --rounds N runs the two builds interleaved, A B A B ..., N times each (same session, so the
# machine's load affects both alike). Inputs are kept in WORK (default out/bench-scans) for the
# next run; --keep keeps the .mt files too. BIN=dir/bin picks another build dir. --simplifier is
# passed to mtbuild (default: mtbuild's own default).
set -euo pipefail
cd "$(dirname "$0")/.."

size=13M rounds=1 memory=512M threads=2 codec=meshopt partition=irregular work=out/bench-scans keep=0 simplifier=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --rounds) rounds=$2; shift 2 ;;
    --memory) memory=$2; shift 2 ;;
    --threads) threads=$2; shift 2 ;;
    --codec) codec=$2; shift 2 ;;
    --partition) partition=$2; shift 2 ;;
    --simplifier) simplifier=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --keep) keep=1; shift ;;
    -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "bench/scans.sh: unknown option $1 (see --help)" >&2; exit 1 ;;
    *) size=$1; shift ;;
  esac
done
[[ "$rounds" =~ ^[1-9][0-9]*$ ]] || { echo "bench/scans.sh: --rounds must be a count from 1 (got '$rounds')" >&2; exit 1; }
triangles=$(python3 - "$size" <<'EOF'
import re, sys
m = re.fullmatch(r"([0-9.]+)([kKmMgG]?)", sys.argv[1])
if not m: sys.exit(1)
print(int(float(m.group(1)) * {"": 1, "k": 1e3, "m": 1e6, "g": 1e9}[m.group(2).lower()]))
EOF
) || { echo "bench/scans.sh: SIZE must be a count like 3M, 13M, 53M (got '$size')" >&2; exit 1; }

bin="${BIN:-build/bin}"
for tool in mtgen mtbuild mtverify; do
  [[ -x "$bin/$tool" ]] || { echo "bench/scans.sh: $bin/$tool is missing: build it first" >&2; exit 1; }
done
[[ -x /usr/bin/time ]] || { echo "bench/scans.sh: /usr/bin/time is missing (Debian package 'time')" >&2; exit 1; }
mkdir -p "$work"

# scangen is run from ../shared, never copied into the repository: the build's target, or compiled
# from there into WORK.
scangen="$bin/scangen"
if [[ ! -x "$scangen" ]]; then
  source=../shared/tools/scangen.cpp
  [[ -f "$source" ]] || { echo "bench/scans.sh: $source is missing (shared/ must be beside the repository)" >&2; exit 1; }
  scangen="$work/scangen"
  [[ -x "$scangen" && "$scangen" -nt "$source" ]] || g++ -O2 -std=c++17 -o "$scangen" "$source"
fi
bases="$(dirname "$bin")/scan-bases"
scripts/scan_bases.sh "$bases" >/dev/null

# The base model and LEVELS nearest to SIZE (log scale), among real scanned models.
read -r base levels scanTriangles < <(python3 - "$bases" "$triangles" <<'EOF'
import math, sys
bases, want = sys.argv[1], int(sys.argv[2])
best = None
for name in ["armadillo", "man", "ChineseDragon-10kv", "camel", "lion-head", "bull", "elephant"]:
    with open(f"{bases}/{name}.off") as f:
        f.readline()
        faces = int(f.readline().split()[1])
    for levels in range(0, 9):
        n = faces * 4 ** levels
        cost = abs(math.log(n / want)) + 0.1 * levels  # of two near sizes, the richer base
        if best is None or cost < best[0] - 1e-9:
            best = (cost, name, levels, n)
print(best[1], best[2], best[3])
EOF
)
scan="$work/scan-$base-L$levels.ply"
if [[ ! -s "$scan" ]]; then
  "$scangen" "$bases/$base.off" "$levels" "$scan.tmp" 2>"$work/scangen.log"
  mv "$scan.tmp" "$scan"
fi
scanTriangles=$(head -c 1000 "$scan" | tr -d '\0' | sed -n 's/^element face \([0-9]*\).*/\1/p' | head -1)
gen="$work/mtgen-$scanTriangles.ply"
holes=$(( scanTriangles / 100 < 100 ? scanTriangles / 100 : 100 ))
if [[ ! -s "$gen" ]]; then
  "$bin/mtgen" -o "$gen" --triangles "$scanTriangles" --holes "$holes" --seed 7 2>"$work/mtgen.log"
fi

echo "bench/scans.sh: $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg); --threads $threads --memory $memory --codec $codec --partition $partition${simplifier:+ --simplifier $simplifier}; $rounds round(s), interleaved"
echo "  scan:  $scan (scangen $base.off $levels: $scanTriangles triangles)"
echo "  mtgen: $gen (--triangles $scanTriangles --holes $holes --seed 7)"
results="$work/results.txt"
: > "$results"
printf '%-6s %5s %8s %8s %8s %7s %9s %7s %10s  %s\n' mesh round wall_s cpu_s user_s "Mtri/s" "rss_MiB" "B/tri" "welded" "mtverify --cuts 32"
for ((round = 1; round <= rounds; ++round)); do
  for which in scan mtgen; do
    input=$([[ $which == scan ]] && echo "$scan" || echo "$gen")
    out="$work/$which.mt"
    rm -rf "$out" "$out.work"
    if ! /usr/bin/time -v -o "$work/time.txt" "$bin/mtbuild" "$input" -o "$out" --memory "$memory" \
         --threads "$threads" --codec "$codec" --partition "$partition" ${simplifier:+--simplifier "$simplifier"} \
         >"$work/build.log" 2>&1; then
      echo "bench/scans.sh: mtbuild failed on $input:" >&2
      tail -5 "$work/build.log" >&2
      exit 1
    fi
    wall=$(sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$work/time.txt" | awk -F: '{ s = 0; for (i = 1; i <= NF; ++i) s = s * 60 + $i; print s }')
    user=$(sed -n 's/.*User time (seconds): //p' "$work/time.txt")
    sys=$(sed -n 's/.*System time (seconds): //p' "$work/time.txt")
    rss=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$work/time.txt")
    welded=$(sed -n 's/.*grid weld: \([0-9]*\) vertices.*/\1/p' "$work/build.log" | head -1)
    inputTriangles=$(sed -n 's/^mtbuild: \([0-9]*\) input triangles.*/\1/p' "$work/build.log" | tail -1)
    bytes=$(stat -c %s "$out")
    verifyStart=$(date +%s.%N)
    verdict=$("$bin/mtverify" "$out" --cuts 32 --memory "$memory" -q 2>&1 | tail -1 || true)
    verifySeconds=$(awk -v a="$verifyStart" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
    [[ $keep == 1 ]] || rm -f "$out"
    line=$(awk -v m="$which" -v r="$round" -v w="$wall" -v u="$user" -v s="$sys" -v k="$rss" -v b="$bytes" -v t="$inputTriangles" -v n="${welded:-0}" \
      'BEGIN { printf "%-6s %5d %8.1f %8.1f %8.1f %7.2f %9.0f %7.3f %10d", m, r, w, u + s, u, t / w / 1e6, k / 1024, b / t, n }')
    printf '%s  %s (%s s)\n' "$line" "$verdict" "$verifySeconds"
    printf '%s %s\n' "$line" "$([[ $verdict == OK ]] && echo OK || echo FAIL)" >> "$results"
  done
done
awk '
  { n[$1]++; wall[$1] += $3; cpu[$1] += $4; rate[$1] += $6; if ($7 > rss[$1]) rss[$1] = $7; bpt[$1] += $8; weld[$1] = $9; if ($10 != "OK") bad[$1]++ }
  END {
    printf "mean   %5s %8s %8s %8s %7s %9s %7s %10s  %s\n", "", "wall_s", "cpu_s", "", "Mtri/s", "maxrss", "B/tri", "welded", "mtverify"
    for (m in n) printf "%-6s %5d %8.1f %8.1f %8s %7.2f %9.0f %7.3f %10d  %s\n", m, n[m], wall[m] / n[m], cpu[m] / n[m], "", rate[m] / n[m], rss[m], bpt[m] / n[m], weld[m], bad[m] ? bad[m] " FAILED" : "all OK"
    if (n["scan"] && n["mtgen"]) printf "CPU time scan / mtgen: %.3f (wall %.3f); bytes per input triangle scan / mtgen: %.3f\n", (cpu["scan"] / n["scan"]) / (cpu["mtgen"] / n["mtgen"]), (wall["scan"] / n["scan"]) / (wall["mtgen"] / n["mtgen"]), (bpt["scan"] / n["scan"]) / (bpt["mtgen"] / n["mtgen"])
  }' "$results"
