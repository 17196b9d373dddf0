"""The contact laws as compiled scalar functions (numba), one contact at a time.

The one implementation of the law's scalar arithmetic: the fast backend's kernel
(:mod:`mdgran.backends.fast_kernel`) calls these functions, and :mod:`mdgran.contact` inverts
the Schwarz law with :func:`branch_t` (through :func:`branch_t_ufunc`).  Units and equations
are those of :mod:`mdgran.contact` (force in ``eta``, compression in ``p``, energy in
``eta p``); with ``t = sqrt(a_hat)`` on the attached branch ``t >= t_min = sigma^(1/3)``::

    delta(t) = t^4 - 4 sigma t,     f(t) = fc + (t^3 - 3 sigma)^2,
    V(delta) = P(t(delta)) - P(t0),  P(t) = 0.4 t^10 - 4 sigma t^7 + (fc + 15 sigma^2) t^4
                                             - 4 sigma (fc + 9 sigma^2) t,   t0^3 = 4 sigma
    Hertz:   f = delta_+^(3/2),     V = 0.4 delta_+^(5/2)

Powers of ``t`` are products here (``t3 = t*t*t``); :class:`mdgran.contact.ContactLaw`
evaluates the same polynomials with numpy's ``**``, which rounds differently in the last bit,
so those two stay separate (see :mod:`mdgran.contact`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

#: Newton steps of the branch inversion (quadratic convergence reaches round-off after 5).
NEWTON_STEPS = 7
# 5-point Gauss-Legendre nodes and weights on [-1, 1] (exact for degree 9)
GL_X = np.array([-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
                 0.9061798459386640])
GL_W = np.array([0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                 0.4786286704993665, 0.2369268850561891])


class SchwarzConstants(NamedTuple):
    """The constants of one Schwarz law (all zero for Hertz, which needs none)."""

    fc: float  # pull-off force fc (units eta)
    sigma: float  # sqrt((fc + 2) / 3)
    t_min: float  # sigma^(1/3): branch parameter at the snap-off minimum of delta
    delta_min: float  # t_min^4 - 4 sigma t_min (units p)
    energy_zero: float  # P(t0): the antiderivative at delta = 0, so that V(0) = 0


NO_SCHWARZ = SchwarzConstants(0.0, 0.0, 0.0, 0.0, 0.0)


def schwarz_constants(law) -> SchwarzConstants:
    """The constants of a :class:`mdgran.contact.ContactLaw` (``NO_SCHWARZ`` for Hertz)."""
    if law.kind != "schwarz":
        return NO_SCHWARZ
    t0 = (4.0 * law.sigma) ** (1.0 / 3.0)
    return SchwarzConstants(float(law.fc), float(law.sigma), float(law.t_min),
                            float(law.delta_min), float(law._antiderivative(t0)))


@njit(cache=True)
def branch_t(delta, sigma, t_min, delta_min):
    """Branch parameter ``t >= t_min`` with ``t^4 - 4 sigma t = delta``, clamped to ``t_min``
    below ``delta_min``.

    Newton on ``phi(w) = w sqrt(w^2 + 4 t_min w + 6 t_min^2) = sqrt(delta - delta_min)``,
    ``w = t - t_min``, from the upper bound ``min(rhs / (sqrt(6) t_min), sqrt(rhs))`` (``phi``
    is increasing and convex, so the iterates fall monotonically to the root; ``phi >=
    max(sqrt(6) t_min w, w^2)`` makes the start an upper bound, within 30 % of the root over
    the whole branch: errors 0.29, 4e-2, 8e-4, 3e-7, 4e-14, 2e-16, so NEWTON_STEPS = 7 is a
    margin); DMT (``t_min = 0``): ``t = sqrt(rhs)`` exactly.
    """
    rhs = math.sqrt(max(delta - delta_min, 0.0))
    if t_min == 0.0:
        return math.sqrt(rhs)
    big = 6.0 * t_min * t_min
    w = min(rhs / math.sqrt(big), math.sqrt(rhs))
    for _ in range(NEWTON_STEPS):
        sq = math.sqrt(w * w + 4.0 * t_min * w + big)
        w = w - (w * sq - rhs) / (sq + w * (w + 2.0 * t_min) / sq)
    return t_min + max(w, 0.0)


@njit(cache=True)
def schwarz_force(delta, law):
    """Attached-branch force ``f(delta) = fc + (t^3 - 3 sigma)^2`` (units eta)."""
    t = branch_t(delta, law.sigma, law.t_min, law.delta_min)
    u = t * t * t - 3.0 * law.sigma
    return law.fc + u * u


@njit(cache=True)
def schwarz_energy(delta, law):
    """Contact energy ``V(delta) = P(t) - P(t0)`` on the attached branch (units eta p)."""
    sg, fc = law.sigma, law.fc
    t = branch_t(delta, sg, law.t_min, law.delta_min)
    t3 = t * t * t
    p = (0.4 * t3 * t3 * t3 * t - 4.0 * sg * t3 * t3 * t + (fc + 15.0 * sg * sg) * t3 * t
         - 4.0 * sg * (fc + 9.0 * sg * sg) * t)
    return p - law.energy_zero


@njit(cache=True)
def schwarz_mean_force(delta0, delta1, law):
    """Mean force over a compression interval, ``(V(delta1) - V(delta0)) / (delta1 - delta0)``.

    In the branch parameter it is the mean of ``f(t)`` weighted by ``delta'(t) = 4 (t^3 -
    sigma) >= 0`` over ``[t0, t1]``; ``f delta'`` is a polynomial of degree 9, so 5-point
    Gauss-Legendre is exact, with no cancellation when ``delta1 - delta0`` is small.  Where the
    weights vanish (both ends at ``t_min``) it is ``f(t0)``.
    """
    sg, tm, fc = law.sigma, law.t_min, law.fc
    t0 = branch_t(delta0, sg, tm, law.delta_min)
    t1 = branch_t(delta1, sg, tm, law.delta_min)
    mid, half = 0.5 * (t0 + t1), 0.5 * (t1 - t0)
    num = 0.0
    den = 0.0
    for k in range(5):
        tau = mid + half * GL_X[k]
        t3 = tau * tau * tau
        wk = GL_W[k] * (t3 - sg)
        u = t3 - 3.0 * sg
        num += wk * (fc + u * u)
        den += wk
    if den <= 0.0:
        u = t0 * t0 * t0 - 3.0 * sg
        return fc + u * u
    return num / den


@njit(cache=True)
def hertz_force(delta):
    """Hertz force ``delta_+^(3/2)`` (units eta)."""
    dp = max(delta, 0.0)
    return dp * math.sqrt(dp)


@njit(cache=True)
def hertz_energy(delta):
    """Hertz energy ``0.4 delta_+^(5/2)`` (units eta p)."""
    dp = max(delta, 0.0)
    return 0.4 * dp * dp * math.sqrt(dp)


@njit(cache=True)
def law_force(delta, hertz, law):
    """Exact force of a closed contact: Hertz if ``hertz``, else the Schwarz law ``law``."""
    if hertz:
        return hertz_force(delta)
    return schwarz_force(delta, law)


@njit(cache=True)
def law_energy(delta, hertz, law):
    """Exact energy of a closed contact: Hertz if ``hertz``, else the Schwarz law ``law``."""
    if hertz:
        return hertz_energy(delta)
    return schwarz_energy(delta, law)


_UFUNCS: dict = {}


def branch_t_ufunc():
    """:func:`branch_t` as a numpy ufunc ``(delta, sigma, t_min, delta_min) -> t`` (compiled
    on first use, cached on disk), for :meth:`mdgran.contact.ContactLaw.t_of_delta`: the plain
    numpy ufunc under numba's dynamic one (whose Python-level call costs ~5 us more)."""
    if "branch_t" not in _UFUNCS:
        from numba import vectorize

        _UFUNCS["branch_t"] = vectorize(["float64(float64, float64, float64, float64)"],
                                        cache=True)(branch_t.py_func).ufunc
    return _UFUNCS["branch_t"]


def _libm_pow(x, y):
    return math.pow(x, y)


def pow_ufunc():
    """``math.pow`` (the C library's ``pow``) as a numpy ufunc ``(x, y) -> x^y``, for the
    t-polynomials of :mod:`mdgran.contact` and :mod:`mdgran.chain`.  numpy's own ``**`` on
    arrays takes SIMD code on AVX-512 machines (SVML, not correctly rounded: 5% of ``t**3``
    differ in the last bit) and the C library elsewhere; the compiled kernels call ``pow``.
    With this ufunc the oracle's values are the same on every machine, and bitwise the
    kernels'."""
    if "pow" not in _UFUNCS:
        from numba import vectorize

        _UFUNCS["pow"] = vectorize(["float64(float64, float64)"], cache=True)(_libm_pow).ufunc
    return _UFUNCS["pow"]
