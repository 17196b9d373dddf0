"""Figures: structural properties, checked on short runs and synthetic event sets.

* the smoothed re-clustering rate is a rate of cluster formation: never negative, and its
  integral is the number of newly formed clusters (property test over random event sets);
* Fig. 5 and B3 draw no negative rate; B1-B3 have a labelled colour bar, one x range for every
  panel, tick labels of at least 8 pt;
* the comparison's events.png numbers contacts with integer ticks and calls Hertz events
  separate/touch (snap-off/snap-to only for adhesive laws); in clusters.png every backend's line
  has its own style and a legend entry; difference.png's horizon line has a legend entry and a
  colour no backend line has.
"""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from mdgran.analysis import clusters as cl  # noqa: E402

MIN_PT = 8.0


# ---- the smoothed re-clustering rate -------------------------------------------------------------
def _segments(times, counts, t0, t1):
    """Segments from re-clustering event times (distinct, inside (t0, t1)) and their counts."""
    times = np.asarray(times, float)
    edges = np.concatenate(([t0], times, [t1]))
    return cl.Segments(edges[:-1], edges[1:], np.concatenate(([0], np.cumsum(counts))))


@st.composite
def event_sets(draw):
    t1 = draw(st.sampled_from([20.0, 60.0, 400.0]))
    dt = draw(st.sampled_from([0.1, 0.25]))
    raw = draw(st.lists(st.floats(0.0, 1.0, exclude_min=True, exclude_max=True), max_size=40))
    # clustered bursts too: the cubic spline overshot most between a burst and a quiet stretch
    burst = draw(st.lists(st.floats(0.0, 0.02), max_size=10))
    times = np.unique(np.round(np.concatenate((np.asarray(raw, float),
                                               0.3 + np.asarray(burst, float))) * t1, 6))
    times = times[(times > 0) & (times < t1)]
    counts = draw(st.lists(st.integers(1, 5), min_size=len(times), max_size=len(times)))
    tau = draw(st.sampled_from([0.0, 1.0, 10.0, 40.0]))
    return t1, dt, times, np.asarray(counts, int), tau


@settings(max_examples=150, deadline=None)
@given(event_sets())
def test_smoothed_rate_is_never_negative_and_integrates_to_the_event_count(case):
    t1, dt, times, counts, tau = case
    t = np.linspace(0.0, t1, int(round(t1 / dt)) + 1)
    smooth, rate = cl.smoothed_cumulative(t, _segments(times, counts, 0.0, t1), tau)
    assert np.all(rate >= 0.0)
    assert np.all(np.diff(smooth) >= 0.0) and smooth[0] == 0.0
    # tolerance: 1e-9 of the count (round-off of the kernel sums; measured ~1e-15)
    total = int(counts.sum())
    integral = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)))
    assert integral == pytest.approx(total, rel=1e-9, abs=1e-9)
    assert smooth[-1] == pytest.approx(total, rel=1e-9, abs=1e-9)


def test_smoothed_rate_where_the_cubic_spline_undershot():
    """A burst of 6 new clusters, then one, then a long quiet stretch: the paper's cubic and
    smoothing splines dipped below zero after the burst."""
    t = np.linspace(0.0, 200.0, 2001)
    s = _segments([2.0, 2.5, 3.0, 40.0, 45.0], [3, 2, 1, 1, 1], 0.0, 200.0)
    smooth, rate = cl.smoothed_cumulative(t, s)
    assert rate.min() >= 0.0 and rate.max() > 0.1
    assert smooth[-1] == pytest.approx(8.0)


# ---- short runs shared by the figure tests -------------------------------------------------------
@pytest.fixture(scope="module")
def micro():
    from mdgran.model.scene import load_scene
    from mdgran.simulation import run

    sc = load_scene("micro-star", [("run.duration", 40.0), ("run.tolerance", 1e-6)])
    return run(sc, "reference").trajectory, sc


@pytest.fixture(scope="module")
def hertz():
    from mdgran.model.scene import load_scene
    from mdgran.simulation import run

    sc = load_scene("macro-hertz", [("run.duration", 20.0), ("run.tolerance", 1e-6)])
    return run(sc, "reference").trajectory, sc


