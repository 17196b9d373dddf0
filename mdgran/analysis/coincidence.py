"""Do peaks of C_eff coincide with peaks of the re-clustering rate?  (paper Sec. IV.B, Fig. 5)

The paper states that peaks of the effective damping coincide with bursts of re-clustering.
This module puts a number on it:

* coincidence fraction: the fraction of peaks ``a`` (C_eff) that lie within ``window`` of some
  peak ``b`` (re-clustering rate), ``|a_i - b_j| <= window``;
* null model: the same fraction after a random circular shift of the ``b`` peaks over the
  analysed interval ``[t_start, t_end)`` (which keeps their number and spacings and breaks
  only their alignment with ``a``), ``n_shifts`` times;
* p-value: ``(1 + #{null >= observed}) / (1 + n_shifts)``.

The default window is one characteristic period ``T_c`` (:mod:`.pulse`).  The interval matters:
shifting over the whole run, when both kinds of peak crowd into the early, active part, rewards
that shared crowding as well as the alignment; pass ``t_range`` to test inside the active part
only.  Peaks are ``scipy.signal.find_peaks`` maxima whose prominence is at least
``prominence`` times the curve's range.
"""
from __future__ import annotations

import numpy as np

from .clusters import MERGE_WITHIN, analyze_reclustering
from .effective_damping import SMOOTHING_TIME, effective_damping
from .pulse import characteristic_period


def peak_times(t, y, prominence: float = 0.1, t_range=None) -> np.ndarray:
    """Times of the local maxima of ``y(t)`` with prominence >= ``prominence * (max - min)``,
    inside ``t_range = (t0, t1)`` if given."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    if t_range is not None:
        sel = (t >= t_range[0]) & (t <= t_range[1])
        t, y = t[sel], y[sel]
    span = float(np.nanmax(y) - np.nanmin(y)) if len(y) else 0.0
    if span <= 0:
        return np.array([])
    from scipy.signal import find_peaks  # here: importing scipy.signal takes 0.6 s

    idx, _ = find_peaks(y, prominence=prominence * span)
    return t[idx]


def coincidence_fraction(a, b, window: float) -> float:
    """Fraction of the times ``a`` within ``window`` of one of the times ``b`` (NaN if no ``a``)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if len(a) == 0:
        return float("nan")
    if len(b) == 0:
        return 0.0
    return float(np.mean(np.min(np.abs(a[:, None] - b[None, :]), axis=1) <= window))


def coincidence_test(a, b, window: float, t_start: float, t_end: float,
                     n_shifts: int = 1000, seed: int = 0) -> dict:
    """Observed coincidence fraction of ``a`` with ``b`` against random circular shifts of ``b``
    over ``[t_start, t_end)``.  Returns ``fraction``, ``null_mean``, ``null_std``, ``p_value``,
    ``n_a``, ``n_b``, ``window``, ``null`` (the ``n_shifts`` shifted fractions)."""
    rng = np.random.default_rng(seed)
    length = t_end - t_start
    b = np.asarray(b, float)
    obs = coincidence_fraction(a, b, window)
    shifts = rng.uniform(0.0, length, n_shifts)
    null = np.array([coincidence_fraction(a, t_start + (b - t_start + s) % length, window)
                     for s in shifts])
    return {"fraction": obs, "null_mean": float(np.mean(null)), "null_std": float(np.std(null)),
            "p_value": float((1 + np.sum(null >= obs)) / (1 + n_shifts)),
            "n_a": int(len(a)), "n_b": int(len(b)), "window": float(window), "null": null}


