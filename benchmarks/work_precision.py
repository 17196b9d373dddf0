"""Work-precision: error against wall time for every method, measured side by side in one run.

    python benchmarks/work_precision.py [--scenes micro-star,macro-hertz,collision-pair]
                                        [--repeat 3] [--quick]

Methods and their accuracy settings:

* ``reference``   event-driven DOP853 at several tolerances (``run.tolerance``);
* ``fast``        fixed-step velocity Verlet with each contact event located inside its step
                  and the step split there, at several ``run.dt``;
* ``verlet``      the same kernel with step-quantized events (a contact switches at the end of
                  the step in which it crossed, as a fixed-step MD code does);
* ``lammps``      LAMMPS with the Python contact hook, at several ``run.dt``;
* ``native``      LAMMPS with the native contact ``fix mdgran/chain`` in its located-events
                  mode (the fix integrates the chain and splits each step at its events);
* ``native-quantized``  the native contact with step-quantized events (plain MD, as the hook).

Errors, against a tight reference run (tolerance 1e-11) of the same scene:

* trajectory error: ``max_{t <= window, i} |x_i(t) - x_i,true(t)|``, the window inside the
  predictability horizon (micro-star's is ~30 time units: see reference_convergence.py);
* ledger error: ``max_t |E(t) - E(0)| / E_imp`` over the whole run (no truth needed).

Wall time is that of the run alone (scene loaded, in-memory output, numba compiled by an
untimed warm-up), the median of ``--repeat`` runs, with max - min as its spread.  The observed
order of each fixed-step method is the least-squares slope of log error against log dt; for
the reference, against log tolerance.  The cost of each method at a ledger error of 1e-6 is read
off a power-law fit of time against ledger error through its points (``extrapolated`` says when
1e-6 lies outside the measured range).

For each fixed-step method the summary also gives the ledger error at the scene's own ``run.dt``
and the predictability horizon as ``mdgran compare`` finds it: the first output time where the
method's own error estimate, ``2^p / (2^p - 1) max_i |x_dt - x_dt/2|`` (Richardson, order ``p``
of the method as declared), exceeds ``mdgran.crosscheck.compare.PREDICTABLE`` (0.01 p).

Writes benchmarks/results/work_precision.json and work_precision.png (``--stem`` another name:
``python benchmarks/work_precision.py --methods native,native-quantized,lammps --repeat 1
--stem work_precision_native`` measures the LAMMPS paths alone).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from mdgran.crosscheck.compare import PREDICTABLE
from mdgran.model.scene import load_scene
from mdgran.simulation import BackendUnavailable, run

RESULTS = Path(__file__).parent / "results"
TRUTH_TOL = 1e-11
TARGET_LEDGER = 1e-6
#: per scene: duration of the run, trajectory-error window
SCENES = {"micro-star": (400.0, 20.0), "macro-hertz": (400.0, 50.0),
          "collision-pair": (20.0, 20.0)}
SETTINGS = {
    "reference": ("run.tolerance", [1e-5, 1e-6, 1e-7, 1e-8, 1e-9]),
    "fast": ("run.dt", [0.005, 0.0025, 0.00125, 0.000625, 0.0003125]),
    "verlet": ("run.dt", [0.005, 0.0025, 0.00125, 0.000625, 0.0003125]),
    "lammps": ("run.dt", [0.01, 0.005, 0.0025, 0.00125]),
    "native": ("run.dt", [0.01, 0.005, 0.0025, 0.00125, 0.000625]),
    "native-quantized": ("run.dt", [0.01, 0.005, 0.0025, 0.00125, 0.000625]),
}
BACKEND = {"reference": ("reference", {}), "fast": ("fast", {}),
           "verlet": ("fast", {"locate_events": False}), "lammps": ("lammps", {}),
           "native": ("lammps", {"contact": "native", "events": "located"}),
           "native-quantized": ("lammps", {"contact": "native", "events": "quantized"})}
#: declared order in dt of the fixed-step methods (Richardson factor of the horizon)
ORDER = {"fast": 2, "verlet": 1, "lammps": 1, "native": 2, "native-quantized": 1}


def timed_runs(scene, method, repeat):
    backend, options = BACKEND[method]
    times, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = run(scene, backend, raise_errors=False, **options)
        times.append(time.perf_counter() - t0)
    return res, times


def slope(x, y):
    """Least-squares slope of log y against log x over the finite positive points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0) & np.isfinite(y)
    if ok.sum() < 2:
        return None
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0])


