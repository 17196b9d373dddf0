"""Spatio-temporal arrays of a run (paper Fig. 2a-b, 3a, 4); arrays only, no plotting.

All maps are ``[F, ...]`` over the stored frames, nondimensional.

* :func:`kinetic_energy_map`: ``T_i(t) / max_j T_j(t)`` [F, n], each instant normalized by its
  most energetic bead (Fig. 2a-b), so that late, weak motion stays visible.
* :func:`relative_velocity_map`: ``|v_(k-1) - v_k|`` per contact [F, n_contacts] (walls at rest),
  not normalized (Fig. 4); optionally its running maximum over ``window`` time units (an
  amplitude rather than an instantaneous value).
* :func:`boundary_map`: True where a contact is open [F, n_contacts]; open contacts are the
  cluster boundaries drawn as lines in Fig. 2b and 3a.
* :func:`cluster_labels`: cluster index of each bead [F, n] (0, 1, ... left to right).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d



def kinetic_energy_map(traj) -> np.ndarray:
    """Per-bead kinetic energy normalized per frame by the largest one [F, n] (0 where all rest);
    ``m_i v_i^2 / 2`` with the beads' masses for unlike beads."""
    e = 0.5 * traj.v ** 2
    mix = getattr(traj.scene, "mixture", None)
    if mix is not None:
        e = e * mix.mass
    top = e.max(axis=1, keepdims=True)
    return np.divide(e, top, out=np.zeros_like(e), where=top > 0)


def relative_velocity_map(traj, walls: bool = True, window: float = 0.0) -> np.ndarray:
    """``|v_(k-1) - v_k|`` for every contact (contract order) [F, n_contacts] (units p q).

    ``window > 0``: running maximum over that many time units (centred).
    """
    v = traj.v
    if walls:
        z = np.zeros((len(v), 1))
        v = np.hstack([z, v, z])
    rel = np.abs(v[:, :-1] - v[:, 1:])
    if window > 0 and len(traj.time) > 1:
        size = max(1, int(round(window / (traj.time[1] - traj.time[0]))))
        rel = maximum_filter1d(rel, size, axis=0)
    return rel


def states_map(traj) -> np.ndarray:
    """Contact states at every frame, True = closed [F, n_contacts]: the run's stored states
    (:attr:`~mdgran.output.run_record.Run.closed`)."""
    return np.asarray(traj.closed, bool)


def boundary_map(traj, states=None) -> np.ndarray:
    """True where a contact is open (a cluster boundary) [F, n_contacts], contract order."""
    return ~(states_map(traj) if states is None else np.asarray(states, bool))


def cluster_labels(traj, states=None) -> np.ndarray:
    """Index of the cluster of each bead at each frame [F, n], counted from the left."""
    closed = states_map(traj) if states is None else np.asarray(states, bool)
    n = traj.n
    inner = closed[:, 1:-1] if closed.shape[1] == n + 1 else closed  # contacts 2..n
    return np.hstack([np.zeros((len(closed), 1), int), np.cumsum(~inner, axis=1)])
