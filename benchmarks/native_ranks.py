"""The native fix's speed-up of two MPI ranks over one, from blocks timed in pairs.

    python benchmarks/native_ranks.py                          # N = 1e6, moving and active
    python benchmarks/native_ranks.py --temperatures 2 --rounds 6

The chains of ``benchmarks/active_chains.py`` (micro-star's physics with ``chain.n = N``,
struck at bead 1; moving at T = 1e-6, active at T = 2, ``thermal.seed = 1``) on
``lammps`` with ``contact=native, events=located``.  One process of two MPI ranks
(``mpiexec -n 2``) holds the same chain twice: once on both ranks (``MPI_COMM_WORLD``) and
once on rank 0 alone (``MPI_COMM_SELF``).  Both are stepped to t = 2 (``--warm-up-time``,
not timed); then their blocks of ``--block-time`` (100 steps at dt = 0.0025) alternate, the
two-rank chain's first in even pairs and the one-rank chain's in odd ones, over the same
stretch of history as active_chains.py (t = 2 to 8).  While rank 0 steps the one-rank chain,
rank 1 waits in a barrier that sleeps (it polls every millisecond), so that the one-rank
block has a core to itself.  A pair's two blocks run within seconds of each other, so a slow
spell of the machine (this one has them: a CPU loop on its own reads up to 1.5x slower for
seconds to minutes) mostly falls on both, where two points measured minutes apart, as in
active_chains.py, take whatever state each found.

Before each pair both ranks time the same CPU loop at once (``--probe``: about 2 ms of
Python): the ratio of rank 1's time to rank 0's, a rough reading of whether one core was
slower than the other then (a two-rank block waits for the slower).  Measured: medians near
1.0, single pairs up to 1.8, not following the pairs' speed-ups (too short a loop to say
more; reported, not used).

Reported per (N, T): the median of the pairs' ratios (one-rank wall time of LAMMPS's ``run``
over two-rank), with its distribution-free 95 % interval, quartiles, min and max and each
round's median; each chain's median ns per bead-step; the cores' probe ratios; the load
averages before and after each round.  Each round is a process of its own (``--rounds``).
Target (issue: long chains): two ranks at least 1.8x one rank at N = 1e6, active.
Writes benchmarks/results/native_ranks.json (``--out``).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from active_chains import ACTIVE, DT, QUIET, native_chain, run_worker  # noqa: E402
from active_chains import timed_run as timed  # noqa: E402
from active_paired import spread  # noqa: E402

OUT = HERE / "results" / "native_ranks.json"


# ---- the worker: both ranks of one mpiexec -n 2 process ------------------------------------
def sleeping_barrier(comm):
    """A barrier whose waiting rank sleeps (MPICH's own barrier spins, taking a core)."""
    request = comm.Ibarrier()
    while not request.Test():
        time.sleep(0.001)


def probe(seconds_hint):
    """Wall time of a fixed CPU loop (integer arithmetic, in cache): a core's speed now."""
    count = max(1, int(seconds_hint * 2e7))
    t0 = time.perf_counter()
    acc = 0
    for i in range(count // 20):
        acc += i * i % 7
    return time.perf_counter() - t0


def timed_run(b, steps):
    """Wall seconds of LAMMPS's run of ``steps`` steps (:func:`active_chains.timed_run`)."""
    return timed(b, steps)[0]


def paired_worker(n, temperature, steps, pairs, warm_up, probe_s):
    """Rank 0: the times of each pair's two blocks and the cores' probe ratios."""
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    rank = world.Get_rank()
    blocks = pairs + warm_up + 1
    two = native_chain(n, temperature, steps, blocks, world)
    one = native_chain(n, temperature, steps, blocks, MPI.COMM_SELF) if rank == 0 else None
    for _ in range(warm_up):
        timed_run(two, steps)
        if one is not None:
            timed_run(one, steps)
        sleeping_barrier(world)
    times = {"one": [], "two": []}
    probes = []
    for k in range(pairs):
        world.Barrier()
        p = world.gather(probe(probe_s), root=0)
        if rank == 0:
            probes.append(p[1] / p[0])
        for which in (("two", "one") if k % 2 == 0 else ("one", "two")):
            world.Barrier()
            if which == "two":
                times["two"].append(timed_run(two, steps))
            elif one is not None:
                times["one"].append(timed_run(one, steps))
            sleeping_barrier(world)
    for b in (two, one):
        if b is not None:
            if getattr(b, "_error", None) is not None:
                raise b._error
            b.lmp.close()
    return {"rank": rank, "wall_s": times, "core_probe_ratio": probes}


def worker(args):
    report = paired_worker(args.worker, args.temperature, args.steps, args.repeats,
                           args.warm_up, args.probe)
    if report["rank"] == 0:
        Path(args.report_dir, "rank-0.json").write_text(json.dumps(report))


# ---- the driver -----------------------------------------------------------------------------
def measure(n, temperature, pairs, block_time, warm_up_time, probe_s, timeout):
    """One round, a process of two ranks: each pair's one-rank / two-rank ratio."""
    steps = int(round(block_time / DT))
    warm_up = max(1, int(round(warm_up_time / block_time)))
    before = os.getloadavg()
    reports = run_worker(n, "native-2", ["--temperature", str(temperature), "--steps",
                                         str(steps), "--repeats", str(pairs), "--warm-up",
                                         str(warm_up), "--probe", str(probe_s)],
                         timeout, script=__file__, reports=1)
    if isinstance(reports, str):
        return {"error": reports}
    w = reports[0]["wall_s"]
    bead_steps = n * steps
    return {"ratio": [a / b for a, b in zip(w["one"], w["two"])],
            "ns_one": [1e9 * t / bead_steps for t in w["one"]],
            "ns_two": [1e9 * t / bead_steps for t in w["two"]],
            "core_probe_ratio": reports[0]["core_probe_ratio"], "steps_per_block": steps,
            "loadavg_before": before, "loadavg_after": os.getloadavg()}


def pooled(n, temperature, rounds) -> dict:
    """One (N, T) row from its rounds (a failed round: the row is its error)."""
    row = {"n": n, "temperature": temperature}
    bad = [r for r in rounds if "error" in r]
    if bad:
        return {**row, "error": bad[0]["error"]}
    every = {key: [x for r in rounds for x in r[key]]
             for key in ("ratio", "ns_one", "ns_two", "core_probe_ratio")}
    return {**row, "two_over_one_speed": spread(every["ratio"]),
            "round_median_ratio": [float(np.median(r["ratio"])) for r in rounds],
            "ns_per_bead_step_one_rank_median": float(np.median(every["ns_one"])),
            "ns_per_bead_step_two_ranks_median": float(np.median(every["ns_two"])),
            "core_probe_ratio": spread(every["core_probe_ratio"]),
            "steps_per_block": rounds[0]["steps_per_block"],
            "loadavg": [[r["loadavg_before"], r["loadavg_after"]] for r in rounds]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e6")
    ap.add_argument("--temperatures", type=float, nargs="+", default=[QUIET, ACTIVE])
    ap.add_argument("--repeats", type=int, default=24, help="pairs of blocks per round")
    ap.add_argument("--rounds", type=int, default=4, help="processes per (N, T)")
    ap.add_argument("--block-time", type=float, default=0.25,
                    help="time units per block (100 steps at dt = 0.0025)")
    ap.add_argument("--warm-up-time", type=float, default=2.0,
                    help="time units stepped before the first timed block")
    ap.add_argument("--probe", type=float, default=0.02,
                    help="seconds of the cores' CPU loop before each pair")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per round")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--temperature", type=float, default=ACTIVE, help=argparse.SUPPRESS)
    ap.add_argument("--steps", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--backend", default="native-2", help=argparse.SUPPRESS)
    ap.add_argument("--warm-up", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--report-dir", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        return worker(args)
    points = [(int(float(s)), t) for s in args.sizes.split(",") for t in args.temperatures]
    measured = {p: [] for p in points}
    for turn in range(args.rounds):
        for n, t in points if turn % 2 == 0 else points[::-1]:
            r = measure(n, t, args.repeats, args.block_time, args.warm_up_time, args.probe,
                        args.timeout)
            measured[n, t].append(r)
            print(json.dumps({"n": n, "temperature": t,
                              **{k: v for k, v in r.items() if not k.startswith("loadavg")}}),
                  flush=True)
    result = {"benchmark": __doc__.splitlines()[0], "dt": DT,
              "block_time": args.block_time, "warm_up_time": args.warm_up_time,
              "cores": os.cpu_count(),
              "rows": [pooled(n, t, measured[n, t]) for n, t in points]}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