def run_coincidence(traj, *, window: float | None = None, t_range=None,
                    prominence: float = 0.1, smoothing_time: float = SMOOTHING_TIME,
                    merge_within: float = MERGE_WITHIN, n_shifts: int = 1000,
                    seed: int = 0, c_eff=None, reclustering=None) -> dict:
    """:func:`coincidence_test` of a run's C_eff peaks against its re-clustering-rate peaks.

    ``window`` defaults to the characteristic period ``T_c``; ``t_range`` to the whole run.
    The result also holds the peak times (``c_eff_peaks``, ``rate_peaks``) and ``t_range``.
    ``c_eff``, ``reclustering``: the run's :func:`~.effective_damping.effective_damping` and
    :func:`~.clusters.analyze_reclustering` at the same settings, if already computed.
    """
    cbar = effective_damping(traj, smoothing_time=smoothing_time) if c_eff is None else c_eff
    rc = (analyze_reclustering(traj, cbar, smoothing_time=smoothing_time,
                               merge_within=merge_within)
          if reclustering is None else reclustering)
    t0, t1 = (float(traj.time[0]), float(traj.time[-1])) if t_range is None else t_range
    window = characteristic_period(traj) if window is None else window
    a = peak_times(traj.time, cbar, prominence, (t0, t1))
    b = peak_times(traj.time, rc.rate, prominence, (t0, t1))
    out = coincidence_test(a, b, window, t0, t1, n_shifts, seed)
    out.update(c_eff_peaks=a, rate_peaks=b, t_range=(t0, t1))
    return out