class Saved:
    """Keeps every figure "saved" (by file name) open for inspection instead of writing and
    closing it; the figure is laid out and its tick labels made, without rasterizing."""

    def __init__(self, mp):
        self.figs = {}

        def savefig(fig, path, *a, **k):
            fig.draw_without_rendering()
            self.figs[getattr(path, "name", str(path)).rsplit("/", 1)[-1]] = fig

        mp.setattr(matplotlib.figure.Figure, "savefig", savefig)
        mp.setattr(plt, "close", lambda *a, **k: None)

    def close(self):
        for f in self.figs.values():
            plt.close(f)


@pytest.fixture
def saved():
    with pytest.MonkeyPatch.context() as mp:
        s = Saved(mp)
        yield s
    s.close()


def _tick_sizes(ax):
    return [t.get_fontsize() for t in ax.get_xticklabels() + ax.get_yticklabels()
            if t.get_visible() and t.get_text()]


# ---- paper figures -----------------------------------------------------------------------------
def test_fig5_draws_no_negative_rate(micro, saved, tmp_path):
    from mdgran.studies import paper_figures as pf

    tr, sc = micro
    pf.fig5(tr, tmp_path / "fig5.png")
    fig = saved.figs["fig5.png"]
    rate_ax = fig.axes[1]
    (line,) = [ln for ln in rate_ax.get_lines() if "re-clustering rate" in ln.get_label()]
    y = line.get_ydata()
    assert len(y) == len(tr.time) and np.max(y) > 0 and np.min(y) >= 0.0
    assert rate_ax.get_ylim()[0] == 0.0


def test_fig_b_colour_bars_shared_x_ticks_and_rates(micro, saved, tmp_path):
    from mdgran.studies import paper_figures as pf

    tr, sc = micro
    # the structure does not depend on the runs: one run labelled as 2 x 2 cases
    m = tr.measures
    cases = [{"k1": k, "v0": v, "scene": sc, "run": (lambda: tr),
              "curves": (tr.time, m.c_eff, m.rate), "segments": m.reclustering.segments,
              "segment_c_eff": m.reclustering.segment_c_eff}
             for k in (4.6, 21.5) for v in (2.0, 16.0)]
    paths = [tmp_path / f"figB{k}.png" for k in (1, 2, 3)]
    pf.fig_b(cases, paths)
    for p in paths:
        fig = saved.figs[p.name]
        panels = [a for a in fig.axes if a.get_label() != "<colorbar>"]
        bars = [a for a in fig.axes if a.get_label() == "<colorbar>"]
        assert len(panels) == 4 and len(bars) == 1, p.name
        assert bars[0].get_ylabel(), p.name  # quantity and unit
        assert len({a.get_xlim() for a in panels}) == 1, p.name  # one x range
        for a in fig.axes:
            assert min(_tick_sizes(a), default=MIN_PT) >= MIN_PT, p.name
    rates = [c for a in saved.figs["figB3.png"].axes if a.get_label() != "<colorbar>"
             for c in a.collections if isinstance(c, LineCollection)]
    assert len(rates) == 4
    for lc in rates:
        y = np.concatenate([s[:, 1] for s in lc.get_segments()])
        assert y.min() >= 0.0 and y.max() > 0.0


# ---- the comparison's figures --------------------------------------------------------------------
def _fake_comparison(traj, scene, names=("reference", "fast")):
    """What compare_report._figures gets, built from one short run (second backend: the same
    run; their lines coincide exactly, the case that hid one of them)."""
    from mdgran.analysis.statistics import cluster_lives
    from mdgran.crosscheck.compare import BackendRuns

    err = np.full(len(traj.time), 1e-9)
    runs = [BackendRuns(n, traj, traj, err, 1.0, 0.1, 1e-9, 1e-9, [traj]) for n in names]
    lives = cluster_lives(traj.measures.history)
    horizon = 0.5 * float(traj.time[-1])
    pred = {"time": traj.time, "difference": np.geomspace(1e-14, 1e-2, len(traj.time))}
    from mdgran.crosscheck.compare import PREDICTABLE, SAFETY

    report = {"pairs": {n: {"horizon": horizon, "clusters": {"lifetimes": {"pvalue": 0.5}}}
                        for n in names[1:]},
              "thresholds": {"predictable_p": PREDICTABLE, "safety": SAFETY}}
    pairs = {n: {"clusters": {"lives": {names[0]: lives, n: lives}, "where": "over the run"}}
             for n in names[1:]}
    return runs, pred, report, pairs


