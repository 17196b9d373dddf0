"""The inner loop of the LAMMPS backend's Python contact hook, compiled with numba.

One call of :func:`contact_step` does, for one MPI rank, what ``fix mdgran/chain`` of the C++
plugin (``mdgran/backends/lammps/fix/fix_mdgran_chain.cpp``) does in ``compute``: the same
floating-point operations in the same order, so that the hook and the native contact agree
bitwise in the step-quantized mode they share.  Units: mdgran's nondimensional ones (mass 1,
length p, force eta, time 1/q, energy eta p).

Per-atom data (LAMMPS local index ``i``, owned ``i < nlocal``, ghosts after; ``fix
property/atom`` arrays that migrate with the atoms):

* ``x0[i]``      initial x of the atom: displacement ``u = x - x0`` (walls: ``u = 0``, ``v = 0``);
* ``closed[i]``  state of the contact to the atom's right (tags ``tag``, ``tag + 1``), 1 closed;
* ``dprev[i]``   that contact's compression at the previous step (owner of the left atom only);
* ``aprev[i]``   the atom's acceleration at the previous step (ghosts: exchanged every call).

Per contact ``k`` (left atom tag ``k``, right ``k + 1``; compression
``delta = u_k - u_(k+1) - gap``, rate ``u'_k - u'_(k+1)`` from ``v(t + dt/2) + dt/2 a(t)``):

* at a new step, a closed contact with ``delta <= delta_off`` opens, an open one with
  ``delta >= 0`` closes (strict inequalities where ``delta_off = 0``); the owner of the left
  atom records the event with its time interpolated linearly in ``delta`` within the step
  and, on opening, the energy ``V(delta)`` lost to hysteresis;
* a closed contact's force ``F = f(delta) + c rate`` (``f`` from the spline table of
  :class:`mdgran.model.contact.ContactTable`, Horner form, or the exact law by Newton) pushes the
  right atom by ``+F`` and the left one by ``-F``; every moving atom also gets ``-k3 u^3`` and the
  linear substrate ``-k u`` (chain.in's ``fix spring/self``, which the backend removes: its
  per-atom ``domain->unmap`` call cost ~5 ns per bead-step; ``k`` is that fix's stiffness,
  :func:`tether_stiffness`, and LAMMPS's force the same number, ``0 + (F - k u)`` against
  ``(0 + F) - k u``, signed zeros included).

A rank evaluates the contacts whose left atom it owns (partner owned or ghost) and those whose
right atom it owns with a ghost left atom, the latter on the ghost's copy of the state: both
ranks of a straddling contact update it from identical positions, so they switch identically.

The constants are named records (:class:`HookParams`: :class:`Chain`, :class:`HookMix`,
:class:`HookDrive`) and the step's arguments four more (:class:`Atoms`, :class:`Scratch`,
:class:`Now`, the parameters), as in the fast kernel: they cross into compiled code as plain
tuples (``fast_kernel.plain``; a named tuple costs ~2 us more per call to type) and are named again
inside.  One step is compiled per variant (:func:`get_step`, :data:`VARIANT_FLAGS`): each of
its flags is a constant of the variant, so numba prunes the branches on it before compiling
and the homogeneous chain's step has none of the table's or the exact law's, the unlike
beads' or the drive's code the other variants have.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ...model.contact_scalar import (SchwarzConstants, hertz_energy, hertz_force,
                              schwarz_constants, schwarz_energy_libm, schwarz_force_libm,
                              spline_cubic, spline_locate)
from ..fast_kernel import variant_jit

# error codes of the step (returned with the local index or tag they concern)
OK, NON_FINITE, BEYOND_TABLE, PARTNER_MISSING = 0, 1, 2, 3


def tether_stiffness(k1) -> float:
    """The linear substrate's stiffness as ``chain.in``'s ``fix spring/self ${k1} x`` has it:
    LAMMPS substitutes an equal-style variable with 15 significant digits (``%.15g``), so the
    tether's force is ``k u`` with this ``k``, not mdgran's ``k1`` (micro-star: 0.0121069489224951
    against 0.012106948922495099).  The hook applies the tether's force itself, bitwise LAMMPS's
    (and ``fix mdgran/chain`` quantized beside the real ``fix spring/self``); the velocity
    estimate of the damping rate keeps ``k1``, as it always had."""
    return float("%.15g" % float(k1))


# ---- the records -----------------------------------------------------------------------------
class HookFlags(NamedTuple):
    """Which terms a run's step has (:func:`get_step` compiles a step per its
    :data:`VARIANT_FLAGS`; the step reads the others at run time)."""

    walls: bool  # a fixed wall atom at each end (tags 1 and ntags)
    strict: bool  # delta_off = 0 (DMT, Hertz): strict inequalities in the switching
    hertz: bool  # the Hertz law (else Schwarz)
    table: bool  # the force from the spline table (else the exact law)
    mixed: bool  # unlike beads: each contact its law, each bead its mass (HookMix)
    sub_damped: bool  # substrate damping force -g c_s w on the beads
    driven: bool  # a force pulse or a base motion (HookDrive)


#: The flags a step is compiled for (:func:`get_step`): each selects code of its own.  The
#: others (a test, or which law function is called) the step reads at run time from
#: ``HookParams.flags``, so that chains differing only in them share a compiled step.
VARIANT_FLAGS = ("table", "mixed", "sub_damped", "driven")


class HookTable(NamedTuple):
    """The force table of :class:`mdgran.model.contact.ContactTable` (zeros without one): the cubic
    of interval ``i`` in ``w = sqrt(delta - base)`` (``coef[i]``, highest power first, in ``w -
    w_i``), ``scale = 1 / h`` intervals per unit of ``w``, coordinates clamped to ``top``."""

    coef: np.ndarray  # [nodes - 1, 4]
    base: float  # delta at w = 0 (units p)
    scale: float
    h: float  # node spacing in w
    top: float  # just below the last node's coordinate
    delta_max: float  # the table's end (units p): a compression beyond it stops the run


#: Column of each of :class:`HookTable`'s numbers in ``HookMix.tables`` (a row per law class).
T_BASE, T_SCALE, T_H, T_TOP, T_DELTA_MAX = range(5)


class Chain(NamedTuple):
    """The chain's constants (units of the module's docstring)."""

    gap: float  # initial gap between neighbours (delta = u_k - u_(k+1) - gap)
    damping: float  # contact damping c (force c * rate in closed contacts)
    k1: float  # linear substrate stiffness (the velocity estimate's acceleration)
    k3: float  # cubic substrate stiffness (force -k3 u^3)
    k_tether: float  # the tether's stiffness k (:func:`tether_stiffness`; 0: LAMMPS's fix)
    dt: float  # LAMMPS's time step
    delta_off: float  # the law's opening threshold (units p)
    ntags: int  # atoms (walls included): tags 1 .. ntags
    law: SchwarzConstants  # the law's constants (NO_SCHWARZ for Hertz)
    table: HookTable


class HookMix(NamedTuple):
    """A chain of unlike beads, or a damped substrate, in the hook (:func:`mix_parameters`; the
    homogeneous chain's :func:`no_mix` is never read).  Arrays by atom tag (``ntags + 1``
    entries, entry 0 unused; wall atoms have mass 1 and factor 0, never read): bead mass
    ``1 / inv_mass``, substrate factor ``on_site`` (``g``: 1 on the substrate, 0 free) and, for
    the contact whose left atom has the tag, the scales of
    :class:`~mdgran.model.mixture.Mixture` (``F = scale f(delta / L)``, ``V = scale L V(delta /
    L)``), its opening threshold ``delta_off = L delta_off(fc_k)`` (units p) and its law class
    ``cls``.  Each class has a row of law constants (``laws``, the fields of
    :class:`SchwarzConstants`), of table numbers (``tables``, columns ``T_*``) and its table's
    coefficients (``coef``, every class with the same number of nodes).  ``sub_damping``: the
    substrate damping ``c_s`` (force ``-g c_s v``)."""

    inv_mass: np.ndarray
    on_site: np.ndarray
    scale: np.ndarray
    inv_len: np.ndarray
    length: np.ndarray
    delta_off: np.ndarray
    cls: np.ndarray  # int64
    laws: np.ndarray  # [classes, 5]
    tables: np.ndarray  # [classes, 5]
    coef: np.ndarray  # [classes, nodes - 1, 4]
    sub_damping: float


class HookDrive(NamedTuple):
    """The excitations of a driven scene (:mod:`mdgran.model.drive`) in the hook
    (:func:`drive_parameters`): the half-sine pulse ``amp sin(pi (t - start) / duration)`` on
    the atom with tag ``pulse_tag`` (0: no pulse) and the base motion's cubics ``coef[k]``
    (highest power first, in ``t - k step``; the last row after the samples; ``base`` 0: no
    base motion), as the fast kernel's ``Drive``."""

    pulse_tag: int
    amp: float
    duration: float
    start: float
    base: int
    step: float
    coef: np.ndarray  # [intervals + 1, 4]


