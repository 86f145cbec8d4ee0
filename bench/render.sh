#!/usr/bin/env bash
# bench/render.sh MT_FILE [MT_FILE...]: the mtrender figures on one recorded path.
#
#   1. the main run: a built-in path (default flythrough: fast turns and zooms, then the camera
#      stops for the last 15% of the frames), >= 600 frames at 1280x720, --budget-ms 50, a cold
#      start (the MT files dropped from the page cache), 256 MiB cache: % frames within budget,
#      max cache bytes vs cap, extract median, first frame from process start, time to <= 1 px
#      after the camera stops; PNG charts (gnuplot) of the per-frame series;
#   2. miss rate and frame time for caches of 32/64/128/256 MiB on the same path (as in El-Sana &
#      Chiang's Table 2), and the baseline mode (--baseline-mmap: the files mapped, the same kind
#      of cut, no RAM cache, no PatchServer, no prefetch; its GPU buffer cache has the same cap),
#      each with its peak RSS (GNU time) since no cgroup memory limit is available here.
#
#   4. the run-time policies on the same path: misses with and without prefetch (--no-prefetch),
#      the cut update's whole cost against its deadline (heaps, prefetch and requests included:
#      extract_within_deadline_pct, extract_ms_max), the GPU cache's peak against its cap, and
#      occlusion culling on a scene where most of the model is hidden (a wall with a window, made
#      here): drawn and loaded triangles with the depth pyramid, with occlusion queries, and
#      without (--no-occlusion), and what each way of testing costs a frame.
#
# Environment: FRAMES (600), WIDTH (1280), HEIGHT (720), BUDGET_MS (50), CAMERA (flythrough),
# CACHES ("32M 64M 128M 256M"), OUT (a fresh directory under /tmp), BIN (build/bin),
# THROUGHPUT (1: also section 3, raw draw throughput for RAW_TRIANGLES="60000 100000 200000 400000"),
# OCC_FRAMES (200), OCC_TRIANGLES (4000000), OCC_WINDOW (0.15), OCC_ONLY (1: only the occlusion
# section), OCCLUSION (0: not the occlusion section). Needs python3 (the wall).
# Miss rate = patches wanted for a cut move but not resident / (those + patches drawn), per run.
set -euo pipefail
if [[ $# -lt 1 ]]; then
  echo "usage: bench/render.sh MT_FILE [MT_FILE...]" >&2
  exit 2
fi
HERE="$(cd "$(dirname "$0")" && pwd)"
BIN="${BIN:-$HERE/../build/bin}"
FRAMES="${FRAMES:-600}"
WIDTH="${WIDTH:-1280}"
HEIGHT="${HEIGHT:-720}"
BUDGET_MS="${BUDGET_MS:-50}"
CAMERA="${CAMERA:-flythrough}"
CACHES="${CACHES:-32M 64M 128M 256M}"
OUT="${OUT:-$(mktemp -d /tmp/render-bench-XXXXXX)}"
mkdir -p "$OUT"
[[ -x "$BIN/mtrender" ]] || { echo "render.sh: $BIN/mtrender not found (build first, or set BIN)" >&2; exit 1; }
GNUTIME=/usr/bin/time
[[ -x $GNUTIME ]] || { echo "render.sh: needs GNU time (/usr/bin/time)" >&2; exit 1; }

run() {  # run NAME ARGS... -> $OUT/NAME.{csv,out}; echoes the summary
  local name=$1; shift
  echo "render.sh: $name ..." >&2
  $GNUTIME -f "peak_rss_kib %M" -o "$OUT/$name.rss" "$BIN/mtrender" "$@" --headless --quiet \
    --camera-path "$CAMERA" --frames "$FRAMES" --width "$WIDTH" --height "$HEIGHT" --budget-ms "$BUDGET_MS" \
    --stats "$OUT/$name.csv" > "$OUT/$name.out"
  cat "$OUT/$name.rss" >> "$OUT/$name.out"
}
val() { awk -v k="$2" '$1 == k { print $2 }' "$OUT/$1.out"; }
rest() { awk -v k="$2" '$1 == k { $1 = ""; sub(/^ /, ""); print }' "$OUT/$1.out"; }
mib() { awk -v b="${1:-0}" 'BEGIN { printf "%.1f", b / 1048576 }'; }
p99() {  # 99th percentile of frame_ms
  tail -n +2 "$OUT/$1.csv" | cut -d, -f2 | sort -g | awk '{ v[NR] = $1 } END { i = int(NR * 0.99); if (i < 1) i = 1; print v[i] }'
}

if [[ ${OCC_ONLY:-0} != 1 ]]; then
run main "$@" --cache 256M --cold --plot "$OUT/plots"
echo
echo "== main run: $* ($FRAMES frames, ${WIDTH}x${HEIGHT}, path $CAMERA, budget $BUDGET_MS ms, cache 256 MiB, cold start)"
printf "frames within budget      %s %%\n" "$(val main within_budget_pct)"
printf "frame ms median / p99 / max %s / %s / %s\n" "$(val main frame_ms_median)" "$(p99 main)" "$(val main frame_ms_max)"
printf "max cache bytes vs cap    %s / %s (%s)\n" "$(val main cache_max_bytes)" "$(val main cache_cap_bytes)" \
  "$(awk '{ if ($1 == "cache_max_bytes") m = $2; if ($1 == "cache_cap_bytes") c = $2 } END { print (m <= c ? "within the cap" : "ABOVE THE CAP") }' "$OUT/main.out")"
printf "extract median            %s ms\n" "$(val main extract_ms_median)"
printf "extract within deadline   %s %%, max %s ms\n" "$(val main extract_within_deadline_pct)" "$(val main extract_ms_max)"
printf "first frame (cold start)  %s ms from process start\n" "$(val main first_frame_ms)"
printf "<= 1 px after the stop    %s (ms; camera stops at frame %s)\n" "$(rest main settle_ms)" "$(val main stop_frame)"
printf "peak RSS                  %s KiB\n" "$(val main peak_rss_kib)"
echo "charts: $OUT/plots/*.png"

[[ ${POLICIES_ONLY:-0} == 1 ]] && CACHES=256M
for c in $CACHES; do
  [[ $c == 256M ]] && { cp "$OUT/main.csv" "$OUT/cache-$c.csv"; cp "$OUT/main.out" "$OUT/cache-$c.out"; continue; }
  run "cache-$c" "$@" --cache "$c"
done
[[ ${POLICIES_ONLY:-0} == 1 ]] || run baseline "$@" --cache 256M --baseline-mmap

if [[ ${POLICIES_ONLY:-0} != 1 ]]; then
echo
echo "== miss rate and frame time by cache size (same path; cf. El-Sana & Chiang Table 2)"
printf "%-16s %10s %8s %12s %10s %10s %10s %14s %12s\n" mode miss_rate misses frame_med_ms frame_p99 within_% extract_ms cache_max_MiB peak_rss_MiB
for c in $CACHES; do
  n="cache-$c"
  printf "%-16s %10s %8s %12s %10s %10s %10s %14s %12s\n" "cache $c" "$(val $n miss_rate)" "$(val $n misses_total)" \
    "$(val $n frame_ms_median)" "$(p99 $n)" "$(val $n within_budget_pct)" "$(val $n extract_ms_median)" \
    "$(mib "$(val $n cache_max_bytes)")" "$(mib "$(( $(val $n peak_rss_kib) * 1024 ))")"
done
n=baseline
printf "%-16s %10s %8s %12s %10s %10s %10s %14s %12s\n" "baseline mmap" "$(val $n miss_rate)" "$(val $n misses_total)" \
  "$(val $n frame_ms_median)" "$(p99 $n)" "$(val $n within_budget_pct)" "$(val $n extract_ms_median)" "-" \
  "$(mib "$(( $(val $n peak_rss_kib) * 1024 ))")"
echo "(baseline: misses = patches decoded synchronously inside frames; its GPU buffer cache is capped at 256 MiB)"
fi

# 4. The run-time policies.
run noprefetch "$@" --cache 256M --cold --no-prefetch
echo
echo "== prefetch (same path, cold start, 256 MiB)"
printf "%-14s %10s %12s %10s %10s %12s\n" mode misses new_misses miss_rate within_% extract_max
for n in main noprefetch; do
  printf "%-14s %10s %12s %10s %10s %12s\n" "$n" "$(val $n misses_total)" "$(val $n new_misses_total)" "$(val $n miss_rate)" \
    "$(val $n within_budget_pct)" "$(val $n extract_ms_max)"
done
awk -v a="$(val main misses_total)" -v b="$(val noprefetch misses_total)" 'BEGIN { if (a > 0) printf "misses without / with prefetch: %.2fx\n", b / a }'
echo "cut update within its deadline (heaps, prefetch, requests included): $(rest main extract_within_deadline_pct)"
echo "its own CPU time within the deadline: $(val main extract_cpu_within_deadline_pct) %, max $(val main extract_cpu_ms_max) ms"
printf "GPU peak vs cap            %s / %s\n" "$(val main gpu_peak_bytes)" "$(val main gpu_cap_bytes)"
fi
# Occlusion culling: a flat wall with a window (a second MT file, made here from the first file's
# bounds) just in front of the model's -y side, filling the view of a camera close to it; the
# window shows OCC_WINDOW^2 of the image. A fixed budget (the culling is measured, not the time
# model), one frame's cut each (--still-frames 1), frames 40 ms apart so the loads keep up.
if [[ ${OCCLUSION:-1} == 1 ]]; then
OCC_FRAMES=${OCC_FRAMES:-200}
OCC_TRIANGLES=${OCC_TRIANGLES:-4000000}
OCC_WINDOW=${OCC_WINDOW:-0.15}
read -r -a BOUNDS <<< "$("$BIN/mtinfo" --json "$1" | python3 -c 'import json, sys; d = json.load(sys.stdin); print(*d["boundsMin"], *d["boundsMax"])')"
python3 - "$OUT/wall.ply" "$OUT/wall.path" "$OCC_WINDOW" "${BOUNDS[@]}" "$WIDTH" "$HEIGHT" <<'PY'
import math, struct, sys
ply, path, win = sys.argv[1], sys.argv[2], float(sys.argv[3])
lo, hi = [float(v) for v in sys.argv[4:7]], [float(v) for v in sys.argv[7:10]]
aspect = float(sys.argv[10]) / float(sys.argv[11])
c = [(a + b) / 2 for a, b in zip(lo, hi)]
s = [b - a for a, b in zip(lo, hi)]
y = lo[1] - 0.1 * s[1]                      # the wall: a tenth of the model's depth in front of it
d = 0.4 * max(s[0], s[2])                   # the eye: this far in front of the wall
t = math.tan(math.radians(22.5)) * 1.15     # 45 degrees vertical field of view, 15% margin
hw, hh = d * t * aspect, d * t
n = 60
verts = [(c[0] - hw + 2 * hw * i / n, y, c[2] - hh + 2 * hh * j / n) for i in range(n + 1) for j in range(n + 1)]
faces = []
for i in range(n):
    for j in range(n):
        xm, zm = -hw + 2 * hw * (i + 0.5) / n, -hh + 2 * hh * (j + 0.5) / n
        if abs(xm) < win * hw and abs(zm) < win * hh:
            continue
        a, b = i * (n + 1) + j, (i + 1) * (n + 1) + j
        faces += [(a, b, b + 1), (a, b + 1, a + 1)]
with open(ply, "wb") as f:
    f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty double x\nproperty double y\n"
            b"property double z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n" % (len(verts), len(faces)))
    for v in verts:
        f.write(struct.pack("<3d", *v))
    for tri in faces:
        f.write(struct.pack("<B3i", 3, *tri))
with open(path, "w") as f:
    f.write("space object\n%.17g %.17g %.17g %.17g %.17g %.17g\n" % (c[0], y - d, c[2], c[0], c[1], c[2]))
PY
"$BIN/mtbuild" "$OUT/wall.ply" -o "$OUT/wall.mt" --threads 2 -q
for o in pyramid queries off; do
  extra="--occlusion-test $o"; [[ $o == off ]] && extra="--no-occlusion"
  echo "render.sh: occlusion $o ..." >&2
  "$BIN/mtrender" "$@" "$OUT/wall.mt" --headless --quiet --camera-path "$OUT/wall.path" --frames "$OCC_FRAMES" \
    --width "$WIDTH" --height "$HEIGHT" --budget-ms "$BUDGET_MS" --cache 1G --fixed-triangles "$OCC_TRIANGLES" \
    --still-frames 1 --frame-interval-ms 40 --screenshots "$OUT/occ-$o" --screenshot-every 100000 \
    --stats "$OUT/occ-$o.csv" $extra > "$OUT/occ-$o.out"
done
echo
echo "== occlusion culling (a wall with a window hides all but ${OCC_WINDOW}^2 of the view; $OCC_FRAMES frames, fixed budget $OCC_TRIANGLES)"
printf "%-9s %12s %14s %14s %16s %12s %16s %14s\n" occlusion cut_last drawn_min_20 drawn_mean_20 loaded_triangles test_frames test_ms_mean tests_per_test
for o in pyramid queries off; do
  f="$OUT/occ-$o.csv"
  printf "%-9s %12s %14s %14s %16s %s\n" "$o" "$(tail -1 "$f" | cut -d, -f4)" \
    "$(tail -20 "$f" | awk -F, 'BEGIN { m = -1 } { if (m < 0 || $10 < m) m = $10 } END { print m }')" \
    "$(tail -20 "$f" | awk -F, '{ s += $10 } END { printf "%.0f", s / NR }')" "$(val occ-$o loaded_triangles_total)" \
    "$(tail -n +2 "$f" | awk -F, '$33 == 1 { n++; ms += $31; t += $32 } END { if (n) printf "%12d %16.2f %14.0f", n, ms / n, t / n; else printf "%12d %16s %14s", 0, "-", "-" }')"
done
last=$(printf "frame_%05d.png" $((OCC_FRAMES - 1)))
for o in pyramid queries; do
  echo "image, $o vs off: $(python3 "$HERE/png_diff.py" "$OUT/occ-$o/$last" "$OUT/occ-off/$last")"
done
echo "(the last frames' images: $OUT/occ-{pyramid,queries,off}/; drawn_min_20 is a frame that tested its own depth)"
fi

# 3. Raw llvmpipe throughput on this machine: the path's final (held) view, a fixed cut of N
#    triangles (--fixed-triangles, the time model off), 60 frames each; ms per frame and the
#    drawn triangles per second (wall and CPU). Tells the draw cost apart from the budget logic.
if [[ ${THROUGHPUT:-1} == 1 ]]; then
  echo
  echo "== raw draw throughput (final view of the path, fixed cut, ${WIDTH}x${HEIGHT}, 60 frames)"
  printf "%-12s %10s %10s %12s %12s\n" triangles drawn frame_med_ms Mtri_s_wall Mtri_s_cpu
  # The flythrough's final pose (camera.cpp), in unit space; CPU time includes start-up (~0.2 s).
  printf "space unit\nfov 45\n0.3 -1.3 0.7  0.05 0.1 0\n" > "$OUT/final.path"
  for n in ${RAW_TRIANGLES:-60000 100000 200000 400000}; do
    $GNUTIME -f "cpu_s %U %S" -o "$OUT/raw-$n.cpu" "$BIN/mtrender" "$@" --headless --quiet \
      --camera-path "$OUT/final.path" --frames 60 --width "$WIDTH" --height "$HEIGHT" --fixed-triangles "$n" --still-frames 1 \
      --stats "$OUT/raw-$n.csv" > "$OUT/raw-$n.out" 2>/dev/null || { echo "raw $n failed"; continue; }
    drawn=$(tail -1 "$OUT/raw-$n.csv" | cut -d, -f10)
    med=$(val "raw-$n" frame_ms_median)
    awk -v n="$n" -v d="$drawn" -v m="$med" -v f="$OUT/raw-$n.cpu" 'BEGIN {
      getline l < f; split(l, c, " "); cpu = (c[2] + c[3]) / 60 * 1000;
      printf "%-12s %10s %10s %12.2f %12.2f\n", n, d, m, d / m / 1000, d / cpu / 1000 }'
  done
fi
echo "outputs: $OUT"
