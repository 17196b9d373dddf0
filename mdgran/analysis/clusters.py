"""Clusters, re-clustering and the segment measures of paper Sec. IV.B, VI and Appendix A.

**Contact states.**  Contacts use the contract numbering: with fixed walls contact ``k = 1..n+1``
joins bead ``k-1`` and bead ``k`` (beads ``0`` and ``n+1`` are the walls); a free chain has
contacts ``2..n``.  A state vector ``closed`` holds one bool per contact in that order.  The
states at any time are the initial states (all closed in the paper's initial condition, all open
when the scene has an initial gap) updated by the event list (``ev_kind`` 1 close, 0 open).

**Clusters.**  A cluster is a maximal run of moving beads joined by closed contacts; every bead
belongs to exactly one cluster (a lone bead is a cluster of size 1, unless ``min_size`` says
otherwise), so the open bead-bead contacts are the cluster boundaries.  A run whose end bead is
held by a closed wall contact *counts* as a cluster and records it (``left_wall``,
``right_wall``).  By default (``attach=True``) the attachment is part of the cluster's identity:
a run that sticks to or leaves a wall is a new cluster, since its dynamics (its linear modes,
:mod:`.modes`) change.  With ``attach=False`` only the bead run matters, so wall events form no
new clusters.

**Re-clustering.**  A newly formed cluster is one present just after an event that was not
present just before it.  Events at the same instant are handled together.  The cumulative
number of newly formed clusters ``N(t)`` starts at 0 (the initial clusters are not counted).
The events that form new clusters split the run into segments; events closer than
``merge_within`` (time units 1/q) are merged into one re-clustering event, so that a snap-off
cascade (three contacts within 0.03 in micro-star) does not make segments of vanishing length,
the "numerical artifacts" of the paper's discretization (Appendix A, Sec. VI).

**Appendix A.**  Smoothed ``N(t)``: a curve through ``(t_0, 0)`` (the start pinned to the
origin), the midpoints of the inner segments at their ``N``, and the start of the last segment at
its ``N`` with zero slope, constant after (flat over the final stable segment); then smoothed
over the frames with the cut-off period of :mod:`.effective_damping`; its derivative is the
re-clustering rate.  The paper joins the knots by a cubic spline and smooths with a smoothing
spline: both overshoot (the spline between unequal steps, the smoothing spline's equivalent
kernel has negative lobes), which drew negative rates of cluster formation.  Here the curve is
the monotone cubic (PCHIP slopes) through the same knots, so its increments are never
negative, and the increments are smoothed with a Gaussian kernel (non-negative, reflected at
both ends so no count is lost), so the rate is never negative, integrates to the number of newly
formed clusters, and the smoothed ``N(t)`` is non-decreasing (:func:`smoothed_cumulative`).
Segment ``m`` ``[t_m, t_(m+1))``: mean ``C_eff`` over it, and rate
``r_m = (N_(m+1) - N_m) / (t_(m+1) - t_m)`` (the slope joining the leading edges of segment ``m``
and ``m+1`` in Fig. A1c; undefined, NaN, for the last segment).  The representative segment of a
run is the one with the largest mean ``C_eff`` among those with a rate (Sec. VI).
"""
from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from ..model.chain import contact_numbers, initial_states, replay_states  # noqa: F401 - re-exported
from .effective_damping import SMOOTHING_TIME

#: Events closer than this (time units 1/q) form one re-clustering event.  About half the fast
#: intra-cluster period (2.3 for the paper's chains).
MERGE_WITHIN = 1.0

#: event times per block of contact states in :func:`cluster_history`
HISTORY_BLOCK = 4096

Cluster = namedtuple("Cluster", "first last left_wall right_wall")
Cluster.__doc__ = "A run of beads ``first..last`` (1-based, inclusive) and its wall attachment."