class HookParams(NamedTuple):
    """Everything constant of a run: the chain, its unlike beads, its excitations, its
    flags."""

    chain: Chain
    mix: HookMix
    drive: HookDrive
    flags: HookFlags


class Atoms(NamedTuple):
    """This rank's atoms: LAMMPS's per-atom arrays (owned ``[:nlocal]``, ghosts to ``nall``;
    the module's docstring) and fix external's force array ``fext`` (``[nlocal, 3]``)."""

    tag: np.ndarray
    x: np.ndarray  # [nall, 3]
    v: np.ndarray  # [nall, 3]
    fext: np.ndarray
    x0: np.ndarray
    closed: np.ndarray
    dprev: np.ndarray
    aprev: np.ndarray
    nlocal: int
    nall: int


class Scratch(NamedTuple):
    """The step's arrays of its own (``>= nall`` entries): the tag map and contact list of
    :func:`contact_list` (``tmap``, ``left``, ``pairs``, and the zeros of ``fcon``), the
    displacements ``u``, velocity estimates ``w`` and contact forces ``fcon`` of the step, and
    ``events`` (``>= nlocal`` rows: ``[local index of the left atom, kind (1 close, 0 open),
    time, energy lost]``)."""

    tmap: np.ndarray
    u: np.ndarray
    w: np.ndarray
    fcon: np.ndarray
    left: np.ndarray
    pairs: np.ndarray
    events: np.ndarray


