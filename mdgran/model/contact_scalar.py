"""The contact laws, one contact at a time: the one source of each law's arithmetic.

Each law is a small pure scalar function (numba ``njit``) with its formula in its docstring;
every user lifts these over contacts with a thin wrapper: :class:`mdgran.model.contact.ContactLaw`,
:mod:`mdgran.model.chain` and :mod:`mdgran.model.mixture` through numpy ufuncs (:func:`lifted`), the
fast kernel (:mod:`mdgran.backends.fast_kernel`) and the LAMMPS hook
(``mdgran.backends.lammps.hook``) by calling them in their compiled loops.  The C++ fix
(``mdgran/backends/lammps/fix/fix_mdgran_chain.cpp``) is the independent implementation: it keeps
its own code and takes its numerical constants from ``law_constants.h``, which
:func:`cxx_header` writes from the constants here.

Units are those of :mod:`mdgran.model.contact` (force in ``eta``, compression in ``p``, energy in
``eta p``).  With ``t = sqrt(a_hat)`` on the attached branch ``t >= t_min = sigma^(1/3)``::

    delta(t) = t^4 - 4 sigma t,     f(t) = fc + (t^3 - 3 sigma)^2,
    V(delta) = P(t(delta)) - P(t0),  P(t) = 0.4 t^10 - 4 sigma t^7 + (fc + 15 sigma^2) t^4
                                             - 4 sigma (fc + 9 sigma^2) t,   t0^3 = 4 sigma
    Hertz:   f = delta_+^(3/2),     V = 0.4 delta_+^(5/2)

**Two roundings of the powers of t.**  The NumPy side (``ContactLaw``, the chain's ledger,
mixtures), the LAMMPS hook and the C++ fix take the powers with the C library's ``pow``
(``*_libm`` functions; numpy's own ``**`` on arrays takes SIMD code on AVX-512 machines and
differs there in the last bit); the fast kernel takes them as products (``t3 = t*t*t``).  The
two differ in the last bit for about a quarter of all ``t``, and each backend's results are
kept bit for bit, so the polynomial ``P`` is written here in both orders, side by side; the
force shares :func:`schwarz_force_of_cube`.  Likewise the positive part ``delta_+`` of Hertz:
``max(delta, 0)`` keeps the sign of ``-0.0`` (the kernels', C++'s ``std::max``), numpy's
``np.maximum`` returns ``+0.0`` (:func:`positive_part_numpy`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

# ---- numerical constants (the C++ fix reads them from law_constants.h, cxx_header) ---------
#: Newton steps of the branch inversion (quadratic convergence reaches round-off after 5).
NEWTON_STEPS = 7
#: 5-point Gauss-Legendre nodes and weights on [-1, 1] (exact for degree 9)
GL_NODES = (-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
            0.9061798459386640)
GL_WEIGHTS = (0.2369268850561891, 0.4786286704993665, 0.5688888888888889, 0.4786286704993665,
              0.2369268850561891)
GL_X = np.array(GL_NODES)
GL_W = np.array(GL_WEIGHTS)
#: Closed contacts with delta below delta_min + SING_BAND get the mean-force kick (Schwarz,
#: displacement rule; the located-event passes of the fast kernel and of the C++ fix).
SING_BAND = 0.1
#: Pull-off forces fc (units eta) of the DMT and JKR limits: a Schwarz law has fc in between.
FC_DMT = -2.0
FC_JKR = -1.5
#: The Carpick-Ogletree-Salmeron relation ``lambda = -COS_LAMBDA ln(1 - COS_ALPHA alpha)``
#: (:func:`mdgran.model.contact.fc_from_lambda`).
COS_LAMBDA = 0.924
COS_ALPHA = 1.02


class SchwarzConstants(NamedTuple):
    """The constants of one Schwarz law (all zero for Hertz, which needs none)."""

    fc: float  # pull-off force fc (units eta)
    sigma: float  # sqrt((fc + 2) / 3)
    t_min: float  # sigma^(1/3): branch parameter at the snap-off minimum of delta
    delta_min: float  # t_min^4 - 4 sigma t_min (units p)
    energy_zero: float  # P(t0): the antiderivative at delta = 0, so that V(0) = 0


NO_SCHWARZ = SchwarzConstants(0.0, 0.0, 0.0, 0.0, 0.0)


def schwarz_constants(law) -> SchwarzConstants:
    """The constants of a :class:`mdgran.model.contact.ContactLaw` (``NO_SCHWARZ`` for Hertz)."""
    if law.kind != "schwarz":
        return NO_SCHWARZ
    return SchwarzConstants(float(law.fc), float(law.sigma), float(law.t_min),
                            float(law.delta_min), float(law.energy_zero))


# ---- the Schwarz branch ----------------------------------------------------------------------
@njit(cache=True)
def branch_delta(t, sigma):
    """Compression at branch parameter ``t``: ``delta = t^4 - 4 sigma t`` (units p)."""
    return math.pow(t, 4.0) - 4.0 * sigma * t


@njit(inline="always")
def branch_newton_start(delta, t_min, delta_min):
    """``(rhs, w, 6 t_min^2)``: the right-hand side ``sqrt(delta - delta_min)`` of
    :func:`branch_t`'s equation and its Newton iteration's start (``t_min > 0``)."""
    rhs = math.sqrt(max(delta - delta_min, 0.0))
    big = 6.0 * t_min * t_min
    return rhs, min(rhs / math.sqrt(big), math.sqrt(rhs)), big


@njit(inline="always")
def branch_newton_step(w, rhs, t_min, big):
    """One Newton step of :func:`branch_t` on ``phi(w) = rhs`` (``big = 6 t_min^2``)."""
    sq = math.sqrt(w * w + 4.0 * t_min * w + big)
    return w - (w * sq - rhs) / (sq + w * (w + 2.0 * t_min) / sq)


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
    if t_min == 0.0:
        return math.sqrt(math.sqrt(max(delta - delta_min, 0.0)))
    rhs, w, big = branch_newton_start(delta, t_min, delta_min)
    for _ in range(NEWTON_STEPS):
        w = branch_newton_step(w, rhs, t_min, big)
    return t_min + max(w, 0.0)


@njit(cache=True)
def schwarz_force_of_cube(t3, fc, sigma):
    """Schwarz force from ``t3 = t^3``: ``f = fc + (t^3 - 3 sigma)^2`` (units eta)."""
    u = t3 - 3.0 * sigma
    return fc + u * u


@njit(cache=True)
def schwarz_antiderivative_libm(t, fc, sigma):
    """``P(t) = 0.4 t^10 - 4 sigma t^7 + (fc + 15 sigma^2) t^4 - 4 sigma (fc + 9 sigma^2) t``
    (``P' = f delta'``; units eta p), the powers by the C library's ``pow``."""
    return (0.4 * math.pow(t, 10.0) - 4.0 * sigma * math.pow(t, 7.0)
            + (fc + 15.0 * sigma * sigma) * math.pow(t, 4.0)
            - 4.0 * sigma * (fc + 9.0 * sigma * sigma) * t)


