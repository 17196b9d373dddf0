"""From a material in SI units to the scales of the nondimensional model (docs/physics.md
section 1).

Units are converted once, here; everything else in mdgran is nondimensional.

Scales, for two equal beads of diameter ``d`` (``R = d/4`` is the pair's effective radius)::

    eta   = pi R w                           force
    p     = (pi^2 R w^2 / K^2)^(1/3)         length
    eta/p = (pi R^2 w K^2)^(1/3)             stiffness   (paper Table I, column 2)
    sqrt(m eta / p)                          damping     (paper Table I, column 3)
    1/q   = sqrt(m p / eta)                  time
    eta p                                    energy

**Modulus convention.**  The paper's text writes ``K = (2/3) E / (1 - nu^2)`` (235.7 GPa for
alumina), but its Table I and its Maugis parameter 0.64 are reproduced only with
``K = E / (2 (1 - nu^2))`` (176.8 GPa).  The paper's results were computed with the latter, so
it is the default (``modulus = "table"``); ``modulus = "text"`` takes the formula as written,
and a material may give ``K`` (Pa) directly.

**Names.**  Every scale is an attribute of :class:`Scales` under the name ``mdgran info``
prints it with (``eta_N``, ``p_m``, ``time_unit_s``, ...: :data:`INFO_KEYS`), and under a
short name (``eta``, ``p``, ``time``, ...) as well.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

MODULUS_CONVENTIONS = ("table", "text")

#: Default interfacial contact separation D0 (m), the paper's value; it enters only the Maugis
#: parameter.
D0_DEFAULT = 0.165e-9

#: What :meth:`Scales.as_dict` (and so ``mdgran info``) prints, in order; each is an attribute.
INFO_KEYS = ("diameter_m", "K_Pa", "mass_kg", "eta_N", "p_m", "stiffness_scale_N_per_m",
             "damping_scale_Ns_per_m", "time_unit_s", "velocity_unit_m_per_s", "energy_unit_J",
             "maugis_lambda")

#: The paper's alumina beads (Sec. II): E, nu, Hamaker constant, contact separation, density
#: (3900 kg/m^3 reproduces Table I column 3 to 4 figures).
ALUMINA = {"E": 338e9, "nu": 0.21, "w": 0.146, "density": 3900.0, "D0": 0.165e-9}


def work_of_adhesion(A12: float = 15e-20, D0: float = 0.165e-9) -> float:
    """``w = A12 / (12 pi D0^2)`` in J/m^2 (0.146 J/m^2 for alumina in vacuum)."""
    return A12 / (12.0 * math.pi * D0 * D0)


def contact_modulus(E: float, nu: float, convention: str = "table") -> float:
    """``K`` in Pa: ``E / (2 (1 - nu^2))`` ("table", default) or ``(2/3) E / (1 - nu^2)``."""
    if convention == "table":
        return E / (2.0 * (1.0 - nu * nu))
    if convention == "text":
        return 2.0 * E / (3.0 * (1.0 - nu * nu))
    raise ValueError(f"modulus convention must be one of {MODULUS_CONVENTIONS}")


@dataclass(frozen=True)
class Scales:
    """Characteristic scales of one bead size and material (SI units)."""

    diameter: float  # m
    K: float  # Pa, contact modulus
    w: float  # J/m^2
    density: float  # kg/m^3
    D0: float = D0_DEFAULT  # m, interfacial contact separation (for the Maugis parameter)

    @property
    def R(self) -> float:
        """Effective radius of two equal beads, ``d / 4`` (m)."""
        return self.diameter / 4.0

    @property
    def mass(self) -> float:
        return self.density * math.pi * self.diameter**3 / 6.0

    @property
    def eta(self) -> float:
        return math.pi * self.R * self.w

    @property
    def p(self) -> float:
        return (math.pi**2 * self.R * self.w**2 / self.K**2) ** (1.0 / 3.0)

    @property
    def stiffness(self) -> float:
        return self.eta / self.p

    @property
    def damping(self) -> float:
        return math.sqrt(self.mass * self.eta / self.p)

    @property
    def time(self) -> float:
        return math.sqrt(self.mass * self.p / self.eta)

    @property
    def velocity(self) -> float:
        return self.p / self.time

    @property
    def energy(self) -> float:
        return self.eta * self.p

    @property
    def maugis_lambda(self) -> float:
        """``2.06 / D0 (R w^2 / (pi K^2))^(1/3)`` (0.64 for the paper's micro beads)."""
        return 2.06 / self.D0 * (self.R * self.w**2 / (math.pi * self.K**2)) ** (1.0 / 3.0)

    # the same scales under the names mdgran info prints them with (INFO_KEYS)
    diameter_m = property(lambda self: self.diameter, doc="Bead diameter (m).")
    K_Pa = property(lambda self: self.K, doc="Contact modulus K (Pa).")
    mass_kg = property(lambda self: self.mass, doc="Bead mass (kg).")
    eta_N = property(lambda self: self.eta, doc="Force unit eta = pi R w (N).")
    p_m = property(lambda self: self.p, doc="Length unit p (m).")
    stiffness_scale_N_per_m = property(lambda self: self.stiffness,
                                       doc="Stiffness unit eta / p (N/m).")
    damping_scale_Ns_per_m = property(lambda self: self.damping,
                                      doc="Damping unit sqrt(m eta / p) (Ns/m).")
    time_unit_s = property(lambda self: self.time, doc="Time unit 1/q = sqrt(m p / eta) (s).")
    velocity_unit_m_per_s = property(lambda self: self.velocity,
                                     doc="Velocity unit p q (m/s).")
    energy_unit_J = property(lambda self: self.energy, doc="Energy unit eta p (J).")

    def as_dict(self) -> dict:
        """Every scale by its :data:`INFO_KEYS` name (attributes of the same names)."""
        return {key: getattr(self, key) for key in INFO_KEYS}


def missing_material_keys(mat: dict) -> list:
    """The keys a complete ``[material]`` table lacks: diameter, nu, w, density, and E unless
    K is given (``modulus`` and ``D0`` have defaults)."""
    need = ("diameter", "E", "nu", "w", "density")
    return [k for k in need if mat.get(k) is None and not (k == "E" and mat.get("K") is not None)]


def scales_from_material(mat: dict, fill: dict | None = ALUMINA) -> Scales:
    """Scales from a ``[material]`` table (keys: diameter, E, nu, w, density, modulus, optional
    K and D0; ``K`` replaces E and modulus; D0 defaults to :data:`D0_DEFAULT`).

    Keys the table lacks are taken from ``fill``, by default the paper's alumina
    (:data:`ALUMINA`), a convenience for Python use (``scales_from_material({"diameter":
    2.5e-6})`` is the paper's micro bead).  Scenes do not use it: a scene's ``[material]``
    must be complete (:func:`mdgran.model.scene.resolve` says which keys are missing), and it is
    converted with ``fill=None``, which raises ``ValueError`` naming the missing keys.
    """
    if fill is None:
        missing = missing_material_keys(mat)
        if missing:
            raise ValueError("material lacks " + ", ".join(missing))
        fill = {"D0": D0_DEFAULT}

    def get(key):
        return float(mat[key]) if mat.get(key) is not None else fill[key]

    K = mat.get("K")
    K = float(K) if K is not None else contact_modulus(get("E"), get("nu"),
                                                       mat.get("modulus") or "table")
    return Scales(diameter=float(mat["diameter"]), K=K, w=get("w"), density=get("density"),
                  D0=get("D0"))


def wire_tension(k1: float, length: float) -> float:
    """Wire pretension ``T_s = K1 L_s / 2`` (N) that gives substrate stiffness ``K1`` (N/m)
    for a taut wire of natural length ``L_s`` (m), paper Eq. 3 and Table II."""
    return 0.5 * k1 * length


def wire_cubic(E_s: float, d_s: float, T_s: float, length: float) -> float:
    """Cubic wire coefficient ``K3 = (E_s A_s - T_s) / L_s^3`` (N/m^3), paper Eq. 3."""
    return (E_s * math.pi * d_s**2 / 4.0 - T_s) / length**3