class Now(NamedTuple):
    """The call: LAMMPS's step, whether it is a new one (a second call for the same step
    recomputes the forces and changes no state), whether an earlier step was seen, and the
    counts of :func:`contact_list`'s contacts (all, this rank's own first)."""

    step: int
    new_step: bool
    have_last: bool
    npair: int
    nown: int


# ---- the records of a chain model ------------------------------------------------------------
def hook_flags(model, law, table) -> HookFlags:
    """The :class:`HookFlags` of a chain model, its law and (optional) table."""
    return HookFlags(bool(model.walls), bool(law.delta_off == 0.0), law.kind == "hertz",
                     table is not None, model.mixture is not None,
                     float(model.substrate_damping) != 0.0, model.drive is not None)


def hook_table(table) -> HookTable:
    """The :class:`HookTable` of a :class:`~mdgran.model.contact.ContactTable` (None: zeros)."""
    if table is None:
        return HookTable(np.zeros((1, 4)), 0.0, 0.0, 0.0, 0.0, 0.0)
    return HookTable(table.f_coef, float(table.base), float(table._scale), float(table._h),
                     float(table.top), float(table.delta_max))


def chain_constants(model, law, table, dt, tether=False) -> Chain:
    """The :class:`Chain` of a chain model, its law and (optional) table; ``tether``: the hook
    applies the linear substrate in place of ``fix spring/self``.  The law's constants are
    :class:`mdgran.model.contact.ContactLaw`'s own (the Python floats its numpy methods use)."""
    return Chain(float(model.gap), float(model.damping), float(model.k1), float(model.k3),
                 tether_stiffness(model.k1) if tether else 0.0, float(dt),
                 float(law.delta_off), model.n + 2 if model.walls else model.n,
                 schwarz_constants(law), hook_table(table))


def no_mix(sub_damping=0.0) -> HookMix:
    """The :class:`HookMix` of the homogeneous chain (empty arrays, never read)."""
    e = np.zeros(1)
    return HookMix(e, e, e, e, e, e, np.zeros(1, dtype=np.int64), np.zeros((1, 5)),
                   np.zeros((1, 5)), np.zeros((1, 1, 4)), float(sub_damping))


def mix_parameters(model, table_points=None) -> HookMix:
    """The :class:`HookMix` of a chain model with unlike beads (``model.mixture``) or substrate
    damping; ``table_points``: nodes of each class's force table
    (:class:`~mdgran.model.contact.ContactTable` to ``delta_max = 100`` in the class's own units),
    ``None`` for the exact law.  A substrate-damped homogeneous chain keeps the homogeneous
    contacts (only ``sub_damping`` is read)."""
    from ...model.contact import ContactTable

    mix = model.mixture
    if mix is None:
        return no_mix(model.substrate_damping)
    walls = bool(model.walls)
    ntags = model.n + 2 if walls else model.n
    first_bead = 2 if walls else 1  # tag of bead 0

    def by_bead(values, wall):
        out = np.full(ntags + 1, float(wall))
        out[first_bead:first_bead + model.n] = values
        return out

    def by_contact(values, dtype=float):
        out = np.zeros(ntags + 1, dtype=dtype)
        out[1:1 + len(values)] = values  # contact j (0-based) has left tag j + 1
        return out

    tables = [hook_table(ContactTable(law, table_points) if table_points else None)
              for law in mix.laws]
    return HookMix(by_bead(1.0 / mix.mass, 1.0), by_bead(mix.substrate, 0.0),
                   by_contact(mix.force_scale), by_contact(1.0 / mix.length_scale),
                   by_contact(mix.length_scale), by_contact(mix.delta_off),
                   by_contact(mix.law_index, np.int64),
                   np.array([schwarz_constants(law) for law in mix.laws], dtype=float),
                   np.array([t[1:] for t in tables], dtype=float),
                   np.ascontiguousarray(np.stack([t.coef for t in tables])),
                   float(model.substrate_damping))


