"""Chains of unlike beads: per-bead masses and a contact law of its own for every contact.

Units stay those of the **reference bead** (docs/physics.md section 1): a pair of two reference
beads (diameter ``d0``, contact modulus ``K0``, work of adhesion ``w0``, density ``rho0``) has
``R0 = d0 / 4``, force unit ``eta0 = pi R0 w0``, length unit ``p0 = (pi^2 R0 w0^2 / K0^2)^(1/3)``,
mass unit ``m0``.  Bead ``i`` is given by its ratios to the reference bead: diameter ``s_i``,
density ``r_i``, contact modulus ``k_i`` (the ``K`` of two beads of its material) and work of
adhesion ``a_i`` (of two of its surfaces).  Its mass is ``m_i = r_i s_i^3``.

**The law of a pair** ``(i, j)`` (paper Eq. 4: ``R = R1 R2 / (R1 + R2)``)::

    R_ij / R0 = 2 s_i s_j / (s_i + s_j)
    K_ij / K0 = 2 k_i k_j / (k_i + k_j)      (1/E* = (1-nu_i^2)/E_i + (1-nu_j^2)/E_j)
    w_ij / w0 = sqrt(a_i a_j)                 (w = 2 gamma; Berthelot: gamma_ij^2 = gamma_i gamma_j)

or a given ``w_ij / w0`` for every pair.  In its own units (``eta_ij``, ``p_ij``) the pair follows
the Schwarz law of its own transition parameter ``fc_ij``; in the reference units::

    F_ij(delta) = A f_ij(delta / L),   V_ij(delta) = A L V_ij(delta / L),
    A = eta_ij / eta0 = (R_ij/R0) (w_ij/w0),   L = p_ij / p0 = ((R_ij/R0)(w_ij/w0)^2 / (K_ij/K0)^2)^(1/3)

so its thresholds are ``L delta_off(fc_ij)`` and its loop energy ``A L W(fc_ij)``.  The Maugis
parameter scales as the length unit (``lambda = 2.06 p / (pi^(1/3) D0)`` with ``D0`` common), so
``lambda_ij = lambda0 L`` and ``fc_ij`` follows by the scene's rule; a scene that fixes ``fc``
gives every pair that ``fc``.  Hertz: ``A L^(-3/2) = (K_ij/K0) sqrt(R_ij/R0)``, so ``w`` cancels
and ``F = (K_ij/K0) sqrt(R_ij/R0) delta_+^(3/2)``, the Hertz law of the pair.

**Walls** are mirror beads: a wall contact has the law of two copies of its bead (as in the
homogeneous chain, whose wall contacts have the bead-bead law).

**Substrate**: the substrate force of bead ``i`` is ``-g_i (k1 x + k3 x^3)`` with ``g_i`` 1 for a
bead on the substrate, 0 for a free one (a striker).  Damping ``c`` is one value for all
contacts (units of the reference pair).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .contact import ContactLaw, fc_from_lambda
from .contact_scalar import numpy_law, schwarz_constants


def pair_ratios(s, k, a, walls: bool, adhesion=None):
    """Per-contact ``(R/R0, K/K0, w/w0)`` of a chain of beads with diameter, modulus and
    adhesion ratios ``s``, ``k``, ``a`` [n], in contact order (walls: mirror beads at both
    ends, ``n + 1`` contacts; else ``n - 1``); ``adhesion``: a given ``w/w0`` for every pair."""
    s, k, a = (np.asarray(v, dtype=float) for v in (s, k, a))
    if walls:
        s, k, a = (np.concatenate([v[:1], v, v[-1:]]) for v in (s, k, a))
    left, right = slice(0, -1), slice(1, None)
    r = 2.0 * s[left] * s[right] / (s[left] + s[right])
    kk = 2.0 * k[left] * k[right] / (k[left] + k[right])
    w = np.sqrt(a[left] * a[right]) if adhesion is None else np.full(len(r), float(adhesion))
    return r, kk, w


@dataclass(frozen=True, eq=False)
class Mixture:
    """Per-bead and per-contact properties of a chain of unlike beads (module doc), reference
    units.  ``law`` is the reference pair's law (its ``kind`` and ``snap_off`` are every
    contact's); ``fc`` [m] each contact's transition parameter (ignored for Hertz)."""

    law: ContactLaw
    mass: np.ndarray  # [n] m_i / m0
    substrate: np.ndarray  # [n] g_i: 1 on the substrate, 0 free
    fc: np.ndarray  # [m]
    force_scale: np.ndarray  # [m] A = eta_k / eta0
    length_scale: np.ndarray  # [m] L = p_k / p0
    info: dict = field(default_factory=dict)  # how the mixture was made (for mdgran info)

    @property
    def n(self) -> int:
        return len(self.mass)

    @property
    def hertz(self) -> bool:
        return self.law.kind == "hertz"

    @cached_property
    def uniform_mass(self) -> bool:
        """True when every bead has the reference mass (no division by the masses)."""
        return bool(np.all(self.mass == 1.0))

    @cached_property
    def free_beads(self) -> bool:
        """True when some bead is off the substrate."""
        return bool(np.any(self.substrate != 1.0))

    # ---- the distinct laws -------------------------------------------------------------------
    @cached_property
    def _classes(self):
        fc = self.fc if not self.hertz else np.zeros_like(self.fc)
        values, index = np.unique(fc, return_inverse=True)
        return values, index.astype(np.int64)

    @cached_property
    def laws(self) -> tuple:
        """The distinct laws (one per distinct ``fc``), in own units."""
        return tuple(self.law_of_class(i) for i in range(len(self._classes[0])))

    @property
    def law_index(self) -> np.ndarray:
        """Index into :attr:`laws` of each contact [m]."""
        return self._classes[1]

    def law_of_class(self, i: int) -> ContactLaw:
        if self.hertz:
            return ContactLaw("hertz", 0.0, "displacement")
        return ContactLaw("schwarz", float(self._classes[0][i]), self.law.snap_off)

    @cached_property
    def _constants(self):
        """Per-contact ``(fc, sigma, t_min, delta_min, P(t0))`` arrays (own units): each
        class's :func:`~mdgran.model.contact_scalar.schwarz_constants` (zeros for Hertz; a one-class
        mixture has the homogeneous law's values)."""
        cols = [tuple(schwarz_constants(law)) for law in self.laws]
        table = np.array(cols, dtype=float)[self.law_index]
        return tuple(np.ascontiguousarray(table[:, i]) for i in range(5))

    # ---- per-contact values in reference units ---------------------------------------------
    @cached_property
    def delta_off(self) -> np.ndarray:
        """Opening threshold of each contact [m] (units p0)."""
        own = np.array([law.delta_off for law in self.laws])[self.law_index]
        return self.length_scale * own

    @cached_property
    def loop_energy(self) -> np.ndarray:
        """Energy lost when each contact opens [m] (units eta0 p0)."""
        own = np.array([law.loop_energy for law in self.laws])[self.law_index]
        return self.force_scale * self.length_scale * own

    def _own(self, k):
        """Per-contact ``(fc, sigma, t_min, delta_min, P(t0))`` of all contacts or of ``k``."""
        return self._constants if k is None else tuple(c[k] for c in self._constants)

    def _law(self, quantity, delta, k):
        """``(A, L, value)``: the scales of all contacts (or of ``k``) and their own law's
        ``quantity`` at ``delta / L`` (:func:`~mdgran.model.contact_scalar.numpy_law`)."""
        A, L = self._scales(k)
        u = np.asarray(delta, dtype=float) / L
        with np.errstate(divide="ignore"):
            return A, L, numpy_law(self.law.kind, quantity)(u, *self._own(k))

    def force(self, delta, k=None):
        """Force of each closed contact at compression ``delta`` [..., m] (or of contacts
        ``k`` at ``delta`` [len(k)]), units eta0: ``A f(delta / L)``."""
        A, _, f = self._law("force", delta, k)
        return A * f

    def energy(self, delta, k=None):
        """Energy of each closed contact at ``delta``, units eta0 p0: ``A L V(delta / L)``."""
        A, L, e = self._law("energy", delta, k)
        return (A * L) * e

    def stiffness(self, delta, k=None):
        """``dF/d delta`` of each closed contact, units eta0 / p0: ``(A / L) f'(delta / L)``."""
        A, L, own = self._law("stiffness", delta, k)
        return (A / L) * own

    def _scales(self, k):
        if k is None:
            return self.force_scale, self.length_scale
        return self.force_scale[k], self.length_scale[k]

    def describe(self) -> dict:
        """Ranges of the per-bead and per-contact values (for ``mdgran info``)."""
        def span(v):
            return [float(np.min(v)), float(np.max(v))]

        out = {"beads": self.n, "mass": span(self.mass), "free_beads": int(np.sum(
            self.substrate == 0.0)), "distinct_laws": len(self.laws),
            "force_scale": span(self.force_scale), "length_scale": span(self.length_scale),
            "loop_energy": span(self.loop_energy)}
        if not self.hertz:
            out["fc"] = span(self.fc)
        out.update(self.info)
        return out


