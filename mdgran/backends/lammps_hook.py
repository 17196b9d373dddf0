"""The inner loop of the LAMMPS backend's Python contact hook, compiled with numba.

One call of :func:`contact_step` does, for one MPI rank, what ``fix mdgran/chain`` of the C++
plugin (``mdgran/lammps_plugin/fix_mdgran_chain.cpp``) does in ``compute``: the same
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
  :class:`mdgran.contact.ContactTable`, Horner form, or the exact law by Newton) pushes the right
  atom by ``+F`` and the left one by ``-F``; every moving atom also gets ``-k3 u^3`` and the
  linear substrate ``-k u`` (chain.in's ``fix spring/self``, which the backend removes: its
  per-atom ``domain->unmap`` call cost ~5 ns per bead-step; ``k`` is that fix's stiffness,
  :func:`tether_stiffness`, and LAMMPS's force the same number, ``0 + (F - k u)`` against
  ``(0 + F) - k u``, signed zeros included).

A rank evaluates the contacts whose left atom it owns (partner owned or ghost) and those whose
right atom it owns with a ghost left atom, the latter on the ghost's copy of the state: both
ranks of a straddling contact update it from identical positions, so they switch identically.
"""
from __future__ import annotations

import math

import numpy as np
from typing import NamedTuple

from numba import njit

from ..contact_scalar import (hertz_energy, hertz_force, schwarz_energy_libm, schwarz_force_libm,
                              spline_cubic, spline_locate)

# indices of the float parameters (``par``) and of the integer ones (``ipar``)
P_GAP, P_DAMPING, P_K1, P_K3, P_DT, P_DELTA_OFF = 0, 1, 2, 3, 4, 5
P_FC, P_SIGMA, P_TM, P_DELTA_MIN, P_P0 = 6, 7, 8, 9, 10
P_BASE, P_SCALE, P_H, P_TOP, P_DELTA_MAX, P_K1_TETHER = 11, 12, 13, 14, 15, 16
NPAR = 17
I_WALLS, I_NTAGS, I_STRICT, I_HERTZ, I_TABLE, I_MIXED, I_SUB_DAMPED = 0, 1, 2, 3, 4, 5, 6
NIPAR = 7

# error codes of contact_step (returned with the local index or tag they concern)
OK, NON_FINITE, BEYOND_TABLE, PARTNER_MISSING = 0, 1, 2, 3


def tether_stiffness(k1) -> float:
    """The linear substrate's stiffness as ``chain.in``'s ``fix spring/self ${k1} x`` has it:
    LAMMPS substitutes an equal-style variable with 15 significant digits (``%.15g``), so the
    tether's force is ``k u`` with this ``k``, not mdgran's ``k1`` (micro-star: 0.0121069489224951
    against 0.012106948922495099).  The hook applies the tether's force itself, bitwise LAMMPS's
    (and ``fix mdgran/chain`` quantized beside the real ``fix spring/self``); the velocity
    estimate of the damping rate keeps ``k1``, as it always had."""
    return float("%.15g" % float(k1))


def parameters(model, law, table, dt, tether=False):
    """``(par, ipar)`` of :func:`contact_step` for a chain model, its law and (optional) table;
    ``tether``: the hook applies the linear substrate in place of ``fix spring/self``.

    The law's constants are taken from :class:`mdgran.contact.ContactLaw` itself (the same
    Python floats its numpy methods use), ``P_P0`` is ``P(t0)``, the energy's constant."""
    par = np.zeros(NPAR)
    ipar = np.zeros(NIPAR, dtype=np.int64)
    par[P_GAP] = float(model.gap)
    par[P_DAMPING] = float(model.damping)
    par[P_K1] = float(model.k1)
    par[P_K1_TETHER] = tether_stiffness(model.k1) if tether else 0.0
    par[P_K3] = float(model.k3)
    par[P_DT] = float(dt)
    par[P_DELTA_OFF] = float(law.delta_off)
    hertz = law.kind == "hertz"
    if not hertz:
        par[P_FC], par[P_SIGMA], par[P_TM] = law.fc, law.sigma, law.t_min
        par[P_DELTA_MIN], par[P_P0] = law.delta_min, law.energy_zero
    if table is not None:
        par[P_BASE], par[P_SCALE], par[P_H] = table.base, table._scale, table._h
        par[P_TOP] = table.top
        par[P_DELTA_MAX] = table.delta_max
    ipar[I_WALLS] = int(bool(model.walls))
    ipar[I_NTAGS] = model.n + 2 if model.walls else model.n
    ipar[I_STRICT] = int(law.delta_off == 0.0)
    ipar[I_HERTZ] = int(hertz)
    ipar[I_TABLE] = int(table is not None)
    return par, ipar