@njit(cache=True)
def schwarz_antiderivative_products(t, fc, sigma):
    """``P(t)`` of :func:`schwarz_antiderivative_libm`, the powers as products of ``t^3`` and
    ``t`` (the fast kernel's rounding)."""
    t3 = t * t * t
    return (0.4 * t3 * t3 * t3 * t - 4.0 * sigma * t3 * t3 * t
            + (fc + 15.0 * sigma * sigma) * t3 * t - 4.0 * sigma * (fc + 9.0 * sigma * sigma) * t)


# ---- one law's values at one compression, constants as scalars (liftable to ufuncs) ----------
# Every law of the NumPy side takes (delta, fc, sigma, t_min, delta_min, energy_zero): the
# compression and the fields of SchwarzConstants (a law reads those it needs).
@njit(cache=True)
def schwarz_force_libm(delta, fc, sigma, t_min, delta_min, energy_zero):
    """Attached-branch force ``f(delta) = fc + (t^3 - 3 sigma)^2``, ``t^3`` by ``pow``."""
    t = branch_t(delta, sigma, t_min, delta_min)
    return schwarz_force_of_cube(math.pow(t, 3.0), fc, sigma)


@njit(cache=True)
def schwarz_energy_libm(delta, fc, sigma, t_min, delta_min, energy_zero):
    """Attached-branch energy ``V(delta) = P(t) - P(t0)`` (``energy_zero = P(t0)``), ``pow``."""
    t = branch_t(delta, sigma, t_min, delta_min)
    return schwarz_antiderivative_libm(t, fc, sigma) - energy_zero


@njit(cache=True, error_model="numpy")
def schwarz_stiffness_libm(delta, fc, sigma, t_min, delta_min, energy_zero):
    """``df/d delta = 6 t^2 (t^3 - 3 sigma) / (4 (t^3 - sigma))`` on the attached branch
    (units eta / p; infinite at ``delta_min``), ``t^3`` by ``pow``."""
    t = branch_t(delta, sigma, t_min, delta_min)
    t3 = math.pow(t, 3.0)
    return 6.0 * t * t * (t3 - 3.0 * sigma) / (4.0 * (t3 - sigma))


# ---- Hertz ----------------------------------------------------------------------------------
@njit(cache=True)
def hertz_force_of(dp):
    """Hertz force of the positive part ``dp = delta_+``: ``dp^(3/2)`` (units eta)."""
    return dp * math.sqrt(dp)


