"""Cost of the LAMMPS backend's contact per bead-step, on one and two MPI ranks, with memory.

    python benchmarks/lammps_scaling.py                       # the whole matrix below
    python benchmarks/lammps_scaling.py --sizes 1e4 --ranks 1 --repeats 2   # a quick try

Cases (micro-star's physics with N beads, mdgran/backends/lammps/chain.in as the backend sets it up):

* ``none``        no contact (``unfix contact``): LAMMPS's own cost with chain.in's fix nve and
                  fix spring/self (put back where the backend took it out), the floor;
* ``hook-before`` the numpy hook of revision ``--before`` (default a0662a2, the last with it:
                  whole-chain ghosts, every contact on every rank), run from a git worktree of
                  that revision (its own chain.in);
* ``hook``        the compiled per-rank hook (mdgran/backends/lammps/hook.py);
* ``native``      ``fix mdgran/chain`` of the plugin, step-quantized events (the hook's work);
* ``native-located`` the same fix integrating the chain itself, events located inside the step
                  (second order; replaces fix nve and fix spring/self).

Default matrix: N = 1e4, 1e5, 1e6 on one rank for every case; N = 1e5, 1e6 on two ranks for
``none``, ``hook``, ``native`` and ``native-located``.  Every (case, N, ranks) point runs in a process of its own
(``mpiexec -n RANKS`` for two) so that its peak memory is its own: set-up and a warm-up run are
not timed, then ``--repeats`` runs of the same number of steps are, each on its own (median and
spread = max - min, ns per bead-step, from rank 0's clock; ranks are in step, LAMMPS
synchronises them every step).  Peak RSS (``ru_maxrss``) of every rank.  ``os.getloadavg()``
before and after every point: the machine has 2 cores, and a load above ~0.5 before a 1-rank
point (~0.2 before a 2-rank one) means other work shared them.  Writes
benchmarks/results/lammps_scaling.json (``--out`` to change).

``--against REV`` measures every point also with revision REV (a git worktree of it on the
``PYTHONPATH``; its plugin is built into the user cache on first use), alternating the two trees
``--rounds`` times (before, after, after, before, ...), so that a change is judged on a busy
machine against the same load; each row says its ``tree`` (``before``: REV, ``after``: this one).
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
ROOT = HERE.parent
OUT = HERE / "results" / "lammps_scaling.json"
BEFORE = "a0662a2"  # the last revision with the numpy hook over the whole chain
MODES = ("none", "hook-before", "hook", "native", "native-located")
DT = 0.0025


def steps_for(n: int, bead_steps: float) -> int:
    return int(np.clip(bead_steps // n, 10, 20000))


# ---- one point, in its own process (every rank runs this) -----------------------------------

def worker(n: int, mode: str, steps: int, repeats: int, report_dir: str):
    from mdgran.backends.lammps import LammpsBackend
    from mdgran.model.scene import load_scene

    sc = load_scene("micro-star", [("chain.n", n), ("run.dt", DT),
                                   ("run.duration", steps * DT),
                                   ("run.output_interval", steps * DT),
                                   ("output.positions", False)])
    options = {"native": {"contact": "native", "events": "quantized"},
               "native-located": {"contact": "native", "events": "located"}}.get(mode, {})
    b = LammpsBackend(sc, **options)
    b._start()
    lmp = b.lmp
    rank = lmp.extract_setting("world_rank")
    try:
        if mode == "none":
            for fix in ("contact", "state"):
                if lmp.has_id("fix", fix):
                    lmp.command(f"unfix {fix}")
            if sc.data["substrate"]["k1"] and not lmp.has_id("fix", "substrate"):
                lmp.command("fix substrate mobile spring/self ${k1} x")  # as chain.in has it
            lmp.command("thermo_style custom step time ke pe")
        lmp.command("run 0 post no")
        lmp.command(f"run {steps} pre no post no")  # warm-up
        walls = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            lmp.command(f"run {steps} pre no post no")
            walls.append(time.perf_counter() - t0)
        if getattr(b, "_error", None) is not None:
            raise b._error
        report = {"rank": rank, "wall_s": walls, "nlocal": lmp.extract_setting("nlocal"),
                  "nghost": lmp.extract_setting("nghost"),
                  "rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}
    finally:
        lmp.close()
    (Path(report_dir) / f"rank-{rank}.json").write_text(json.dumps(report))


# ---- the driver -----------------------------------------------------------------------------

def measure(n: int, mode: str, ranks: int, repeats: int, bead_steps: float,
            before_tree: Path | None, tree: Path | None = None) -> dict:
    """One point in a process of its own; ``tree``: the mdgran checkout to import (a worktree
    of another revision), default this one."""
    steps = steps_for(n, bead_steps)
    row = {"n": n, "contact": mode, "ranks": ranks, "steps_per_repeat": steps,
           "repeats": repeats, "loadavg_before": os.getloadavg()}
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    if mode == "hook-before":
        if before_tree is None:
            return {**row, "error": "no worktree of the 'before' revision"}
        env["PYTHONPATH"] = str(before_tree)
    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, __file__, "--worker", str(n), "--mode", mode, "--steps",
               str(steps), "--repeats", str(repeats), "--report-dir", tmp]
        if ranks > 1:
            cmd = [mpiexec, "-n", str(ranks)] + cmd
        res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=7200)
        reports = sorted((json.loads(p.read_text()) for p in Path(tmp).glob("rank-*.json")),
                         key=lambda r: r["rank"])
    row["loadavg_after"] = os.getloadavg()
    if res.returncode or len(reports) != ranks:
        return {**row, "error": (res.stderr or res.stdout)[-600:]}
    ns = 1e9 * np.array(reports[0]["wall_s"]) / (n * steps)
    row.update({"ns_per_bead_step_median": float(np.median(ns)),
                "ns_per_bead_step_spread": float(ns.max() - ns.min()),
                "ns_per_bead_step": ns.tolist(),
                "peak_rss_MB_per_rank": [r["rss_MB"] for r in reports],
                "atoms_per_rank": [r["nlocal"] for r in reports],
                "ghosts_per_rank": [r["nghost"] for r in reports]})
    return row


def before_worktree(rev: str):
    """A detached worktree of ``rev`` (None if git cannot make one)."""
    path = Path(tempfile.mkdtemp(prefix="mdgran-before-")) / "tree"
    res = subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), rev],
                         capture_output=True, text=True)
    return path if res.returncode == 0 else None


def plan(args):
    """(n, mode, ranks) points: every mode on one rank, the others on more."""
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    points = []
    for ranks in args.ranks:
        for n in sizes:
            if ranks > 1 and n < args.min_n_multi:
                continue
            for mode in args.modes:
                if ranks > 1 and mode == "hook-before" and not args.before_on_ranks:
                    continue
                points.append((n, mode, ranks))
    return points


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e4,1e5,1e6")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--bead-steps", type=float, default=2e7,
                    help="bead-steps per timed run (steps = this / N, 10 to 20000)")
    ap.add_argument("--min-n-multi", type=int, default=100_000,
                    help="smallest N run on several ranks")
    ap.add_argument("--before", default=BEFORE, help="revision of the 'hook-before' case")
    ap.add_argument("--before-on-ranks", action="store_true",
                    help="also run 'hook-before' on several ranks")
    ap.add_argument("--against", default=None,
                    help="also measure every point with this revision (alternating trees)")
    ap.add_argument("--rounds", type=int, default=2,
                    help="with --against: measurements of each point per tree")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--mode", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--steps", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--report-dir", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        return worker(args.worker, args.mode, args.steps, args.repeats, args.report_dir)
    points = plan(args)
    tree = before_worktree(args.before) if any(p[1] == "hook-before" for p in points) else None
    against = before_worktree(args.against) if args.against else None
    if args.against and against is None:
        raise SystemExit(f"cannot make a git worktree of {args.against}")
    rows = []
    try:
        for n, mode, ranks in points:
            if against is None:
                runs = [(None, None)]
            else:  # before, after, after, before, ...: both trees see the same drift in load
                order = [("before", against), ("after", None)]
                runs = [r for k in range(args.rounds) for r in (order if k % 2 == 0
                                                                 else order[::-1])]
            for label, where in runs:
                row = measure(n, mode, ranks, args.repeats, args.bead_steps, tree, where)
                if label is not None:
                    row = {"tree": label, **row}
                rows.append(row)
                print(json.dumps({k: v for k, v in row.items() if k != "ns_per_bead_step"}),
                      flush=True)
    finally:
        for t in (tree, against):
            if t is not None:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(t)],
                               capture_output=True)
                shutil.rmtree(t.parent, ignore_errors=True)
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    result = {"benchmark": "LAMMPS contact cost per bead-step, 1 and 2 ranks (micro-star)",
              "revision": head, "before_revision": args.before, "against": args.against,
              "dt": DT,
              "cpu_count": os.cpu_count(), "machine": platform.machine(),
              "note": "ns per bead-step = wall time of a timed run / (N * steps), rank 0; "
                      "loadavg_before/after: 1, 5, 15-minute load averages; a 1-minute load "
                      "above ~0.5 before a point means the 2 cores were shared with other work",
              "rows": rows}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
