"""The primary (Nesterenko) pulse and the paper's time normalization (Sec. III, IV.A).

The paper divides time "by the time needed for the primary Nesterenko solitary pulse to travel
twice from one boundary to the other" and calls that a characteristic period::

    T_c = 2 (n + 1) / c_pulse

with ``n + 1`` bead spacings between the walls and ``c_pulse`` in beads per time unit (1/q).
(Sec. IV.A also words it "twice the duration of the Nesterenko primary pulse"; we read it as the
same normalization, which puts micro-star's localization at about 1.6 T_c as in the paper;
:func:`pulse_duration` gives the pulse's own width for comparison.)  For micro-star
``c_pulse = 1.40`` and ``T_c = 30``.
"""
from __future__ import annotations

import numpy as np


def _arrival_index(v, level):
    above = np.flatnonzero(v > level)
    if above.size == 0:
        return None
    k = above[0]
    while k + 1 < len(v) and v[k + 1] >= v[k]:
        k += 1
    return k


def primary_pulse_speed(traj, v0: float | None = None, first: int = 3, last: int | None = None):
    """Speed of the primary pulse (beads per time unit): straight-line fit of the time at which
    each bead's velocity first peaks above ``0.2 v0``, beads ``first..last`` (1-based, away from
    the walls; ``last`` defaults to ``n - 2``).  ``v0`` defaults to the largest initial speed.
    NaN if the pulse does not reach those beads."""
    v0 = float(np.max(np.abs(traj.v[0]))) if v0 is None else abs(v0)
    sign = np.sign(traj.v[0][np.argmax(np.abs(traj.v[0]))]) or 1.0
    last = traj.n - 2 if last is None else last
    beads, times = [], []
    for i in range(first, last + 1):
        k = _arrival_index(sign * traj.v[:, i - 1], 0.2 * v0)
        if k is not None:
            beads.append(i)
            times.append(traj.time[k])
    if len(beads) < 2:
        return float("nan")
    return 1.0 / np.polyfit(beads, times, 1)[0]


def characteristic_period(traj, speed: float | None = None) -> float:
    """``T_c = 2 (n + 1) / c_pulse`` in time units (the paper's time normalization)."""
    c = primary_pulse_speed(traj) if speed is None else speed
    return 2.0 * (traj.n + 1) / c


def pulse_duration(traj, bead: int | None = None) -> float:
    """Full width at half maximum (time units) of the primary pulse's velocity at ``bead``
    (1-based, default the middle bead) on its first passage."""
    bead = (traj.n + 1) // 2 if bead is None else bead
    sign = np.sign(traj.v[0][np.argmax(np.abs(traj.v[0]))]) or 1.0
    v = sign * traj.v[:, bead - 1]
    k = _arrival_index(v, 0.2 * np.max(np.abs(traj.v[0])))
    if k is None:
        return float("nan")
    half = 0.5 * v[k]
    lo = k
    while lo > 0 and v[lo - 1] > half:
        lo -= 1
    hi = k
    while hi + 1 < len(v) and v[hi + 1] > half:
        hi += 1
    return float(traj.time[hi] - traj.time[lo])
