"""Cluster statistics of a run, and their comparison between ensembles of runs.

Past the predictability horizon two runs of a chaotic chain no longer share individual events,
but a correct backend still produces the same *statistics*: the same distribution of cluster
lifetimes and sizes.  A cluster (see :mod:`.clusters`) lives from the event time at which it
appears to the event time at which it stops existing (a bead joins it, leaves it, or its wall
attachment changes); clusters still alive at the end of the run are censored there and left out
of the lifetime sample (they would bias it towards the run's length).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .clusters import ClusterHistory


@dataclass
class ClusterLives:
    """One row per cluster that formed at ``t >= t_from`` and ended before the run's end:
    ``born`` [C], ``lifetime`` [C] (time units 1/q), ``size`` [C] (beads), and the cluster
    itself (``clusters`` [C], :class:`~.clusters.Cluster`)."""

    born: np.ndarray
    lifetime: np.ndarray
    size: np.ndarray
    clusters: list = None

    def __len__(self):
        return len(self.born)


def cluster_lives(history: ClusterHistory, t_from: float = -np.inf) -> ClusterLives:
    """Lifetimes and sizes of the clusters formed at or after ``t_from`` (the initial clusters,
    present before the first event, have no birth time and are not counted)."""
    alive = {c: None for c in history.initial}  # cluster -> birth time (None: initial)
    born, life, size, which = [], [], [], []
    for t, after in zip(history.times, history.clusters):
        now = set(after)
        for c in [c for c in alive if c not in now]:
            t0 = alive.pop(c)
            if t0 is not None and t0 >= t_from:
                born.append(t0)
                life.append(t - t0)
                size.append(c.last - c.first + 1)
                which.append(c)
        for c in now:
            alive.setdefault(c, t)
    return ClusterLives(np.array(born, float), np.array(life, float), np.array(size, int), which)


def pooled(lives: list) -> ClusterLives:
    """Pool several runs' :class:`ClusterLives` into one sample."""
    return ClusterLives(*(np.concatenate([getattr(x, k) for x in lives]) if lives
                          else np.zeros(0) for k in ("born", "lifetime", "size")),
                        [c for x in lives for c in (x.clusters or [])])


def ks_compare(a, b) -> dict:
    """Two-sample Kolmogorov-Smirnov test: statistic D, p-value, and the sample sizes."""
    import warnings

    from scipy.stats import ks_2samp

    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 2 or len(b) < 2:
        return {"statistic": None, "pvalue": None, "n": [len(a), len(b)]}
    with warnings.catch_warnings():  # "exact calculation unsuccessful, using asymptotic"
        warnings.simplefilter("ignore", RuntimeWarning)
        r = ks_2samp(a, b)
    return {"statistic": float(r.statistic), "pvalue": float(r.pvalue), "n": [len(a), len(b)]}
