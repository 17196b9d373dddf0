"""Cross-check against LAMMPS's own contact models (``pair_style granular``), no mdgran hook.

The LAMMPS backend (:mod:`mdgran.backends.lammps`) evaluates mdgran's contact law in a Python
``fix external`` hook, so it checks the integration but not the law.  Here the same scene runs
with LAMMPS's native normal models instead, in ``units si``:

* ``jkr``            for ``contact.law = "jkr"`` (Schwarz with ``fc = -1.5``),
* ``dmt``            for ``contact.law = "dmt"`` (``fc = -2``),
* ``hertz/material`` for ``contact.law = "hertz"``.

**Parameter mapping** (R = d/4 is LAMMPS's ``R_eff = R_i R_j / (R_i + R_j)`` for equal beads).
LAMMPS mixes ``E_mix = 1 / ((1 - nu^2)/E + (1 - nu^2)/E) = E / (2 (1 - nu^2))`` and uses

    hertz/material   F = (4/3) E_mix sqrt(R) delta^(3/2)
    jkr              delta = a^2/R - 2 sqrt(pi gamma a / E_mix),
                     F = (4/3) E_mix a^3/R - 2 pi a^2 sqrt(4 gamma E_mix / (pi a))
    dmt              F = (4/3) E_mix sqrt(R) delta^(3/2) - 4 pi gamma R

mdgran's law is ``F = K sqrt(R) delta^(3/2)`` (Hertz) and ``delta = a^2/R - sqrt(8 pi w a /
(3 K))``, ``F = K a^3/R - sqrt(6 pi w K a^3)`` (JKR: the Schwarz law at ``fc = -1.5`` with
``F = eta f``, ``delta = p delta_hat``, ``a = (R eta / K)^(1/3) a_hat``), so the two coincide
exactly when

    E_mix = 3 K / 4,  i.e.  E_lammps = (3/2) (1 - nu^2) K,     gamma = w / 2,

with ``nu`` the scene's Poisson ratio.  For ``modulus = "table"`` (``K = E / (2 (1 - nu^2))``,
the paper's Table I, mdgran's default) that is ``E_lammps = 3 E / 4``; for ``modulus = "text"``
(``K = (2/3) E / (1 - nu^2)``, the textbook Hertz ``(4/3) E*``) it is ``E_lammps = E``.  Handing
LAMMPS the scene's ``E`` unchanged under the table convention makes every contact 4/3 stiffer.
``gamma`` is LAMMPS's *surface* energy (pull-off ``3 pi gamma R = (3/2) pi w R``), half the
work of adhesion ``w``.  Damping: ``damping velocity`` with ``eta_n0 = C_hat sqrt(m eta / p)``
(Ns/m), which LAMMPS applies to touching pairs only, like mdgran's unilateral damping.  The
substrate is ``fix spring/self`` with ``K1 = k1_hat eta / p`` along x.  No tangential force
(``tangential linear_nohistory 0 0``); the beads move on the x axis only.

Snap-off: LAMMPS's ``jkr`` keeps a touching pair in contact until the centre distance exceeds
``radsum + cbrt(3 pi^2 / 16) cbrt(R gamma^2 / E_mix^2)``, which is ``-delta`` at the tensile
force maximum ``F = -3 pi gamma R`` (load-controlled pull-off): mdgran's ``snap_off = "force"``.
It closes when the pair overlaps (``delta > 0``).  Events are step-quantized, as in the hook
backend, so agreement is first order in ``dt`` through snap events.

Scenes without a ``[material]`` table run with the paper's micro bead (alumina, d = 2.5 um);
the nondimensional results do not depend on that choice.  Serial only.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from mdgran.backends.base import steps_per_frame
from mdgran.model.contact import FC_DMT, FC_JKR, ContactLaw
from mdgran.backends.lammps.env import new_lammps
from mdgran.model.units import ALUMINA, Scales, contact_modulus

#: Bead used when a scene has no [material] table (paper's micro bead).
DEFAULT_DIAMETER = 2.5e-6


class NativeUnsupported(ValueError):
    """The scene has physics LAMMPS's native models do not have (one line why)."""


