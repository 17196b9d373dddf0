"""The paper's figures, drawn from runs and sweep results through :mod:`mdgran.analysis`.

One function per figure; each takes runs (:class:`~mdgran.output.run_record.Run`, whose cached
``measures`` it reads) or sweep case tables, draws onto a new matplotlib figure, saves it as PNG
and returns the numbers it shows (for the report).  Time is
shown in characteristic periods ``T_c`` (the primary pulse's double crossing time, see
:mod:`mdgran.analysis.pulse`), as in the paper; energies over the impulse energy.
"""
from __future__ import annotations

import math

import numpy as np

from .. import analysis as an
from ..analysis.statistics import cluster_lives

DPI = 120
#: Font size (points) of tick labels in the dense grid figures (B1-B3): 8 pt is 13 px at DPI.
TICK_PT = 8


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path):
    fig.savefig(path, dpi=DPI)
    _plt().close(fig)


def _tc(run):
    tc = run.measures.characteristic_period
    return tc if np.isfinite(tc) and tc > 0 else 1.0


def _energy_map(ax, traj, tc, boundaries=True, title="", cbar=True, vmax=1.0):
    """Beads (vertical) x time (horizontal) map of T_i / max_j T_j, cluster boundaries as lines."""
    emap = an.kinetic_energy_map(traj)
    t = traj.time / tc
    im = ax.imshow(emap.T, aspect="auto", origin="lower", cmap="magma", vmin=0, vmax=vmax,
                   extent=(t[0], t[-1], 0.5, traj.n + 0.5), interpolation="nearest")
    if boundaries:
        _draw_boundaries(ax, traj, tc)
    ax.set(xlabel="time / T_c", ylabel="bead", title=title)
    ax.yaxis.get_major_locator().set_params(integer=True)
    if cbar:
        ax.figure.colorbar(im, ax=ax, label="T_i / max_j T_j", pad=0.01)
    return im


def _draw_boundaries(ax, traj, tc, color="c", lw=0.6):
    """A horizontal segment at height k - 1/2 wherever contact k is open (between beads)."""
    open_ = an.boundary_map(traj)  # [F, n_contacts], contract order
    t = traj.time / tc
    for j, k in enumerate(traj.contact_numbers):
        o = open_[:, j].astype(np.int8)
        edges = np.flatnonzero(np.diff(np.concatenate(([0], o, [0]))))
        for a, b in zip(edges[::2], edges[1::2]):
            ax.plot([t[a], t[min(b, len(t) - 1)]], [k - 0.5, k - 0.5], color=color, lw=lw)


# ---- Fig. 2 ------------------------------------------------------------------------------------
def fig2(micro, macro, path) -> dict:
    """(a) macro and (b) micro kinetic-energy maps, (c) T / E_imp, (d) C_eff / C_+."""
    plt = _plt()
    fig = plt.figure(figsize=(12, 8.5))
    gs = fig.add_gridspec(3, 2, height_ratios=[1, 1, 1.1])
    tcs = {"micro": _tc(micro), "macro": _tc(macro)}
    _energy_map(fig.add_subplot(gs[0, :]), macro, tcs["macro"], boundaries=False,
                title=f"(a) macro-hertz: kinetic energy per bead, normalized per instant "
                      f"(T_c = {tcs['macro']:.3g})")
    _energy_map(fig.add_subplot(gs[1, :]), micro, tcs["micro"],
                title=f"(b) micro-star: the same, cluster boundaries (open contacts) in cyan "
                      f"(T_c = {tcs['micro']:.3g})")
    axc, axd = fig.add_subplot(gs[2, 0]), fig.add_subplot(gs[2, 1])
    out = {"T_c": tcs}
    for tr, name, col in ((macro, "macro", "C0"), (micro, "micro", "C3")):
        t = tr.time / tcs[name]
        e_imp = tr.scene.impulse_energy
        axc.plot(t, tr.ledger["kinetic_energy"] / e_imp, color=col, lw=0.6, alpha=0.45)
        axc.plot(t, an.smoothed_kinetic(tr) / e_imp, color=col, lw=1.6, label=f"{name}: <<T>>")
        cbar = tr.measures.c_eff
        axd.plot(t, cbar, color=col, lw=1.4, label=name)
        out[name] = {"kinetic_remaining": tr.measures.summary["kinetic_remaining"],
                     "c_eff_peak": float(np.max(cbar)), "c_eff_mean": float(np.mean(cbar))}
    axc.set(xlabel="time / T_c", ylabel="T / E_imp", title="(c) total kinetic energy (thin: "
            "instantaneous; thick: envelope mean)")
    axc.legend(fontsize=8)
    axd.set(xlabel="time / T_c", ylabel="C_eff / C_+", title="(d) effective damping, Eq. 9")
    axd.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, path)
    return out