class HookMix(NamedTuple):
    """A chain of unlike beads, or a damped substrate, in the hook (:func:`mix_parameters`; the
    homogeneous chain's :func:`no_mix` is never read).  Arrays by atom tag (``ntags + 1``
    entries, entry 0 unused; wall atoms have mass 1 and factor 0, never read): bead mass
    ``1 / inv_mass``, substrate factor ``on_site`` (``g``: 1 on the substrate, 0 free) and, for
    the contact whose left atom has the tag, the scales of
    :class:`~mdgran.mixture.Mixture` (``F = scale f(delta / L)``, ``V = scale L V(delta /
    L)``), its opening threshold ``delta_off = L delta_off(fc_k)`` (units p) and its law class
    ``cls``.  Each class has its own row of :func:`parameters` (``cpar``: constants of its law
    and its table) and its table's coefficients (``coef``, every class with the same number of
    nodes).  ``sub_damping``: the substrate damping ``c_s`` (force ``-g c_s v``)."""

    inv_mass: np.ndarray
    on_site: np.ndarray
    scale: np.ndarray
    inv_len: np.ndarray
    length: np.ndarray
    delta_off: np.ndarray
    cls: np.ndarray  # int64
    cpar: np.ndarray  # [classes, NPAR]
    coef: np.ndarray  # [classes, nodes - 1, 4]
    sub_damping: float


def no_mix() -> HookMix:
    """The :class:`HookMix` of the homogeneous chain (empty arrays, never read)."""
    e = np.zeros(1)
    return HookMix(e, e, e, e, e, e, np.zeros(1, dtype=np.int64), np.zeros((1, NPAR)),
                   np.zeros((1, 1, 4)), 0.0)


def mix_parameters(model, ipar, dt, table_points=None, tether=False) -> HookMix:
    """The :class:`HookMix` of a chain model with unlike beads (``model.mixture``) or substrate
    damping, and the flags ``I_MIXED``, ``I_SUB_DAMPED`` set in ``ipar``; ``table_points``:
    nodes of each class's force table (:class:`~mdgran.contact.ContactTable` to ``delta_max =
    100`` in the class's own units), ``None`` for the exact law.  A substrate-damped
    homogeneous chain keeps the homogeneous contacts (only ``sub_damping`` is read)."""
    from ..contact import ContactTable

    mix = model.mixture
    ipar[I_MIXED] = int(mix is not None)
    ipar[I_SUB_DAMPED] = int(float(model.substrate_damping) != 0.0)
    if mix is None:
        return no_mix()._replace(sub_damping=float(model.substrate_damping))
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

    tables = [ContactTable(law, table_points) if table_points else None for law in mix.laws]
    rows = [parameters(model, law, tab, dt, tether)[0] for law, tab in zip(mix.laws, tables)]
    coef = (np.stack([t.f_coef for t in tables]) if table_points
            else np.zeros((len(rows), 1, 4)))
    return HookMix(by_bead(1.0 / mix.mass, 1.0), by_bead(mix.substrate, 0.0),
                   by_contact(mix.force_scale), by_contact(1.0 / mix.length_scale),
                   by_contact(mix.length_scale), by_contact(mix.delta_off),
                   by_contact(mix.law_index, np.int64), np.ascontiguousarray(rows),
                   np.ascontiguousarray(coef), float(model.substrate_damping))


