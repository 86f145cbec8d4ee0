#!/usr/bin/env bash
# bench/billion.sh: a billion-triangle scan end to end on one machine, every figure printed.
#   1. mtgen streams a scan with holes straight to WORK/scan.ply (O(1) memory, no copy besides it)
#   2. mtbuild --memory 512M --threads 2: input M tri/s end to end, CPU (user + sys, sys share),
#      peak RSS, temporary disk high-water mark (mtbuild's own peak_temp_bytes, and the free space
#      of WORK's file system sampled every second), bytes per input triangle, bytes written (/proc io)
#   2b. with --same-bytes-at MEM: the build again at --memory MEM, its wall, CPU, peak RSS and
#      whether its file is byte for byte the first one (sha256 of both)
#   3. mtverify --cuts 4 --memory 1G: verdict, wall, peak RSS
#   4. mtinfo
#   5. mtextract of the finest cut --memory 1G: wall, peak RSS against the cap, the PLY's size
#      (the input PLY is removed first unless --keep-input: the finest cut is as large as it)
#   6. a headless flythrough (mtrender, EGL): frames within the 50 ms budget, extract median,
#      first frame (cold)
#
#   bench/billion.sh [--triangles 1000M] [--work DIR] [--memory 512M] [--threads 2] [--frames 600]
#                    [--keep-input] [--keep] [--skip-render] [--same-bytes-at 256M] [--level-ratio 2]
# --level-ratio K goes to both builds (mtbuild --level-ratio: each level keeps 1/K of the one below).
# BIN=dir/bin picks the build dir (default build/bin). Disk needed is checked first and printed:
# about 19 bytes per triangle for the PLY, about as much again of build scratch (0.76x the PLY
# measured at a billion), ~2.4 for the MT file.
set -euo pipefail
cd "$(dirname "$0")/.."
triangles=1000M; work=out/billion; memory=512M; threads=2; frames=600
keepInput=0; keep=0; render=1; again=""; ratio=2
while [[ $# -gt 0 ]]; do
  case "$1" in
    --triangles) triangles="$2"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    --memory) memory="$2"; shift 2 ;;
    --threads) threads="$2"; shift 2 ;;
    --frames) frames="$2"; shift 2 ;;
    --keep-input) keepInput=1; shift ;;
    --keep) keep=1; shift ;;
    --skip-render) render=0; shift ;;
    --same-bytes-at) again="$2"; shift 2 ;;
    --level-ratio) ratio="$2"; shift 2 ;;
    -h|--help) sed -n '2,20p' "$0"; exit 0 ;;
    *) echo "billion.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
bin="${BIN:-build/bin}"
for t in mtgen mtbuild mtverify mtinfo mtextract; do
  [[ -x "$bin/$t" ]] || { echo "billion.sh: $bin/$t not found (build first, or set BIN)" >&2; exit 1; }
done
[[ -x /usr/bin/time ]] || { echo "billion.sh: needs GNU time (/usr/bin/time)" >&2; exit 1; }
count=$(python3 -c "import sys; s=sys.argv[1].upper(); m={'K':1e3,'M':1e6,'G':1e9}; print(int(float(s[:-1])*m[s[-1]]) if s[-1] in m else int(s))" "$triangles")
mkdir -p "$work"
ply="$work/scan.ply"; mt="$work/scan.mt"; cut="$work/finest.ply"

# ---- disk: the PLY (19 B/tri), build scratch (the store's packed blocks and the sorts' runs: 0.76x
# the PLY at a billion; 1.2x asked for), the MT file (2.4 B/tri); the extract replaces the input PLY
# unless --keep-input.
gib() { awk -v b="$1" 'BEGIN { printf "%.1f GiB", b / 2^30 }'; }
need=$(( count * 19 + count * 23 + count * 24 / 10 ))
(( keepInput )) && need=$(( need + count * 19 ))
have=$(( $(df -B1 --output=avail "$work" | tail -1) ))
[[ -f "$ply" ]] && have=$(( have + $(stat -c %s "$ply") ))
echo "billion.sh: $count triangles need about $(gib $need) of disk in $work; $(gib $have) available"
if (( have < need )); then
  echo "billion.sh: not enough free disk in $work: need $(gib $need), have $(gib $have) (try a smaller --triangles or another --work)" >&2
  exit 1
fi

