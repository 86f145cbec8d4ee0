#!/usr/bin/env bash
# Quality at equal size: our cut of a given triangle count against the input, mean and maximum
# distance both ways (MeshLab's Hausdorff filter, as bench/fidelity.sh), at 1/8 of the input's
# triangles and at other fractions; and Nexus's cut at the same count when a Nexus build is given.
#
# Usage: bench/quality.sh INPUT.ply [OUT.mt] [--fractions "2 8 32"] [--nexus DIR] [--nxs FILE.nxs]
#   OUT.mt: built here with mtbuild's defaults when missing (env MTBUILD_ARGS adds options).
#   --nexus DIR: a Nexus build directory (with src/nxsbuild/nxsbuild and src/nxsedit/nxsedit, built
#     outside this repository); FILE.nxs is built from INPUT with nxsbuild's defaults when missing.
#     nxsedit -t drops whole nodes and counts differently from us, so its budget is searched (up to
#     10 tries) for the cut closest to ours in triangles.
#   env SAMPLES: MeshLab's sample count (default 2000000; vertex, edge and face samples).
#   env EXACT=1: exact distances (bench_cut_distance, deterministic, no MeshLab) instead of
#     MeshLab's sampled ones; use it to compare builds, MeshLab as the independent reference.
# Prints one row per (tool, fraction): triangles, mean and max cut->input, mean and max input->cut.
# Needs meshlab (Debian package) and xvfb-run.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${MT_BIN:-$root/build/bin}"
input="" mt="" nexus="" nxs="" fractions="8"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --fractions) fractions="$2"; shift 2 ;;
    --nexus) nexus="$2"; shift 2 ;;
    --nxs) nxs="$2"; shift 2 ;;
    -*) echo "quality: unknown option $1" >&2; exit 2 ;;
    *) if [[ -z "$input" ]]; then input="$1"; else mt="$1"; fi; shift ;;
  esac
done
[[ -n "$input" && -f "$input" ]] || { echo "usage: bench/quality.sh INPUT.ply [OUT.mt] [--fractions \"2 8\"] [--nexus DIR] [--nxs F.nxs]" >&2; exit 2; }
exact="${EXACT:-0}"
[[ "$exact" == 1 ]] || command -v meshlabserver >/dev/null ||
  { echo "quality: needs meshlabserver (apt-get install meshlab), or EXACT=1" >&2; exit 1; }
work="$(mktemp -d "${TMPDIR:-/tmp}/quality.XXXXXX")"
trap 'rm -rf "$work"' EXIT
if [[ -z "$mt" ]]; then mt="$work/in.mt"; fi
if [[ ! -f "$mt" ]]; then
  # shellcheck disable=SC2086
  "$bin/mtbuild" "$input" -o "$mt" -q ${MTBUILD_ARGS:-}
fi
samples="${SAMPLES:-2000000}"
# shellcheck source=bench/hausdorff.sh
source "$(dirname "$0")/hausdorff.sh"
oneway() { hausdorff_oneway "$@"; }
faces() { grep -a -m1 '^element face' "$1" | awk '{print $3}'; }
row() {  # $1 tool, $2 fraction, $3 cut.ply
  local a b
  if [[ "$exact" == 1 ]]; then
    "$bin/bench_cut_distance" "$input" "$3" --samples "$samples" |
      awk -v t="$1" -v f="$2" '$2 == "c->in" && $1 ~ /^[0-9]+$/ { printf "%-6s 1/%-4s %10s %12s %12s %12s %12s\n", t, f, $1, $3, $4, $6, $7 }'
    return
  fi
  a=$(oneway "$3" "$input")
  b=$(oneway "$input" "$3")
  read -r am ax <<<"$a"
  read -r bm bx <<<"$b"
  printf '%-6s 1/%-4s %10s %12s %12s %12s %12s\n' "$1" "$2" "$(faces "$3")" "$am" "$ax" "$bm" "$bx"
}
n=$(faces "$input")
if [[ -n "$nexus" && -z "$nxs" ]]; then nxs="$work/in.nxs"; fi
if [[ -n "$nexus" && ! -f "$nxs" ]]; then
  "$nexus/src/nxsbuild/nxsbuild" "$input" -o "$nxs" >"$work/nxsbuild.log" 2>&1 ||
    { tail -5 "$work/nxsbuild.log" >&2; echo "quality: nxsbuild failed" >&2; exit 1; }
fi
how="MeshLab Hausdorff, $samples samples"
[[ "$exact" == 1 ]] && how="exact distances (bench_cut_distance)"
echo "quality: $input ($n triangles), $mt${nexus:+, Nexus $nxs}; $how"
printf '%-6s %-6s %10s %12s %12s %12s %12s\n' tool cut triangles "mean c->in" "max c->in" "mean in->c" "max in->c"
for f in $fractions; do
  target=$((n / f))
  "$bin/mtextract" "$mt" --triangles "$target" -o "$work/ours.ply" >/dev/null 2>&1
  row ours "$f" "$work/ours.ply"
  if [[ -n "$nexus" ]]; then
    ours=$(faces "$work/ours.ply")
    budget=$((2 * ours)) best="" bestd=""
    for _ in 1 2 3 4 5 6 7 8 9 10; do  # secant-free search: scale the budget by the miss
      "$nexus/src/nxsedit/nxsedit" "$nxs" -t "$budget" -p "$work/nx.ply" >/dev/null 2>&1
      got=$(faces "$work/nx.ply")
      d=$((got > ours ? got - ours : ours - got))
      if [[ -z "$bestd" || $d -lt $bestd ]]; then bestd=$d best=$budget; cp "$work/nx.ply" "$work/nxbest.ply"; fi
      [[ $((d * 200)) -le $ours || $got -eq 0 ]] && break
      budget=$(awk -v b="$budget" -v o="$ours" -v g="$got" 'BEGIN { printf "%d", b * o / g }')
    done
    row nexus "$f" "$work/nxbest.ply"
  fi
done
