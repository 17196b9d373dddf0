"""``mdgran report DIR``: the paper's study, every figure from one command.

What it does, reusing whatever ``DIR`` already holds (so a second call only redraws):

1. runs ``micro-star`` and ``macro-hertz`` to t = 400 into ``DIR/runs/`` (reference backend
   unless ``backend`` says otherwise);
2. runs the ``paper-robustness`` sweep into ``DIR/sweep/`` (or reads ``sweep_dir``), resumable,
   in parallel; ``small`` runs its CI-sized version;
3. analyses them with :mod:`mdgran.analysis` and draws Figs. 2-7 and B1-B3
   (:mod:`mdgran.studies.paper_figures`) into ``DIR/figures/``;
4. writes ``DIR/report.md`` (the figures with the numbers they show) and ``DIR/report.json``;
   its "Run status" section names every run and sweep case that is not complete (its ledger
   error exceeded its backend's declared bound, or it failed): their numbers are in the
   figures and tables but are not to be trusted.

**Realizations.**  A sweep run with ``[sweep] realizations = K`` (:mod:`mdgran.studies.sweep`) holds
K realizations of each grid point.  The figures and sections pool them all; report.md's
"Realizations" section gives every statistic of the study (Fig. 7 slope after the impact
transient, pooled coincidence fraction and its z at T_c / 4 in the active part, the z of each
null model of :func:`null_models`, with smaller shuffle counts) computed on each realization
alone, their mean and the 95% Student-t interval of that mean (:func:`interval_over_realizations`),
next to the pooled value (:func:`realization_statistics`).  With one realization it says so.
"""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np

from .. import analysis as an
from . import paper_figures as pf
from . import controls
from ..model.scene import load_scene
from ..output.storage import write_atomic
from ..output.run_record import read_h5

FLAGSHIP = ("micro-star", "macro-hertz")
#: beyond the paper: sweep name -> (axis shown as colour, its label, log colour scale)
BEYOND = {"chain-100": ("substrate.k1_si", "substrate stiffness K1 (N/m)", False),
          "chain-1000": ("substrate.k1_si", "substrate stiffness K1 (N/m)", False),
          "lambda-range": ("contact.lambda", "Maugis parameter lambda", True)}
#: beyond the paper, studies that are no sweep: the primary pulse in long chains
#: (mdgran.studies.long_chain, on the fast backend)
BEYOND_STUDIES = ("long-chain",)



def ensure_run(name: str, out: Path, backend: str, progress: bool, duration=None,
               label: str | None = None):
    """The run ``out/NAME.h5`` (made if missing), as read back from the file (a
    :class:`~mdgran.output.run_record.Run`, its scene the stored one); ``label``: its progress
    line's label (default the scene and backend)."""
    from ..simulation import run

    scene = load_scene(name, [] if duration is None else [("run.duration", float(duration))])
    path = out / f"{name}.h5"
    if not path.exists():
        out.mkdir(parents=True, exist_ok=True)
        reporters = []
        if progress:
            from ..output.progress import ProgressReporter

            reporters.append(ProgressReporter(float(scene.run.duration),
                                              label=label or f"{name} [{backend}]"))
        run(scene, backend, out=path, progress=False, keep=False, reporters=reporters)
    return read_h5(path)


