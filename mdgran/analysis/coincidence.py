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
from scipy.signal import find_peaks

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


def run_coincidence(traj, scene, window: float | None = None, t_range=None,
                    prominence: float = 0.1, smoothing_time: float = SMOOTHING_TIME,
                    merge_within: float = MERGE_WITHIN, n_shifts: int = 1000,
                    seed: int = 0) -> dict:
    """:func:`coincidence_test` of a run's C_eff peaks against its re-clustering-rate peaks.

    ``window`` defaults to the characteristic period ``T_c``; ``t_range`` to the whole run.
    The result also holds the peak times (``c_eff_peaks``, ``rate_peaks``) and ``t_range``.
    """
    cbar = effective_damping(traj, scene, smoothing_time)
    rc = analyze_reclustering(traj, scene, cbar, smoothing_time, merge_within)
    t0, t1 = (float(traj.time[0]), float(traj.time[-1])) if t_range is None else t_range
    window = characteristic_period(traj) if window is None else window
    a = peak_times(traj.time, cbar, prominence, (t0, t1))
    b = peak_times(traj.time, rc.rate, prominence, (t0, t1))
    out = coincidence_test(a, b, window, t0, t1, n_shifts, seed)
    out.update(c_eff_peaks=a, rate_peaks=b, t_range=(t0, t1))
    return out