def no_drive() -> HookDrive:
    """The :class:`HookDrive` of an undriven scene (never read)."""
    return HookDrive(0, 0.0, 1.0, 0.0, 0, 1.0, np.zeros((1, 4)))


def drive_parameters(model) -> HookDrive:
    """The :class:`HookDrive` of a chain model's ``drive`` (:func:`no_drive` without one)."""
    d = model.drive
    if d is None:
        return no_drive()
    p, b = d.pulse, d.base
    first_bead = 2 if model.walls else 1  # tag of bead 0
    return HookDrive(0 if p is None else int(p.bead) + first_bead,
                     0.0 if p is None else float(p.amplitude),
                     1.0 if p is None else float(p.duration),
                     0.0 if p is None else float(p.start),
                     0 if b is None else 1, 1.0 if b is None else float(b.step),
                     np.zeros((1, 4)) if b is None
                     else np.ascontiguousarray(b.coef, dtype=float))


def hook_parameters(model, law, table, dt, tether=False) -> HookParams:
    """The :class:`HookParams` of a chain model, its law and (optional) table (each class of
    unlike beads gets a table of as many nodes)."""
    points = table.n if table is not None else None
    return HookParams(chain_constants(model, law, table, dt, tether),
                      mix_parameters(model, points), drive_parameters(model),
                      hook_flags(model, law, table))


@njit(inline="always")
def named_params(p):
    """:class:`HookParams` from ``plain(params)``."""
    c = p[0]
    return HookParams(Chain(c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7],
                            SchwarzConstants(*c[8]), HookTable(*c[9])),
                      HookMix(*p[1]), HookDrive(*p[2]), HookFlags(*p[3]))


# ---- the law ---------------------------------------------------------------------------------

@njit(cache=True)
def spline_force(table, d):
    """``ContactTable.force`` for one value: the spline of :mod:`mdgran.model.contact_scalar`."""
    i, x = spline_locate(d, table.base, table.scale, table.top, table.h)
    c = table.coef
    return spline_cubic(c[i, 0], c[i, 1], c[i, 2], c[i, 3], x)


@njit(cache=True)
def exact_force(hertz, law, d):
    """``ContactLaw.force``: ``delta_+^(3/2)`` (Hertz) or ``fc + (t^3 - 3 sigma)^2``
    (:mod:`mdgran.model.contact_scalar`'s scalar laws; ``law``: :class:`SchwarzConstants`)."""
    if hertz:
        return hertz_force(d)
    return schwarz_force_libm(d, law.fc, law.sigma, law.t_min, law.delta_min, law.energy_zero)


@njit(cache=True)
def law_energy(hertz, law, d):
    """``ContactLaw.energy``: ``(2/5) delta_+^(5/2)`` (Hertz) or ``P(t(delta)) - P(t0)``."""
    if hertz:
        return hertz_energy(d)
    return schwarz_energy_libm(d, law.fc, law.sigma, law.t_min, law.delta_min,
                               law.energy_zero)


@njit(inline="always")
def class_law(laws, c):
    """The :class:`SchwarzConstants` of law class ``c`` (row ``c`` of ``HookMix.laws``)."""
    return SchwarzConstants(laws[c, 0], laws[c, 1], laws[c, 2], laws[c, 3], laws[c, 4])


@njit(cache=True)
def mixed_energy(mix, hertz, jt, d):
    """Energy of the unlike contact whose left atom has tag ``jt`` at compression ``d``:
    ``A L V(d / L)`` (units eta0 p0; :class:`HookMix`), the exact law of its class."""
    law = class_law(mix.laws, mix.cls[jt])
    return mix.scale[jt] * mix.length[jt] * law_energy(hertz, law, d * mix.inv_len[jt])


@njit(inline="always")
def class_force(table, hertz, tables, coef, laws, c, d):
    """Force of law class ``c`` at own-units compression ``d``: its spline (``coef[c]``,
    ``tables[c]``, indexed in place: no view of them per contact) or its exact law."""
    if table:
        i, x = spline_locate(d, tables[c, T_BASE], tables[c, T_SCALE], tables[c, T_TOP],
                             tables[c, T_H])
        return spline_cubic(coef[c, i, 0], coef[c, i, 1], coef[c, i, 2], coef[c, i, 3], x)
    return exact_force(hertz, class_law(laws, c), d)


@njit(inline="always")
def lost_energy(mixed, hertz, params, jt, d):
    """Energy ``V(d)`` a contact (left tag ``jt``) loses on opening at compression ``d``: the
    chain's law, or the unlike contact's own (:func:`mixed_energy`)."""
    if mixed:
        return mixed_energy(params.mix, hertz, jt, d)
    return law_energy(hertz, params.chain.law, d)