@dataclass(frozen=True)
class NativeMapping:
    """LAMMPS ``units si`` parameters equivalent to a scene (see the module docstring)."""

    model: str  # "jkr" | "dmt" | "hertz/material"
    scales: Scales
    nu: float
    E: float  # Pa, Young's modulus handed to LAMMPS
    gamma: float  # J/m^2, LAMMPS surface energy (0 for Hertz)
    damping: float  # Ns/m, eta_n0 of ``damping velocity``
    k1: float  # N/m, spring/self
    gap: float  # m, initial surface gap

    def as_dict(self) -> dict:
        s = self.scales
        return {"lammps_model": self.model, "units": "si", "diameter_m": s.diameter,
                "R_eff_m": s.R, "mass_kg": s.mass, "K_Pa": s.K, "nu": self.nu,
                "E_lammps_Pa": self.E, "E_mix_Pa": self.E / (2.0 * (1.0 - self.nu**2)),
                "E_mix_over_K": self.E / (2.0 * (1.0 - self.nu**2)) / s.K,
                "gamma_J_m2": self.gamma, "w_J_m2": s.w, "damping_Ns_m": self.damping,
                "k1_N_m": self.k1, "gap_m": self.gap, "eta_N": s.eta, "p_m": s.p,
                "time_unit_s": s.time}


def native_mapping(scene, raw_modulus: bool = False) -> NativeMapping:
    """The LAMMPS parameters for ``scene``.  ``raw_modulus=True`` hands LAMMPS the scene's
    Young's modulus unchanged (the naive mapping, to show what the 3/4 factor is for)."""
    d = scene.data
    mat = d.get("material", {})
    if mat.get("diameter") is not None:
        scales = scene.scales
    else:
        scales = Scales(DEFAULT_DIAMETER, contact_modulus(ALUMINA["E"], ALUMINA["nu"]),
                        ALUMINA["w"], ALUMINA["density"], ALUMINA["D0"])
    nu = float(mat["nu"]) if mat.get("nu") is not None else ALUMINA["nu"]
    law = scene.law
    if law.kind == "hertz":
        model, gamma = "hertz/material", 0.0
    elif law.fc == FC_JKR:
        # LAMMPS opens at the force maximum whatever scene.snap_off says: a scene with the
        # displacement rule still runs, so that the mismatch can be measured
        model, gamma = "jkr", 0.5 * scales.w
    elif law.fc == FC_DMT:
        model, gamma = "dmt", 0.5 * scales.w
    else:
        raise NativeUnsupported(f"LAMMPS has no Schwarz model for fc = {law.fc:.5f}: native "
                                "cross-checks exist for jkr (fc = -1.5), dmt (-2) and hertz")
    if float(d["substrate"]["k3"]):
        raise NativeUnsupported("substrate.k3 != 0 has no native LAMMPS counterpart")
    if raw_modulus:
        E = float(mat["E"]) if mat.get("E") is not None else ALUMINA["E"]
    else:
        E = 1.5 * (1.0 - nu * nu) * scales.K
    return NativeMapping(model=model, scales=scales, nu=nu, E=E, gamma=gamma,
                         damping=float(d["contact"]["damping"]) * scales.damping,
                         k1=float(d["substrate"]["k1"]) * scales.stiffness,
                         gap=float(d["chain"]["initial_gap"]) * scales.p)


