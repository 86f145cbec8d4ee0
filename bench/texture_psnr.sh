#!/usr/bin/env bash
# The appearance figure of a textured MT file (docs/appearance.md "Figures"): the fixed view drawn
# with its node textures at 1/4, 1/2, 1 and 2 px of screen error against the full resolution,
# each rendered at 3200 x 2400 and box-filtered to 800 x 600 (bench_psnr --downsample 4), PSNR over
# the pixels the model covers and over the whole image, with the cut's triangles.
#
# Usage: bench/texture_psnr.sh FILE.mt WORKDIR [TOLERANCES...]
#   TOLERANCES: screen errors at 3200 x 2400 (default "1 2 4 8": 0.25 to 2 px at 800 x 600).
#   The reference (--tolerance 0.01 --no-cull: every patch of the input, also the inside seen
#   through holes) is rendered once into WORKDIR/ref and reused while it exists.
#   env MT_BIN: the tools' directory (default build/bin).
# A scan-derived textured input: mtgen --paint /work/data/arm0.8M.ply -o arm_t.ply --texture box
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${MT_BIN:-$root/build/bin}"
mt="${1:?usage: bench/texture_psnr.sh FILE.mt WORKDIR [TOLERANCES...]}"
work="${2:?usage: bench/texture_psnr.sh FILE.mt WORKDIR [TOLERANCES...]}"
shift 2
tolerances=("$@")
[[ ${#tolerances[@]} -gt 0 ]] || tolerances=(1 2 4 8)
mkdir -p "$work"
draw() {  # draw TAG TOLERANCE [options]
  local tag="$1" tol="$2"
  shift 2
  rm -rf "$work/$tag"
  nice -n 19 "$bin/mtrender" "$mt" --headless --camera-path fixed --width 3200 --height 2400 --frames "${FRAMES:-60}" \
    --fixed-triangles 20000000 --cache 2G --load-budget 2000 --extract-ms 200 --budget-ms 60000 --color texture \
    --screenshots "$work/$tag" --screenshot-every 1000 --tolerance "$tol" --stats "$work/$tag.csv" "$@" > "$work/$tag.log" 2>&1
  ls "$work/$tag"/*.png | tail -1
}
if [[ -d "$work/ref" ]]; then ref=$(ls "$work/ref"/*.png | tail -1); else ref=$(FRAMES=80 draw ref 0.01 --no-cull); fi
printf "%-12s %-12s %-14s %s\n" "screen err" triangles "PSNR covered" "PSNR all"
for t in "${tolerances[@]}"; do
  img=$(draw "cut_$t" "$t")
  read -r _ all _ covered _ _ < <("$bin/bench_psnr" "$img" "$ref" --downsample 4)
  triangles=$(tail -1 "$work/cut_$t.csv" | cut -d, -f4)
  printf "%-12s %-12s %-14s %s\n" "$(awk -v t="$t" 'BEGIN { print t / 4 " px" }')" "$triangles" "$covered dB" "$all dB"
done