# ---- contact states --------------------------------------------------------------------------
def contact_states(times, ev_time, ev_contact, ev_kind, n: int, walls: bool = True,
                   initial=None) -> np.ndarray:
    """Contact states at each of ``times``: bool ``[F, n_contacts]`` (True = closed).

    A frame at time ``t`` shows every event with ``ev_time <= t`` applied
    (:func:`~mdgran.model.chain.replay_states`).
    """
    init = initial_states(n, walls) if initial is None else np.asarray(initial, bool)
    return replay_states(init, ev_time, ev_contact, ev_kind, times, walls)


# ---- clusters of one state -------------------------------------------------------------------
def clusters_of(closed, n: int, min_size: int = 1) -> list:
    """Clusters of one contact state vector, left to right, as :class:`Cluster` tuples."""
    closed = np.asarray(closed, bool)
    walls = len(closed) == n + 1
    inner = closed[1:-1] if walls else closed  # bead-bead contacts 2..n: between bead k-1, k
    out, first = [], 1
    for k in range(2, n + 2):  # a cluster ends at bead k-1 if contact k is open (or k = n+1)
        if k == n + 1 or not inner[k - 2]:
            last = k - 1
            if last - first + 1 >= min_size:
                out.append(Cluster(first, last, bool(walls and first == 1 and closed[0]),
                                   bool(walls and last == n and closed[-1])))
            first = k
    return out


def _key(c: Cluster, attach: bool):
    return c if attach else (c.first, c.last)


def new_clusters(before: list, after: list, attach: bool = True) -> list:
    """Clusters of ``after`` that are not in ``before``."""
    old = {_key(c, attach) for c in before}
    return [c for c in after if _key(c, attach) not in old]


@dataclass
class ClusterHistory:
    """Clusters after each distinct event time.

    ``times`` [K] distinct event times; ``clusters`` list of K lists (after the events at that
    time); ``count`` [K] number of clusters; ``new`` [K] newly formed clusters at that time;
    ``cumulative`` [K] running sum of ``new``; ``initial``: clusters before the first event.
    """

    times: np.ndarray
    clusters: list
    count: np.ndarray
    new: np.ndarray
    cumulative: np.ndarray
    initial: list

    def cumulative_at(self, t) -> np.ndarray:
        """Step function ``N(t)``: newly formed clusters up to and including ``t``."""
        i = np.searchsorted(self.times, np.asarray(t, float), side="right")
        return np.concatenate(([0], self.cumulative))[i]

    def count_at(self, t) -> np.ndarray:
        i = np.searchsorted(self.times, np.asarray(t, float), side="right")
        return np.concatenate(([len(self.initial)], self.count))[i]


def cluster_history(ev_time, ev_contact, ev_kind, n: int, walls: bool = True, initial=None,
                    attach: bool = True, min_size: int = 1) -> ClusterHistory:
    """Follow the clusters through the event list (see the module docstring): the contact
    states just after each distinct event time (:func:`contact_states` there), and their
    clusters."""
    init = initial_states(n, walls) if initial is None else np.array(initial, bool)
    times = np.unique(np.asarray(ev_time, float))
    current = clusters_of(init, n, min_size)
    initial_clusters = current
    clusters, new = [], []
    for start in range(0, len(times), HISTORY_BLOCK):  # blocks bound the states' memory
        block = times[start:start + HISTORY_BLOCK]
        for state in contact_states(block, ev_time, ev_contact, ev_kind, n, walls, init):
            after = clusters_of(state, n, min_size)
            clusters.append(after)
            new.append(len(new_clusters(current, after, attach)))
            current = after
    new = np.array(new, int)
    count = np.array([len(c) for c in clusters], int)
    return ClusterHistory(np.array(times, float), clusters, count, new, np.cumsum(new),
                          initial_clusters)


def trajectory_history(run, *, attach: bool = True, min_size: int = 1) -> ClusterHistory:
    """:func:`cluster_history` of a run (a :class:`~mdgran.output.run_record.Run`)."""
    return cluster_history(run.ev_time, run.ev_contact, run.ev_kind, run.n, run.walls,
                           run.initial_states(), attach, min_size)