# ---- Fig. 3 ------------------------------------------------------------------------------------
def long_lived_clusters(traj, count: int = 4, min_size: int = 3, min_periods: float = 4.0):
    """The ``count`` longest-lived clusters of at least ``min_size`` beads whose lifetime spans
    at least ``min_periods`` periods of their lowest linearized mode; sorted by birth time.
    Returns ``[(cluster, t_born, t_end, omegas)]`` (clusters alive at the run's end run to it)."""
    hist = traj.measures.history
    lives = cluster_lives(hist)
    rows = list(zip(lives.clusters, lives.born, lives.born + lives.lifetime))
    if hist.clusters:  # clusters alive at the end, censored there
        ended = {(c, b) for c, b, _ in rows}
        born = {}
        for t, after in zip(hist.times, hist.clusters):
            for c in after:
                born.setdefault(c, t)
            for c in list(born):
                if c not in after:
                    born.pop(c)
        rows += [(c, b, float(traj.time[-1])) for c, b in born.items() if (c, b) not in ended]
    rows = [r for r in rows if r[0].last - r[0].first + 1 >= min_size]
    rows.sort(key=lambda r: r[2] - r[1], reverse=True)
    picked = []
    for c, t0, t1 in rows:
        # skip the first period of the cluster's life (its formation transient)
        a, b = t0 + 0.15 * (t1 - t0), t1
        if np.count_nonzero((traj.time >= a) & (traj.time <= b)) < 20:
            continue
        omega, _, _ = an.cluster_modes_in_run(traj, c, a, b)
        if not np.all(np.isfinite(omega[:2])) or omega[0] <= 0:
            continue
        if (b - a) * omega[0] / (2 * math.pi) < min_periods:
            continue
        if any(p[0] == c and abs(p[1] - t0) < 1e-9 for p in picked):
            continue
        picked.append((c, a, b, omega))
        if len(picked) == count:
            break
    return sorted(picked, key=lambda p: p[1])


