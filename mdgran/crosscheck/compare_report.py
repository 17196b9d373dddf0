"""Writing a comparison: ``report.json``, ``report.md`` and PNG figures (see
mdgran.crosscheck.compare)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..output.storage import write_atomic


def _adhesive(scene) -> bool:
    """Does the scene's contact law stick (Schwarz, JKR, DMT: snap-off and snap-to events) or
    not (Hertz: contacts only separate and touch)?"""
    return scene.contact.law != "hertz"


def event_labels(scene) -> tuple:
    """Legend labels of (open, close) events: snap-off/snap-to only where the law adheres."""
    if _adhesive(scene):
        return "open (snap-off)", "close (snap-to)"
    return "open (separate)", "close (touch)"


#: Line style of each backend in the figures where their curves overlap (the first, the
#: reference, is drawn wide and pale underneath, the others narrower, dashed, on top).
BACKEND_STYLES = [dict(ls="-", lw=2.6, alpha=0.55), dict(ls="--", lw=1.2, alpha=1.0),
                  dict(ls=":", lw=1.4, alpha=1.0), dict(ls="-.", lw=1.2, alpha=1.0)]
#: The predictability horizon: black, dash-dot, never a backend's colour.
HORIZON_STYLE = dict(color="k", ls="-.", lw=1.0)


def _write_figure(plt, fig, path: Path, rect=None):
    """Lay ``fig`` out (its panels within ``rect`` of the figure, all of it by default), write
    it to ``path`` (PNG, 110 dpi) and close it."""
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _figures(out: Path, scene, runs, pred, report, pairs):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    scale = scene.energy_scale or 1.0
    styles = ["-", "--", ":", "-."]
    # energies
    fig, ax = plt.subplots(figsize=(11, 4.5))
    names = {"kinetic_energy": "kinetic", "contact_energy": "contact",
             "substrate_energy": "substrate", "dissipated_viscous": "dissipated, viscous",
             "dissipated_hysteresis": "dissipated, hysteresis"}
    for r, ls in zip(runs, styles):
        for i, (key, label) in enumerate(names.items()):
            ax.plot(r.nominal.time, r.nominal.ledger[key] / scale, ls, color=f"C{i}", lw=1.2,
                    label=f"{label} ({r.name})")
    ax.set(xlabel="time (1/q)", ylabel="energy / E_imp",
           title=f"{scene.name}: energy ledger terms ({', '.join(r.name for r in runs)})")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    _write_figure(plt, fig, out / "energies.png")
    # ledger error
    fig, ax = plt.subplots(figsize=(8, 4))
    for r, ls in zip(runs, styles):
        e = np.abs(r.nominal.ledger_error())
        ax.semilogy(r.nominal.time, np.maximum(e, 1e-17), ls, label=r.name)
    ax.set(xlabel="time (1/q)", ylabel="|E(t) - E0| / E_imp",
           title="energy-ledger error of each backend")
    ax.legend()
    _write_figure(plt, fig, out / "ledger_error.png")
    # differences
    fig, ax = plt.subplots(figsize=(8, 4.5))
    ref = runs[0]
    t = ref.nominal.time
    ax.semilogy(pred["time"], np.maximum(pred["difference"], 1e-18), color="0.6",
                label=f"{ref.name}: impulse x (1 + 1e-12)")
    ax.semilogy(t[: len(ref.error)], np.maximum(ref.error, 1e-18), color="C0", lw=0.8,
                label=f"{ref.name}: own error estimate")
    for i, r in enumerate(runs[1:], start=1):
        d = np.max(np.abs(r.nominal.x[: len(t)] - ref.nominal.x[: len(r.nominal.time)]), axis=1)
        tt = t[: len(d)]
        ax.semilogy(tt, np.maximum(d, 1e-18), color=f"C{i}", lw=1.5,
                    label=f"{r.name} - {ref.name}")
        safety = report["thresholds"]["safety"]
        ax.semilogy(tt, safety * (r.error[: len(d)] + ref.error[: len(d)]), ":",
                    color=f"C{i}", label=f"allowed for {r.name}: {safety:g} x (own errors)")
        # black for every pair (never a backend's colour); with several pairs, one style each
        hstyle = {**HORIZON_STYLE, "ls": ["-.", (0, (6, 2)), (0, (1, 1)), "-"][(i - 1) % 4]}
        ax.axvline(report["pairs"][r.name]["horizon"], **hstyle,
                   label=f"predictability horizon, {r.name} vs {ref.name} "
                         f"(t = {report['pairs'][r.name]['horizon']:.4g})")
    ax.set(xlabel="time (1/q)", ylabel="max_i |x_i - x_i'| (units of p)",
           title="difference between backends (black vertical line: predictability horizon)")
    ax.legend(fontsize=7)
    _write_figure(plt, fig, out / "difference.png")
    # event timelines
    fig, axs = plt.subplots(1, len(runs), figsize=(4 * len(runs) + 1, 4.5), sharey=True,
                            squeeze=False)
    open_label, close_label = event_labels(scene)
    for ax, r in zip(axs[0], runs):
        tr = r.nominal
        for kind, mk, col, lab in ((0, "v", "C3", open_label), (1, "^", "C2", close_label)):
            sel = tr.ev_kind == kind
            ax.plot(tr.ev_time[sel], tr.ev_contact[sel], mk, color=col, ms=4, label=lab)
        ax.set(xlabel="time (1/q)", title=f"{r.name}: {len(tr.ev_time)} contact events")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # contacts are numbered
        ax.grid(alpha=0.3)
    axs[0][0].set_ylabel("contact (i joins bead i-1 and i)")
    # above the panels: inside, it hid the events of a busy run (macro-hertz has ~1700)
    fig.legend(*axs[0][0].get_legend_handles_labels(), loc="upper center", ncol=2, fontsize=8,
               frameon=False)
    _write_figure(plt, fig, out / "events.png", rect=(0, 0, 1, 0.94))
    _cluster_figures(out, runs, report, pairs, plt)


def _cluster_figures(out, runs, report, pairs, plt):
    """clusters.png: clusters over time, cumulative new clusters, lifetime distributions;
    c_eff.png: the effective damping of each backend on the same axes."""
    from matplotlib.ticker import MaxNLocator

    horizon = min(info["horizon"] for info in report["pairs"].values()) if report["pairs"] \
        else None
    style = {r.name: {"color": f"C{i}", **BACKEND_STYLES[i % len(BACKEND_STYLES)]}
             for i, r in enumerate(runs)}
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.2))
    for r in runs:
        tr = r.nominal
        h = tr.measures.history
        # step functions of time: drawn as steps, the reference wide and pale underneath, the
        # others dashed on top, so that where they coincide both stay visible
        a1.plot(tr.time, h.count_at(tr.time), drawstyle="steps-post", label=r.name,
                **style[r.name])
        a2.plot(tr.time, h.cumulative_at(tr.time), drawstyle="steps-post", label=r.name,
                **style[r.name])
    for name, info in pairs.items():
        lives = info["clusters"]["lives"]
        for i, (who, lv) in enumerate(lives.items()):
            if len(lv):
                x = np.sort(lv.lifetime)
                st = style.get(who, {"color": f"C{i}", **BACKEND_STYLES[i % 4]})
                a3.step(x, np.arange(1, len(x) + 1) / len(x), where="post",
                        label=f"{who}: {len(x)} clusters", **st)
        lt = report["pairs"][name]["clusters"]["lifetimes"]
        if lt["pvalue"] is not None:
            a3.set_title(f"cluster lifetimes {info['clusters']['where']}\n"
                         f"(ensembles; KS p = {lt['pvalue']:.2g})", fontsize=9)
    for ax in (a1, a2):
        if horizon is not None:
            ax.axvline(horizon, label="predictability horizon", **HORIZON_STYLE)
        ax.set_xlabel("time (1/q)")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # counts
        ax.legend(fontsize=7)
    a1.set(ylabel="clusters", title="number of clusters (dash-dot: horizon)")
    a2.set(ylabel="newly formed clusters, cumulative", title="cumulative new clusters")
    a3.set(xscale="log", xlabel="cluster lifetime (1/q)", ylabel="cumulative fraction")
    if a3.get_legend_handles_labels()[0]:
        a3.legend(fontsize=7)
    _write_figure(plt, fig, out / "clusters.png")
    fig, ax = plt.subplots(figsize=(8, 4))
    for r in runs:
        ax.plot(r.nominal.time, r.nominal.measures.c_eff, label=r.name,
                **style[r.name])
    if horizon is not None:
        ax.axvline(horizon, label="predictability horizon", **HORIZON_STYLE)
    ax.set(xlabel="time (1/q)", ylabel="C_eff / C_+",
           title="effective damping, Eq. 9 (dash-dot: horizon)")
    ax.legend()
    _write_figure(plt, fig, out / "c_eff.png")


def _markdown(scene, runs, report) -> str:
    p = report["predictability"]
    lines = [
        f"# Comparison: {scene.name}",
        "",
        f"**Verdict: {'PASS' if report['passed'] else 'FAIL'}** "
        f"({sum(c['passed'] for c in report['criteria'])} of {len(report['criteria'])} "
        f"criteria pass). Backends: {', '.join(report['backends'])} (the first is the reference).",
        "",
        "## Criteria",
        "",
        "| criterion | verdict | measured | threshold | detail |",
        "|---|---|---|---|---|",
    ]
    for c in report["criteria"]:
        verdict = ("pass" if c["passed"] else "**FAIL**") if c["judged"] else "not judged"
        measured = f"{c['measured']:.3g}" if c["judged"] else "-"
        lines.append(f"| {c['name']} | {verdict} | {measured} | {c['threshold']:.3g} | "
                     f"{c['detail']} |")
    lines += [
        "",
        "## Predictability",
        "",
        f"The reference run with the impulse (and any force pulse or base motion) scaled by 1 + {p['perturbation']:g} (relative) departs "
        f"from the nominal run by a factor {p['amplification']:.3g} at most (reached at "
        f"t = {p['t_max_difference']:.4g}); finite-time Lyapunov exponent "
        f"{p['ftle']:.3g} per time unit. A backend pair is judged up to its horizon: the first "
        f"time either backend's own error estimate exceeds {report['thresholds']['predictable_p']:g} p.",
        "",
        "| pair | horizon | events compared | max event time offset | events in the whole run "
        "| whole-run sequence identical (not judged) |",
        "|---|---|---|---|---|---|",
    ]
    for name, info in report["pairs"].items():
        lines.append(f"| {name} vs {report['backends'][0]} | {info['horizon']:.4g} | "
                     f"{info['events_compared']} | {info['max_event_time_offset']:.3g} | "
                     f"{info['events_whole_run'][0]} vs {info['events_whole_run'][1]} | "
                     f"{'yes' if info['whole_run_sequence_identical'] else 'no'} |")
    lines += ["", "## Runs", "", "| backend | wall time (s) | ledger error / E_imp | "
              "refined run's | events | max own error (p) |", "|---|---|---|---|---|---|"]
    for name, r in report["runs"].items():
        lines.append(f"| {name} | {r['wall_s']:.2f} | {r['ledger_error']:.3g} | "
                     f"{r['ledger_error_refined']:.3g} | {r['events']} | "
                     f"{r['max_own_error']:.3g} |")
    lines += [
        "",
        "## Figures",
        "",
        "![energies](energies.png)",
        "",
        "![ledger error](ledger_error.png)",
        "",
        "![difference](difference.png)",
        "",
        "![events](events.png)",
        "",
        "![clusters](clusters.png)",
        "",
        "![effective damping](c_eff.png)",
        "",
        "How to read: each backend's own error estimate is the difference between its nominal "
        "run and a refined run (1/100 of the tolerance for the reference; half the time step "
        "for fixed-step backends, scaled by Richardson's factor). The backends agree when their "
        f"difference stays below {report['thresholds']['safety']:g} times the sum of those "
        "estimates.",
    ]
    return "\n".join(lines) + "\n"


def write_report(out: Path, scene, runs, pred, report, pairs):
    _figures(out, scene, runs, pred, report, pairs)
    write_atomic(out / "report.json", json.dumps(report, indent=2, default=float) + "\n")
    write_atomic(out / "report.md", _markdown(scene, runs, report))


def write_failure(out: Path, scene, report):
    """The report of a comparison a backend's run failed in
    (:func:`mdgran.crosscheck.compare.compare`): which backend, why, and the runs done before it."""
    f = report["failed"]
    lines = [f"# Comparison of {scene.name}: FAIL", "",
             f"The run on **{f['backend']}** failed: {f['error']}", "",
             "Nothing is judged. Its file holds its frames up to the failure (status "
             "`failed: ...`).", ""]
    if report["runs"]:
        lines += ["Runs done before it:", "", "| backend | status | ledger error | bound |",
                  "|---|---|---|---|"]
        lines += [f"| {name} | {r['status']} | {r['ledger_error']:.3g} | "
                  f"{r['ledger_bound']:.3g} |" for name, r in report["runs"].items()]
    write_atomic(out / "report.json", json.dumps(report, indent=2, default=float) + "\n")
    write_atomic(out / "report.md", "\n".join(lines) + "\n")