@njit(cache=True)
def hertz_energy_of(dp):
    """Hertz energy of ``dp = delta_+``: ``0.4 dp^(5/2)`` (units eta p)."""
    return 0.4 * dp * dp * math.sqrt(dp)


@njit(cache=True)
def hertz_stiffness_of(dp):
    """Hertz stiffness of ``dp = delta_+``: ``1.5 dp^(1/2)`` (units eta / p)."""
    return 1.5 * math.sqrt(dp)


@njit(cache=True)
def positive_part_numpy(delta):
    """``np.maximum(delta, 0.0)``: ``+0.0`` for ``-0.0`` and for negatives, NaN kept (numba's
    ``max(delta, 0.0)`` keeps ``-0.0``)."""
    return 0.0 if delta <= 0.0 else delta


@njit(cache=True)
def hertz_force(delta):
    """Hertz force ``delta_+^(3/2)`` (units eta), ``delta_+ = max(delta, 0)``."""
    return hertz_force_of(max(delta, 0.0))


@njit(cache=True)
def hertz_energy(delta):
    """Hertz energy ``0.4 delta_+^(5/2)`` (units eta p), ``delta_+ = max(delta, 0)``."""
    return hertz_energy_of(max(delta, 0.0))


@njit(cache=True)
def hertz_force_numpy(delta, fc, sigma, t_min, delta_min, energy_zero):
    """:func:`hertz_force` with numpy's positive part (:func:`positive_part_numpy`); the
    Schwarz constants are not read."""
    return hertz_force_of(positive_part_numpy(delta))


@njit(cache=True)
def hertz_energy_numpy(delta, fc, sigma, t_min, delta_min, energy_zero):
    """:func:`hertz_energy` with numpy's positive part (:func:`positive_part_numpy`)."""
    return hertz_energy_of(positive_part_numpy(delta))


@njit(cache=True)
def hertz_stiffness_numpy(delta, fc, sigma, t_min, delta_min, energy_zero):
    """Hertz stiffness ``1.5 delta_+^(1/2)`` with numpy's positive part."""
    return hertz_stiffness_of(positive_part_numpy(delta))


#: The NumPy side's laws by kind: ``(force, energy, stiffness)``, each a scalar function of
#: ``(delta, *SchwarzConstants)`` that :func:`numpy_law` lifts to a ufunc.
NUMPY_LAWS = {
    "schwarz": (schwarz_force_libm, schwarz_energy_libm, schwarz_stiffness_libm),
    "hertz": (hertz_force_numpy, hertz_energy_numpy, hertz_stiffness_numpy),
}
QUANTITIES = ("force", "energy", "stiffness")


# ---- the fast kernel's forms: constants in a SchwarzConstants record, powers as products ----
@njit(cache=True)
def schwarz_force(delta, law):
    """Attached-branch force ``f(delta) = fc + (t^3 - 3 sigma)^2`` (units eta), ``t^3`` as
    ``t*t*t``."""
    t = branch_t(delta, law.sigma, law.t_min, law.delta_min)
    return schwarz_force_of_cube(t * t * t, law.fc, law.sigma)


@njit(cache=True)
def schwarz_energy(delta, law):
    """Contact energy ``V(delta) = P(t) - P(t0)`` on the attached branch (units eta p), the
    powers as products."""
    t = branch_t(delta, law.sigma, law.t_min, law.delta_min)
    return schwarz_antiderivative_products(t, law.fc, law.sigma) - law.energy_zero


@njit(cache=True)
def schwarz_mean_force(delta0, delta1, law):
    """Mean force over a compression interval, ``(V(delta1) - V(delta0)) / (delta1 - delta0)``.

    In the branch parameter it is the mean of ``f(t)`` weighted by ``delta'(t) = 4 (t^3 -
    sigma) >= 0`` over ``[t0, t1]``; ``f delta'`` is a polynomial of degree 9, so 5-point
    Gauss-Legendre is exact, with no cancellation when ``delta1 - delta0`` is small.  Where the
    weights vanish (both ends at ``t_min``) it is ``f(t0)``.
    """
    t0 = branch_t(delta0, law.sigma, law.t_min, law.delta_min)
    t1 = branch_t(delta1, law.sigma, law.t_min, law.delta_min)
    return schwarz_mean_force_of_branch(t0, t1, law)


