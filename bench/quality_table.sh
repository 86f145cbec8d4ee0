#!/usr/bin/env bash
# The quality line at equal size on the scan-derived meshes: for each mesh, the 1/8 cut of our
# build (exact distances, `EXACT=1 bench/quality.sh`), next to Nexus's cut at the same count
# recorded in docs/mtbuild.md ("Third pass": nxsbuild defaults, nxsedit -t searched to our count,
# measured with the same exact tool), and whether both of our means are at or under Nexus's.
# Nexus is not rebuilt here (it lives outside the repository); use `bench/quality.sh IN.ply
# OUT.mt --nexus DIR` to measure it again.
#
# Usage: bench/quality_table.sh [MESH ...]   (default: arm0.8M arm3.3M arm13M)
#   MESH is a name under $DATA (default /work/data): DATA/MESH.ply is the input. Each build goes
#   to $OUT (default a temporary directory), `mtbuild MESH.ply -o MESH.mt --threads 2 -q
#   $MTBUILD_ARGS` (default MTBUILD_ARGS: --simplifier quadric); an existing OUT/MESH.mt is reused.
# Prints one row per mesh and tool: triangles, mean and max cut->in, mean and max in->cut, and
# for ours bytes per input triangle, build CPU seconds (user+sys) and the verdict.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${MT_BIN:-$root/build/bin}"
data="${DATA:-/work/data}"
args="${MTBUILD_ARGS:---simplifier quadric}"
out="${OUT:-}"
if [[ -z "$out" ]]; then out="$(mktemp -d "${TMPDIR:-/tmp}/qtable.XXXXXX")"; trap 'rm -rf "$out"' EXIT; fi
meshes=("$@")
[[ ${#meshes[@]} -gt 0 ]] || meshes=(arm0.8M arm3.3M arm13M)
# Nexus's 1/8 cuts, exact distances, keyed by the input's triangle count (the mesh they were
# measured on: scangen is deterministic, but a mesh of the same name made with other options is
# another mesh): triangles, mean c->in, max c->in, mean in->c, max in->c.
nexus() {
  case "$1" in
    319680) echo "39982 0.025287 0.3908 0.026020 0.4224" ;;       # scangen ChineseDragon-10kv.off 2
    832000) echo "103982 0.016436 0.1662 0.016651 0.3597" ;;      # scangen armadillo.off 2
    3328000) echo "415932 0.007337 0.1037 0.007781 0.1848" ;;     # scangen armadillo.off 3
    5118464) echo "634536 0.005683 0.0773 0.006653 0.1865" ;;     # scangen ChineseDragon-10kv.off 4
    13312000) echo "1662000 0.002967 0.0495 0.003064 0.1035" ;;   # scangen armadillo.off 4
    *) echo "" ;;
  esac
}
printf '%-11s %-6s %10s %12s %10s %12s %10s %8s %8s %s\n' mesh tool triangles "mean c->in" "max c->in" "mean in->c" "max in->c" B/tri cpu-s verdict
for m in "${meshes[@]}"; do
  in="$data/$m.ply"
  [[ -f "$in" ]] || { echo "quality_table: no $in" >&2; exit 2; }
  mt="$out/$m.mt" cpu="-"
  if [[ ! -f "$mt" ]]; then
    # shellcheck disable=SC2086
    cpu=$( { /usr/bin/time -f '%U %S' "$bin/mtbuild" "$in" -o "$mt" --threads 2 -q $args >/dev/null; } 2>&1 | tail -1 |
      awk '{ printf "%.1f", $1 + $2 }')
  fi
  n=$(grep -a -m1 '^element face' "$in" | awk '{print $3}')
  bpt=$(awk -v s="$(stat -c %s "$mt")" -v n="$n" 'BEGIN { printf "%.3f", s / n }')
  read -r _ _ tri cm cx im ix < <(MT_BIN="$bin" EXACT=1 "$root/bench/quality.sh" "$in" "$mt" | tail -1)
  nx=$(nexus "$n") verdict="(no Nexus figure)"
  if [[ -n "$nx" ]]; then
    read -r ntri ncm ncx nim nix <<<"$nx"
    verdict=$(awk -v a="$cm" -v b="$im" -v c="$ncm" -v d="$nim" 'BEGIN {
      printf "%s (c->in %+.1f%%, in->c %+.1f%%)", (a <= c && b <= d) ? "ok" : "ABOVE NEXUS", 100 * (a / c - 1), 100 * (b / d - 1) }')
  fi
  printf '%-11s %-6s %10s %12s %10s %12s %10s %8s %8s %s\n' "$m" ours "$tri" "$cm" "$cx" "$im" "$ix" "$bpt" "$cpu" "$verdict"
  [[ -n "$nx" ]] && printf '%-11s %-6s %10s %12s %10s %12s %10s\n' "$m" nexus "$ntri" "$ncm" "$ncx" "$nim" "$nix"
done
