"""The fast backend: fixed-step velocity Verlet with located contact events, compiled (numba).

The method (details and equations in :mod:`mdgran.backends.fast_kernel`):

* velocity Verlet at ``run.dt`` (which must divide ``run.output_interval``), the unilateral
  damping force evaluated with a predicted end-of-step velocity, the viscous dissipation
  ``D_viscous`` accumulated by the trapezoid rule over each (sub)step;
* every contact event inside a step (close when ``delta`` rises through 0, open when a closed
  contact's ``delta`` falls through the law's ``delta_off``) is located inside the step (the
  positions of a Verlet step are a parabola in the elapsed time, so the root is in closed
  form), the step is split there, the contact switches (``D_hysteresis += V(delta(te))`` on
  opening, as the reference does) and the rest of the step continues in the new state.  This
  keeps the error second order in ``dt`` across snap events (``order = 2``);
* ``locate_events=False`` gives plain step-quantized Verlet instead (switch at the end of the
  step, as a fixed-step MD code does: first order through events), for comparison.

Options (``run(scene, "fast", **options)``): ``locate_events`` (True), ``contact_eval``
(``"table"``: :class:`~mdgran.model.contact.ContactTable`, a cubic spline in ``sqrt(delta -
delta_min)`` on ``table_points`` nodes (its default if None) up to ``delta_max``; ``"exact"``:
Newton inversion of the law at every evaluation, slower), ``dt`` (overrides ``run.dt``).  A compression beyond ``delta_max``
stops the run with :class:`IntegrationError`.

Frames, events and checkpoints follow the reference backend: a frame at every output time
(the first at ``t = 0``, after opening contacts that sit on their snap-off point moving
outward), each with the events since the previous frame (contract numbering); a checkpoint
is the whole state at the last frame, and a resumed run is bitwise identical to an
uninterrupted one.  One call of the compiled loop runs a block of frames (about
``BLOCK_BEAD_STEPS`` bead-steps, at least one frame) and copies each frame's state into a
:class:`~mdgran.backends.fast_kernel.FrameBlock`; :meth:`FastBackend.blocks` (what the driver
iterates) yields its rows as one :class:`~mdgran.backends.base.Frames`, so a small chain's
frames cost no Python each; :meth:`FastBackend.frames` unpacks them.

Example::

    from mdgran.model.scene import load_scene
    from mdgran.simulation import run
    res = run(load_scene("micro-star", [("run.duration", 50.0)]), "fast")
"""
from __future__ import annotations

import math
import os
import time as _time
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache

import numba
import numpy as np

from ..model.contact import ContactTable
from ..model.contact_scalar import SING_BAND, schwarz_constants
from ..model.scene import SceneError
from . import fast_kernel as fk
from .base import (ALL_FEATURES, Backend, Events, Frame, Frames, IntegrationError,
                   check_excitation_steps, steps_per_frame)

EVENT_BUFFER = 65536
#: bead-steps per call of the compiled loop, at least one frame (a 20-bead chain runs ~5000
#: frames of 10 steps per call, handed over as one block); a checkpoint falls between calls
BLOCK_BEAD_STEPS = 1_000_000
#: ... and at most about this many seconds a call (its step budget, from the time the calls
#: so far took per step): an interrupt or a SIGTERM is honoured between calls, and events can
#: make a step of an active chain cost many nominal bead-steps
CALL_SECONDS = 0.5


#: distinct pair laws whose force tables the fast backend holds (unlike beads); more (random
#: diameters with contact.lambda: one law per pair) need the exact law
MAX_LAW_TABLES = 255


#: the pid of the process whose threads ran on GNU OpenMP (numba's "omp" layer), if any
_openmp_pid = None


def note_threads_ran() -> None:
    """Remember that this process ran the pass on numba's threads (after the first run)."""
    global _openmp_pid
    if _openmp_pid is None and numba.threading_layer() == "omp":
        _openmp_pid = os.getpid()


