"""Null models for the Fig. 7 relation and a selection-free alternative.

**Fig. 7** (paper Sec. VI): each case contributes one point, the segment with the largest mean
``C_eff / C_+`` (:func:`~.clusters.representative_segment`) at ``x = log10 r_m`` (its
re-clustering rate) and ``y = C_eff,m``; the figure's slope is the least-squares slope of y on x
(``mdgran.studies.paper_figures.fit_slope``).  Choosing the maximum favours short segments: a short
segment's mean is an average over little time, so it scatters more and wins the maximum more
often, and a short segment has a high rate ``r_m = new / lifespan`` by construction.  The slope
is then positive even with no link between damping and re-clustering.  The nulls below measure
how much of the observed slope that selection builds in.

A case is a :class:`NullCase` (``time`` [F], ``c_eff`` [F], ``segments``, smoothed ``rate`` [F],
``t_min``, ``window``): plain arrays, from a run (:func:`case_of_run`) or made up
(:func:`synthetic_case`).  Statistics are pure functions of the cases and of segment means
``means[c]`` of shape ``[K, M_c]`` (K shuffles of case c), returning ``[K]``; null generators
build the K shuffled means and apply a statistic:

* :func:`time_shift` (null a) circularly shifts each case's ``C_eff`` by a random offset inside
  its ``window``.  Destroys: the alignment of ``C_eff`` with the segments of its own case.
  Keeps: the segments (lengths, rates), ``C_eff``'s values, marginal and autocorrelation, each
  case's mean level, hence any between-case association of level and rate.  (A trend shared by
  ``C_eff`` and the rate inside the window is destroyed too and so counts as alignment: keep the
  window to the active part.)
* :func:`swap_cases` (null b) gives each case the ``C_eff`` of another case (a random
  derangement), resampled onto its time grid.  Destroys: all link between a case's ``C_eff``
  and its segments, including the between-case one.  Keeps: the segments, the pool of ``C_eff``
  curves and each curve's time course (shared trends with time included).
* :func:`random_late_null` (null c) keeps the observed ``C_eff`` and segments and replaces the
  maximum by a uniformly random eligible segment (:func:`random_late`).  Destroys: the selection
  by ``C_eff``.  Keeps: everything else (it answers "what slope does an arbitrary late segment
  give"; the maximum's own bias towards short segments is not in it).

Selection-free measures, with no choice of segment: :func:`segment_statistic` (every segment
with a rate, i.e. all but the last of each case, starting at or after ``t_min``, weighted by
its lifespan: weighted slope of ``C_eff,m`` on ``log10 r_m`` and weighted correlation) and
:func:`rate_damping_correlation` (Spearman rank correlation of the smoothed re-clustering rate
with ``C_eff`` over time inside the window, averaged over cases; its time-shift null is exact
and vectorized by a circular cross-correlation of the ranks, :func:`rate_damping_null`).

:func:`null_summary` condenses an observed value and its null: mean, sd, fraction positive and
the one-sided p-value ``(1 + #{null >= observed}) / (1 + K)``, never below ``1 / (1 + K)``.

Example (one study: cases of a sweep, T_c / 2 as t_min, active windows)::

    cases = [case_of_run(run) for run in runs]
    obs = fig7_slope(cases)                         # = report's numbers["fig7"]["slope"]
    print(null_summary(obs, time_shift(cases, n_shuffles=300, rng=0)))
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .clusters import (MERGE_WITHIN, Segments, analyze_reclustering, reclustering_events,
                       representative_segment, segment_means, smoothed_cumulative)
from .effective_damping import SMOOTHING_TIME, effective_damping
from .pulse import characteristic_period


class NullCase(NamedTuple):
    """One case's arrays for the nulls.

    ``time`` [F] (uniform grid: shifts are in frames), ``c_eff`` [F] (``C_eff / C_+``),
    ``segments`` (:class:`~.clusters.Segments`), ``rate`` [F] smoothed re-clustering rate,
    ``t_min``: segments starting earlier are not eligible (Fig. 7 uses ``T_c / 2``),
    ``window = (t0, t1)``: the part of the run where ``C_eff`` is shifted and the rate-damping
    correlation is taken (the active part)."""

    time: np.ndarray
    c_eff: np.ndarray
    segments: Segments
    rate: np.ndarray
    t_min: float
    window: tuple


def null_case(time, c_eff, segs: Segments, rate=None, t_min: float = -np.inf, window=None,
              smoothing_time: float = SMOOTHING_TIME) -> NullCase:
    """A :class:`NullCase` from arrays; ``rate`` defaults to that of
    :func:`~.clusters.smoothed_cumulative`, ``window`` to the whole run."""
    time = np.asarray(time, float)
    if rate is None:
        rate = smoothed_cumulative(time, segs, smoothing_time)[1]
    window = (float(time[0]), float(time[-1])) if window is None else tuple(map(float, window))
    return NullCase(time, np.asarray(c_eff, float), segs, np.asarray(rate, float),
                    float(t_min), window)


def case_of_run(traj, c_eff=None, *, late: bool = True, active: bool = True,
                smoothing_time: float = SMOOTHING_TIME,
                merge_within: float = MERGE_WITHIN, reclustering=None) -> NullCase:
    """A run's :class:`NullCase` as the report's Fig. 7 sees it: ``c_eff`` defaults to
    :func:`~.effective_damping.effective_damping`; ``late``: ``t_min = T_c / 2`` (as
    ``c_eff_late_segment`` of :func:`~mdgran.analysis.run_summary`), else ``-inf`` (the literal
    rule); ``active``: window from ``max(t_start, t_min)`` to one ``T_c`` after the last
    re-clustering event (as the pooled coincidence test's active part), else the whole run.
    ``reclustering``: the run's :func:`~.clusters.analyze_reclustering` with this ``c_eff``
    at the same settings, if already computed."""
    cbar = effective_damping(traj, smoothing_time=smoothing_time) if c_eff is None else c_eff
    rc = (analyze_reclustering(traj, cbar, smoothing_time=smoothing_time,
                               merge_within=merge_within)
          if reclustering is None else reclustering)
    tc = characteristic_period(traj)
    t0, t1 = float(traj.time[0]), float(traj.time[-1])
    t_min = 0.5 * tc if late and np.isfinite(tc) else -np.inf
    window = (t0, t1)
    if active:
        ev_t, _ = reclustering_events(rc.history, merge_within)
        end = min(t1, ev_t[-1] + tc) if len(ev_t) and np.isfinite(tc) else t1
        window = (max(t0, t_min), end)
    return NullCase(np.asarray(traj.time, float), np.asarray(cbar, float), rc.segments,
                    rc.rate, t_min, window)


# ---- selectors: which segment represents a case ---------------------------------------------
def max_mean(means, segs: Segments, t_min: float = -np.inf, rng=None) -> int:
    """The paper's rule: the segment with the largest mean ``C_eff`` among those with a rate
    starting at or after ``t_min`` (:func:`~.clusters.representative_segment`); -1 if none."""
    return representative_segment(segs, means, t_min)


def random_late(means, segs: Segments, t_min: float = -np.inf, rng=None) -> int:
    """Null c: a uniformly random segment among those :func:`max_mean` chooses from."""
    ok = np.flatnonzero((np.asarray(segs.start[:-1]) >= t_min)
                        & np.isfinite(np.asarray(means, float)[:-1]))
    return int(np.random.default_rng(rng).choice(ok)) if len(ok) else -1


# ---- segment means, vectorized over shuffles -------------------------------------------------
def _interp_weights(time, x):
    """Indices and weights so that ``(1 - w) y[j] + w y[j+1] == np.interp(x, time, y)``."""
    j = np.clip(np.searchsorted(time, x, side="right") - 1, 0, len(time) - 2)
    w = np.clip((x - time[j]) / (time[j + 1] - time[j]), 0.0, 1.0)
    return j, w


def segment_means_many(time, values, segs: Segments) -> np.ndarray:
    """:func:`~.clusters.segment_means` of each row of ``values`` [K, F]: [K, M]."""
    time = np.asarray(time, float)
    v = np.atleast_2d(np.asarray(values, float))
    integral = np.concatenate((np.zeros((len(v), 1)),
                               np.cumsum(0.5 * (v[:, 1:] + v[:, :-1]) * np.diff(time), axis=1)),
                              axis=1)

    def at(y, x):
        j, w = _interp_weights(time, np.asarray(x, float))
        return (1.0 - w) * y[:, j] + w * y[:, j + 1]

    life = segs.lifespan
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(life > 0, (at(integral, segs.end) - at(integral, segs.start)) / life,
                        at(v, segs.start))


def _window_index(case: NullCase) -> np.ndarray:
    t0, t1 = case.window
    return np.flatnonzero((case.time >= t0) & (case.time <= t1))


def shifted_c_eff(case: NullCase, offsets) -> np.ndarray:
    """``C_eff`` [K, F] with its samples inside ``case.window`` rotated by ``offsets`` [K]
    frames (circularly within the window; outside it unchanged)."""
    idx = _window_index(case)
    n = len(idx)
    out = np.tile(case.c_eff, (len(offsets), 1))
    if n > 1:
        src = idx[0] + (np.arange(n)[None, :] - np.asarray(offsets)[:, None]) % n
        out[:, idx] = case.c_eff[src]
    return out


# ---- statistics of segment means [K, M_c] per case -------------------------------------------
def _ols_slopes(x, y) -> np.ndarray:
    """Least-squares slope of each row of y on x ([K, C], NaN = missing); NaN if < 3 points."""
    ok = np.isfinite(x) & np.isfinite(y)
    n = ok.sum(axis=1)
    xs, ys = np.where(ok, x, 0.0), np.where(ok, y, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my = xs.sum(axis=1) / n, ys.sum(axis=1) / n
        dx = np.where(ok, xs - mx[:, None], 0.0)
        slope = np.sum(dx * (ys - my[:, None]), axis=1) / np.sum(dx * dx, axis=1)
    return np.where(n >= 3, slope, np.nan)


def fig7_statistic(cases, means, selector=max_mean, rng=None) -> np.ndarray:
    """Fig. 7 slope for each of K sets of segment means (``means[c]`` [K, M_c]): per case and
    row, ``selector`` picks a segment; the point is ``(log10 r, C_eff mean)`` if ``r > 0``;
    the slope is the least-squares slope over the cases (NaN below 3 points)."""
    rng = np.random.default_rng(rng)
    k = len(means[0])
    x = np.full((k, len(cases)), np.nan)
    y = np.full((k, len(cases)), np.nan)
    for c, (case, m) in enumerate(zip(cases, means)):
        rate = case.segments.rate
        for row in range(k):
            i = selector(m[row], case.segments, case.t_min, rng)
            if i >= 0 and rate[i] > 0 and np.isfinite(m[row, i]):
                x[row, c], y[row, c] = np.log10(rate[i]), m[row, i]
    return _ols_slopes(x, y)


def fig7_points(cases, selector=max_mean, rng=None):
    """The points of Fig. 7: ``(x, y, index)``: ``x = log10 r`` [n] and ``y`` the segment-mean
    ``C_eff / C_+`` [n] of the segment ``selector`` picks in each case that has one with
    ``r > 0`` (as ``paper_figures.fig7`` keeps them); ``index`` [C] the segment of each case
    (-1: none)."""
    rng = np.random.default_rng(rng)
    x, y, index = [], [], []
    for case in cases:
        m = segment_means(case.time, case.c_eff, case.segments)
        i = selector(m, case.segments, case.t_min, rng)
        index.append(i)
        r = case.segments.rate[i] if i >= 0 else np.nan
        if i >= 0 and r > 0 and np.isfinite(m[i]):
            x.append(np.log10(r))
            y.append(m[i])
    return np.array(x), np.array(y), np.array(index, int)


def fig7_slope(cases, selector=max_mean, rng=None) -> float:
    """Slope of Fig. 7 (``scipy.stats.linregress`` of y on x, as ``paper_figures.fit_slope``);
    NaN below 3 points.  With :func:`max_mean` and the cases of :func:`case_of_run` (``late``)
    it is the report's ``numbers["fig7"]["slope"]``."""
    from scipy import stats

    x, y, _ = fig7_points(cases, selector, rng)
    return float(stats.linregress(x, y).slope) if len(x) >= 3 else float("nan")


def segment_points(case: NullCase, means=None):
    """Every segment with a rate (all but the last) starting at or after ``t_min``, with
    ``r > 0`` and ``lifespan > 0``: ``(x = log10 r, y = mean C_eff, w = lifespan, keep)``;
    ``means`` [K, M] (default: the observed means, K = 1) gives ``y`` [K, n]."""
    segs = case.segments
    if means is None:
        means = segment_means(case.time, case.c_eff, segs)[None, :]
    r, life = segs.rate, segs.lifespan
    keep = np.zeros(len(segs), bool)
    keep[:-1] = (segs.start[:-1] >= case.t_min) & (r[:-1] > 0) & (life[:-1] > 0)
    return np.log10(r[keep]), np.asarray(means)[:, keep], life[keep], keep


def segment_statistic(cases, means, kind: str = "slope", center: bool = False) -> np.ndarray:
    """Selection-free Fig. 7: all segments of every case (:func:`segment_points`), weighted by
    lifespan; ``kind="slope"``: weighted least-squares slope of segment-mean ``C_eff`` on
    ``log10 r``; ``"r"``: weighted Pearson correlation.  ``center``: subtract each case's
    weighted means of x and y first (within-case relation only).  [K]."""
    xs, ys, ws = [], [], []
    for case, m in zip(cases, means):
        x, y, w, _ = segment_points(case, m)
        if len(x) == 0:
            continue
        if center:
            x = x - np.average(x, weights=w)
            y = y - (y @ w / w.sum())[:, None]
        xs.append(x), ys.append(y), ws.append(w)
    x, y, w = np.concatenate(xs), np.concatenate(ys, axis=1), np.concatenate(ws)
    w = w / w.sum()
    dx = x - w @ x
    dy = y - (y @ w)[:, None]
    sxy, sxx, syy = dy @ (w * dx), w @ (dx * dx), (dy * dy) @ w
    with np.errstate(invalid="ignore", divide="ignore"):
        return sxy / sxx if kind == "slope" else sxy / np.sqrt(sxx * syy)


def observed_means(cases) -> list:
    """Segment means of each case's own ``C_eff``, [1, M_c] each (for the statistics)."""
    return [segment_means(c.time, c.c_eff, c.segments)[None, :] for c in cases]


# ---- null generators ---------------------------------------------------------------------------
def time_shift(cases, statistic=fig7_statistic, n_shuffles: int = 300, rng=0,
               **kwargs) -> np.ndarray:
    """Null a: ``statistic`` [K] with each case's ``C_eff`` shifted circularly inside its
    window by an independent uniform offset (in frames) per case and shuffle.
    ``kwargs`` go to ``statistic`` (e.g. ``selector=``, ``kind=``)."""
    rng = np.random.default_rng(rng)
    means = []
    for case in cases:
        n = max(len(_window_index(case)), 1)
        off = rng.integers(0, n, n_shuffles)
        means.append(segment_means_many(case.time, shifted_c_eff(case, off), case.segments))
    return _apply(statistic, cases, means, rng, kwargs)


def _derangement(rng, n: int) -> np.ndarray:
    while True:
        p = rng.permutation(n)
        if n < 2 or not np.any(p == np.arange(n)):
            return p


def swap_cases(cases, statistic=fig7_statistic, n_shuffles: int = 300, rng=0,
               **kwargs) -> np.ndarray:
    """Null b: ``statistic`` [K] with each case given the ``C_eff`` of another case (a random
    derangement per shuffle), linearly resampled onto its own time grid (held constant beyond
    the other case's end)."""
    rng = np.random.default_rng(rng)
    perms = np.array([_derangement(rng, len(cases)) for _ in range(n_shuffles)])
    means = []
    for c, case in enumerate(cases):
        src = perms[:, c]
        resampled = {j: np.interp(case.time, cases[j].time, cases[j].c_eff) for j in set(src)}
        means.append(segment_means_many(case.time, np.array([resampled[j] for j in src]),
                                        case.segments))
    return _apply(statistic, cases, means, rng, kwargs)


def random_late_null(cases, n_shuffles: int = 300, rng=0) -> np.ndarray:
    """Null c: the Fig. 7 slope [K] with each case's segment chosen by :func:`random_late`."""
    means = [np.repeat(m, n_shuffles, axis=0) for m in observed_means(cases)]
    return fig7_statistic(cases, means, random_late, np.random.default_rng(rng))


def _apply(statistic, cases, means, rng, kwargs):
    if statistic is fig7_statistic:
        return statistic(cases, means, rng=rng, **kwargs)
    return statistic(cases, means, **kwargs)


# ---- rate-damping correlation over time ------------------------------------------------------
def _centred_ranks(y) -> np.ndarray:
    from scipy.stats import rankdata

    r = rankdata(y)
    r = r - r.mean()
    s = np.sqrt(np.sum(r * r))
    return r / s if s > 0 else r * np.nan


def rate_damping_rho(case: NullCase) -> np.ndarray:
    """Spearman correlation of the smoothed rate with ``C_eff`` inside ``case.window``, for
    every circular shift ``k`` of ``C_eff`` there (frames): [n]; ``[0]`` is the observed one.
    (A shift keeps the set of ranks, so Spearman at shift k is the circular cross-correlation
    of the centred ranks, by FFT.)"""
    idx = _window_index(case)
    a, b = _centred_ranks(case.rate[idx]), _centred_ranks(case.c_eff[idx])
    # rho[k] = sum_i a[i] b[(i - k) mod n]  (b rotated by k, as shifted_c_eff)
    return np.real(np.fft.ifft(np.fft.fft(a) * np.conj(np.fft.fft(b))))


def rate_damping_correlation(cases) -> float:
    """Mean over cases of the Spearman correlation of rate and ``C_eff`` in each window."""
    return float(np.nanmean([rate_damping_rho(c)[0] for c in cases]))


def rate_damping_null(cases, n_shuffles: int = 10000, rng=0) -> np.ndarray:
    """Time-shift null of :func:`rate_damping_correlation`: [K] means over cases, each case's
    ``C_eff`` shifted by an independent uniform offset in its window."""
    rng = np.random.default_rng(rng)
    rhos = [rate_damping_rho(c) for c in cases]
    return np.nanmean([r[rng.integers(0, len(r), n_shuffles)] for r in rhos], axis=0)


# ---- summary -----------------------------------------------------------------------------------
def null_summary(observed: float, null) -> dict:
    """``observed`` against its null [K]: ``null_mean``, ``null_sd``, ``fraction_positive`` of
    the null, ``p_value = (1 + #{null >= observed}) / (1 + K)`` (one-sided, upper), ``p_floor =
    1 / (1 + K)`` (a p at the floor means only "below that"), ``z = (observed - null_mean) /
    null_sd`` (how far beyond the floor), ``K`` (finite null values)."""
    null = np.asarray(null, float)
    null = null[np.isfinite(null)]
    k = len(null)
    return {"observed": float(observed), "K": k,
            "null_mean": float(np.mean(null)) if k else float("nan"),
            "null_sd": float(np.std(null)) if k else float("nan"),
            "fraction_positive": float(np.mean(null > 0)) if k else float("nan"),
            "p_value": float((1 + np.sum(null >= observed)) / (1 + k)),
            "p_floor": 1.0 / (1 + k),
            "z": float((observed - np.mean(null)) / np.std(null)) if k and np.std(null) > 0
            else float("nan")}


# ---- synthetic cases (known answer) ------------------------------------------------------------
def synthetic_case(rng, coupling: float = 0.0, event_rate: float = 0.1, duration: float = 300.0,
                   active: float = 150.0, dt: float = 0.25, corr_time: float = 8.0,
                   sigma: float = 0.5, smoothing_time: float = SMOOTHING_TIME) -> NullCase:
    """A made-up case: re-clustering events a Poisson process of ``event_rate`` on
    ``(0, active)``, each forming ``1 + Poisson(1)`` clusters; ``C_eff = exp(sigma z(t))
    + coupling * rate(t) / mean rate``, ``z`` white noise Gaussian-filtered over ``corr_time``
    and scaled to unit variance (log-normal marginal, independent of the events), ``rate`` the
    smoothed re-clustering rate.  ``coupling = 0``: no link; ``> 0``: damping raised in
    proportion to the local rate.  Window ``(0, active + 20)``, ``t_min = 0``."""
    from scipy.ndimage import gaussian_filter1d

    rng = np.random.default_rng(rng)
    time = np.arange(0.0, duration + 0.5 * dt, dt)
    ev = np.sort(rng.uniform(0.0, active, rng.poisson(event_rate * active)))
    ev = ev[np.concatenate(([True], np.diff(ev) >= dt))] if len(ev) else ev
    new = 1 + rng.poisson(1.0, len(ev))
    edges = np.concatenate(([time[0]], ev, [time[-1]]))
    segs = Segments(edges[:-1], edges[1:], np.concatenate(([0], np.cumsum(new))))
    _, rate = smoothed_cumulative(time, segs, smoothing_time)
    z = gaussian_filter1d(rng.standard_normal(len(time)), corr_time / dt, mode="wrap")
    c = np.exp(sigma * z / np.std(z))
    win = (0.0, min(active + 20.0, duration))
    mean_rate = np.mean(rate[time <= win[1]])
    if coupling and mean_rate > 0:
        c = c + coupling * rate / mean_rate
    return NullCase(time, c, segs, rate, 0.0, win)
