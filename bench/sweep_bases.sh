#!/usr/bin/env bash
# Every base model Debian's libcgal-demo ships (scripts/scan_bases.sh: scanned statues and animals,
# CAD parts, non-manifold and degenerate test meshes), made scan-like by ../shared/tools/scangen.cpp
# and built: one line per model with the scangen options, the triangle count and the verdict
# (`mtbuild` exit status and last line, then `mtverify --cuts N`; for a good file, its top level
# and that level's triangles), and a count at the end. The scangen options rotate over none,
# holes, shuffled faces and noise with holes (--rotate K starts the rotation K models later, so
# two runs cover other pairs). A model scangen cannot read
# (polygons, counts that do not match) is listed as skipped. Exit status 1 when a build or a
# verification failed; the failing inputs are kept in WORK.
#
#   bench/sweep_bases.sh [--size 150k] [--cuts 8] [--rotate 0] [--work DIR] [--models "A B ..."]
#                        [-- MTBUILD OPTIONS...]
#
# --size: each model's LEVELS is the smallest giving at least this many triangles (base triangles
# x 4^LEVELS, at most 7 levels); 150k takes ~10 minutes for the ~125 readable models on 2 cores.
# Options after -- go to mtbuild (e.g. -- --partition regular, -- --simplifier quadric,
# -- --memory 64M --threads 1). BIN=dir/bin picks another build dir.
set -euo pipefail
cd "$(dirname "$0")/.."

size=150k cuts=8 rotate=0 work=out/sweep-bases models="" extra=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --size) size=$2; shift 2 ;;
    --cuts) cuts=$2; shift 2 ;;
    --rotate) rotate=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --models) models=$2; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench/sweep_bases.sh: unknown option $1 (see --help)" >&2; exit 1 ;;
  esac
done
target=$(python3 - "$size" <<'EOF'
import re, sys
m = re.fullmatch(r"([0-9.]+)([kKmM]?)", sys.argv[1])
if not m: sys.exit(1)
print(int(float(m.group(1)) * {"": 1, "k": 1e3, "m": 1e6}[m.group(2).lower()]))
EOF
) || { echo "bench/sweep_bases.sh: --size must be a count like 150k or 2M (got '$size')" >&2; exit 1; }
[[ "$cuts" =~ ^[1-9][0-9]*$ ]] || { echo "bench/sweep_bases.sh: --cuts must be a count from 1 (got '$cuts')" >&2; exit 1; }
[[ "$rotate" =~ ^[0-9]+$ ]] || { echo "bench/sweep_bases.sh: --rotate must be a count from 0 (got '$rotate')" >&2; exit 1; }

bin="${BIN:-build/bin}"
for tool in mtbuild mtverify mtinfo scangen; do
  [[ -x "$bin/$tool" ]] || { echo "bench/sweep_bases.sh: $bin/$tool is missing: build it first (scangen needs ../shared)" >&2; exit 1; }
done
bases="$(dirname "$bin")/scan-bases"
scripts/scan_bases.sh "$bases" >/dev/null
mkdir -p "$work"
[[ -n "$models" ]] || models=$(cd "$bases" && ls *.off | sed 's/\.off$//' | tr '\n' ' ')

options=("" "--holes 0.3" "--shuffle 5" "--amp 0.01 --holes 0.05")
echo "bench/sweep_bases.sh: $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg); size >= $target, mtverify --cuts $cuts, mtbuild ${extra[*]:-(defaults)}"
i=$rotate ok=0 failed=0 skipped=0
for name in $models; do
  off="$bases/$name.off"
  [[ -f "$off" ]] || { echo "bench/sweep_bases.sh: no base model $off" >&2; exit 1; }
  # The face count: the second number of the first line that is not the OFF keyword or a comment.
  faces=$(awk '/^[[:space:]]*#/ || NF == 0 { next } !seen && $1 == "OFF" && NF == 1 { seen = 1; next } { if ($1 == "OFF") print $3; else print $2; exit }' "$off")
  [[ "$faces" =~ ^[0-9]+$ && "$faces" -gt 0 ]] || faces=1
  levels=0 n=$faces
  while (( n < target && levels < 7 )); do n=$((n * 4)); levels=$((levels + 1)); done
  opt=${options[$((i % 4))]}
  i=$((i + 1))
  label="$name $levels${opt:+ $opt}"
  if ! "$bin/scangen" "$off" "$levels" "$work/in.ply" $opt >"$work/scangen.log" 2>&1; then
    printf '%-52s skipped (scangen: %s)\n' "$label" "$(tail -1 "$work/scangen.log")"
    skipped=$((skipped + 1))
    continue
  fi
  triangles=$(sed -n 's/.* \([0-9]*\) triangles.*/\1/p' "$work/scangen.log" | head -1)
  if ! "$bin/mtbuild" "$work/in.ply" -o "$work/out.mt" -q "${extra[@]}" >"$work/build.log" 2>&1; then
    printf '%-52s %9s  BUILD FAILED: %s\n' "$label" "$triangles" "$(tail -1 "$work/build.log")"
    cp "$work/in.ply" "$work/failed-$name.ply"
    failed=$((failed + 1))
    continue
  fi
  verdict=$("$bin/mtverify" "$work/out.mt" --cuts "$cuts" 2>&1 | grep -E 'crack-free cuts|^OK|FAILED' | tr -s ' ' | tr '\n' ' ' || true)
  if [[ "$verdict" == *OK* && "$verdict" != *FAILED* ]]; then
    ok=$((ok + 1))
    # The coarsest level's triangles and the level count: a build whose retries kept its regions
    # whole stops early with a large coarsest level.
    coarsest=$("$bin/mtinfo" "$work/out.mt" --json | sed -n 's/.*"level": \([0-9]*\),.*"triangles": \([0-9]*\),.*/\1 \2/p' | tail -1)
    printf '%-52s %9s  ok, top level %s: %s triangles\n' "$label" "$triangles" "${coarsest%% *}" "${coarsest##* }"
  else
    failed=$((failed + 1))
    cp "$work/in.ply" "$work/failed-$name.ply"
    printf '%-52s %9s  VERIFY FAILED: %s\n' "$label" "$triangles" "$verdict"
  fi
done
rm -f "$work/in.ply" "$work/out.mt"
echo "bench/sweep_bases.sh: $ok ok, $failed failed, $skipped skipped (scangen could not read them)"
[[ $failed -eq 0 ]]
