#!/usr/bin/env bash
# Fidelity of an MT build, measured by an independent tool (BRIEF "Fidelity"): for three error
# levels E, `mtextract --error E` is compared with the input by MeshLab's Hausdorff filter in both
# directions. The bound is true when Hausdorff <= E, tight when Hausdorff >= E/3 (checked for the two
# finer levels). The finest cut (E = the quantization error) must match the input within the
# quantization step.
#
# Usage: bench/fidelity.sh [INPUT.ply [OUT.mt]]
#   default INPUT: a 1M-triangle mtgen scan with 30 holes (built here), OUT: built with mtbuild's defaults.
#   env MTBUILD_ARGS adds mtbuild options (e.g. "--codec draco"); SAMPLES the MeshLab sample count.
# Needs meshlab (Debian package; installed here when missing) and xvfb-run (meshlabserver is a Qt app).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${MT_BIN:-$root/build/bin}"  # MT_BIN: another build's bin/
[[ -x "$bin/mtbuild" ]] || "$root/scripts/setup.sh"
if ! command -v meshlabserver >/dev/null; then
  echo "fidelity: installing meshlab (Debian package)" >&2
  SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO="sudo"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends meshlab >/dev/null
fi

work="$(mktemp -d "${TMPDIR:-/tmp}/fidelity.XXXXXX")"
trap 'rm -rf "$work"' EXIT
input="${1:-}"
if [[ -z "$input" ]]; then
  input="$work/scan.ply"
  "$bin/mtgen" -o "$input" --triangles 1M --holes 30 --shuffle --seed 3 >/dev/null
fi
mt="${2:-$work/scan.mt}"
if [[ ! -f "$mt" ]]; then
  # shellcheck disable=SC2086
  "$bin/mtbuild" "$input" -o "$mt" -q ${MTBUILD_ARGS:-}
fi
samples="${SAMPLES:-2000000}"

# shellcheck source=bench/hausdorff.sh
source "$(dirname "$0")/hausdorff.sh"
# One-sided Hausdorff (max distance from samples of $1 to the surface of $2), in object units.
hausdorff() { hausdorff_oneway "$@" | awk '{ print $2 }'; }

json="$("$bin/mtinfo" "$mt" --json)"
levels=$(grep -o '"levels": [0-9]*' <<<"$json" | grep -o '[0-9]*$')
qerr=$(grep -o '"quantizationError": [0-9.e+-]*' <<<"$json" | grep -o '[0-9.e+-]*$')
step=$(grep -o '"gridStep": [0-9.e+-]*' <<<"$json" | grep -o '[0-9.e+-]*$')
level_error() {  # errorMax of level $1
  grep -o "\"level\": $1, [^}]*" <<<"$json" | grep -o '"errorMax": [0-9.e+-]*' | grep -o '[0-9.e+-]*$'
}
# Three error levels spread over the DAG: a quarter, half and three quarters of the way up.
picks=($((levels / 4 > 0 ? levels / 4 : 1)) $((levels / 2)) $((3 * levels / 4)))

echo "fidelity: $mt ($levels levels, grid step $step, quantization error $qerr), input $input"
printf '%-8s %-12s %10s %12s %12s %12s %8s  %s\n' level E triangles "H(cut->in)" "H(in->cut)" H H/E verdict
status=0
row() {  # $1 label, $2 E, $3 finer (check tightness), $4 limit (defaults to E)
  local cut="$work/cut.ply"
  local tris
  tris=$("$bin/mtextract" "$mt" --error "$2" -o "$cut" 2>&1 | grep -o '[0-9]* triangles' | head -1 | grep -o '^[0-9]*')
  local a b
  a=$(hausdorff "$cut" "$input")
  b=$(hausdorff "$input" "$cut")
  local verdict
  verdict=$(awk -v a="$a" -v b="$b" -v e="$2" -v lim="${4:-$2}" -v tight="$3" 'BEGIN {
      h = (a > b ? a : b); v = (h <= lim) ? "bound-true" : "BOUND-VIOLATED";
      if (tight == 1) v = v ((h >= e / 3) ? ",tight" : ",LOOSE");
      printf "%.6g %.3f %s", h, h / e, v }')
  read -r h ratio word <<<"$verdict"
  printf '%-8s %-12.6g %10s %12.6g %12.6g %12.6g %8s  %s\n' "$1" "$2" "$tris" "$a" "$b" "$h" "$ratio" "$word"
  [[ "$word" == *VIOLATED* || "$word" == *LOOSE* ]] && status=1
  return 0
}
row finest "$qerr" 0 "$step"
row "${picks[0]}" "$(level_error "${picks[0]}")" 1
row "${picks[1]}" "$(level_error "${picks[1]}")" 1
row "${picks[2]}" "$(level_error "${picks[2]}")" 0
exit $status
