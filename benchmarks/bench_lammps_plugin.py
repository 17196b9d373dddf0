"""Cost per bead-step of the LAMMPS backend's contact: Python hook, native plugin, and none.

    python benchmarks/bench_lammps_plugin.py [--repeat 3] [--sizes 1e4,1e5,1e6]

Each case sets up micro-star's physics with N beads (mdgran/backends/lammps/chain.in, as the backend
does), runs ``run 0``, then times ``run STEPS`` alone (set-up and output excluded), --repeat
times: median and spread (max - min) in ns per bead-step, for

* ``hook``   - the Python ``fix external`` callback (the default contact),
* ``native`` - ``fix mdgran/chain`` of the plugin (``contact="native"``),
* ``none``   - no contact at all (``unfix contact``): LAMMPS's own cost (Verlet, fix nve,
  spring/self, setforce, balance, neighbour checks), the floor of both.

The load average before and after is recorded: the 2 cores may be shared.  Writes
benchmarks/results/bench_lammps_plugin.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from mdgran.backends.lammps import LammpsBackend
from mdgran.model.scene import load_scene

STEPS = {10_000: 1000, 100_000: 300, 1_000_000: 100}


def time_case(n: int, steps: int, mode: str, dt: float) -> float:
    duration = steps * dt
    sc = load_scene("micro-star", [("chain.n", n), ("run.dt", dt), ("run.duration", duration),
                                   ("run.output_interval", duration),
                                   ("output.positions", False)])
    b = LammpsBackend(sc, contact="native" if mode == "native" else "hook")
    b._start()
    lmp = b.lmp
    try:
        if mode == "none":
            lmp.command("unfix contact")
            lmp.command("thermo_style custom step time ke pe")
        lmp.command("run 0 post no")
        t0 = time.perf_counter()
        lmp.command(f"run {steps} pre no post no")
        wall = time.perf_counter() - t0
        if b._error is not None:
            raise b._error
    finally:
        lmp.close()
    return wall


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dt", type=float, default=0.0025)
    ap.add_argument("--sizes", default="1e4,1e5,1e6")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    rows = []
    for n in (int(float(s)) for s in args.sizes.split(",")):
        steps = STEPS.get(n, max(10, int(2e7 // n)))
        for mode in ("none", "native", "hook"):
            walls = [time_case(n, steps, mode, args.dt) for _ in range(args.repeat)]
            ns = [1e9 * w / steps / n for w in walls]
            row = {"n": n, "steps": steps, "contact": mode,
                   "per_bead_step_ns_median": float(np.median(ns)),
                   "per_bead_step_ns_spread": float(np.max(ns) - np.min(ns)),
                   "repeats": args.repeat, "loadavg_1min": os.getloadavg()[0]}
            rows.append(row)
            print(json.dumps(row), flush=True)
    result = {"cpu_count": os.cpu_count(), "machine": platform.machine(),
              "loadavg_before": load0, "loadavg_after": os.getloadavg(),
              "note": "load averages above ~1 mean the other core (or both) was busy with other "
                      "work during the measurement: absolute numbers are then inflated and noisy",
              "rows": rows}
    out = Path(__file__).parent / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_lammps_plugin.json").write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
