"""What every backend yields, and the errors it raises.

A backend is constructed from a resolved scene and iterated: ``for frame in backend.frames()``
yields one :class:`Frame` per stored output time, the first at ``t = 0``;
``backend.blocks()`` yields the same frames as blocks of consecutive ones (:class:`Frames`),
which the driver iterates.  Each frame carries
the contact events since the previous frame.  The ledger (energies) is computed from the frame
by the shared :class:`~mdgran.model.chain.ChainModel`, so every backend's ledger means the same
thing. Writing output, progress and energy checks are reporters (see :mod:`mdgran.simulation`), not
the backend's business.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

CLOSE, OPEN = 1, 0

# Declared ledger bounds (Backend.ledger_bound), calibrated on the reference (DOP853): ledger
# error / E_s / tol = 0.008-0.23 on the built-in and hard scenes at tol 1e-8, 0.67 on
# hard/undamped-long to t = 400 (a drift: 5.6e-6 E_imp to t = 1e5), and 4-14 on hard/grazing
# at tol 1e-6 to 1e-12; below tol ~1e-12 it stops shrinking (micro-star: 1.2e-12 E_s at tol
# 1e-14).  Fixed-step constants are the backends' ``ledger_c``.
#: tolerance-controlled backends: multiple of the tolerance, per unit of the energy scale
#: (3x over hard/grazing's 13.5 tol)
LEDGER_TOL_MULTIPLE = 40.0
#: ... below this tolerance, event location and round-off set the error, not the tolerance
LEDGER_TOL_FLOOR = 1e-12
#: ... the bound grows as 1 + T / LEDGER_TOL_TIME with the run's duration T (20x over the
#: drift of hard/undamped-long to t = 1e5)
LEDGER_TOL_TIME = 400.0
#: fixed-step backends: no run is complete with a ledger error above this share of E_s
#: (correct runs at the scenes' dt: up to 1.0e-2 E_s, hard/jkr-force at first order)
LEDGER_CAP = 0.03
#: round-off floor, in machine epsilons of (largest ledger term + N_c eta p) (hard/tiny:
#: 1.4 of them measured on every backend)
LEDGER_ROUNDOFF = 20.0


class IntegrationError(RuntimeError):
    """A run failed (blow-up, step collapse, out-of-table compression): exit status 1.

    The message is one line naming the time, and the bead or contact where known.
    """


@dataclass
class Event:
    time: float
    contact: int  # contract numbering: contact i joins bead i-1 and bead i
    kind: int  # CLOSE = 1, OPEN = 0


class Events(Sequence):
    """Contact events in order, as three arrays: ``time`` [k], ``contact`` [k] int64
    (contract numbering), ``kind`` [k] int8 (CLOSE, OPEN).  A sequence of :class:`Event`:
    an item is made when it is asked for, a slice is an ``Events`` of views.  A long active
    chain has ~1e5 events a block: made one object each, they cost ~0.9 us of CPU apiece and
    walks of Python's garbage collector, so blocks carry them as arrays and writers take the
    arrays."""

    __slots__ = ("time", "contact", "kind")

    def __init__(self, time=(), contact=(), kind=()):
        self.time = np.asarray(time, dtype=float)
        self.contact = np.asarray(contact, dtype=np.int64)
        self.kind = np.asarray(kind, dtype=np.int8)

    @classmethod
    def of(cls, events) -> "Events":
        """``events`` (an ``Events``, or any iterable of :class:`Event`) as ``Events``."""
        if isinstance(events, Events):
            return events
        events = list(events)
        return cls([e.time for e in events], [e.contact for e in events],
                   [e.kind for e in events])

    @classmethod
    def join(cls, parts) -> "Events":
        """The events of ``parts`` (each as :meth:`of` takes it) one after another."""
        parts = [cls.of(p) for p in parts]
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, name) for p in parts] or [[]])
                     for name in ("time", "contact", "kind")))

    def __len__(self) -> int:
        return self.time.shape[0]

    def __getitem__(self, i):
        if isinstance(i, slice):
            return Events(self.time[i], self.contact[i], self.kind[i])
        return Event(float(self.time[i]), int(self.contact[i]), int(self.kind[i]))

    def __iter__(self) -> Iterator[Event]:
        return map(Event, self.time.tolist(), self.contact.tolist(), self.kind.tolist())

    def __add__(self, other) -> "Events":
        return Events.join((self, other))

    def __radd__(self, other) -> "Events":
        return Events.join((other, self))

    def __eq__(self, other) -> bool:
        """Equal to any sequence of the same :class:`Event` s in the same order."""
        if not isinstance(other, Sequence) or len(other) != len(self):
            return False
        return list(self) == list(other)

    __hash__ = None

    def __repr__(self) -> str:
        return f"Events({len(self)})"


@dataclass(slots=True)
class Frame:
    """One stored output time.  ``block``: None, or the :class:`Frames` this frame is row
    ``block_row`` of (a backend that makes frames by blocks, the fast one); the frame's
    ledger is then the block's row (computed with the block's).  A frame made from another
    with other states (``dataclasses.replace``) must set ``block=None``."""

    step: int
    time: float
    x: np.ndarray  # [n] displacement
    v: np.ndarray  # [n] velocity
    closed: np.ndarray  # [n_contacts] bool
    dissipated_viscous: float
    dissipated_hysteresis: float
    events: Sequence = field(default_factory=list)  # Event s in (previous frame time, time]
    block: "Frames | None" = None
    block_row: int = 0
    external_work: float = 0.0  # work of the force pulse and base motion (mdgran.model.drive)

    def ledger(self, model) -> dict:
        """The energy ledger of this frame (:meth:`~mdgran.model.chain.ChainModel.ledger` of
        ``model``, the backend's), from its block's if it has one (bitwise the same)."""
        if self.block is not None:
            return self.block.ledger_row(self.block_row)
        return model.ledger(self.x, self.v, self.closed, self.dissipated_viscous,
                            self.dissipated_hysteresis, self.external_work, self.time)


class Frames:
    """``F`` consecutive frames as arrays: what :meth:`Backend.blocks` yields and the driver
    hands its reporters (``report_block``; frame by frame to a reporter with ``report``
    only).

    ``step`` [F] int, ``time`` [F]; ``x``, ``v`` [F, n]; ``closed`` [F, n_contacts] bool;
    ``dissipated_viscous``, ``dissipated_hysteresis`` [F]; ``external_work`` [F] or None
    (no excitation: 0); ``events``: the events of the F frames in order (:class:`Events`;
    a backend may give any sequence of :class:`Event`), the first ``event_ends[k]`` of them in
    frames ``0 .. k``.  The arrays are the block's own: nobody
    changes them after.  :meth:`ledger` is computed once, for every frame together
    (:meth:`~mdgran.model.chain.ChainModel.ledger_block`: bitwise each frame's own ledger, or, with
    ``moved``, equal to it to round-off).

    ``moved``: None, or the 0-based bead range ``(lo, hi)`` (``lo .. hi - 1``) outside which,
    in every frame of the block, every bead is at rest at ``x = v = +0.0`` and every contact
    that joins two such beads (or a bead and a wall) is in its initial state (a long chain
    struck at one end: :mod:`mdgran.rest_blocks`).  The ledger, the writer and the checks
    then cost the beads in it, not the chain."""

    __slots__ = ("model", "step", "time", "x", "v", "closed", "dissipated_viscous",
                 "dissipated_hysteresis", "external_work", "events", "event_ends",
                 "moved", "_ledger", "_rows", "_contacts")

    def __init__(self, model, step, time, x, v, closed, dissipated_viscous,
                 dissipated_hysteresis, external_work, events, event_ends, ledger=None,
                 moved=None):
        self.moved = moved
        self.model = model
        self.step, self.time, self.x, self.v, self.closed = step, time, x, v, closed
        self.dissipated_viscous = dissipated_viscous
        self.dissipated_hysteresis = dissipated_hysteresis
        self.external_work = external_work
        self.events, self.event_ends = Events.of(events), event_ends
        self._ledger, self._rows, self._contacts = ledger, None, None

    @classmethod
    def of(cls, frame: Frame, model) -> "Frames":
        """The block of the one ``frame`` (its ledger: ``frame.ledger(model)``)."""
        led = {k: np.array([v]) for k, v in frame.ledger(model).items()}
        return cls(model, np.array([frame.step]), np.array([frame.time]), frame.x[None],
                   frame.v[None], frame.closed[None], np.array([frame.dissipated_viscous]),
                   np.array([frame.dissipated_hysteresis]), np.array([frame.external_work]),
                   Events.of(frame.events), np.array([len(frame.events)]), ledger=led)

    def __len__(self) -> int:
        return len(self.time)

    def ledger(self) -> dict:
        """``{term: [F] array}``: the energy ledger of every frame (computed on first use)."""
        if self._ledger is None:
            t = self.time if self.external_work is not None else None
            self._ledger = self.model.ledger_block(
                self.x, self.v, self.closed, self.dissipated_viscous,
                self.dissipated_hysteresis, self.external_work, t, moved=self.moved)
        return self._ledger

    def contact_series(self) -> dict:
        """``{"compression": [F, n_contacts], "force": [F, n_contacts]}``: each frame's
        contact compressions and forces (``ChainModel.compressions`` and
        :meth:`~mdgran.model.chain.ChainModel.contact_forces`: the force the backend integrates),
        computed on first use."""
        if self._contacts is None:
            m = self.model
            self._contacts = {
                "compression": np.array([m.compressions(x) for x in self.x]),
                "force": np.array([m.contact_forces(x, v, c)
                                   for x, v, c in zip(self.x, self.v, self.closed)])}
        return self._contacts

    def ledger_row(self, k: int) -> dict:
        """Frame ``k``'s ledger as :meth:`~mdgran.model.chain.ChainModel.ledger` gives it
        (floats)."""
        if self._rows is None:
            led = self.ledger()
            names = tuple(led)
            self._rows = [dict(zip(names, row))
                          for row in zip(*(led[name].tolist() for name in names))]
        return self._rows[k]

    def frame_events(self, k: int) -> Events:
        """The events of frame ``k``: those in (frame ``k - 1``'s time, its time]."""
        lo = int(self.event_ends[k - 1]) if k else 0
        return self.events[lo:int(self.event_ends[k])]

    def frame(self, k: int) -> Frame:
        """Frame ``k`` (its arrays are views of the block's rows)."""
        work = 0.0 if self.external_work is None else float(self.external_work[k])
        return Frame(int(self.step[k]), float(self.time[k]), self.x[k], self.v[k],
                     self.closed[k], float(self.dissipated_viscous[k]),
                     float(self.dissipated_hysteresis[k]), self.frame_events(k), self, k, work)


#: a fixed-step backend resolves a force pulse of at least this many steps, and a base motion
#: whose samples are at least this many steps apart (a pulse's work is then within 1.6 % of the
#: reference's: c (dt / T)^2, c = 0.15-1.64 measured over 10-60 steps and starts, 1.64 for a
#: pulse that starts on a step)
MIN_STEPS = 10


def steps_per_frame(dt: float, interval: float) -> int:
    """Steps of ``dt`` in one output interval ``run.output_interval`` (same time unit), which
    ``dt`` must divide to a relative 1e-9; else :class:`~mdgran.model.scene.SceneError` on
    ``run.dt``."""
    from ..model.scene import SceneError

    steps = int(round(interval / dt))
    if steps < 1 or abs(steps * dt - interval) > 1e-9 * interval:
        raise SceneError("run.dt", f"must divide run.output_interval = {interval} (dt = {dt})")
    return steps


def check_excitation_steps(model, dt: float, backend: str):
    """Refuse (:class:`~mdgran.model.scene.SceneError`) a force pulse shorter than
    :data:`MIN_STEPS` steps of ``dt`` (``pulse.duration``), or a base motion whose samples
    are closer than that (``base.interval``): a fixed-step backend samples the excitation at
    its steps and steps over what happens between them (a pulse of one step's length did no
    work, a one-sample spike of the base none, and the run was complete)."""
    from ..model.scene import SceneError

    drive = model.drive
    if drive is None:
        return
    what = (("pulse.duration", drive.pulse.duration) if drive.pulse is not None else None,
            ("base.interval", drive.base.step) if drive.base is not None else None)
    for key, length in (w for w in what if w is not None):
        if length < MIN_STEPS * dt:
            raise SceneError(key, f"must be at least {MIN_STEPS} steps ({MIN_STEPS * dt:g} at "
                             f"run.dt = {dt:g}) on the {backend} backend, not {length:g}; make "
                             "run.dt smaller or use the reference backend")


def scene_features(scene, model) -> list:
    """``(feature, key, what)`` of each feature beyond the paper's chain that the scene uses:
    ``"mixture"`` (unlike beads or a striker), ``"thermal"`` (initial random velocities),
    ``"substrate damping"``."""
    out = []
    if model.mixed:
        key = "striker.diameter" if scene.striker.diameter is not None else "beads"
        out.append(("mixture", key, "chains of unlike beads ([beads], [striker])"))
    if model.temperature:
        out.append(("thermal", "thermal.temperature", "initial random velocities"))
    if model.substrate_damping:
        out.append(("substrate damping", "substrate.damping", "substrate damping"))
    if model.drive is not None and model.drive.pulse is not None:
        out.append(("pulse", "pulse.amplitude", "a force pulse"))
    if model.drive is not None and model.drive.base is not None:
        out.append(("base", "base.kind", "a base motion"))
    return out


#: every feature of :func:`scene_features`
ALL_FEATURES = frozenset({"mixture", "thermal", "substrate damping", "pulse", "base"})


class Backend:
    """Base class: holds the scene and model; subclasses implement :meth:`frames`."""

    name = "base"
    #: every option the backend's constructor takes (``run(scene, name, **options)``); others
    #: are rejected.  The default is the reference's: its adaptive ``tolerance``.
    accepted_options: tuple = ("tolerance",)
    #: the scene features beyond the paper's chain (:func:`scene_features`) that the backend
    #: runs; it refuses a scene with any other before running
    supports: frozenset = frozenset()

    def __init__(self, scene, **options):
        from ..model.chain import model_from_scene
        from ..model.scene import SceneError

        unknown = [k for k in options if k not in self.accepted_options]
        if unknown:
            raise SceneError(unknown[0], f"unknown option of backend {self.name!r}; allowed: "
                             + (", ".join(self.accepted_options) or "none"))
        self.scene = scene
        self.model = model_from_scene(scene)
        missing = [f for f in scene_features(scene, self.model) if f[0] not in self.supports]
        if missing:
            _, key, what = missing[0]
            raise SceneError(key, f"backend {self.name!r} does not run {what} yet; the "
                             "reference and fast backends do")
        if self.model.mixed:  # refused here, before a run, if the chain has no equilibrium
            self.model.initial_state(1, 0.0)
        self.options = options
        self.stats: dict = {}

    #: order of convergence in ``run.dt`` for fixed-step backends (used for error estimates)
    order = 2

    def refinement(self, scene=None):
        """Overrides for a more accurate run of the same scene (default: this backend's), and
        the factor that turns the difference between the two runs into an error estimate of
        the nominal one.  Called on the backend as constructed: its options may set its order.

        Fixed-step backends of order ``p`` halve ``run.dt``: Richardson gives
        ``error(dt) ~ |x_dt - x_dt/2| * 2^p / (2^p - 1)``.
        """
        dt = float((self.scene if scene is None else scene).run.dt)
        return [("run.dt", dt / 2)], 2.0**self.order / (2.0**self.order - 1.0)

    # ---- declared energy-ledger bound (a run that exceeds it is not "complete") -----------
    #: fixed-step backends: ``{order: C}`` of the bound ``C * dt**order`` (see
    #: :meth:`ledger_bound`); None for a backend that declares no fixed-step bound
    ledger_c: dict | None = None

    def energy_scale(self, scale: float) -> float:
        """``E_s = scale + N_c * E_a`` (units eta p): what the chain holds, the impulse energy
        ``scale`` plus the adhesion energy of its ``N_c`` contacts, ``E_a = max(W_loop, 1)``
        for an adhesive law (its energy unit eta p, or the energy of one snap-off if larger;
        a DMT contact loses nothing on a snap-off but still stores energies of order eta p),
        0 for Hertz.  Errors of every backend scale with ``E_s``: at small impulses (sweep
        v0 = 1, hard/grazing, DMT scenes) the adhesion energy, not ``E_imp``, sets them."""
        m = self.model
        if m.law.kind == "hertz":
            return scale
        return scale + m.n_contacts * max(float(np.max(m.loop_energy)), 1.0)

    def ledger_roundoff(self, scale: float, term_max: float) -> float:
        """Round-off floor, relative to ``scale``: ``LEDGER_ROUNDOFF * eps * (M + N_c) /
        scale``.  The ledger sums terms up to ``M = term_max`` (largest ``|term|`` over the run),
        and each of the ``N_c`` contact energies is a difference of numbers of order eta p
        (the law's unit), so the total carries a few eps of ``M + N_c`` whatever the
        integrator (hard/tiny, E_imp = 5e-13: 1.4e-2 of E_imp on every backend)."""
        n_c = self.model.n_contacts
        return LEDGER_ROUNDOFF * np.finfo(float).eps * (term_max + n_c) / scale

    def ledger_model(self) -> float:
        """The integrator's part of the bound, per unit of :meth:`energy_scale`.

        Fixed-step (``self.dt`` and ``ledger_c``): ``min(C * dt**order, LEDGER_CAP)``.  The
        cap is a policy, not an error model: a fixed-step run whose ledger is off by more than
        ``LEDGER_CAP`` of the energy scale is not reported complete, even where it is on its
        ``C dt**order`` curve (micro-star on fast at dt = 0.25: 0.12 E_imp).  A backend with
        neither declares no bound (``inf``); the reference overrides this with its
        tolerance rule.
        """
        dt = getattr(self, "dt", None)
        if dt is None or not self.ledger_c or self.order not in self.ledger_c:
            return math.inf
        return min(self.ledger_c[self.order] * float(dt) ** self.order, LEDGER_CAP)

    def ledger_bound(self, scale: float, term_max: float) -> float:
        """The declared bound of ``max_t |E(t) - E0| / scale`` (the driver's ledger error,
        ``scale`` = E_imp): ``ledger_model() * E_s / scale + ledger_roundoff(scale, M)``."""
        return (self.ledger_model() * self.energy_scale(scale) / scale
                + self.ledger_roundoff(scale, term_max))

    def frames(self, resume: dict | None = None) -> Iterator[Frame]:  # pragma: no cover
        """Yield frames from t = 0, or from just after a checkpoint (``resume``)."""
        raise NotImplementedError

    def blocks(self, resume: dict | None = None) -> Iterator[Frames]:
        """:meth:`frames` as blocks of consecutive frames (what the driver iterates): here
        one frame a block; a backend that computes frames by blocks yields them whole.  After
        a block, :meth:`checkpoint_state` is the state at its last frame."""
        for frame in self.frames(resume):
            yield Frames.of(frame, self.model)

    def checkpoint_state(self) -> dict | None:
        """The state to continue from the last yielded frame, or None if the backend cannot
        checkpoint (then runs are not resumable).  A flat dict of arrays and JSON scalars with
        at least ``i_out`` (the last frame's index); stored opaquely
        (:mod:`mdgran.output.checkpoint`) and handed back to :meth:`frames` as ``resume``."""
        return None

    @property
    def can_checkpoint(self) -> bool:
        return type(self).checkpoint_state is not Backend.checkpoint_state

    def output_times(self) -> np.ndarray:
        run = self.scene.run
        dt_out = float(run.output_interval)
        n_out = int(np.floor(float(run.duration) / dt_out + 1e-9))
        return dt_out * np.arange(n_out + 1)
