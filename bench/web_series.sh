#!/usr/bin/env bash
# The web viewer's figures as a series: bench/web.sh RUNS times on each FILE, the files alternated
# (A B C A B C ...: a host whose load drifts weighs on every file alike), then one table per file
# with each figure's runs and how many met the web viewer's targets (docs/web.md): the first image
# within 1 s of the page's load event, at least 95% of the path's frames within the budget, the
# cache never above its cap, and the screen error at the tolerance within 2 s of the camera
# stopping. Each run's full output is kept in OUT (default out/web-series/) as I.K.log: the
# I-th file given (from 0), its K-th run.
#   bench/web_series.sh [--runs 5] [--out DIR] FILE.mt... [-- bench/web.sh options]
# Exit status 1 when a run failed (its log names why); the targets missed are only counted.
set -euo pipefail
cd "$(dirname "$0")/.."
runs=5 out=out/web-series files=() extra=()
while [[ $# -gt 0 ]]; do
  case $1 in
    --runs) runs=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "web_series.sh: unknown option $1 (--runs N, --out DIR, FILE.mt..., -- bench/web.sh options)" >&2; exit 2 ;;
    *) files+=("$1"); shift ;;
  esac
done
[[ ${#files[@]} -gt 0 ]] || { echo "web_series.sh: no FILE.mt given (bench/web_series.sh --help)" >&2; exit 2; }
[[ $runs =~ ^[1-9][0-9]*$ ]] || { echo "web_series.sh: --runs must be a positive count, not '$runs'" >&2; exit 2; }
for f in "${files[@]}"; do [[ -f $f ]] || { echo "web_series.sh: $f: no such file" >&2; exit 2; }; done
mkdir -p "$out"
failed=0
for ((k = 1; k <= runs; ++k)); do
  for i in "${!files[@]}"; do
    log="$out/$i.$k.log"  # file i of the command line, run k
    echo "web_series.sh: run $k of $runs, ${files[$i]}" >&2
    bench/web.sh "${files[$i]}" "${extra[@]}" >"$log" 2>&1 || { echo "web_series.sh: run $k of ${files[$i]} failed: $(tail -1 "$log")" >&2; failed=1; }
  done
done
python3 - "$out" "$runs" "${files[@]}" <<'PY'
import os, re, sys
out, runs, files = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
pat = {
    'load': (r'^load average: ([\d.]+)', float),
    'first': (r'^first image .* (\d+) ms after the load event', int),
    'frames': (r'^frames within .*?([\d.]+)% of', float),
    'cache': (r'^cache +max ([\d.]+) MiB of a ([\d.]+) MiB cap', None),
    'fetched': (r'^bytes fetched .*\(([\d.]+) KiB/frame\), ([\d.]+) MiB in all = ([\d.]+)%', None),
    'loaded': (r'nothing loading ([\d.]+|never)', None),
    'tol': (r'^screen error after stop +(?:reached [\d.]+ px (\d+) ms|not at)', None),
}
for i, f in enumerate(files):
    rows = []
    for k in range(1, runs + 1):
        log = os.path.join(out, f'{i}.{k}.log')
        r = {}
        for line in open(log):
            for key, (rx, conv) in pat.items():
                m = re.search(rx, line)
                if m and key not in r:
                    r[key] = m.groups() if conv is None else conv(m.group(1))
        rows.append(r)
    ok = [r for r in rows if 'tol' in r]
    print(f'{f}: {len(ok)} of {runs} runs completed')
    if not ok:
        continue
    def line(label, cells, verdict=''):
        print(f'  {label:<29}{" / ".join(cells)}' + (f'  ({verdict})' if verdict else ''))
    n = len(ok)
    line('load average at start', [str(r['load']) for r in ok])
    first = [r['first'] for r in ok]
    line('first image after load event', [f'{x} ms' for x in first], f'{sum(x <= 1000 for x in first)} of {n} within 1 s')
    frames = [r['frames'] for r in ok]
    line('frames within the budget', [f'{x}%' for x in frames], f'{sum(x >= 95 for x in frames)} of {n} at 95% or more')
    cache = [r['cache'] for r in ok]
    line('cache max / cap (MiB)', [f'{m}/{c}' for m, c in cache], f'{sum(float(m) <= float(c) for m, c in cache)} of {n} never above')
    line('fetched (KiB/frame, MiB, %)', [f'{a}, {b}, {c}%' for a, b, c in (r['fetched'] for r in ok)])
    line('stop to loaded at the tol.', [r['loaded'][0] + ('' if r['loaded'][0] == 'never' else ' s') for r in ok])
    tol = [r['tol'][0] for r in ok]
    line('tolerance after the stop', [f'{int(t) / 1000:.2f} s' if t else 'not in 20 s' for t in tol],
         f'{sum(1 for t in tol if t and int(t) <= 2000)} of {n} within 2 s')
PY
exit $failed