def usable_threads(threads: int) -> int:
    """Threads for the pass: ``threads``, or for 0 every core this process may use; at most
    numba's pool (``NUMBA_NUM_THREADS``).  One in a process forked from one whose threads ran
    on GNU OpenMP, which cannot start threads again after a fork (it would stop the process:
    "fork() called from a process already using GNU OpenMP"); the result is the same."""
    if threads < 0:
        raise SceneError("run.threads", f"must be an integer >= 0, not {threads}")
    if _openmp_pid is not None and _openmp_pid != os.getpid():
        return 1
    if threads == 0:
        threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") \
            else (os.cpu_count() or 1)
    return max(1, min(threads, numba.config.NUMBA_NUM_THREADS))


def rest_displacement(x: np.ndarray):
    """What the beads at rest of a run starting from displacements ``x`` hold while they stay
    at rest (they are not stepped: :func:`~mdgran.backends.fast_kernel.advance_front`): None
    when every ``x`` is ``+0.0`` (then frames start as zeros and cost the beads that move),
    else a copy of ``x`` (unlike beads between walls start from their equilibrium)."""
    if not np.asarray(x).view(np.uint64).any():
        return None
    return np.array(x, dtype=float)


@lru_cache(maxsize=8)
def contact_table(law, points: int | None, delta_max: float) -> tuple:
    """``(ContactTable, its error())`` of ``law`` on ``points`` nodes (ContactTable's default
    if None) up to ``delta_max`` (``p``), built once per process for each of them (the table
    depends on these alone): a sweep's cases share their law, and the table and its error
    took 20 ms of each case.  Shared: the caller must not change them.  (A chain of unlike
    beads builds its pair laws' tables per run: up to 255 of them, too many to keep.)"""
    table = (ContactTable(law, delta_max=delta_max) if points is None
             else ContactTable(law, int(points), delta_max))
    return table, table.error()


class _Done:
    """A call already made, as a future of it."""

    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