def cost_at(errors, times, target):
    """Wall time at ledger error ``target`` from a power-law fit of time against error."""
    e, t = np.asarray(errors, float), np.asarray(times, float)
    ok = (e > 0) & np.isfinite(e)
    if ok.sum() < 2:
        return None, None
    p = np.polyfit(np.log(e[ok]), np.log(t[ok]), 1)
    inside = e[ok].min() <= target <= e[ok].max()
    return float(np.exp(np.polyval(p, np.log(target)))), not inside


def horizon(time, x_dt, x_half, order):
    """First time where 2^p/(2^p - 1) max_i |x_dt - x_dt/2| exceeds PREDICTABLE (the end of
    the run if never): mdgran compare's predictability horizon of a fixed-step method."""
    n = min(len(x_dt), len(x_half))
    est = 2.0**order / (2.0**order - 1.0) * np.max(np.abs(x_dt[:n] - x_half[:n]), axis=1)
    above = np.flatnonzero(est > PREDICTABLE)
    return float(time[above[0]]) if above.size else float(time[n - 1])


def measure_scene(name, methods, repeat, quick):
    duration, window = SCENES[name]
    if quick:
        duration = min(duration, 40.0)
    base = [("run.duration", duration)]
    truth = run(load_scene(name, base + [("run.tolerance", TRUTH_TOL)]), "reference").trajectory
    in_window = truth.time <= window + 1e-9
    dt0 = float(load_scene(name).data["run"]["dt"])
    rows = []
    at_dt = {}  # (method, dt) -> positions, for the horizon at dt0
    for method in methods:
        key, values = SETTINGS[method]
        if quick:
            values = values[:3]
        backend, options = BACKEND[method]
        try:  # warm-up: numba compilation, LAMMPS library load; not timed
            run(load_scene(name, [("run.duration", 1.0)]), backend, raise_errors=False, **options)
        except BackendUnavailable as exc:
            print(f"{method}: skipped ({exc})", flush=True)
            continue
        for value in values:
            scene = load_scene(name, base + [(key, value)])
            res, times = timed_runs(scene, method, repeat)
            tr = res.trajectory
            n = min(len(tr.time), len(truth.time))
            traj_err = float(np.max(np.abs(tr.x[:n] - truth.x[:n])[in_window[:n]]))
            row = {"scene": name, "method": method, "setting": key, "value": value,
                   "status": res.status, "trajectory_error": traj_err,
                   "ledger_error": res.max_ledger_error,
                   "wall_s_median": float(np.median(times)),
                   "wall_s_spread": float(np.max(times) - np.min(times)), "repeats": repeat}
            rows.append(row)
            if key == "run.dt" and res.status == "complete" and any(
                    abs(value - d) < 1e-12 for d in (dt0, dt0 / 2)):
                at_dt[method, round(value / dt0, 6)] = tr.x
            print(json.dumps(row), flush=True)
    summary = {}
    for method in methods:
        mine = [r for r in rows if r["method"] == method and r["status"] == "complete"]
        if not mine:
            continue
        x = [r["value"] for r in mine]
        cost, extrapolated = cost_at([r["ledger_error"] for r in mine],
                                     [r["wall_s_median"] for r in mine], TARGET_LEDGER)
        summary[method] = {
            "order_trajectory": slope(x, [r["trajectory_error"] for r in mine]),
            "order_ledger": slope(x, [r["ledger_error"] for r in mine]),
            "order_in": SETTINGS[method][0],
            "wall_s_at_ledger_1e-6": cost, "extrapolated": extrapolated}
        if method in ORDER:
            own = [r for r in mine if abs(r["value"] - dt0) < 1e-12]
            summary[method]["ledger_error_at_default_dt"] = (own[0]["ledger_error"] if own
                                                             else None)
            if (method, 1.0) in at_dt and (method, 0.5) in at_dt:
                summary[method]["horizon"] = horizon(truth.time, at_dt[method, 1.0],
                                                     at_dt[method, 0.5], ORDER[method])
    return {"scene": name, "duration": duration, "window": window, "default_dt": dt0,
            "rows": rows,
            "summary": summary}