# ---- atoms by tag ----------------------------------------------------------------------------

@njit(cache=True)
def build_map(tag, nall, tmap):
    """``tmap[tag] = local index`` for owned and ghost atoms (owned ones win).  Entries of
    atoms no longer here are left stale: :func:`find` checks them against ``tag``."""
    for i in range(nall - 1, -1, -1):
        tmap[tag[i]] = i


@njit(cache=True)
def find(tag, nall, tmap, t):
    """Local index of the atom with tag ``t``, -1 if this rank does not see it."""
    if t < 1 or t >= tmap.shape[0]:
        return -1
    i = tmap[t]
    if 0 <= i < nall and tag[i] == t:
        return i
    return -1


@njit(cache=True)
def boundary_atoms(tag, nlocal, nall, tmap, out):
    """Owned atoms next (by tag) to a ghost atom: their ``aprev`` is needed on the ghost's
    rank.  Local indices in ``out[:count]`` (an atom between two ghosts twice); returns
    ``count``.  Loops over the ghosts only (a few per rank)."""
    n = 0
    for g in range(nlocal, nall):
        for t in (tag[g] - 1, tag[g] + 1):
            i = find(tag, nall, tmap, t)
            if 0 <= i < nlocal:
                out[n] = i
                n += 1
    return n


@njit(cache=True)
def pack_aprev(tag, aprev, idx, count, buf):
    for k in range(count):
        buf[2 * k] = tag[idx[k]]
        buf[2 * k + 1] = aprev[idx[k]]