class HookDrive(NamedTuple):
    """The excitations of a driven scene (:mod:`mdgran.drive`) in the hook
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


def drive_parameters(model):
    """The :class:`HookDrive` of a chain model's ``drive``, or None without one."""
    d = model.drive
    if d is None:
        return None
    p, b = d.pulse, d.base
    first_bead = 2 if model.walls else 1  # tag of bead 0
    return HookDrive(0 if p is None else int(p.bead) + first_bead,
                     0.0 if p is None else float(p.amplitude),
                     1.0 if p is None else float(p.duration),
                     0.0 if p is None else float(p.start),
                     0 if b is None else 1, 1.0 if b is None else float(b.step),
                     np.zeros((1, 4)) if b is None
                     else np.ascontiguousarray(b.coef, dtype=float))


# ---- the law ---------------------------------------------------------------------------------

@njit(cache=True)
def spline_force(coef, par, d):
    """``ContactTable.force`` for one value: the spline of :mod:`mdgran.contact_scalar`."""
    i, x = spline_locate(d, par[P_BASE], par[P_SCALE], par[P_TOP], par[P_H])
    return spline_cubic(coef[i, 0], coef[i, 1], coef[i, 2], coef[i, 3], x)


@njit(cache=True)
def exact_force(par, ipar, d):
    """``ContactLaw.force``: ``delta_+^(3/2)`` (Hertz) or ``fc + (t^3 - 3 sigma)^2``
    (:mod:`mdgran.contact_scalar`'s scalar laws)."""
    if ipar[I_HERTZ]:
        return hertz_force(d)
    return schwarz_force_libm(d, par[P_FC], par[P_SIGMA], par[P_TM], par[P_DELTA_MIN],
                              par[P_P0])


@njit(cache=True)
def law_energy(par, ipar, d):
    """``ContactLaw.energy``: ``(2/5) delta_+^(5/2)`` (Hertz) or ``P(t(delta)) - P(t0)``."""
    if ipar[I_HERTZ]:
        return hertz_energy(d)
    return schwarz_energy_libm(d, par[P_FC], par[P_SIGMA], par[P_TM], par[P_DELTA_MIN],
                               par[P_P0])


@njit(cache=True)
def mixed_energy(mix, ipar, jt, d):
    """Energy of the unlike contact whose left atom has tag ``jt`` at compression ``d``:
    ``A L V(d / L)`` (units eta0 p0; :class:`HookMix`), the exact law of its class."""
    c = mix.cls[jt]
    return mix.scale[jt] * mix.length[jt] * law_energy(mix.cpar[c], ipar, d * mix.inv_len[jt])


@njit(inline="always")
def class_spline_force(coef, cpar, c, d):
    """:func:`spline_force` of law class ``c`` (``coef[c]``, ``cpar[c]``), indexing the
    class's rows in place (no view of them per contact)."""
    i, x = spline_locate(d, cpar[c, P_BASE], cpar[c, P_SCALE], cpar[c, P_TOP], cpar[c, P_H])
    return spline_cubic(coef[c, i, 0], coef[c, i, 1], coef[c, i, 2], coef[c, i, 3], x)


@njit(cache=True)
def class_exact_force(cpar, ipar, c, u):
    """:func:`exact_force` of law class ``c`` at own-units compression ``u`` (the view of the
    class's row made here, out of the contact loop)."""
    return exact_force(cpar[c], ipar, u)


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


# ---- one step --------------------------------------------------------------------------------

@njit(cache=True)
def _record(l, opening, delta, step, have_last, par, ipar, dprev, events, nev):
    """Event of contact ``l`` at this step (rare: out of the hot loop): its time by linear
    interpolation of ``delta`` within the step and, on opening, the energy lost."""
    dt = par[P_DT]
    t = step * dt
    prev = dprev[l] if have_last else delta
    thr = par[P_DELTA_OFF] if opening else 0.0
    span = prev - delta
    frac = (prev - thr) / span if span != 0.0 else 1.0
    te = t - dt + min(max(frac, 0.0), 1.0) * dt if step > 0 else t
    events[nev, 0] = l
    events[nev, 1] = 0.0 if opening else 1.0
    events[nev, 2] = te
    events[nev, 3] = law_energy(par, ipar, delta) if opening else 0.0
    return nev + 1


