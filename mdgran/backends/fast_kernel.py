"""Hot loop of the fast backend: velocity Verlet on plain numpy arrays, compiled with numba.

Units and equations are those of :mod:`mdgran.model.chain` (bead mass 1, nondimensional)::

    x_i'' = a_i = F_i - F_(i+1) - k1 x_i - k3 x_i^3,
    F_k   = closed_k * (f(delta_k) + c * d delta_k/dt),   delta_k = x_left - x_right - gap

**One step** of length ``h`` from ``(x0, v0, a0)`` (velocity Verlet; the damping force makes
``a`` depend on ``v``, so the end velocity is predicted first)::

    v_half = v0 + h/2 a0,   x1 = x0 + h v_half            (= x0 + h v0 + h^2/2 a0)
    v_est  = v_half + h/2 a0                               (= v(t+h) + O(h^2))
    a1     = a(x1, v_est)                                  (damping rate from v_est)
    v1     = v_half + h/2 a1
    D_visc += h/2 (P0 + P1),   P = c * sum_closed (d delta/dt)^2 from v_est

The prediction error ``O(h^2)`` in the damping force enters ``v1`` multiplied by ``h``, so the
method stays second order.  Everything for one step is one fused pass over the beads (each
bead is read and written once); two copies of ``(x, v, a)`` alternate as old and new buffers.

**Events** (``locate = True``).  Inside a step every bead moves on the parabola
``x0 + s v0 + s^2/2 a0``, so each contact's event function ``g`` (``delta - delta_off`` when
closed, ``-delta`` when open; positive inside the state) is exactly the quadratic
``g(s) = g0 + s g0' + s^2/2 g0''`` along the step.  The pass flags a contact when its end value
could hide a crossing (``g1 < 0`` or ``g1 < h/2 g'(h)``: a dip below zero inside the step
implies this, so the filter never misses one).  A contact that switches at ``s`` in the step
changes the force on its two beads only, so the event is handled where it happens
(:func:`local_events`): the beads of the flagged contacts whose quadratic has a root in the
step form *event windows* (windows within two beads of each other joined), and each window is
stepped again alone from the step's start: a pass over its beads to the earliest root ``te``
of its contacts, where they switch (``D_hysteresis += V(delta(te))`` on opening, exact law,
as the reference does), then the rest of the step in the new state (repeated for further
events).  The beads next to a window (its neighbours) move on their parabolas meanwhile; at
the end their accelerations and velocities are finished again with the window's end force,
and their velocities get the window's impulse on the contact they share (so that the
contact's impulses on its two beads are equal and opposite: momentum is kept).  A window
whose edge contact switches inside the step, or is closed in the mean-force band, takes in
that neighbour and is stepped again; one that reaches a window already stepped is joined with
it, and the step's windows are stepped again (rare).  The damping power's trapezoid is the
whole step's, with each window's own sub-steps in place of its share.  The cost is a few
passes over a few beads per event, whatever the chain's length.  A window's result depends
on its beads and contacts alone (it starts from the step's counters and chatter guard, and
keeps its events apart), so the windows are stepped in :data:`LANES` lanes, on the threads
in a threaded variant, and merged in order along the chain (events, hysteresis losses,
chatter guard): the result does not depend on the thread count.  A contact that sits on
its switching point after a switch (DMT, Hertz: ``delta_off = 0``) is switched back at once
if it moves outward (the reference's settle rule); more than ``MAX_SWITCHES`` switches of
one contact at one instant stop the run (chatter).

``locate = False``: plain step-quantized Verlet, as a fixed-step MD code: after each step a
closed contact with ``delta <= delta_off`` opens and an open one with ``delta >= 0`` closes
(strict inequalities when ``delta_off = 0``), before the force at the new positions is
computed; the event time is interpolated linearly in the step (as the LAMMPS backend does).

**Force** ``f(delta)``: the table of :class:`mdgran.model.contact.ContactTable`, nodes uniform in
``w = sqrt(delta - base)`` (``base = delta_min``, 0 for Hertz) with a cubic spline in ``w``
between them (:class:`ForceTable`), or the exact law (``exact = True``: Newton inversion,
slower).  Hertz always uses the exact ``delta^(3/2)`` (cheaper than the table, and free of
the spline's round-off force near ``delta = 0``, which made resting contacts ahead of the
pulse flicker).  Energies at events use the exact law.  The exact law is the scalar one of
:mod:`mdgran.model.contact_scalar`.

Terms switched off (walls, damping, k1, k3, event location, exact law) are compile-time
constants of :func:`get_kernel` (:class:`Flags`, passed down as literal booleans): each
combination is a separately compiled variant (cached on disk by numba), so an absent term
costs nothing in the loop.

**Segments and threads.**  The pass is cut into segments of :data:`SEGMENT` contacts
(:class:`Segments`, :func:`segment_pass`).  Each segment finishes the beads inside it and
hands back its damping power, the forces of its first and last contacts, the contacts it
flagged and its step-quantized switches; :func:`merge_segments` then finishes the bead at
each edge from those two forces (the same operations) and joins the rest in segment order.
A threaded variant (``Flags.threaded``) runs the segments on numba's threads
(``prange``), each thread taking the next few from a shared counter (:data:`KernelState`'s
``sharing``, :mod:`mdgran.backends.atomic`) until none is left; since the cut depends on the
chain alone, the result does not depend on the thread count or on which thread ran which
segment, bitwise.  Against one segment (a chain of at most SEGMENT contacts is one),
only the damping power is summed in another order: positions, velocities, states and events
are bitwise the same, ``D_viscous`` agrees to round-off.  The event windows are stepped in
lanes after the pass, on the threads too when a step has many (:func:`local_events`).

**Records** (numba named tuples and one structured record, so that each function takes a
few arguments that say what they are): :class:`Flags` (the variant), :class:`Params` (the
run's constants, with the law's :class:`~mdgran.model.contact_scalar.SchwarzConstants` and the
:class:`ForceTable`), :class:`Beads` (``x, v, a``), :class:`KernelState` (contact states,
the :data:`COUNTERS` record, the :class:`EventLog`, scratch lists), all updated in place, and
:class:`FrameBlock` (the states at the ends of the frames one call of the loop runs).

**Indices.** The bead and contact indices of the pass are unsigned (``np.uint64``): numba
emits no negative-index wraparound code for them (it does for signed ones it cannot prove
non-negative).  No fastmath and no FMA contraction: results are bitwise those of the
operations as written.
"""
from __future__ import annotations

import hashlib
import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..model.contact_scalar import (SchwarzConstants, branch_t, law_energy, law_force,
                                    schwarz_mean_force_of_branch,
                                    spline_cubic)
from .atomic import fetch_add
from .prefetch import prefetch_row
from .simd import branch_t8

# status codes (counters.status)
OK, OUT_OF_TABLE, CHATTER, TOO_MANY_SUBSTEPS, EVENTS_FULL, EVENT_OVERFLOW = 0, 1, 2, 3, 4, 5
STEP_BUDGET = 6  # a call stopped inside a frame at its step budget (counters.budget)

MAX_SWITCHES = 4  # switches of one contact at one instant before the run stops (chatter)
MAX_SUBSTEPS = 10000  # event splits in one step
SIMULTANEOUS = 1e-12  # events within SIMULTANEOUS * (1 + t) of the earliest switch with it
#: The state invariant (as the reference's): no contact beyond its switching point by more
#: than this (units of p) after a step; one found beyond it switches at once.
STATE_TOL = 1e-12
FLAG_CAP = 64  # flagged contacts remembered per pass (beyond: all contacts are scanned)
CHAT_CAP = 64
#: Closed contacts with delta below delta_min + SING_BAND (mdgran.model.contact_scalar) get the
#: mean-force kick (Schwarz, displacement rule); see `segment_pass`.
#: Contacts per segment of a pass (:class:`Segments`): the unit the threads share.  It depends
#: on nothing but this constant, so a run's result does not depend on the thread count; a
#: chain of at most SEGMENT contacts is one segment, and its pass is the serial one.
SEGMENT = 2048
#: a threaded pass runs its segments on the threads only when the step runs at least this
#: many (the activity front of a pulse in a long chain is one or two): waking the threads
#: costs ~10 us a step on idle cores and milliseconds when another process holds one
#: (1e6 beads, one segment in motion: 18 s against 0.18 s over 3000 steps)
PARALLEL_SEGMENTS = 4


#: Unsigned offsets into the flat coefficient arrays (an int64 added to a uint64 is a float64).
U1, U2, U3, U4 = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4)


# ---- the kernel's records -----------------------------------------------------------------
class Flags(NamedTuple):
    """Which terms a compiled variant has (compile-time constants of :func:`get_kernel`)."""

    walls: bool  # a fixed wall at each end (contacts 0..n; else 1..n-1 between the beads)
    damped: bool  # unilateral damping force c * d delta/dt in closed contacts
    k1_on: bool  # linear substrate force -k1 x
    k3_on: bool  # cubic substrate force -k3 x^3
    locate: bool  # events located inside the step (else switched at the step's end)
    exact: bool  # the exact law instead of the force table
    hertz: bool  # the Hertz law (else Schwarz)
    mixed: bool = False  # unlike beads: per-bead masses, per-contact laws (:class:`Mix`)
    sub_damped: bool = False  # substrate damping force -c_s v on the beads
    off_substrate: bool = False  # (mixed) some bead is off the substrate: Mix.on_site is read
    threaded: bool = False  # the segments of a pass run on several threads (same results)
    pulse: bool = False  # a force pulse on one bead (:class:`Drive`)
    base: bool = False  # a base motion under the substrate (:class:`Drive`)


#: Index of each flag in a variant's flags (``flags[PULSE]``): inside a variant they are a
#: tuple of literal booleans, so that each function taking them is compiled for the variant.
(WALLS, DAMPED, K1_ON, K3_ON, LOCATE, EXACT, HERTZ, MIXED, SUB_DAMPED, OFF_SUBSTRATE, THREADED,
 PULSE, BASE) = range(len(Flags._fields))


class ForceTable(NamedTuple):
    """The force table of :class:`mdgran.model.contact.ContactTable`: the cubic of interval ``i``
    in ``w = sqrt(delta - base)`` has coefficients ``coef[4 i: 4 i + 4]`` (highest power
    first; one flat array, so that the index needs no stride from memory) in
    ``w - w_i``; ``w / step`` is the interval coordinate, ``scale = 1 / step``."""

    coef: np.ndarray  # [4 (n - 1)]
    base: float  # delta at w = 0 (delta_min; 0 for Hertz)
    scale: float  # 1 / step
    last: float  # n - 1: table coordinates at and beyond it are outside the table
    step: float  # node spacing in w


class Mix(NamedTuple):
    """A chain of unlike beads (:class:`mdgran.model.mixture.Mixture`; empty arrays otherwise).

    Contact ``j`` is of kind ``kind[j]``: row ``k`` of ``pair`` (``pair[k * NPAIR + P_*]``, a
    flat array: its index needs no stride from memory) and a law class ``pair_class[k]``.  It
    has its class's law in its own units, scaled as ``F = A f(delta / L)``,
    ``V = A L V(delta / L)``.  Each class has a force table (its cubics in ``coef``, from the
    row's ``P_FIRST`` on, as :class:`ForceTable`'s; its ``base``, ``scale``, ``step`` copied
    into each row of the class) and its Schwarz constants (a row of ``laws``,
    :class:`~mdgran.model.contact_scalar.SchwarzConstants`' fields).  A row also holds the mass and
    substrate factor of the contact's left bead, which the pass finishes at that contact, so
    that the pass reads one small array per contact (``kind``) and a few rows, which stay in
    cache, where per-contact arrays of every constant would be five streams from memory
    (a chain whose contacts all differ has as many rows as contacts).  Bead ``i`` has mass
    ``1 / inv_mass[i]`` and substrate factor ``on_site[i]`` (0 or 1): the rare paths read
    those."""

    inv_mass: np.ndarray  # [n]
    on_site: np.ndarray  # [n]
    kind: np.ndarray  # [m] uint32: the contact's row of pair
    pair: np.ndarray  # [kinds * NPAIR]
    pair_class: np.ndarray  # [kinds] uint32: the kind's law class
    laws: np.ndarray  # [classes, 5]
    coef: np.ndarray  # [classes * 4 (nodes - 1)]


#: The fields of a row of :attr:`Mix.pair`: the force scale A, 1 / L, L, the opening
#: threshold L delta_off (units p), the class table's base, scale and step, the class's
#: own delta_min + SING_BAND (or -inf: no mean-force kick), the index in Mix.coef of the
#: class's first cubic coefficient, and the left bead's 1 / m and substrate factor (1 and 1
#: for a wall).
PAIR_FIELDS = ("force_scale", "inv_len", "length", "delta_off", "base", "scale", "step",
               "below", "first_coef", "left_inv_mass", "left_on_site")
(P_SCALE, P_INV_LEN, P_LEN, P_OFF, P_BASE, P_WSCALE, P_STEP, P_BELOW, P_FIRST, P_INV_MASS,
 P_ON_SITE) = range(len(PAIR_FIELDS))
NPAIR = len(PAIR_FIELDS)


def no_mix() -> Mix:
    """The :class:`Mix` of a homogeneous chain: empty arrays (never read)."""
    e = np.zeros(0)
    return Mix(e, e, np.zeros(0, dtype=np.uint32), e, np.zeros(0, dtype=np.uint32),
               np.zeros((0, 5)), e)


class Drive(NamedTuple):
    """The excitations of :mod:`mdgran.model.drive` (flags[PULSE], flags[BASE]): the half-sine pulse
    ``amp sin(pi (t - start) / duration)`` on bead ``bead``; the base motion's cubics
    ``coef[k]`` (highest power first, in ``t - k step``; the last row after the samples)."""

    bead: int
    amp: float
    duration: float
    start: float
    step: float
    coef: np.ndarray  # [intervals + 1, 4]


def no_drive() -> Drive:
    """The :class:`Drive` of a scene without excitations (never read)."""
    return Drive(0, 0.0, 1.0, 0.0, 1.0, np.zeros((1, 4)))