def fig3(traj, path) -> dict:
    """(a) micro-star's energy map with the chosen clusters boxed; (b-e) wavelet spectra of
    each cluster's middle bead with its first two linearized frequencies (dashed)."""
    plt = _plt()
    picked = long_lived_clusters(traj)
    tc = _tc(traj)
    fig = plt.figure(figsize=(12, 8))
    gs = fig.add_gridspec(2, max(len(picked), 1), height_ratios=[1.1, 1])
    ax = fig.add_subplot(gs[0, :])
    _energy_map(ax, traj, tc, title=f"(a) micro-star: the {len(picked)} longest-lived "
                "clusters of 3 or more beads (white boxes); their middle bead is analysed below")
    roman = ["I", "II", "III", "IV", "V", "VI"]
    rows = []
    for k, (c, t0, t1, omega) in enumerate(picked):
        ax.add_patch(plt.Rectangle((t0 / tc, c.first - 0.5), (t1 - t0) / tc, c.last - c.first + 1,
                                   fill=False, ec="w", lw=2.0))
        ax.text(t0 / tc + 0.1, c.last + 0.1, roman[k], color="k", fontsize=10, va="top",
                bbox={"fc": "w", "ec": "none", "pad": 1.5})
        mid = (c.first + c.last) // 2
        t, om, amp = an.wavelet_spectrum(traj, mid, t0=t0, t1=t1, quantity="v")
        ridge = an.peak_frequency(om, amp)
        a2 = fig.add_subplot(gs[1, k])
        a2.pcolormesh(t / tc, om, amp, shading="auto", cmap="viridis")
        for j, ls in ((0, "--"), (1, ":")):
            a2.axhline(omega[j], color="w", ls=ls, lw=1.2)
        a2.set(yscale="log", xlabel="time / T_c",
               title=f"({'bcdef'[k]}) cluster {roman[k]}: beads {c.first}-{c.last}, bead {mid}",
               ylim=(max(om[0], 0.3 * omega[0]), min(om[-1], 4 * omega[-1])))
        if k == 0:
            a2.set_ylabel("frequency (rad / time unit)")
        mean_ridge = float(np.median(ridge))
        rows.append({"cluster": roman[k], "beads": [c.first, c.last], "walls":
                     [c.left_wall, c.right_wall], "t": [t0, t1], "omega_1": float(omega[0]),
                     "omega_2": float(omega[1]), "wavelet_ridge_median": mean_ridge})
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    fig.text(0.5, 0.005, "wavelet amplitude of the middle bead's velocity; white lines: the "
             "cluster's first (dashed) and second (dotted) linearized frequencies",
             ha="center", fontsize=9)
    _save(fig, path)
    return {"clusters": rows}


# ---- Fig. 4 ------------------------------------------------------------------------------------
def fig4(traj, path) -> dict:
    """Relative velocity amplitude between neighbours (running maximum over 1 time unit)."""
    plt = _plt()
    tc = _tc(traj)
    rel = an.relative_velocity_map(traj, traj.walls, window=1.0)
    first = int(traj.contact_numbers[0])
    fig, ax = plt.subplots(figsize=(12, 4.2))
    t = traj.time / tc
    im = ax.imshow(rel.T, aspect="auto", origin="lower", cmap="inferno",
                   extent=(t[0], t[-1], first - 0.5, first + rel.shape[1] - 0.5),
                   vmax=np.percentile(rel, 99.5), interpolation="nearest")
    fig.colorbar(im, ax=ax, label="|v_(k-1) - v_k| (p q), max over 1 time unit", pad=0.01)
    ax.yaxis.get_major_locator().set_params(integer=True)
    ax.set(xlabel="time / T_c", ylabel="contact k (joins beads k-1, k)",
           title="micro-star: amplitude of relative velocity between neighbouring beads")
    fig.tight_layout()
    _save(fig, path)
    return {"max": float(rel.max())}


# ---- Fig. 5 ------------------------------------------------------------------------------------
def fig5(traj, path) -> dict:
    """Cumulative new clusters (raw and smoothed), re-clustering rate and C_eff, with the
    coincidence of their peaks."""
    plt = _plt()
    tc = _tc(traj)
    cbar = traj.measures.c_eff
    rc = traj.measures.reclustering
    co = traj.measures.coincidence
    t = traj.time / tc
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    a1.step(t, rc.history.cumulative_at(traj.time), where="post", color="0.5", lw=1,
            label="cumulative new clusters N(t)")
    a1.plot(t, rc.cumulative_smooth, color="C0", lw=1.6,
            label="smoothed (Appendix A knots, monotone; non-decreasing)")
    a1.set(ylabel="clusters formed")
    a1.legend(fontsize=8)
    a2.plot(t, rc.rate, color="C0", lw=1.5, label="re-clustering rate dN/dt (per time unit)")
    a2.set_ylabel("re-clustering rate dN/dt\n(new clusters per time unit 1/q)", color="C0")
    a2.set_ylim(bottom=0.0)  # a rate of cluster formation; the smoothing keeps it >= 0
    for p in co["rate_peaks"]:
        a2.axvline(p / tc, color="C0", ls=":", lw=1)
    a3 = a2.twinx()
    a3.plot(t, cbar, color="C3", lw=1.3, label="C_eff / C_+")
    a3.plot(co["c_eff_peaks"] / tc, np.interp(co["c_eff_peaks"], traj.time, cbar), "v",
            color="C3", ms=6)
    a3.set_ylabel("C_eff / C_+", color="C3")
    a2.set(xlabel="time / T_c", title=f"peaks: {len(co['c_eff_peaks'])} of C_eff (triangles), "
           f"{len(co['rate_peaks'])} of the rate (dotted); fraction of C_eff peaks within T_c of "
           f"a rate peak {co['fraction']:.2f} vs {co['null_mean']:.2f} +- {co['null_std']:.2f} "
           f"for shifted peaks (p = {co['p_value']:.3f})")
    a2.title.set_fontsize(9)
    fig.tight_layout()
    _save(fig, path)
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in co.items()
            if k != "null"}