# ---- segments ----------------------------------------------------------------------------------
def reclustering_events(history: ClusterHistory, merge_within: float = MERGE_WITHIN):
    """Times and sizes of re-clustering events: ``(times [E], new [E])``.

    Event times that form new clusters, grouped when each is within ``merge_within`` of the
    previous one; a group takes its first time and the sum of its new clusters.
    """
    t = history.times[history.new > 0]
    k = history.new[history.new > 0]
    if len(t) == 0:
        return t, k
    start = np.concatenate(([True], np.diff(t) >= merge_within))
    group = np.cumsum(start) - 1
    return t[start], np.bincount(group, weights=k).astype(int)


@dataclass
class Segments:
    """Intervals between re-clustering events: ``start`` [M], ``end`` [M], ``cumulative`` [M]
    (newly formed clusters up to the segment's start; 0 for the first segment)."""

    start: np.ndarray
    end: np.ndarray
    cumulative: np.ndarray

    def __len__(self):
        return len(self.start)

    @property
    def lifespan(self) -> np.ndarray:
        return self.end - self.start

    @property
    def rate(self) -> np.ndarray:
        """``r_m = (N_(m+1) - N_m) / lifespan_m`` [M]; NaN for the last segment."""
        r = np.full(len(self), np.nan)
        r[:-1] = np.diff(self.cumulative) / self.lifespan[:-1]
        return r


def segments(history: ClusterHistory, t_start: float, t_end: float,
             merge_within: float = MERGE_WITHIN) -> Segments:
    """Split ``[t_start, t_end]`` at the re-clustering events (Appendix A.B)."""
    t, k = reclustering_events(history, merge_within)
    keep = (t > t_start) & (t < t_end)
    t, k = t[keep], k[keep]
    edges = np.concatenate(([t_start], t, [t_end]))
    return Segments(edges[:-1], edges[1:], np.concatenate(([0], np.cumsum(k))))


def smoothed_cumulative(time, segs: Segments, smoothing_time: float = SMOOTHING_TIME):
    """Appendix A.A: smooth ``N(t)`` and its derivative, the re-clustering rate, on ``time``.

    Returns ``(N_smooth [F], rate [F])``; rate in clusters per time unit (1/q).

    ``N`` through the Appendix A knots (see the module docstring) is the monotone cubic
    (PCHIP slopes, zero slope at the last knot), so its increment ``m_i`` over each frame
    interval is >= 0.  The increments are convolved with a normalized Gaussian of standard
    deviation ``sigma = smoothing_time sqrt(2 ln 2) / (2 pi)`` (in frames), whose transfer
    function passes the period ``smoothing_time`` at half amplitude, as the smoothing spline of
    :mod:`.effective_damping` does, but with no negative lobe; the kernel is reflected at both
    ends of ``time`` (a symmetric, mass-preserving operator), so the increments still add up to
    ``N`` at the end.  The rate at a frame is the mean density of the two intervals beside it;
    ``N_smooth`` is its running trapezoid integral.  Hence ``rate >= 0``, ``N_smooth`` is
    non-decreasing from 0, and on a uniform grid ``N_smooth[-1]`` (the rate's trapezoid
    integral) equals the number of newly formed clusters inside ``time``'s span to round-off.
    ``smoothing_time <= 0``: no smoothing (the monotone curve's own increments).
    """
    from scipy.interpolate import CubicHermiteSpline, PchipInterpolator
    from scipy.ndimage import gaussian_filter1d

    time = np.asarray(time, float)
    m = len(segs)
    if m == 1 or len(time) < 2:
        return np.zeros_like(time), np.zeros_like(time)
    mid = 0.5 * (segs.start + segs.end)
    kt = np.concatenate(([segs.start[0]], mid[1:-1], [segs.start[-1]]))
    kv = np.concatenate(([0.0], segs.cumulative[1:-1], [segs.cumulative[-1]])).astype(float)
    slope = PchipInterpolator(kt, kv).derivative()(kt)
    slope[-1] = 0.0  # flat into the final stable segment; 0 keeps the cubic monotone
    curve = CubicHermiteSpline(kt, kv, np.maximum(slope, 0.0))(np.clip(time, kt[0], kt[-1]))
    mass = np.maximum(np.diff(curve), 0.0)  # clusters formed in each frame interval
    width = np.diff(time)
    if smoothing_time > 0 and len(mass) > 1:
        sigma = smoothing_time * np.sqrt(2.0 * np.log(2.0)) / (2.0 * np.pi) / np.mean(width)
        # the kernel must fit in the interval for the reflection to keep every count
        sigma = min(sigma, (len(mass) - 1) / 8.0)
        mass = gaussian_filter1d(mass, sigma, mode="reflect", truncate=4.0)
        mass = np.maximum(mass, 0.0)  # round-off only: the kernel has no negative weight
    rate = np.empty_like(time)
    rate[0], rate[-1] = mass[0] / width[0], mass[-1] / width[-1]
    rate[1:-1] = (mass[:-1] + mass[1:]) / (width[:-1] + width[1:])
    smooth = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * width)))
    return smooth, rate