@njit(cache=True)
def unpack_aprev(tag, nlocal, nall, tmap, aprev, buf):
    """Ghost copies of ``aprev`` from the ``(tag, aprev)`` pairs every rank sent."""
    for k in range(buf.shape[0] // 2):
        j = find(tag, nall, tmap, int(buf[2 * k]))
        if j >= nlocal:
            aprev[j] = buf[2 * k + 1]


@njit(inline="always")
def _list_contacts(tag, nlocal, nall, closed, tmap, ntags, left, fcon, pairs):
    """The contacts this rank evaluates, as ``(left, right)`` local indices in ``pairs``: first
    those whose left atom is owned (their events and damping power are this rank's), noting
    the left neighbour of each owned right atom in ``left``; then those whose left atom is a
    ghost and right atom owned (updated on the ghost's copy of the state).  Returns ``(count,
    owned count, i)``: ``i >= 0`` is an owned atom whose closed contact's partner is beyond
    the ghost cut-off (an error)."""
    nmap = tmap.shape[0]
    for i in range(nlocal):
        left[i] = -1
    npair = 0
    for i in range(nlocal):
        fcon[i] = 0.0
        t = tag[i] + 1
        if t > ntags:  # last atom: no contact to its right
            continue
        j = tmap[t] if t < nmap else -1
        if j < 0 or j >= nall or tag[j] != t:  # beyond the ghost cut-off: only if open
            if closed[i] != 0:
                return npair, npair, i
            continue
        if j < nlocal:
            left[j] = i
        pairs[npair, 0] = i
        pairs[npair, 1] = j
        npair += 1
    nown = npair
    for i in range(nlocal):
        if left[i] >= 0 or tag[i] <= 1:
            continue
        t = tag[i] - 1
        l = tmap[t]
        if l < 0 or l >= nall or tag[l] != t:
            l = -1  # beyond the cut-off, so open (its owner checks)
        left[i] = l
        if l >= nlocal:
            fcon[l] = 0.0
            pairs[npair, 0] = l
            pairs[npair, 1] = i
            npair += 1
    return npair, nown, -1


@njit(cache=True)
def contact_list(atoms, scratch, ntags):
    """The map and the contact list of the step (``atoms``, ``scratch``: plain
    :class:`Atoms`, :class:`Scratch`), made anew only when LAMMPS has re-neighboured (atoms
    migrated or re-sorted, ghosts made anew: local indices change) or set up a run, and kept
    in between (rebuilt at every step they cost ~15% of the hook's step): ``tmap[tag] = local
    index`` (:func:`build_map`), the ``(left, right)`` local indices of the contacts this rank
    evaluates in ``pairs`` with the left neighbour of each owned atom in ``left``
    (:func:`_list_contacts`), and ``fcon`` zeroed where no contact writes it.  Returns
    ``(count, owned count, i)``: ``i >= 0`` is an owned atom whose closed contact's partner is
    beyond the ghost cut-off (an error; states change only in a contact's evaluation, so a
    contact not listed keeps its state until the next rebuild)."""
    a, s = Atoms(*atoms), Scratch(*scratch)
    build_map(a.tag, a.nall, s.tmap)
    return _list_contacts(a.tag, a.nlocal, a.nall, a.closed, s.tmap, ntags, s.left, s.fcon,
                          s.pairs)


# ---- one step --------------------------------------------------------------------------------

@njit(cache=True)
def _record(l, opening, delta, delta_off, energy, step, have_last, dt, dprev, events, nev):
    """Event of contact ``l`` at this step (rare: out of the hot loop): its time by linear
    interpolation of ``delta`` within the step (to ``delta_off`` on opening, 0 on closing)
    and, on opening, the energy lost."""
    t = step * dt
    prev = dprev[l] if have_last else delta
    thr = delta_off if opening else 0.0
    span = prev - delta
    frac = (prev - thr) / span if span != 0.0 else 1.0
    te = t - dt + min(max(frac, 0.0), 1.0) * dt if step > 0 else t
    events[nev, 0] = l
    events[nev, 1] = 0.0 if opening else 1.0
    events[nev, 2] = te
    events[nev, 3] = energy
    return nev + 1


@njit(inline="always")
def _displacements(walls, a, s, now, chain):
    """Displacement ``u = x - x0`` and velocity estimate ``w = v(t + dt/2) + dt/2 a(t)`` of
    every owned and ghost atom; walls (found through ``tmap``) 0 afterwards, so that the loop
    tests nothing per atom."""
    x, v, x0, aprev, u, w = a.x, a.v, a.x0, a.aprev, s.u, s.w
    hdt = 0.5 * chain.dt
    if now.step > 0 and now.have_last:
        for i in range(a.nall):
            u[i] = x[i, 0] - x0[i]
            w[i] = v[i, 0] + hdt * aprev[i]
    else:
        for i in range(a.nall):
            u[i] = x[i, 0] - x0[i]
            w[i] = v[i, 0]
    if walls:
        for t in (1, chain.ntags):
            i = find(a.tag, a.nall, s.tmap, t)
            if i >= 0:
                u[i] = 0.0
                w[i] = 0.0


@njit(inline="always")
def _switches(c, delta, delta_off, strict):
    """``(opening, closing)`` of a contact in state ``c`` (closed) at compression ``delta``: a
    closed contact at or past ``delta_off`` opens, an open one at or past 0 closes (strict
    inequalities where ``delta_off = 0``)."""
    if strict:
        return c and delta < 0.0, (not c) and delta > 0.0
    return c and delta <= delta_off, (not c) and delta >= 0.0


@njit(inline="always")
def _update_state(strict, hertz, mixed, params, a, s, now, l, jt, own, delta, doff, nev):
    """At a new step, contact ``l``'s state update (:func:`_switches`; unlike beads: strict
    where its own threshold ``doff`` is 0) and, on the owner of its left atom (``own``), its
    event (:func:`_record`, the energy lost :func:`lost_energy`) and ``dprev``.  Returns the
    number of events."""
    closed, dprev = a.closed, a.dprev
    cl = closed[l] != 0
    if mixed:
        opening, closing = _switches(cl, delta, doff, doff == 0.0)
    else:
        opening, closing = _switches(cl, delta, doff, strict)
    if opening or closing:
        if own:
            e = lost_energy(mixed, hertz, params, jt, delta) if opening else 0.0
            nev = _record(l, opening, delta, doff, e, now.step, now.have_last,
                          params.chain.dt, dprev, s.events, nev)
        closed[l] = 0 if opening else 1
    if own:
        dprev[l] = delta
    return nev


@njit(inline="always")
def _contact_forces(strict, hertz, table, mixed, a, s, now, params):
    """Each listed contact: at a new step its state update (step-quantized,
    :func:`_update_state`), then its force ``f(delta) + c d(delta)/dt`` (closed) or 0 into
    ``fcon[left atom]``; unlike beads (``mixed``): each contact (left tag ``jt``) its
    own threshold and law ``A f(delta / L)`` (:class:`HookMix`), its table's range checked
    in its own units (the value returned with ``BEYOND_TABLE`` is in those units).  Returns
    ``(events, sum rate^2 of owned closed contacts, error code, its local index, its
    value)``."""
    ch, mix = params.chain, params.mix
    gap, damping, delta_off, delta_max = ch.gap, ch.damping, ch.delta_off, ch.table.delta_max
    # arrays taken out of the records once: taken in the loop, for a call, the classes' ones
    # cost 27 ns per contact (42 ns per contact in all, against 15 ns)
    tag, closed = a.tag, a.closed
    u, w, fcon, pairs = s.u, s.w, s.fcon, s.pairs
    laws, tables, coef = mix.laws, mix.tables, mix.coef
    new_step, nown = now.new_step, now.nown
    nev = 0
    rate2 = 0.0
    for k in range(now.npair):
        l = pairs[k, 0]
        r = pairs[k, 1]
        own = k < nown
        delta = u[l] - u[r]
        if gap != 0.0:
            delta = delta - gap
        rate = w[l] - w[r]
        jt = tag[l] if mixed else 0
        doff = mix.delta_off[jt] if mixed else delta_off
        if new_step:
            nev = _update_state(strict, hertz, mixed, params, a, s, now, l, jt, own, delta, doff,
                                nev)
        c = mix.cls[jt] if mixed else 0
        d = delta * mix.inv_len[jt] if mixed else delta
        if table and d > (tables[c, T_DELTA_MAX] if mixed else delta_max):
            return nev, rate2, BEYOND_TABLE, l, d
        F = 0.0
        if closed[l] != 0:
            if not math.isfinite(delta):
                F = math.nan
            elif mixed:
                F = mix.scale[jt] * class_force(table, hertz, tables, coef, laws, c, d)
            elif table:
                F = spline_force(ch.table, delta)
            else:
                F = exact_force(hertz, ch.law, delta)
            if damping != 0.0:
                F = F + damping * rate
                if own and new_step:
                    rate2 += rate * rate
        fcon[l] = F
    return nev, rate2, OK, -1, 0.0


@njit(cache=True)
def drive_at(drive, t):
    """``(u_b, u_b', F)`` at time t: the base's displacement and velocity, the pulse's force
    (0 where the scene has none); the operations of the fast kernel's ``drive_at``."""
    ub, vb, fp = 0.0, 0.0, 0.0
    if drive.pulse_tag != 0:
        s = (t - drive.start) / drive.duration
        if 0.0 <= s <= 1.0:
            fp = drive.amp * math.sin(math.pi * s)
    if drive.base != 0:
        k = min(math.floor(max(t, 0.0) / drive.step), drive.coef.shape[0] - 1)
        y = t - k * drive.step
        c = drive.coef[int(k)]
        ub = ((c[0] * y + c[1]) * y + c[2]) * y + c[3]
        vb = (3.0 * c[0] * y + 2.0 * c[1]) * y + c[2]
    return ub, vb, fp


@njit(inline="always")
def _bead_forces(walls, mixed, sub_damped, driven, a, s, now, params, ub, vb, fp):
    """Force on owned atom ``i`` (substrate factor ``g``, :class:`HookMix`; 1 without unlike
    beads) ``F_left - F_right - g (k3 y^3 + c_s (w - u_b') + k y)`` (``y = u - u_b``; ``k``
    the tether's stiffness; ``c_s`` with ``sub_damped``; the base ``u_b``, ``u_b'`` and the
    pulse's force ``fp`` on the atom with tag ``drive.pulse_tag`` with ``driven``) into
    ``fext`` (y, z zeroed), and at a new step ``aprev = (F - g k1 y) / m`` (the same force
    with ``k1`` in place of the tether's ``k``, over the bead's mass).  Returns ``(error
    code, local index, value, substrate damping power g c_s (w - u_b')^2, power of the
    excitations F(t) w_b + u_b' sum_i F_sub,i)`` over the owned beads, with ``F_sub,i = -g
    (k1 y + k3 y^3 + c_s (w - u_b'))``."""
    ch, mix, drive = params.chain, params.mix, params.drive
    tag, fext, aprev, u, w, fcon, left = a.tag, a.fext, a.aprev, s.u, s.w, s.fcon, s.left
    ntags, new_step = ch.ntags, now.new_step
    k1, k3, k_tether, cs = ch.k1, ch.k3, ch.k_tether, mix.sub_damping
    power = 0.0
    work = 0.0
    sub_sum = 0.0
    for i in range(a.nlocal):
        ext = 0.0
        t = tag[i]
        g = 0.0
        y = 0.0
        if not (walls and (t == 1 or t == ntags)):
            g = mix.on_site[t] if mixed else 1.0
            y = u[i] - ub if driven else u[i]
            wv = w[i] - vb if driven else w[i]
            fl = fcon[left[i]] if left[i] >= 0 else 0.0
            ext = (0.0 - fcon[i]) + fl
            fsub = 0.0
            if k3 != 0.0:
                c3 = g * (k3 * math.pow(y, 3.0))
                ext = ext - c3
                fsub = fsub - c3
            if sub_damped:
                cd = g * (cs * wv)
                ext = ext - cd
                fsub = fsub - cd
                if new_step:
                    power += g * (cs * wv * wv)
            if driven:
                if t == drive.pulse_tag:
                    ext = ext + fp
                    if new_step:
                        work += fp * w[i]
                if drive.base != 0 and new_step:
                    sub_sum += fsub - g * (k1 * y)
        if not math.isfinite(ext):
            return NON_FINITE, i, ext, power, 0.0
        fext[i, 0] = ext - g * (k_tether * y) if k_tether != 0.0 else ext
        fext[i, 1] = 0.0
        fext[i, 2] = 0.0
        if new_step:
            acc = ext - g * (k1 * y) if k1 != 0.0 else ext
            aprev[i] = acc * mix.inv_mass[t] if mixed else acc
    return OK, -1, 0.0, power, work + vb * sub_sum if driven else 0.0


_STEPS: dict = {}


def get_step(flags: HookFlags):
    """The compiled step of the variant of ``flags`` (its :data:`VARIANT_FLAGS`; compiled on
    first use, then cached on disk by numba), ``step(atoms, scratch, now, params) -> (number
    of events, damping power, power of the excitations, error code, its local index, its
    value)``, the records as plain tuples (``fast_kernel.plain``).

    Forces of the contacts and the substrate on this rank's atoms into ``fext`` (x column; y,
    z zeroed) and, at a new step, state switches, ``aprev`` of owned atoms and this rank's
    events: the displacements (:func:`_displacements`), the contacts
    (:func:`_contact_forces`), the beads (:func:`_bead_forces`, with the excitations at the
    time LAMMPS's velocity Verlet evaluates this step's forces, the end of its position update
    ``t = step dt``); the damping power is ``c sum rate^2`` over this rank's contacts plus the
    substrate's, the excitations' over its beads.  ``tmap``, ``pairs[:npair]``, ``left`` and
    the zeros of ``fcon`` are those :func:`contact_list` made for the current atoms."""
    variant = tuple(bool(getattr(flags, name)) for name in VARIANT_FLAGS)
    if variant not in _STEPS:
        _STEPS[variant] = _make_step(variant)
    return _STEPS[variant]


def _make_step(variant):
    """:func:`get_step`'s step.  Each flag of the variant (:data:`VARIANT_FLAGS`; the others
    from ``HookParams.flags``) is a constant of the closure: numba prunes the branches on it
    before typing (a flag taken out of a tuple, ``flags[k]``, it does not: every branch was
    compiled, and the homogeneous step took 5.3 s to compile instead of 2).
    The three passes are functions the compiler inlines (``inline="always"``): a call it does
    not inline, with these arrays (numba passes each as a structure of 7 values), cost ~60 ns
    per contact, three times the contact's own work; only an event calls out
    (:func:`_record`).  The step's body is the closure's own: numba copies an inlined
    function's IR block by block, each copy with all its variables, and inlining the whole
    step into the closure took 2 s of its compile.  It allocates nothing and the caller holds
    every array for the call, so it runs without numba's reference counting (``_nrt=False``,
    as the fast kernel's loop)."""
    table, mixed, sub_damped, driven = variant
    tag = "".join("1" if f else "0" for f in variant)  # the variant's own name (variant_jit)

    @variant_jit(tag, cache=True, _nrt=False)
    def contact_step(atoms, scratch, now, params):
        a, s, n, p = Atoms(*atoms), Scratch(*scratch), Now(*now), named_params(params)
        walls, strict, hertz = p.flags.walls, p.flags.strict, p.flags.hertz  # at run time
        _displacements(walls, a, s, n, p.chain)
        nev, rate2, code, where, value = _contact_forces(strict, hertz, table, mixed, a, s, n,
                                                         p)
        if code != OK:
            return nev, rate2, 0.0, code, where, value
        ub, vb, fp = 0.0, 0.0, 0.0
        if driven:
            ub, vb, fp = drive_at(p.drive, n.step * p.chain.dt)
        code, where, value, sub_power, ext_power = _bead_forces(
            walls, mixed, sub_damped, driven, a, s, n, p, ub, vb, fp)
        damping = p.chain.damping
        power = damping * rate2 if damping != 0.0 else 0.0
        if sub_damped:
            power = power + sub_power
        if code != OK:
            return nev, rate2, 0.0, code, where, value
        return nev, power, ext_power, OK, -1, 0.0

    return contact_step


@njit(cache=True)
def contact_energy(atoms, scratch, params):
    """Energy ``sum V(delta)`` of the closed contacts whose left atom is owned (``u`` as left
    by the step), the exact law (unlike beads: each contact's own); ``atoms``, ``scratch``,
    ``params``: plain :class:`Atoms`, :class:`Scratch`, :class:`HookParams` (its flags read at
    run time)."""
    a, s, p = Atoms(*atoms), Scratch(*scratch), named_params(params)
    tag, ch, flags = a.tag, p.chain, p.flags
    e = 0.0
    for i in range(a.nlocal):
        if a.closed[i] == 0 or tag[i] >= ch.ntags:
            continue
        j = find(tag, a.nall, s.tmap, tag[i] + 1)
        if j < 0:
            continue
        delta = s.u[i] - s.u[j]
        if ch.gap != 0.0:
            delta = delta - ch.gap
        if flags.mixed:
            e += mixed_energy(p.mix, flags.hertz, tag[i], delta)
        else:
            e += law_energy(flags.hertz, ch.law, delta)
    return e
