"""Effective damping C_eff(t) of a chain response (paper Eq. 7-9), nondimensional.

The paper replaces the chain, at each instant, by one oscillator of mass ``m_eff = N m`` that has
dissipated the same energy ``E_d(t)`` and has the same kinetic energy ``T(t)``.  From
``dE_d/dt = C_eff xdot_eff^2 = 2 C_eff T / m_eff`` (Eq. 8)::

    C_eff(t) = (m N / 2) * d<E_d>/dt / <<T>>                                  (Eq. 9)

* ``<E_d>``: a smoothing cubic spline of the dissipated energy.  Here ``E_d`` is read from the
  ledger, ``dissipated_viscous + dissipated_hysteresis``; the ledger closes, so this equals the
  paper's ``E0 - T - V`` up to the backend's error.
* ``<<T>>``: the mean of two cubic-spline interpolants, one through the local maxima of
  ``T(t)``, one through its local minima (the upper and lower envelopes).

Units: nondimensional, bead mass ``m = 1``; time in ``1/q``, energy in ``eta p``, so ``C_eff``
is in units of the damping scale ``sqrt(m eta / p)`` (Table I column 3).  The paper plots
``C_eff / C_+``; ``C_+`` in these units is the scene's ``contact.damping`` (``C_hat`` of Eq. 6,
0.013285 for the paper's chains).  :func:`effective_damping` returns that normalized value.

**Smoothing.**  ``make_smoothing_spline`` minimizes ``sum (y_i - s(t_i))^2 + lam int s''^2 dt``;
for samples spaced ``h`` this acts as the low-pass filter ``1 / (1 + lam h omega^4)``.  We set
``lam = (tau / 2 pi)^4 / h``, so ``smoothing_time = tau`` is the period that is passed at half
amplitude (period ``tau/2`` is cut to 6 %, ``2 tau`` kept at 94 %).
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline, CubicSpline, PchipInterpolator
from scipy.linalg import solve_banded

#: Default smoothing time (time units 1/q).  The fast intra-cluster period is about 2.3 and the
#: substrate period 2 pi / sqrt(k1) about 57 for the paper's chains: tau = 10 removes the former
#: and keeps the latter.  See :func:`smoothing_effect`.
SMOOTHING_TIME = 10.0


def smoothing_spline(t, y, smoothing_time: float = SMOOTHING_TIME):
    """Cubic smoothing spline of ``y(t)`` with half-amplitude cut-off period ``smoothing_time``.

    Returns a scipy ``BSpline`` (call it, or ``.derivative()``).  ``smoothing_time <= 0`` gives
    the interpolating spline.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    h = (t[-1] - t[0]) / (len(t) - 1)
    lam = (smoothing_time / (2.0 * np.pi)) ** 4 / h if smoothing_time > 0 else 0.0
    return make_smoothing_spline(t, y, lam)


def divided_difference_coefficients(x) -> np.ndarray:
    """The coefficients of the divided difference on the nodes ``x[:, j]`` of each column
    ``j`` of ``x`` [k, m]: ``1 / prod_{l != i} (x[i, j] - x[l, j])`` [k, m] (the product taken
    from ``l = 0`` up, as scipy's ``_coeff_of_divided_diff`` takes it for one column)."""
    x = np.asarray(x, float)
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        pp = np.ones(x.shape[1:])
        for k in range(x.shape[0]):
            if k != i:
                pp *= x[i] - x[k]
        out[i] = 1.0 / pp
    return out