def plot(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(results), figsize=(5.2 * len(results), 8.4), squeeze=False)
    for col, res in enumerate(results):
        for row, (err, label) in enumerate([("trajectory_error",
                                             f"trajectory error, t <= {res['window']:g}"),
                                            ("ledger_error", "ledger error / E_imp, whole run")]):
            ax = axes[row, col]
            for method, s in res["summary"].items():
                pts = [r for r in res["rows"] if r["method"] == method
                       and r["status"] == "complete"]
                order = s["order_trajectory" if row == 0 else "order_ledger"]
                unit = "tol" if s["order_in"] == "run.tolerance" else "dt"
                lab = f"{method} (slope in {unit}: {order:.2f})" if order else method
                ax.loglog([r["wall_s_median"] for r in pts], [max(r[err], 1e-17) for r in pts],
                          "o-", label=lab)
            if row == 1:
                ax.axhline(TARGET_LEDGER, color="k", ls=":", lw=1)
            from matplotlib.ticker import NullFormatter

            ax.xaxis.set_minor_formatter(NullFormatter())  # overlapping minor labels
            ax.set(xlabel="wall time of the run (s, median)", ylabel=label,
                   title=f"{res['scene']} to t = {res['duration']:g}")
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--methods", default=",".join(SETTINGS))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="short runs, three settings each")
    ap.add_argument("--stem", default=None, help="name of the result files (default "
                    "work_precision, or work_precision_quick with --quick)")
    ap.add_argument("--plot-only", action="store_true",
                    help="redraw the PNG from the JSON of the last run")
    args = ap.parse_args(argv)
    stem = args.stem or ("work_precision_quick" if args.quick else "work_precision")
    if args.plot_only:
        saved = json.loads((RESULTS / f"{stem}.json").read_text())
        return plot(saved["results"], RESULTS / f"{stem}.png")
    methods = args.methods.split(",")
    results = [measure_scene(s, methods, args.repeat, args.quick) for s in args.scenes.split(",")]
    out = {"target_ledger_error": TARGET_LEDGER, "truth_tolerance": TRUTH_TOL,
           "quick": args.quick, "results": results}
    for res in results:
        s = res["summary"]
        fastest = min((m for m in s if m != "lammps" and s[m]["wall_s_at_ledger_1e-6"]),
                      key=lambda m: s[m]["wall_s_at_ledger_1e-6"], default=None)
        if fastest and "lammps" in s and s["lammps"]["wall_s_at_ledger_1e-6"]:
            res["speedup_vs_lammps_at_1e-6"] = {
                "fastest": fastest,
                "ratio": s["lammps"]["wall_s_at_ledger_1e-6"] / s[fastest]["wall_s_at_ledger_1e-6"],
                "lammps_extrapolated": s["lammps"]["extrapolated"]}
        print(res["scene"], json.dumps(s, indent=1), res.get("speedup_vs_lammps_at_1e-6"))
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{stem}.json").write_text(json.dumps(out, indent=1) + "\n")
    plot(results, RESULTS / f"{stem}.png")


if __name__ == "__main__":
    main()
