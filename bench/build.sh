#!/usr/bin/env bash
# End-to-end build benchmark: runs mtbuild on a mesh (or a patch store made
# by `mtstore ingest`, to time the level loop alone) and prints throughput in M input triangles/s
# (end to end and for the level loop), CPU time (user+sys: the honest figure on a shared machine),
# peak RSS against the cap, bytes per input triangle, the CPU of the ingest, and one line per level with its
# CPU (user, sys); then mtverify.
#   bench/build.sh INPUT [MEMORY=512M] [THREADS=2] [WORKDIR=out/bench-build] [-- extra mtbuild options]
# INPUT defaults to a generated 53M-triangle mtgen scan with holes (WORKDIR/scan-53M.ply).
# BIN=dir/bin picks the build dir; MTBUILD=path/to/mtbuild compares another binary (e.g. a baseline build dir) on the same input.
set -euo pipefail
cd "$(dirname "$0")/.."
input="${1:-}"; memory="${2:-512M}"; threads="${3:-2}"; work="${4:-out/bench-build}"
shift $(( $# < 4 ? $# : 4 )) || true
[[ "${1:-}" == "--" ]] && shift
bin="${BIN:-build/bin}"  # BIN=build-NAME/bin for another build dir
mtbuild="${MTBUILD:-$bin/mtbuild}"
mkdir -p "$work"
if [[ -z "$input" ]]; then
  input="$work/scan-53M.ply"
  [[ -f "$input" ]] || "$bin/mtgen" -o "$input" --triangles 53M --holes 100 --seed 7
fi
out="$work/out.mt"
/usr/bin/time -f "%e %U %S %M" -o "$work/time.txt" "$mtbuild" "$input" -o "$out" --memory "$memory" \
  --threads "$threads" --stats-json "$work/stats.json" -q "$@"
read -r wall user sys rssKb < "$work/time.txt"
python3 - "$work/stats.json" "$wall" "$user" "$sys" "$rssKb" "$memory" "$threads" "$mtbuild" "$input" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
wall, user, sys_, rss = float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5]) * 1024
tris = d["input_triangles"]
loop = sum(l["seconds"] for l in d["levels"])
print(f"binary {sys.argv[8]}  input {sys.argv[9]}  memory cap {sys.argv[6]}  threads {sys.argv[7]}")
print(f"input {tris} triangles -> {d['stored_triangles']} stored in {d['patches']} patches, {d['nodes']} nodes")
print(f"end to end  {wall:7.1f} s wall  {tris / wall / 1e6:5.2f} M input tri/s   "
      f"(ingest {d['ingest_seconds']:.1f} s, levels {loop:.1f} s = {tris / max(loop, 1e-9) / 1e6:.2f} M input tri/s)")
print(f"cpu         {user + sys_:7.1f} s (user {user:.1f} + sys {sys_:.1f})  {tris / (user + sys_) / 1e6:5.2f} M input tri per cpu-s")
print(f"peak RSS    {rss / 2**20:7.1f} MiB (cap {sys.argv[6]})")
print(f"file        {d['file_bytes']} bytes = {d['bytes_per_input_triangle']:.3f} bytes/input triangle "
      f"({d['file_bytes'] / max(d['stored_triangles'], 1):.3f} per stored), grid step {d['grid_step']:.4g}")
# Where the CPU went (the build's own accounting, --stats-json): the ingest, each level, and the
# rest of the run (the grid weld, the sink, the file's index).
total_cpu = d["cpu_user_seconds"] + d["cpu_sys_seconds"]
ingest_cpu = d["ingest_user_seconds"] + d["ingest_sys_seconds"]
levels_cpu = sum(l["user_seconds"] + l["sys_seconds"] for l in d["levels"])
def share(user, sys_):
    return f"{user + sys_:7.1f} s cpu (user {user:.1f} + sys {sys_:.1f}, sys {100 * sys_ / max(user + sys_, 1e-9):4.1f}%)"
print(f"ingest      {share(d['ingest_user_seconds'], d['ingest_sys_seconds'])}  {100 * ingest_cpu / max(total_cpu, 1e-9):4.1f}% of the run's")
print(f"levels      {levels_cpu:7.1f} s cpu  {100 * levels_cpu / max(total_cpu, 1e-9):4.1f}% of the run's; "
      f"other (grid weld, sink, file) {total_cpu - ingest_cpu - levels_cpu:.1f} s")
print("level  regions  triangles in -> out       max error   seconds   M tri/s   cpu s  user s   sys s  sys %  runs/region")
for l in d["levels"]:
    cpu = l["user_seconds"] + l["sys_seconds"]
    print(f"{l['level']:5d}  {l['regions']:7d}  {l['triangles_in']:12d} -> {l['triangles_out']:10d}  "
          f"{l['max_error']:10.4g}  {l['seconds']:8.2f}  {l['triangles_in'] / max(l['seconds'], 1e-9) / 1e6:8.2f}  "
          f"{cpu:6.1f}  {l['user_seconds']:6.1f}  {l['sys_seconds']:6.1f}  {100 * l['sys_seconds'] / max(cpu, 1e-9):5.1f}  "
          f"{l.get('simplifier_runs', 0) / max(l['regions'], 1):11.2f}")
EOF
"$bin/mtverify" "$out" --cuts 4 | tail -1