def make_smoothing_spline(x, y, lam: float):
    """scipy's ``make_smoothing_spline(x, y, lam=lam)`` (scipy 1.17) for 1-D ``y``, unit
    weights and a given ``lam >= 0``, bitwise: the same operations in the same order, with the
    penalty matrix's columns computed together instead of one per sample (scipy's loop over
    the samples took 30 ms of 4001 samples, most of a sweep case's summary).  Returns a
    ``BSpline``; ``tests/test_analysis.py`` compares it with scipy's."""
    x = np.ascontiguousarray(x, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    if any(x[1:] - x[:-1] <= 0):
        raise ValueError("``x`` should be an ascending array")
    if x.ndim != 1 or y.ndim != 1 or x.shape[0] != y.shape[0]:
        raise ValueError(f"``x`` and ``y`` should be 1D of one length: {x.shape}, {y.shape}")
    n = x.shape[0]
    if n <= 4:
        raise ValueError("``x`` and ``y`` length must be at least 5")
    if lam < 0.0:
        raise ValueError("Regularization parameter should be non-negative")
    t = np.r_[[x[0]] * 3, x, [x[-1]] * 3]
    # the design matrix in the B-spline basis, moved to the basis of natural splines
    # (scipy's equations (2.1.7)): rows i + r, columns 3 + r of its bands, r = 0 .. n - 5
    X_bspl = BSpline.design_matrix(x, t, 3)
    X = np.zeros((5, n))
    for i in range(1, 4):
        X[i, 2:-2] = X_bspl[np.arange(i, n - 4 + i), np.arange(3, n - 1)]
    X[1, 1] = X_bspl[0, 0]
    X[2, :2] = ((x[2] + x[1] - 2 * x[0]) * X_bspl[0, 0], X_bspl[1, 1] + X_bspl[1, 2])
    X[3, :2] = ((x[2] - x[0]) * X_bspl[1, 1], X_bspl[2, 2])
    X[1, -2:] = (X_bspl[-3, -3], (x[-1] - x[-3]) * X_bspl[-2, -2])
    X[2, -2:] = (X_bspl[-2, -3] + X_bspl[-2, -2], (2 * x[-1] - x[-2] - x[-3]) * X_bspl[-1, -1])
    X[3, -2] = X_bspl[-1, -1]
    # the penalty matrix (unit weights): column j from the five samples j - 2 .. j + 2
    wE = np.zeros((5, n))
    wE[2:, 0] = divided_difference_coefficients(x[:3, None])[:, 0]
    wE[1:, 1] = divided_difference_coefficients(x[:4, None])[:, 0]
    nodes = np.stack([x[i:n - 4 + i] for i in range(5)])  # nodes[i, j - 2] = x[j - 2 + i]
    wE[:, 2:n - 2] = (x[4:] - x[:-4]) * divided_difference_coefficients(nodes)
    wE[:-1, -2] = -divided_difference_coefficients(x[-4:, None])[:, 0]
    wE[:-2, -1] = divided_difference_coefficients(x[-3:, None])[:, 0]
    wE *= 6
    c = solve_banded((2, 2), X + lam * wE, y)
    # back to the B-spline basis (scipy's equations (2.2.10))
    c0, c1 = c[0:1], c[1:2]
    cm0, cm1 = c[-1:-2:-1], c[-2:-3:-1]
    c_ = np.r_[c0 * (t[5] + t[4] - 2 * t[3]) + c1,
               c0 * (t[5] - t[3]) + c1,
               c[1:-1],
               cm0 * (t[-4] - t[-6]) + cm1,
               cm0 * (2 * t[-4] - t[-5] - t[-6]) + cm1]
    return BSpline.construct_fast(t, c_, 3)


def interior_extrema(y, comparator) -> np.ndarray:
    """Indices ``i`` (``0 < i < len(y) - 1``) where ``comparator(y[i], y[i - 1])`` and
    ``comparator(y[i], y[i + 1])`` (``np.greater``: the strict local maxima): scipy's
    ``argrelextrema(y, comparator)[0]`` (order 1; its clipped ends compare a sample with
    itself, never an extremum for a strict comparator), without importing scipy.signal (0.6 s
    of a process's start)."""
    y = np.asarray(y)
    inner = comparator(y[1:-1], y[:-2]) & comparator(y[1:-1], y[2:])
    return np.flatnonzero(inner) + 1


def envelope_mean(t, y, interpolant: str = "cubic"):
    """``<<y>>``: mean of the interpolants through the local maxima and the local minima of ``y``.

    An end sample counts as a maximum (minimum) when it is above (below) its neighbour; outside
    its first and last extremum each envelope is held constant (no extrapolation).
    ``interpolant`` is ``"cubic"`` (the paper's cubic spline) or ``"pchip"`` (no overshoot).
    The cubic envelope is kept from undershooting below the lower of the two extrema it joins:
    between two small maxima next to large ones a cubic spline can dip to zero or below, and
    ``<<T>>`` near zero made ``C_eff`` reach 5e9 C_+ in a sweep case (K1 = 5.9 N/m, v0 = 1).
    Returns an array like ``y``; ``[F]``, same units as ``y``.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    make = CubicSpline if interpolant == "cubic" else PchipInterpolator
    out = np.zeros_like(y)
    for sign, comparator in ((1.0, np.greater), (-1.0, np.less)):
        idx = list(interior_extrema(y, comparator))
        if sign * (y[0] - y[1]) >= 0:
            idx.insert(0, 0)
        if sign * (y[-1] - y[-2]) >= 0:
            idx.append(len(y) - 1)
        idx = np.array(idx, int)
        tc = np.clip(t, t[idx[0]], t[idx[-1]])
        if len(idx) > 2:
            env = make(t[idx], y[idx])(tc)
            k = np.clip(np.searchsorted(t[idx], tc, side="right") - 1, 0, len(idx) - 2)
            env = np.maximum(env, np.minimum(y[idx][k], y[idx][k + 1]))
        else:
            env = np.interp(tc, t[idx], y[idx])
        out += env
    return 0.5 * out


def c_eff(t, dissipated, kinetic, n_beads: int, mass: float = 1.0,
          smoothing_time: float = SMOOTHING_TIME, interpolant: str = "cubic",
          floor: float = 1e-9):
    """Eq. 9 on plain arrays: ``C_eff = (m N / 2) d<E_d>/dt / <<T>>`` (not normalized).

    ``t`` [F], ``dissipated`` ``E_d`` [F], ``kinetic`` ``T`` [F]; returns ``C_eff`` [F] in units of
    ``mass / time``.  ``<<T>>`` is clipped below at ``floor * max(T)`` so that a spline
    undershoot near ``T = 0`` gives a large value, not a division by zero.
    """
    rate = smoothing_spline(t, dissipated, smoothing_time).derivative()(t)
    tt = envelope_mean(t, kinetic, interpolant)
    tt = np.maximum(tt, floor * np.max(kinetic))
    return 0.5 * mass * n_beads * rate / tt


def dissipated_energy(traj) -> np.ndarray:
    """``E_d(t) = D_viscous + D_hysteresis`` from the ledger [F] (energy units eta p)."""
    return traj.ledger["dissipated_viscous"] + traj.ledger["dissipated_hysteresis"]


def contact_damping(scene) -> float:
    """``C_+`` in units of the damping scale: the scene's ``contact.damping`` (``C_hat``)."""
    return float(scene.contact.damping)


def effective_damping(run, *, smoothing_time: float = SMOOTHING_TIME,
                      interpolant: str = "cubic") -> np.ndarray:
    """Normalized effective damping ``C_eff(t) / C_+`` of a run (a
    :class:`~mdgran.output.run_record.Run`), [F] (dimensionless).

    Example::

        cbar = effective_damping(run(load_scene("micro-star"), "reference").trajectory)
    """
    mix = getattr(run.scene, "mixture", None)  # unlike beads: m N of Eq. 9 is the chain's mass
    mass = 1.0 if mix is None else float(np.mean(mix.mass))
    c = c_eff(run.time, dissipated_energy(run), run.ledger["kinetic_energy"], run.n, mass,
              smoothing_time=smoothing_time, interpolant=interpolant)
    cp = contact_damping(run.scene)
    return c / cp if cp > 0 else c


def smoothing_effect(run, smoothing_times=(2.5, 5.0, 10.0, 20.0, 40.0), *,
                     interpolant: str = "cubic") -> dict:
    """``C_eff / C_+`` for several smoothing times: ``{tau: array [F]}``, to show how much the
    curve (its peaks in particular) depends on that choice."""
    return {float(tau): effective_damping(run, smoothing_time=tau, interpolant=interpolant)
            for tau in smoothing_times}


def smoothed_kinetic(traj, interpolant: str = "cubic") -> np.ndarray:
    """``<<T>>(t)`` of a run [F] (energy units eta p)."""
    return envelope_mean(traj.time, traj.ledger["kinetic_energy"], interpolant)


def decay_time(t, kinetic, fraction: float = float(np.exp(-1.0)),
               interpolant: str = "cubic", envelope=None) -> float:
    """First time at which ``<<T>>`` falls below ``fraction * T(0)`` (NaN if it never does).

    Uses the envelope mean so that the fast exchange between kinetic and potential energy does
    not trigger it early.  ``envelope``: ``envelope_mean(t, kinetic, interpolant)`` if the
    caller has it already.
    """
    tt = envelope_mean(t, kinetic, interpolant) if envelope is None else envelope
    below = np.nonzero(tt < fraction * kinetic[0])[0]
    return float(t[below[0]]) if len(below) else float("nan")


#: The ledger's dissipation channels, name -> ledger key.
CHANNELS = {"viscous": "dissipated_viscous", "hysteresis": "dissipated_hysteresis"}


def dissipated_channels(traj) -> dict:
    """``E_d`` of each channel from the ledger: ``{"viscous": [F], "hysteresis": [F]}`` (energy
    units eta p); they add up to :func:`dissipated_energy`."""
    return {name: np.asarray(traj.ledger[key], float) for name, key in CHANNELS.items()}


def channel_damping(run, *, smoothing_time: float = SMOOTHING_TIME,
                    interpolant: str = "cubic", total=None) -> dict:
    """``C_eff / C_+`` [F] of Eq. 9 with ``E_d`` taken from one dissipation channel at a time:
    ``{"total", "viscous", "hysteresis"}``.  ``C_eff`` is linear in ``E_d`` (the smoothing
    spline and its derivative are linear, ``<<T>>`` is shared), so ``viscous + hysteresis`` is
    ``total`` (:func:`effective_damping`) to round-off.  Hysteresis is booked at the snap-off
    events that also form new clusters, so its peaks coincide with re-clustering partly by
    construction; the viscous part carries no such bookkeeping link.  ``total``: the run's
    :func:`effective_damping` at the same settings, if already computed."""
    kin = run.ledger["kinetic_energy"]
    cp = contact_damping(run.scene)
    if total is None:
        total = effective_damping(run, smoothing_time=smoothing_time, interpolant=interpolant)
    out = {"total": total}
    for name, ed in dissipated_channels(run).items():
        c = c_eff(run.time, ed, kin, run.n, smoothing_time=smoothing_time,
                  interpolant=interpolant)
        out[name] = c / cp if cp > 0 else c
    return out
