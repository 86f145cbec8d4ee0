#!/usr/bin/env bash
# File size on scan-derived meshes against mtgen meshes (meshopt codec): builds each mesh, then
# prints bytes per input triangle, where the payload bytes go (index code / positions / headers,
# bench_mt_payload), single-thread decode speed, the finest level's error, and mtverify's verdict.
#   bench/size_scan.sh [WORKDIR=/tmp/size_scan] [MESH.ply ...]
# Without meshes: the scan-derived meshes in /work/data (arm0.8M, bunny1.2M, dragon0.3M,
# arm3.3M; made with ../shared/tools/scangen) and two mtgen meshes of similar sizes, generated in
# WORKDIR. BIN=dir/bin picks the build; CUTS=K for mtverify (default 8, 0 skips it); MTBUILD_ARGS adds
# mtbuild options (e.g. "--simplifier quadric").
# Meshes and .mt files stay in WORKDIR (outside the repository): delete them when done.
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${BIN:-build/bin}"
work="${1:-/tmp/size_scan}"
shift $(( $# > 0 ? 1 : 0 )) || true
cuts="${CUTS:-8}"
mkdir -p "$work"
meshes=("$@")
if [[ ${#meshes[@]} -eq 0 ]]; then
  for m in dragon0.3M arm0.8M bunny1.2M arm3.3M; do
    [[ -f /work/data/$m.ply ]] && meshes+=("/work/data/$m.ply")
  done
  for t in 1M 3.3M; do
    [[ -f "$work/mtgen$t.ply" ]] || "$bin/mtgen" -o "$work/mtgen$t.ply" --triangles "$t" --holes 10 --seed 7 >/dev/null
    meshes+=("$work/mtgen$t.ply")
  done
fi
printf "%-14s %9s %7s %7s %7s %7s %7s %9s %9s %11s %s\n" mesh triangles "B/tri" index pos header meta \
  "dec MB/s" "dec Mt/s" "L0 error" verify
for mesh in "${meshes[@]}"; do
  name=$(basename "$mesh" .ply)
  out="$work/$name.mt"
  # shellcheck disable=SC2086
  "$bin/mtbuild" "$mesh" -o "$out" --threads 2 -q ${MTBUILD_ARGS:-}
  j=$("$bin/bench_mt_payload" "$out" --repeat 3 --json)
  err=$("$bin/mtinfo" "$out" --json | python3 -c 'import json,sys; d=json.load(sys.stdin); print(d["perLevel"][0]["errorMax"])' 2>/dev/null || echo "?")
  verdict="skipped"
  if [[ "$cuts" != 0 ]]; then
    if "$bin/mtverify" "$out" --cuts "$cuts" >"$work/$name.verify" 2>&1; then verdict=OK; else verdict="FAIL ($work/$name.verify)"; fi
  fi
  python3 - "$name" "$j" "$err" "$verdict" <<'PY'
import json, sys
name, d, err, verdict = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3], sys.argv[4]
print(f"{name:14s} {d['input_triangles']:9d} {d['bpt']:7.3f} {d['index']:7.3f} {d['position']:7.3f} "
      f"{d['header']:7.3f} {d['meta'] + d['pad']:7.3f} {d['decode_mb_s']:9.1f} {d['decode_mtri_s']:9.2f} {err:>11s} {verdict}")
PY
done
echo "(B/tri, index (the triangles' code), pos, header, meta+pad: bytes per input triangle; decode: one thread, payloads in memory, best of 3)"