# ---- vectorized shift nulls (many shifts, p not at its floor) ---------------------------------
def shifted_fractions(a, b, window: float, t_start: float, t_end: float, shifts,
                      chunk: int = 2000) -> np.ndarray:
    """:func:`coincidence_fraction` of ``a`` with ``b`` shifted circularly by each of
    ``shifts`` [K] (time units) over ``[t_start, t_end)``: [K] (NaN if no ``a``)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    shifts = np.asarray(shifts, float)
    if len(a) == 0:
        return np.full(len(shifts), np.nan)
    if len(b) == 0:
        return np.zeros(len(shifts))
    length = t_end - t_start
    out = np.empty(len(shifts))
    for i in range(0, len(shifts), chunk):
        bb = t_start + (b[None, :] - t_start + shifts[i:i + chunk, None]) % length  # [k, nb]
        near = np.min(np.abs(a[None, :, None] - bb[:, None, :]), axis=2) <= window  # [k, na]
        out[i:i + chunk] = np.mean(near, axis=1)
    return out


def _z(obs, null) -> float:
    sd = float(np.std(null))
    return float((obs - np.mean(null)) / sd) if sd > 0 else float("nan")


def coincidence_shift_test(a, b, window: float, t_start: float, t_end: float,
                           n_shifts: int = 10000, seed: int = 0) -> dict:
    """:func:`coincidence_test`, vectorized (same shifts for the same seed, so the same null and
    p-value), for many shifts; adds ``n_shifts`` and ``p_floor = 1 / (1 + n_shifts)``."""
    rng = np.random.default_rng(seed)
    obs = coincidence_fraction(a, b, window)
    null = shifted_fractions(a, b, window, t_start, t_end,
                             rng.uniform(0.0, t_end - t_start, n_shifts))
    return {"fraction": obs, "null_mean": float(np.mean(null)), "null_std": float(np.std(null)),
            "p_value": float((1 + np.sum(null >= obs)) / (1 + n_shifts)),
            "n_a": int(len(a)), "n_b": int(len(b)), "window": float(window),
            "n_shifts": int(n_shifts), "p_floor": 1.0 / (1 + n_shifts),
            "z": _z(obs, null), "null": null}


def coincidence_case(time, c_eff, rate, window: float, t_range=None, prominence: float = 0.1):
    """One case's input to :func:`pooled_coincidence_test`: ``(a, b, window, t0, t1)`` with
    ``a`` the ``C_eff`` peaks and ``b`` the rate peaks in ``t_range`` (default the whole run);
    None if either has no peak."""
    t0, t1 = (float(time[0]), float(time[-1])) if t_range is None else map(float, t_range)
    a = peak_times(time, c_eff, prominence, (t0, t1))
    b = peak_times(time, rate, prominence, (t0, t1))
    return (a, b, float(window), t0, t1) if len(a) and len(b) else None


def pooled_coincidence_test(per_case, n_shifts: int = 10000, seed: int = 0) -> dict:
    """Coincidence pooled over cases: the fraction of all ``a`` peaks within their case's window
    of a ``b`` peak of their case, against every case's ``b`` shifted circularly and
    independently (``per_case``: :func:`coincidence_case` tuples; None entries are skipped).
    The shifts are drawn as ``mdgran.studies.paper_study.pooled_coincidence`` draws them (same seed,
    same null), all at once.  Returns ``cases``, ``c_eff_peaks``, ``rate_peaks``, ``fraction``,
    ``null_mean``, ``null_std``, ``p_value``, ``n_shifts``, ``p_floor``, ``z`` (``(fraction -
    null_mean) / null_std``: when p is at its floor, how far beyond), ``null`` [K]."""
    per_case = [p for p in per_case if p is not None]
    n_a = sum(len(p[0]) for p in per_case)
    if not n_a:
        return {"cases": 0}
    rng = np.random.default_rng(seed)
    u = rng.uniform(size=(n_shifts, len(per_case)))
    obs = sum(coincidence_fraction(a, b, w) * len(a) for a, b, w, _, _ in per_case) / n_a
    null = np.zeros(n_shifts)
    for (a, b, w, t0, t1), s in zip(per_case, u.T):
        null += shifted_fractions(a, b, w, t0, t1, s * (t1 - t0)) * len(a)
    null /= n_a
    return {"cases": len(per_case), "c_eff_peaks": n_a,
            "rate_peaks": sum(len(p[1]) for p in per_case), "fraction": float(obs),
            "null_mean": float(null.mean()), "null_std": float(null.std()),
            "p_value": float((1 + np.sum(null >= obs)) / (1 + n_shifts)),
            "n_shifts": int(n_shifts), "p_floor": 1.0 / (1 + n_shifts),
            "z": _z(obs, null), "null": null}


def pooled_channel_coincidence(cases, window_frac: float = 0.25, prominence: float = 0.1,
                               active: bool = True, n_shifts: int = 10000,
                               seed: int = 0) -> dict:
    """:func:`pooled_coincidence_test` for each dissipation channel over sweep cases.

    ``cases``: mappings with ``"curves" = (time, c_eff_total, rate)``, ``"channels" = {name:
    c_eff [F]}`` (e.g. :func:`~.effective_damping.channel_damping` without ``"total"``),
    ``"characteristic_period"`` and ``"last_reclustering_time"`` (the rows of
    ``mdgran.studies.paper_study.sweep_cases`` plus ``"channels"``).  Window ``window_frac x T_c``;
    ``active``: each case from its start to one ``T_c`` after its last re-clustering event (as
    ``study.pooled_coincidence(active=True)``).  Returns ``{"total", name...}`` -> result (without
    ``null``), each with ``window_T_c``, ``prominence``, ``range``."""
    per = {}
    for c in cases:
        time, total, rate = c["curves"]
        tc = c.get("characteristic_period")
        if tc is None or not np.isfinite(tc):
            continue
        t0, t1 = float(time[0]), float(time[-1])
        if active:
            last = c.get("last_reclustering_time")
            if last is None:
                continue
            t1 = min(t1, last + tc)
        for name, cbar in {"total": total, **c.get("channels", {})}.items():
            per.setdefault(name, []).append(
                coincidence_case(time, cbar, rate, window_frac * tc, (t0, t1), prominence))
    out = {}
    for name, pc in per.items():
        r = pooled_coincidence_test(pc, n_shifts, seed)
        r.pop("null", None)
        r.update(window_T_c=window_frac, prominence=prominence,
                 range="active part" if active else "whole run")
        out[name] = r
    return out
