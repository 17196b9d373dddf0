"""Scale-up of the LAMMPS backend on 1 and 2 MPI ranks: time per bead-step and peak memory.

    python benchmarks/scale_up_lammps.py [--sizes 100 1000 10000 100000 1000000] [--repeats 3]

Each chain is micro-star's physics with ``chain.n = N`` (as benchmarks/scale_up.py does for the
fast backend).  Every (N, ranks) point runs in its own process (``mpiexec -n RANKS``) so that
memory is measured per run: set-up (LAMMPS instance, contact table, first frame) is not timed;
then ``--repeats`` frames of a fixed number of steps are, and the median, min and max ns per
bead-step reported, with the peak RSS of each rank (summed over ranks).  Writes
benchmarks/results/scale_up_lammps.json.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "results" / "scale_up_lammps.json"
BEAD_STEPS_PER_REPEAT = 2e6


def worker(n: int, repeats: int, report_dir: str):
    from mdgran.model.scene import load_scene
    from mdgran.simulation import make_backend, mpi_rank

    dt = 0.0025
    steps = int(np.clip(BEAD_STEPS_PER_REPEAT // n, 20, 20000))
    sc = load_scene("micro-star", [("chain.n", n), ("run.dt", dt),
                                   ("run.output_interval", steps * dt),
                                   ("run.duration", (repeats + 1) * steps * dt),
                                   ("output.positions", False)])
    b = make_backend(sc, "lammps")
    frames = b.frames()
    next(frames)  # set-up and t = 0
    next(frames)  # warm-up repeat
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        next(frames)
        times.append(time.perf_counter() - t0)
    ns = np.array(times) / (n * steps) * 1e9
    rank = mpi_rank()  # each rank writes its own line: ranks' stdout interleaves under mpiexec
    (Path(report_dir) / f"rank-{rank}.json").write_text(json.dumps(
        {"rank": rank, "n": n, "steps_per_repeat": steps, "ns": ns.tolist(),
         "hook_s": b.stats.get("callback_s"),
         "rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def measure(n: int, ranks: int, repeats: int) -> dict:
    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, __file__, "--worker", str(n), "--repeats", str(repeats),
               "--report-dir", tmp]
        if ranks > 1:
            cmd = [mpiexec, "-n", str(ranks)] + cmd
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=3600,
                             env={**os.environ, "OMP_NUM_THREADS": "1"})
        lines = [json.loads(p.read_text()) for p in sorted(Path(tmp).glob("rank-*.json"))]
    if res.returncode or not lines:
        return {"n": n, "ranks": ranks, "error": (res.stderr or res.stdout)[-400:]}
    r0 = next(x for x in lines if x["rank"] == 0)
    ns = np.array(r0["ns"])
    return {"n": n, "ranks": ranks, "steps_per_repeat": r0["steps_per_repeat"],
            "repeats": repeats, "ns_per_bead_step_median": float(np.median(ns)),
            "ns_per_bead_step_min": float(ns.min()), "ns_per_bead_step_max": float(ns.max()),
            "peak_rss_MB_total": float(sum(x["rss_MB"] for x in lines)),
            "peak_rss_MB_per_rank": [x["rss_MB"] for x in sorted(lines, key=lambda x: x["rank"])]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000, 100000, 1000000])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--report-dir", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        return worker(args.worker, args.repeats, args.report_dir)
    rows = []
    for n in args.sizes:
        for k in args.ranks:
            row = measure(n, k, args.repeats)
            rows.append(row)
            print(json.dumps(row), flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"benchmark": "LAMMPS backend scale-up (micro-star physics)",
                               "rows": rows}, indent=1) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