def segment_means(time, values, segs: Segments) -> np.ndarray:
    """Time mean of ``values(t)`` (linear between frames) over each segment [M]."""
    time = np.asarray(time, float)
    values = np.asarray(values, float)
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(time))))
    i0, i1 = np.interp(segs.start, time, integral), np.interp(segs.end, time, integral)
    mean_at = np.interp(segs.start, time, values)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(segs.lifespan > 0, (i1 - i0) / segs.lifespan, mean_at)


def representative_segment(segs: Segments, c_means, t_min: float = -np.inf) -> int:
    """Index of the segment with the largest mean ``C_eff`` among those with a rate (all but the
    last) that start at or after ``t_min``; -1 if there is none (no re-clustering).

    ``t_min`` excludes the impact transient: in the first instants after the impulse ``C_eff``
    measures the struck bead's dashpots, not re-clustering (in the paper's sweep, at v0 <= 2
    the literal rule picks a segment [0, 0.2-0.4] with C_eff ~ 50-220 C_+)."""
    c = np.asarray(c_means, float)[:-1].copy()
    c[np.asarray(segs.start[:-1]) < t_min] = np.nan
    if len(c) == 0 or not np.any(np.isfinite(c)):
        return -1
    return int(np.nanargmax(c))


@dataclass
class ReclusteringAnalysis:
    """Everything of Appendix A for one run (see :func:`analyze_reclustering`)."""

    history: ClusterHistory
    segments: Segments
    cumulative_smooth: np.ndarray  # [F]
    rate: np.ndarray  # [F] smoothed re-clustering rate
    segment_c_eff: np.ndarray  # [M]
    segment_rate: np.ndarray  # [M]
    representative: int  # segment index, -1 if none


def analyze_reclustering(run, c_eff, *, smoothing_time: float = SMOOTHING_TIME,
                         merge_within: float = MERGE_WITHIN, attach: bool = True,
                         min_size: int = 1, history: ClusterHistory | None = None
                         ) -> ReclusteringAnalysis:
    """Clusters, segments, smoothed rate and segment measures of a run (a
    :class:`~mdgran.output.run_record.Run`), given its ``c_eff`` [F] (normally
    :func:`~.effective_damping.effective_damping`); ``history``: its
    :func:`trajectory_history` with the same ``attach`` and ``min_size``, if already known."""
    hist = trajectory_history(run, attach=attach, min_size=min_size) if history is None \
        else history
    segs = segments(hist, float(run.time[0]), float(run.time[-1]), merge_within)
    smooth, rate = smoothed_cumulative(run.time, segs, smoothing_time)
    means = segment_means(run.time, c_eff, segs)
    return ReclusteringAnalysis(hist, segs, smooth, rate, means, segs.rate,
                                representative_segment(segs, means))