class NativeChain:
    """One scene set up in LAMMPS with a native granular pair style (``units si``).

    Atoms have tags ``1..ntot`` along x (walls: tags 1 and ntot, never integrated), centred on
    the origin, spaced by ``d + gap``.  :meth:`state` returns nondimensional displacements,
    velocities and per-atom x forces ordered by tag.
    """

    def __init__(self, scene, dt: float | None = None, mapping: NativeMapping | None = None):
        d = scene.data
        self.scene = scene
        self.map = mapping or native_mapping(scene)
        self.walls = d["chain"]["boundary"] == "fixed"
        self.n = int(d["chain"]["n"])
        self.ntot = self.n + 2 if self.walls else self.n
        self.dt = float(dt if dt is not None else d["run"]["dt"])
        s = self.map.scales
        self.p, self.T, self.eta = s.p, s.time, s.eta
        self.lmp = lmp = new_lammps()
        dia, pitch = s.diameter, s.diameter + self.map.gap
        x0 = (np.arange(self.ntot) - 0.5 * (self.ntot - 1)) * pitch
        half = 0.5 * (self.ntot + 1) * pitch
        m = self.map
        coeff = (f"{m.model} {m.E!r} {m.damping!r} {m.nu!r}"
                 + (f" {m.gamma!r}" if m.model != "hertz/material" else ""))
        cmds = [
            "units si", "atom_style sphere", "dimension 3",
            "atom_modify map array sort 0 0.0", "boundary m f f", "comm_modify vel yes",
            f"region box block {-half!r} {half!r} {-dia!r} {dia!r} {-dia!r} {dia!r} units box",
            "create_box 1 box",
            *[f"create_atoms 1 single {float(x)!r} 0 0 units box" for x in x0],
            f"set atom * diameter {dia!r}", f"set atom * density {s.density!r}",
            "pair_style granular",
            f"pair_coeff * * {coeff} tangential linear_nohistory 0.0 0.0 damping velocity",
            f"neighbor {0.05 * dia!r} bin", "neigh_modify every 1 delay 0 check yes",
            f"timestep {self.dt * self.T!r}",
        ]
        if self.walls:
            cmds += [f"group wall id 1 {self.ntot}", "group mobile subtract all wall"]
        else:
            cmds += ["group mobile union all"]
        cmds += ["fix move mobile nve", "fix line all setforce NULL 0.0 0.0"]
        if m.k1 > 0.0:
            cmds.append(f"fix substrate mobile spring/self {m.k1!r} x")
        for c in cmds:
            lmp.command(c)
        self.x0 = self._by_tag("x")[:, 0].copy()
        bead = int(d["impulse"]["bead"])
        struck = bead + 1 if self.walls else bead
        v0 = float(d["impulse"]["velocity"]) * s.velocity
        lmp.command("velocity all set 0.0 0.0 0.0 units box")
        lmp.command(f"group struck id {struck}")
        lmp.command(f"velocity struck set {v0!r} 0.0 0.0 units box")
        if m.model != "hertz/material" and self.map.gap <= 0.0:
            self._pre_touch()
        lmp.command("run 0 post no")
        self.step = 0

    def _by_tag(self, name):
        lmp = self.lmp
        n = lmp.extract_setting("nlocal")
        tags = lmp.numpy.extract_atom("id", nelem=n)
        arr = lmp.numpy.extract_atom(name, nelem=n, dim=3)
        out = np.empty((self.ntot, 3))
        out[tags - 1] = arr
        return out

    def _pre_touch(self):
        """mdgran starts every contact closed at delta = 0; LAMMPS's jkr/dmt mark a pair as
        touching only once it overlaps.  Overlap every pair by 1e-9 p for one ``run 0`` (which
        sets LAMMPS's own touch history), then put the atoms back."""
        lmp = self.lmp
        n = lmp.extract_setting("nlocal")
        tags = lmp.numpy.extract_atom("id", nelem=n)
        x = lmp.numpy.extract_atom("x", nelem=n, dim=3)
        saved = x[:, 0].copy()
        x[:, 0] -= (tags - 0.5 * (self.ntot + 1)) * 1e-9 * self.p
        lmp.command("run 0 post no")
        x = lmp.numpy.extract_atom("x", nelem=n, dim=3)
        x[:, 0] = saved

    def state(self):
        """``(x, v, f)``: displacement / p, velocity / (p q), force / eta of every atom by tag."""
        x = (self._by_tag("x")[:, 0] - self.x0) / self.p
        v = self._by_tag("v")[:, 0] * self.T / self.p
        f = self._by_tag("f")[:, 0] / self.eta
        return x, v, f

    def advance(self, steps: int = 1):
        self.lmp.command(f"run {int(steps)} pre no post no")
        self.step += int(steps)

    def close(self):
        self.lmp.close()


@dataclass
class NativeResult:
    time: np.ndarray  # [F] nondimensional
    x: np.ndarray  # [F, n] displacements of the moving beads
    v: np.ndarray  # [F, n]
    ev_time: np.ndarray  # [E] (pair scenes only; empty otherwise)
    ev_kind: np.ndarray  # [E] 1 close, 0 open
    mapping: dict
    dt: float


