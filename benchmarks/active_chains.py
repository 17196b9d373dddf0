"""Cost of contact events in long chains: ns per bead-step of a quiet and of an active chain.

    python benchmarks/active_chains.py                        # the matrix below
    python benchmarks/active_chains.py --sizes 1e3,1e4 --backends fast-1 --repeats 2

Each point is micro-star's physics with ``chain.n = N`` and ``thermal.temperature = T``
(``thermal.seed = 1``), struck at bead 1 (v0 = 12): at T = 0 the beads the pulse has not
reached are at rest (the fast backend steps only its activity front, so its ns per bead-step of
the whole chain fall with N); at T = 1e-6 every bead moves, slightly, and contacts switch only
where the pulse is (a quiet chain stepped whole); at T = 2 contacts snap shut and apart all
along the chain (about 0.08 events per bead per time unit). A point runs in a process of its
own (``mpiexec -n 2`` for two ranks): set-up and one warm-up block of steps are not timed, then
``--repeats`` blocks of the same number of steps are, each on its own, and the whole matrix is
measured ``--rounds`` times (every other time in reverse order), so that a slow spell of the
machine does not fall on one point only. A block is ``--block-time`` time units (800 steps by
default) whatever N, so that every chain is timed over the same part of its history (a thermal
chain's events are most frequent early: its damping takes its energy). Reported per point: the
median ns per bead-step of the stepping over the blocks of all rounds (wall time of the
compiled loop for ``fast``, of LAMMPS's ``run`` for ``native``) with its min and max and each
round's median, the process's CPU ns per bead-step over the timed blocks (all threads of the
process; rank 0's for ``native``), the events in the timed blocks, and the event windows
stepped (``fast``). ``os.getloadavg()`` before and after each point says whether the two cores
were idle.

A backend's moving (T = 1e-6) and active (T = 2) chains run as a pair, in one process (of
two ranks for native-2), their blocks alternating (:func:`paired_worker`; for native, two
LAMMPS instances, :func:`native_paired_worker`): blocks of ``--pair-time`` (100 steps by
default; at least the fast backend's 1e6 bead-steps, 1000 steps at N = 1e3) over the same
stretch of history as the other points (t = 2 to 8 by default), so that a pair's two blocks
run within seconds of each other and a slow spell of the machine (this one has them, up to
1.5x, lasting seconds to minutes) mostly falls on both. Their active-over-moving ratio is the
median of all pairs' ratios, with a distribution-free 95 % interval, quartiles and each
round's median. Two threads or ranks over one is the median of the rounds' ratios (within a
round the points of one N and backend run one after another; benchmarks/native_ranks.py
times two ranks over one in pairs).

Backends: ``fast-1`` and ``fast-2`` (the fast backend on 1 and 2 threads), ``native-1`` and
``native-2`` (``lammps`` with ``contact=native, events=located`` on 1 and 2 MPI ranks).
Targets: the active chain (T = 2) within 1.3x the quiet one stepped whole (T = 1e-6) at every
N; two ranks at least 1.8x one rank at N = 1e6, active. Writes
benchmarks/results/active_chains.json (``--out``); a run of some backends, sizes or
temperatures replaces their points' rows there and keeps the others'.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "results" / "active_chains.json"
DT = 0.0025
BACKENDS = ("fast-1", "fast-2", "native-1", "native-2")
QUIET, ACTIVE = 1e-6, 2.0  # temperatures of the quiet chain stepped whole and the active one


def scene_for(n: int, temperature: float, steps: int, blocks: int):
    from mdgran.model.scene import load_scene

    return load_scene("micro-star", [
        ("chain.n", n), ("run.dt", DT), ("run.output_interval", steps * DT),
        ("run.duration", blocks * steps * DT), ("thermal.temperature", temperature),
        ("thermal.seed", 1), ("output.bead_stride", 0)])


# ---- one point, in its own process ---------------------------------------------------------
def fast_worker(n, temperature, threads, steps, repeats):
    """The fast backend: each frame is one block of ``steps`` steps."""
    from mdgran.backends.fast import FastBackend

    # one block more than is timed: each timed next() then steps one block (the backend steps
    # the next block, in line or on a second core, before it hands over the last)
    b = FastBackend(scene_for(n, temperature, steps, repeats + 2), threads=threads)
    frames = b.blocks()
    next(frames)  # t = 0
    next(frames)  # warm-up block
    walls, cpus, events0, win0 = [], [], b.stats["events"], b.stats["event_windows"]
    for _ in range(repeats):
        k0, c0 = b.stats["kernel_s"], time.process_time()
        next(frames)
        walls.append(b.stats["kernel_s"] - k0)
        cpus.append(time.process_time() - c0)
    return {"wall_s": walls, "cpu_s": cpus, "events": b.stats["events"] - events0,
            "event_windows": b.stats["event_windows"] - win0,
            "threads": b.stats["threads"], "rss_MB": _rss()}


def paired_worker(n, threads, steps, repeats, warm_up):
    """The fast backend's moving (T = 1e-6) and active (T = 2) chains in one process, their
    blocks of ``steps`` alternating after ``warm_up`` blocks of each (the moving chain's first
    in even pairs, the active chain's in odd ones), so that each pair's two blocks run within
    seconds of each other.  On one thread the process is pinned to one core: the backend then
    steps each block in line (it would otherwise step a chain's next block on the second core
    while the other chain's block is timed).  Per temperature (as a string): the compiled
    loop's wall time of each block (``loop_s``), the wall and CPU time of each whole
    ``next()`` (``wall_s``, ``cpu_s``), the events and event windows of the timed blocks."""
    from mdgran.backends.fast import FastBackend

    if threads == 1 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    # one block more than is timed: each timed next() then steps one block
    backends = {t: FastBackend(scene_for(n, t, steps, repeats + warm_up + 1), threads=threads)
                for t in (QUIET, ACTIVE)}
    frames = {t: b.blocks() for t, b in backends.items()}
    for t in (QUIET, ACTIVE):
        for _ in range(1 + warm_up):  # t = 0, then the warm-up blocks
            next(frames[t])
    loop, wall, cpu = ({QUIET: [], ACTIVE: []} for _ in range(3))
    start = {t: (b.stats["events"], b.stats["event_windows"]) for t, b in backends.items()}
    for k in range(repeats):
        for t in ((QUIET, ACTIVE) if k % 2 == 0 else (ACTIVE, QUIET)):
            b = backends[t]
            k0, w0, c0 = b.stats["kernel_s"], time.perf_counter(), time.process_time()
            next(frames[t])
            loop[t].append(b.stats["kernel_s"] - k0)
            wall[t].append(time.perf_counter() - w0)
            cpu[t].append(time.process_time() - c0)
    return {"loop_s": {str(t): v for t, v in loop.items()},
            "wall_s": {str(t): v for t, v in wall.items()},
            "cpu_s": {str(t): v for t, v in cpu.items()},
            "events": {str(t): b.stats["events"] - start[t][0] for t, b in backends.items()},
            "event_windows": {str(t): b.stats["event_windows"] - start[t][1]
                              for t, b in backends.items()},
            "threads": backends[ACTIVE].stats["threads"]}


def native_chain(n, temperature, steps, blocks, comm=None):
    """``fix mdgran/chain`` with located events on the chain of :func:`scene_for`, on the MPI
    communicator ``comm`` (default: every rank), set up by a ``run 0``."""
    from mdgran.backends.lammps import LammpsBackend

    b = LammpsBackend(scene_for(n, temperature, steps, blocks), comm=comm, contact="native",
                      events="located")
    b._start()
    b.lmp.command("run 0 post no")
    return b


def timed_run(b, steps):
    """Wall and CPU seconds of LAMMPS's ``run`` of ``steps`` steps (no set-up, no summary)."""
    t0, c0 = time.perf_counter(), time.process_time()
    b.lmp.command(f"run {steps} pre no post no")
    return time.perf_counter() - t0, time.process_time() - c0


def native_paired_worker(n, steps, repeats, warm_up):
    """``paired_worker`` for ``fix mdgran/chain`` with located events: the moving and the
    active chain as two LAMMPS instances of one process (of one rank, or of each of two
    ranks), their runs of ``steps`` alternating after ``warm_up`` runs of each.  The ranks of
    LAMMPS's run are in step, so rank 0's wall time of a run is the run's."""
    chains = {t: native_chain(n, t, steps, repeats + warm_up + 1) for t in (QUIET, ACTIVE)}
    for b in chains.values():
        for _ in range(warm_up):
            timed_run(b, steps)

    def events(b):
        return int(b.lmp.extract_fix("contact", 0, 1, 2))

    wall, cpu = {QUIET: [], ACTIVE: []}, {QUIET: [], ACTIVE: []}
    start = {t: events(b) for t, b in chains.items()}
    try:
        for k in range(repeats):
            for t in ((QUIET, ACTIVE) if k % 2 == 0 else (ACTIVE, QUIET)):
                w, c = timed_run(chains[t], steps)
                wall[t].append(w)
                cpu[t].append(c)
        for b in chains.values():
            if getattr(b, "_error", None) is not None:
                raise b._error
        return {"loop_s": {str(t): v for t, v in wall.items()},
                "cpu_s": {str(t): v for t, v in cpu.items()},
                "events": {str(t): events(b) - start[t] for t, b in chains.items()},
                "event_windows": {str(t): None for t in chains},
                "threads": None, "rank": chains[ACTIVE].lmp.extract_setting("world_rank")}
    finally:
        for b in chains.values():
            b.lmp.close()


def native_worker(n, temperature, steps, repeats):
    """``fix mdgran/chain`` with located events: LAMMPS's ``run`` of ``steps`` steps."""
    b = native_chain(n, temperature, steps, repeats + 1)
    lmp = b.lmp
    try:
        timed_run(b, steps)  # warm-up
        walls, cpus = [], []
        for _ in range(repeats):
            w, c = timed_run(b, steps)
            walls.append(w)
            cpus.append(c)
        if getattr(b, "_error", None) is not None:
            raise b._error
        return {"wall_s": walls, "cpu_s": cpus, "rank": lmp.extract_setting("world_rank"),
                "rss_MB": _rss()}
    finally:
        lmp.close()


def _rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(args):
    n, temperature, steps = args.worker, args.temperature, args.steps
    if args.pair and args.backend.startswith("native"):
        report = native_paired_worker(n, steps, args.repeats, args.warm_up)
        report["rss_MB"] = _rss()
    elif args.pair:
        report = paired_worker(n, int(args.backend[-1]), steps, args.repeats, args.warm_up)
        report["rank"], report["rss_MB"] = 0, _rss()
    elif args.backend.startswith("fast"):
        report = fast_worker(n, temperature, int(args.backend[-1]), steps, args.repeats)
        report["rank"] = 0
    else:
        report = native_worker(n, temperature, steps, args.repeats)
    Path(args.report_dir, f"rank-{report['rank']}.json").write_text(json.dumps(report))


# ---- the driver -----------------------------------------------------------------------------
def run_worker(n, backend, options, timeout, script=__file__, reports=None):
    """Run ``script``'s worker process (``mpiexec -n 2`` for native-2) with the options
    ``options``; returns the ``reports`` (default: one a rank) it wrote, or an error message
    (a string)."""
    ranks = 2 if backend == "native-2" else 1
    expected = ranks if reports is None else reports
    # one BLAS thread: an idle OpenBLAS thread spinning after numpy's set-up is CPU time
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, script, "--worker", str(n), "--backend", backend,
               "--report-dir", tmp] + options
        if ranks > 1:
            cmd = [mpiexec, "-n", str(ranks)] + cmd
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout,
                                 start_new_session=True)
        except subprocess.TimeoutExpired:
            return f"not finished in {timeout} s"
        got = sorted((json.loads(p.read_text()) for p in Path(tmp).glob("rank-*.json")),
                     key=lambda r: r["rank"])
    if res.returncode or len(got) != expected:
        return (res.stderr or res.stdout)[-600:]
    return got