@njit(cache=True)
def _record_mixed(l, opening, delta, step, have_last, par, ipar, dprev, events, nev, mix, jt):
    """:func:`_record` of the unlike contact with left tag ``jt``: its own threshold and lost
    energy ``A L V(delta / L)`` (:class:`HookMix`)."""
    dt = par[P_DT]
    t = step * dt
    prev = dprev[l] if have_last else delta
    thr = mix.delta_off[jt] if opening else 0.0
    span = prev - delta
    frac = (prev - thr) / span if span != 0.0 else 1.0
    te = t - dt + min(max(frac, 0.0), 1.0) * dt if step > 0 else t
    events[nev, 0] = l
    events[nev, 1] = 0.0 if opening else 1.0
    events[nev, 2] = te
    events[nev, 3] = mixed_energy(mix, ipar, jt, delta) if opening else 0.0
    return nev + 1


@njit(inline="always")
def _displacements(tag, x, v, x0, aprev, nall, par, ipar, use_est, tmap, u, w):
    """Displacement ``u = x - x0`` and velocity estimate ``w = v(t + dt/2) + dt/2 a(t)`` of
    every owned and ghost atom; walls (found through ``tmap``) 0 afterwards, so that the loop
    tests nothing per atom."""
    hdt = 0.5 * par[P_DT]
    if use_est:
        for i in range(nall):
            u[i] = x[i, 0] - x0[i]
            w[i] = v[i, 0] + hdt * aprev[i]
    else:
        for i in range(nall):
            u[i] = x[i, 0] - x0[i]
            w[i] = v[i, 0]
    if ipar[I_WALLS]:
        for t in (1, ipar[I_NTAGS]):
            i = find(tag, nall, tmap, t)
            if i >= 0:
                u[i] = 0.0
                w[i] = 0.0


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


@njit(inline="always")
def _contact_forces(pairs, npair, nown, u, w, closed, dprev, coef, par, ipar, step, new_step,
                    have_last, fcon, events):
    """Each listed contact: at a new step its state update (step-quantized: a closed contact
    at or past ``delta_off`` opens, an open one at or past 0 closes; strict inequalities where
    ``delta_off = 0``), then its force ``f(delta) + c d(delta)/dt`` (closed) or 0 into
    ``fcon[left atom]``.  Returns ``(events, sum rate^2 of owned closed contacts, error code,
    its local index, its value)``."""
    gap, damping, delta_off = par[P_GAP], par[P_DAMPING], par[P_DELTA_OFF]
    strict, table = ipar[I_STRICT], ipar[I_TABLE]
    nev = 0
    rate2 = 0.0
    for k in range(npair):
        l = pairs[k, 0]
        r = pairs[k, 1]
        own = k < nown
        delta = u[l] - u[r]
        if gap != 0.0:
            delta = delta - gap
        rate = w[l] - w[r]
        if new_step:
            c = closed[l] != 0
            if strict:
                opening = c and delta < 0.0
                closing = (not c) and delta > 0.0
            else:
                opening = c and delta <= delta_off
                closing = (not c) and delta >= 0.0
            if opening or closing:
                if own:
                    nev = _record(l, opening, delta, step, have_last, par, ipar, dprev, events,
                                  nev)
                closed[l] = 0 if opening else 1
            if own:
                dprev[l] = delta
        if table and delta > par[P_DELTA_MAX]:
            return nev, rate2, BEYOND_TABLE, l, delta
        F = 0.0
        if closed[l] != 0:
            if not math.isfinite(delta):
                F = math.nan
            elif table:
                F = spline_force(coef, par, delta)
            else:
                F = exact_force(par, ipar, delta)
            if damping != 0.0:
                F = F + damping * rate
                if own and new_step:
                    rate2 += rate * rate
        fcon[l] = F
    return nev, rate2, OK, -1, 0.0