def run_native(scene, dt: float | None = None, duration: float | None = None,
               mapping: NativeMapping | None = None) -> NativeResult:
    """Run ``scene`` with LAMMPS's native model; frames every ``run.output_interval``.

    For a free two-bead scene the contact's open/closed state is read from LAMMPS every step
    (closed exactly when the pair force is non-zero), and each event time is interpolated
    linearly in ``delta`` within its step to the threshold LAMMPS switched at
    (:func:`lammps_delta_off` on opening, 0 on closing), as the hook backend does.  Chains
    (and a tethered pair) report no events.
    """
    d = scene.data
    dt = float(dt if dt is not None else d["run"]["dt"])
    duration = float(duration if duration is not None else d["run"]["duration"])
    interval = float(d["run"]["output_interval"])
    per_frame = steps_per_frame(dt, interval)
    frames = int(round(duration / interval))
    chain = NativeChain(scene, dt, mapping)
    # events are read off the atom force, which is the pair force alone without a tether
    pair = chain.ntot == 2 and chain.map.k1 == 0.0
    law = scene.law
    gap = float(d["chain"]["initial_gap"])
    sl = slice(1, -1) if chain.walls else slice(None)
    off = lammps_delta_off(law)
    try:
        xs, vs, evt, evk = [], [], [], []
        x, v, f = chain.state()
        closed = bool(f[0] != 0.0) if pair else None
        delta_prev = x[0] - x[1] - gap if pair else None
        xs.append(x[sl])
        vs.append(v[sl])
        for _ in range(frames):
            if not pair:
                chain.advance(per_frame)
                x, v, f = chain.state()
            else:
                for _ in range(per_frame):
                    chain.advance(1)
                    x, v, f = chain.state()
                    delta = x[0] - x[1] - gap
                    now = bool(f[0] != 0.0)
                    if now != closed:
                        target = 0.0 if now else off
                        u = (target - delta_prev) / (delta - delta_prev) \
                            if delta != delta_prev else 1.0
                        evt.append((chain.step - 1 + min(max(u, 0.0), 1.0)) * dt)
                        evk.append(int(now))
                        closed = now
                    delta_prev = delta
            xs.append(x[sl])
            vs.append(v[sl])
    finally:
        chain.close()
    return NativeResult(time=np.arange(frames + 1) * interval, x=np.array(xs), v=np.array(vs),
                        ev_time=np.array(evt), ev_kind=np.array(evk, dtype=int),
                        mapping=chain.map.as_dict(), dt=dt)


def probe_force(scene, deltas, mapping: NativeMapping | None = None):
    """LAMMPS's normal force for two beads at each compression in ``deltas`` (nondimensional,
    visited in the given order starting from a touching pair, so a decreasing sequence follows
    the attached branch through the tensile region until LAMMPS lets go).  Returns the
    repulsive force / eta at each point (0 where LAMMPS reports no contact)."""
    from mdgran.model.scene import Scene, resolve

    data = {k: dict(v) for k, v in scene.data.items()}
    data["chain"].update(n=2, boundary="free", initial_gap=0.0)
    data["substrate"].update(k1=0.0, k1_si=None)
    data["contact"].update(damping=0.0, damping_si=None)
    data["impulse"].update(bead=1, velocity=0.0, velocity_si=None)
    data["run"].update(duration_si=None)
    probe = Scene(scene.name, resolve(data))
    if mapping is not None:  # the contact parameters only: no tether, no damping, no gap
        mapping = dataclasses.replace(mapping, k1=0.0, damping=0.0, gap=0.0)
    chain = NativeChain(probe, 1.0, mapping)
    lmp = chain.lmp
    out = []
    try:
        for delta in np.asarray(deltas, dtype=float):
            n = lmp.extract_setting("nlocal")
            tags = lmp.numpy.extract_atom("id", nelem=n)
            x = lmp.numpy.extract_atom("x", nelem=n, dim=3)
            # tag 1 moves right by delta p / 2, tag 2 left by delta p / 2
            x[:, 0] = chain.x0[tags - 1] + np.where(tags == 1, 0.5, -0.5) * delta * chain.p
            lmp.command("run 0 post no")
            out.append(-chain.state()[2][0])
    finally:
        chain.close()
    return np.array(out)


# ---- comparisons with the reference backend -------------------------------------------------

def pair_summary(time, x, v, ev_time, ev_kind) -> dict:
    """Outcome of a two-bead collision (bead 1 moving towards bead 2): final velocities,
    relative rebound speed, contact duration (first close to first open), whether the pair
    separated, event count."""
    ev_time, ev_kind = np.asarray(ev_time), np.asarray(ev_kind)
    closes, opens = ev_time[ev_kind == 1], ev_time[ev_kind == 0]
    separated = bool(len(opens) and (not len(closes) or opens[-1] > closes[-1]))
    out = {"v_final": [float(v[-1, 0]), float(v[-1, 1])],
           # relative speed after the pair let go (None while it is still stuck)
           "rebound_speed": float(v[-1, 1] - v[-1, 0]) if separated else None,
           "separated": separated,
           "t_close": float(closes[0]) if len(closes) else None,
           "t_open": float(opens[0]) if len(opens) else None, "events": int(len(ev_time))}
    out["contact_duration"] = (out["t_open"] - out["t_close"]
                               if out["t_open"] is not None and out["t_close"] is not None
                               else None)
    return out