@njit(cache=True)
def schwarz_mean_force_of_branch(t0, t1, law):
    """:func:`schwarz_mean_force` from the branch parameters ``t0``, ``t1`` of the interval's
    ends (:func:`branch_t`)."""
    sg, fc = law.sigma, law.fc
    mid, half = 0.5 * (t0 + t1), 0.5 * (t1 - t0)
    num = 0.0
    den = 0.0
    for k in range(5):
        tau = mid + half * GL_X[k]
        t3 = tau * tau * tau
        wk = GL_W[k] * (t3 - sg)
        num += wk * schwarz_force_of_cube(t3, fc, sg)
        den += wk
    if den <= 0.0:
        return schwarz_force_of_cube(t0 * t0 * t0, fc, sg)
    return num / den


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


# ---- the force table's spline (mdgran.model.contact.ContactTable)
# ---------------------------------
@njit(inline="always")
def spline_cubic(c0, c1, c2, c3, x):
    """One interval's cubic, highest power first, in Horner form:
    ``((c0 x + c1) x + c2) x + c3``."""
    return ((c0 * x + c1) * x + c2) * x + c3


@njit(inline="always")
def spline_locate(delta, base, scale, top, h):
    """``(i, x)``: the interval ``i`` of a table with nodes uniform in ``w = sqrt(delta - base)``
    (``scale = 1 / h`` nodes per unit of w; the coordinate clamped to ``top`` just below the
    last node) and the offset ``x = w - w_i``."""
    w = math.sqrt(max(delta - base, 0.0))
    s = min(w * scale, top)
    i = int(s)
    return i, (s - i) * h


@njit(cache=True)
def spline_values(coef, base, scale, top, h, delta):
    """The table's spline ([n - 1, 4] coefficients ``coef``) at each of ``delta`` (1-D; NaN
    where ``delta`` is not finite)."""
    out = np.empty(delta.shape[0])
    for k in range(delta.shape[0]):
        if not math.isfinite(delta[k]):
            out[k] = math.nan
            continue
        i, x = spline_locate(delta[k], base, scale, top, h)
        out[k] = spline_cubic(coef[i, 0], coef[i, 1], coef[i, 2], coef[i, 3], x)
    return out


# ---- lifted over arrays: numpy ufuncs of the scalar functions --------------------------------
_UFUNCS: dict = {}


def lifted(fn):
    """The compiled scalar function ``fn`` (float64 arguments and result) as a numpy ufunc,
    compiled on first use and cached on disk: the plain numpy ufunc under numba's dynamic one
    (whose Python-level call costs ~5 us more).  Elementwise the same operations as ``fn``."""
    name = fn.__name__
    if name not in _UFUNCS:
        from numba import vectorize

        py = fn.py_func
        sig = "float64(" + ", ".join(["float64"] * py.__code__.co_argcount) + ")"
        _UFUNCS[name] = vectorize([sig], cache=True)(py).ufunc
    return _UFUNCS[name]


def numpy_law(kind: str, quantity: str):
    """The ufunc ``(delta, fc, sigma, t_min, delta_min, energy_zero) -> value`` of ``quantity``
    (``"force"``, ``"energy"`` or ``"stiffness"``) of a law of ``kind`` (:data:`NUMPY_LAWS`)."""
    return lifted(NUMPY_LAWS[kind][QUANTITIES.index(quantity)])


# ---- the C++ fix's constants ----------------------------------------------------------------
CXX_HEADER = "law_constants.h"


def cxx_header() -> str:
    """The text of ``mdgran/backends/lammps/fix/law_constants.h``: the numerical constants above as
    C++ ``constexpr`` values (``repr`` digits: the same doubles)."""
    def arr(v):
        return "{" + ", ".join(repr(float(x)) for x in v) + "}"

    lines = [
        "// Generated by mdgran.model.contact_scalar.cxx_header() from",
        "// mdgran/model/contact_scalar.py: do not edit (python -m mdgran.model.contact_scalar",
        "// writes it; tests/test_contact_scalar.py checks).",
        "#ifndef MDGRAN_LAW_CONSTANTS_H",
        "#define MDGRAN_LAW_CONSTANTS_H",
        "namespace mdgran_law {",
        f"constexpr int NEWTON_STEPS = {NEWTON_STEPS};",
        f"constexpr double GL_X[5] = {arr(GL_NODES)};",
        f"constexpr double GL_W[5] = {arr(GL_WEIGHTS)};",
        f"constexpr double SING_BAND = {SING_BAND!r};",
        f"constexpr double FC_DMT = {FC_DMT!r};",
        f"constexpr double FC_JKR = {FC_JKR!r};",
        f"constexpr double COS_LAMBDA = {COS_LAMBDA!r};",
        f"constexpr double COS_ALPHA = {COS_ALPHA!r};",
        "}  // namespace mdgran_law",
        "#endif",
    ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    from pathlib import Path

    (Path(__file__).resolve().parents[1] / "backends" / "lammps" / "fix"
     / CXX_HEADER).write_text(cxx_header())
