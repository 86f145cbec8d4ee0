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
#                        [--tools] [-- MTBUILD OPTIONS...]
#
# --tools: after a verified build, every tool that reads the file runs on it too, and any exit
# status but 0 fails the model: the finest cut (`mtextract --error 0`, its triangles checked
# against level 0's) built again by `mtbuild` and verified, a cut of an eighth of the triangles as
# GLB, `mtexport tiles`, `mtrender --headless` (20 orbit frames; needs EGL) and `mtinfo --json`.
#
# --size: each model's LEVELS is the smallest giving at least this many triangles (base triangles
# x 4^LEVELS, at most 7 levels); 150k takes ~10 minutes for the ~125 readable models on 2 cores.
# Options after -- go to mtbuild (e.g. -- --partition regular, -- --simplifier quadric,
# -- --memory 64M --threads 1). BIN=dir/bin picks another build dir.
set -euo pipefail
cd "$(dirname "$0")/.."

size=150k cuts=8 rotate=0 work=out/sweep-bases models="" tools=0 extra=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --size) size=$2; shift 2 ;;
    --cuts) cuts=$2; shift 2 ;;
    --rotate) rotate=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --models) models=$2; shift 2 ;;
    --tools) tools=1; shift ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,23p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
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
needed="mtbuild mtverify mtinfo scangen"
(( tools )) && needed="$needed mtextract mtexport mtrender"
for tool in $needed; do
  [[ -x "$bin/$tool" ]] || { echo "bench/sweep_bases.sh: $bin/$tool is missing: build it first (scangen needs ../shared)" >&2; exit 1; }
done
bases="$(dirname "$bin")/scan-bases"
scripts/scan_bases.sh "$bases" >/dev/null
mkdir -p "$work"
[[ -n "$models" ]] || models=$(cd "$bases" && ls *.off | sed 's/\.off$//' | tr '\n' ' ')

options=("" "--holes 0.3" "--shuffle 5" "--amp 0.01 --holes 0.05")

# Runs the tools of --tools on MT file $1 in folder $2 (emptied first); prints " TOOL: last line"
# for each that failed, nothing when all passed. Each tool's output is kept in $2/TOOL.log.
tools_on() {
  local mt=$1 dir=$2 out=""
  rm -rf "$dir" && mkdir -p "$dir"
  step() {  # step NAME COMMAND...: runs it, its output in NAME.log; a failure is added to out
    local tag=$1
    shift
    if ! timeout 600 "$@" >"$dir/$tag.log" 2>&1; then out+=" $tag: $(tail -1 "$dir/$tag.log")"; return 1; fi
  }
  local level0
  step info "$bin/mtinfo" "$mt" --json
  level0=$(sed -n 's/.*"level": 0,.*"triangles": \([0-9]*\),.*/\1/p' "$dir/info.log")
  [[ -n "$level0" ]] || { out+=" info: no level 0 in its --json"; level0=0; }
  if step extract-finest "$bin/mtextract" "$mt" --error 0 -o "$dir/finest.ply"; then
    local got
    got=$(sed -n 's/.*: \([0-9]*\) triangles,.*/\1/p' "$dir/extract-finest.log")
    [[ "$got" == "$level0" ]] || out+=" extract-finest: $got triangles, level 0 has $level0"
    step rebuild "$bin/mtbuild" "$dir/finest.ply" -o "$dir/finest.mt" -q &&
      step rebuild-verify "$bin/mtverify" "$dir/finest.mt" --cuts 2
  fi
  step extract-glb "$bin/mtextract" "$mt" --triangles $(( (level0 + 7) / 8 )) -o "$dir/eighth.glb"
  step tiles "$bin/mtexport" tiles "$mt" "$dir/tiles"
  step render "$bin/mtrender" "$mt" --headless --quiet --camera-path orbit --frames 20 --width 320 --height 240
  rm -rf "$dir/finest.ply" "$dir/finest.mt" "$dir/tiles" "$dir/eighth.glb"
  printf '%s' "$out"
}
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
  verified=0
  [[ "$verdict" == *OK* && "$verdict" != *FAILED* ]] && verified=1
  # --tools: what failed among the tools run on the verified file, empty when all passed.
  broken=""
  (( tools && verified )) && broken=$(tools_on "$work/out.mt" "$work/tools")
  if (( verified )) && [[ -n "$broken" ]]; then
    failed=$((failed + 1))
    cp "$work/in.ply" "$work/failed-$name.ply"
    printf '%-52s %9s  TOOLS FAILED:%s\n' "$label" "$triangles" "$broken"
  elif (( verified )); then
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
