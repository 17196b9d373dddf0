"""The fast backend's active / moving ratio from blocks timed in pairs, one process per round.

    python benchmarks/active_paired.py                                # 1e5 and 1e6, 1 and 2 threads
    python benchmarks/active_paired.py --sizes 1e6 --threads 1 --rounds 6

The same chains as ``benchmarks/active_chains.py`` (micro-star's physics with ``chain.n = N``,
struck at bead 1; the moving chain at T = 1e-6, the active one at T = 2, ``thermal.seed = 1``,
by default the same stretch of their history, t = 2 to 8, after 2 time units of warm-up), but
both chains live in one process and their blocks alternate: ``--repeats`` pairs of blocks of
``--block-time`` (100 steps at dt = 0.0025 by default), the moving chain's first in even pairs
and the active chain's first in odd ones. A pair's two blocks run within two seconds of each
other (at 1e6 beads), so a slow spell of the machine (this one has them, lasting seconds to
minutes, up to 1.5x) mostly falls on both: the ratio of a pair is far steadier than the ratio
of two medians taken minutes apart, and the shorter the blocks, the fewer pairs a spell's start
or end cuts. Each round is a process of its own (``--rounds``).

A pair's ratios, active over moving: of the compiled loop's wall time (``loop``,
``stats["kernel_s"]``, as active_chains.py reports), and of the wall and the CPU time of the
whole ``next()`` of the block iterator (``wall``, ``cpu``: the loop plus Python's handling of
the block, its events included; the CPU of both threads on two).  On one thread the process
is pinned to one core, so that the backend steps each block in line (it would otherwise step
the next block on a second core while the other chain's block is timed).  Reported per (N,
threads): the median of the pairs' ratios with their min, quartiles and max, each chain's
median ns per bead-step of the loop, the events per active block, and the load averages
before and after each round.
Target: the active chain within 1.3x of the moving one.  Writes
benchmarks/results/active_paired.json (``--out``).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from active_chains import ACTIVE, DT, QUIET, median_ci95, pair_blocks, run_worker  # noqa: E402

OUT = HERE / "results" / "active_paired.json"


def measure(n: int, threads: int, repeats: int, block_time: float, warm_up_time: float,
             timeout: float) -> dict:
    """One round: a worker process; its pairs' ratios and blocks (of ``block_time``, at least
    the backend's block, :func:`active_chains.pair_blocks`)."""
    steps, repeats, warm_up = pair_blocks(n, repeats, block_time, warm_up_time)
    before = os.getloadavg()
    reports = run_worker(n, f"fast-{threads}", ["--pair", "--steps", str(steps), "--repeats",
                                                str(repeats), "--warm-up", str(warm_up)],
                         timeout)
    if isinstance(reports, str):
        return {"error": reports}
    report = reports[0]
    q, a = str(QUIET), str(ACTIVE)
    bead_steps = n * steps

    def ratios(key):
        return [x / y for x, y in zip(report[key][a], report[key][q])]

    return {"loop_ratio": ratios("loop_s"), "wall_ratio": ratios("wall_s"),
            "cpu_ratio": ratios("cpu_s"),
            "ns_moving": [1e9 * w / bead_steps for w in report["loop_s"][q]],
            "ns_active": [1e9 * w / bead_steps for w in report["loop_s"][a]],
            "active_events_per_block": report["events"][a] / repeats,
            "steps_per_block": steps, "threads": report["threads"], "loadavg_before": before,
            "loadavg_after": os.getloadavg()}


def spread(values) -> dict:
    """Median (with its 95 % interval, :func:`active_chains.median_ci95`), min, quartiles and
    max of ``values``."""
    v = np.asarray(values, dtype=float)
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return {"median": float(med), "ci95": median_ci95(v)[1], "min": float(v.min()),
            "q1": float(q1), "q3": float(q3), "max": float(v.max()), "count": int(v.size)}


def pooled(n: int, threads: int, rounds: list) -> dict:
    """One (N, threads) row from its rounds (a failed round: the row is its error)."""
    bad = [r for r in rounds if "error" in r]
    if bad:
        return {"n": n, "threads": threads, "error": bad[0]["error"]}
    every = {key: [x for r in rounds for x in r[key]]
             for key in ("loop_ratio", "wall_ratio", "cpu_ratio", "ns_moving", "ns_active")}
    return {"n": n, "threads": threads, "pairs": len(every["loop_ratio"]),
            "active_over_moving_loop": spread(every["loop_ratio"]),
            "active_over_moving_wall": spread(every["wall_ratio"]),
            "active_over_moving_cpu": spread(every["cpu_ratio"]),
            "round_median_loop_ratio": [float(np.median(r["loop_ratio"])) for r in rounds],
            "ns_per_bead_step_moving_median": float(np.median(every["ns_moving"])),
            "ns_per_bead_step_active_median": float(np.median(every["ns_active"])),
            "active_events_per_block": rounds[0]["active_events_per_block"],
            "steps_per_block": rounds[0]["steps_per_block"],
            "loadavg": [[r["loadavg_before"], r["loadavg_after"]] for r in rounds]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e5,1e6")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=int, default=24, help="pairs of blocks per round")
    ap.add_argument("--rounds", type=int, default=4, help="processes per (N, threads)")
    ap.add_argument("--block-time", type=float, default=0.25,
                    help="time units per block (100 steps at dt = 0.0025)")
    ap.add_argument("--warm-up-time", type=float, default=2.0,
                    help="time units stepped before the first timed block")
    ap.add_argument("--timeout", type=float, default=1200.0, help="seconds per round")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    points = [(int(float(s)), th) for s in args.sizes.split(",") for th in args.threads]
    measured = {p: [] for p in points}
    for turn in range(args.rounds):
        for n, th in points if turn % 2 == 0 else points[::-1]:
            r = measure(n, th, args.repeats, args.block_time, args.warm_up_time, args.timeout)
            measured[n, th].append(r)
            print(json.dumps({"n": n, "threads": th, **{k: v for k, v in r.items()
                                                        if not k.startswith("loadavg")}}),
                  flush=True)
    result = {"benchmark": __doc__.splitlines()[0], "dt": DT,
              "steps_per_block": int(round(args.block_time / DT)),
              "warm_up_time": args.warm_up_time,
              "temperatures": {"moving": QUIET, "active": ACTIVE}, "cores": os.cpu_count(),
              "rows": [pooled(n, th, measured[n, th]) for n, th in points]}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