# Free space of WORK's file system every second: its drop below the start is the high-water mark
# of everything the step wrote.
watchDisk() {  # watchDisk OUTFILE & -> the lowest free bytes seen
  local low; low=$(df -B1 --output=avail "$work" | tail -1)
  while true; do
    local now; now=$(df -B1 --output=avail "$work" | tail -1)
    (( now < low )) && low=$now
    echo "$low" > "$1"
    sleep 1
  done
}
peakio() {  # peakio PID FILE: write_bytes of the process, sampled until it exits
  while kill -0 "$1" 2>/dev/null; do
    awk '/^write_bytes/ { print $2 }' "/proc/$1/io" > "$2.tmp" 2>/dev/null && mv "$2.tmp" "$2"
    sleep 1
  done
}

loadavg() { echo "load (1/5/15 min) $(cut -d' ' -f1-3 /proc/loadavg) at $(date -u +%H:%M:%S) before: $1"; }

# ---- 1. generate (streamed)
if [[ ! -f "$ply" ]] || [[ "$(cat "$work/scan.count" 2>/dev/null)" != "$count" ]]; then
  rm -f "$ply"
  /usr/bin/time -f "%e %U %S %M" -o "$work/gen.time" "$bin/mtgen" -o "$ply" --triangles "$count" --holes 100 --seed 11 2> "$work/gen.log" \
    || { cat "$work/gen.log" >&2; exit 1; }
  echo "$count" > "$work/scan.count"
  read -r gw gu gs gr < "$work/gen.time"
  echo "generate: $(stat -c %s "$ply") bytes in $gw s ($(awk -v n="$count" -v w="$gw" 'BEGIN{printf "%.2f", n/w/1e6}') M tri/s), peak RSS $(( gr / 1024 )) MiB"
fi
plyBytes=$(stat -c %s "$ply")

# ---- 2. build
loadavg "build"
rm -f "$mt"
start=$(df -B1 --output=avail "$work" | tail -1)
watchDisk "$work/disk.low" & watcher=$!
/usr/bin/time -f "%e %U %S %M" -o "$work/build.time" "$bin/mtbuild" "$ply" -o "$mt" --memory "$memory" --threads "$threads" \
  --level-ratio "$ratio" --stats-json "$work/stats.json" -q > "$work/build.log" 2>&1 &
builder=$!
sleep 0.2
bpid=$(pgrep -P "$builder" | head -1 || true)  # mtbuild (whatever name it runs under)
sampler=""
if [[ -n "$bpid" ]]; then peakio "$bpid" "$work/build.io" & sampler=$!; fi
wait "$builder" || { kill "$watcher"; cat "$work/build.log" >&2; exit 1; }
[[ -n "$sampler" ]] && wait "$sampler" || true
kill "$watcher" 2>/dev/null || true
low=$(cat "$work/disk.low"); mtBytes=$(stat -c %s "$mt")
read -r bw bu bs br < "$work/build.time"
written=$(cat "$work/build.io" 2>/dev/null || echo 0)
python3 - "$work/stats.json" "$bw" "$bu" "$bs" "$br" "$memory" "$threads" "$plyBytes" "$(( start - low ))" "$mtBytes" "$written" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
wall, user, sys_, rss = float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5]) * 1024
ply, dfPeak, mt, written = int(sys.argv[8]), int(sys.argv[9]), int(sys.argv[10]), int(sys.argv[11])
tris = d["input_triangles"]
loop = sum(l["seconds"] for l in d["levels"])
print(f"build: {tris} input triangles, --memory {sys.argv[6]}, {sys.argv[7]} threads")
print(f"  end to end        {wall:8.1f} s wall   {tris / wall / 1e6:6.3f} M input tri/s (ingest {d['ingest_seconds']:.1f} s, "
      f"levels {loop:.1f} s = {tris / max(loop, 1e-9) / 1e6:.2f} M tri/s)")
print(f"  cpu               {user + sys_:8.1f} s (user {user:.1f} + sys {sys_:.1f}: sys {100 * sys_ / max(user + sys_, 1e-9):.1f}%)")
print(f"  peak RSS          {rss / 2**20:8.1f} MiB (cap {sys.argv[6]})")
print(f"  temp disk peak    {d['peak_temp_bytes'] / 2**30:8.2f} GiB = {d['peak_temp_bytes'] / ply:.2f}x the PLY (mtbuild); "
      f"file system high-water {dfPeak / 2**30:.2f} GiB incl. the MT file")
