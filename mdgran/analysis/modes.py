"""Linearized modes of a cluster (paper Sec. IV.A): Eq. 6 linearized about a compressed state.

For small motions ``u`` about a state with contact compressions ``delta_c``, unit bead mass, the
undamped linearized Eq. 6 of the beads ``first..last`` of a cluster is::

    u'' = -K u,     K = k1 I + sum_c k_c b_c b_c^T,     k_c = dF/d delta (delta_c)

where ``b_c = e_(i-1) - e_i`` for a bead-bead contact joining beads ``i-1`` and ``i`` of the
cluster, and ``b_c = e_i`` for a closed wall contact of an end bead (the wall does not move).
The cubic substrate term adds ``3 k3 x_i^2`` to the diagonal when it is kept.  Frequencies are
``omega_j = sqrt(eig_j(K))`` in rad per time unit (``q``), ascending; shapes are the unit
eigenvectors, one column per mode.  Damping is left out (``C_hat = 0.013`` shifts the
frequencies by less than 0.01 %).

The Schwarz law's stiffness is negative between ``delta_min`` and the tensile force maximum
``delta_force_max`` (-0.40 and -0.19 for lambda = 0.64): linearizing there, or about the mean of
a window in which a contact was open part of the time, gives NaN frequencies.  Linearize a
cluster over a window in which it persists (its contacts then sit near ``delta_eq``, 1.3-1.5 in
micro-star's late clusters).

Check: ``n`` beads, walls on both ends, equal ``k``:
``omega_j = sqrt(k1 + 4 k sin^2(j pi / (2 (n + 1))))``, ``j = 1..n``.
"""
from __future__ import annotations

import numpy as np


def stiffness_matrix(k_contacts, k1: float, left_wall: bool = False, right_wall: bool = False,
                     k_substrate=None) -> np.ndarray:
    """``K`` [b, b] of a cluster of ``b`` beads.

    ``k_contacts``: contact stiffnesses left to right: the left wall contact first if
    ``left_wall``, then the ``b - 1`` bead-bead contacts, then the right wall contact if
    ``right_wall``.  ``k_substrate``: optional per-bead substrate stiffness [b] (overrides
    ``k1``).
    """
    k = np.asarray(k_contacts, float)
    b = len(k) + 1 - int(left_wall) - int(right_wall)
    K = np.diag(np.full(b, float(k1)) if k_substrate is None else np.asarray(k_substrate, float))
    if left_wall:
        K[0, 0] += k[0]
        k = k[1:]
    if right_wall:
        K[-1, -1] += k[-1]
        k = k[:-1]
    for i, kc in enumerate(k):  # contact between cluster beads i and i+1
        K[i, i] += kc
        K[i + 1, i + 1] += kc
        K[i, i + 1] -= kc
        K[i + 1, i] -= kc
    return K


def modes(k_contacts, k1: float, left_wall: bool = False, right_wall: bool = False,
          k_substrate=None, masses=None):
    """Frequencies ``omega`` [b] (rad per time unit, ascending) and shapes [b, b] (columns).

    A negative eigenvalue (an unstable state) gives a NaN frequency.  ``masses`` [b] (unlike
    beads): ``M u'' = -K u``, solved as ``M^-1/2 K M^-1/2``; shapes ``M^-1/2 y`` scaled to unit
    length."""
    kmat = stiffness_matrix(k_contacts, k1, left_wall, right_wall, k_substrate)
    if not np.all(np.isfinite(kmat)):  # a contact off its attached branch: no linear modes
        return np.full(len(kmat), np.nan), np.full(kmat.shape, np.nan)
    s = None if masses is None else 1.0 / np.sqrt(np.asarray(masses, float))
    if s is not None:
        kmat = s[:, None] * kmat * s[None, :]
    w2, shapes = np.linalg.eigh(kmat)
    if s is not None:
        shapes = s[:, None] * shapes
        shapes /= np.linalg.norm(shapes, axis=0)
    tiny = 1e-12 * max(1.0, float(np.max(np.abs(w2))))
    w2 = np.where(np.abs(w2) < tiny, 0.0, w2)
    with np.errstate(invalid="ignore"):
        return np.sqrt(w2), shapes  # NaN for an unstable state (negative eigenvalue)