# ---- Fig. 6 and B1-B3: the sweep grid ----------------------------------------------------------
#: Margins of the grid figures in inches: left, right (colour bar and its label), bottom, top
#: (a three-line title and the column titles).  Fixed margins instead of a layout engine:
#: constrained layout took ~20 s per figure on the 13 x 7 grid.
_GRID_MARGINS = (0.95, 1.45, 0.6, 1.05)


def _grid_axes(plt, k1s, v0s, size=(2.0, 1.3), sharey=True):
    """One panel per case (rows: v0, columns: K1), x shared by every panel of the figure, and
    room on the right for a colour bar (:func:`_grid_colorbar`)."""
    left, right, bottom, top = _GRID_MARGINS
    width = max(size[0] * len(k1s), 5.0) + left + right
    height = size[1] * len(v0s) + bottom + top
    fig, axs = plt.subplots(len(v0s), len(k1s), figsize=(width, height), sharex=True,
                            sharey=sharey, squeeze=False)
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, wspace=0.08, hspace=0.12)
    return fig, axs


def _grid_colorbar(fig, mappable, label, extend="neither"):
    """A colour bar right of the grid, 60 % of its height, ticks and label of readable size."""
    left, right, bottom, top = _GRID_MARGINS
    w, h = fig.get_size_inches()
    grid_h = h - bottom - top
    cax = fig.add_axes([1 - (right - 0.15) / w, (bottom + 0.2 * grid_h) / h, 0.14 / w,
                        0.6 * grid_h / h], label="<colorbar>")  # matplotlib's own name
    cb = fig.colorbar(mappable, cax=cax, label=label, extend=extend)
    cb.ax.tick_params(labelsize=TICK_PT)
    cb.ax.yaxis.label.set_size(TICK_PT + 1)
    return cb


def _colored_line(ax, x, y, c, norm, cmap, lw=1.0, max_points=1200):
    """``y(x)`` drawn as a line coloured by ``c`` (a LineCollection); at most ``max_points``
    vertices (every k-th frame of a smooth curve)."""
    from matplotlib.collections import LineCollection

    step = max(1, int(math.ceil(len(x) / max_points)))
    idx = np.unique(np.concatenate((np.arange(0, len(x), step), [len(x) - 1])))
    pts = np.column_stack((np.asarray(x, float)[idx], np.asarray(y, float)[idx]))
    lc = LineCollection(np.stack((pts[:-1], pts[1:]), axis=1), cmap=cmap, norm=norm,
                        linewidths=lw)
    cc = np.asarray(c, float)[idx]
    lc.set_array(0.5 * (cc[:-1] + cc[1:]))
    ax.add_collection(lc)
    return lc