@njit(inline="always")
def _contact_forces_mixed(tag, pairs, npair, nown, u, w, closed, dprev, par, ipar, step,
                          new_step, have_last, fcon, events, mix):
    """:func:`_contact_forces` of unlike beads (``I_MIXED``): each contact (left tag ``jt``)
    with its own threshold (strict inequalities where it is 0) and law ``A f(delta / L)``
    (:class:`HookMix`), its table's range checked in its own units (the value returned with
    ``BEYOND_TABLE`` is in those units)."""
    gap, damping = par[P_GAP], par[P_DAMPING]
    table = ipar[I_TABLE]
    # the classes' arrays taken out of the record once: taken in the loop, for a call, they
    # cost 27 ns per contact (42 ns per contact in all, against 15 ns)
    cpar, coef = mix.cpar, mix.coef
    nev = 0
    rate2 = 0.0
    for k in range(npair):
        l = pairs[k, 0]
        r = pairs[k, 1]
        own = k < nown
        delta = u[l] - u[r]
        if gap != 0.0:
            delta = delta - gap
        rate = w[l] - w[r]
        jt = tag[l]
        delta_off = mix.delta_off[jt]
        if new_step:
            c = closed[l] != 0
            if delta_off == 0.0:
                opening = c and delta < 0.0
                closing = (not c) and delta > 0.0
            else:
                opening = c and delta <= delta_off
                closing = (not c) and delta >= 0.0
            if opening or closing:
                if own:
                    nev = _record_mixed(l, opening, delta, step, have_last, par, ipar, dprev,
                                        events, nev, mix, jt)
                closed[l] = 0 if opening else 1
            if own:
                dprev[l] = delta
        c = mix.cls[jt]
        own_delta = delta * mix.inv_len[jt]  # F = A f(delta / L), f the class's law
        if table and own_delta > cpar[c, P_DELTA_MAX]:
            return nev, rate2, BEYOND_TABLE, l, own_delta
        F = 0.0
        if closed[l] != 0:
            if not math.isfinite(delta):
                F = math.nan
            elif table:
                F = mix.scale[jt] * class_spline_force(coef, cpar, c, own_delta)
            else:
                F = mix.scale[jt] * class_exact_force(cpar, ipar, c, own_delta)
            if damping != 0.0:
                F = F + damping * rate
                if own and new_step:
                    rate2 += rate * rate
        fcon[l] = F
    return nev, rate2, OK, -1, 0.0


@njit(inline="always")
def _bead_forces_mixed(tag, nlocal, left, fcon, u, w, par, ipar, new_step, fext, aprev, mix):
    """:func:`_bead_forces` of unlike beads or a damped substrate: the force on owned atom
    ``i`` (bead of mass ``m``, substrate factor ``g``, :class:`HookMix`)
    ``F_left - F_right - g (k3 u^3 + c_s w + k u)`` into ``fext``, with ``w`` the velocity
    estimate of the contact damping, and at a new step ``aprev = (F - g k1 u) / m`` (the
    same force with ``k1`` in place of the tether's ``k``, over the mass).  Returns ``(error
    code, local index, value, substrate damping power g c_s w^2 of the owned beads)``."""
    walls, ntags, mixed = ipar[I_WALLS], ipar[I_NTAGS], ipar[I_MIXED] != 0
    k1, k3, k_tether = par[P_K1], par[P_K3], par[P_K1_TETHER]
    cs = mix.sub_damping
    power = 0.0
    for i in range(nlocal):
        ext = 0.0
        t = tag[i]
        g = 0.0
        if not (walls and (t == 1 or t == ntags)):
            g = mix.on_site[t] if mixed else 1.0
            fl = fcon[left[i]] if left[i] >= 0 else 0.0
            ext = (0.0 - fcon[i]) + fl
            if k3 != 0.0:
                ext = ext - g * (k3 * math.pow(u[i], 3.0))
            if cs != 0.0:
                ext = ext - g * (cs * w[i])
                if new_step:
                    power += g * (cs * w[i] * w[i])
        if not math.isfinite(ext):
            return NON_FINITE, i, ext, power
        fext[i, 0] = ext - g * (k_tether * u[i]) if k_tether != 0.0 else ext
        fext[i, 1] = 0.0
        fext[i, 2] = 0.0
        if new_step:
            a = ext - g * (k1 * u[i]) if k1 != 0.0 else ext
            aprev[i] = a * mix.inv_mass[t] if mixed else a
    return OK, -1, 0.0, power