def drive_record(drive) -> Drive:
    """The kernel's :class:`Drive` of a :class:`mdgran.model.drive.Drive` (or None)."""
    if drive is None:
        return no_drive()
    p, b = drive.pulse, drive.base
    out = no_drive()
    if p is not None:
        out = out._replace(bead=int(p.bead), amp=float(p.amplitude),
                           duration=float(p.duration), start=float(p.start))
    if b is not None:
        out = out._replace(step=float(b.step), coef=np.ascontiguousarray(b.coef, dtype=float))
    return out


class Params(NamedTuple):
    """The constants of one run (units of :mod:`mdgran.model.chain`)."""

    gap: float  # delta = x_left - x_right - gap
    damping: float  # c
    k1: float
    k3: float
    delta_off: float  # a closed contact opens when delta falls to it
    delta_max: float  # compressions at or beyond it are outside the table (error)
    mean_force_below: float  # closed contacts with delta below it get the mean-force kick
    law: SchwarzConstants
    table: ForceTable
    mix: Mix  # unlike beads (flags[MIXED]); no_mix() otherwise
    sub_damping: float  # c_s (flags[SUB_DAMPED])
    drive: Drive  # force pulse and base motion (flags[PULSE], flags[BASE]); no_drive() otherwise


class Beads(NamedTuple):
    """Positions, velocities and accelerations of the beads: 1-D ``[n]`` arrays for one
    state, or ``[2, n]`` for the two alternating buffers (:func:`buffer`)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray


class EventLog(NamedTuple):
    """Events of the run so far: time, contact index, kind (1 close, 0 open), hysteresis loss
    (``V(delta)`` on opening, 0 on closing); the count is ``counters.events``."""

    time: np.ndarray
    contact: np.ndarray
    kind: np.ndarray
    loss: np.ndarray


# columns of Segments.real, Segments.ints and Segments.kick
K_FV_LEFT, K_FV_RIGHT, K_T0, K_T1, K_DUE = range(5)
R_POWER, R_FIRST, R_FIRST_KICK, R_LAST, R_LAST_KICK = 0, 1, 2, 3, 4
I_FLAGGED, I_SWITCHES, I_STATUS, I_BAD = 0, 1, 2, 3


class Segments(NamedTuple):
    """The pass's parallel unit: contacts ``s * size .. min((s + 1) * size, m) - 1`` form
    segment ``s`` (:func:`segment_pass`), which writes what it found into row ``s`` of these
    arrays; :func:`merge_segments` then combines them in segment order.  ``size`` depends on
    the chain alone (:data:`SEGMENT`), never on the thread count.  Few arrays, because each
    one a pass touches costs numba's reference counting once per pass."""

    size: int  # contacts per segment
    count: int  # segments
    real: np.ndarray  # [count, 5] damping power; (F, Fv) of the first and of the last contact
    ints: np.ndarray  # [count, 4] int64 flagged contacts, step-quantized switches, status
    #                   (OK or OUT_OF_TABLE: the segment's last failure), its contact
    flag: np.ndarray  # [count, FLAG_CAP] int64 the first flagged contacts of each segment
    ev_real: np.ndarray  # [m, 2] switch k of segment s at row s * size + k: time, loss
    ev_contact: np.ndarray  # [m] int64 its contact
    kicked: np.ndarray  # [m] int64 contact k of segment s in the mean-force band at row
    #                     s * size + k (:func:`apply_kicks`)
    kick: np.ndarray  # [m, 5] the pass's Fv of the contacts left and right of kicked[k], and
    #                   its branch parameters at the step's start and end (K_* columns;
    #                   :func:`kick_branches`)
    branch: np.ndarray  # [m, 2] contact j's last branch inversion (u, branch_t(u)); NaN: none
    #                     (:func:`memo_mean_force`)


#: Columns of KernelState.windows, one row per event window of a step: its first and last
#: bead; whether it is to be stepped (again); the sides it must grow by (1 left, 2 right);
#: the lane that stepped it, its first event there and its count; its sub-steps; its status
#: and the contact that concerns.
(W_LO, W_HI, W_TODO, W_GROW, W_LANE, W_FIRST, W_EVENTS, W_SUBSTEPS, W_STATUS,
 W_BAD) = range(10)
#: Columns of KernelState.window_sums: what a window adds to the step's trapezoid of the
#: damping power, to its end power and to the excitations' work; the time of its failure.
S_VISCOUS, S_POWER, S_WORK, S_BAD_TIME = range(4)
#: Event windows are stepped in LANES lanes, lane g taking windows g * count // LANES ..
#: (g + 1) * count // LANES - 1 of the step's count: a number that depends on nothing else, so
#: that which windows share a lane's event buffer does not depend on the thread count.
LANES = 8
#: a threaded variant steps its lanes on the threads when a step has at least this many
#: windows (waking them costs ~10 us)
PARALLEL_WINDOWS = 16
#: a threaded pass's threads take its segments from a shared counter this many claims a
#: thread at a time (:func:`segment_chunk`)
CLAIMS_PER_THREAD = 64
#: Entries of KernelState.sharing: the next segment and the next lane to take, the threads.
SHARE_SEGMENT, SHARE_LANE, SHARE_THREADS = range(3)


class Lanes(NamedTuple):
    """The event windows' lanes (:func:`step_lane`): what stepping a window changes besides
    the beads and its contacts' states, one row per lane."""

    counters: np.ndarray  # [LANES, 1] COUNTERS: a window's own (status, events, chatter guard)
    log: EventLog  # [LANES, capacity] each lane's events of the step, window after window
    switching: np.ndarray  # [LANES, FLAG_CAP] contacts switching at the located event time
    chatter: np.ndarray  # [LANES, CHAT_CAP, 2] the chatter guard's (contact, switches)


class Lane(NamedTuple):
    """One lane's view (:class:`Lanes` row, and what the windows share) as the switching
    functions take it, in place of a :class:`KernelState`."""

    closed: np.ndarray  # [m] the chain's contact states (a window switches its own)
    counters: np.ndarray  # [1] COUNTERS
    log: EventLog
    switching: np.ndarray  # [FLAG_CAP]
    chatter: np.ndarray  # [CHAT_CAP, 2]
    memo: np.ndarray  # Segments.branch (a window writes its own contacts' rows)
    local: Beads  # [2, n] the sub-steps of the windows (each its own beads)


class KernelState(NamedTuple):
    """Everything the kernel updates in place besides the beads."""

    closed: np.ndarray  # [m] bool: contact states
    counters: np.ndarray  # one record of dtype COUNTERS
    log: EventLog
    chatter: np.ndarray  # [CHAT_CAP, 2] (contact, switches) at the current instant
    seg: Segments  # the pass's segments
    local: Beads  # [2, n] the sub-steps of an event window (:func:`resolve_window`)
    windows: np.ndarray  # [m, 10] int64 the event windows of a step (columns W_*)
    window_sums: np.ndarray  # [m, 4] their sums (columns S_*)
    lanes: Lanes
    sharing: np.ndarray  # [3] int64 the threads' work: the next segment and the next lane
    #                      a thread takes (:func:`~mdgran.backends.atomic.fetch_add`), and
    #                      the number of threads (SHARE_* columns)


class FrameBlock(NamedTuple):
    """The states at the ends of consecutive frames, written by the loop (:func:`get_kernel`):
    row ``k`` is frame ``first + k``.  ``sums[k]`` = ``(D_viscous, D_hysteresis, P, W,
    P_ext)`` (the excitations' work and its rate),
    ``counts[k]`` = ``(counters.events, counters.substeps, counters.windows,
    counters.widened, counters.bead_steps, counters.front_lo, counters.front_hi)`` at that
    frame."""

    x: np.ndarray  # [K, n]
    v: np.ndarray  # [K, n]
    a: np.ndarray  # [K, n]
    closed: np.ndarray  # [K, m] bool
    sums: np.ndarray  # [K, 5]
    counts: np.ndarray  # [K, 7] int64


def new_block(frames: int, n: int, n_contacts: int, rest_x=None) -> FrameBlock:
    """A :class:`FrameBlock` of ``frames`` rows whose beads are at rest (the loop fills in the
    others): ``x = rest_x`` (default 0), ``v = a = 0``.  Zeros cost nothing until written
    (:func:`mdgran.rest_blocks.lazy_zeros`): a long chain's frames cost the beads that
    moved."""
    from ..rest_blocks import lazy_zeros

    x = lazy_zeros((frames, n))
    if rest_x is not None:
        x[:] = rest_x
    return FrameBlock(x, lazy_zeros((frames, n)), lazy_zeros((frames, n)),
                      np.empty((frames, n_contacts), dtype=np.bool_), np.empty((frames, 5)),
                      np.empty((frames, 7), dtype=np.int64))


#: The kernel's counters and running sums (one record).
COUNTERS = np.dtype([
    ("current", np.int64),  # which buffer of Beads holds the current state
    ("step", np.int64),  # steps done
    ("events", np.int64),  # events in the log
    ("status", np.int64),  # OK or an error code
    ("bad_contact", np.int64),  # the contact an error concerns
    ("flagged", np.int64),  # contacts the last pass flagged (may exceed FLAG_CAP)
    ("chatter_count", np.int64),  # rows of KernelState.chatter in use
    ("substeps", np.int64),  # event splits so far
    ("windows", np.int64),  # event windows stepped so far (:func:`local_events`)
    ("widened", np.int64),  # of which widened or joined with another while stepped
    ("front_lo", np.int64),  # first bead of the activity front (-1: not known yet, step all)
    ("front_hi", np.int64),  # its last bead (front_lo > front_hi: every bead at rest)
    ("seg_first", np.int64),  # the segments the step's pass runs (:func:`step_range`)
    ("seg_last", np.int64),
    ("pass_lo", np.int64),  # and the contacts it runs in them: pass_lo .. pass_hi - 1
    ("pass_hi", np.int64),
    ("bead_steps", np.int64),  # beads stepped so far (passes over the segments run)
    ("budget", np.int64),  # steps one call of the loop may take (0: no limit)
    ("d_viscous", np.float64),  # D_viscous
    ("d_hysteresis", np.float64),  # D_hysteresis
    ("power", np.float64),  # damping power at the current state
    ("bad_time", np.float64),  # the time an error concerns
    ("chatter_time", np.float64),  # the instant KernelState.chatter counts switches at
    ("work", np.float64),  # W, the excitations' work (mdgran.model.drive)
    ("ext_power", np.float64),  # its rate at the current state
])