def mixture_from_ratios(law: ContactLaw, walls: bool, diameter, density=1.0, modulus=1.0,
                        adhesion=1.0, pair_adhesion=None, lam=None, fc_rule: str = "cos",
                        substrate=1.0, info=None) -> Mixture:
    """A :class:`Mixture` from per-bead ratios to the reference bead (scalars broadcast to
    ``len(diameter)`` beads).  ``law``: the reference pair's law; ``lam``: its Maugis parameter
    (each pair then gets ``fc`` from ``lam * L`` by ``fc_rule``); ``lam = None``: every pair
    keeps ``law.fc``.  ``pair_adhesion``: a given ``w/w0`` for every pair."""
    s = np.asarray(diameter, dtype=float)
    n = len(s)

    def per_bead(v):
        return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()

    r, k, a = per_bead(density), per_bead(modulus), per_bead(adhesion)
    R, K, w = pair_ratios(s, k, a, walls, pair_adhesion)
    if law.kind == "hertz":
        A = K * np.sqrt(R)  # with L = 1: the Hertz pair needs no length unit of its own
        L = np.ones_like(A)
    else:
        A = R * w
        L = np.cbrt(R * w * w / (K * K))
    if law.kind == "hertz" or lam is None:
        fc = np.full(len(A), float(law.fc))
    else:
        scales, where = np.unique(L, return_inverse=True)  # each distinct pair once
        fc = np.array([fc_from_lambda(float(lam) * Lk, fc_rule) for Lk in scales])[where]
    return Mixture(law, r * s**3, per_bead(substrate), fc, A, L, dict(info or {}))