@njit(inline="always")
def _bead_forces(tag, nlocal, left, fcon, u, par, ipar, new_step, fext, aprev):
    """Forces on owned atoms, ``x'' = F_left - F_right - k3 u^3 - k u`` (``k`` the tether's
    stiffness) into ``fext`` (y, z zeroed), and at a new step ``aprev`` (``- k1 u``, as
    before the hook applied the tether itself).  Returns ``(error code, local index, value)``
    (a non-finite force)."""
    walls, ntags = ipar[I_WALLS], ipar[I_NTAGS]
    k1, k3, k_tether = par[P_K1], par[P_K3], par[P_K1_TETHER]
    for i in range(nlocal):
        ext = 0.0
        t = tag[i]
        if not (walls and (t == 1 or t == ntags)):
            fl = fcon[left[i]] if left[i] >= 0 else 0.0
            ext = (0.0 - fcon[i]) + fl
            if k3 != 0.0:
                ext = ext - k3 * math.pow(u[i], 3.0)
        if not math.isfinite(ext):
            return NON_FINITE, i, ext
        fext[i, 0] = ext - k_tether * u[i] if k_tether != 0.0 else ext
        fext[i, 1] = 0.0
        fext[i, 2] = 0.0
        if new_step:
            aprev[i] = ext - k1 * u[i] if k1 != 0.0 else ext
    return OK, -1, 0.0


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
def _bead_forces_driven(tag, nlocal, left, fcon, u, w, par, ipar, new_step, fext, aprev, mix,
                        drive, ub, vb, fp):
    """:func:`_bead_forces_mixed` of a driven scene: the substrate (and its tether) acts on
    ``y = u - u_b`` and ``w - u_b'`` (``ub``, ``vb``), the pulse's force ``fp`` pushes the atom
    with tag ``drive.pulse_tag``.  Returns ``(error code, local index, value, substrate
    damping power, power of the excitations over the owned beads)``: ``F(t) w_b + u_b'
    sum_i F_sub,i``, ``F_sub,i = -g (k1 y + k3 y^3 + c_s (w - u_b'))``."""
    walls, ntags, mixed = ipar[I_WALLS], ipar[I_NTAGS], ipar[I_MIXED] != 0
    k1, k3, k_tether = par[P_K1], par[P_K3], par[P_K1_TETHER]
    cs = mix.sub_damping
    based = drive.base != 0
    power = 0.0
    work = 0.0
    sub_sum = 0.0
    for i in range(nlocal):
        ext = 0.0
        t = tag[i]
        g = 0.0
        y = 0.0
        if not (walls and (t == 1 or t == ntags)):
            g = mix.on_site[t] if mixed else 1.0
            y = u[i] - ub
            wv = w[i] - vb
            fl = fcon[left[i]] if left[i] >= 0 else 0.0
            ext = (0.0 - fcon[i]) + fl
            fsub = 0.0
            if k3 != 0.0:
                c3 = g * (k3 * math.pow(y, 3.0))
                ext = ext - c3
                fsub = fsub - c3
            if cs != 0.0:
                cd = g * (cs * wv)
                ext = ext - cd
                fsub = fsub - cd
                if new_step:
                    power += g * (cs * wv * wv)
            if t == drive.pulse_tag:
                ext = ext + fp
                if new_step:
                    work += fp * w[i]
            if based and new_step:
                sub_sum += fsub - g * (k1 * y)
        if not math.isfinite(ext):
            return NON_FINITE, i, ext, power, work
        fext[i, 0] = ext - g * (k_tether * y) if k_tether != 0.0 else ext
        fext[i, 1] = 0.0
        fext[i, 2] = 0.0
        if new_step:
            a = ext - g * (k1 * y) if k1 != 0.0 else ext
            aprev[i] = a * mix.inv_mass[t] if mixed else a
    return OK, -1, 0.0, power, work + vb * sub_sum