def compare_pair(scene, dt: float, reference=None) -> dict:
    """Native LAMMPS against the reference backend for a two-bead collision scene."""
    from mdgran.simulation import run

    ref = reference if reference is not None else run(scene, "reference").trajectory
    nat = run_native(scene, dt)
    keep = ref.ev_contact > 0
    rs = pair_summary(ref.time, ref.x, ref.v, ref.ev_time[keep], ref.ev_kind[keep])
    ns = pair_summary(nat.time, nat.x, nat.v, nat.ev_time, nat.ev_kind)
    k = min(len(ref.time), len(nat.time))
    out = {"dt": dt, "reference": rs, "lammps": ns,
           "same_outcome": rs["separated"] == ns["separated"] and rs["events"] == ns["events"],
           "x_max_abs_error": float(np.max(np.abs(nat.x[:k] - ref.x[:k]))),
           "v_max_abs_error": float(np.max(np.abs(nat.v[:k] - ref.v[:k])))}
    if rs["separated"] and ns["separated"]:
        out["rebound_speed_error"] = abs(ns["rebound_speed"] - rs["rebound_speed"])
    if rs["contact_duration"] is not None and ns["contact_duration"] is not None:
        out["contact_duration_error"] = abs(ns["contact_duration"] - rs["contact_duration"])
    if len(ref.ev_time[keep]) == len(nat.ev_time):
        out["event_time_max_error"] = float(np.max(np.abs(ref.ev_time[keep] - nat.ev_time))) \
            if len(nat.ev_time) else 0.0
    return out


def compare_chain(scene, dt: float, duration: float, reference=None,
                  mapping: NativeMapping | None = None) -> dict:
    """Native LAMMPS against the reference backend: largest displacement and velocity
    differences over the frames up to ``duration`` (nondimensional)."""
    from mdgran.simulation import run

    if reference is None:
        reference = run(scene.with_overrides([("run.duration", duration)]),
                        "reference").trajectory
    nat = run_native(scene, dt, duration, mapping)
    k = min(len(reference.time), len(nat.time))
    ex = np.abs(nat.x[:k] - reference.x[:k])
    return {"dt": dt, "duration": duration, "x_max_abs_error": float(ex.max()),
            "x_max_abs": float(np.abs(reference.x[:k]).max()),
            "v_max_abs_error": float(np.max(np.abs(nat.v[:k] - reference.v[:k]))),
            "v_max_abs": float(np.abs(reference.v[:k]).max()), "frames": int(k)}


def lammps_delta_off(law) -> float:
    """Compression at which LAMMPS's native model opens a touching pair (nondimensional):
    ``-cbrt(3 pi^2/16) cbrt(R gamma^2 / E_mix^2) / p`` for jkr, which under the mapping is the
    tensile force maximum of the JKR law; 0 for dmt and hertz/material."""
    if law.kind == "hertz" or law.fc == FC_DMT:
        return 0.0
    return ContactLaw("schwarz", FC_JKR, "force").delta_off


def lammps_pulloff_distance(mapping: NativeMapping) -> float:
    """LAMMPS's jkr pull-off distance (m) from its source formula, for the record."""
    e_mix = mapping.E / (2.0 * (1.0 - mapping.nu**2))
    R = mapping.scales.R
    return (3.0 * math.pi**2 / 16.0) ** (1.0 / 3.0) * (R * mapping.gamma**2 / e_mix**2) ** (1 / 3)


def quantization_bound(law, v_close: float, v_open: float, dt: float) -> float:
    """Bound on the rebound-speed error of a step-quantized pair collision: closing up to one
    step late misses at most ``|f_on| v_close dt`` of contact energy, opening up to one step
    late books at most ``|f_off| v_open dt`` too much loss; the relative kinetic energy is
    ``v_rel^2 / 4``, so ``|d v_rel| <= 2 (|f_on| v_close + |f_off| v_open) dt / v_open``."""
    f_off = abs(float(law.force(lammps_delta_off(law)))) if law.kind != "hertz" else 0.0
    de = (abs(law.f_on) * abs(v_close) + f_off * abs(v_open)) * dt
    return 2.0 * de / max(abs(v_open), 1e-12)


def escape_speed(law) -> float:
    """Smallest impact speed (relative) at which a free pair separates again:
    ``v^2 / 4 = V(delta_off)`` (reduced mass 1/2)."""
    return 2.0 * math.sqrt(max(law.loop_energy, 0.0))
