"""Reference integrator: ledger closure, run time and trajectory convergence against tolerance.

    python benchmarks/reference_convergence.py [--scene micro-star] [--duration 400]

For each tolerance: the energy-ledger error max |E(t) - E0| / E_imp, the number of events, the
wall time (median of --repeat runs, with the spread).  Between successive tolerances: the
trajectory difference max_i |x_i(t) - x_i'(t)| over time.  The predictability horizon is where
the difference between the two tightest tolerances first exceeds 1e-3 (in units of p, against
displacements of order 1-10): past it the chaotic chain has forgotten its initial state to the
precision the integrator holds.  Writes benchmarks/results/reference_convergence.{json,png}.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from mdgran.model.scene import load_scene
from mdgran.simulation import run

RESULTS = Path(__file__).parent / "results"
HORIZON_THRESHOLD = 1e-3


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="micro-star")
    ap.add_argument("--duration", type=float, default=400.0)
    ap.add_argument("--tolerances", default="1e-6,1e-7,1e-8,1e-9,1e-10,1e-11")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    tols = [float(t) for t in args.tolerances.split(",")]
    rows, trajs = [], []
    for tol in tols:
        sc = load_scene(args.scene, [("run.duration", args.duration), ("run.tolerance", tol)])
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = run(sc, "reference")
            times.append(time.perf_counter() - t0)
        tr = res.trajectory
        trajs.append(tr)
        rows.append({"tolerance": tol, "ledger_error": res.max_ledger_error,
                     "events": int(len(tr.ev_time)), "steps": res.stats["steps"],
                     "wall_s_median": float(np.median(times)),
                     "wall_s_spread": float(np.max(times) - np.min(times)),
                     "repeats": args.repeat})
        print(json.dumps(rows[-1]), flush=True)
    diffs = []
    for a, b, ta, tb in zip(trajs[:-1], trajs[1:], tols[:-1], tols[1:]):
        d = np.max(np.abs(a.x - b.x), axis=1)
        above = np.flatnonzero(d > HORIZON_THRESHOLD)
        diffs.append({"tolerances": [ta, tb], "max_diff_t50": float(d[a.time <= 50].max()),
                      "horizon": float(a.time[above[0]]) if above.size else None, "d": d})
    horizon = diffs[-1]["horizon"]
    out = {"scene": args.scene, "duration": args.duration, "rows": rows,
           "horizon_threshold": HORIZON_THRESHOLD, "predictability_horizon": horizon,
           "pairs": [{k: v for k, v in p.items() if k != "d"} for p in diffs]}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "reference_convergence.json").write_text(json.dumps(out, indent=2) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for p in diffs:
        a1.semilogy(trajs[0].time, np.maximum(p["d"], 1e-17),
                    label=f"tol {p['tolerances'][0]:g} vs {p['tolerances'][1]:g}")
    a1.axhline(HORIZON_THRESHOLD, color="k", ls=":", lw=1)
    a1.set(xlabel="time (1/q)", ylabel="max_i |x_i - x_i'| (p)",
           title=f"{args.scene}: trajectory difference between tolerances")
    a1.legend(fontsize=7)
    a2.loglog([r["wall_s_median"] for r in rows], [r["ledger_error"] for r in rows], "o-")
    for r in rows:
        a2.annotate(f"{r['tolerance']:g}", (r["wall_s_median"], r["ledger_error"]), fontsize=7)
    a2.set(xlabel="wall time (s), median", ylabel="max ledger error / E_imp",
           title="ledger closure vs cost")
    fig.tight_layout()
    fig.savefig(RESULTS / "reference_convergence.png", dpi=110)
    print(json.dumps(out["pairs"], indent=1))
    print("predictability horizon:", horizon)


if __name__ == "__main__":
    main()