@njit(cache=True)
def contact_list(tag, nlocal, nall, closed, tmap, ipar, left, fcon, pairs):
    """The map and the contact list of :func:`contact_step`, made anew only when LAMMPS has
    re-neighboured (atoms migrated or re-sorted, ghosts made anew: local indices change) or
    set up a run, and kept in between (rebuilt at every step they cost ~15% of the hook's
    step): ``tmap[tag] = local index`` (:func:`build_map`), the ``(left, right)`` local indices
    of the contacts this rank evaluates in ``pairs`` with the left neighbour of each owned atom
    in ``left`` (:func:`_list_contacts`), and ``fcon`` zeroed where no contact writes it.
    Returns ``(count, owned count, i)``: ``i >= 0`` is an owned atom whose closed contact's
    partner is beyond the ghost cut-off (an error; states change only in a contact's
    evaluation, so a contact not listed keeps its state until the next rebuild)."""
    build_map(tag, nall, tmap)
    return _list_contacts(tag, nlocal, nall, closed, tmap, ipar[I_NTAGS], left, fcon, pairs)


@njit(cache=True)
def contact_step(tag, x, v, fext, nlocal, nall, x0, closed, dprev, aprev, tmap, coef, par,
                 ipar, step, new_step, have_last, u, w, fcon, left, pairs, npair, nown, events):
    """Forces of the contacts and the substrate on this rank's atoms into ``fext`` (x column;
    y, z zeroed) and, at a new step, state switches, ``aprev`` of owned atoms and this rank's
    events.

    ``tmap``, ``pairs[:npair]`` (the first ``nown`` of them this rank's own), ``left`` and the
    zeros of ``fcon`` are those :func:`contact_list` made for the current atoms; ``u, w, fcon``
    (``>= nall``) are scratch; ``events`` (``>= nlocal`` rows) receives ``[local index of the
    left atom, kind (1 close, 0 open), time, energy lost]``.  Returns ``(number of events,
    damping power c sum rate^2 over this rank's contacts, error code, its local index, its
    value)``.

    Three passes, each a function the compiler inlines (``inline="always"``): a call it does
    not inline, with these arrays (numba passes each as a structure of 7 values), cost ~60 ns
    per contact, three times the contact's own work; only an event calls out
    (:func:`_record`)."""
    _displacements(tag, x, v, x0, aprev, nall, par, ipar, step > 0 and have_last, tmap, u, w)
    nev, rate2, code, where, value = _contact_forces(pairs, npair, nown, u, w, closed, dprev,
                                                     coef, par, ipar, step, new_step,
                                                     have_last, fcon, events)
    if code != OK:
        return nev, rate2, code, where, value
    code, where, value = _bead_forces(tag, nlocal, left, fcon, u, par, ipar, new_step, fext,
                                      aprev)
    damping = par[P_DAMPING]
    power = damping * rate2 if damping != 0.0 else 0.0
    if code != OK:
        return nev, rate2, code, where, value
    return nev, power, OK, -1, 0.0


@njit(inline="always")
def _displaced_contact_forces(tag, x, v, nall, x0, closed, dprev, aprev, tmap, coef, par, ipar,
                              step, new_step, have_last, u, w, fcon, pairs, npair, nown,
                              events, mix):
    """The beads' displacements and velocity estimates, then the contact forces: each
    contact's own law for unlike beads (``I_MIXED``), else the chain's; returns ``(number of
    events, sum of squared closing rates, error code, its local index, its value)``."""
    _displacements(tag, x, v, x0, aprev, nall, par, ipar, step > 0 and have_last, tmap, u, w)
    if ipar[I_MIXED] != 0:
        return _contact_forces_mixed(tag, pairs, npair, nown, u, w, closed, dprev, par, ipar,
                                     step, new_step, have_last, fcon, events, mix)
    return _contact_forces(pairs, npair, nown, u, w, closed, dprev, coef, par, ipar, step,
                           new_step, have_last, fcon, events)