def measure(n, temperature, backend, repeats, block_time, timeout):
    """One point in a process of its own: its blocks' ns per bead-step and CPU time."""
    steps = int(round(block_time / DT))
    row = {"n": n, "temperature": temperature, "backend": backend, "steps_per_block": steps,
           "repeats": repeats, "loadavg_before": os.getloadavg()}
    reports = run_worker(n, backend, ["--temperature", str(temperature), "--steps", str(steps),
                                      "--repeats", str(repeats)], timeout)
    row["loadavg_after"] = os.getloadavg()
    if isinstance(reports, str):
        return {**row, "error": reports}
    r0 = reports[0]
    row.update({"ns_blocks": [1e9 * w / (n * steps) for w in r0["wall_s"]],
                "cpu_ns_per_bead_step": 1e9 * sum(r0["cpu_s"]) / (n * steps * repeats),
                "peak_rss_MB_per_rank": [r["rss_MB"] for r in reports]})
    for key in ("events", "event_windows", "threads"):
        if key in r0:
            row[key] = r0[key]
    return row


def pair_blocks(n, pairs, pair_time, warm_up_time):
    """(steps per block, pairs, warm-up blocks) of a pair at N beads: blocks of ``pair_time``,
    but at least the fast backend's ``BLOCK_BEAD_STEPS`` (it hands over no less; 1000 steps at
    N = 1e3), over the stretch of history of ``pairs`` blocks of ``pair_time`` (at least 2)
    after ``warm_up_time``."""
    from mdgran.backends.fast import BLOCK_BEAD_STEPS

    steps = max(int(round(pair_time / DT)), -(-BLOCK_BEAD_STEPS // n))
    return (steps, max(2, int(round(pairs * pair_time / (steps * DT)))),
            max(1, int(round(warm_up_time / (steps * DT)))))


def measure_pair(n, backend, pairs, pair_time, warm_up_time, timeout):
    """The moving and the active chain of a backend in one process, their blocks
    alternating (:func:`paired_worker`, :func:`native_paired_worker`, :func:`pair_blocks`):
    a row of each, the active one with the ratio of each pair's blocks (``pair_ratios``)."""
    steps, pairs, warm_up = pair_blocks(n, pairs, pair_time, warm_up_time)
    base = {"n": n, "backend": backend, "steps_per_block": steps, "repeats": pairs,
            "paired": True, "loadavg_before": os.getloadavg()}
    reports = run_worker(n, backend, ["--pair", "--steps", str(steps), "--repeats", str(pairs),
                                      "--warm-up", str(warm_up)], timeout)
    base["loadavg_after"] = os.getloadavg()
    if isinstance(reports, str):
        return {t: {**base, "temperature": t, "error": reports} for t in (QUIET, ACTIVE)}
    r0 = reports[0]
    rows = {}
    for t in (QUIET, ACTIVE):
        loop, cpu = r0["loop_s"][str(t)], r0["cpu_s"][str(t)]
        rows[t] = {**base, "temperature": t,
                   "ns_blocks": [1e9 * w / (n * steps) for w in loop],
                   "cpu_ns_per_bead_step": 1e9 * sum(cpu) / (n * steps * pairs),
                   "peak_rss_MB_per_rank": [r0["rss_MB"]], "events": r0["events"][str(t)],
                   "event_windows": r0["event_windows"][str(t)], "threads": r0["threads"]}
    rows[ACTIVE]["pair_ratios"] = [a / q for a, q in zip(r0["loop_s"][str(ACTIVE)],
                                                         r0["loop_s"][str(QUIET)])]
    return rows


def pooled(rounds):
    """One point's row from its rounds (each a :func:`measure` row): the median, min and max
    of all their blocks, each round's median, the CPU time averaged over the rounds, the load
    averages of each."""
    bad = [r for r in rounds if "error" in r]
    if bad:
        return bad[0]
    ns = np.concatenate([r["ns_blocks"] for r in rounds])
    row = {k: v for k, v in rounds[0].items() if k not in ("ns_blocks", "loadavg_before",
                                                            "loadavg_after", "pair_ratios")}
    if "pair_ratios" in rounds[0]:
        row["pair_ratios"] = [x for r in rounds for x in r["pair_ratios"]]
        row["pair_ratio_round_medians"] = [float(np.median(r["pair_ratios"])) for r in rounds]
    row.update({"rounds": len(rounds),
                "loadavg_before": [r["loadavg_before"] for r in rounds],
                "loadavg_after": [r["loadavg_after"] for r in rounds],
                "ns_per_bead_step_median": float(np.median(ns)),
                "ns_per_bead_step_min": float(ns.min()),
                "ns_per_bead_step_max": float(ns.max()),
                "ns_per_bead_step_round_medians": [float(np.median(r["ns_blocks"]))
                                                   for r in rounds],
                "cpu_ns_per_bead_step": float(np.mean([r["cpu_ns_per_bead_step"]
                                                       for r in rounds]))})
    return row


def round_medians(row):
    """A row's median of each round (a row of a single round: its median)."""
    return row.get("ns_per_bead_step_round_medians", [row["ns_per_bead_step_median"]])


def median_ci95(values):
    """The median of ``values`` with a distribution-free 95 % interval: the order statistics
    of ranks n/2 -+ 0.98 sqrt(n) (the binomial(n, 1/2) quantiles, normal approximation)."""
    v = np.sort(np.asarray(values, dtype=float))
    half = 0.98 * np.sqrt(v.size)
    lo = max(int(np.floor(v.size / 2 - half)), 0)
    hi = min(int(np.ceil(v.size / 2 + half)), v.size - 1)
    return float(np.median(v)), [float(v[lo]), float(v[hi])]


def pair_ratio(row):
    """Active over moving from a paired row's pairs (:func:`measure_pair`): the median of all
    pairs' ratios, its 95 % interval, quartiles, the median of each round's pairs."""
    median, ci = median_ci95(row["pair_ratios"])
    q1, q3 = np.percentile(row["pair_ratios"], [25, 75])
    return {"backend": row["backend"], "n": row["n"], "active_over_quiet": median,
            "ci95": ci, "quartiles": [float(q1), float(q3)], "pairs": len(row["pair_ratios"]),
            "rounds": row["pair_ratio_round_medians"]}


def round_ratio(num, den):
    """The ratio of two rows as the median of their rounds' ratios (each round measures the
    two points within a minute of each other, so that a slow spell of the machine mostly falls
    on both), with the rounds' ratios."""
    each = [a / b for a, b in zip(round_medians(num), round_medians(den))]
    return float(np.median(each)), each


def ratios(rows):
    """Active (T = 2) / quiet stepped whole (T = 1e-6) per (backend, N): of the pairs
    (:func:`pair_ratio`) for a row timed in pairs, else the median of the rounds' ratios
    (:func:`round_ratio`); and 2 / 1 (threads or ranks) per (N, T), the median of the rounds'
    ratios."""
    done = {(r["backend"], r["n"], r["temperature"]): r for r in rows if "error" not in r}
    out = []
    for (backend, n, t), r in sorted(done.items()):
        quiet = done.get((backend, n, QUIET))
        if t == ACTIVE and "pair_ratios" in r:
            out.append(pair_ratio(r))
        elif t == ACTIVE and quiet is not None:
            ratio, each = round_ratio(r, quiet)
            out.append({"backend": backend, "n": n, "active_over_quiet": ratio,
                        "rounds": each})
        if backend.endswith("-2"):
            one = done.get((backend[:-1] + "1", n, t))
            if one is not None:
                ratio, each = round_ratio(one, r)
                out.append({"backend": backend[:-2], "n": n, "temperature": t,
                            "two_over_one_speed": ratio, "rounds": each})
    return out


def kept_rows(path, new_rows):
    """The rows of the result file ``path`` of points this run did not measure (a run of some
    backends, sizes or temperatures replaces their rows and keeps the others')."""
    if not path.exists():
        return []

    def point(r):
        return r["backend"], r["n"], r["temperature"]

    measured = {point(r) for r in new_rows}
    return [r for r in json.loads(path.read_text())["rows"] if point(r) not in measured]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e3,1e4,1e5,1e6")
    ap.add_argument("--temperatures", type=float, nargs="+", default=[0.0, QUIET, ACTIVE])
    ap.add_argument("--backends", nargs="+", default=list(BACKENDS), choices=BACKENDS)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=4,
                    help="times the whole matrix is measured, every other time in reverse order")
    ap.add_argument("--block-time", type=float, default=2.0,
                    help="time units per timed block (800 steps at dt = 0.0025)")
    ap.add_argument("--pair-time", type=float, default=0.25,
                    help="time units per block of a fast pair (100 steps at dt = 0.0025)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per point")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--temperature", type=float, default=0.0, help=argparse.SUPPRESS)
    ap.add_argument("--backend", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--steps", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--pair", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--warm-up", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--report-dir", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        return worker(args)
    points = [(int(float(s)), backend, t) for s in args.sizes.split(",")
              for backend in args.backends for t in args.temperatures]
    measured = {p: [] for p in points}
    paired = {QUIET, ACTIVE} <= set(args.temperatures)
    # a backend's moving and active chains: one point, their blocks in pairs
    runs = [(n, b, "pair" if paired and t == QUIET else t)
            for n, b, t in points if not (paired and t == ACTIVE)]
    pairs = int(round(args.repeats * args.block_time / args.pair_time))
    for turn in range(args.rounds):
        for n, backend, t in runs if turn % 2 == 0 else runs[::-1]:
            if t == "pair":
                got = measure_pair(n, backend, pairs, args.pair_time, args.block_time,
                                   args.timeout)
            else:
                got = {t: measure(n, t, backend, args.repeats, args.block_time, args.timeout)}
            for t, row in got.items():
                measured[n, backend, t].append(row)
                print(json.dumps({k: row[k] for k in row if not k.startswith("loadavg")}),
                      flush=True)
    rows = [pooled(measured[p]) for p in points]
    rows = kept_rows(Path(args.out), rows) + rows
    result = {"benchmark": __doc__.splitlines()[0], "dt": DT,
              "machine": platform.processor() or platform.machine(), "cores": os.cpu_count(),
              "rows": rows, "ratios": ratios(rows)}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
