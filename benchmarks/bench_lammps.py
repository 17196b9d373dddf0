"""Cost of the LAMMPS backend: time per step (N = 20) and per bead-step (N = 1e4, 1e5).

    python benchmarks/bench_lammps.py [--repeat 5]

Each case runs micro-star's physics with N beads for a fixed number of steps (one output frame
at the end), --repeat times; the median wall time and the spread (max - min) are reported, with
the share spent in the Python contact hook.  Writes benchmarks/results/bench_lammps.json.
Quote ratios from one run of this script on a quiet machine.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from mdgran.model.scene import load_scene
from mdgran.simulation import run

CASES = [(20, 4000), (10_000, 400), (100_000, 100)]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--dt", type=float, default=0.0025)
    args = ap.parse_args(argv)
    rows = []
    for n, steps in CASES:
        duration = steps * args.dt
        sc = load_scene("micro-star", [("chain.n", n), ("run.dt", args.dt),
                                       ("run.duration", duration),
                                       ("run.output_interval", duration),
                                       ("output.positions", False)])
        walls, hooks = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = run(sc, "lammps", keep=False)
            walls.append(time.perf_counter() - t0)
            hooks.append(res.stats["callback_s"])
        med = float(np.median(walls))
        row = {"n": n, "steps": steps, "wall_s_median": med,
               "wall_s_spread": float(np.max(walls) - np.min(walls)),
               "per_step_us": 1e6 * med / steps, "per_bead_step_ns": 1e9 * med / steps / n,
               "hook_share": float(np.median(hooks) / med), "repeats": args.repeat}
        rows.append(row)
        print(json.dumps(row), flush=True)
    out = Path(__file__).parent / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_lammps.json").write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