@pytest.fixture(scope="module")
def comparison(request, tmp_path_factory):
    """The comparison figures of each short run, drawn once: ``{"micro"|"hertz": Saved}``."""
    from mdgran.crosscheck.compare_report import _figures

    drawn = {}
    for which in ("micro", "hertz"):
        traj, scene = request.getfixturevalue(which)
        with pytest.MonkeyPatch.context() as mp:
            drawn[which] = Saved(mp)
            _figures(tmp_path_factory.mktemp(which), scene, *_fake_comparison(traj, scene))
    yield drawn
    for s in drawn.values():
        s.close()


@pytest.mark.parametrize("which", ["micro", "hertz"])
def test_events_integer_ticks_and_law_dependent_labels(which, comparison):
    fig = comparison[which].figs["events.png"]
    for ax in fig.axes:
        loc = ax.yaxis.get_major_locator()
        assert isinstance(loc, MaxNLocator) and loc._integer
        assert all(float(v).is_integer() for v in ax.get_yticks())
        assert min(_tick_sizes(ax)) >= MIN_PT
    labels = " ".join(fig.axes[0].get_legend_handles_labels()[1])
    if which == "hertz":
        assert "snap" not in labels and "separate" in labels and "touch" in labels
    else:
        assert "snap-off" in labels and "snap-to" in labels


def test_clusters_lines_distinct_and_horizon_in_legend(comparison):
    saved = comparison["micro"]
    backend_colours = set()
    for ax in saved.figs["clusters.png"].axes[:2]:
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        a, b = lines["reference"], lines["fast"]
        # the same data drawn twice stays visible: different style or width, and a legend
        assert (a.get_linestyle(), a.get_linewidth()) != (b.get_linestyle(), b.get_linewidth())
        assert {"reference", "fast"} <= {t.get_text() for t in ax.get_legend().get_texts()}
    fig = saved.figs["difference.png"]
    ax = fig.axes[0]
    legend = {t.get_text() for t in ax.get_legend().get_texts()}
    horizon = [ln for ln in ax.get_lines() if "horizon" in ln.get_label()]
    assert len(horizon) == 1 and horizon[0].get_label() in legend
    for ln in ax.get_lines():
        if ln not in horizon:
            backend_colours.add(to_rgba(ln.get_color()))
    assert to_rgba(horizon[0].get_color()) not in backend_colours


def test_controls_figure_leaves_out_a_control_whose_run_failed(tmp_path, monkeypatch):
    """A sweep of the controls in which macro-si's run failed (its LAMMPS run stopped): the
    figure draws micro-star and the two macro variants that ran, one line each in (b), instead
    of stopping the report on the missing one."""
    from mdgran.studies import paper_figures as pf

    s = np.linspace(0.0, 10.0, 21)
    curves = {"s": s, "micro": np.exp(-0.3 * s), "macro": np.exp(-0.2 * s)}
    numbers = {"vs_micro": {"macro-pulse": {"curves": curves},
                            "macro-schwarz": {"curves": {**curves, "macro": np.exp(-0.25 * s)}}}}
    drawn = []
    monkeypatch.setattr(pf, "_save", lambda fig, path: drawn.append(fig))
    assert pf.fig_controls(numbers, tmp_path / "controls.png") == {
        "path": str(tmp_path / "controls.png")}
    (ax, bx) = drawn[0].axes[:2]
    assert [ln.get_label() for ln in ax.get_lines()] == [
        "micro-star", "macro, Hertz, paper's matching", "macro, Schwarz at its own lambda"]
    assert len([ln for ln in bx.get_lines() if ln.get_label().startswith("micro / ")]) == 2