# ---- per-bead SI values to ratios (scene keys beads.E, nu, w, density_si, mass) ------------
def _each(f, *values):
    """``f`` of each bead's values: a float if every value is a number, else a list (the lists
    have one length, chain.n; a number stands for every bead)."""
    n = max((len(v) for v in values if isinstance(v, list)), default=0)
    if not n:
        return float(f(*values))
    return [float(f(*(v[i] if isinstance(v, list) else v for v in values))) for i in range(n)]


def modulus_ratios(E, nu, K0: float, convention: str = "table"):
    """Contact-modulus ratios ``k_i = K_ii / K0`` of beads of Young's modulus ``E`` (Pa) and
    Poisson's ratio ``nu`` (each a number or a list of n), ``K_ii`` the ``K`` of two beads of
    bead ``i``'s material by ``convention`` (:func:`mdgran.model.units.contact_modulus`), ``K0``
    (Pa) the reference pair's.

    Both conventions are ``K = c E*`` with the Hertz effective modulus of the pair,
    ``1/E* = (1 - nu_i^2)/E_i + (1 - nu_j^2)/E_j`` (``c = 1`` "table", ``4/3`` "text"), so
    ``E*_ii = E_i / (2 (1 - nu_i^2))`` and ``1/E*_ij = (1/E*_ii + 1/E*_jj) / 2``: the pair's
    true ``K_ij`` is the harmonic mean of ``K_ii`` and ``K_jj``, the rule of
    :func:`pair_ratios`."""
    from .units import contact_modulus

    return _each(lambda e, v: contact_modulus(float(e), float(v), convention) / K0, E, nu)