def new_segments(n_contacts: int, size: int | None = None) -> Segments:
    """The :class:`Segments` of a chain of ``n_contacts`` contacts, ``size`` (default
    :data:`SEGMENT`) contacts each (at least one segment)."""
    size = int(size or SEGMENT)
    count = max(1, -(-n_contacts // size))
    return Segments(size, count, np.zeros((count, 5)), np.zeros((count, 4), dtype=np.int64),
                    np.zeros((count, FLAG_CAP), dtype=np.int64), np.zeros((n_contacts, 2)),
                    np.zeros(n_contacts, dtype=np.int64), np.zeros(n_contacts, dtype=np.int64),
                    np.zeros((n_contacts, 5)), np.full((n_contacts, 2), np.nan))


def new_state(n: int, n_contacts: int, event_capacity: int,
              segment: int | None = None) -> KernelState:
    """A zeroed :class:`KernelState` of a chain of ``n`` beads and ``n_contacts`` contacts (no
    chatter instant yet), its pass cut into segments of ``segment`` contacts (default
    :data:`SEGMENT`)."""
    counters = np.zeros(1, dtype=COUNTERS)
    counters["chatter_time"] = -1.0
    counters["front_lo"] = -1
    seg = new_segments(n_contacts, segment)
    local = Beads(np.zeros((2, n)), np.zeros((2, n)), np.zeros((2, n)))
    rows = max(n_contacts, 1)
    return KernelState(np.zeros(n_contacts, dtype=np.bool_), counters, new_log(event_capacity),
                       np.zeros((CHAT_CAP, 2), dtype=np.int64), seg, local,
                       np.zeros((rows, 10), dtype=np.int64), np.zeros((rows, 4)),
                       new_lanes(event_capacity // 2), np.zeros(3, dtype=np.int64))


def new_log(capacity: int, lanes: tuple = ()) -> EventLog:
    """An empty :class:`EventLog` of ``capacity`` events (``lanes + (capacity,)`` arrays)."""
    shape = (*lanes, capacity)
    return EventLog(np.zeros(shape), np.zeros(shape, dtype=np.int64),
                    np.zeros(shape, dtype=np.int8), np.zeros(shape))


def new_lanes(capacity: int) -> Lanes:
    """:class:`Lanes` whose event buffers hold ``capacity`` events each (the pages are touched
    only as far as a step's events reach)."""
    return Lanes(np.zeros((LANES, 1), dtype=COUNTERS), new_log(capacity, (LANES,)),
                 np.zeros((LANES, FLAG_CAP), dtype=np.int64),
                 np.zeros((LANES, CHAT_CAP, 2), dtype=np.int64))


# ---- geometry and the force of a closed contact -------------------------------------------
# A variant's flags reach the hot functions as a tuple of literal booleans (``flags[PULSE]``),
# so each is compiled for the variant and the branches on them fold away.  The pass
# (segment_pass) and the joins (merge_segments, switch_all) are functions of their own; the
# small helpers and the loop around the pass are inlined (numba IR).  Inlining the pass too
# made numba copy its IR at every level: a variant took 30 s to compile instead of 13.  The
# rare-path functions take the flags at run time (:func:`at_run_time`): compiled once.
@njit(inline="always")
def beads_of(walls, j):
    """Left and right bead of contact j (walls: j-1, j, the walls being -1 and n)."""
    if walls:
        return j - 1, j
    return j, j + 1


@njit(inline="always")
def at_run_time(flags):
    """The variant's flags as a :class:`Flags` of plain booleans: the rare-path functions
    (switching, settling, the excitations' power, segment edges) take them so, and are
    compiled once for every variant."""
    return Flags(*flags)


@njit(inline="always")
def across(walls, x, j):
    """x_left - x_right of contact j (walls at x = 0)."""
    n = x.shape[0]
    left, right = beads_of(walls, j)
    xl = x[left] if left >= 0 else 0.0
    xr = x[right] if right < n else 0.0
    return xl - xr


@njit(inline="always")
def buffer(beads, i):
    """Buffer i (0 or 1) of the two alternating copies of the beads."""
    return Beads(beads.x[i], beads.v[i], beads.a[i])


@njit(inline="always")
def spline(table, w):
    """Table force at table coordinate w = sqrt(delta - base) * scale (0 <= w < last): the
    cubic of interval i = floor(w)."""
    c = table.coef
    i = int(w)
    x = (w - i) * table.step
    k = U4 * np.uint64(i)  # unsigned: no negative-index wraparound code on c[k]
    return spline_cubic(c[k], c[k + U1], c[k + U2], c[k + U3], x)


@njit(inline="always")
def contact_force(exact, hertz, d, params):
    """(f, ok): force f(delta) of a closed contact (table or exact law; Hertz always exact:
    delta^(3/2) is cheaper than the table, and free of the spline's round-off force at 0);
    ok is False beyond the table or for a non-finite delta."""
    if exact or hertz:
        if not (d < params.delta_max):
            return 0.0, False
        return law_force(d, hertz, params.law), True
    u = d - params.table.base
    if u < 0.0:
        u = 0.0
    w = math.sqrt(u) * params.table.scale
    if not (w < params.table.last):
        return 0.0, False
    return spline(params.table, w), True


# ---- unlike beads: each contact's own law (flags[MIXED]; Mix) --------------------------------
@njit(inline="always")
def class_law(mix, k):
    """The Schwarz constants of the law class of contact kind k."""
    c = mix.pair_class[k]
    return SchwarzConstants(mix.laws[c, 0], mix.laws[c, 1], mix.laws[c, 2], mix.laws[c, 3],
                            mix.laws[c, 4])


@njit(inline="always")
def row_of(k):
    """Index in Mix.pair of the first field of contact kind k's row (unsigned)."""
    return np.uint64(NPAIR) * np.uint64(k)


@njit(inline="always")
def pair_at(params, k, field):
    """Field ``field`` (P_*) of contact kind k's row."""
    return params.mix.pair[row_of(k) + np.uint64(field)]


@njit(inline="always")
def class_spline(params, k, u):
    """(f, ok): table force of contact kind k at its own compression u (as
    :func:`contact_force`: beyond the table (0, False)).  The early return is a branch: with
    ``ok`` a value instead, LLVM made the pass's failure test a select whose result it kept
    on the stack, a dependence through memory from one contact to the next (9.7 -> 9.0 ns a
    bead-step on a dimer chain of 1e4 beads).  (The variants compile without reference
    counting, whose cost once made this function avoid early returns.)"""
    u = u - pair_at(params, k, P_BASE)
    if u < 0.0:
        u = 0.0
    w = math.sqrt(u) * pair_at(params, k, P_WSCALE)
    if not (w < params.table.last):
        return 0.0, False
    i = int(w)
    x = (w - i) * pair_at(params, k, P_STEP)
    n = np.uint64(pair_at(params, k, P_FIRST)) + U4 * np.uint64(i)
    c = params.mix.coef
    return spline_cubic(c[n], c[n + U1], c[n + U2], c[n + U3], x), True


@njit(inline="always")
def force_at(flags, params, j, d):
    """(f, ok): force of closed contact j at compression d: the one law, or contact j's
    (``A f(d / L)``)."""
    if not flags[MIXED]:
        return contact_force(flags[EXACT], flags[HERTZ], d, params)
    k = params.mix.kind[j]
    u = d * pair_at(params, k, P_INV_LEN)
    if flags[EXACT] or flags[HERTZ]:
        ok = u < params.delta_max
        f = law_force(u, flags[HERTZ], class_law(params.mix, k)) if ok else 0.0
        return pair_at(params, k, P_SCALE) * f, ok
    f, ok = class_spline(params, k, u)
    return pair_at(params, k, P_SCALE) * f, ok


@njit(inline="always")
def energy_at(flags, params, j, d):
    """Exact energy of closed contact j at compression d (``A L V(d / L)`` when mixed)."""
    if not flags[MIXED]:
        return law_energy(d, flags[HERTZ], params.law)
    k = params.mix.kind[j]
    e = law_energy(d * pair_at(params, k, P_INV_LEN), flags[HERTZ], class_law(params.mix, k))
    return pair_at(params, k, P_SCALE) * pair_at(params, k, P_LEN) * e


@njit(inline="always")
def delta_off_at(params, j):
    """Opening threshold of contact j (per contact kind for unlike beads)."""
    if params.mix.kind.shape[0] > 0:
        return pair_at(params, params.mix.kind[j], P_OFF)
    return params.delta_off


@njit(inline="always")
def memo_branch(memo, j, u, law):
    """``branch_t(u)`` of contact j's law, taken from ``memo[j]`` when it holds u (the same
    number: the inversion is a function of u alone)."""
    if memo[j, 0] == u:
        return memo[j, 1]
    return branch_t(u, law.sigma, law.t_min, law.delta_min)


@njit(inline="always")
def kick_law(flags, params, j):
    """(Schwarz constants, 1 / L, A) of contact j's law: its class's and its scales
    (``A f(delta / L)``) for unlike beads; the one law and (1, 1) otherwise."""
    if flags[MIXED]:
        k = params.mix.kind[j]
        return (class_law(params.mix, k), pair_at(params, k, P_INV_LEN),
                pair_at(params, k, P_SCALE))
    return params.law, 1.0, 1.0


@njit(inline="always")
def memo_mean_force(flags, params, j, d0, d1, t0, t1, memo, keep):
    """Mean force of contact j over [d0, d1]
    (:func:`~mdgran.model.contact_scalar.schwarz_mean_force`, scaled for unlike beads), its
    start's branch inversion (seven Newton steps) taken from ``memo`` when the last one of
    contact j was there (the same number): a kicked contact's end of one step is its start of
    the next.  ``t0``, ``t1``: the ends' branch parameters if the caller has them
    (:func:`kick_branches`), else NaN.  Its end's goes into ``memo[j]`` if ``keep``.  A
    contact's memo is written by the one segment that owns it, or by the one event window
    that holds it; a window's neighbour bead reads its other contact's memo without writing
    it (two windows may share that contact).  Whether it is written changes no result, only
    the time."""
    law, il, scale = kick_law(flags, params, j)
    u0, u1 = d0 * il, d1 * il
    if t0 != t0:
        t0 = memo_branch(memo, j, u0, law)
    if t1 != t1:
        t1 = branch_t(u1, law.sigma, law.t_min, law.delta_min)
    if keep:
        memo[j, 0], memo[j, 1] = u1, t1
    f = schwarz_mean_force_of_branch(t0, t1, law)
    return scale * f if flags[MIXED] else f


@njit(inline="always")
def bead_factors(flags, params, i):
    """(1 / m, substrate factor) of bead i: (1, 1) in a homogeneous chain."""
    if flags[MIXED]:
        return params.mix.inv_mass[i], params.mix.on_site[i]
    return 1.0, 1.0


@njit(inline="always")
def fail(counters, status, j):
    """Stop the run: error ``status`` about contact ``j``."""
    counters.status = status
    counters.bad_contact = j


@njit(inline="always")
def record_event(ks, j, t, kind, loss):
    """Append event (t, contact index j, kind 1 close / 0 open, hysteresis loss) to the
    log."""
    counters = ks.counters[0]
    k = counters.events
    if k >= ks.log.time.shape[0]:
        fail(counters, EVENT_OVERFLOW, j)
        return
    ks.log.time[k] = t
    ks.log.contact[k] = j
    ks.log.kind[k] = kind
    ks.log.loss[k] = loss
    counters.events = k + 1


# ---- one Verlet pass ------------------------------------------------------------------------
@njit(inline="always")
def quantized_switch(flags, params, j, d, doff, x_old, h, t0, closed):
    """locate = False: switch contact j, whose end-of-step compression d is past its
    switching point ``doff`` (closed) or 0 (open); returns ``(j, time, loss)``: the event
    time interpolated linearly between the step's ends, and the hysteresis loss ``V(d)`` on
    opening (0 on closing)."""
    thr = doff if closed[j] else 0.0
    d0 = across(flags[WALLS], x_old, np.int64(j)) - params.gap
    span = d0 - d
    frac = min(max((d0 - thr) / span if span != 0.0 else 1.0, 0.0), 1.0)
    loss = 0.0
    if closed[j]:
        loss = energy_at(flags, params, j, d)
    closed[j] = not closed[j]
    return np.int64(j), t0 + frac * h, loss


@njit(inline="always")
def drive_at(flags, params, t):
    """``(u_b, u_b', F)`` at time t: the base's displacement and velocity, the pulse's force
    (each 0 when the variant has none; :mod:`mdgran.model.drive`)."""
    ub, vb, fp = 0.0, 0.0, 0.0
    d = params.drive
    if flags[PULSE]:
        s = (t - d.start) / d.duration
        if 0.0 <= s <= 1.0:
            fp = d.amp * math.sin(math.pi * s)
    if flags[BASE]:
        k = min(math.floor(max(t, 0.0) / d.step), d.coef.shape[0] - 1)
        u = t - k * d.step
        c = d.coef[np.uint64(k)]
        ub = ((c[0] * u + c[1]) * u + c[2]) * u + c[3]
        vb = (3.0 * c[0] * u + 2.0 * c[1]) * u + c[2]
    return ub, vb, fp


@njit(cache=True)
def external_power(flags, params, beads, t, lo, hi):
    """Rate of the excitations' work on beads lo .. hi at time t in state ``beads``: ``F(t)
    v_b + u_b'(t) sum_i F_sub,i`` (:mod:`mdgran.model.drive`)."""
    ub, vb, fp = drive_at(flags, params, t)
    p = 0.0
    if flags[PULSE] and lo <= params.drive.bead <= hi:
        p += fp * beads.v[params.drive.bead]
    if flags[BASE]:
        total = 0.0
        for i in range(lo, hi + 1):
            y = beads.x[i] - ub
            f = -(params.k1 * y + params.k3 * y * y * y
                  + params.sub_damping * (beads.v[i] - vb))
            total += params.mix.on_site[i] * f if flags[OFF_SUBSTRATE] else f
        p += vb * total
    return p


@njit(cache=True, inline="always")
def bead_accelerations(f, fv, x, ve, im, g, flags, params, now):
    """A bead's acceleration from its net contact force ``f`` (and ``fv``, the same with the
    mean-force kick near snap-off) plus the substrate terms the scene switches on (unlike
    beads: the substrate times the bead's factor ``g``, all times its ``im = 1 / m``; see
    :func:`bead_factors`; both read only when flags[MIXED]); ``ve`` the bead's
    velocity estimate at the step's end, for the substrate damping ``-c_s v``.  ``now`` =
    :func:`drive_at` at the step's end: the substrate acts on ``x - u_b`` and ``ve - u_b'``
    (the pulse is added after the pass, :func:`push_pulsed_bead`)."""
    if flags[BASE]:
        x = x - now[0]
        ve = ve - now[1]
    if flags[SUB_DAMPED]:
        fd = params.sub_damping * ve
        if flags[OFF_SUBSTRATE]:
            fd *= g
        f -= fd
        fv -= fd
    if flags[MIXED]:
        if not flags[OFF_SUBSTRATE]:
            g = 1.0
        if flags[K1_ON]:
            f -= g * (params.k1 * x)
            fv -= g * (params.k1 * x)
        if flags[K3_ON]:
            f -= g * (params.k3 * x * x * x)
            fv -= g * (params.k3 * x * x * x)
        return f * im, fv * im
    if flags[K1_ON]:
        f -= params.k1 * x
        fv -= params.k1 * x
    if flags[K3_ON]:
        f -= params.k3 * x * x * x
        fv -= params.k3 * x * x * x
    return f, fv


@njit(inline="always")
def substrate_power(v, g, flags, params):
    """Dissipation rate of the substrate damping on a bead of substrate factor g,
    ``g c_s v^2``."""
    p = params.sub_damping * v * v
    return p * g if flags[OFF_SUBSTRATE] else p


@njit(inline="always")
def in_kick_band(flags, params, j, d):
    """Whether closed contact j at compression d gets the mean-force kick (never for Hertz):
    in its class's band near snap-off, in its own units when mixed."""
    if flags[HERTZ]:
        return False
    if flags[MIXED]:
        k = params.mix.kind[j]
        return d * pair_at(params, k, P_INV_LEN) < pair_at(params, k, P_BELOW)
    return d < params.mean_force_below


@njit(inline="always")
def predicted(old, b, h):
    """Bead b's predicted (x, v_half, v_est) at the end of a step of length h (as the pass)."""
    hh = 0.5 * h
    a = old.a[b]
    vh = old.v[b] + hh * a
    return old.x[b] + h * vh, vh, vh + hh * a


@njit(inline="always")
def pass_force(flags, params, old, closed, h, j, t0, t1, memo, keep):
    """``(F, Fv)`` of contact j at the end of the pass of length h from ``old`` (the force,
    and the force the beads' velocity kick uses: :func:`segment_pass`'s ``f`` and ``fv``),
    by the pass's operations (``t0``, ``t1``, ``memo``, ``keep``: :func:`memo_mean_force`)."""
    walls = flags[WALLS]
    n = old.x.shape[0]
    rshift = 0 if walls else 1
    lb, rb = j + rshift - 1, j + rshift
    x_l, ve_l, x_r, ve_r = 0.0, 0.0, 0.0, 0.0
    if lb >= 0:
        x_l, _, ve_l = predicted(old, lb, h)
    if rb < n:
        x_r, _, ve_r = predicted(old, rb, h)
    if not closed[j]:
        return 0.0, 0.0
    d = x_l - x_r - params.gap
    r = ve_l - ve_r
    f = force_at(flags, params, j, d)[0]
    fv = f
    if in_kick_band(flags, params, j, d):
        d0 = across(walls, old.x, j) - params.gap
        fv = (2.0 * memo_mean_force(flags, params, j, d0, d, t0, t1, memo, keep)
              - force_at(flags, params, j, d0)[0])
    if flags[DAMPED]:
        f += params.damping * r
        fv += params.damping * r
    return f, fv


@njit(cache=True)
def read_pass_force(flags, params, old, closed, h, j, memo):
    """:func:`pass_force` of contact j, its memo read and not written: a call, for the event
    windows' neighbours (inlined there as well, it cost ~10 s more to compile, for calls
    that are rare beside the kicks')."""
    return pass_force(flags, params, old, closed, h, j, math.nan, math.nan, memo, False)


@njit(cache=True)
def refinish(flags, params, old, vn, h, now, b, fv_l, fv_r):
    """Bead b's end velocity ``v_half + h/2 a_v`` again, with the kick forces ``fv_l`` and
    ``fv_r`` of its left and right contacts (:func:`pass_force`), by the pass's operations."""
    x, vh, ve = predicted(old, b, h)
    im, g = bead_factors(flags, params, b)
    av = bead_accelerations(0.0, fv_l - fv_r, x, ve, im, g, flags, params, now)[1]
    vn[b] = vh + 0.5 * h * av


@njit(inline="always")
def invert_kicks(law, kick, row, count):
    """Column K_T1 of rows row .. row + count - 1 of ``kick`` eight rows at a time in vector
    instructions (:func:`mdgran.backends.simd.branch_t8`; the last eight padded with the last
    row), and column K_T0 of the rows whose K_DUE is nonzero one by one (a kicked contact's
    start is mostly in its memo): compressions replaced by their branch parameters."""
    last = row + count - 1
    for k in range(row, row + count, 8):
        r = (k, min(k + 1, last), min(k + 2, last), min(k + 3, last), min(k + 4, last),
             min(k + 5, last), min(k + 6, last), min(k + 7, last))
        t = branch_t8((kick[r[0], K_T1], kick[r[1], K_T1], kick[r[2], K_T1], kick[r[3], K_T1],
                       kick[r[4], K_T1], kick[r[5], K_T1], kick[r[6], K_T1], kick[r[7], K_T1]),
                      law.sigma, law.t_min, law.delta_min)
        for i in range(8):
            kick[r[i], K_T1] = t[i]
    for k in range(row, row + count):
        if kick[k, K_DUE] != 0.0:
            kick[k, K_T0] = branch_t(kick[k, K_T0], law.sigma, law.t_min, law.delta_min)


@njit(cache=True)
def kick_branches(flags, params, old, h, kicked, kick, row, count, memo):
    """Columns K_T0 and K_T1 of ``kick`` for the kicked contacts ``kicked[row: row + count]``:
    the branch parameters (:func:`branch_t`) of each one's compressions at the start and at
    the end of the pass of length h from ``old`` (in its own units when mixed), by the pass's
    operations; the start's from ``memo`` when it holds it (:func:`memo_mean_force`).  With
    one law, the end's inversions eight at a time in vector instructions (:func:`invert_kicks`:
    one inversion is a chain of dependent square roots and divisions), and the memo rows, far
    apart in a long chain, read one after another before any is used (the kicks of an active
    chain of 1e5 beads took 1.4 ns a bead-step, one contact after another).  The pass asked
    for each row when it found the contact in the band (``prefetch_row``,
    :mod:`mdgran.backends.prefetch`): at 1e6 beads this function then took 0.08 ns a
    bead-step, 0.45 before (a miss per row)."""
    walls = flags[WALLS]
    rshift = 0 if walls else 1
    n = old.x.shape[0]
    for k in range(row, row + count):
        j = kicked[k]
        il = kick_law(flags, params, j)[1]
        lb, rb = j + rshift - 1, j + rshift
        x_l = predicted(old, lb, h)[0] if lb >= 0 else 0.0
        x_r = predicted(old, rb, h)[0] if rb < n else 0.0
        kick[k, K_T1] = (x_l - x_r - params.gap) * il
        u0 = (across(walls, old.x, j) - params.gap) * il
        hit = memo[j, 0] == u0
        kick[k, K_T0] = memo[j, 1] if hit else u0
        kick[k, K_DUE] = 0.0 if hit else 1.0
    if flags[MIXED]:
        for k in range(row, row + count):
            law = kick_law(flags, params, kicked[k])[0]
            kick[k, K_T1] = branch_t(kick[k, K_T1], law.sigma, law.t_min, law.delta_min)
            if kick[k, K_DUE] != 0.0:
                kick[k, K_T0] = branch_t(kick[k, K_T0], law.sigma, law.t_min, law.delta_min)
        return
    invert_kicks(params.law, kick, row, count)


@njit(cache=True)
def apply_kicks(flags, params, old, vn, closed, h, t0, kicked, kick, row, j0, j1, count,
                fv_first, fv_last, memo):
    """The mean-force kicks of a segment's contacts ``kicked[row: row + count]`` (in the band
    near snap-off, in order along the chain; its pass ran contacts j0 .. j1 - 1), after its
    pass: the velocities of the beads next to them that the pass finished, redone with each
    contact's ``Fv`` (:func:`pass_force`) and the pass's ``Fv`` of their other contacts
    (``kick``) by the pass's operations, and the pass's first and last ``Fv``; returns
    those two.  Each kicked contact's ``Fv`` (a mean force) is computed once and each bead
    redone once, however the kicked contacts neighbour each other.  Out of the pass's loop,
    whose registers a call inside it cost 20-30 % on a chain of unlike beads."""
    n = old.x.shape[0]
    rshift = 0 if flags[WALLS] else 1
    now = drive_at(flags, params, t0 + h)
    # the beads this pass finished: the left bead of each of its contacts but the first's when
    # j0 > 0 (finish_edge does it, or it is at rest) and the walls; the last bead is
    # finished after it
    lo = max(j0 + rshift - (0 if j0 > 0 else 1), 0)
    hi = min(j1 + rshift - 2, n - 1)
    kick_branches(flags, params, old, h, kicked, kick, row, count, memo)
    prev, fv_prev = -2, 0.0  # the last kicked contact and its Fv
    for k in range(count):
        j = kicked[row + k]
        fv = pass_force(flags, params, old, closed, h, j, kick[row + k, K_T0],
                        kick[row + k, K_T1], memo, True)[1]
        if j == j0:
            fv_first = fv
        if j == j1 - 1:
            fv_last = fv
        b = j + rshift - 1  # the bead left of contact j (right of contact j - 1)
        if lo <= b <= hi:
            fv_left = fv_prev if prev == j - 1 else kick[row + k, K_FV_LEFT]
            refinish(flags, params, old, vn, h, now, b, fv_left, fv)
        b += 1  # the bead right of contact j: now, unless contact j + 1 is kicked next
        if lo <= b <= hi and not (k + 1 < count and kicked[row + k + 1] == j + 1):
            refinish(flags, params, old, vn, h, now, b, fv, kick[row + k, K_FV_RIGHT])
        prev, fv_prev = j, fv
    return fv_first, fv_last


@njit(inline="always")
def quantized_due(closed, d, delta_off):
    """locate = False: whether a contact with end-of-step compression d switches (strict
    inequalities when delta_off = 0: a DMT or Hertz contact resting at delta = 0 stays)."""
    strict = delta_off == 0.0
    if closed:
        return d < delta_off if strict else d <= delta_off
    return d > 0.0 if strict else d >= 0.0


@njit
def segment_pass(flags, params, old, xn, vn, an, closed, seg, s):
    """Segment ``s`` of one Verlet step of length h from the beads ``old`` into ``(xn, vn,
    an)`` (:class:`Segments`; ``seg = (h, t0, size, flag, ev_real, ev_contact, kicked, kick,
    branch, jlo, jhi)``: its contacts from ``jlo`` to ``jhi - 1`` alone, the rest of the
    pass's activity front being at rest, :func:`step_range`): returns its row of
    ``Segments.real`` (damping power from the v_est rates, and the forces of its first and
    last contacts) and of ``Segments.ints`` (flagged contacts, step-quantized switches,
    status, its contact); the first flagged contacts go into row ``s`` of ``flag``, the
    switches into ``ev_*``.  The bead left of its first contact is left to
    :func:`merge_segments` (both its contact forces are needed), or at rest if the pass
    starts inside the segment.  The arrays it writes are arguments, not fields of a record:
    numba's parallel loop drops writes made through a record built inside it
    (:func:`run_segments`).

    One pass over the contacts from left to right: predict the right bead of the contact,
    compute the contact force, finish the left bead (its acceleration and end velocity).
    Closed contacts flag a possible event (locate) or switch at once (quantized).

    Near snap-off (displacement rule) the force goes as sqrt(delta - delta_min), and the
    trapezoid kick h/2 (f0 + f1) of Verlet errs by O(h^1.5) in the last steps before the
    event; for those contacts the kick uses the mean force (V(delta1) - V(delta0)) /
    (delta1 - delta0), exact along a straight path, through Fv = 2 f_mean - f0 (so that
    h/2 (f0 + Fv) = h f_mean): second order again.
    """
    h, t0, size, flag, ev_real, ev_contact, kicked, kick, branch, jlo, jhi = seg
    walls = flags[WALLS]
    now = drive_at(flags, params, t0 + h)
    xo, vo, ao = old.x, old.v, old.a
    # unsigned indices: numba emits no negative-index wraparound code for them
    n = np.uint64(xo.shape[0])
    one = np.uint64(1)
    row = np.uint64(s * size)  # the segment's first row of ev_* and kicked
    j0 = max(row, np.uint64(jlo))
    j1 = min(row + np.uint64(size), np.uint64(jhi))
    hh = 0.5 * h
    gap, c, doff = params.gap, params.damping, params.delta_off
    nflag = 0
    nev = 0
    nkick = 0
    last_kicked = n  # the last kicked contact (n: none yet)
    status = OK
    bad = 0
    power = 0.0
    rshift = np.uint64(0) if walls else one  # right bead of contact j: j + rshift
    # left bead of the current contact: (x, v_half, v_est); the wall for walls
    x_c, vh_c, ve_c = 0.0, 0.0, 0.0
    if j0 + rshift >= one:
        x_c, vh_c, ve_c = predicted(old, j0 + rshift - one, h)
    f_l, fv_l = 0.0, 0.0  # force of the contact left of that bead (Fv: for the kick)
    f_first, fv_first = 0.0, 0.0
    for i in range(j1 - j0):
        j = j0 + i
        rb = j + rshift
        x_r, vh_r, ve_r = 0.0, 0.0, 0.0
        if rb < n:
            a_r = ao[rb]
            vh_r = vo[rb] + hh * a_r
            x_r = xo[rb] + h * vh_r
            ve_r = vh_r + hh * a_r
        d = x_c - x_r - gap
        r = ve_c - ve_r
        im_l, g_l, k = 1.0, 1.0, np.uint32(0)  # the left bead's factors (bead_factors), kind
        if flags[MIXED]:
            k = params.mix.kind[j]
            doff = pair_at(params, k, P_OFF)
            im_l, g_l = pair_at(params, k, P_INV_MASS), pair_at(params, k, P_ON_SITE)
        if not flags[LOCATE] and quantized_due(closed[j], d, doff):
            k = row + np.uint64(nev)
            ev_contact[k], ev_real[k, 0], ev_real[k, 1] = quantized_switch(
                flags, params, j, d, doff, xo, h, t0, closed)
            nev += 1
        # closed or open, written as selects (the force of an open contact, computed and
        # dropped, is finite: the table's at 0); LLVM compiles the force's as a jump around
        # the table's cubic for an open contact, which measured faster than a forced select
        # in an active chain, where contacts are closed and open at random (docs/fast.md)
        cl = closed[j]
        f, ok = force_at(flags, params, j, d)
        if cl and not ok:
            status, bad = OUT_OF_TABLE, np.int64(j)
        if flags[DAMPED]:
            cr = c * r if cl else 0.0
            f += cr
            power += cr * r
        f_r = f if cl else 0.0
        fv_r = f_r
        if last_kicked + one == j:  # the kicked contact left: this is its right neighbour
            kick[row + np.uint64(nkick) - one, K_FV_RIGHT] = fv_r
        # near snap-off: the mean-force kick, after the loop (apply_kicks)
        if cl and in_kick_band(flags, params, j, d):
            kicked[row + np.uint64(nkick)] = np.int64(j)
            prefetch_row(branch, j)  # its memo row, read by kick_branches
            kick[row + np.uint64(nkick), K_FV_LEFT] = fv_l
            nkick += 1
            last_kicked = j
        g = d - doff if cl else -d
        gd = r if cl else -r
        if flags[LOCATE]:
            # a dip of g below 0 inside the step implies g1 < h/2 g'(h) (g is a parabola)
            if g < 0.0 or g < 0.5 * h * gd:
                if nflag < flag.shape[1]:
                    flag[s, nflag] = np.int64(j)
                nflag += 1
        if j == j0:  # the segment's edge: its first contact's force, for merge_segments
            f_first, fv_first = f_r, fv_r
        if rb >= one and (j > j0 or j0 == 0):  # finish the left bead
            a, av = bead_accelerations(f_l - f_r, fv_l - fv_r, x_c, ve_c, im_l, g_l, flags,
                                       params, now)
            if flags[SUB_DAMPED]:
                power += substrate_power(ve_c - now[1], g_l, flags, params)
            xn[rb - one] = x_c
            an[rb - one] = a
            vn[rb - one] = vh_c + hh * av
        x_c, vh_c, ve_c = x_r, vh_r, ve_r
        f_l, fv_l = f_r, fv_r
    if nkick > 0:
        fv_first, fv_l = apply_kicks(at_run_time(flags), params, old, vn, closed, h, t0,
                                     kicked, kick, np.int64(row), np.int64(j0), np.int64(j1),
                                     np.int64(nkick), fv_first, fv_l, branch)
    if not walls and j1 == np.uint64(closed.shape[0]):  # the last bead: no contact right
        im, g = bead_factors(flags, params, n - one)
        a, av = bead_accelerations(f_l, fv_l, x_c, ve_c, im, g, flags, params, now)
        if flags[SUB_DAMPED]:
            power += substrate_power(ve_c - now[1], g, flags, params)
        xn[n - one] = x_c
        an[n - one] = a
        vn[n - one] = vh_c + hh * av
    return (power, f_first, fv_first, f_l, fv_l), (nflag, nev, status, bad)


@njit(cache=True)
def finish_edge(flags, params, old, new, h, t1, seg, s):
    """Finish the bead left of segment s's first contact (s >= 1), between the last contact
    of segment s - 1 and the first of s, as :func:`segment_pass` finishes every other bead
    (the same operations; the step ends at t1); returns its substrate damping power."""
    now = drive_at(flags, params, t1)
    b = s * seg.size - (1 if flags[WALLS] else 0)
    hh = 0.5 * h
    x, vh, ve = predicted(old, b, h)
    real = seg.real
    im, g = bead_factors(flags, params, b)
    a, av = bead_accelerations(real[s - 1, R_LAST] - real[s, R_FIRST],
                               real[s - 1, R_LAST_KICK] - real[s, R_FIRST_KICK], x, ve, im, g,
                               flags, params, now)
    new.x[b] = x
    new.a[b] = a
    new.v[b] = vh + hh * av
    return substrate_power(ve - now[1], g, flags, params) if flags[SUB_DAMPED] else 0.0


@njit(cache=True)
def log_switches(ks, s):
    """Log segment s's step-quantized switches in order (hysteresis loss on opening)."""
    seg = ks.seg
    counters = ks.counters[0]
    first = s * seg.size
    for k in range(first, first + seg.ints[s, I_SWITCHES]):
        j = seg.ev_contact[k]
        loss = 0.0
        if not ks.closed[j]:
            loss = seg.ev_real[k, 1]
            counters.d_hysteresis += loss
        record_event(ks, j, seg.ev_real[k, 0], 1 if ks.closed[j] else 0, loss)


@njit
def merge_segments(flags, params, old, new, h, t1, ks):
    """After every segment of a pass (:func:`segment_pass`): finish the beads at their
    edges, then in segment order add up the damping power, log the step-quantized switches
    (and their hysteresis losses), count the flagged contacts (each segment's stay in its
    row of ``Segments.flag``, :func:`find_windows`) and record failures, so that all of it
    is as one pass from left to right would have it whatever thread ran which segment.
    Returns the damping power at the step's end."""
    seg = ks.seg
    ints, real = seg.ints, seg.real
    power = 0.0
    total = 0
    first = ks.counters[0].seg_first
    for s in range(first, ks.counters[0].seg_last + 1):
        if s > first:
            power += finish_edge(at_run_time(flags), params, old, new, h, t1, seg, s)
        power += real[s, R_POWER]
        if ints[s, I_SWITCHES] > 0:
            log_switches(ks, s)
        total += ints[s, I_FLAGGED]
        if ints[s, I_STATUS] != OK:
            fail(ks.counters[0], ints[s, I_STATUS], ints[s, I_BAD])
    ks.counters[0].flagged = total
    return power


@njit(inline="always")
def push_pulsed_bead(flags, params, new, h, t1):
    """Add the pulse's force at the step's end t1 to its bead's new acceleration and velocity
    (``a += F / m``, ``v += h/2 F / m``: the force is the same in both kicks), once per pass
    rather than a test of every bead."""
    b = params.drive.bead
    da = drive_at(flags, params, t1)[2]
    if flags[MIXED]:
        da *= params.mix.inv_mass[b]
    new.a[b] += da
    new.v[b] += 0.5 * h * da


@njit(inline="always")
def verlet_pass(flags, params, old, new, h, t0, ks, run_segments):
    """One Verlet step of length h from the beads ``old`` into ``new``; returns the damping
    power at the end (rates from v_est).  The pass is cut into segments
    (:class:`Segments`): one is run here, several by ``run_segments`` (a loop over them, on
    several threads in a threaded variant), and :func:`merge_segments` joins them."""
    seg = ks.seg
    if seg.count > 1:
        power = run_segments(params, old, new, h, t0, ks)
        if flags[PULSE]:
            push_pulsed_bead(flags, params, new, h, t0 + h)
        return power
    first = np.int64(0)  # typed int64, as one_segment's: a literal 0 made numba compile
    # segment_pass a second time in each variant (~7 s)
    real, ints = segment_pass(flags, params, old, new.x, new.v, new.a, ks.closed,
                              (h, t0, seg.size, seg.flag, seg.ev_real, seg.ev_contact,
                               seg.kicked, seg.kick, seg.branch, first, ks.closed.shape[0]),
                              first)
    if ints[I_SWITCHES] > 0:
        seg.ints[0, I_SWITCHES] = ints[I_SWITCHES]
        log_switches(ks, first)
    if ints[I_STATUS] != OK:
        fail(ks.counters[0], ints[I_STATUS], ints[I_BAD])
    seg.ints[0, I_FLAGGED] = ints[I_FLAGGED]
    ks.counters[0].flagged = ints[I_FLAGGED]
    if flags[PULSE]:
        push_pulsed_bead(flags, params, new, h, t0 + h)
    return real[R_POWER]


# ---- event location and switching (rare path; flags at run time) --------------------------
@njit(inline="always")
def event_function(walls, params, j, beads, closed):
    """(g, g', g'') of contact j in its current state (g > 0 inside the state)."""
    d = across(walls, beads.x, j) - params.gap
    r = across(walls, beads.v, j)
    q = across(walls, beads.a, j)
    if closed[j]:
        return d - delta_off_at(params, j), r, q
    return -d, -r, -q


@njit(inline="always")
def first_root(walls, params, j, old, x_new, closed, h):
    """First s in [0, h] where g(s) = g0 + s g0' + s^2/2 g0'' falls to min(g0, 0), or -1."""
    g0, b, q = event_function(walls, params, j, old, closed)
    c = 0.5 * q
    d1 = across(walls, x_new, j) - params.gap
    g1 = d1 - delta_off_at(params, j) if closed[j] else -d1
    if g0 <= 0.0:  # on its switching point (left alone: moving inward): event if it goes out
        if b < 0.0 or g0 < -STATE_TOL:  # moving out, or beyond it (the state invariant)
            return 0.0
        if c < 0.0 and -b / c <= h:
            return -b / c
        return h if g1 < g0 else -1.0
    s = -1.0
    if c == 0.0:
        if b < 0.0:
            s = -g0 / b
    else:
        disc = b * b - 4.0 * c * g0
        if disc >= 0.0:
            qq = -0.5 * (b + math.copysign(math.sqrt(disc), b))
            r1 = qq / c
            r2 = g0 / qq if qq != 0.0 else -1.0
            if r1 > 0.0 and (r2 <= 0.0 or r1 < r2):
                s = r1
            elif r2 > 0.0:
                s = r2
    if 0.0 <= s <= h:
        return s
    if g1 < 0.0:  # the pass saw it out at the end: rounding put the root past h
        return h
    return -1.0


@njit(cache=True)
def locate_events(walls, params, old, x_new, h, tol, ks, jl, jr):
    """Earliest root te among contacts jl .. jr, and the contacts switching with it (into
    ks.switching): returns (te, count), te = -1 if none."""
    counters = ks.counters[0]
    closed, switching = ks.closed, ks.switching
    te = -1.0
    for j in range(jl, jr + 1):
        s = first_root(walls, params, j, old, x_new, closed, h)
        if s >= 0.0 and (te < 0.0 or s < te):
            te = s
    if te < 0.0:
        return te, 0
    ns = 0
    for j in range(jl, jr + 1):
        s = first_root(walls, params, j, old, x_new, closed, h)
        if s >= 0.0 and s <= te + tol:
            if ns >= switching.shape[0]:
                fail(counters, EVENT_OVERFLOW, j)
                return te, ns
            switching[ns] = j
            ns += 1
    return te, ns


@njit(inline="always")
def count_switch(ks, j, t):
    """Chatter guard: count the switches of contact j at the instant t; more than
    MAX_SWITCHES stop the run."""
    counters = ks.counters[0]
    chat = ks.chatter
    if abs(t - counters.chatter_time) > SIMULTANEOUS * (1.0 + abs(t)):
        counters.chatter_time = t
        counters.chatter_count = 0
    nc = counters.chatter_count
    for k in range(nc):
        if chat[k, 0] == j:
            chat[k, 1] += 1
            if chat[k, 1] > MAX_SWITCHES:
                fail(counters, CHATTER, j)
            return
    if nc < chat.shape[0]:
        chat[nc, 0] = j
        chat[nc, 1] = 1
        counters.chatter_count = nc + 1


@njit(cache=True)
def switch(flags, params, j, t, beads, ks):
    """Switch contact j at time t in state ``beads``: hysteresis loss V(delta) on opening,
    the event, the change of force on its two beads and of the damping power; chatter guard."""
    counters = ks.counters[0]
    closed = ks.closed
    x, a = beads.x, beads.a
    n = x.shape[0]
    c = params.damping
    d = across(flags[WALLS], x, j) - params.gap
    r = across(flags[WALLS], beads.v, j)
    f_old = 0.0
    f_new = 0.0
    if closed[j]:
        f_old, ok = force_at(flags, params, j, d)
        if flags[DAMPED]:
            f_old += c * r
            counters.power -= c * r * r
        loss = energy_at(flags, params, j, d)
        counters.d_hysteresis += loss
        closed[j] = False
        record_event(ks, j, t, 0, loss)
    else:
        closed[j] = True
        record_event(ks, j, t, 1, 0.0)
        f_new, ok = force_at(flags, params, j, d)
        if not ok:
            fail(counters, OUT_OF_TABLE, j)
        if flags[DAMPED]:
            f_new += c * r
            counters.power += c * r * r
    left, right = beads_of(flags[WALLS], j)
    df = f_new - f_old
    if left >= 0:
        a[left] -= df * params.mix.inv_mass[left] if flags[MIXED] else df
    if right < n:
        a[right] += df * params.mix.inv_mass[right] if flags[MIXED] else df
    count_switch(ks, j, t)


@njit(cache=True)
def settle(flags, params, contacts, count, t, beads, ks):
    """Switch at once every contact of contacts[:count] on or over its switching point and
    moving outward (g <= 0, g' < 0), or beyond it by more than STATE_TOL, until none is (the
    reference's rule)."""
    counters = ks.counters[0]
    while True:
        moved = False
        for k in range(count):
            j = contacts[k]
            g, gd, _ = event_function(flags[WALLS], params, j, beads, ks.closed)
            if g < -STATE_TOL or (g <= 0.0 and gd < 0.0):
                switch(flags, params, j, t, beads, ks)
                moved = True
                if counters.status != OK:
                    return
        if not moved:
            return


@njit(cache=True)
def settle_all(flags, params, t, beads, ks):
    """The initial settle, over every contact, with the run's counters, log and chatter guard
    seen as a :class:`Lane` (the switching functions are then compiled for one record
    type, the event windows')."""
    m = ks.closed.shape[0]
    lane = Lane(ks.closed, ks.counters, ks.log, ks.lanes.switching[0], ks.chatter,
                ks.seg.branch, ks.local)
    settle(flags, params, np.arange(m), m, t, beads, lane)


@njit(cache=True)
def init_acc(flags, params, beads, ks):
    """a = a(x, v) at t = 0 for the current contact states; returns the damping power.  The
    excitations vanish at t = 0 (a pulse starts at 0 force, a base at rest at 0)."""
    x, v, a = beads
    closed = ks.closed
    n = x.shape[0]
    power = 0.0
    for i in range(n):
        a[i] = 0.0
        g = bead_factors(flags, params, i)[1]
        if flags[SUB_DAMPED]:
            power += substrate_power(v[i], g, flags, params)
            a[i] -= (g * (params.sub_damping * v[i]) if flags[MIXED]
                     else params.sub_damping * v[i])
        if flags[K1_ON]:
            a[i] -= g * (params.k1 * x[i]) if flags[MIXED] else params.k1 * x[i]
        if flags[K3_ON]:
            a[i] -= (g * (params.k3 * x[i] * x[i] * x[i]) if flags[MIXED]
                     else params.k3 * x[i] * x[i] * x[i])
    for j in range(closed.shape[0]):
        if not closed[j]:
            continue
        f, ok = force_at(flags, params, j, across(flags[WALLS], x, j) - params.gap)
        if not ok:
            fail(ks.counters[0], OUT_OF_TABLE, j)
        if flags[DAMPED]:
            r = across(flags[WALLS], v, j)
            f += params.damping * r
            power += params.damping * r * r
        left, right = beads_of(flags[WALLS], j)
        if left >= 0:
            a[left] -= f
        if right < n:
            a[right] += f
    if flags[MIXED]:
        for i in range(n):
            a[i] *= params.mix.inv_mass[i]
    return power


# ---- the stepping loop, one compiled variant per Flags ---------------------------------------
@njit
def switch_all(flags, params, count, t, beads, ks):
    """Switch the located contacts ks.switching[:count] at t, then settle them."""
    for k in range(count):
        switch(flags, params, ks.switching[k], t, beads, ks)
    settle(flags, params, ks.switching, count, t, beads, ks)


# ---- events where they happen: windows of beads sub-stepped alone (rare path) ---------------
# A contact that switches at s in (0, h) changes the force on its two beads only.  The pass
# steps the whole chain; then each event window (the beads of the contacts that switch in the
# step, with their neighbours within one bead) is stepped again alone, split at its events,
# while the beads next to it (its *neighbours*) move on their parabolas of the step.  Cost per
# event: a few passes over a few beads, whatever the chain's length.
@njit(inline="always")
def window_contacts(walls, n, m, lo, hi):
    """The contacts of the window of beads lo .. hi: (first, last, left edge, right edge), an
    edge being the contact with a neighbour bead (-1 where the window reaches the chain's
    end; a wall is not a neighbour: it does not move)."""
    s = 0 if walls else 1  # contact left of bead b: b - s; right: b - s + 1
    jl, jr = max(lo - s, 0), min(hi - s + 1, m - 1)
    return jl, jr, jl if lo >= 1 else -1, jr if hi <= n - 2 else -1


@njit(cache=True)
def find_windows(walls, params, old, x_new, h, ks):
    """The event windows of a pass from ``old`` (beads of the flagged contacts that have a
    root in the step, :func:`first_root`; windows within two beads of each other joined)
    into ``ks.windows``, in order along the chain; returns their count."""
    seg, win, closed = ks.seg, ks.windows, ks.closed
    n = old.x.shape[0]
    count = 0
    for s in range(ks.counters[0].seg_first, ks.counters[0].seg_last + 1):
        nf = seg.ints[s, I_FLAGGED]
        j0 = s * seg.size
        listed = nf <= seg.flag.shape[1]  # else the segment's every contact
        for k in range(nf if listed else min(j0 + seg.size, closed.shape[0]) - j0):
            j = seg.flag[s, k] if listed else j0 + k
            if first_root(walls, params, j, old, x_new, closed, h) < 0.0:
                continue
            left, right = beads_of(walls, j)
            left, right = max(left, 0), min(right, n - 1)
            if count > 0 and left <= win[count - 1, W_HI] + 2:
                win[count - 1, W_HI] = max(win[count - 1, W_HI], right)
            else:
                win[count, W_LO], win[count, W_HI], win[count, W_TODO] = left, right, 1
                count += 1
    return count


@njit(inline="always")
def window_power(flags, params, beads, closed, lo, hi, t):
    """Damping power of window lo .. hi in state ``beads`` at time t: its contacts' (edges
    included, rates from v) and its beads' substrate damping."""
    walls = flags[WALLS]
    jl, jr, _, _ = window_contacts(walls, beads.x.shape[0], closed.shape[0], lo, hi)
    p = 0.0
    if flags[DAMPED]:
        for j in range(jl, jr + 1):
            if closed[j]:
                r = across(walls, beads.v, j)
                p += params.damping * r * r
    if flags[SUB_DAMPED]:
        vb = drive_at(flags, params, t)[1]
        for b in range(lo, hi + 1):
            p += substrate_power(beads.v[b] - vb, bead_factors(flags, params, b)[1], flags,
                                 params)
    return p


@njit(inline="always")
def start_force(flags, params, beads, closed, j):
    """Force of contact j in state ``beads`` (damping rate from v)."""
    if j < 0 or not closed[j]:
        return 0.0
    f = force_at(flags, params, j, across(flags[WALLS], beads.x, j) - params.gap)[0]
    if flags[DAMPED]:
        f += params.damping * across(flags[WALLS], beads.v, j)
    return f


@njit(inline="always")
def bead_power(flags, params, b, ve, now):
    """Substrate damping power of bead b at v_est ``ve`` (``now``: :func:`drive_at`)."""
    g = bead_factors(flags, params, b)[1]
    return substrate_power(ve - now[1], g, flags, params) if flags[SUB_DAMPED] else 0.0


@njit(inline="always")
def finish_bead(flags, params, nxt, b, f, fv, h, t1, now):
    """Bead b of a window sub-step ending at t1: acceleration and end velocity from its net
    contact forces (f, fv), as the pass; ``nxt`` holds its predicted x, v_half and (in
    ``a``) v_est.  Returns its substrate damping power."""
    im, g = bead_factors(flags, params, b)
    x, vh, ve = nxt.x[b], nxt.v[b], nxt.a[b]
    a, av = bead_accelerations(f, fv, x, ve, im, g, flags, params, now)
    nxt.a[b] = a
    nxt.v[b] = vh + 0.5 * h * av
    if flags[PULSE] and b == params.drive.bead:
        push_pulsed_bead(flags, params, nxt, h, t1)
    return bead_power(flags, params, b, ve, now)


@njit(cache=True)
def window_start(flags, params, cur, x_new, closed, h, t0, lo, hi):
    """What the events of a window's first (sub)step of length h from ``cur`` need of
    :func:`window_pass`, without its forces: the beads' positions (into ``x_new``, from
    ``lo - 1`` to ``hi + 1``) and, bit for bit as window_pass returns them, the damping
    power of the window at the end (rates from v_est, summed in the same order), which edge
    is closed in the mean-force band, and the status and its contact (the force's range
    test only).  The step is rarely kept whole (an event inside it cuts it); when it is,
    :func:`resolve_window` steps it again with window_pass."""
    walls = flags[WALLS]
    n, m = cur.x.shape[0], closed.shape[0]
    jl, jr, _, _ = window_contacts(walls, n, m, lo, hi)
    now = drive_at(flags, params, t0 + h)
    for b in range(max(lo - 1, 0), min(hi + 1, n - 1) + 1):
        x_new[b] = predicted(cur, b, h)[0]
    power, band, status, bad = 0.0, 0, OK, 0
    for j in range(jl, jr + 1):
        left, right = beads_of(walls, j)
        x_l, ve_l = (x_new[left], predicted(cur, left, h)[2]) if left >= 0 else (0.0, 0.0)
        x_r, ve_r = (x_new[right], predicted(cur, right, h)[2]) if right < n else (0.0, 0.0)
        d = x_l - x_r - params.gap
        r = ve_l - ve_r
        edge = 1 if 0 <= left < lo else (2 if hi < right < n else 0)
        if closed[j]:
            if not force_at(flags, params, j, d)[1]:
                status, bad = OUT_OF_TABLE, j
            if edge and in_kick_band(flags, params, j, d):
                band |= edge
            if flags[DAMPED]:
                power += params.damping * r * r
        if lo <= left <= hi:
            power += bead_power(flags, params, left, ve_l, now)
    if not walls and hi == n - 1:  # the last bead: no contact right
        power += bead_power(flags, params, hi, predicted(cur, hi, h)[2], now)
    return power, band, status, bad


@njit(cache=True)
def window_pass(flags, params, cur, nxt, closed, h, t0, lo, hi, memo):
    """One Verlet (sub)step of length h from ``cur`` into ``nxt`` of the window of beads
    lo .. hi: its beads stepped as the pass steps them (mean-force kick near snap-off
    included; ``memo``: :func:`memo_mean_force`), its neighbours along their parabolas
    (acceleration unchanged).  Returns
    (damping power of the window at the end, the forces of its left and right edge
    contacts, which edge is closed in the mean-force band (1 left, 2 right, 3 both), status,
    its contact)."""
    walls = flags[WALLS]
    n, m = cur.x.shape[0], closed.shape[0]
    jl, jr, _, _ = window_contacts(walls, n, m, lo, hi)
    now = drive_at(flags, params, t0 + h)
    for b in range(max(lo - 1, 0), min(hi + 1, n - 1) + 1):
        x, vh, ve = predicted(cur, b, h)
        nxt.x[b], nxt.v[b], nxt.a[b] = x, vh, ve  # a: v_est until the bead is finished
    power, f_edge_l, f_edge_r, band, status, bad = 0.0, 0.0, 0.0, 0, OK, 0
    f_l, fv_l = 0.0, 0.0  # force of the contact left of the bead to finish next
    for j in range(jl, jr + 1):
        left, right = beads_of(walls, j)
        x_l, ve_l = (nxt.x[left], nxt.a[left]) if left >= 0 else (0.0, 0.0)
        x_r, ve_r = (nxt.x[right], nxt.a[right]) if right < n else (0.0, 0.0)
        d = x_l - x_r - params.gap
        r = ve_l - ve_r
        edge = 1 if 0 <= left < lo else (2 if hi < right < n else 0)
        f, fv = 0.0, 0.0
        if closed[j]:
            f, ok = force_at(flags, params, j, d)
            if not ok:
                status, bad = OUT_OF_TABLE, j
            fv = f
            if in_kick_band(flags, params, j, d):
                if edge:
                    band |= edge
                else:
                    d0 = across(walls, cur.x, j) - params.gap
                    fv = (2.0 * memo_mean_force(flags, params, j, d0, d, math.nan, math.nan, memo,
                                                True)
                          - force_at(flags, params, j, d0)[0])
            if flags[DAMPED]:
                f += params.damping * r
                fv += params.damping * r
                power += params.damping * r * r
        if edge == 1:
            f_edge_l = f
        elif edge == 2:
            f_edge_r = f
        if lo <= left <= hi:
            power += finish_bead(flags, params, nxt, left, f_l - f, fv_l - fv, h, t0 + h, now)
        f_l, fv_l = f, fv
    if not walls and hi == n - 1:  # the last bead: no contact right
        power += finish_bead(flags, params, nxt, hi, f_l, fv_l, h, t0 + h, now)
    for b in (lo - 1, hi + 1):  # the neighbours: on their parabolas
        if 0 <= b < n:
            nxt.v[b] = nxt.a[b]
            nxt.a[b] = cur.a[b]
    return power, f_edge_l, f_edge_r, band, status, bad


@njit(cache=True)
def finish_neighbour(flags, params, old, new, closed, h, t1, b, f_edge, impulse, window_left,
                     memo):
    """Neighbour bead b of a window after the step of length h ending at t1: its end
    acceleration and velocity from the window's end force ``f_edge`` on the contact they
    share and the pass's force on its other contact, its velocity given the difference
    ``impulse`` between the window's impulse on that contact (sum over the sub-steps) and the
    step's trapezoid, so that the contact's impulses on its two beads are equal and opposite
    (momentum is kept).  ``window_left``: the window is on b's left."""
    s = 0 if flags[WALLS] else 1
    x, vh, ve = predicted(old, b, h)
    now = drive_at(flags, params, t1)
    im, g = bead_factors(flags, params, b)
    jo = b - s + 1 if window_left else b - s  # b's other contact
    fo, fvo = 0.0, 0.0
    if 0 <= jo < closed.shape[0]:
        fo, fvo = read_pass_force(flags, params, old, closed, h, jo, memo)
    if window_left:  # the edge is b's left contact: +F on b
        f, fv, dj = f_edge - fo, f_edge - fvo, impulse
    else:  # the edge is b's right contact: -F on b
        f, fv, dj = fo - f_edge, fvo - f_edge, -impulse
    a, av = bead_accelerations(f, fv, x, ve, im, g, flags, params, now)
    new.x[b] = x
    new.a[b] = a
    new.v[b] = vh + 0.5 * h * av + dj * im
    if flags[PULSE] and b == params.drive.bead:
        push_pulsed_bead(flags, params, new, h, t1)


@njit(cache=True)
def resolve_window(flags, params, old, new, lane, lo, hi, t0, dt):
    """Step the window of beads lo .. hi from ``old`` (time t0) through its events to t0 +
    dt, as the whole chain was once stepped (:func:`window_pass` to the earliest root te of
    its contacts, the contacts switch there, the rest of the step in the new state, repeated),
    into ``new``, and finish its neighbours (:func:`finish_neighbour`).

    Returns ``(grow, viscous, power, work)``: ``grow`` is nonzero (1 left, 2 right, 3 both,
    nothing written) when an edge contact switches in the step or is closed in the mean-force
    band: the window must take in that neighbour.  Else ``viscous`` and ``work`` are what the
    window's sub-steps add to the step's trapezoids of the damping power and of the
    excitations' power (:func:`external_power`), ``power`` what they add to its end.
    Its switches, events and counters go to ``lane`` (:class:`Lane`)."""
    ks = lane
    counters = ks.counters[0]
    walls = flags[WALLS]
    n, m = old.x.shape[0], ks.closed.shape[0]
    jl, jr, edge_l, edge_r = window_contacts(walls, n, m, lo, hi)
    copies = (buffer(ks.local, 0), buffer(ks.local, 1))
    for b in range(max(lo - 1, 0), min(hi + 1, n - 1) + 1):
        copies[0].x[b], copies[0].v[b], copies[0].a[b] = old.x[b], old.v[b], old.a[b]
    p_state = p_start = window_power(flags, params, old, ks.closed, lo, hi, t0)
    driven = flags[PULSE] or flags[BASE]
    e_state = e_start = external_power(flags, params, old, t0, lo, hi) if driven else 0.0
    work = 0.0
    f0_l = start_force(flags, params, old, ks.closed, edge_l)
    f0_r = start_force(flags, params, old, ks.closed, edge_r)
    fs_l, fs_r, j_l, j_r = f0_l, f0_r, 0.0, 0.0  # edge forces at the state, impulses so far
    tol = SIMULTANEOUS * (1.0 + abs(t0))
    c, done, h, redo, nsub, viscous, p_pass, light = 0, 0.0, dt, 0, 0, 0.0, 0.0, True
    while True:
        cur, nxt = copies[c], copies[1 - c]
        if light:  # the whole step from the start, as the pass took it: no forces
            p1, band, status, bad = window_start(flags, params, cur, nxt.x, ks.closed, h, t0,
                                                 lo, hi)
            p_pass, f_l, f_r = p1, 0.0, 0.0  # the window's share of the whole pass's power
        else:
            p1, f_l, f_r, band, status, bad = window_pass(flags, params, cur, nxt, ks.closed,
                                                          h, t0 + done, lo, hi, ks.memo)
        if status != OK:
            fail(counters, status, bad)
            counters.bad_time = t0 + done + h
            return 0, 0.0, 0.0, 0.0
        if band:
            return band, 0.0, 0.0, 0.0
        ns, te, last = redo, h, False
        if redo == 0:
            te, ns = locate_events(walls, params, cur, nxt.x, h, tol, ks, jl, jr)
            if counters.status != OK:
                counters.bad_time = t0 + done
                return 0, 0.0, 0.0, 0.0
            last = ns == 0 or te >= h - tol
        grow = 0
        for k in range(ns):
            grow |= (1 if ks.switching[k] == edge_l else 0) | (2 if ks.switching[k] == edge_r
                                                                 else 0)
        if grow:
            return grow, 0.0, 0.0, 0.0
        if light:
            light = False
            if last:  # no event inside the step: step it again, with its forces, and keep it
                continue
        if last or redo > 0:  # keep this sub-step
            viscous += 0.5 * h * (p_state + p1)
            if driven:
                e1 = external_power(flags, params, nxt, t0 + done + h, lo, hi)
                work += 0.5 * h * (e_state + e1)
                e_state = e1
            j_l += 0.5 * h * (fs_l + f_l)
            j_r += 0.5 * h * (fs_r + f_r)
            p_state, fs_l, fs_r, c = p1, f_l, f_r, 1 - c
        if ns == 0:
            break
        if redo == 0 and not last and te > 0.0:
            redo, h = ns, te  # step again, up to the event
            continue
        tev = t0 + dt if last else t0 + done + te
        before = counters.power
        switch_all(flags, params, ns, tev, copies[c], ks)
        p_state += counters.power - before
        counters.substeps += 1
        nsub += 1
        if nsub > MAX_SUBSTEPS:
            fail(counters, TOO_MANY_SUBSTEPS, ks.switching[0])
        if counters.status != OK:
            counters.bad_time = tev
            return 0, 0.0, 0.0, 0.0
        if last:
            break
        done += te
        h = dt - done
        redo = 0
    out = copies[c]
    for b in range(lo, hi + 1):
        new.x[b], new.v[b], new.a[b] = out.x[b], out.v[b], out.a[b]
    t1 = t0 + dt
    if edge_l >= 0:
        finish_neighbour(flags, params, old, new, ks.closed, dt, t1, lo - 1, fs_l,
                         j_l - 0.5 * dt * (f0_l + fs_l), np.bool_(False), ks.memo)
    if edge_r >= 0:
        finish_neighbour(flags, params, old, new, ks.closed, dt, t1, hi + 1, fs_r,
                         j_r - 0.5 * dt * (f0_r + fs_r), np.bool_(True), ks.memo)
    return (0, viscous - 0.5 * dt * (p_start + p_pass), p_state - p_pass,
            work - 0.5 * dt * (e_start + e_state))


@njit(cache=True)
def drop_window(ks, k, count):
    """Remove window k of ``count`` (rows after it move up; a loop: the kernel allocates
    nothing, since its loop runs without numba's reference counting); returns the count."""
    win, sums = ks.windows, ks.window_sums
    for i in range(k, count - 1):
        for c in range(win.shape[1]):
            win[i, c] = win[i + 1, c]
        for c in range(sums.shape[1]):
            sums[i, c] = sums[i + 1, c]
    return count - 1


@njit(cache=True)
def lane_view(closed, memo, local, lanes, g):
    """Lane g of ``lanes`` as a :class:`Lane`."""
    log = lanes.log
    return Lane(closed, lanes.counters[g],
                EventLog(log.time[g], log.contact[g], log.kind[g], log.loss[g]),
                lanes.switching[g], lanes.chatter[g], memo, local)


@njit(cache=True)
def step_window(flags, params, old, new, counters, chatter, lane, windows, sums, k, g, t0,
                dt):
    """Window k (row k of ``KernelState.windows`` and ``.window_sums``) stepped by lane g
    (:func:`resolve_window`).  The lane starts from the step's ``counters`` and chatter guard,
    so that a window's result depends on nothing another window does.  A window that must
    grow takes back its switches."""
    c = lane.counters[0]
    first = c.events
    c.status, c.substeps = OK, 0
    c.power, c.d_hysteresis = counters.power, counters.d_hysteresis
    c.chatter_time, c.chatter_count = counters.chatter_time, counters.chatter_count
    for i in range(counters.chatter_count):
        lane.chatter[i, 0], lane.chatter[i, 1] = chatter[i, 0], chatter[i, 1]
    grow, dv, dp, dw = resolve_window(flags, params, old, new, lane, windows[k, W_LO],
                                      windows[k, W_HI], t0, dt)
    if grow and c.status == OK:
        for e in range(c.events - 1, first - 1, -1):
            j = lane.log.contact[e]
            lane.closed[j] = not lane.closed[j]
        c.events = first
    windows[k, W_TODO], windows[k, W_GROW], windows[k, W_LANE] = 0, grow, g
    windows[k, W_FIRST], windows[k, W_EVENTS] = first, c.events - first
    windows[k, W_SUBSTEPS], windows[k, W_STATUS], windows[k, W_BAD] = (c.substeps, c.status,
                                                                        c.bad_contact)
    sums[k, S_VISCOUS], sums[k, S_POWER], sums[k, S_WORK] = dv, dp, dw
    sums[k, S_BAD_TIME] = c.bad_time


@njit(cache=True)
def step_lane(flags, params, old, new, shared, lanes, g, count, t0, dt):
    """The windows of lane g (:data:`LANES`) still to be stepped, of the step's ``count``.
    Every argument that is written is an array or a plain tuple of arrays (``new``:
    ``(x, v, a)``; ``shared``: the :class:`KernelState`'s ``(closed, counters, chatter,
    Segments.branch, local x, v, a, windows, window_sums)``; ``lanes``: :class:`Lanes`'
    arrays, the log's flattened): numba's parallel loop (``run_lanes``) drops writes made
    through a record built inside it."""
    closed, counters, chatter, memo, lx, lv, la, windows, sums = shared
    lc, time, contact, kind, loss, switching, lchat = lanes
    view = lane_view(closed, memo, Beads(lx, lv, la),
                     Lanes(lc, EventLog(time, contact, kind, loss), switching, lchat), g)
    out = Beads(new[0], new[1], new[2])
    for k in range(g * count // LANES, (g + 1) * count // LANES):
        if windows[k, W_TODO]:
            step_window(flags, params, old, out, counters[0], chatter, view, windows, sums,
                        k, g, t0, dt)


@njit(cache=True)
def undo_window(ks, k):
    """Take back window k's switches (its events, in its lane, last first)."""
    win, log = ks.windows, ks.lanes.log
    g, first = win[k, W_LANE], win[k, W_FIRST]
    for e in range(first + win[k, W_EVENTS] - 1, first - 1, -1):
        j = log.contact[g, e]
        ks.closed[j] = not ks.closed[j]
    win[k, W_EVENTS] = 0


@njit(cache=True)
def regroup(ks, count):
    """After the lanes stepped the windows to do: each window that must take in a neighbour
    grows by it, and windows within two beads of each other are joined (the switches of a
    stepped one taken back); those are to be stepped again.  Returns the new count and
    whether any is (none when a window failed: the step stops)."""
    win = ks.windows
    for k in range(count):
        if win[k, W_STATUS] != OK:
            return count, False
    again = False
    for k in range(count):
        grow = win[k, W_GROW]
        if grow:
            win[k, W_LO] -= 1 if grow & 1 else 0
            win[k, W_HI] += 1 if grow & 2 else 0
            win[k, W_GROW], win[k, W_TODO] = 0, 1
            ks.counters[0].widened += 1
            again = True
    k = 0
    while k + 1 < count:
        if win[k + 1, W_LO] > win[k, W_HI] + 2:
            k += 1
            continue
        for i in (k, k + 1):
            if not win[i, W_TODO]:
                undo_window(ks, i)
        win[k, W_HI] = max(win[k, W_HI], win[k + 1, W_HI])
        win[k, W_TODO] = 1
        count = drop_window(ks, k + 1, count)
        again = True
    return count, again


@njit(cache=True)
def merge_windows(ks, count):
    """The step's windows in order along the chain, as if stepped one after another: their
    events into the log (hysteresis losses added and the chatter guard counted in that
    order), their sub-steps counted, the first failure recorded; returns what they add to the
    step's damping-power trapezoid, end power and excitations' work, and their count."""
    counters, win, sums, log = ks.counters[0], ks.windows, ks.window_sums, ks.lanes.log
    viscous, power, work = 0.0, 0.0, 0.0
    for k in range(count):
        g = win[k, W_LANE]
        for e in range(win[k, W_FIRST], win[k, W_FIRST] + win[k, W_EVENTS]):
            j, t, kind, loss = log.contact[g, e], log.time[g, e], log.kind[g, e], log.loss[g, e]
            if kind == 0:
                counters.d_hysteresis += loss
            record_event(ks, j, t, kind, loss)
            count_switch(ks, j, t)
            if counters.status != OK:
                counters.bad_time = t
                return 0.0, 0.0, 0.0, 0
        counters.substeps += win[k, W_SUBSTEPS]
        if win[k, W_STATUS] != OK:
            fail(counters, win[k, W_STATUS], win[k, W_BAD])
            counters.bad_time = sums[k, S_BAD_TIME]
            return 0.0, 0.0, 0.0, 0
        viscous += sums[k, S_VISCOUS]
        power += sums[k, S_POWER]
        work += sums[k, S_WORK]
    counters.windows += count
    return viscous, power, work, count


@njit(inline="always")
def local_events(flags, params, old, new, t0, dt, ks, run_lanes):
    """The events of the step from ``old`` (t0) whose pass is in ``new``, each window of them
    stepped alone (:func:`find_windows`, :func:`resolve_window`) by the lanes
    (``run_lanes``: on the threads in a threaded variant); a window that must take in a
    neighbour grows, one that comes within two beads of another is joined with it, and
    those are stepped again (:func:`regroup`; rare).  A window's result depends on its beads
    and contacts alone and the windows are merged in order along the chain
    (:func:`merge_windows`): the result does not depend on the thread count.  Returns what
    the windows add to the step's trapezoid of the damping power, to its end power and to its
    trapezoid of the excitations' power, and their count."""
    count = find_windows(flags[WALLS], params, old, new.x, dt, ks)
    for g in range(LANES):
        ks.lanes.counters[g, 0].events = 0
    again = True
    while again:
        run_lanes(params, old, new, t0, dt, ks, count)
        count, again = regroup(ks, count)
    return merge_windows(ks, count)


# ---- the activity front: beads at rest are not stepped --------------------------------------
# A bead at rest (v and a +0.0) whose neighbours are at rest too is a fixed point of the pass:
# its x + h v_half is x, its contact forces and so its acceleration are those it had, bit for
# bit.  The beads of the chain that are not all at rest lie in the *front*, a range of beads
# that only grows (a disturbance reaches one bead further per step, in velocity Verlet); the
# pass runs the segments that cover it.  The first step of a run steps every bead (the
# accelerations of the initial state come from init_acc, not from the pass).
@njit(inline="always")
def at_rest(beads, b):
    """Bead b exactly at rest: v and a +0.0 (a -0.0 would turn into +0.0 in a step) and x not
    -0.0."""
    x, v, a = beads.x[b], beads.v[b], beads.a[b]
    return (v == 0.0 and a == 0.0 and math.copysign(1.0, v) > 0.0
            and math.copysign(1.0, a) > 0.0 and (x != 0.0 or math.copysign(1.0, x) > 0.0))


@njit(cache=True)
def moving_hull(beads):
    """First and last bead not at rest (first > last: none)."""
    n = beads.x.shape[0]
    lo = 0
    while lo < n and at_rest(beads, lo):
        lo += 1
    hi = n - 1
    while hi >= lo and at_rest(beads, hi):
        hi -= 1
    return lo, hi


@njit(cache=True)
def step_range(walls, ks, n):
    """The contacts the step's pass runs, ``counters.pass_lo .. pass_hi - 1``, and their
    segments ``seg_first .. seg_last``: those that finish the front's beads (bead b is
    finished at its right contact, the pass starting one contact before, whose left bead is
    at rest), every contact while the front is not known or the chain is one segment (a
    chain of at most :data:`SEGMENT` contacts is stepped whole); returns the number of beads
    they finish."""
    c, seg = ks.counters[0], ks.seg
    m = ks.closed.shape[0]
    lo, hi = c.front_lo, c.front_hi
    if lo < 0 or seg.count == 1:
        c.seg_first, c.seg_last, c.pass_lo, c.pass_hi = 0, seg.count - 1, 0, m
        return n
    if lo > hi:
        c.seg_first, c.seg_last, c.pass_lo, c.pass_hi = 0, -1, 0, 0
        return 0
    rshift = 0 if walls else 1  # bead b's contacts: b - rshift (left), b + 1 - rshift (right)
    c.pass_lo = max(lo - rshift, 0)
    c.pass_hi = min(hi + 1 - rshift, m - 1) + 1
    c.seg_first = c.pass_lo // seg.size
    c.seg_last = (c.pass_hi - 1) // seg.size
    return min(hi + 1, n) - lo


@njit(cache=True)
def advance_front(flags, params, start, new, ks, windows):
    """The front after a step into ``new``.  After the first step, the beads not at rest at
    its start (``start``: :func:`moving_hull` of it) or end, and one bead more on each side.
    After the others, the front takes in the step's event windows and their neighbours, then
    grows while its edge bead or the one beyond is not at rest.  A pulse's bead is always in
    it; with a base motion every bead is."""
    c = ks.counters[0]
    n = new.x.shape[0]
    if flags[BASE]:
        c.front_lo, c.front_hi = 0, n - 1
        return
    if c.front_lo < 0:
        lo, hi = moving_hull(new)
        if start[0] <= start[1]:
            lo, hi = (min(lo, start[0]), max(hi, start[1])) if lo <= hi else start
        if lo <= hi:
            lo, hi = lo - 1, hi + 1
    else:
        lo, hi = c.front_lo, c.front_hi
        for k in range(windows):
            lo, hi = min(lo, ks.windows[k, 0] - 1), max(hi, ks.windows[k, 1] + 1)
        lo, hi = max(lo, 0), min(hi, n - 1)
        if lo <= hi:
            while hi < n - 1 and not (at_rest(new, hi) and at_rest(new, hi + 1)):
                hi += 1
            while lo > 0 and not (at_rest(new, lo) and at_rest(new, lo - 1)):
                lo -= 1
    if flags[PULSE]:
        b = params.drive.bead
        lo, hi = (min(lo, b - 1), max(hi, b + 1)) if lo <= hi else (b - 1, b + 1)
    if lo > hi:  # every bead at rest
        c.front_lo, c.front_hi = n, n - 1
    else:
        c.front_lo, c.front_hi = max(lo, 0), min(hi, n - 1)


@njit(inline="always")
def advance_steps(flags, params, buffers, ks, nsteps, dt, run_segments, run_lanes):
    """Up to nsteps steps of dt from buffers[counters.current]: a pass over the chain, then
    the windows of the events located inside the step stepped alone (:func:`local_events`).
    Stops early on an error or when the event log is half full (counters.status).

    (One function: with the step in a function of its own, inlined, the loop ran 30 % slower
    on a 20-bead chain.)"""
    counters = ks.counters[0]
    copies = (buffer(buffers, 0), buffer(buffers, 1))
    for _ in range(nsteps):
        if counters.events > ks.log.time.shape[0] // 2:
            counters.status = EVENTS_FULL
            return
        t0 = counters.step * dt
        o = counters.current
        old, new = copies[o], copies[1 - o]
        start = moving_hull(old) if counters.front_lo < 0 else (0, -1)  # once in a run
        counters.bead_steps += step_range(flags[WALLS], ks, old.x.shape[0])
        counters.flagged = 0
        p1 = verlet_pass(flags, params, old, new, dt, t0, ks, run_segments)
        if counters.status != OK:
            counters.bad_time = t0 + dt
            return
        p0 = counters.power
        viscous, power, work, windows = 0.0, 0.0, 0.0, 0
        if flags[LOCATE] and counters.flagged > 0:
            viscous, power, work, windows = local_events(at_run_time(flags), params, old, new,
                                                         t0, dt, ks, run_lanes)
            if counters.status != OK:
                return
        advance_front(at_run_time(flags), params, start, new, ks, windows)
        counters.d_viscous += 0.5 * dt * (p0 + p1) + viscous
        counters.power = p1 + power
        counters.current = 1 - o
        if flags[PULSE] or flags[BASE]:  # the excitations' work, by the same rule
            pe = external_power(at_run_time(flags), params, new, t0 + dt, np.int64(0),
                                new.x.shape[0] - 1)
            counters.work += 0.5 * dt * (counters.ext_power + pe) + work
            counters.ext_power = pe
        counters.step += 1


@njit(inline="always")
def advance_frames(flags, params, buffers, ks, block, first, nframes, spf, dt,
                   run_segments, run_lanes):
    """Frames ``first .. first + nframes - 1`` (frame ``i`` ends at step ``i * spf``), each
    state at a frame's end copied into ``block`` row ``i - first`` (the beads of the activity
    front only, once it is known: ``block`` holds the beads at rest already, :func:`new_block`;
    every contact's state); at most ``counters.budget`` steps (when > 0; then
    ``counters.status = STEP_BUDGET`` inside a frame); returns the frames done
    (fewer on an error or a half-full event log: ``counters.status``; the steps of the
    unfinished frame done so far are kept, and a next call continues them)."""
    counters = ks.counters[0]
    step0 = counters.step
    for k in range(nframes):
        end = (first + k) * spf  # the frame's last step
        todo = end - counters.step
        if counters.budget > 0:
            todo = min(todo, counters.budget - (counters.step - step0))
        advance_steps(flags, params, buffers, ks, todo, dt, run_segments, run_lanes)
        if counters.status != OK:
            return k
        if counters.step < end:  # the budget ran out inside the frame
            counters.status = STEP_BUDGET
            return k
        c = counters.current
        lo, hi = 0, buffers.x.shape[1] - 1  # the beads not at rest: the front once known
        if counters.front_lo >= 0:
            lo, hi = counters.front_lo, counters.front_hi
        for i in range(lo, hi + 1):  # loops, not slices: no temporary arrays
            block.x[k, i] = buffers.x[c, i]
            block.v[k, i] = buffers.v[c, i]
            block.a[k, i] = buffers.a[c, i]
        for j in range(ks.closed.shape[0]):
            block.closed[k, j] = ks.closed[j]
        block.sums[k, 0] = counters.d_viscous
        block.sums[k, 1] = counters.d_hysteresis
        block.sums[k, 2] = counters.power
        block.sums[k, 3] = counters.work
        block.sums[k, 4] = counters.ext_power
        block.counts[k, 0] = counters.events
        block.counts[k, 1] = counters.substeps
        block.counts[k, 2] = counters.windows
        block.counts[k, 3] = counters.widened
        block.counts[k, 4] = counters.bead_steps
        block.counts[k, 5] = counters.front_lo
        block.counts[k, 6] = counters.front_hi
    return nframes


@njit(inline="always")
def segment_chunk(count, threads):
    """How many of a pass's ``count`` segments a thread claims at a time: about
    :data:`CLAIMS_PER_THREAD` claims a thread (few enough that taking them costs nothing
    beside the segments, small enough that the threads finish within a claim of each
    other), at least one."""
    return max(1, count // (CLAIMS_PER_THREAD * threads))


# ---- the entry point ----------------------------------------------------------------------
# A named tuple crosses from Python into compiled code about 1 us slower than a plain one (numba
# types it in Python), and the fast backend calls the loop once per block of frames (once per
# frame for long chains); so the records cross as plain tuples (`plain`) and are named again
# on the compiled side (`named_*`).
def plain(record):
    """A record (named tuples, nested) as plain tuples, for :func:`get_kernel`'s loop."""
    if isinstance(record, tuple):
        return tuple(plain(field) for field in record)
    return record


@njit(inline="always")
def named_params(p):
    """:class:`Params` from ``plain(params)``."""
    return Params(p[0], p[1], p[2], p[3], p[4], p[5], p[6], SchwarzConstants(*p[7]),
                  ForceTable(*p[8]), Mix(*p[9]), p[10], Drive(*p[11]))


@njit(inline="always")
def named_state(k):
    """:class:`KernelState` from ``plain(ks)``."""
    lanes = k[8]
    return KernelState(k[0], k[1], EventLog(*k[2]), k[3], Segments(*k[4]), Beads(*k[5]), k[6],
                       k[7], Lanes(lanes[0], EventLog(*lanes[1]), lanes[2], lanes[3]), k[9])


_KERNELS: dict = {}


def get_kernel(flags: Flags):
    """The compiled stepping loop of one variant (compiled on first use, then cached on disk by
    numba), ``advance(plain(params), plain(buffers), plain(ks), plain(block), first, nframes,
    spf, dt) -> frames done``: from ``buffers`` (:class:`Beads` of ``[2, n]`` arrays) at
    ``counters.current``, steps of ``dt`` to the ends of frames ``first .. first + nframes -
    1`` (frame ``i`` ends at step ``i * spf``), each frame's state into ``block``
    (:func:`advance_frames`); stops early on an error or when the event log is half full
    (``counters.status``)."""
    flags = Flags(*(bool(f) for f in flags))
    if flags not in _KERNELS:
        _KERNELS[flags] = _without_refcounts(flags)
    return _KERNELS[flags]


def _without_refcounts(flags):
    """The variant's loop compiled without numba's reference counting (``_nrt=False``).

    Every array the loop takes out of a record, a tuple or a buffer costs an atomic increment
    and decrement of its reference count: on a 20-bead chain they were ~80 % of a step (1150
    ns of it for 2 beads, against 43 ns without).  The loop allocates nothing, and the arrays
    it is given are held by the caller for the call, so it needs no counting.  Should a
    variant need numba's runtime after all (it then fails to compile, before running), it is
    compiled with it."""
    from numba.core.errors import NumbaError

    lean = _make_advance(flags, nrt=False)

    def advance(*args):
        try:
            done = lean(*args)
        except NumbaError as exc:
            if "NRT required" not in str(exc):
                raise
            _KERNELS[flags] = counted = _make_advance(flags, nrt=True)
            return counted(*args)
        _KERNELS[flags] = lean
        return done

    return advance


def variant_jit(tag: str, **options):
    """``njit(**options)`` of a variant's closure under a name of its own (``tag`` appended).

    numba names a compiled function by its qualified name, its argument types and a counter
    of the process that compiled it; the variant's flags reach ``one_segment`` and
    ``run_segments`` through the closure, not as an argument.  Two variants compiled by two
    processes with the same counter then had the same symbol, and a process that loaded
    both from the disk cache linked the second variant's ``advance`` to the first one's
    ``run_segments``: the other variant's physics, or a segmentation fault when it read
    arrays this one leaves empty (chains of more than SEGMENT contacts, whose pass runs
    through ``run_segments``)."""
    def compile_as_variant(fn):
        fn.__name__ = f"{fn.__name__}_{tag}"
        fn.__qualname__ = f"{fn.__qualname__}_{tag}"
        return njit(**options)(fn)

    return compile_as_variant


def _make_advance(flags, nrt: bool):
    literal = tuple(flags)  # typed as literal booleans (see PULSE)
    tag = "".join("1" if f else "0" for f in flags)  # the variant's own names (variant_jit)

    @variant_jit(tag, cache=True)
    def one_segment(params, old, xn, vn, an, closed, seg, s):
        """Segment s of a pass (:func:`segment_pass`), its results into row s of
        ``Segments.real`` and ``.ints``.  A call of its own in :func:`run_segments`'s
        parallel loop: inlined there, numba's array analysis of the loop fails on it."""
        h, t0, size, real, ints, flag, ev_real, ev_contact, kicked, kick, branch, jlo, jhi = seg
        r, i = segment_pass(literal, params, old, xn, vn, an, closed,
                            (h, t0, size, flag, ev_real, ev_contact, kicked, kick, branch, jlo,
                             jhi), s)
        for k in range(5):
            real[s, k] = r[k]
        for k in range(4):
            ints[s, k] = i[k]

    @variant_jit(tag, cache=True, parallel=flags.threaded)
    def run_segments(params, old, new, h, t0, ks):
        """Every segment of a pass (:func:`segment_pass`), on the threads numba has
        (``numba.set_num_threads``) in a threaded variant, in order otherwise, joined by
        :func:`merge_segments`; returns the damping power at the step's end.  The threads
        take the segments a few at a time from ``ks.sharing`` (:func:`segment_chunk`)
        until none is left, so that a thread whose segments cost more (kicks and flagged
        contacts are not spread evenly along an active chain) or that the machine slows
        does not keep the other waiting.  numba's parallel loop takes arrays and numbers
        from outside, not records: they are taken apart before it and put together again
        in it."""
        gap, damping, k1, k3, delta_off, delta_max, below, law, table, mix, c_s, drive = params
        l0, l1, l2, l3, l4 = law
        t_coef, t_base, t_scale, t_last, t_step = table
        m0, m1, m2, m3, m4, m5, m6 = mix
        d0, d1, d2, d3, d4, d5 = drive
        xo, vo, ao = old
        xn, vn, an = new
        closed = ks.closed
        size, count, real, ints, flag, ev_real, ev_contact, kicked, kick, branch = ks.seg
        jlo, jhi = ks.counters[0].pass_lo, ks.counters[0].pass_hi
        first, last = ks.counters[0].seg_first, ks.counters[0].seg_last
        if not literal[THREADED] or last - first + 1 < PARALLEL_SEGMENTS:
            # one thread, or a few segments (no threads to wake): in order
            for s in range(first, last + 1):
                one_segment(params, old, xn, vn, an, closed,
                            (h, t0, size, real, ints, flag, ev_real, ev_contact, kicked,
                             kick, branch, jlo, jhi), s)
            return merge_segments(literal, params, old, new, h, t0 + h, ks)
        sharing = ks.sharing
        sharing[SHARE_SEGMENT] = first
        threads = max(sharing[SHARE_THREADS], 1)  # (each claims until none is left)
        chunk = segment_chunk(last - first + 1, threads)
        for _ in prange(threads):
            p = Params(gap, damping, k1, k3, delta_off, delta_max, below,
                       SchwarzConstants(l0, l1, l2, l3, l4),
                       ForceTable(t_coef, t_base, t_scale, t_last, t_step),
                       Mix(m0, m1, m2, m3, m4, m5, m6), c_s,
                       Drive(d0, d1, d2, d3, d4, d5))
            s0 = fetch_add(sharing, SHARE_SEGMENT, chunk)
            while s0 <= last:
                for s in range(s0, min(s0 + chunk, last + 1)):
                    one_segment(p, Beads(xo, vo, ao), xn, vn, an, closed,
                                (h, t0, size, real, ints, flag, ev_real, ev_contact, kicked,
                                 kick, branch, jlo, jhi), s)
                s0 = fetch_add(sharing, SHARE_SEGMENT, chunk)
        return merge_segments(literal, params, old, new, h, t0 + h, ks)

    @variant_jit(tag, cache=True, parallel=flags.threaded)
    def run_lanes(params, old, new, t0, dt, ks, count):
        """The lanes' windows still to be stepped (:func:`step_lane`), on the threads numba
        has in a threaded variant when there are at least :data:`PARALLEL_WINDOWS` (each
        thread taking the next lane from ``ks.sharing`` until none is left), in order
        otherwise (the same results).  As in ``run_segments``, the records are taken apart
        before the parallel loop and put together again in it."""
        rt = at_run_time(literal)
        shared = (ks.closed, ks.counters, ks.chatter, ks.seg.branch, ks.local.x, ks.local.v,
                  ks.local.a, ks.windows, ks.window_sums)
        lanes = ks.lanes
        log = lanes.log
        lane_arrays = (lanes.counters, log.time, log.contact, log.kind, log.loss,
                       lanes.switching, lanes.chatter)
        if not literal[THREADED] or count < PARALLEL_WINDOWS:
            for g in range(LANES):
                step_lane(rt, params, old, (new.x, new.v, new.a), shared, lane_arrays, g,
                          count, t0, dt)
            return
        gap, damping, k1, k3, delta_off, delta_max, below, law, table, mix, c_s, drive = params
        l0, l1, l2, l3, l4 = law
        t_coef, t_base, t_scale, t_last, t_step = table
        m0, m1, m2, m3, m4, m5, m6 = mix
        d0, d1, d2, d3, d4, d5 = drive
        xo, vo, ao = old
        xn, vn, an = new
        closed, counters, chatter, memo, lx, lv, la, windows, sums = shared
        lc, time, contact, kind, loss, switching, lchat = lane_arrays
        sharing = ks.sharing
        sharing[SHARE_LANE] = 0
        for _ in prange(max(sharing[SHARE_THREADS], 1)):
            p = Params(gap, damping, k1, k3, delta_off, delta_max, below,
                       SchwarzConstants(l0, l1, l2, l3, l4),
                       ForceTable(t_coef, t_base, t_scale, t_last, t_step),
                       Mix(m0, m1, m2, m3, m4, m5, m6), c_s,
                       Drive(d0, d1, d2, d3, d4, d5))
            g = fetch_add(sharing, SHARE_LANE, 1)
            while g < LANES:
                step_lane(Flags(*literal), p, Beads(xo, vo, ao), (xn, vn, an),
                          (closed, counters, chatter, memo, lx, lv, la, windows, sums),
                          (lc, time, contact, kind, loss, switching, lchat), g, count, t0, dt)
                g = fetch_add(sharing, SHARE_LANE, 1)

    @variant_jit(tag + ("_counted" if nrt else ""), cache=True, _nrt=nrt, nogil=True)
    def advance(params, buffers, ks, block, first, nframes, spf, dt):
        return advance_frames(literal, named_params(params), Beads(*buffers), named_state(ks),
                              FrameBlock(*block), first, nframes, spf, dt, run_segments,
                              run_lanes)

    variant_cache(run_segments, flags)
    variant_cache(run_lanes, flags)
    variant_cache(advance, (*flags, nrt))
    return advance


def variant_cache(dispatcher, flags):
    """Let numba's disk cache find a variant's compiled ``advance`` and ``run_segments`` in
    the next process.

    numba keys a cached closure by its cell contents, pickled, and a compiled function in a
    cell (``one_segment``, ``run_segments``) pickles with UUIDs drawn at random in each
    process: the variant would be compiled anew in every process.  Its key here is the
    function's code and the variant's flags instead (the cache still checks this file's
    time stamp, so an edit of the kernel invalidates it).  Uses numba's
    ``Dispatcher._cache``; without it a variant is only compiled more often."""
    from numba.core.caching import FunctionCache

    class VariantCache(FunctionCache):
        def _index_key(self, sig, codegen):
            code = hashlib.sha256(self._py_func.__code__.co_code).hexdigest()
            return sig, codegen.magic_tuple(), (code, repr(tuple(flags)))

    if hasattr(dispatcher, "_cache"):
        dispatcher._cache = VariantCache(dispatcher.py_func)