def cluster_modes(law, compressions, k1: float, left_wall: bool = False,
                  right_wall: bool = False, k3: float = 0.0, x=None):
    """Modes of a cluster about given contact compressions (same order as ``k_contacts`` of
    :func:`stiffness_matrix`), with ``k_c = law.stiffness(delta_c)``.  ``x`` [b]: bead
    displacements, needed only for the cubic substrate (``k1 + 3 k3 x^2``)."""
    kc = np.atleast_1d(law.stiffness(np.asarray(compressions, float)))
    ks = None
    if k3 and x is not None:
        ks = k1 + 3.0 * k3 * np.asarray(x, float) ** 2
    return modes(kc, k1, left_wall, right_wall, ks)


def equilibrium_modes(law, size: int, k1: float, left_wall: bool = False,
                      right_wall: bool = False):
    """Modes of a cluster of ``size`` beads with every contact at the law's natural equilibrium
    ``delta_eq`` (the star of paper Fig. 1b, stiffness 1.811 for lambda = 0.64)."""
    nc = size - 1 + int(left_wall) + int(right_wall)
    return cluster_modes(law, np.full(nc, law.delta_eq), k1, left_wall, right_wall)


def cluster_modes_in_run(traj, cluster, t0: float, t1: float):
    """Modes of ``cluster`` (a :class:`~.clusters.Cluster`) about its mean state over frames in
    ``[t0, t1]``: each contact's stiffness at its time-mean compression.

    Returns ``(omega [b], shapes [b, b], mean_compressions)``.
    """
    from ..model.chain import contact_columns, model_from_scene

    model = model_from_scene(traj.scene)
    sel = (traj.time >= t0) & (traj.time <= t1)
    xm = traj.x[sel].mean(axis=0)
    delta = model.compressions(xm)  # per contact, contract order
    lo = cluster.first if cluster.left_wall else cluster.first + 1  # contract numbers
    hi = cluster.last + 1 if cluster.right_wall else cluster.last
    c_lo, c_hi = contact_columns([lo, hi], model.walls)
    comp = delta[c_lo: c_hi + 1]
    x = xm[cluster.first - 1: cluster.last]
    if model.mixed:  # unlike beads: each contact's own stiffness, the beads' masses
        mix = model.mixture
        kc = mix.stiffness(comp, np.arange(c_lo, c_hi + 1))
        ks = mix.substrate[cluster.first - 1: cluster.last] * (model.k1 + 3.0 * model.k3 * x**2)
        om, sh = modes(kc, model.k1, cluster.left_wall, cluster.right_wall, ks,
                       mix.mass[cluster.first - 1: cluster.last])
        return om, sh, comp
    om, sh = cluster_modes(model.law, comp, model.k1, cluster.left_wall, cluster.right_wall,
                           model.k3, x)
    return om, sh, comp


def damped_impulse_response(n: int, k0: float, k1: float, c: float, v0: float, bead: int,
                            t) -> np.ndarray:
    """Analytic motion of a chain of ``n`` beads between walls, every contact linear with
    stiffness ``k0`` and unilateral damping ``c`` (both contacts closed throughout), substrate
    ``k1``, after an impulse ``v0`` on ``bead`` (1-based), at times ``t`` [F]: ``x`` [F, n].

    With L the wall-to-wall Laplacian, K = k0 L + k1 I and C = c L commute: mode ``j`` has
    ``w_j^2 = k1 + k0 lam_j`` and decay rate ``c lam_j / 2``, ``lam_j = 4 sin^2(j pi/(2(n+1)))``,
    shapes ``sqrt(2/(n+1)) sin(i j pi / (n+1))``.  This is the linear limit of a tiny impulse
    (hard/tiny), with ``k0`` the law's stiffness at ``delta = 0``.
    """
    j = np.arange(1, n + 1)
    phi = np.sqrt(2.0 / (n + 1)) * np.sin(np.outer(np.arange(1, n + 1), j) * np.pi / (n + 1))
    lam = 4 * np.sin(j * np.pi / (2 * (n + 1))) ** 2
    w2 = k1 + k0 * lam
    gam = 0.5 * c * lam
    wd = np.sqrt(w2 - gam**2)
    q0dot = phi[bead - 1, :] * v0
    tt = np.asarray(t, float)[:, None]
    return (q0dot / wd * np.exp(-gam * tt) * np.sin(wd * tt)) @ phi.T