class FastBackend(Backend):
    """Fixed-step velocity Verlet with located (or step-quantized) contact events."""

    name = "fast"
    order = 2
    accepted_options = ("locate_events", "contact_eval", "table_points", "delta_max", "dt",
                        "threads")
    #: ledger bound ``C dt**order`` per unit of the energy scale (Backend.ledger_model):
    #: measured C (ledger error / E_s / dt**order) up to 4.3 located (the 91-case
    #: paper-robustness sweep at dt = 0.0025, largest at v0 = 64; built-in and hard scenes
    #: 1.4-3.3), up to 1.0 step-quantized (hard/jkr-force at dt = 0.01): 3.5x and 4x margins
    ledger_c = {2: 15.0, 1: 4.0}
    supports = ALL_FEATURES

    def __init__(self, scene, locate_events: bool = True, contact_eval: str = "table",
                 table_points: int | None = None, delta_max: float = 100.0, **options):
        super().__init__(scene, **options)
        run = scene.run
        self.dt = float(options.get("dt", run.dt))
        spf = steps_per_frame(self.dt, float(run.output_interval))
        check_excitation_steps(self.model, self.dt, self.name)
        if contact_eval not in ("table", "exact"):
            raise SceneError("contact_eval", f"must be 'table' or 'exact', not {contact_eval!r}")
        self.steps_per_frame = spf
        self.threads = usable_threads(int(options.get("threads", run.threads)))
        self.locate = bool(locate_events)
        if not self.locate:
            self.order = 1
        m = self.model
        law = m.law
        self.table, table_error = contact_table(law, table_points, float(delta_max))
        table = fk.ForceTable(np.ascontiguousarray(self.table.f_coef, dtype=float).ravel(),
                              float(self.table.base), float(self.table._scale),
                              float(self.table.n - 1), float(self.table._h))
        singular = law.kind == "schwarz" and law.snap_off == "displacement" and law.t_min > 0.0
        exact = contact_eval == "exact"
        self.params = fk.Params(
            gap=float(m.gap), damping=float(m.damping), k1=float(m.k1), k3=float(m.k3),
            delta_off=float(law.delta_off), delta_max=self.table.delta_max,
            mean_force_below=law.delta_min + SING_BAND if singular else -math.inf,
            law=schwarz_constants(law), table=table,
            mix=fk.no_mix() if m.mixture is None else self._mix(self.table.n, delta_max, exact),
            sub_damping=float(m.substrate_damping), drive=fk.drive_record(m.drive))
        self.flags = fk.Flags(walls=m.walls, damped=m.damping != 0.0, k1_on=m.k1 != 0.0,
                              k3_on=m.k3 != 0.0, locate=self.locate,
                              exact=exact, hertz=law.kind == "hertz",
                              mixed=m.mixture is not None, sub_damped=m.substrate_damping != 0.0,
                              off_substrate=m.mixture is not None and m.mixture.free_beads,
                              threaded=self.threads > 1 and m.n_contacts > fk.SEGMENT,
                              pulse=m.drive is not None and m.drive.pulse is not None,
                              base=m.drive is not None and m.drive.base is not None)
        self.advance = fk.get_kernel(self.flags)
        self.stats = {"method": "velocity Verlet, " + ("located events" if self.locate
                                                        else "step-quantized events"),
                      "dt": self.dt, "threads": self.threads if self.flags.threaded else 1,
                      "steps": 0, "events": 0, "event_substeps": 0, "event_windows": 0,
                      "event_windows_widened": 0, "bead_steps": 0, "front": None,
                      "contact_eval": contact_eval, "wall_time_s": 0.0, "kernel_s": 0.0}
        if contact_eval == "table":
            self.stats["table"] = dict(table_error)

    def _mix(self, points: int, delta_max: float, exact: bool) -> fk.Mix:
        """The kernel's :class:`~mdgran.backends.fast_kernel.Mix` of the scene's unlike beads:
        a force table of ``points`` nodes to ``delta_max`` (own units) per distinct law (one
        placeholder with the exact law, which needs only each law's constants), and a row of
        constants per kind of contact (contacts, with their left beads, that have the same
        constants share one: a dimer chain has three, a chain of random sizes one per
        contact)."""
        mix = self.model.mixture
        laws = mix.laws
        if len(laws) > MAX_LAW_TABLES and not exact:
            raise SceneError("beads", f"{len(laws)} distinct pair laws (each pair's lambda "
                             "follows its size): the fast backend tabulates at most "
                             f"{MAX_LAW_TABLES}; run it with the exact law "
                             "('fast:contact_eval=exact'), or give contact.fc (one law)")
        tables = [ContactTable(law, points, delta_max)
                  for law in (laws if not exact else laws[:1])]
        cls = np.asarray(mix.law_index, dtype=np.int64)
        table = [tables[c if not exact else 0] for c in cls]  # (exact: never read)
        below = np.array([law.delta_min + SING_BAND if law.kind == "schwarz"
                          and law.snap_off == "displacement" and law.t_min > 0.0
                          else -math.inf for law in laws])
        inv_mass = 1.0 / np.asarray(mix.mass, dtype=float)
        on_site = np.ascontiguousarray(mix.substrate, dtype=float)
        left = np.arange(len(cls)) - (1 if self.model.walls else 0)  # -1: the wall
        length = np.asarray(mix.length_scale, dtype=float)
        columns = {"force_scale": mix.force_scale, "inv_len": 1.0 / length, "length": length,
                   "delta_off": mix.delta_off, "base": [t.base for t in table],
                   "scale": [t._scale for t in table], "step": [t._h for t in table],
                   "below": below[cls],
                   "first_coef": tables[0].f_coef.size * (cls if not exact else 0 * cls),
                   "left_inv_mass": np.where(left >= 0, inv_mass[np.maximum(left, 0)], 1.0),
                   "left_on_site": np.where(left >= 0, on_site[np.maximum(left, 0)], 1.0)}
        rows = np.column_stack([np.asarray(columns[f], dtype=float) for f in fk.PAIR_FIELDS]
                               + [cls.astype(float)])
        kinds, kind = np.unique(rows, axis=0, return_inverse=True)
        return fk.Mix(
            inv_mass=inv_mass, on_site=on_site,
            kind=np.ascontiguousarray(kind.reshape(-1), dtype=np.uint32),
            pair=np.ascontiguousarray(kinds[:, :-1]).ravel(),
            pair_class=np.ascontiguousarray(kinds[:, -1], dtype=np.uint32),
            laws=np.array([tuple(schwarz_constants(law)) for law in laws], dtype=float),
            coef=np.concatenate([np.ravel(t.f_coef) for t in tables]).astype(float))

    # ---- state ----------------------------------------------------------------------------
    def _alloc(self):
        n = self.model.n
        self.buffers = fk.Beads(np.zeros((2, n)), np.zeros((2, n)), np.zeros((2, n)))
        self.ks = fk.new_state(n, self.model.n_contacts, EVENT_BUFFER)
        self.closed = self.ks.closed
        self.counters = self.ks.counters[0]  # a view: reads and writes go to the kernel's
        # the two buffers as Beads of [n] views, and one-element views of the counters the
        # frame loop reads (an element of an array is read ~5x faster than a record's field)
        self._copies = tuple(fk.Beads(self.buffers.x[c], self.buffers.v[c], self.buffers.a[c])
                             for c in (0, 1))
        self._count = {k: self.ks.counters[k] for k in (
            "current", "step", "status", "events", "substeps", "d_viscous", "d_hysteresis",
            "power")}
        self._pending = Events()
        self._last = None
        self._step_seconds = None  # seconds per step of the last call (its step budget)

    def _current(self) -> fk.Beads:
        """The beads' current state (views of the kernel's buffer)."""
        return self._copies[int(self._count["current"][0])]

    def _take_events(self) -> Events:
        """Every event in the log (sorted by time), which is emptied."""
        k = int(self.counters["events"])
        evs = self._events(0, k)
        self.counters["events"] = 0
        self.stats["events"] += k
        return evs

    def _events(self, lo: int, hi: int, frame=None) -> Events:
        """Events ``lo .. hi - 1`` of the log (copies), sorted by time (stable: step-quantized
        events come per step, by contact); with ``frame`` (each one's frame, ascending), by
        time within each frame."""
        if hi <= lo:
            return Events()
        log = self.ks.log
        t = log.time[lo:hi]
        order = lo + (np.argsort(t, kind="stable") if frame is None else np.lexsort((t, frame)))
        return Events(log.time[order], self.model.contact_numbers[log.contact[order]],
                      log.kind[order])

    def _check(self):
        status = int(self.counters["status"])
        if status in (fk.OK, fk.EVENTS_FULL, fk.STEP_BUDGET):
            self.counters["status"] = fk.OK
            return
        t = float(self.counters["bad_time"])
        j = int(self.counters["bad_contact"])
        num = int(self.model.contact_numbers[j]) if 0 <= j < self.model.n_contacts else j
        if status == fk.OUT_OF_TABLE:
            inside = 0 <= j < len(self.closed)
            d = float(self.model.compressions(self._current().x)[j]) if inside else math.nan
            dmax = self.table.delta_max
            if not math.isfinite(d):
                raise IntegrationError(f"non-finite state at t = {t:.12g}, contact {num}")
            if d < dmax:  # flagged inside the step (a trial or sub-step state), not at its end
                raise IntegrationError(
                    f"contact {num} left the contact table (compression beyond delta_max = "
                    f"{dmax:g}, or not finite) inside the step ending at t = {t:.12g}, where "
                    f"its compression is {d:.4g}: a smaller run.dt (now {self.dt:g}) or a "
                    "larger table would resolve it")
            raise IntegrationError(f"compression {d:.4g} beyond the contact table (delta_max ="
                                   f" {dmax:g}) at t = {t:.12g}, contact {num}")
        if status == fk.CHATTER:
            raise IntegrationError(f"contact {num} chatters at t = {t:.12g}: it switches state"
                                   f" more than {fk.MAX_SWITCHES} times at one instant")
        if status == fk.TOO_MANY_SUBSTEPS:
            raise IntegrationError(f"more than {fk.MAX_SUBSTEPS} events in one step at t = "
                                   f"{t:.12g}, contact {num}")
        raise IntegrationError(f"more than {EVENT_BUFFER // 2} events in one step at "
                               f"t = {t:.12g}, contact {num}")

    def checkpoint_state(self) -> dict | None:
        """The state at the last yielded frame (stored opaquely by :mod:`mdgran.output.checkpoint`):
        ``y`` = ``[x, v, a, D_viscous, P]`` (``a`` and the damping power ``P`` are the integrator's
        own, so a resumed run is bitwise identical), then ``[W, P_ext]`` with excitations,
        ``closed``, ``d_hyst``, ``i_out``; None before the first frame."""
        if getattr(self, "_last", None) is None:
            return None
        block, a, sums, k = self._last  # a, sums: the kernel's rows of the frame's block
        ledger = [block.dissipated_viscous[k], sums[k, 2]]
        if self.model.drive is not None:
            ledger += [sums[k, 3], sums[k, 4]]
        y = np.concatenate([block.x[k], block.v[k], a[k], ledger])
        return {"t": float(self._out_times[block.step[k]]), "y": y,
                "closed": block.closed[k].copy(), "d_hyst": float(block.dissipated_hysteresis[k]),
                "i_out": int(block.step[k])}

    def _first_frame(self) -> Frames:
        """The frame at t = 0 of the current state (copies), a block of one."""
        now = self._current()
        x, v = now.x.copy(), now.v.copy()
        self._check_finite(x[None], v[None], [0.0])
        frame = Frame(step=0, time=0.0, x=x, v=v, closed=self.closed.copy(),
                      dissipated_viscous=self._count["d_viscous"].item(),
                      dissipated_hysteresis=self._count["d_hysteresis"].item(),
                      events=self._take_events(), external_work=float(self.counters["work"]))
        return Frames.of(frame, self.model)

    @staticmethod
    def _check_finite(x, v, times, first=0):
        """IntegrationError at the first of the states ``x[k], v[k]`` (time ``times[k]``; the
        beads from 0-based ``first`` on) with a non-finite element."""
        if np.isfinite(x).all() and np.isfinite(v).all():
            return
        bad = ~(np.isfinite(x) & np.isfinite(v))
        k, bead = np.argwhere(bad)[0]
        raise IntegrationError(f"non-finite state at t = {times[k]:.12g}, bead "
                               f"{first + bead + 1}")

    def _moved(self, counts):
        """:attr:`~mdgran.backends.base.Frames.moved` of a block whose rows have the kernel's
        ``counts``: the beads of the activity front (its ``front_lo .. front_hi`` columns) of
        any of them, when the beads at rest sit at ``x = 0``; None while the front is not
        known, or with beads at rest elsewhere."""
        if self._rest_x is not None or not len(counts) or (counts[:, 5] < 0).any():
            return None
        lo, hi = int(counts[:, 5].min()), int(counts[:, 6].max()) + 1
        return (lo, hi) if lo < hi else (0, 0)

    # ---- main loop ------------------------------------------------------------------------
    def frames(self, resume: dict | None = None):
        """Integrate the scene; yield a Frame at every output time (:meth:`blocks`, unpacked)."""
        for block in self.blocks(resume):
            last = self._last
            for k in range(len(block)):
                self._last = last[:3] + (k,)
                yield block.frame(k)

    def blocks(self, resume: dict | None = None):
        """Integrate the scene; yield the frames (:class:`~mdgran.backends.base.Frames`) of
        each call of the compiled loop together (the frame at t = 0 alone)."""
        wall0 = _time.perf_counter()
        out_times = self._out_times = self.output_times()  # once (checkpoint_state reads it)
        n = self.model.n
        self._alloc()
        cnt = self.counters
        kernel_args = fk.plain((self.params, self.buffers, self.ks))
        if resume is None:
            imp = self.scene.impulse
            x, v, closed = self.model.initial_state(int(imp.bead), float(imp.velocity))
            now = self._current()
            now.x[:], now.v[:], self.closed[:] = x, v, closed
            self._rest_x = rest_displacement(x)
            fk.settle_all(self.flags, self.params, 0.0, now, self.ks)
            cnt["power"] = fk.init_acc(self.flags, self.params, now, self.ks)
            self._check()
            i_out = 0
            first = self._first_frame()
            power = self._count["power"].item()  # as a block's row: a [1, n], sums [1, 5]
            self._last = (first, now.a.copy()[None], np.array([[0.0, 0.0, power, 0.0, 0.0]]), 0)
            yield first
        else:
            y = np.asarray(resume["y"], dtype=float)
            now = self._current()
            now.x[:], now.v[:], now.a[:] = y[:n], y[n:2 * n], y[2 * n:3 * n]
            self._rest_x = rest_displacement(now.x)
            cnt["d_viscous"], cnt["power"] = y[3 * n], y[3 * n + 1]
            if len(y) > 3 * n + 2:  # with excitations
                cnt["work"], cnt["ext_power"] = y[3 * n + 2], y[3 * n + 3]
            cnt["d_hysteresis"] = float(resume["d_hyst"])
            self.closed[:] = np.asarray(resume["closed"], dtype=bool)
            i_out = int(resume["i_out"])
            cnt["step"] = i_out * self.steps_per_frame
        try:
            yield from self._blocks_from(i_out + 1, out_times, kernel_args)
        finally:
            self.stats["wall_time_s"] = _time.perf_counter() - wall0

    def _block_events(self, block, done) -> tuple[list, np.ndarray, int]:
        """The events of the first ``done`` frames of ``block`` in order (the pending ones
        first; each frame's sorted by time), how many of them belong to frames ``0 .. k``
        (``[done]``), and the log's count of events up to the last frame."""
        ends = block.counts[:done, 0]  # the log's count of events at each frame
        count = int(ends[-1]) if done else 0
        frame = np.repeat(np.arange(done), np.diff(ends, prepend=0))
        pending, self._pending = self._pending, Events()  # an earlier call's unfinished
        # frame's
        return Events.join((pending, self._events(0, count, frame))), ends + len(pending), count

    def _call(self, kernel_args, i, nframes):
        """One call of the compiled loop: frames ``i .. i + nframes - 1`` (fewer if it stops
        early) into a fresh :class:`~mdgran.backends.fast_kernel.FrameBlock`; ``(block,
        frames done, seconds)``.  It may run on the backend's own thread (:meth:`_blocks_from`):
        it touches the kernel's buffers, counters and log and the new block alone."""
        block = fk.new_block(nframes, self.model.n, self.model.n_contacts, self._rest_x)
        self.counters["budget"] = self._step_budget()
        step0 = int(self.counters["step"])
        k0 = _time.perf_counter()
        if self.flags.threaded:
            numba.set_num_threads(self.threads)
            self.ks.sharing[fk.SHARE_THREADS] = self.threads
        done = self.advance(*kernel_args, fk.plain(block), i, nframes, self.steps_per_frame,
                            self.dt)
        if self.flags.threaded:
            note_threads_ran()
        seconds = _time.perf_counter() - k0
        steps = int(self.counters["step"]) - step0
        if steps > 0:  # a first call that compiled makes the next one short, no more
            self._step_seconds = seconds / steps
        return block, done, seconds

    def _step_budget(self) -> int:
        """Steps the next call may take: about :data:`CALL_SECONDS` at the time per step of
        the last call (no limit on the first)."""
        if self._step_seconds is None:
            return 0
        return max(1, int(CALL_SECONDS / max(self._step_seconds, 1e-12)))

    def _blocks_from(self, i, out_times, kernel_args):
        """Frames ``i ..`` to the end: the kernel runs a block of frames per call (about
        BLOCK_BEAD_STEPS bead-steps, :meth:`_call`), whose rows the yielded
        :class:`~mdgran.backends.base.Frames` holds (its ledger computed when first asked).

        The next call starts before a block is yielded, once the block's events and status
        are read: on a thread of its own when the kernel runs on one thread and the process
        may use two cores or more (the compiled loop releases Python's lock, so the driver's
        ledger and reporters of this block run beside the next block's steps), in line
        otherwise.  The results are the same either way (the kernel sees nothing the
        reporters do)."""
        spf, stats = self.steps_per_frame, self.stats
        status, events = self._count["status"], self._count["events"]
        per_call = max(1, int(BLOCK_BEAD_STEPS // (self.model.n * spf)))
        driven = self.model.drive is not None
        ahead = (ThreadPoolExecutor(1, thread_name_prefix="mdgran-kernel")
                 if not self.flags.threaded and usable_threads(0) > 1 else None)

        def start(i, inline=False):
            args = (kernel_args, i, min(per_call, len(out_times) - i))
            if ahead is None or inline:
                return _Done(self._call(*args))
            return ahead.submit(self._call, *args)

        # the first call in line: it may compile the variant (15-25 s), which Ctrl-C must stop
        call = start(i, inline=True) if i < len(out_times) else None
        try:
            while call is not None:
                block, done, seconds = call.result()
                call = None
                stats["kernel_s"] += seconds
                times = out_times[i:i + done]
                error = None  # a non-finite state: the frames before it, then the error
                moved = self._moved(block.counts[:done])
                cols = slice(None) if moved is None else slice(*moved)
                try:
                    self._check_finite(block.x[:done, cols], block.v[:done, cols], times,
                                       cols.start or 0)
                except IntegrationError as exc:
                    error = exc
                    done = next(k for k in range(done) if not np.all(
                        np.isfinite(block.x[k]) & np.isfinite(block.v[k])))
                evs, ends, lo = self._block_events(block, done)
                if not done:
                    self._pending = evs
                if status[0] in (fk.EVENTS_FULL, fk.STEP_BUDGET):  # the unfinished frame's
                    # events so far
                    count = int(events[0])
                    self._pending += self._events(lo, count)
                    lo = count
                self.counters["events"] = 0
                stats["events"] += lo
                if error is None and status[0] != fk.OK:
                    try:
                        self._check()
                    except IntegrationError as exc:
                        error = exc
                first, i = i, i + done
                if error is None and i < len(out_times):
                    call = start(i)
                if done:
                    sums = block.sums[:done]  # (D_viscous, D_hysteresis, power, W, P_ext)
                    frames = Frames(self.model, np.arange(first, i), times[:done],
                                    block.x[:done], block.v[:done], block.closed[:done],
                                    sums[:, 0], sums[:, 1], sums[:, 3] if driven else None,
                                    evs, ends, moved=moved)
                    stats["steps"] = (i - 1) * spf
                    stats["event_substeps"] = int(block.counts[done - 1, 1])
                    stats["event_windows"] = int(block.counts[done - 1, 2])
                    stats["event_windows_widened"] = int(block.counts[done - 1, 3])
                    stats["bead_steps"] = int(block.counts[done - 1, 4])
                    lo, hi = block.counts[done - 1, 5:7].tolist()
                    stats["front"] = [lo + 1, hi + 1] if 0 <= lo <= hi else None
                    self._last = (frames, block.a, block.sums, done - 1)
                    yield frames
                if error is not None:
                    raise error
        finally:
            if ahead is not None:
                ahead.shutdown(wait=True)  # a call under way (an interrupt) ends first
