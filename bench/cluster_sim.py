#!/usr/bin/env python3
"""Scaling model for mtcluster (issue 6, docs/cluster.md): replays per-region task times measured
by `mtbuild --task-times` (or mtcluster's) on a scan scaled to TARGET triangles, on N machines.

Model (what cluster/cluster_build.cpp does):
  * ingest + planning run on rank 0 alone (measured seconds per input triangle, scaled linearly);
  * per level, rank 0 has two serial servers: a dispatch thread that loads + assembles a floor
    and sends it over its NIC, and receives results; a commit thread that commits them in region
    order (--no-overlap: one thread does both, the first version); at most `window` = 2N+2
    regions ahead of the commit point; the level ends with a sync;
  * each worker processes one region at a time (process_s measured), regions handed out to
    whichever worker is idle first (a work queue);
  * rank 0 also works when N <= 4 (ignored here: N >= 8);
  * rank 0's NIC carries task_bytes out and result_bytes in at BANDWIDTH bytes/s (workers' own
    links are not the bottleneck: each carries 1/N of it).
Scaling a 10 M-triangle run to 1 B: V-partition regions keep about the same size at every level
(each level halves the triangles and the number of regions, BMT 4.2), so level l of the big scan
has (TARGET / measured) times the regions of level l, each drawn from the measured regions of that
level (or the finest levels when the measured run has no such level), until one region remains;
the top regions then grow (one root region of whatever is left), costed per triangle.

  bench/cluster_sim.py TASKS.csv --stats STATS.json [--target 1e9] [--machines 8,32,64]
                       [--bandwidth 117e6] [--cores 1]
"""
import argparse, csv, heapq, json, math, random, sys
from collections import defaultdict


def load(path):
    levels = defaultdict(list)
    with open(path) as f:
        for row in csv.DictReader(f):
            levels[int(row["level"])].append({k: float(v) for k, v in row.items()})
    return levels