print(f"  bytes written     {written / 2**30:8.2f} GiB = {written / ply:.2f}x the PLY (/proc io, sampled each second)")
print(f"  file              {mt} bytes = {mt / tris:.3f} bytes/input triangle, {d['nodes']} nodes, {d['patches']} patches, "
      f"{len(d['levels'])} levels")
EOF

# ---- 2b. the same build at another memory cap: the same bytes?
if [[ -n "$again" ]]; then
  loadavg "build at --memory $again"
  mt2="$work/scan.$again.mt"; rm -f "$mt2"
  if /usr/bin/time -f "%e %U %S %M" -o "$work/build2.time" "$bin/mtbuild" "$ply" -o "$mt2" --memory "$again" --threads "$threads" \
       --level-ratio "$ratio" --stats-json "$work/stats2.json" -q > "$work/build2.log" 2>&1; then
    read -r aw au as ar < "$work/build2.time"
    h1=$(sha256sum "$mt" | cut -c1-16); h2=$(sha256sum "$mt2" | cut -c1-16)
    [[ "$h1" == "$h2" ]] && same="the same bytes" || same="DIFFERENT bytes"
    echo "build at --memory $again: $aw s wall ($(awk -v n="$count" -v w="$aw" 'BEGIN{printf "%.3f", n/w/1e6}') M input tri/s), $(awk -v u="$au" -v s="$as" 'BEGIN{printf "%.1f s cpu (sys %.1f%%)", u+s, 100*s/(u+s)}'), peak RSS $(( ar / 1024 )) MiB, temp disk peak $(python3 -c "import json,sys; print('%.2f GiB' % (json.load(open(sys.argv[1]))['peak_temp_bytes'] / 2**30))" "$work/stats2.json"); sha256 $h1... ($memory) vs $h2... ($again): $same"
  else
    echo "build at --memory $again: FAILED ($(tail -1 "$work/build2.log"))"
  fi
  rm -f "$mt2"
fi

# ---- 3. verify
loadavg "verify"
/usr/bin/time -f "%e %U %S %M" -o "$work/verify.time" "$bin/mtverify" "$mt" --cuts 4 --memory 1G -q > "$work/verify.log" 2>&1 \
  && verdict=OK || verdict="FAILED ($(tail -1 "$work/verify.log"))"
read -r vw vu vs vr < "$work/verify.time"
echo "verify: $verdict, $vw s wall, $(awk -v u="$vu" -v s="$vs" 'BEGIN{print u+s}') s cpu, peak RSS $(( vr / 1024 )) MiB (--memory 1G)"

# ---- 4. info
"$bin/mtinfo" "$mt" | sed 's/^/info: /'

# ---- 5. the finest cut
loadavg "extract"
(( keepInput )) || rm -f "$ply" "$work/scan.count"
/usr/bin/time -f "%e %U %S %M" -o "$work/extract.time" "$bin/mtextract" "$mt" --error 0 --memory 1G -o "$cut" > "$work/extract.log" 2>&1 \
  || { cat "$work/extract.log" >&2; exit 1; }
read -r xw xu xs xr < "$work/extract.time"
echo "extract (finest cut, --memory 1G): $xw s wall, peak RSS $(( xr / 1024 )) MiB, $(stat -c %s "$cut") bytes; $(sed 's/^mtextract: //' "$work/extract.log" | tail -1)"
rm -f "$cut"

# ---- 6. headless flythrough
if (( render )); then
  loadavg "render"
  if [[ -x "$bin/mtrender" ]]; then
    /usr/bin/time -f "%M" -o "$work/render.rss" "$bin/mtrender" "$mt" --headless --quiet --camera-path flythrough --frames "$frames" \
      --budget-ms 50 --cache 256M --cold --stats "$work/frames.csv" > "$work/render.out" 2> "$work/render.err" \
      && awk -v r="$(cat "$work/render.rss")" '
        $1 == "within_budget_pct" { w = $2 } $1 == "extract_ms_median" { e = $2 } $1 == "first_frame_ms" { f = $2 }
        $1 == "frame_ms_median" { m = $2 } $1 == "frame_ms_max" { x = $2 }
        END { printf "render (flythrough, 50 ms budget): %s%% frames within budget, frame median %s ms, max %s ms, extract median %s ms, first frame %s ms (cold), peak RSS %d MiB\n", w, m, x, e, f, r / 1024 }' "$work/render.out" \
      || echo "render: failed ($(tail -1 "$work/render.err"))"
  else
    echo "render: $bin/mtrender not built"
  fi
fi
(( keep )) || rm -f "$mt"