def _case_record(sweep_dir: Path, index: int):
    """A case's JSON record, or None if it has none (or an unreadable one)."""
    try:
        rec = json.loads((sweep_dir / "cases" / f"{index:04d}.json").read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return rec if isinstance(rec, dict) else None


def _listed(indices: list) -> str:
    shown = ", ".join(f"{i:04d}" for i in indices[:5])
    return shown + (f" and {len(indices) - 5} more" if len(indices) > 5 else "")


def check_sweep_files(sweep_dir: Path, key: str = "--sweep-dir") -> list:
    """Refuse (:class:`~mdgran.model.scene.SceneError`, one line, exit status 2) a sweep folder that
    is unfinished (a case without its JSON) or whose finished cases lack their ``.h5`` (an
    older mdgran's MPI sweep wrote only the JSON on its worker ranks): their figures and tests
    would silently leave those cases out, or whose ``.h5`` cannot be read (cut short,
    overwritten: the report ran a minute, then a traceback).  Returns the cases that failed
    without writing an
    ``.h5`` (an exception, a worker that died), which the report names in its run status."""
    from ..model.scene import SceneError

    from ..output.run_record import unreadable

    spec = json.loads((sweep_dir / "sweep.json").read_text())
    unrun, no_h5, failed, broken = [], [], [], []
    for c in spec["cases"]:
        h5 = sweep_dir / "cases" / f"{c['index']:04d}.h5"
        if h5.exists():
            why = unreadable(h5)
            if why is not None:
                broken.append((c["index"], why))
            continue
        rec = _case_record(sweep_dir, c["index"])
        if rec is None:
            unrun.append(c["index"])
        elif str(rec.get("status", "")).startswith("failed"):
            failed.append({"index": c["index"], "params": c["params"],
                           "status": f"{rec['status']} (no .h5 written)"})
        else:
            no_h5.append(c["index"])
    total = len(spec["cases"])
    again = ("; run the same mdgran sweep command on that folder again to "
             + ("finish it" if unrun else "redo them"))
    if unrun:
        raise SceneError(key, f"{sweep_dir}: the sweep is unfinished, {len(unrun)} of {total} "
                         f"cases have not run (no cases/NNNN.json: {_listed(unrun)})" + again)
    if broken:
        raise SceneError(key, f"{sweep_dir}: {len(broken)} of {total} case files cannot be read "
                         f"({_listed([i for i, _ in broken])}; cases/{broken[0][0]:04d}.h5: "
                         f"{broken[0][1]})" + again)
    if no_h5:
        raise SceneError(key, f"{sweep_dir}: {len(no_h5)} of {total} finished cases have no "
                         f"cases/NNNN.h5 ({_listed(no_h5)}; their .json says they ran: an "
                         "older mdgran's MPI sweep wrote none on its worker ranks), so "
                         "Figs. 6, 7, B1-B3 and the pooled test would leave them out" + again)
    return failed


def sweep_cases(sweep_dir: Path, key: str = "--sweep-dir") -> list:
    """Every finished case of a sweep folder: params, the scene stored in its run file, a lazy
    loader of its :class:`~mdgran.output.run_record.Run` (``"run"``), and its measures
    (:class:`~mdgran.output.measures.Measures`: the summary recomputed with the current analysis
    code, the C_eff and rate curves, the channels, segments and null-model case).  A folder with
    cases missing their files is refused (:func:`check_sweep_files`); a case that failed
    without an ``.h5`` is left out here (the report names it in its run status)."""
    check_sweep_files(sweep_dir, key)
    spec = json.loads((sweep_dir / "sweep.json").read_text())
    cases = []
    for c in spec["cases"]:
        h5 = sweep_dir / "cases" / f"{c['index']:04d}.h5"
        if not h5.exists():
            continue
        run = read_h5(h5)
        m = run.measures
        p = c["params"]
        row = {"index": c["index"], "params": p, "scene": run.scene,
               "k1": p.get("substrate.k1_si", p.get("substrate.k1")),
               "v0": p.get("impulse.velocity"),
               "run": (lambda path=h5: read_h5(path))}
        row.update(m.summary)
        row["curves"] = (run.time, m.c_eff, m.rate)  # for the pooled coincidence test
        row["segments"] = m.reclustering.segments  # for Fig. B2
        row["segment_c_eff"] = m.reclustering.segment_c_eff
        row["channels"] = {"viscous": m.channels["viscous"],  # for the null models
                           "hysteresis": m.channels["hysteresis"]}
        row["null_case"] = m.null_case
        row["ledger_error"] = run.max_ledger_error
        row["status"] = run.status or "unknown (no status in the file)"
        cases.append(row)
    return cases


def not_complete(cases: list) -> list:
    """Index, parameters and status of the sweep cases whose run is not complete."""
    return [{"index": c["index"], "params": c["params"], "status": c["status"]}
            for c in cases if c["status"] != "complete"]


def run_status(runs: dict, cases: list) -> dict:
    """The status of each flagship run (name -> Run) and the sweep's incomplete cases."""
    return {"runs": {name: tr.status or "unknown (no status in the file)"
                     for name, tr in runs.items()},
            "sweep_not_complete": not_complete(cases)}


def status_markdown(nb: dict) -> list:
    """report.md's "Run status" section: which runs and cases exceeded their ledger bound or
    failed (the incomplete ones of the beyond sweeps too)."""
    st = nb["status"]
    bad_runs = {k: v for k, v in st["runs"].items() if v != "complete"}
    bad = {"the sweep": st["sweep_not_complete"],
           **{f"beyond/{k}": b["not_complete"] for k, b in nb.get("beyond", {}).items()}}
    if "long_chain" in nb:
        bad["beyond/long-chain"] = nb["long_chain"]["not_complete"]
    L = ["## Run status", ""]
    if not bad_runs and not any(bad.values()):
        return L + ["Every run and sweep case is complete: its energy-ledger error is within its "
                    "backend's declared bound.", ""]
    L += ["Not complete (a ledger error above the backend's declared bound, or a failure): "
          "these runs are in the figures and tables below, but their numbers are not to be "
          "trusted.", ""]
    L += [f"* run {k}: {v}" for k, v in bad_runs.items()]
    for where, rows in bad.items():
        L += [f"* {where}, case {r['index']:04d} {r['params']}: {r['status']}" for r in rows]
    return L + [""]


def _folder_backend(folder: Path, backend: str) -> str:
    """A sweep folder that exists keeps the backend it was started on (a chain-1000 sweep run
    with ``mdgran sweep --backend fast`` is resumed and analysed as such)."""
    f = folder / "sweep.json"
    return json.loads(f.read_text())["backend"] if f.exists() else backend


def _fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


def _tc(x):
    """A time in units of T_c, or "not reached" (None)."""
    return "not reached" if x is None else f"{x:.3g} T_c"


def make_report(out, small: bool = False, workers: int | None = None,
                backend: str = "reference", sweep: str = "paper-robustness",
                sweep_dir=None, progress: bool = True, duration: float | None = None,
                beyond=()) -> dict:
    """Runs what ``out`` lacks, then draws every figure; returns the numbers shown.
    ``duration`` shortens the two flagship runs (tests).  ``beyond``: names of the sweeps of
    :data:`BEYOND` to run into ``out/beyond/NAME`` and analyse the same way (Fig. 7 and the
    pooled coincidence test per sweep)."""
    from .sweep import run_sweep

    out = Path(out)
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    say = (lambda m: print(m, file=sys.stderr, flush=True)) if progress else (lambda m: None)
    if sweep_dir is not None:  # a sweep with cases missing their files is refused up front
        check_sweep_files(Path(sweep_dir), "--sweep-dir")
    runs = {name: ensure_run(name, out / "runs", backend, progress, duration,
                             f"report: flagship run {k} of {len(FLAGSHIP)}, {name} [{backend}]")
            for k, name in enumerate(FLAGSHIP, 1)}
    micro, macro = runs["micro-star"], runs["macro-hertz"]
    sdir = Path(sweep_dir) if sweep_dir is not None else out / "sweep"
    if sweep_dir is None:
        run_sweep(sweep, sdir, workers=workers or (os.cpu_count() or 1), small=small,
                  progress=progress, backend=_folder_backend(sdir, backend))
    say("analysing the sweep cases")
    key = "--sweep-dir" if sweep_dir is not None else "DIR"
    failed = check_sweep_files(sdir, key)
    cases = sweep_cases(sdir, key)
    if failed:
        say(f"{len(failed)} sweep cases failed without output and are left out of the sweep's "
            "figures (named in report.md's run status)")
    say("drawing figures")
    numbers = {
        "fig2": pf.fig2(micro, macro, figs / "fig2.png"),
        "fig3": pf.fig3(micro, figs / "fig3.png"),
        "fig4": pf.fig4(micro, figs / "fig4.png"),
        "fig5": pf.fig5(micro, figs / "fig5.png"),
    }
    numbers["status"] = run_status({"micro-star": micro, "macro-hertz": macro}, cases)
    numbers["status"]["sweep_not_complete"] += failed
    numbers["decay"] = kinetic_decay(micro, macro)
    numbers["paper_details"] = paper_details()
    say("controls: the macro chain matched in m/s, and with adhesion (Schwarz at its lambda)")
    numbers["controls"] = controls.run_controls(out / "runs", backend, duration, progress,
                                                have={"micro": micro, "macro-pulse": macro})
    if numbers["controls"]["vs_micro"]:
        pf.fig_controls(numbers["controls"], figs / "controls.png")
    numbers["coincidence_windows"] = coincidence_windows(micro)
    numbers["smoothing"] = smoothing_sensitivity(micro)
    if cases:
        numbers.update(sweep_numbers(cases, sdir, figs, small, say, numbers))
    numbers["beyond"] = {}
    if "long-chain" in beyond:
        numbers["long_chain"] = _long_chain(figs / "beyond-long-chain.png", small, say)
    for name in (b for b in beyond if b not in BEYOND_STUDIES):
        numbers["beyond"][name] = beyond_sweep(name, out, figs, workers, small, progress,
                                               backend)
    write_atomic(out / "report.json", json.dumps(numbers, indent=1, default=_json) + "\n")
    write_atomic(out / "report.md", markdown(numbers, cases, small))
    say(f"report: {out / 'report.md'}")
    return numbers


def sweep_numbers(cases, sdir, figs, small, say, numbers) -> dict:
    """The study's numbers over the sweep's ``cases`` (folder ``sdir``): the pooled
    coincidence test, Figs. 6, B and 7 (after the impact transient and by the literal rule),
    their null models, the sweep's summary and the statistics per realization (``numbers``:
    the report's so far, for the pooled statistics)."""
    out = {}
    say("pooled coincidence test over the sweep")
    out["coincidence_pooled"] = [
        pooled_coincidence(cases, w, n_shifts=200 if small else 1000, active=act)
        for act in (False, True) for w in (0.25, 1.0)]
    out["fig6"] = pf.fig6(cases, figs / "fig6.png")
    out["figB"] = pf.fig_b(cases, [figs / f"figB{k}.png" for k in (1, 2, 3)])
    late = [{**c, "c_eff_max_segment": c["c_eff_late_segment"],
             "c_eff_max_segment_rate": c["c_eff_late_segment_rate"]} for c in cases]
    out["fig7"] = pf.fig7(late, figs / "fig7.png", "after the impact transient "
                          "(segments starting at t >= T_c/2)")
    out["fig7_literal"] = pf.fig7(cases, figs / "fig7_literal.png",
                                  "literal rule (any segment but the last)")
    say("null models of Fig. 7 and of the coincidence test")
    out["nulls"] = null_models(cases, small)
    spec = json.loads((sdir / "sweep.json").read_text())
    out["sweep"] = {"cases": len(cases), "dir": str(sdir),
                    "max_ledger_error": max(c["ledger_error"] for c in cases),
                    "realizations": int(spec.get("realizations", 1))}
    groups = realization_groups(cases)
    if len(groups) > 1:
        say(f"the study's statistics on each of {len(groups)} realizations")
        rz = realization_statistics(cases, small, pooled_statistics({**numbers, **out}))
    else:
        rz = {"K": 1, "realizations": list(groups), "interval": None, "statistics": {}}
    rz["perturbation"] = spec.get("perturbation")
    if rz["K"] > 1:
        rz["shuffles"] = (f"{REALIZATION_SHIFTS[bool(small)]} circular shifts for the "
                          "coincidence test, {} and {} shuffles for the null models".format(
                              *REALIZATION_SHUFFLES[bool(small)]))
    out["realizations"] = rz
    return out


def beyond_sweep(name, out, figs, workers, small, progress, backend) -> dict:
    """The sweep ``name`` of :data:`BEYOND` run into ``out/beyond/NAME`` (what it lacks) and
    analysed as the study's: Fig. 7 coloured by its parameter, the pooled coincidence test,
    the cases that are not complete."""
    from .sweep import run_sweep

    bdir = out / "beyond" / name
    run_sweep(name, bdir, workers=workers or (os.cpu_count() or 1), small=small,
              progress=progress, backend=_folder_backend(bdir, backend))
    bfailed = check_sweep_files(bdir, "DIR")
    bc = sweep_cases(bdir, "DIR")
    key, label, log = BEYOND[name]
    late = [{**c, "c_eff_max_segment": c["c_eff_late_segment"],
             "c_eff_max_segment_rate": c["c_eff_late_segment_rate"]} for c in bc]
    return {
        "cases": len(bc), "n": bc[0]["scene"].chain.n if bc else None,
        "fig7": pf.fig7(late, figs / f"beyond-{name}.png", "segments starting at t >= T_c/2",
                        color_key=key, color_label=label, title=name, log_color=log),
        "coincidence_pooled": pooled_coincidence(bc, 0.25, n_shifts=200 if small else 1000),
        "max_ledger_error": max((c["ledger_error"] for c in bc), default=None),
        "not_complete": not_complete(bc) + bfailed,
        "backend": _folder_backend(bdir, backend)}


def _long_chain(figure, small: bool, say) -> dict:
    """:func:`mdgran.studies.long_chain.long_chain_study` (smaller and shorter with ``small``), its
    runs that are not complete listed as the sweeps' are (``not_complete``)."""
    from . import long_chain as lc

    if small:
        nb = lc.long_chain_study(figure, sizes=(100, 1000, 3000), velocities=(12.0, 100.0),
                                 lambdas=(0.64, 5.0), duration=20.0, progress=say)
    else:  # the cross-check on a chain of a million beads split over 2 MPI ranks
        nb = lc.long_chain_study(figure, progress=say, check_n=1_000_000, check_ranks=2)
    nb["not_complete"] = [{"index": k, "params": {key: r[key] for key in ("n", "v0", "lambda")},
                           "status": r["status"]}
                          for k, r in enumerate(nb["runs"]) if r["status"] != "complete"]
    cc = nb.get("cross_check")
    if cc and "unavailable" not in cc and not cc["agree"]:  # a check that failed says so
        nb["not_complete"].append({"index": "cross-check",
                                   "params": {"n": cc["n"], "backend": cc["backend"]},
                                   "status": "disagrees" if cc["status"] == "complete"
                                   else cc["status"]})
    return nb


def long_chain_markdown(lc: dict) -> list:
    """report.md's section on the primary pulse in long chains."""
    L = ["", "## The primary pulse in long chains", "",
         f"micro-star struck at bead 1 (fast backend, t = {lc['duration']:g}), on chains of "
         "several lengths and, on the longest, for several impulse velocities and Maugis "
         "parameters. Reach: the farthest bead whose largest speed is at least 1e-3 v0; speed "
         "of the pulse from the times of the beads' largest speeds; energy left: the "
         "mechanical energy on the chain at the end (contacts at rest hold 0; a contact "
         "settled in its adhesive well holds less); bead-steps: the share of N x steps the "
         "activity front stepped.", "",
         "| varies | beads | v0 | lambda | reach (beads) | speed (beads per 1/q) | open "
         "contacts | snap-offs | energy left / E_imp | bead-steps | status | ledger error |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in lc["runs"]:
        share = (r["bead_steps"] / (r["n"] * r["steps"])
                 if r["bead_steps"] and r["steps"] else None)
        L.append(f"| {r['varies']} | {r['n']} | {r['v0']:g} | {_fmt(r['lambda'])} | "
                 f"{r['reach']} | {_fmt(r['speed_beads_per_time'])} | {r['open_contacts']} | "
                 f"{r['snapoffs_total']} | {r['energy_left_total'] / (0.5 * r['v0'] ** 2):.3g} | "
                 f"{_fmt(share)} | {r['status']} | {_fmt(r['max_ledger_error'])} |")
    conv = ", ".join(f"N = {n}: {d:.3g}" for n, d in lc["converged_peak_v"].items())
    L += ["", f"Largest difference of a chain's per-bead largest speed from the longest "
          f"chain's (p q): {conv} (0 exactly once the chain is longer than the pulse's "
          "reach: its beads move bitwise alike).", ""]
    cc = lc.get("cross_check")
    if cc and "unavailable" in cc:
        L += [f"Cross-check on {cc['backend']}: not run ({cc['unavailable']}).", ""]
    elif cc:
        ranks = f", {cc['ranks']} MPI ranks" if cc.get("ranks", 1) > 1 else ""
        L += [f"Cross-check: the pulse (v0 = 12) again on {cc['backend']}, on {cc['n']} "
              f"beads{ranks}, against the fast backend's on {cc.get('fast_n', cc['n'])}: "
              f"{'agrees' if cc['agree'] else 'DISAGREES'} (per-bead largest "
              f"speeds within {cc['max_peak_v_difference_over_v0']:.2g} v0; reach "
              f"{cc['reach'][0]} and {cc['reach'][1]} beads; snap-offs {cc['snapoffs'][0]} and "
              f"{cc['snapoffs'][1]}; wall time {cc['wall_s'][0]:.3g} s and "
              f"{cc['wall_s'][1]:.3g} s; status {cc['status']}).", ""]
    L += ["![long chains](figures/beyond-long-chain.png)"]
    return L


def _json(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def kinetic_decay(micro, macro) -> dict:
    """Kinetic energy of both chains averaged over one T_c (centred running mean of T / T(0):
    a pointwise value would land on the dips where the macro pulse reflects at a wall, every
    T_c / 2), at multiples of T_c, and the first time that mean falls below 1/e and 1/10 (in
    units of each chain's T_c)."""
    out = {}
    for name, tr in (("micro", micro), ("macro", macro)):
        tc = tr.measures.characteristic_period
        k = tr.ledger["kinetic_energy"] / tr.ledger["kinetic_energy"][0]
        w = max(1, int(round(tc / (tr.time[1] - tr.time[0]))))
        mean = np.convolve(k, np.ones(w) / w, mode="same")
        valid = (tr.time >= tr.time[0] + tc / 2) & (tr.time <= tr.time[-1] - tc / 2)

        def first_below(level):
            i = np.flatnonzero(valid & (mean < level))
            return float(tr.time[i[0]] / tc) if i.size else None

        at = {f"{m:g}": float(np.interp(m * tc, tr.time, mean)) for m in (1, 2, 3, 4, 6, 8, 10, 12)
              if m * tc <= tr.time[-1] - tc / 2}
        out[name] = {"T_c": tc, "T_over_T0_at_multiples_of_T_c": at,
                     "decay_1e_over_T_c": first_below(math.exp(-1.0)),
                     "decay_10pct_over_T_c": first_below(0.1)}
    return out


def coincidence_windows(traj) -> list:
    """The coincidence test at windows of T_c / 4, T_c / 2 and T_c; for all C_eff peaks
    (prominence 0.1 of the range) and the major ones (0.3); in both directions (C_eff peaks
    near a rate peak, rate peaks near a C_eff peak)."""
    m = traj.measures
    tc = m.characteristic_period
    t0, t1 = float(traj.time[0]), float(traj.time[-1])
    rows = []
    for prom in (0.1, 0.3):
        co = an.run_coincidence(traj, prominence=prom, c_eff=m.c_eff,
                                reclustering=m.reclustering)
        a, b = co["c_eff_peaks"], co["rate_peaks"]
        for frac in (0.25, 0.5, 1.0):
            for direction, x, y in (("C_eff peaks near a rate peak", a, b),
                                    ("rate peaks near a C_eff peak", b, a)):
                r = an.coincidence_test(x, y, frac * tc, t0, t1)
                rows.append({"window_T_c": frac, "prominence": prom, "direction": direction,
                             "fraction": r["fraction"], "null_mean": r["null_mean"],
                             "p_value": r["p_value"], "n": r["n_a"], "n_other": r["n_b"]})
    return rows


def pooled_coincidence(cases, window_frac: float = 1.0, prominence: float = 0.1,
                       n_shifts: int = 1000, seed: int = 0, active: bool = False) -> dict:
    """The coincidence test pooled over sweep cases: the fraction of all C_eff peaks lying within
    ``window_frac x T_c`` (each case's own) of a rate peak of their case, against the same
    fraction when every case's rate peaks are shifted circularly and independently.  One run
    has only 3-4 rate peaks; pooling gives the test its power.  ``active``: test only inside
    each case's active part, from the start to one T_c after its last re-clustering event, so
    that both kinds of peak crowding into the early, active part is not counted as alignment."""
    total_only = [{k: v for k, v in c.items() if k != "channels"} for c in cases]
    return an.pooled_channel_coincidence(total_only, window_frac, prominence, active, n_shifts,
                                         seed).get("total", {"cases": 0})


def null_models(cases: list, small: bool = False, shuffles: tuple | None = None) -> dict:
    """Fig. 7's slope and the pooled coincidence beside their null models
    (:mod:`mdgran.analysis.nulls`): the slope against (a) C_eff shifted in time against the
    segments, (b) another case's C_eff, (c) a random late segment instead of the largest-C_eff
    one; two selection-free measures (all segments weighted by length, within each case; the
    Spearman correlation of rate and C_eff over each case's active window) against the time
    shift; the coincidence at T_c / 4 for C_eff from all dissipation, viscous only and
    hysteresis only.  ``shuffles``: ``(K, K_long)`` shuffle counts instead of the defaults
    (100, 1000 small; 300, 10000), as :func:`realization_statistics` uses per realization."""
    from ..analysis import nulls

    nc = [c["null_case"] for c in cases]
    k, k_long = shuffles or ((100, 1000) if small else (300, 10000))
    obs = an.fig7_slope(nc)
    out = {"fig7_slope": obs, "fig7": {
        "C_eff shifted in time": an.null_summary(obs, an.time_shift(nc, n_shuffles=k, rng=0)),
        "another case's C_eff": an.null_summary(obs, an.swap_cases(nc, n_shuffles=k, rng=0)),
        "random late segment": an.null_summary(obs, an.random_late_null(nc, k, 0))}}
    om = nulls.observed_means(nc)
    within = an.segment_statistic(nc, om, "r", True)[0]
    out["selection_free"] = {
        "all segments, length-weighted correlation within cases": an.null_summary(
            within, an.time_shift(nc, an.segment_statistic, k_long // 10, 0, kind="r",
                                  center=True)),
        "Spearman of rate and C_eff over the active window": an.null_summary(
            an.rate_damping_correlation(nc), an.rate_damping_null(nc, k_long, 0))}
    out["coincidence_by_channel"] = {
        part: an.pooled_channel_coincidence(cases, 0.25, active=act, n_shifts=k_long)
        for part, act in (("active part", True), ("whole run", False))}
    return out


def nulls_markdown(nm: dict) -> list:
    """report.md's section on the null models (:func:`null_models`), with its claims rows."""
    def row(name, s):
        p = f"{s['p_value']:.2g}" + (" (floor)" if s["p_value"] <= s["p_floor"] else "")
        return (f"| {name} | {s['observed']:.3g} | {s['null_mean']:.3g} +- {s['null_sd']:.2g} | "
                f"{100 * s['fraction_positive']:.0f}% | {p} | {s['z']:.2g} | {s['K']} |")

    L = ["## Null models: Fig. 7 and the coincidence test", "",
         "Each observed statistic beside its null distribution (K shuffles; p one-sided with "
         "the +1 correction, so it cannot be below 1/(K+1); z = (observed - null mean) / null "
         "sd).", "", "| Fig. 7 slope against | observed | null | null > 0 | p | z | K |",
         "|---|---|---|---|---|---|---|"]
    L += [row(name, s) for name, s in nm["fig7"].items()]
    L += ["", "| selection-free measure | observed | time-shift null | null > 0 | p | z | K |",
          "|---|---|---|---|---|---|---|"]
    L += [row(name, s) for name, s in nm["selection_free"].items()]
    L += ["", "Pooled coincidence of C_eff peaks with rate peaks (window T_c / 4), by the "
          "dissipation C_eff is computed from:", "",
          "| part of the runs | C_eff from | fraction | null | p | z |", "|---|---|---|---|---|---|"]
    for part, by in nm["coincidence_by_channel"].items():
        for ch, r in by.items():
            z = (r["fraction"] - r["null_mean"]) / r["null_std"] if r["null_std"] else math.nan
            L.append(f"| {part} | {ch} | {r['fraction']:.3f} | {r['null_mean']:.3f} +- "
                     f"{r['null_std']:.3f} | {r['p_value']:.2g} | {z:.2g} |")
    return L + [""]


def null_verdicts(nm: dict) -> list:
    """Rows of the table of claims from :func:`null_models`."""
    f7 = nm["fig7"]["C_eff shifted in time"]
    sf = nm["selection_free"]["all segments, length-weighted correlation within cases"]
    act = nm["coincidence_by_channel"]["active part"]
    rows = [("Fig. 7: the representative segment's damping rises with its re-clustering rate",
             f"slope {nm['fig7_slope']:.3g}",
             f"time-shift null {f7['null_mean']:.3g} +- {f7['null_sd']:.2g} "
             f"({100 * f7['fraction_positive']:.0f}% > 0); selection-free within-case r "
             f"{sf['observed']:.2g} vs {sf['null_mean']:.2g} +- {sf['null_sd']:.2g}",
             ("largely built in by the selection" if f7["z"] < 3 else "beyond the selection's null")
             + ("; a relation survives without selection" if sf["z"] >= 3 else
                "; no relation without selection"))]
    if {"viscous", "hysteresis"} <= set(act):
        v, h = act["viscous"], act["hysteresis"]

        def z(r):
            return (r["fraction"] - r["null_mean"]) / r["null_std"] if r["null_std"] else 0.0

        rows.append(("C_eff peaks coincide with re-clustering peaks (damping follows "
                     "re-clustering)",
                     f"active part: hysteresis-only {h['fraction']:.2f} vs {h['null_mean']:.2f}"
                     f" (z {z(h):.2g}); viscous-only {v['fraction']:.2f} vs "
                     f"{v['null_mean']:.2f} (z {z(v):.2g})",
                     "time-shift null by dissipation channel",
                     "partly circular: hysteresis is booked at the snap-offs that form the "
                     "clusters" + ("; the viscous part coincides too" if z(v) >= 3 else
                                   "; the viscous part barely coincides")))
    return rows


# ---- realizations ---------------------------------------------------------------------------
#: shuffle counts ``(K, K_long)`` of :func:`null_models` per realization (small, full study)
REALIZATION_SHUFFLES = {True: (30, 200), False: (100, 1000)}
#: circular shifts of the pooled coincidence test per realization (small, full study)
REALIZATION_SHIFTS = {True: 200, False: 500}
#: how report.md and report.json describe the interval (:func:`interval_over_realizations`)
INTERVAL = ("95% Student-t interval of the mean over the K realizations: mean +- "
            "t(0.975, K-1) sd / sqrt(K), sd the sample standard deviation (ddof 1)")


def interval_over_realizations(values, level: float = 0.95) -> dict:
    """Mean of a statistic over realizations and the Student-t interval of that mean:
    ``mean +- t((1 + level) / 2, n - 1) * sd / sqrt(n)``, ``sd`` with ``ddof = 1``, over the
    ``n`` finite values of ``values`` (a realization where the statistic is undefined, NaN, is
    left out and counted in ``K - n``).  Identical values give ``sd = 0`` and a zero-width
    interval exactly.  With fewer than 2 finite values there is no interval (``sd``,
    ``half_width`` and ``interval`` None).  Also ``min`` and ``max`` (the spread of single
    realizations, which the interval of the mean is not)."""
    from scipy import stats

    v = np.asarray(values, float).ravel()
    fin = v[np.isfinite(v)]
    n = int(len(fin))
    out = {"K": int(len(v)), "n": n, "level": level,
           "mean": float(fin.mean()) if n else float("nan"),
           "min": float(fin.min()) if n else float("nan"),
           "max": float(fin.max()) if n else float("nan"),
           "sd": None, "half_width": None, "interval": None}
    if n >= 2:
        if np.all(fin == fin[0]):
            mean, sd = float(fin[0]), 0.0
        else:
            mean, sd = float(fin.mean()), float(np.std(fin, ddof=1))
        half = float(stats.t.ppf(0.5 + level / 2, n - 1) * sd / math.sqrt(n))
        out.update(mean=mean, sd=sd, half_width=half, interval=[mean - half, mean + half])
    return out


def realization_groups(cases: list) -> dict:
    """Sweep cases by realization (``params["realization"]``, 0 where absent), in order."""
    groups: dict = {}
    for c in cases:
        groups.setdefault(int(c["params"].get("realization", 0)), []).append(c)
    return dict(sorted(groups.items()))


def late_fig7_fit(cases: list) -> dict:
    """Fig. 7 after the impact transient without drawing it: the fit of
    :func:`mdgran.studies.paper_figures.fit_slope` on each case's representative segment starting at
    ``t >= T_c / 2`` (what ``numbers["fig7"]`` holds)."""
    rows = [c for c in cases if c.get("c_eff_late_segment") is not None
            and (c.get("c_eff_late_segment_rate") or 0) > 0]
    return pf.fit_slope(np.log10([c["c_eff_late_segment_rate"] for c in rows]),
                        [c["c_eff_late_segment"] for c in rows])


def _z(r: dict) -> float:
    if not r or not r.get("cases", 1) or not r.get("null_std"):
        return float("nan")
    return float((r["fraction"] - r["null_mean"]) / r["null_std"])


def study_statistics(fig7_fit: dict, coincidence: dict, nulls: dict | None = None) -> dict:
    """The study's statistics as ``{name: value}`` (NaN where undefined): the Fig. 7 slope after
    the impact transient (:func:`late_fig7_fit`), the pooled coincidence fraction and its z at
    T_c / 4 in the active part (:func:`pooled_coincidence`), and, given :func:`null_models`,
    the z of each of its nulls."""
    nan = float("nan")
    out = {"Fig. 7 slope (after the impact transient)": float(fig7_fit.get("slope", nan)),
           "pooled coincidence fraction (T_c/4, active part)":
               float(coincidence.get("fraction", nan)) if coincidence.get("cases") else nan,
           "pooled coincidence z (T_c/4, active part)": _z(coincidence)}
    if nulls:
        for name, r in nulls["fig7"].items():
            out[f"null z: Fig. 7 slope against {name}"] = float(r["z"])
        for name, r in nulls["selection_free"].items():
            out[f"null z: {name}"] = float(r["z"])
        for ch, r in nulls["coincidence_by_channel"]["active part"].items():
            out[f"null z: coincidence (T_c/4, active part), C_eff from {ch}"] = _z(r)
    return out


def pooled_statistics(numbers: dict) -> dict:
    """:func:`study_statistics` of the report's numbers (every case, all realizations pooled)."""
    co = next((r for r in numbers.get("coincidence_pooled", [])
               if r.get("range") == "active part" and r.get("window_T_c") == 0.25), {})
    return study_statistics(numbers.get("fig7", {}), co, numbers.get("nulls"))


def realization_statistics(cases: list, small: bool = False, pooled: dict | None = None,
                           nulls: bool = True, n_shifts: int | None = None,
                           shuffles: tuple | None = None) -> dict:
    """Every statistic of :func:`study_statistics` computed on each realization's cases alone
    (:func:`realization_groups`), with small shuffle counts (:data:`REALIZATION_SHIFTS`,
    :data:`REALIZATION_SHUFFLES`, or ``n_shifts``, ``shuffles``); ``nulls=False`` leaves out the
    null models.  Returns ``{"K", "realizations", "interval", "statistics": {name: {"values"
    [K], "pooled" (from ``pooled``, the all-realization value, or None), and
    :func:`interval_over_realizations`}}}``."""
    groups = realization_groups(cases)
    n_shifts = n_shifts or REALIZATION_SHIFTS[bool(small)]
    shuffles = shuffles or REALIZATION_SHUFFLES[bool(small)]
    per = []
    for group in groups.values():
        co = pooled_coincidence(group, 0.25, n_shifts=n_shifts, active=True)
        nm = null_models(group, small, shuffles) if nulls else None
        per.append(study_statistics(late_fig7_fit(group), co, nm))
    names = list(dict.fromkeys(k for p in per for k in p))
    pooled = pooled or {}
    stats = {}
    for name in names:
        values = [p.get(name, float("nan")) for p in per]
        stats[name] = {"values": values, "pooled": pooled.get(name),
                       **interval_over_realizations(values)}
    return {"K": len(groups), "realizations": list(groups), "interval": INTERVAL,
            "statistics": stats}


def realizations_markdown(rz: dict) -> list:
    """report.md's "Realizations" section (:func:`realization_statistics`)."""
    L = ["## Realizations", ""]
    if rz["K"] < 2:
        return L + ["One realization per grid point: every statistic above is that of one "
                    "realization of a chaotic system, with no interval over realizations. "
                    "(`realizations = K` in the sweep's `[sweep]` table runs K, each with the "
                    "impulse velocity perturbed: `mdgran/studies/sweep.py`.)", ""]
    eps = rz.get("perturbation")
    L += [f"{rz['K']} realizations of each grid point"
          + (f", realization r with the impulse velocity v0 (1 + r x {eps:g})" if eps else "")
          + ": past the predictability horizon each is one realization of a chaotic system. "
          "Each statistic computed on each realization's cases alone (shuffle counts per "
          f"realization: {rz.get('shuffles', '')}), its mean and the {INTERVAL}; "
          "min to max is the spread of single realizations. 'Pooled' is the value over every "
          "case of every realization (the numbers in the sections above): realizations of one "
          "grid point share their early, predictable part, so the pooled Fig. 7 interval is "
          "too narrow and the 'another case's C_eff' null may swap a case with its own "
          "realization.", "",
          "| statistic | pooled (all realizations) | mean over realizations | 95% interval "
          "of the mean | sd | min to max | per realization |",
          "|---|---|---|---|---|---|---|"]
    for name, s in rz["statistics"].items():
        ci = (f"{s['interval'][0]:.3g} to {s['interval'][1]:.3g}" if s["interval"] else
              "- (fewer than 2 defined)")
        each = ", ".join(_fmt(v) if np.isfinite(v) else "-" for v in s["values"])
        pooled = s["pooled"]
        L.append(f"| {name} | {_fmt(pooled) if pooled is not None and np.isfinite(pooled) else '-'}"
                 f" | {_fmt(s['mean'])} | {ci} | {_fmt(s['sd'])} | {_fmt(s['min'])} to "
                 f"{_fmt(s['max'])} | {each} |")
    return L + [""]


def smoothing_sensitivity(traj) -> list:
    """Peak C_eff / C_+ and the coincidence p-value for several smoothing times (the clusters,
    which do not depend on it, followed once: ``traj.measures.history``)."""
    m = traj.measures
    rows = []
    for tau in (5.0, 10.0, 20.0):
        cb = m.c_eff if tau == an.SMOOTHING_TIME else an.effective_damping(traj, smoothing_time=tau)
        rc = an.analyze_reclustering(traj, cb, smoothing_time=tau, history=m.history)
        co = an.run_coincidence(traj, smoothing_time=tau, c_eff=cb, reclustering=rc)
        rows.append({"smoothing_time": tau, "c_eff_peak": float(cb.max()),
                     "c_eff_mean": float(cb.mean()), "p_value": co["p_value"],
                     "fraction": co["fraction"]})
    return rows


#: the paper's Table II (SI): bead diameter d, wire length L_s, wire diameter d_s, K_1, wire
#: tension T_s and the stress column sigma_y it prints
TABLE_II = ({"d": 2.5e-6, "L_s": 6.25e-6, "d_s": 1e-6, "K_1": 21.5, "T_s": 67.2e-6,
             "sigma_y": 2.19e6},
            {"d": 2.5e-3, "L_s": 6.25e-3, "d_s": 1e-3, "K_1": 2150.0, "T_s": 6.72,
             "sigma_y": 0.219e6})


def paper_details() -> dict:
    """Two details of the paper the report states: (1) Table II's stress column is T_s over a
    circle of the wire's *length* as diameter, T_s / (pi L_s^2 / 4), not T_s / A_s with
    A_s = pi d_s^2 / 4; (2) the COS relation the paper uses for fc against the exact
    Maugis-Dugdale pull-off (:func:`mdgran.model.contact.maugis_dugdale_pulloff`)."""
    from ..model.contact import fc_from_lambda, maugis_dugdale_pulloff

    wires = [{"d": r["d"], "printed_MPa": r["sigma_y"] / 1e6,
              "T_s_over_pi_L_s2_4_MPa": r["T_s"] / (math.pi * r["L_s"] ** 2 / 4) / 1e6,
              "T_s_over_A_s_MPa": r["T_s"] / (math.pi * r["d_s"] ** 2 / 4) / 1e6,
              "K_1_from_2_T_s_over_L_s": 2 * r["T_s"] / r["L_s"], "K_1_printed": r["K_1"]}
             for r in TABLE_II]
    pulloff = [{"lambda": lam, "cos": fc_from_lambda(lam, "cos"),
                "maugis_dugdale": maugis_dugdale_pulloff(lam)} for lam in (0.3, 0.64, 1.5)]
    for p in pulloff:
        p["cos_over_md_minus_1"] = p["cos"] / p["maugis_dugdale"] - 1.0
    return {"table_II": wires, "pull_off": pulloff}


def paper_details_markdown(pd: dict) -> list:
    L = ["## Details of the paper", "",
         "Table II's stress column equals the wire tension over a circle whose diameter is the "
         "wire's length, T_s / (pi L_s^2 / 4); the tensile stress in the wire is T_s / A_s "
         "with A_s = pi d_s^2 / 4:", "",
         "| bead d | printed | T_s / (pi L_s^2/4) | T_s / A_s | K_1 = 2 T_s / L_s (printed) |",
         "|---|---|---|---|---|"]
    for w in pd["table_II"]:
        L.append(f"| {w['d']:g} m | {w['printed_MPa']:.3g} MPa | "
                 f"{w['T_s_over_pi_L_s2_4_MPa']:.3g} MPa | {w['T_s_over_A_s_MPa']:.3g} MPa | "
                 f"{w['K_1_from_2_T_s_over_L_s']:.4g} N/m ({w['K_1_printed']:g}) |")
    L += ["", "The paper's COS relation for the pull-off force fc (units of pi R w) against "
          "the exact Maugis-Dugdale pull-off (`contact.fc_rule = \"maugis-dugdale\"` runs "
          "with it):", "", "| lambda | COS | exact MD | COS overstates by |", "|---|---|---|---|"]
    for p in pd["pull_off"]:
        L.append(f"| {p['lambda']:g} | {p['cos']:.4f} | {p['maugis_dugdale']:.4f} | "
                 f"{100 * p['cos_over_md_minus_1']:.1f}% |")
    return L + ["", "The COS relation tends to -1.515 as lambda grows and never reaches the JKR "
                "limit -1.5; the exact pull-off does.", ""]


def controls_markdown(ctl: dict) -> list:
    """report.md's section on the controls of the macro/micro comparison
    (mdgran.studies.controls)."""
    L = ["## What survives: the controls of the macro/micro comparison", "",
         "The paper matches its macro chain to the micro chain by equal primary-pulse speed in "
         "nondimensional units. Two controls: the macro chain struck at the micro chain's "
         "impulse in m/s, and the macro chain given the Schwarz law at its own Maugis "
         "parameter (adhesion at macro scale), at the paper's matching.", ""]
    if ctl["vs_micro"]:
        L += ["![controls](figures/controls.png)", ""]
    L += ["| run | backend | status | law (lambda) | v0 (p q) | v0 (m/s) | T_c | new clusters "
          "| T < T(0)/e at | T < T(0)/10 at |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in ctl["runs"].items():
        lam = f" ({r['lambda']:.3g})" if r["lambda"] is not None else ""
        L.append(f"| {name} | {r['backend']} | {r['status']} | {r['law']}{lam} | "
                 f"{r['impulse_velocity']:.4g} | {r['impulse_m_per_s']:.3g} | {r['T_c']:.3g} | "
                 f"{r['clusters_formed']} | {_tc(r['decay_1e_over_T_c'])} | "
                 f"{_tc(r['decay_10pct_over_T_c'])} |")
    for name, why in ctl["missing"].items():
        L.append(f"| {name} | {why} | | | | | | | | |")
    L += ["", "macro-si runs on LAMMPS with the law evaluated exactly: at 3.8e3 p q its "
          "Hertz contacts compress beyond 100 p, past the fast and LAMMPS tables, and the "
          "reference stops on a chattering contact.", "",
          "| claim (paper) | mdgran's measurement | control | verdict |", "|---|---|---|---|"]
    L += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in controls.verdicts(ctl)]
    return L + [""]


def markdown(nb: dict, cases: list, small: bool) -> str:
    """``report.md``: the study's numbers ``nb`` (:func:`make_report`) as Markdown, section
    by section; the sweep's sections only with ``cases``."""
    L = _intro_markdown(nb, small)
    L += _fig2_markdown(nb["decay"], nb["fig2"])
    L += _fig3_markdown(nb["fig3"])
    L += _coincidence_markdown(nb)
    if cases:
        L += _sweep_markdown(nb, cases)
    if nb.get("beyond"):
        L += _beyond_markdown(nb["beyond"])
    if "long_chain" in nb:
        L += long_chain_markdown(nb["long_chain"])
    return "\n".join(L) + "\n"


def _intro_markdown(nb: dict, small: bool) -> list:
    """The report's title and units, the run status, the small-version warning, the
    controls, the paper's details and the null models with their verdicts."""
    f2 = nb["fig2"]
    L = ["# mdgran report: the paper's study", "",
         "All quantities nondimensional (time in 1/q, energy in eta p); time axes in "
         "characteristic periods T_c (the primary pulse's double crossing time: "
         f"micro-star {f2['T_c']['micro']:.3g}, macro-hertz {f2['T_c']['macro']:.3g}).", ""]
    L += status_markdown(nb)
    if small:
        L += ["**Small version** (the sweep's CI-sized grid): the sweep figures and Fig. 7 "
              "have too few cases to mean anything; run without --small for the study.", ""]
    L += controls_markdown(nb["controls"])
    L += paper_details_markdown(nb["paper_details"])
    if "nulls" in nb:
        L += nulls_markdown(nb["nulls"])
        L += ["| claim (paper) | mdgran's measurement | null | verdict |", "|---|---|---|---|"]
        L += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in null_verdicts(nb["nulls"])]
        L += [""]
    return L


def _fig2_markdown(d: dict, f2: dict) -> list:
    """Fig. 2: the kinetic energy T / T(0) of the micro and macro chains at multiples of T_c
    with its decay times (``d``: :func:`kinetic_decay`), and their C_eff / C_+."""
    at = d["micro"]["T_over_T0_at_multiples_of_T_c"]
    L = ["## Fig. 2: macro vs micro chain", "", "![fig2](figures/fig2.png)", "",
         "Kinetic energy T / T(0), running mean over one T_c, at multiples of T_c:", "",
         "| chain | " + " | ".join(f"{k} T_c" for k in at)
         + " | falls below 1/e at | below 1/10 at |",
         "|---|" + "---|" * (len(at) + 2)]
    for name in ("micro", "macro"):
        row = d[name]
        vals = [row["T_over_T0_at_multiples_of_T_c"].get(k) for k in at]
        L.append(f"| {name} | " + " | ".join(_fmt(v) for v in vals) +
                 f" | {_fmt(row['decay_1e_over_T_c'])} T_c | {_fmt(row['decay_10pct_over_T_c'])} "
                 "T_c |")
    return L + ["", f"C_eff / C_+: micro peak {f2['micro']['c_eff_peak']:.3g}, mean "
                f"{f2['micro']['c_eff_mean']:.3g}; macro peak {f2['macro']['c_eff_peak']:.3g}, "
                f"mean {f2['macro']['c_eff_mean']:.3g}.", ""]


def _fig3_markdown(f3: dict) -> list:
    """Fig. 3: the clusters with their linearized modes and wavelet ridges."""
    L = ["## Fig. 3: clusters and their linearized modes", "", "![fig3](figures/fig3.png)", "",
         "| cluster | beads | walls | time | omega_1 | omega_2 | wavelet ridge (median) |",
         "|---|---|---|---|---|---|---|"]
    for r in f3["clusters"]:
        L.append(f"| {r['cluster']} | {r['beads'][0]}-{r['beads'][1]} | "
                 f"{'L' if r['walls'][0] else ''}{'R' if r['walls'][1] else ''} | "
                 f"{r['t'][0]:.1f}-{r['t'][1]:.1f} | {r['omega_1']:.3g} | {r['omega_2']:.3g} | "
                 f"{r['wavelet_ridge_median']:.3g} |")
    return L


def _coincidence_markdown(nb: dict) -> list:
    """Figs. 4 and 5, and the coincidence of C_eff peaks with re-clustering-rate peaks in
    the micro chain: the test, its variants over window and prominence, and its sensitivity
    to the splines' smoothing time."""
    co = nb["fig5"]
    L = ["", "## Fig. 4: relative velocity amplitude", "", "![fig4](figures/fig4.png)", "",
         "## Fig. 5: re-clustering rate and effective damping", "", "![fig5](figures/fig5.png)",
         "", f"Coincidence of C_eff peaks with re-clustering-rate peaks (window T_c): "
         f"{co['fraction']:.2f} of {co['n_a']} C_eff peaks lie within T_c of one of "
         f"{co['n_b']} rate peaks, against {co['null_mean']:.2f} +- {co['null_std']:.2f} "
         f"for 1000 random circular shifts of the rate peaks: p = {co['p_value']:.3f}.", "",
         "Variants (peak prominence as a fraction of each curve's range; the null shifts the "
         "second set of peaks):", "",
         "| window | prominence | test | fraction | shifted (mean) | p | peaks tested | "
         "other peaks |", "|---|---|---|---|---|---|---|---|"]
    for r in nb["coincidence_windows"]:
        L.append(f"| {r['window_T_c']:g} T_c | {r['prominence']:g} | {r['direction']} | "
                 f"{r['fraction']:.2f} | {r['null_mean']:.2f} | {r['p_value']:.3f} | {r['n']} | "
                 f"{r['n_other']} |")
    L += ["", "Smoothing time of the C_eff and rate splines (default 10):", "",
          "| smoothing time | C_eff peak | C_eff mean | coincidence fraction | p |",
          "|---|---|---|---|---|"]
    for r in nb["smoothing"]:
        L.append(f"| {r['smoothing_time']:g} | {r['c_eff_peak']:.3g} | {r['c_eff_mean']:.3g} | "
                 f"{r['fraction']:.2f} | {r['p_value']:.3f} |")
    return L


def _sweep_markdown(nb: dict, cases: list) -> list:
    """The sweep's sections: the coincidence test pooled over its ``cases``, Figs. 6 and
    B1-B3, the Fig. 7 fits and the statistics per realization."""
    L = ["", "Pooled over the sweep's cases (each case's rate peaks shifted independently):",
         "", "| window | range | cases | C_eff peaks | rate peaks | fraction | shifted "
         "(mean +- sd) | p |", "|---|---|---|---|---|---|---|---|"]
    for r in nb["coincidence_pooled"]:
        if r.get("cases"):
            L.append(f"| {r['window_T_c']:g} T_c | {r['range']} | {r['cases']} | "
                     f"{r['c_eff_peaks']} | "
                     f"{r['rate_peaks']} | {r['fraction']:.3f} | {r['null_mean']:.3f} +- "
                     f"{r['null_std']:.3f} | {r['p_value']:.3g} |")
    L += ["", f"## Figs. 6, B1-B3: the sweep ({len(cases)} cases)", "",
          "![fig6](figures/fig6.png)", "", "![figB1](figures/figB1.png)", "",
          "![figB2](figures/figB2.png)", "", "![figB3](figures/figB3.png)", "",
          "## Fig. 7: maximum segment C_eff against re-clustering rate", "",
          "![fig7](figures/fig7.png)", "", "![fig7 literal](figures/fig7_literal.png)", ""]
    for key, label in (("fig7", "after the impact transient"),
                       ("fig7_literal", "literal rule")):
        L.append(_fig7_line(label, nb[key]))
    if "realizations" in nb:
        L += [""] + realizations_markdown(nb["realizations"])
    return L


def _fig7_line(label: str, f: dict) -> str:
    """One Fig. 7 fit ``f`` (:func:`mdgran.studies.paper_figures.fit_slope` with its
    correlations) as a bullet, or why there is none."""
    if "slope" not in f:
        return f"* {label}: too few cases for a fit (n = {f['n']})."
    return (f"* {label}: slope {f['slope']:.3g} (95% CI {f['slope_ci95'][0]:.3g} "
            f"to {f['slope_ci95'][1]:.3g}), Pearson r = {f['pearson_r']:.2f} "
            f"(p = {f['p_value']:.2g}), Spearman rho = {f['spearman_rho']:.2f} "
            f"(p = {f['spearman_p']:.2g}), n = {f['n']}.")


def _beyond_markdown(beyond: dict) -> list:
    """"Beyond the paper": a row per sweep of ``beyond`` (Fig. 7 fit, pooled coincidence,
    ledger error) and its figure."""
    L = ["", "## Beyond the paper", "",
         "The same measures on longer chains and over the adhesion parameter lambda "
         "(representative segment after the impact transient; coincidence window T_c/4, "
         "pooled over each sweep's cases):", "",
         "| sweep | beads | backend | cases | Fig. 7 slope (95% CI) | Spearman rho (p) | "
         "C_eff peaks near a rate peak | shifted | p | max ledger error |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    L += [_beyond_row(name, b) for name, b in beyond.items()]
    L.append("")
    return L + [f"![{name}](figures/beyond-{name}.png)" for name in beyond]


def _beyond_row(name: str, b: dict) -> str:
    """The table row of one beyond-the-paper sweep ``b``; '-' where a fit or the pooled
    test has too few cases."""
    f, co = b["fig7"], b["coincidence_pooled"]
    fit = (f"{f['slope']:.3g} ({f['slope_ci95'][0]:.3g} to {f['slope_ci95'][1]:.3g})"
           if "slope" in f else f"- (n = {f['n']})")
    rho = f"{f['spearman_rho']:.2f} ({f['spearman_p']:.2g})" if "slope" in f else "-"
    cof = (f"{co['fraction']:.3f} | {co['null_mean']:.3f} +- {co['null_std']:.3f} | "
           f"{co['p_value']:.3g}" if co.get("cases") else "- | - | -")
    return (f"| {name} | {b['n']} | {b['backend']} | {b['cases']} | {fit} | {rho} | {cof} | "
            f"{_fmt(b['max_ledger_error'])} |")