def fig6(cases, path, pick=None) -> dict:
    """Four sweep cases (softest and stiffest substrate x a low and a high impulse): (a) energy
    maps, (b) C_eff / C_+."""
    plt = _plt()
    k1s = sorted({c["k1"] for c in cases})
    v0s = sorted({c["v0"] for c in cases})
    pick = pick or [(k1s[0], v0s[len(v0s) // 3]), (k1s[0], v0s[2 * len(v0s) // 3]),
                    (k1s[-1], v0s[len(v0s) // 3]), (k1s[-1], v0s[2 * len(v0s) // 3])]
    chosen = [next(c for c in cases if c["k1"] == k and c["v0"] == v) for k, v in pick]
    fig, axs = plt.subplots(2, len(chosen), figsize=(3.4 * len(chosen) + 0.8, 6.4),
                            squeeze=False, layout="constrained")
    for j, c in enumerate(chosen):
        tr = c["run"]()
        tc = _tc(tr)
        im = _energy_map(axs[0, j], tr, tc, cbar=False,
                         title=f"K1 = {c['k1']:g} N/m, v0 = {c['v0']:g}")
        time, cbar, _ = c["curves"]
        axs[1, j].plot(time / tc, cbar, color="C3", lw=1.2)
        axs[1, j].set(xlabel="time / T_c", ylabel="C_eff / C_+" if j == 0 else "")
    fig.colorbar(im, ax=axs[0, :], label="T_i / max_j T_j", pad=0.01)  # one norm, 0 to 1
    fig.suptitle("(a) kinetic energy maps (cyan: cluster boundaries) and (b) effective damping "
                 "for four sweep cases")
    _save(fig, path)
    return {"cases": [(c["k1"], c["v0"]) for c in chosen]}


def fig_b(cases, paths) -> dict:
    """B1: energy maps of every case; B2: C_eff / C_+ of every case with its representative
    segment shaded; B3: the smoothed re-clustering rate of every case.

    Every panel of a figure shares its time axis (time / T_c, from 0 to the longest case's end:
    the runs have one duration, 400 time units in the paper's sweep, which is fewer of its own
    T_c for a case with a slow pulse); tick labels are ``TICK_PT`` points; each figure has one
    colour bar for all its panels: B1 the normalized kinetic energy, B2 the line colour
    C_eff / C_+ (clipped at 100, like the axes), B3 the line colour the rate on one log scale
    for every case (the y axes keep one scale per row, since the rates grow ~100x from the
    weakest impulse to the strongest)."""
    plt = _plt()
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.ticker import MaxNLocator

    k1s = sorted({c["k1"] for c in cases})
    v0s = sorted({c["v0"] for c in cases})
    figs = [_grid_axes(plt, k1s, v0s, sharey=share) for share in (True, True, "row")]
    mappables = [None, None, None]
    drawn = []  # B2 and B3 need the colour scale of every case first: keep their curves only
    for c in cases:
        i, j = v0s.index(c["v0"]), k1s.index(c["k1"])
        tr = c["run"]()
        tc = _tc(tr)
        mappables[0] = _energy_map(figs[0][1][i, j], tr, tc, cbar=False, boundaries=False)
        time, cbar, rate = c["curves"]
        segs, means = c["segments"], c["segment_c_eff"]
        m = an.representative_segment(segs, means, 0.5 * tc)
        span = (segs.start[m] / tc, segs.end[m] / tc) if m >= 0 else None
        drawn.append((i, j, time / tc, cbar, rate, span))
    t_start = min(float(d[2][0]) for d in drawn)
    t_end = max(float(d[2][-1]) for d in drawn)
    rate_max = max([float(np.max(d[4])) for d in drawn] + [0.0])
    c_norm = Normalize(0.0, 100.0)
    r_norm = LogNorm(rate_max * 1e-3, rate_max) if rate_max > 0 else LogNorm(1e-3, 1.0)
    row_max = [0.0] * len(v0s)
    for i, j, t, cbar, rate, span in drawn:
        ax = figs[1][1][i, j]
        if span is not None:
            ax.axvspan(*span, color="0.8", zorder=0)
        mappables[1] = _colored_line(ax, t, cbar, np.clip(cbar, 0.0, 100.0), c_norm,
                                     "viridis", lw=1.0)
        ax.set_ylim(0, 100)
        mappables[2] = _colored_line(figs[2][1][i, j], t, rate,
                                     np.maximum(rate, r_norm.vmin), r_norm, "viridis", lw=1.0)
        row_max[i] = max(row_max[i], float(np.max(rate)))
    for fig, axs in figs:
        for a in axs.flat:
            a.set(xlabel="", ylabel="", title="")
            a.tick_params(labelsize=TICK_PT)
            a.xaxis.set_major_locator(MaxNLocator(nbins=4))
        axs[0, 0].set_xlim(t_start, t_end)  # shared by every panel of the figure
    for i, row in enumerate(figs[2][1]):  # one y scale per row, from 0 to its largest rate
        row[0].set_ylim(0.0, 1.08 * row_max[i] if row_max[i] > 0 else 1.0)
    labels = ["kinetic energy per bead\nT_i / max_j T_j (dimensionless)",
              "effective damping C_eff / C_+\n(dimensionless; axes clipped at 100)",
              "re-clustering rate, log scale\n(new clusters per time unit 1/q)"]
    extend = ["neither", "max", "min"]
    titles = ["B1: kinetic energy maps, bead against time / T_c\n(blank: after the run's end)",
              "B2: effective damping C_eff / C_+ against time / T_c\n(grey: representative "
              "segment, starting at t >= T_c/2)",
              "B3: smoothed re-clustering rate against time / T_c\n(y: one scale per row; "
              "colour: one scale for every panel)"]
    ylabel = ["bead", "C_eff / C_+", "rate (1/q)"]
    for (fig, axs), title, path, mp, lab, ext, yl in zip(figs, titles, paths, mappables, labels,
                                                         extend, ylabel):
        if mp is not None:
            _grid_colorbar(fig, mp, lab, ext)
        for j, k in enumerate(k1s):
            axs[0, j].set_title(f"K1 = {k:g} N/m", fontsize=TICK_PT + 1)
        for i, v in enumerate(v0s):
            axs[i, 0].set_ylabel(f"v0 = {v:g}", fontsize=TICK_PT + 1)
        fig.supxlabel("time / T_c (one range for every panel; a run lasts a different number "
                      "of its own T_c)", fontsize=TICK_PT + 1, y=0.15 / fig.get_size_inches()[1])
        fig.supylabel(f"rows: impulse v0 (p q); y: {yl}", fontsize=TICK_PT + 1,
                      x=0.12 / fig.get_size_inches()[0])
        fig.suptitle(f"{title}\ncolumns: substrate stiffness K1", fontsize=10,
                     y=1 - 0.08 / fig.get_size_inches()[1], va="top")
        _save(fig, path)
    return {"grid": [len(v0s), len(k1s)]}


# ---- Fig. 7 ------------------------------------------------------------------------------------
def fit_slope(x, y) -> dict:
    """Least-squares line y = a + b x with the 95% confidence interval of the slope b
    (Student t with n - 2 degrees of freedom), Pearson r and Spearman's rank correlation."""
    from scipy import stats

    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 3:
        return {"n": int(len(x))}
    r = stats.linregress(x, y)
    half = stats.t.ppf(0.975, len(x) - 2) * r.stderr
    sp = stats.spearmanr(x, y)
    return {"n": int(len(x)), "slope": float(r.slope), "intercept": float(r.intercept),
            "slope_ci95": [float(r.slope - half), float(r.slope + half)],
            "pearson_r": float(r.rvalue), "p_value": float(r.pvalue),
            "spearman_rho": float(sp.statistic), "spearman_p": float(sp.pvalue)}


def fig7(cases, path, rule: str = "", color_key: str = "k1",
         color_label: str = "substrate stiffness K1 (N/m)", title: str = "Fig. 7",
         log_color: bool = False) -> dict:
    """Max segment C_eff against log10 of its re-clustering rate, marker size for the impulse,
    shade for the stiffness, with the fitted line and its slope's 95% interval.  ``rule`` says
    how the representative segment was chosen (shown in the title).  ``color_key`` picks
    another parameter for the shade; ``log_color`` shades it on a log scale (linear below
    0.01), for lambda, which spans 0 to 5 with most values below 1."""
    plt = _plt()
    rows = [c for c in cases if c.get("c_eff_max_segment") is not None
            and (c.get("c_eff_max_segment_rate") or 0) > 0]
    x = np.log10([c["c_eff_max_segment_rate"] for c in rows])
    y = np.array([c["c_eff_max_segment"] for c in rows])
    fit = fit_slope(x, y)
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    shade = np.array([c["params"].get(color_key, c.get(color_key)) if "params" in c
                      else c[color_key] for c in rows], float)
    e_imp = np.array([0.5 * c["v0"] ** 2 for c in rows])
    def size(e):
        return 12 + 60 * np.log10(e / e_imp.min() + 1)

    from matplotlib.colors import Normalize, SymLogNorm

    norm = (SymLogNorm(0.01, vmin=shade.min(), vmax=shade.max()) if log_color
            else Normalize(shade.min(), shade.max()))
    sc = ax.scatter(x, y, s=size(e_imp), c=shade, cmap="viridis", norm=norm, edgecolors="k",
                    linewidths=0.5, alpha=0.85)
    for e in sorted({float(e_imp.min()), float(np.median(e_imp)), float(e_imp.max())}):
        ax.scatter([], [], s=size(e), c="w", edgecolors="k", label=f"E_imp = {e:.3g} eta p")
    fig.colorbar(sc, ax=ax, label=color_label)
    if "slope" in fit:
        xx = np.linspace(x.min(), x.max(), 50)
        ax.plot(xx, fit["intercept"] + fit["slope"] * xx, "k--", lw=1.2,
                label=f"slope {fit['slope']:.3g}, 95% CI [{fit['slope_ci95'][0]:.3g}, "
                      f"{fit['slope_ci95'][1]:.3g}], n = {fit['n']}")
    ax.legend(fontsize=8, loc="best", labelspacing=1.2, framealpha=0.8)
    ax.set(xlabel="log10 re-clustering rate of the segment (clusters per time unit)",
           ylabel="max segment-mean C_eff / C_+",
           title=f"{title}: representative segment of each case (size: impulse energy)\n{rule}")
    ax.title.set_fontsize(10)
    fig.tight_layout()
    _save(fig, path)
    return fit


def fig_controls(controls_numbers: dict, path) -> dict:
    """The controls (:mod:`mdgran.studies.controls`): (a) ``T / T(0)`` averaged over one ``T_c``
    against ``t / T_c`` for micro-star and the three macro variants; (b) micro over each
    macro variant, with the line where they are equal.  A variant whose run failed is left
    out (the report's table of the controls lists it with the reason)."""
    plt = _plt()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    vs = controls_numbers["vs_micro"]
    styles = {"macro-pulse": ("C0", "-", "macro, Hertz, paper's matching"),
              "macro-si": ("C2", "--", "macro, Hertz, matched in m/s"),
              "macro-schwarz": ("C1", "-.", "macro, Schwarz at its own lambda")}
    first = next(iter(vs.values()))["curves"]
    ax.semilogy(first["s"], first["micro"], color="C3", lw=2.0, label="micro-star")
    for name, (col, ls, label) in styles.items():
        if name not in vs:  # its run failed or did not run: the report's table says why
            continue
        c = vs[name]["curves"]
        ax.semilogy(c["s"], c["macro"], color=col, ls=ls, label=label)
        with np.errstate(invalid="ignore", divide="ignore"):
            bx.semilogy(c["s"], c["micro"] / c["macro"], color=col, ls=ls,
                        label=f"micro / {label}")
    bx.axhline(1.0, color="k", lw=0.8, label="equal")
    ax.set(xlabel="time / T_c (each chain's own)", ylabel="T / T(0), mean over one T_c",
           title="(a) kinetic energy")
    bx.set(xlabel="time / T_c", ylabel="ratio", title="(b) micro over macro (< 1: micro lower)")
    for a in (ax, bx):
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return {"path": str(path)}
