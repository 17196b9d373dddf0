"""Contact laws between two beads, nondimensional (units of docs/physics.md section 1).

Every quantity here is in the units of the inter-bead interaction: force in ``eta = pi R w``,
compression ``delta`` in ``p = (pi^2 R w^2 / K^2)^(1/3)``, energy in ``eta * p``.

The Schwarz law (paper Eqs. 1-2) is written with ``t = sqrt(a_hat)`` as parameter, where
``a_hat`` is the contact radius in units of ``(R eta / K)^(1/3)``, ``s = (fc + 2) / 3`` and
``sigma = sqrt(s)``::

    delta(t) = t^4 - 4 sigma t
    f(t)     = fc + (t^3 - 3 sigma)^2

so both are polynomials in ``t``.  The attached (stable) branch is ``t >= t_min = sigma^(1/3)``,
where ``delta`` is monotone, so ``f`` is a single-valued function of ``delta`` there.  It is
inverted to machine precision by Newton's method on ``phi(w) = sqrt(delta - delta_min)`` with
``w = t - t_min`` (``phi`` is increasing and convex, with ``phi'(0) > 0``, so Newton started
above the root converges monotonically and quadratically even at the snap-off point, where
``t(delta)`` has a square-root singularity).  The arithmetic of each law (branch inversion,
force, energy, stiffness, the table's spline) is written once, as scalar functions in
:mod:`mdgran.model.contact_scalar`; the methods here lift them over arrays as numpy ufuncs
(:func:`mdgran.model.contact_scalar.lifted`), with the C library's ``pow`` for the powers of ``t``
(numpy's ``**`` would take SIMD code on AVX-512 machines and differ there in the last bit).

The contact energy on the attached branch, ``V(delta) = integral_0^delta f d delta'``, is the
closed-form polynomial ``P(t) - P(t0)`` with ``P`` the antiderivative of ``f(t) delta'(t)`` and
``t0 = (4 sigma)^(1/3)`` the point ``delta = 0``.

Hysteresis (docs/physics.md section 2): an open contact carries no force and closes when ``delta``
reaches 0 from below (``delta_on = 0``); a closed contact follows the attached branch and
opens when ``delta`` falls to ``delta_off``: the minimum ``delta_min`` of ``delta(a)`` (the
paper's displacement rule, default) or the tensile force maximum ``f = fc`` (``snap_off =
"force"``, as LAMMPS's ``granular jkr`` does).  On opening the closed contact's energy
``V(delta_off)`` is lost; for the displacement rule that is the loop energy ``W``.

The law depends on the adhesion through ``fc`` alone (``fc = -2`` DMT, ``-1.5`` JKR).  From
the Maugis parameter ``lambda`` it follows by a rule (:data:`FC_RULES`, scene key
``contact.fc_rule``): the paper's Carpick-Ogletree-Salmeron relation (``"cos"``, default) or
the exact Maugis-Dugdale pull-off (``"maugis-dugdale"``, :func:`maugis_dugdale_pulloff`).

The Hertz law is ``f = delta_+^(3/2)``, ``V = (2/5) delta_+^(5/2)``; it opens and closes at
``delta = 0`` with no force jump.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from . import contact_scalar as cs
from .contact_scalar import (COS_ALPHA, COS_LAMBDA, FC_DMT, FC_JKR, SchwarzConstants, lifted,
                             numpy_law, schwarz_constants)

#: Contact-law names a scene may use.
LAWS = ("schwarz", "jkr", "dmt", "hertz")
#: Snap-off rules.
SNAP_OFF_RULES = ("displacement", "force")
#: Rules giving the pull-off force ``fc`` from the Maugis parameter: ``"cos"`` the
#: Carpick-Ogletree-Salmeron fit the paper uses (default), ``"maugis-dugdale"`` Maugis's
#: equations solved exactly (:func:`maugis_dugdale_pulloff`).
FC_RULES = ("cos", "maugis-dugdale")


def fc_from_lambda(lam: float, rule: str = "cos") -> float:
    """Transition parameter ``fc = Fc / (pi R w)`` from the Maugis parameter ``lambda``.

    ``rule = "cos"`` (default): the Carpick-Ogletree-Salmeron relation as the paper states it,
    ``lambda = -0.924 ln(1 - 1.02 alpha)`` with ``alpha = sqrt(-3 - 6 / fc)``, so
    ``alpha = (1 - exp(-lambda / 0.924)) / 1.02`` and ``fc = -6 / (alpha^2 + 3)``.
    ``lambda = 0`` gives DMT (``fc = -2``); ``lambda -> inf`` gives ``fc -> -1.5147``, not JKR.
    It overstates the exact pull-off by 6.6-10.8 % for lambda in [0.3, 1.5] (-1.852 against
    -1.672 at lambda = 0.64).

    ``rule = "maugis-dugdale"``: the exact pull-off of Maugis's model,
    :func:`maugis_dugdale_pulloff` (-2 at ``lambda = 0``, -> -1.5 as ``lambda -> inf``).
    """
    if rule == "cos":
        alpha = (1.0 - math.exp(-lam / COS_LAMBDA)) / COS_ALPHA
        return -6.0 / (alpha * alpha + 3.0)
    if rule == "maugis-dugdale":
        return maugis_dugdale_pulloff(lam)
    raise ValueError(f"fc rule must be one of {FC_RULES}, not {rule!r}")


def lambda_from_fc(fc: float, rule: str = "cos") -> float:
    """Inverse of :func:`fc_from_lambda` for ``rule`` (``inf`` where ``fc`` is beyond the
    rule's range: above -1.5147 for ``"cos"``, at -1.5 for ``"maugis-dugdale"``)."""
    if rule == "maugis-dugdale":
        if fc <= FC_DMT:
            return 0.0
        if fc >= FC_JKR:
            return math.inf
        from scipy.optimize import brentq

        lo, hi = -27.0, 34.0  # ln lambda; the pull-off is within 1e-15 of -2 and -1.5 beyond
        g = lambda u: maugis_dugdale_pulloff(math.exp(u)) - fc  # noqa: E731
        if g(lo) >= 0.0:
            return math.exp(lo)
        if g(hi) <= 0.0:
            return math.inf
        return math.exp(brentq(g, lo, hi, xtol=1e-14, rtol=1e-15))
    if rule != "cos":
        raise ValueError(f"fc rule must be one of {FC_RULES}, not {rule!r}")
    alpha = math.sqrt(max(-3.0 - 6.0 / fc, 0.0))
    arg = 1.0 - COS_ALPHA * alpha
    return math.inf if arg <= 0.0 else -COS_LAMBDA * math.log(arg)


def _md_curve(s, lam: float):
    """Maugis's contact radius ``A`` and load ``P`` along the curve parametrized by
    ``s = sqrt(m^2 - 1)`` (see :func:`maugis_dugdale_pulloff`); arrays in, arrays out."""
    s = np.asarray(s, dtype=float)
    m = np.sqrt(1.0 + s * s)
    at = np.arctan(s)
    # s - atan(s), without the cancellation at small s
    s_at = np.where(s < 1e-3, s**3 / 3.0 - s**5 / 5.0 + s**7 / 7.0, s - at)
    a2 = 0.5 * lam * (s_at + s * s * at)  # = lam/2 [s + (m^2 - 2) atan s]
    a1 = 4.0 * lam * lam / 3.0 * (s * at - s * s / (m + 1.0))  # = 4 lam^2/3 [s atan s - m + 1]
    A = 2.0 / (a1 + np.sqrt(a1 * a1 + 4.0 * a2))  # positive root of a2 A^2 + a1 A - 1 = 0
    P = A**3 - lam * A * A * (s + m * m * at)
    return A, P


@lru_cache(maxsize=4096)
def maugis_dugdale_pulloff(lam: float) -> float:
    """Exact pull-off force of the Maugis-Dugdale model, in units of ``pi R w`` (= ``eta``, the
    unit of ``fc``), under load control: the least load on the equilibrium curve.

    Maugis (1992) in the notation of Johnson and Greenwood (1997, J. Colloid Interface Sci.
    192, 326): contact radius ``A = a (K / (pi w R^2))^(1/3)``, load ``P = F / (pi w R)``,
    ``m = c / a`` the ratio of the cohesive zone's outer radius to the contact radius, and the
    Maugis parameter ``lambda = 2 sigma_0 (R / (pi w K^2))^(1/3)`` (with the Dugdale stress
    ``sigma_0 = w / (0.97 D0)`` this is ``2.06 / D0 (R w^2 / (pi K^2))^(1/3)``,
    docs/physics.md section 1),
    ``K = (4/3) E*``::

        (lambda A^2 / 2) [sqrt(m^2-1) + (m^2-2) atan sqrt(m^2-1)]
            + (4 lambda^2 A / 3) [sqrt(m^2-1) atan sqrt(m^2-1) - m + 1] = 1
        P = A^3 - lambda A^2 [sqrt(m^2-1) + m^2 atan sqrt(m^2-1)]

    The first equation is a quadratic in ``A`` with positive coefficients for every ``m > 1``,
    so each ``s = sqrt(m^2-1)`` in ``(0, inf)`` gives one ``A`` exactly (its positive root),
    and the curve runs from ``A -> inf`` (``s -> 0``) to ``A -> 0`` (``s -> inf``, where
    ``P -> -(pi/2) lambda (m A)^2``).  ``P`` along it has one minimum (checked for lambda in
    [1e-10, 1e13]); it is bracketed on a grid in ``ln s`` and located by Brent's method to
    round-off.  The units need no conversion: ``fc`` of the Schwarz law is ``Fc / (pi R w)``
    with the same ``R`` and ``w``, and the law depends on ``lambda`` only through ``fc``.

    Values: -2 at ``lambda = 0`` (DMT), -1.8156 at 0.3, -1.6719 at 0.64, -1.5556 at 1.5,
    -1.5 + 0.164 / lambda^2 for large ``lambda`` (JKR).
    """
    lam = float(lam)
    if not lam >= 0.0 or math.isinf(lam):
        if math.isinf(lam) and lam > 0:
            return FC_JKR
        raise ValueError(f"lambda must be a finite number >= 0, not {lam}")
    if lam < 1e-12:  # within 1e-17 of DMT
        return FC_DMT
    if lam > 1e15:  # within 1e-30 of JKR
        return FC_JKR
    from scipy.optimize import minimize_scalar

    u = np.linspace(-40.0, 40.0, 4001)
    _, P = _md_curve(np.exp(u), lam)
    i = int(np.clip(np.argmin(P), 1, len(u) - 2))
    res = minimize_scalar(lambda x: float(_md_curve(math.exp(x), lam)[1]),
                          bounds=(u[i - 1], u[i + 1]), method="bounded",
                          options={"xatol": 1e-12})
    # the end of the curve, A -> 0 with c = m A finite: (pi/4) lam c^2 + k c = 1,
    # k = (4 lam^2 / 3)(pi/2 - 1), and P -> -(pi/2) lam c^2 (above the minimum, kept as a guard)
    k = 4.0 * lam * lam / 3.0 * (math.pi / 2.0 - 1.0)
    c = 2.0 / (k + math.sqrt(k * k + math.pi * lam))
    p_end = -0.5 * math.pi * lam * c * c
    return min(max(float(min(res.fun, P[i], p_end)), FC_DMT), FC_JKR)


@dataclass(frozen=True)
class ContactLaw:
    """One contact law with its hysteresis rule.

    ``kind`` is ``"schwarz"`` (JKR and DMT are Schwarz laws with ``fc = -1.5`` and ``-2``) or
    ``"hertz"``.  ``fc`` is ignored for Hertz.  All methods take and return nondimensional
    values and accept numpy arrays.

    ``fc_rule`` and ``lambda_source`` only record how ``fc`` was obtained (the rule that made it
    from the Maugis parameter; where that parameter came from: ``"scene"``, ``"material"`` or
    ``"default"``, ``None`` if ``fc`` was given or fixed by the law); they do not enter the
    law's values, its comparison or its repr.
    """

    kind: str = "schwarz"
    fc: float = -1.8518
    snap_off: str = "displacement"
    fc_rule: str | None = field(default=None, compare=False, repr=False)
    lambda_source: str | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if self.kind not in ("schwarz", "hertz"):
            raise ValueError(f"contact kind must be 'schwarz' or 'hertz', not {self.kind!r}")
        if self.kind == "schwarz" and not (FC_DMT <= self.fc <= FC_JKR):
            raise ValueError(f"fc must lie in [-2, -1.5], not {self.fc}")
        if self.snap_off not in SNAP_OFF_RULES:
            raise ValueError(f"snap_off must be one of {SNAP_OFF_RULES}, not {self.snap_off!r}")
        if self.fc_rule is not None and self.fc_rule not in FC_RULES:
            raise ValueError(f"fc_rule must be one of {FC_RULES}, not {self.fc_rule!r}")

    # ---- constants of the law -------------------------------------------------------------
    @property
    def s(self) -> float:
        return (self.fc + 2.0) / 3.0 if self.kind == "schwarz" else 0.0

    @property
    def sigma(self) -> float:
        return math.sqrt(max(self.s, 0.0))

    @property
    def t_min(self) -> float:
        """Parameter ``t = sqrt(a)`` at the minimum of ``delta(a)``: ``t_min^3 = sigma``."""
        return self.sigma ** (1.0 / 3.0)

    @property
    def delta_min(self) -> float:
        """Smallest compression on the attached branch, ``t_min^4 - 4 sigma t_min``."""
        return cs.branch_delta(self.t_min, self.sigma)

    @property
    def delta_force_max(self) -> float:
        """Compression at the tensile force maximum ``f = fc`` (``t^3 = 3 sigma``)."""
        return cs.branch_delta((3.0 * self.sigma) ** (1.0 / 3.0), self.sigma)

    @property
    def delta_off(self) -> float:
        """A closed contact opens when ``delta`` falls to this value."""
        if self.kind == "hertz":
            return 0.0
        return self.delta_min if self.snap_off == "displacement" else self.delta_force_max

    @property
    def f_on(self) -> float:
        """Force just after snap-to-contact at ``delta = 0``: ``fc + s`` (0 for Hertz)."""
        return self.fc + self.s if self.kind == "schwarz" else 0.0

    @property
    def f_off(self) -> float:
        """Force just before snap-off at ``delta_off``: ``fc + 4 s`` (displacement rule), ``fc``
        (force rule), 0 for Hertz."""
        return float(self.force(self.delta_off))

    @property
    def loop_energy(self) -> float:
        """Energy lost per open event, ``V(delta_off)``; with the displacement rule this is
        ``W = -integral_{delta_min}^0 f d delta``."""
        return float(self.energy(self.delta_off))

    @property
    def delta_eq(self) -> float:
        """Natural equilibrium (``f = 0``) on the attached branch."""
        if self.kind == "hertz":
            return 0.0
        return cs.branch_delta((3.0 * self.sigma + math.sqrt(-self.fc)) ** (1.0 / 3.0),
                               self.sigma)

    @property
    def stiffness_eq(self) -> float:
        """``df/d delta`` at the natural equilibrium."""
        if self.kind == "hertz":
            return 0.0
        return float(self.stiffness(self.delta_eq))

    @property
    def energy_zero(self) -> float:
        """``P(t0)``, the antiderivative at ``delta = 0`` (``t0 = (4 sigma)^(1/3)``), so that
        ``V(0) = 0`` (0 for Hertz)."""
        if self.kind == "hertz":
            return 0.0
        return cs.schwarz_antiderivative_libm((4.0 * self.sigma) ** (1.0 / 3.0), self.fc,
                                              self.sigma)

    # ---- the law as functions of delta: contact_scalar's functions lifted over arrays ------
    def t_of_delta(self, delta):
        """Branch parameter ``t >= t_min`` with ``t^4 - 4 sigma t = delta`` (Schwarz only).

        Below ``delta_min`` the value is clamped to ``t_min`` (the force then stays at ``f_off``,
        a continuous extension used only inside an integration step that overshoots an event).
        :func:`mdgran.model.contact_scalar.branch_t` applied elementwise.
        """
        d = np.asarray(delta, dtype=float)
        return lifted(cs.branch_t)(d, self.sigma, self.t_min, self.delta_min)

    @property
    def constants(self) -> SchwarzConstants:
        """The constants the scalar laws read
        (:func:`~mdgran.model.contact_scalar.schwarz_constants`; zeros for Hertz)."""
        return schwarz_constants(self)

    def force(self, delta):
        """Force on the attached branch (positive = repulsive), for a closed contact."""
        return numpy_law(self.kind, "force")(np.asarray(delta, dtype=float), *self.constants)

    def stiffness(self, delta):
        """``df/d delta`` on the attached branch (infinite at ``delta_min``)."""
        with np.errstate(divide="ignore"):
            return numpy_law(self.kind, "stiffness")(np.asarray(delta, dtype=float),
                                                     *self.constants)

    def energy(self, delta):
        """Energy of a closed contact, ``V(delta) = integral_0^delta f`` on the attached branch.

        Zero at ``delta = 0``, so closing at ``delta = 0`` leaves the energy continuous.
        """
        return numpy_law(self.kind, "energy")(np.asarray(delta, dtype=float), *self.constants)

    def describe(self) -> dict:
        """The law's characteristic values (the check table of docs/physics.md section 2),
        nondimensional."""
        return {
            "law": self.kind,
            "fc": self.fc if self.kind == "schwarz" else None,
            "snap_off": self.snap_off,
            "delta_min": self.delta_min if self.kind == "schwarz" else 0.0,
            "delta_off": self.delta_off,
            "f_on": self.f_on,
            "f_off": self.f_off,
            "loop_energy": self.loop_energy,
            "delta_eq": self.delta_eq,
            "stiffness_eq": self.stiffness_eq,
            "fc_rule": self.fc_rule,
            "lambda_source": self.lambda_source,
        }

    def tabulate(self, n: int = 2001, delta_max: float = 10.0):
        """Table of the attached branch on ``[delta_off, delta_max]``.

        Returns ``(delta, force, energy)``, ``n`` points each, spaced uniformly in the branch
        parameter ``t`` (dense where the force varies fast, near snap-off) for Schwarz, and
        uniformly in ``delta`` for Hertz.  See :func:`table_error` for the interpolation error.
        """
        if self.kind == "hertz":
            d = np.linspace(0.0, delta_max, n)
        else:
            t_lo = float(self.t_of_delta(self.delta_off))
            t_hi = float(self.t_of_delta(delta_max))
            t = np.linspace(t_lo, t_hi, n)
            d = lifted(cs.branch_delta)(t, self.sigma)
            d[0], d[-1] = self.delta_off, delta_max
        return d, self.force(d), self.energy(d)


def law_from_contact_table(contact: dict, lambda_source: str | None = None) -> ContactLaw:
    """Build the law from a scene's ``[contact]`` table (already validated).  ``fc`` comes from
    ``contact.fc`` if given, else from ``contact.lambda`` by ``contact.fc_rule`` (default
    ``"cos"``); ``lambda_source`` is recorded on the law (see :class:`ContactLaw`)."""
    law = contact.get("law", "schwarz")
    snap = contact.get("snap_off", "displacement")
    if law == "hertz":
        return ContactLaw("hertz", 0.0, "displacement")
    if law == "jkr":
        return ContactLaw("schwarz", FC_JKR, snap)
    if law == "dmt":
        return ContactLaw("schwarz", FC_DMT, snap)
    if contact.get("fc") is not None:
        return ContactLaw("schwarz", float(contact["fc"]), snap)
    rule = contact.get("fc_rule") or "cos"
    lam = contact.get("lambda")
    lam = 0.64 if lam is None else float(lam)
    return ContactLaw("schwarz", fc_from_lambda(lam, rule), snap, fc_rule=rule,
                      lambda_source=lambda_source)


def table_error(law: ContactLaw, n: int, delta_max: float = 10.0, kind: str = "linear") -> dict:
    """Largest interpolation error of a table of ``n`` points, measured on a 20x finer grid.

    ``kind`` is ``"linear"`` (what LAMMPS-style lookup does).  The error falls as ``1/n``, not
    ``1/n^2``: near ``delta_min`` the force goes as ``sqrt(delta - delta_min)``.  Returns absolute errors of force
    and energy, and the force error relative to the largest force in the table.
    """
    d, f, e = law.tabulate(n, delta_max)
    dd = np.sort(np.concatenate([law.tabulate(20 * n, delta_max)[0], d]))
    f_int = np.interp(dd, d, f)
    e_int = np.interp(dd, d, e)
    ef = np.max(np.abs(f_int - law.force(dd)))
    ee = np.max(np.abs(e_int - law.energy(dd)))
    return {"points": n, "force_abs": float(ef), "energy_abs": float(ee),
            "force_rel": float(ef / np.max(np.abs(f)))}


class ContactTable:
    """The attached branch tabulated for backends that need a table (the LAMMPS hook).

    Nodes are uniform in ``w = sqrt(delta - delta_min)`` (``delta_min = 0`` for Hertz), in which
    the force is a smooth function (``t(w)`` is analytic at the snap-off point, and
    ``delta^(3/2) = w^3`` for Hertz and DMT).  Between nodes the force and energy are the
    not-a-knot cubic spline in ``w`` through the exact node values: fourth order in the node
    spacing everywhere, snap-off included (interpolation in ``delta`` would be first order
    there).  Linear interpolation in ``w`` was second order, and at the default 16001 nodes
    left a 1.4e-7 force offset and a 1e-3 relative stiffness error at ``delta = 0``, which a
    tiny impulse (hard/tiny) resolved.  At the default 4001 nodes to ``delta_max = 100`` the
    force error is 2e-12 (the round-off floor of forces up to ~1e3); where ``f(w)`` is a cubic
    (Hertz, and Schwarz at ``fc = -2``) it is exact to round-off.  Compressions
    above ``delta_max`` are outside the table (:meth:`force` flags them).
    """

    def __init__(self, law: ContactLaw, n: int = 4001, delta_max: float = 100.0):
        from scipy.interpolate import CubicSpline

        self.law = law
        self.n = n
        self.delta_max = float(delta_max)
        self.base = law.delta_min if law.kind == "schwarz" else 0.0
        self.w_max = math.sqrt(self.delta_max - self.base)
        self.w = np.linspace(0.0, self.w_max, n)
        self.delta = self.base + self.w**2
        self.f = law.force(self.delta)
        self.e = law.energy(self.delta)
        self._scale = (n - 1) / self.w_max
        self._h = self.w_max / (n - 1)
        # per-interval polynomial coefficients in (w - w_i), highest power first: [n - 1, 4]
        self.f_coef = np.ascontiguousarray(CubicSpline(self.w, self.f).c.T)
        self.e_coef = np.ascontiguousarray(CubicSpline(self.w, self.e).c.T)

    @property
    def top(self) -> float:
        """The largest table coordinate ``w / h``: just below the last node."""
        return self.n - 1 - 1e-9

    def _spline(self, coef, delta):
        d = np.asarray(delta, dtype=float)
        out = cs.spline_values(coef, self.base, self._scale, self.top, self._h, d.ravel())
        return out.reshape(d.shape)[()]

    def force(self, delta):
        """The force spline at ``delta`` (:func:`mdgran.model.contact_scalar.spline_values`)."""
        return self._spline(self.f_coef, delta)

    def energy(self, delta):
        """The energy spline at ``delta``."""
        return self._spline(self.e_coef, delta)

    def error(self) -> dict:
        """Largest interpolation errors against the exact law, on 17 points per interval."""
        u = np.linspace(0.0, 1.0, 17)[1:-1]
        w = (self.w[:-1, None] + u[None, :] * (self.w[1] - self.w[0])).ravel()
        d = self.base + w**2
        ef = np.max(np.abs(self.force(d) - self.law.force(d)))
        ee = np.max(np.abs(self.energy(d) - self.law.energy(d)))
        return {"points": self.n, "delta_max": self.delta_max, "force_abs": float(ef),
                "energy_abs": float(ee)}

    def write_lammps(self, path, keyword: str = "MDGRAN_CONTACT"):
        """The table in LAMMPS's tabulated-potential layout (index, delta, energy, force), keyed
        by compression delta (not a distance), for a LAMMPS user to inspect or plot."""
        with open(path, "w") as fh:
            fh.write(f"# mdgran contact law {self.law.kind} fc = {self.law.fc} snap_off = "
                     f"{self.law.snap_off}; units eta (force), p (delta), eta p (energy).\n"
                     f"# columns: index, compression delta, energy V(delta), force f(delta);\n"
                     f"# nodes uniform in sqrt(delta - {self.base!r}) (mdgran interpolates a cubic spline in "
                     f"that variable); interpolation error "
                     f"{self.error()}\n\n{keyword}\nN {self.n}\n\n")
            for k in range(self.n):
                fh.write(f"{k + 1} {self.delta[k]:.17g} {self.e[k]:.17g} {self.f[k]:.17g}\n")