def simulate_level(tasks, workers, bandwidth, window, overlap=True):
    """Event simulation of one level. Returns (seconds, rank0_busy, worker_busy).

    Rank 0 has a dispatch thread (load + send + receive, one at a time) and, with `overlap`, a
    commit thread (commits in region order) - cluster_build.cpp's Committer; without it, one
    thread does both (the first version)."""
    n = len(tasks)
    t = 0.0                       # the dispatch thread's clock
    c = 0.0                       # the commit thread's clock (== t without overlap)
    free = [(0.0, w) for w in range(workers)]   # (time the worker is idle, worker)
    heapq.heapify(free)
    back = {}                     # region -> time its result has been received by rank 0
    done_at = []                  # commit finish times, in order
    nxt = 0
    rank0 = 0.0
    busy = 0.0
    pending = []                  # (result arrival, region) not yet received
    fin = 0                       # commits finished by the dispatch thread's time (done_at is sorted)
    while len(done_at) < n:
        committed = len(done_at)
        # The commit thread: next region in order, once received.
        if committed in back and (overlap or back[committed] <= t):
            r = tasks[committed]
            start = max(c if overlap else t, back[committed])
            dt = r["commit_s"]
            if overlap:
                c = start + dt
            else:
                t = start + dt
            rank0 += dt
            done_at.append(c if overlap else t)
            continue
        # Window: how many commits have finished by the dispatch thread's time.
        while fin < len(done_at) and done_at[fin] <= t:
            fin += 1
        finished = fin if overlap else committed
        if nxt < n and nxt < finished + window and free[0][0] <= t:
            idle_at, w = heapq.heappop(free)
            r = tasks[nxt]
            dt = r["load_s"] + r["task_bytes"] / bandwidth
            t += dt
            rank0 += dt
            finish = t + r["process_s"]
            busy += r["process_s"]
            heapq.heappush(pending, (finish, nxt))
            heapq.heappush(free, (finish, w))
            nxt += 1
            continue
        # Receive the earliest result (the dispatch thread's time moves to its arrival).
        if pending:  # (dispatch was not possible now)
            arrive, i = heapq.heappop(pending)
            t = max(t, arrive) + tasks[i]["result_bytes"] / bandwidth
            rank0 += tasks[i]["result_bytes"] / bandwidth
            back[i] = t
            continue
        # Waiting for a commit to open the window, or for a worker.
        t = done_at[fin] if fin < len(done_at) else max(t, free[0][0])
    return max(t, c, done_at[-1]), rank0, busy


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tasks")
    ap.add_argument("--stats", required=True, help="--stats-json of the measured run (ingest time, levels)")
    ap.add_argument("--target", type=float, default=1e9)
    ap.add_argument("--machines", default="8,32,64")
    ap.add_argument("--bandwidth", type=float, default=117e6, help="rank 0's NIC, bytes/s (117e6: 1 GbE)")
    ap.add_argument("--cores", type=int, default=1, help="worker ranks per machine (the measured times are 1 core)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-overlap", action="store_true", help="rank 0 loads, sends and commits on one thread")
    ap.add_argument("--ingest-seconds", type=float, default=None,
                    help="ingest seconds of the measured scan (default: from --stats; override with a quieter run)")
    args = ap.parse_args()
    levels = load(args.tasks)
    stats = json.load(open(args.stats))
    measured = stats["input_triangles"]
    scale = args.target / measured
    ingest_per_tri = (args.ingest_seconds if args.ingest_seconds is not None else stats["ingest_seconds"]) / measured
    finest = [r for l in sorted(levels)[:2] for r in levels[l]]
    per_tri = sum(r["process_s"] for r in finest) / sum(r["triangles_in"] for r in finest)
    load_per_tri = sum(r["load_s"] + r["commit_s"] for r in finest) / sum(r["triangles_in"] for r in finest)
    bytes_per_tri = sum(r["task_bytes"] + r["result_bytes"] for r in finest) / sum(r["triangles_in"] for r in finest)
    rng = random.Random(args.seed)

    # The big scan's levels: region counts scaled, costs drawn from the measured level.
    plan = []
    tri = args.target
    l = 1
    root_tri = 2000
    while tri > root_tri:
        src = levels.get(l) or levels[max(levels)]
        count = len(src) * scale if l in levels else len(levels[max(levels)]) * scale / 2 ** (l - max(levels))
        count = max(1, int(round(count)))
        if count > 1 and l in levels and len(src) >= 4:
            tasks = [rng.choice(src) for _ in range(count)]
        else:  # few, big regions at the top: cost per triangle
            each = tri / count
            tasks = [{"process_s": each * per_tri, "load_s": each * load_per_tri * 0.5, "commit_s": each * load_per_tri * 0.5,
                      "task_bytes": each * bytes_per_tri * 0.6, "result_bytes": each * bytes_per_tri * 0.4,
                      "triangles_in": each}] * count
        plan.append((l, tasks))
        tri = sum(t["triangles_in"] for t in tasks) / 2
        l += 1
        if count == 1 and tri <= root_tri:
            break

    ingest = ingest_per_tri * args.target
    serial_work = sum(t["process_s"] + t["load_s"] + t["commit_s"] for _, ts in plan for t in ts)
    print(f"# measured: {measured} triangles, ingest {ingest_per_tri * measured:.1f} s; scaled x{scale:.0f} to {args.target:.3g}")
    print(f"# one machine, one core: ingest {ingest:.0f} s + levels {serial_work:.0f} s = {ingest + serial_work:.0f} s")
    print("# per level (64 machines): regions, rank-0 seconds, worker seconds, level seconds, network MB")
    results = {}
    for machines in [int(m) for m in args.machines.split(",")]:
        workers = machines * args.cores - 1 if args.cores > 1 else machines - 1
        total = ingest
        rows = []
        for l, tasks in plan:
            secs, rank0, busy = simulate_level(tasks, max(1, workers), args.bandwidth, 2 * (workers + 1) + 2, not args.no_overlap)
            net = sum(t["task_bytes"] + t["result_bytes"] for t in tasks)
            rows.append((l, len(tasks), rank0, busy, secs, net, max(t["process_s"] for t in tasks)))
            total += secs
        results[machines] = (total, rows)
        levels_time = total - ingest
        print(f"machines {machines:3d}: total {total:7.0f} s = ingest {ingest:.0f} s + levels {levels_time:.0f} s; "
              f"speedup vs 1 core {(ingest + serial_work) / total:5.1f}x, levels alone {serial_work / levels_time:5.1f}x "
              f"(efficiency {serial_work / levels_time / machines:.0%} of {machines} machines)")
    total, rows = results[max(results)]
    for l, n, rank0, busy, secs, net, longest in rows:
        print(f"  level {l:2d}: {n:7d} regions  rank0 {rank0:7.1f} s  workers {busy:8.1f} s  level {secs:7.1f} s  "
              f"longest region {longest:6.2f} s  network {net / 1e6:8.0f} MB")


if __name__ == "__main__":
    sys.exit(main())
