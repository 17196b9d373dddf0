"""A small study from Python, end to end: micro-star on two backends, read back, measured.

    python docs/examples/small_study.py OUT_DIR [--duration 100]

1. runs the paper's micro chain (scene ``micro-star``) to ``t = duration`` on the reference
   integrator (event-driven DOP853, the accuracy oracle) and on the fast backend (velocity
   Verlet at dt = 0.0025 with located events), each written to ``OUT_DIR/<backend>.h5``;
2. reads both files back with ``mdgran.read``;
3. computes a few of the study's measures with ``mdgran.analysis``: primary pulse speed and
   the characteristic period ``T_c``, the kinetic-energy decay time, clusters formed, the time
   mean and peak of the effective damping ``C_eff / C_+`` (Eq. 9);
4. prints a table, checks that the backends agree on the early motion (displacements over the
   first ``T_c``) within ``mdgran.crosscheck.compare.PREDICTABLE`` = 0.01 p, the level up to which
   ``mdgran compare`` judges single trajectories; and
5. saves ``OUT_DIR/small_study.png`` (kinetic energy and ``C_eff / C_+`` against time) and
   ``OUT_DIR/summary.json`` (the table's numbers).

Everything is nondimensional (docs/physics.md section 1): time ``1/q``, length ``p``, energy
``eta p``.  About 10 s on one core at the default duration (the fast backend's first run
compiles its kernel for a few seconds and caches it).  Exit status 0 if the backends agree and
both runs are complete, 1 otherwise.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import mdgran

BACKENDS = ("reference", "fast")


def measures(traj) -> dict:
    """A few of the study's measures of one run (an mdgran.Run; mdgran.analysis, cached in
    ``traj.measures``; nondimensional)."""
    import numpy as np

    from mdgran import analysis

    t, kin = traj.time, traj.ledger["kinetic_energy"]
    cbar = traj.measures.c_eff  # C_eff(t) / C_+, Eq. 9
    history = traj.measures.history
    return {
        "pulse_speed": float(analysis.primary_pulse_speed(traj)),  # beads per time unit
        "T_c": float(analysis.characteristic_period(traj)),
        "kinetic_decay_time": float(analysis.decay_time(t, kin, math.exp(-1.0))),
        "clusters_formed": int(history.cumulative[-1]) if len(history.cumulative) else 0,
        "events": int(len(traj.ev_time)),
        "c_eff_mean": float(np.sum(0.5 * (cbar[1:] + cbar[:-1]) * np.diff(t)) / (t[-1] - t[0])),
        "c_eff_peak": float(np.max(cbar)),
        "final_kinetic_share": float(kin[-1] / kin[0]),
    }


def main(argv=None) -> int:
    import numpy as np

    from mdgran.crosscheck.compare import PREDICTABLE

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="folder for the runs, the figure and summary.json")
    ap.add_argument("--duration", type=float, default=100.0, help="run.duration (default 100)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    runs, table, walls = {}, {}, {}
    for backend in BACKENDS:
        start = time.perf_counter()
        res = mdgran.run("micro-star", backend, out=args.out / f"{backend}.h5",
                         set={"run.duration": args.duration})
        walls[backend] = time.perf_counter() - start
        print(res)
        if res.status != "complete":
            print(f"{backend}: run not complete: {res.status}", file=sys.stderr)
            return 1
        traj = mdgran.read(args.out / f"{backend}.h5")  # the file, as another script would
        runs[backend] = traj
        table[backend] = {**measures(traj),
                          "ledger_error": traj.max_ledger_error, "wall_s": walls[backend]}

    ref, fast = runs["reference"], runs["fast"]
    t_c = table["reference"]["T_c"]
    early = ref.time <= t_c + 1e-9
    dx = float(np.max(np.abs(ref.x[early] - fast.x[early])))
    agree = dx <= PREDICTABLE

    names = list(table["reference"])
    print()
    print(f"micro-star to t = {args.duration:g} (nondimensional units)")
    print(f"{'measure':<22}{'reference':>14}{'fast':>14}")
    for name in names:
        print(f"{name:<22}" + "".join(f"{table[b][name]:>14.6g}" for b in BACKENDS))
    print(f"early_max_dx {dx:.3e} p over t <= T_c = {t_c:.4g} (tolerance {PREDICTABLE:g} p): "
          + ("agree" if agree else "DISAGREE"))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(6.4, 5.6))
    for backend, traj in runs.items():
        ls = "-" if backend == "reference" else "--"
        ax1.plot(traj.time, traj.ledger["kinetic_energy"], ls, label=backend)
        ax2.plot(traj.time, traj.measures.c_eff, ls, label=backend)
    ax1.set_ylabel("kinetic energy (eta p)")
    ax1.legend()
    ax2.set_ylabel("C_eff / C_+")
    ax2.set_xlabel("time (1/q)")
    ax1.set_title("micro-star: reference vs fast")
    fig.tight_layout()
    fig.savefig(args.out / "small_study.png", dpi=100)
    plt.close(fig)

    summary = {"duration": args.duration, "measures": table, "early_max_dx": dx,
               "early_window": t_c, "tolerance": PREDICTABLE, "agree": agree}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"wrote {args.out / 'small_study.png'} and {args.out / 'summary.json'}")
    return 0 if agree else 1


if __name__ == "__main__":
    sys.exit(main())