@njit(cache=True)
def contact_step_mixed(tag, x, v, fext, nlocal, nall, x0, closed, dprev, aprev, tmap, coef,
                       par, ipar, step, new_step, have_last, u, w, fcon, left, pairs, npair, nown,
                       events, mix):
    """:func:`contact_step` of unlike beads or a damped substrate (flags ``I_MIXED``,
    ``I_SUB_DAMPED``; ``mix`` their :class:`HookMix`): each contact its own law
    (:func:`_contact_forces_mixed`, or the chain's where only the substrate is damped), each
    bead its mass, substrate factor and substrate damping (:func:`_bead_forces_mixed`), whose
    power is added to the returned one.  A function of its own, so that the homogeneous
    chain's :func:`contact_step` is compiled as before."""
    nev, rate2, code, where, value = _displaced_contact_forces(
        tag, x, v, nall, x0, closed, dprev, aprev, tmap, coef, par, ipar, step, new_step,
        have_last, u, w, fcon, pairs, npair, nown, events, mix)
    if code != OK:
        return nev, rate2, code, where, value
    code, where, value, sub_power = _bead_forces_mixed(tag, nlocal, left, fcon, u, w, par,
                                                       ipar, new_step, fext, aprev, mix)
    damping = par[P_DAMPING]
    power = damping * rate2 if damping != 0.0 else 0.0
    if ipar[I_SUB_DAMPED] != 0:
        power = power + sub_power
    if code != OK:
        return nev, rate2, code, where, value
    return nev, power, OK, -1, 0.0


@njit(cache=True)
def contact_step_driven(tag, x, v, fext, nlocal, nall, x0, closed, dprev, aprev, tmap, coef,
                        par, ipar, step, new_step, have_last, u, w, fcon, left, pairs, npair,
                        nown, events, mix, drive):
    """:func:`contact_step_mixed` of a driven scene (``drive``, :class:`HookDrive`): the
    excitations at the time LAMMPS's velocity Verlet evaluates this step's forces, the end of
    its position update ``t = step dt`` (:func:`_bead_forces_driven`).  Returns ``(number of
    events, damping power, power of the excitations over this rank's beads, error code, its
    local index, its value)``.  A function of its own: the undriven ones are compiled as
    before."""
    nev, rate2, code, where, value = _displaced_contact_forces(
        tag, x, v, nall, x0, closed, dprev, aprev, tmap, coef, par, ipar, step, new_step,
        have_last, u, w, fcon, pairs, npair, nown, events, mix)
    if code != OK:
        return nev, rate2, 0.0, code, where, value
    ub, vb, fp = drive_at(drive, step * par[P_DT])
    code, where, value, sub_power, ext_power = _bead_forces_driven(
        tag, nlocal, left, fcon, u, w, par, ipar, new_step, fext, aprev, mix, drive, ub, vb, fp)
    damping = par[P_DAMPING]
    power = damping * rate2 if damping != 0.0 else 0.0
    if ipar[I_SUB_DAMPED] != 0:
        power = power + sub_power
    if code != OK:
        return nev, rate2, 0.0, code, where, value
    return nev, power, ext_power, OK, -1, 0.0


@njit(cache=True)
def contact_energy(tag, nlocal, nall, tmap, closed, u, par, ipar, mix):
    """Energy ``sum V(delta)`` of the closed contacts whose left atom is owned (``u`` as left
    by :func:`contact_step`), the exact law (unlike beads: each contact's own)."""
    e = 0.0
    for i in range(nlocal):
        if closed[i] == 0 or tag[i] >= ipar[I_NTAGS]:
            continue
        j = find(tag, nall, tmap, tag[i] + 1)
        if j < 0:
            continue
        delta = u[i] - u[j]
        if par[P_GAP] != 0.0:
            delta = delta - par[P_GAP]
        if ipar[I_MIXED] != 0:
            e += mixed_energy(mix, ipar, tag[i], delta)
        else:
            e += law_energy(par, ipar, delta)
    return e
