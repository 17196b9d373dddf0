"""The chain model: equations of motion (paper Eq. 6) and the energy ledger, nondimensional.

Bead mass is 1.  ``x[i]`` is the displacement of moving bead ``i`` (0-based here; the paper's
bead ``i + 1``) from its initial place.  Contacts:

* ``boundary = "fixed"``: ``n + 1`` contacts; contact ``k`` (0-based, the contract's contact
  number ``k + 1``) joins bead ``k - 1`` and bead ``k``, beads ``-1`` and ``n`` being walls
  at ``x = 0``.
* ``boundary = "free"``: ``n - 1`` contacts between neighbouring beads (contract numbers
  ``2..n``).

Compression of a contact: ``delta = x_left - x_right - gap``.  With ``F`` the force of each
closed contact (law force plus unilateral damping ``c * d delta/dt``; zero when open)::

    x_i'' = F_i - F_(i+1) - k1 x_i - k3 x_i^3

Terms switched off by the scene (``k1 = 0``, ``k3 = 0``, ``damping = 0``) are not evaluated.

**Unlike beads** (``mixture``, :class:`mdgran.model.mixture.Mixture`): bead ``i`` has mass ``m_i``
and substrate factor ``g_i``, contact ``k`` its own law ``F_k`` (in the reference bead's units);
with the substrate's damping ``c_s`` (``substrate.damping``, dissipation booked as viscous)::

    m_i x_i'' = F_i - F_(i+1) - g_i (k1 x_i + k3 x_i^3 + c_s x_i')

Without a mixture every mass is 1 and every contact has ``law`` (the homogeneous chain, whose
arithmetic is unchanged).

**Excitations** (``drive``, :mod:`mdgran.model.drive`): a force pulse ``F(t)`` on one bead, and a
base motion ``u_b(t)`` under the substrate, whose terms then act on ``x_i - u_b`` and ``x_i' -
u_b'``; their work is the ledger's ``external_work``.  The dynamics take the time ``t`` for
them (ignored without a drive).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .contact import ContactLaw
from .contact_scalar import numpy_law
from .drive import Drive
from .mixture import Mixture


# ---- contact numbering and states: the one place that knows them -----------------------------
def n_contacts(n: int, walls: bool = True) -> int:
    """Number of contacts of a chain of ``n`` moving beads: ``n + 1`` between fixed walls,
    ``n - 1`` for a free chain."""
    return n + 1 if walls else n - 1


def first_contact(walls: bool = True) -> int:
    """Contract number of the first contact: 1 (wall-bead 1) with walls, 2 (bead 1-bead 2)
    for a free chain."""
    return 1 if walls else 2


def contact_numbers(n: int, walls: bool = True) -> np.ndarray:
    """Contract numbers of the contacts, in column order: ``1..n+1`` with walls, ``2..n`` for a
    free chain (contact ``i`` joins bead ``i-1`` and bead ``i``; beads 0 and n+1 are walls)."""
    return first_contact(walls) + np.arange(n_contacts(n, walls))


def contact_columns(contacts, walls: bool = True) -> np.ndarray:
    """Column (0-based, the order of :func:`contact_numbers`) of each contract number in
    ``contacts``."""
    return np.asarray(contacts, dtype=np.int64) - first_contact(walls)


def touching_contacts(n: int, walls: bool, lo: int, hi: int) -> tuple[int, int]:
    """``(c0, c1)``: the 0-based contacts ``c0 .. c1 - 1`` that touch the 0-based beads
    ``lo .. hi - 1`` (contact ``j`` joins beads ``j - 1`` and ``j`` with walls, ``j`` and
    ``j + 1`` without)."""
    w = 1 if walls else 0
    return max(lo - 1 + w, 0), min(hi + w, n_contacts(n, walls))


def initial_states(n: int, walls: bool = True, initial_gap: float = 0.0) -> np.ndarray:
    """The paper's initial contact states [n_contacts]: every contact closed at ``delta = 0``,
    or every contact open when the scene has an initial gap (``initial_gap > 0``)."""
    return np.full(n_contacts(n, walls), float(initial_gap) <= 0.0)


def replay_states(initial, ev_time, ev_contact, ev_kind, times, walls: bool = True
                  ) -> np.ndarray:
    """Contact states at each of ``times`` [F] (bool ``[F, n_contacts]``, True = closed),
    rebuilt from the events: the ``initial`` states [n_contacts], then every event with
    ``ev_time <= t`` applied in time order (events at equal times in list order, the last
    one winning).  ``ev_contact``: contract numbers; ``ev_kind``: 1 close, 0 open."""
    init = np.asarray(initial, dtype=bool)
    times = np.asarray(times, dtype=float)
    ev_time = np.asarray(ev_time, dtype=float)
    ev_kind = np.asarray(ev_kind).astype(bool)
    cols = contact_columns(ev_contact, walls)
    bad = (cols < 0) | (cols >= len(init))
    if bad.any():
        first, last = first_contact(walls), first_contact(walls) + len(init) - 1
        raise ValueError(f"ev_contact: contact numbers of this chain are {first}..{last}, not "
                         f"{int(np.asarray(ev_contact)[bad][0])}")
    states = np.tile(init, (len(times), 1))
    order = np.argsort(ev_time, kind="stable")
    order = order[np.argsort(cols[order], kind="stable")]  # by contact, then time, then list
    bounds = np.flatnonzero(np.diff(cols[order])) + 1
    for mine in np.split(order, bounds) if len(order) else ():  # one contact's events
        last = np.searchsorted(ev_time[mine], times, side="right") - 1
        seen = last >= 0
        states[seen, cols[mine[0]]] = ev_kind[mine[last[seen]]]
    return states


#: beads or contacts the ledger sums together (ChainModel.ledger_block): a chain of at most
#: this many is one block; blocks of a long chain at rest cost nothing (mdgran.rest_blocks)
LEDGER_BLOCK = 4096


def dots(a, b) -> np.ndarray:
    """``[np.dot(r, s) for r, s in zip(a, b)]`` of 2-D arrays (:func:`row_dots`)."""
    return np.matmul(a[:, None, :], b[:, :, None])[:, 0, 0]


def sum_blocks(sums: list, blocks: list, count: int, F: int, rest=None) -> np.ndarray:
    """The row sums ``[F]`` of a quantity over ``count`` beads or contacts summed by blocks of
    :data:`LEDGER_BLOCK`: ``sums`` ([F] each) of the blocks ``blocks`` (slices), the others'
    from ``rest(length)`` (None: zeros, left out), added in block order.  Adding a block of
    zeros changes no sum, so the result does not depend on which blocks of zeros were
    computed."""
    b = LEDGER_BLOCK
    have = {s.start // b: part for s, part in zip(blocks, sums)}
    total = None
    for j in range(max(1, -(-count // b))):
        part = have.get(j)
        if part is None:
            if rest is None:
                continue
            part = rest(min(count, (j + 1) * b) - j * b)
        total = part if total is None else total + part
    return np.zeros(F) if total is None else total


def row_dots(a) -> np.ndarray:
    """``[np.dot(r, r) for r in a]`` of a 2-D array ``a``, in one call: a stack of row-times-
    column products, which numpy's matmul computes with the same BLAS dot as ``np.dot`` of
    two vectors (bitwise the same; tests/test_ledger_block.py checks it)."""
    return np.matmul(a[:, None, :], a[:, :, None])[:, 0, 0]


@dataclass(frozen=True)
class ChainModel:
    n: int
    law: ContactLaw
    boundary: str = "fixed"
    damping: float = 0.0
    k1: float = 0.0
    k3: float = 0.0
    gap: float = 0.0
    mixture: Mixture | None = field(default=None, compare=False)
    substrate_damping: float = 0.0  # c_s: force -c_s v on each bead on the substrate
    temperature: float = 0.0  # initial random velocities, variance temperature / m_i
    seed: int = 0  # of those velocities
    drive: Drive | None = field(default=None, compare=False)  # force pulse, base motion
    walls: bool = field(init=False)

    def __post_init__(self):
        object.__setattr__(self, "walls", self.boundary == "fixed")
        mix = self.mixture
        if mix is not None and (mix.n != self.n or len(mix.fc) != self.n_contacts):
            raise ValueError(f"mixture: {mix.n} beads and {len(mix.fc)} contacts for a chain "
                             f"of {self.n} beads and {self.n_contacts} contacts")

    # ---- per-contact laws (the mixture's, else the one law) ---------------------------------
    @property
    def mixed(self) -> bool:
        """True for a chain of unlike beads (a :class:`~mdgran.model.mixture.Mixture`)."""
        return self.mixture is not None

    @property
    def delta_off(self):
        """Opening threshold: ``law.delta_off``, or an array [n_contacts] for a mixture."""
        return self.law.delta_off if self.mixture is None else self.mixture.delta_off

    @property
    def loop_energy(self):
        """Energy lost per opening: ``law.loop_energy``, or an array [n_contacts]."""
        return self.law.loop_energy if self.mixture is None else self.mixture.loop_energy

    @property
    def masses(self) -> np.ndarray:
        """Bead masses [n] (ones for a homogeneous chain)."""
        return np.ones(self.n) if self.mixture is None else self.mixture.mass

    def law_force(self, delta, k=None):
        """Force of closed contacts at ``delta`` (all contacts [..., m], or contacts ``k``)."""
        if self.mixture is None:
            return self.law.force(delta)
        return self.mixture.force(delta, k)

    def contact_law_energy(self, delta, k=None):
        """Energy of closed contacts at ``delta`` (all contacts, or contacts ``k``)."""
        if self.mixture is None:
            return self.law_energy(delta)
        return self.mixture.energy(delta, k)

    # ---- geometry --------------------------------------------------------------------------
    @property
    def n_contacts(self) -> int:
        return n_contacts(self.n, self.walls)

    @property
    def contact_numbers(self) -> np.ndarray:
        """Contract numbering of the contacts (:func:`contact_numbers`)."""
        return contact_numbers(self.n, self.walls)

    def differences(self, x):
        """``x_left - x_right`` for every contact (walls at 0)."""
        if self.walls:
            d = np.empty(self.n + 1)
            d[0] = -x[0]
            d[1:-1] = x[:-1] - x[1:]
            d[-1] = x[-1]
            return d
        return x[:-1] - x[1:]

    def compressions(self, x):
        d = self.differences(x)
        return d - self.gap if self.gap else d

    def _apply(self, f):
        """Net force on each bead from per-contact forces ``f`` (``f_i - f_(i+1)``)."""
        if self.walls:
            return f[:-1] - f[1:]
        a = np.zeros(self.n)
        a[1:] += f
        a[:-1] -= f
        return a

    # ---- dynamics --------------------------------------------------------------------------
    def contact_forces(self, x, v, closed):
        """Per-contact force (law plus unilateral damping), zero on open contacts."""
        delta = self.compressions(x)
        f = self.law_force(delta)
        if self.damping:
            f = f + self.damping * self.differences(v)
        return np.where(closed, f, 0.0)

    def substrate_force(self, x, v=None, t=0.0):
        """``-g_i (k1 x_i + k3 x_i^3 + c_s v_i)`` [n] (``c_s`` with ``v`` given), or None
        when the scene has no substrate term; with a base motion, of ``x_i - u_b(t)`` and
        ``v_i - u_b'(t)``."""
        if self.drive is not None and self.drive.base is not None:
            ub, vb = self.drive.base_at(t)
            x = x - ub
            v = None if v is None else v - vb
        s = None
        if self.k3:
            s = -(self.k1 + self.k3 * x * x) * x
        elif self.k1:
            s = -self.k1 * x
        if self.substrate_damping and v is not None:
            s = -self.substrate_damping * v if s is None else s - self.substrate_damping * v
        if s is not None and self.mixture is not None and self.mixture.free_beads:
            s = self.mixture.substrate * s
        return s

    def free_acceleration(self, x, v, t=0.0):
        """Acceleration with every contact open: the substrate (and a pulse) alone, over the
        masses."""
        s = self._add_pulse(self.substrate_force(x, v, t), t)
        if s is None:
            return np.zeros(self.n)
        return self._per_mass(s)

    def _add_pulse(self, force, t):
        """``force`` [n] (or None: zero) plus the pulse's force at t on its bead."""
        if self.drive is None or self.drive.pulse is None:
            return force
        p = self.drive.pulse
        force = np.zeros(self.n) if force is None else force.copy()
        force[p.bead] += p.force(t)
        return force

    def _per_mass(self, force):
        if self.mixture is not None and not self.mixture.uniform_mass:
            return force / self.mixture.mass
        return force

    def acceleration(self, x, v, closed, t=0.0):
        a = self._apply(self.contact_forces(x, v, closed))
        s = self._add_pulse(self.substrate_force(x, v, t), t)
        return self._per_mass(a if s is None else a + s)

    def external_power(self, x, v, t) -> float:
        """Rate of the excitations' work (eta p q): ``F(t) v_b + u_b'(t) sum_i F_sub,i``
        (:mod:`mdgran.model.drive`); 0 without a drive."""
        if self.drive is None:
            return 0.0
        p = 0.0
        if self.drive.pulse is not None:
            p += self.drive.pulse.force(t) * float(v[self.drive.pulse.bead])
        if self.drive.base is not None:
            s = self.substrate_force(x, v, t)
            p += self.drive.base_at(t)[1] * float(np.sum(s))
        return p

    def viscous_power(self, v, closed, t=0.0):
        """Rate of viscous dissipation, ``sum_closed c (d delta/dt)^2`` plus the substrate's
        ``sum_i g_i c_s v_i^2`` (``v_i - u_b'(t)`` with a base motion)."""
        p = 0.0
        if self.damping:
            dv = self.differences(v)
            p = self.damping * float(np.sum(np.where(closed, dv * dv, 0.0)))
        if self.substrate_damping:
            g = 1.0 if self.mixture is None else self.mixture.substrate
            if self.drive is not None and self.drive.base is not None:
                v = v - self.drive.base_at(t)[1]
            p += self.substrate_damping * float(np.sum(g * v * v))
        return p

    # ---- energy ledger ---------------------------------------------------------------------
    def closed_contact_energies(self, delta, closed, k=None) -> np.ndarray:
        """``np.where(closed, contact_law_energy(delta, k), 0.0)`` (any shape; ``k``: the
        contacts of the last axis, a slice or indices, default all), the law evaluated once
        for every contact at ``delta = 0`` (a long chain's contacts at rest: the Newton
        iterations of the Schwarz energy cost ~0.25 us a contact) and at the others alone:
        bitwise the same, the law being elementwise."""
        delta = np.asarray(delta, dtype=float)
        if self.mixture is not None:
            return np.where(closed, self.contact_law_energy(delta, k), 0.0)
        out = np.zeros(delta.shape)
        moved = closed & (delta != 0.0)
        out[moved] = self.law_energy(delta[moved])
        rest = closed & (delta == 0.0)
        if rest.any():
            zero = self.law_energy(np.array([0.0, -0.0]))
            out[rest] = np.where(np.signbit(delta[rest]), zero[1], zero[0])
        return out

    @cached_property
    def _law_constants(self):
        """The law's constants (:attr:`ContactLaw.constants`), computed once: the ledger
        evaluates the energy at every frame, and the law would recompute them at each call."""
        return tuple(self.law.constants)

    def law_energy(self, delta):
        """``law.energy(delta)`` with the law's constants computed once: the same scalar law
        (:func:`~mdgran.model.contact_scalar.numpy_law`) lifted over ``delta``."""
        return numpy_law(self.law.kind, "energy")(np.asarray(delta, dtype=float),
                                                  *self._law_constants)

    def ledger(self, x, v, closed, dissipated_viscous, dissipated_hysteresis,
               external_work=0.0, t=0.0) -> dict:
        """The energy ledger of docs/physics.md section 4 for one state at time t, with the
        excitations' work ``external_work`` (:mod:`mdgran.model.drive`): ``total = kinetic +
        contact + substrate + dissipated - external_work``; row 0 of :meth:`ledger_block`
        (floats)."""
        led = self.ledger_block(np.asarray(x, dtype=float)[None],
                                np.asarray(v, dtype=float)[None], np.asarray(closed)[None],
                                [dissipated_viscous], [dissipated_hysteresis],
                                [external_work], [t])
        return {term: float(value[0]) for term, value in led.items()}

    def ledger_block(self, x, v, closed, dissipated_viscous, dissipated_hysteresis,
                     external_work=None, t=None, moved=None) -> dict:
        """The ledger (:meth:`ledger`) of ``F`` states at once: ``x``, ``v`` [F, n],
        ``closed`` [F, n_contacts], the dissipated energies, the external work and the times
        [F] (the last two None: 0); each term an array [F].

        Each sum over beads or contacts is taken by blocks of :data:`LEDGER_BLOCK` (BLAS's
        dot product, :func:`row_dots`, or numpy's pairwise sum within a block; the blocks'
        sums added in order, :func:`sum_blocks`): a chain of at most ``LEDGER_BLOCK`` beads
        is one block.  ``moved`` (:attr:`mdgran.backends.base.Frames.moved`): the beads
        ``lo .. hi - 1`` outside which every bead is at ``x = v = +0`` and every contact in
        its initial state; only the blocks that meet them are computed from the states (the
        others' sums are those of beads and contacts at rest), and the result is bitwise the
        same as without ``moved``: a long chain's ledger costs the beads that moved."""
        x, v = np.asarray(x, dtype=float), np.asarray(v, dtype=float)
        closed = np.asarray(closed)
        F = len(x)
        if self.drive is not None and self.drive.base is not None:
            moved = None  # the substrate acts on x - u_b everywhere
        beads = self._live_blocks(self.n, moved, 0)
        contacts = self._live_blocks(self.n_contacts, moved, 1)
        mix = self.mixture
        mass_v = v if mix is None else mix.mass * v
        kinetic = 0.5 * sum_blocks([dots(mass_v[:, s], v[:, s]) for s in beads], beads, self.n,
                                   F)
        delta = self._block_differences(x, contacts)
        energies = [np.sum(self.closed_contact_energies(d, closed[:, s], s), axis=1)
                    for d, s in zip(delta, contacts)]
        contact = sum_blocks(energies, contacts, self.n_contacts, F, self._rest_contact_sums(F))
        y = x
        if self.drive is not None and self.drive.base is not None:
            y = x - self.drive.base.position(t)[:, None]
        if mix is not None and mix.free_beads:
            y = y * np.sqrt(mix.substrate)
        substrate = np.zeros(F)
        if self.k1:
            sq = sum_blocks([row_dots(y[:, s]) for s in beads], beads, self.n, F)
            substrate = substrate + 0.5 * self.k1 * sq
        if self.k3:
            quart = sum_blocks([np.sum(y[:, s] ** 4, axis=1) for s in beads], beads, self.n, F)
            substrate = substrate + 0.25 * self.k3 * quart
        led = {
            "kinetic_energy": kinetic,
            "contact_energy": contact,
            "substrate_energy": substrate,
            "dissipated_viscous": np.asarray(dissipated_viscous, dtype=float),
            "dissipated_hysteresis": np.asarray(dissipated_hysteresis, dtype=float),
        }
        total = 0.0  # kinetic + contact + substrate + dissipated, in this order
        for term in led.values():
            total = total + term
        work = np.zeros(F) if external_work is None else np.asarray(external_work, float)
        led["external_work"] = work
        led["total_energy"] = total - work
        return led

    def _live_blocks(self, count, moved, contacts) -> list:
        """The blocks of :data:`LEDGER_BLOCK` beads (``contacts = 0``) or contacts (1) of
        ``count`` that meet ``moved`` (all without it), as slices."""
        lo, hi = 0, count
        if moved is not None:
            lo, hi = moved
            if contacts:
                lo, hi = touching_contacts(self.n, self.walls, lo, hi)
        b = LEDGER_BLOCK
        return [slice(j * b, min(count, (j + 1) * b)) for j in range(lo // b, -(-hi // b))]

    def _rest_contact_sums(self, F):
        """The energy sum of a block of contacts at rest (initial state, ``delta = +0``),
        from its length: ``fn(length) -> [F]``."""
        if self.gap > 0 or self.mixture is not None:
            return None  # open at rest: 0 (a mixture is always summed whole)
        e0 = self.closed_contact_energies(np.zeros(1), np.ones(1, dtype=bool))[0]
        return lambda length: np.full(F, np.sum(np.full(length, e0)))

    def _block_differences(self, x, blocks) -> list:
        """:meth:`differences` (minus the gap) of each row of ``x`` [F, n] for each slice of
        contacts in ``blocks``: ``[F, len]`` each.  Contact ``j`` joins ``xp[j]`` and
        ``xp[j + 1]``, ``xp = [0, x, 0]`` with walls (the walls' contacts ``-x_1`` and
        ``x_n``), ``x`` without."""
        w = 1 if self.walls else 0
        out = []
        for s in blocks:
            c0, c1 = s.start, s.stop
            b0, b1 = max(c0 - w, 0), min(c1 + 1 - w, self.n)  # the beads they join
            xp = np.zeros((len(x), c1 + 1 - c0))
            xp[:, b0 + w - c0:b1 + w - c0] = x[:, b0:b1]
            d = xp[:, :-1] - xp[:, 1:]
            if w and c0 == 0:
                d[:, 0] = -x[:, 0]
            if w and c1 == self.n_contacts:
                d[:, -1] = x[:, -1]
            out.append(d - self.gap if self.gap else d)
        return out

    def initial_state(self, bead: int, velocity: float, closed: bool = True):
        """Paper's initial state: beads at rest at x = 0 except ``bead`` (1-based); every
        contact closed at ``delta = 0`` (open when the scene has an initial gap).  A backend
        then opens at once any contact that sits on its snap-off point moving outward (the
        wall contact behind the struck bead, for DMT and Hertz).

        Unlike beads between walls start from the chain's static equilibrium
        (:meth:`equilibrium`): their contacts' forces at ``delta = 0`` differ, so ``x = 0``
        is no equilibrium there (the homogeneous chain's uniform tension is).  A free chain
        starts at ``delta = 0`` as the homogeneous one does."""
        states = initial_states(self.n, self.walls, self.gap)
        if not closed:
            states = np.zeros_like(states)
        x = np.zeros(self.n)
        if self.mixture is not None and self.walls and states.all():
            x = self.equilibrium.copy()
        v = self.thermal_velocities()
        v[bead - 1] += velocity
        return x, v, states

    @staticmethod
    def _flush_tail(x, net_force, tol):
        """``x`` with displacements below 1e-20 of the largest set to 0, if the forces stay
        within ``tol``.  On a substrate the equilibrium's displacement decays exponentially
        into the bulk (over sqrt(k / k1) beads) down to subnormal numbers, whose arithmetic
        costs x86 processors ~100x: 318 of 1e4 beads made the fast kernel 2.9x slower."""
        flushed = np.where(np.abs(x) < 1e-20 * np.max(np.abs(x)), 0.0, x)
        force = net_force(flushed)
        return flushed if force is not None and np.max(np.abs(force)) <= tol else x

    def thermal_velocities(self) -> np.ndarray:
        """Initial random velocities [n]: ``v_i = sqrt(temperature / m_i) N_i``, ``N_i``
        standard normal from numpy's ``default_rng(seed)`` (each bead's mean kinetic energy
        ``temperature / 2``, units eta p); zeros at temperature 0."""
        if not self.temperature:
            return np.zeros(self.n)
        normal = np.random.default_rng(self.seed).standard_normal(self.n)
        return np.sqrt(self.temperature / self.masses) * normal

    def _rest_at_contact(self, x, closed) -> np.ndarray:
        """:meth:`equilibrium` of a chain whose contacts switch at ``delta = 0`` (Hertz, DMT):
        ``x = 0``, every contact touching, if the forces there balance (Hertz: every force is
        0); else none exists with every contact closed (unlike DMT pairs pull unequally, and
        any stretch would open one)."""
        from .scene import SceneError

        force = self.masses * self.acceleration(x, np.zeros(self.n), closed)
        scale = 1.0 + float(np.max(np.abs(self.law_force(self.compressions(x)))))
        if np.max(np.abs(force)) <= 4.0 * np.finfo(float).eps * scale:
            return x
        raise SceneError("beads", "the closed chain of these beads has no static equilibrium: "
                         "its contacts open at delta = 0 and unlike pairs pull unequally there; "
                         "use a free chain (chain.boundary = 'free') or like beads")

    @cached_property
    def equilibrium(self) -> np.ndarray:
        """Displacements [n] at which every bead of the closed chain is at rest,
        ``F_i - F_(i+1) = g_i (k1 x_i + k3 x_i^3)``, by Newton's method from ``x = 0`` with the
        tridiagonal stiffness matrix, to 4 machine epsilons of the largest contact force.
        Raises :class:`~mdgran.model.scene.SceneError` where the closed chain has no equilibrium
        near ``x = 0`` (a contact would have to open)."""
        from scipy.linalg import solve_banded

        from .scene import SceneError

        closed = np.ones(self.n_contacts, dtype=bool)

        def net_force(x):
            """Net force per bead [n], or None where a contact has left its closed branch."""
            if np.any(self.compressions(x) <= self.delta_off):
                return None
            return self.masses * self.acceleration(x, np.zeros(self.n), closed)

        x = np.zeros(self.n)
        force = net_force(x)
        if force is None:  # delta_off = 0 (Hertz, DMT): every contact on its switching point
            return self._rest_at_contact(x, closed)
        for _ in range(50):
            delta = self.compressions(x)
            scale = 1.0 + float(np.max(np.abs(self.law_force(delta))))
            tol = 4.0 * np.finfo(float).eps * scale
            if np.max(np.abs(force)) <= tol:
                return self._flush_tail(x, net_force, tol)
            kc = self.mixture.stiffness(delta)
            k_left = kc[:-1] if self.walls else np.concatenate([[0.0], kc])
            k_right = kc[1:] if self.walls else np.concatenate([kc, [0.0]])
            on_site = self.k1 + 3.0 * self.k3 * x * x
            if self.mixture.free_beads:
                on_site = self.mixture.substrate * on_site
            bands = np.zeros((3, self.n))
            bands[0, 1:] = k_right[:-1]
            bands[1] = -(k_left + k_right) - on_site
            bands[2, :-1] = k_right[:-1]
            step = solve_banded((1, 1), bands, force)
            for _ in range(60):  # damped: halve the step until the force decreases
                trial = net_force(x - step)
                if trial is not None and np.max(np.abs(trial)) < np.max(np.abs(force)):
                    break
                step = 0.5 * step
            else:
                break
            x, force = x - step, trial
        raise SceneError("beads", "the closed chain of these beads has no static equilibrium "
                         "near x = 0 (a contact would open); make the beads less unlike")


def model_from_scene(scene) -> "ChainModel":
    """Build the model from a resolved scene (see :mod:`mdgran.model.scene`)."""
    from .contact import law_from_contact_table

    chain, sub = scene.chain, scene.substrate
    return ChainModel(
        n=int(chain.n),
        law=law_from_contact_table(scene.contact.table()),
        boundary=chain.boundary,
        damping=float(scene.contact.damping),
        k1=float(sub.k1),
        k3=float(sub.k3),
        gap=float(chain.initial_gap),
        mixture=scene.mixture,
        substrate_damping=float(sub.damping),
        temperature=float(scene.thermal.temperature),
        seed=int(scene.thermal.seed),
        drive=scene.drive,
    )