def ratios_to(values, reference: float):
    """``values / reference`` (a number or a list; e.g. ``w_i / w0`` from ``w_i`` in J/m^2,
    ``rho_i / rho0`` from kg/m^3)."""
    return _each(lambda v: float(v) / reference, values)


def density_from_mass(mass, diameter):
    """Density ratios ``rho_i / rho0 = m_i / s_i^3`` from mass ratios ``m_i / m0`` (a number or
    a list of n) and diameter ratios ``s_i`` [n] (:func:`pattern_diameters`), as
    ``m_i = rho_i s_i^3`` in the reference bead's units; a number where every bead has it."""
    s = [float(x) for x in np.asarray(diameter, dtype=float)]
    if not isinstance(mass, list) and len(set(s)) == 1:
        return float(mass) / s[0] ** 3
    return _each(lambda m, d: float(m) / d**3, mass, s)


# ---- from a scene ([beads], [striker]) -------------------------------------------------------
def pattern_diameters(beads: dict, n: int) -> np.ndarray:
    """Diameter ratios ``d_i / d0`` [n] of a scene's ``[beads]`` table (``beads.pattern``):

    * ``uniform``  ``beads.diameter`` (a number or a list; 1 if not given),
    * ``dimer``    1, r, 1, r, ... (``r = beads.ratio``),
    * ``tapered``  ``r^(i-1)`` for bead ``i``,
    * ``intruder`` 1 but bead ``beads.index`` (default the middle one, ``(n + 1) // 2``): ``r``,
    * ``random``   ``1 + spread (2 U_i - 1)``, ``U_i`` uniform on [0, 1) from numpy's
      ``default_rng(beads.seed)``.
    """
    pattern, r = beads["pattern"], beads.get("ratio")
    if pattern == "uniform":
        d = beads.get("diameter")
        return np.broadcast_to(np.asarray(1.0 if d is None else d, dtype=float), (n,)).copy()
    s = np.ones(n)
    if pattern == "dimer":
        s[1::2] = r
    elif pattern == "tapered":
        s = float(r) ** np.arange(n, dtype=float)
    elif pattern == "intruder":
        index = beads.get("index") or (n + 1) // 2
        s[index - 1] = r
    elif pattern == "random":
        u = np.random.default_rng(int(beads.get("seed") or 0)).random(n)
        s = 1.0 + float(beads.get("spread") or 0.0) * (2.0 * u - 1.0)
    else:
        raise ValueError(f"unknown beads.pattern {pattern!r}")
    return s


def mixture_from_scene(scene) -> Mixture | None:
    """The :class:`Mixture` of a resolved scene's ``[beads]`` and ``[striker]`` tables, or
    ``None`` when every bead and pair is the reference one (the homogeneous chain, computed as
    before).  A striker is bead 1 with its own diameter and density, off the substrate.  Each
    pair's ``fc`` follows from ``contact.lambda`` times its length scale (by
    ``contact.fc_rule``); with ``contact.fc`` given, or law jkr or dmt, every pair has the
    scene's ``fc``."""
    beads, striker, n = scene.beads, scene.striker, int(scene.chain.n)
    s = pattern_diameters(beads.table(), n)
    density = np.broadcast_to(np.asarray(beads.density, dtype=float), (n,)).copy()
    substrate = np.ones(n)
    if striker.diameter is not None:
        s[0], density[0], substrate[0] = striker.diameter, striker.density, 0.0
    per_bead = [s, density, np.asarray(beads.modulus, dtype=float),
                np.asarray(beads.adhesion, dtype=float), substrate]
    pair_w = beads.pair_adhesion
    if all(np.all(v == 1.0) for v in per_bead) and pair_w in (None, 1.0):
        return None
    law = scene.law
    contact = scene.contact
    lam = contact.lambda_ if law.kind == "schwarz" else None
    info = {"pattern": beads.pattern, "striker": striker.diameter is not None,
            "units": "those of the reference bead (diameter, density, modulus and adhesion "
                     "ratios 1): mass m0, force eta0 = pi R0 w0, length p0"}
    return mixture_from_ratios(law, scene.chain.boundary == "fixed", s, density,
                               beads.modulus, beads.adhesion, pair_w, lam,
                               contact.fc_rule or "cos", substrate, info)
