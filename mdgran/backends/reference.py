"""The reference backend: event-driven integration, as the paper integrates (Sec. II, end).

Between contact events the equations of motion are smooth and are integrated with SciPy's
DOP853 (explicit Runge-Kutta of order 8, dense output of order 7) at ``rtol = atol =
run.tolerance``.  The state vector is ``[x (n), v (n), D_viscous]``: the viscous dissipation is
integrated with the motion, so the energy ledger closes to the integrator's accuracy.  A scene
with a force pulse or a base motion (:mod:`mdgran.model.drive`) adds their work ``W`` as a last
component, ``[x, v, D_viscous, W]``, integrated the same way.

**Events.**  Every contact has an event function that is positive inside its current state::

    closed:  g = delta - delta_off        (opens when g falls to 0)
    open:    g = -delta                   (closes when delta rises to 0)

After each accepted step, a contact is an event candidate when

* ``g`` went from >= 0 to < 0 across the step (a crossing), or
* ``g`` stayed positive at both ends but its rate ``g'`` went from negative to positive and
  ``g`` at the rate's zero (found with ``brentq`` on the dense output) is <= 0: a grazing
  excursion inside one step, which sign checks at the step ends alone would miss.

Each candidate's crossing time is located with ``brentq`` on the step's dense output to
``4 eps |t|``; the earliest is the event.  All candidates within ``1e-12 (1 + |t|)`` of it switch
together (several events at one instant), the state is switched, and integration restarts there.

**Switching policy** (no re-trigger loop, no endless chatter).  A contact switches only if it
moves into its new state's domain, judged by the relative velocity ``d delta/dt`` (its sign
tells which side it goes to).  A contact that sits on its switching point at the start of a
segment (``g <= 0``, as after a switch of a DMT or Hertz contact, whose ``delta_off = 0``, or in
the initial state) is switched at once if it moves outward and left alone otherwise; it is a
candidate again only if it ends a step further outside than it started.  A contact that would
switch more than ``MAX_SWITCHES_AT_ONE_INSTANT`` times without time advancing is a modelling
dead end (Zeno chatter): the run stops with :class:`IntegrationError`, naming the contact.

**The state invariant.**  After every accepted step and at every frame, no closed contact lies
below its switching point and no open one past contact by more than ``STATE_TOL`` (1e-12 p):
a step that ends with a contact outside its state (its root within the simultaneity window of
the step end, or an event landing on an output time with ``g`` at -1e-16) stops the solver
there and the contact switches at once (:meth:`_settle`), so no segment starts from a violated
state.  Inside ``[-STATE_TOL, 0]`` the switching policy above decides (DMT chatter guard).

**Watchdog.**  Every ``WATCH_STEPS`` solver steps (accepted steps, steps redone up to an
event and the short segments of an event's approach all count), ``t`` must have advanced by at
least ``WATCH_STEPS * STEP_FLOOR * (1 + |t|)``: on average a step of ``1e-12 (1 + |t|)``.  Less
is a step size that collapsed (a force too stiff for the tolerance: 1e-150 at substrate.k1 =
1e300) or an event location that stalls (positions too large for the absolute event
tolerance), and the run stops with :class:`IntegrationError` naming the time, the step, the
bead with the largest acceleration and the contacts whose event was being located, instead of
running on without progress.  Legitimate tiny steps (the approach to an event, the redone step
up to it, the square-root singularity at snap-off) are isolated: measured, no window of
tests/test_reference.py, test_hard_cases.py, test_oracle_events.py, test_invariant_campaign.py
nor of micro-star at v0 = +-1e3 (the largest allowed) averaged below 1e-5 (1 + |t|), 7 orders
above the floor.

**Ledger.**  On opening, the contact's energy ``V(delta(t_e))`` goes to ``D_hysteresis``; for
the displacement rule that is the loop energy ``W``, to the accuracy of the event location.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import DOP853
from scipy.optimize import brentq

from .base import (ALL_FEATURES, CLOSE, LEDGER_TOL_FLOOR, LEDGER_TOL_MULTIPLE, LEDGER_TOL_TIME,
                   OPEN, Backend, Event, Frame, IntegrationError)

MAX_SWITCHES_AT_ONE_INSTANT = 4
SIMULTANEOUS = 1e-12
#: A pending contact switches when its event function is at most this (units of p).
EVENT_G_TOL = 1e-13
#: The state invariant: after every accepted step and at every frame, no closed contact lies
#: below its switching point (``delta < delta_off``) and no open one past contact (``delta >
#: 0``) by more than this (units of p); a contact found beyond it is switched at once.
STATE_TOL = 1e-12
#: Tolerance factor for steps that approach a snap-off (see ``_near_snap_off``) and for the
#: redone step that ends on an event.
EVENT_TIGHTEN = 1e-3
#: Tighten when a snap-off is predicted within this many steps.
NEAR_STEPS = 3.0
#: DOP853 refuses a smaller rtol (100 machine epsilons).
RTOL_FLOOR = 2.5e-14
#: The watchdog (module doc): over every WATCH_STEPS solver steps t advances by at least
#: WATCH_STEPS * STEP_FLOOR * (1 + |t|), else the run stops (IntegrationError).
STEP_FLOOR = 1e-12
WATCH_STEPS = 1000


#: a step inside a force pulse is at most this share of the pulse's duration
PULSE_STEP_SHARE = 0.125


@dataclass
class _Loop:
    """The event loop's state between steps (:meth:`ReferenceBackend.frames`).

    ``t``, ``y`` (``[x, v, D_viscous]``), ``h_last`` (last step size), ``armed_out``
    (contacts that start a segment on or over their switching point: a candidate again if
    they end a step further out), ``post_event`` (tighten the next segment) and ``i_out``
    (the frame index) are what a checkpoint stores (:meth:`ReferenceBackend._snap`, with the
    backend's contact states and hysteresis loss); the rest is rebuilt on resume: the segment
    ``target``, the ``pending`` contacts of an event being approached (``{contact:
    was_closed}``), the right-hand side ``rhs``, the chatter guard's ``switches_here``, the
    watchdog's ``watch_t`` and ``watch_n``, and the ``events`` since the last frame.
    """

    t: float
    y: np.ndarray
    h_last: float | None = None
    armed_out: np.ndarray | None = None
    post_event: bool = False
    i_out: int = 0
    target: float = 0.0
    pending: dict | None = None
    rhs: object = None
    switches_here: dict = field(default_factory=dict)
    watch_t: float = 0.0
    watch_n: int = 0
    events: list = field(default_factory=list)


class ReferenceBackend(Backend):
    """Event-driven DOP853 integration at ``run.tolerance``; the accuracy oracle."""

    name = "reference"
    supports = ALL_FEATURES

    def __init__(self, scene, **options):
        super().__init__(scene, **options)
        self.tol = float(options.get("tolerance", scene.run.tolerance))
        m = self.model
        self.n = m.n
        self.delta_off = m.delta_off  # a number, or per contact for unlike beads
        law = m.law  # kind, snap-off rule and (lambda = 0) DMT are every pair's
        if law.kind == "hertz" or law.fc == -2.0:
            self._singular = "both"  # f - f(0) ~ delta^(3/2) at delta = 0
        elif law.snap_off == "displacement":
            self._singular = "approach"  # f - f_off ~ sqrt(delta - delta_min)
        else:
            self._singular = None  # the force maximum is a regular point of the branch
        self.stats = {"steps": 0, "rhs_evals": 0, "events": 0, "segments": 0,
                      "wall_time_s": 0.0, "method": "DOP853 event-driven", "tolerance": self.tol}
        pulse = m.drive.pulse if m.drive is not None else None
        # a force pulse's start and end are segment ends, and inside it a step is at most
        # PULSE_STEP_SHARE of its duration: a chain at rest takes steps as long as the output
        # interval, which stepped over a short pulse (its work was 0)
        self._pulse = None if pulse is None else (pulse.start, pulse.start + pulse.duration,
                                                  pulse.duration * PULSE_STEP_SHARE)

    @classmethod
    def refinement(cls, scene):
        """The same scene at 1/100 of the tolerance; its difference from the nominal run is
        taken as the nominal run's error."""
        return [("run.tolerance", max(float(scene.run.tolerance) / 100, 1e-14))], 1.0

    def ledger_model(self) -> float:
        """Ledger bound per unit of the energy scale: ``LEDGER_TOL_MULTIPLE * max(tol,
        LEDGER_TOL_FLOOR) * (1 + T / LEDGER_TOL_TIME)``, ``T`` the run's duration: step control
        is local, so the ledger error of a long run grows with ``T`` (constants and their
        calibration in :mod:`mdgran.backends.base`)."""
        t = float(self.scene.run.duration)
        return (LEDGER_TOL_MULTIPLE * max(self.tol, LEDGER_TOL_FLOOR)
                * (1.0 + t / LEDGER_TOL_TIME))

    # ---- right-hand side and event functions ---------------------------------------------
    def _rhs_factory(self, closed):
        m = self.model
        n = self.n
        any_closed = bool(closed.any())

        driven = m.drive is not None

        def rhs(t, y):
            x = y[:n]
            v = y[n:2 * n]
            out = np.empty_like(y)
            out[:n] = v
            if any_closed:
                out[n:2 * n] = m.acceleration(x, v, closed, t)
            else:
                out[n:2 * n] = m.free_acceleration(x, v, t)
            out[2 * n] = m.viscous_power(v, closed, t)
            if driven:
                out[2 * n + 1] = m.external_power(x, v, t)
            return out

        return rhs

    def _g(self, y, closed):
        """Event function (positive inside the current state) and its rate, per contact."""
        n = self.n
        delta = self.model.compressions(y[:n])
        rate = self.model.differences(y[n:2 * n])
        g = np.where(closed, delta - self.delta_off, -delta)
        gdot = np.where(closed, rate, -rate)
        return g, gdot

    def _near_snap_off(self, g, gd, h):
        """True when a closed contact is within ``NEAR_STEPS`` steps of size ``h`` of a
        switching point where the force is singular (linear extrapolation of ``g``).

        Schwarz with the displacement rule: ``df/d delta`` is infinite at ``delta_min``, which a
        contact reaches only when it is about to open.  Hertz and DMT: ``f - f(0) ~
        delta^(3/2)`` at ``delta = 0``, on both sides, so also just after closing.
        """
        if self._singular is None:
            return False
        if h is None:  # first step: no step size yet, judge on the output interval
            h = float(self.scene.run.output_interval)
        if self._singular == "approach":
            near = self._closed & (gd < 0.0)
            return bool(np.any(g[near] < -gd[near] * NEAR_STEPS * h))
        near = self._closed
        return bool(np.any(np.abs(g[near]) < np.abs(gd[near]) * NEAR_STEPS * h))

    # ---- event handling ------------------------------------------------------------------
    def _candidates(self, sol, t0, t1, g0, gd0, g1, gd1, armed_out):
        """(root time, contact) pairs for contacts that leave their state in [t0, t1]."""
        out = []
        crossing = (g0 >= 0.0) & (g1 < 0.0)
        further_out = (g0 < 0.0) & (g1 < g0) & armed_out
        grazing = (g0 > 0.0) & (g1 > 0.0) & (gd0 < 0.0) & (gd1 > 0.0)
        for k in np.flatnonzero(crossing):
            out.append((self._root(sol, k, t0, t1, g0[k]), k))
        for k in np.flatnonzero(further_out):
            out.append((t0, k))
        for k in np.flatnonzero(grazing):
            try:
                tm = brentq(lambda t: self._gk(sol(t), k)[1], t0, t1, xtol=1e-15, rtol=1e-15)
            except ValueError:
                continue
            if self._gk(sol(tm), k)[0] <= 0.0:
                out.append((self._root(sol, k, t0, tm, g0[k]), k))
        return out

    def _gk(self, y, k):
        g, gd = self._g(y, self._closed)
        return g[k], gd[k]

    def _root(self, sol, k, t0, t1, g0k):
        if g0k <= 0.0:
            return t0
        f = lambda t: self._gk(sol(t), k)[0]  # noqa: E731
        return brentq(f, t0, t1, xtol=4e-16 * max(1.0, abs(t1)), rtol=1e-15)

    def _switch(self, t, y, ks, events):
        """Switch contacts ``ks`` at time ``t`` (state ``y``): hysteresis loss and events."""
        m = self.model
        nums = m.contact_numbers
        delta = m.compressions(y[:self.n])
        for k in ks:
            if self._closed[k]:
                self._d_hyst += float(m.contact_law_energy(delta[k], k))
                self._closed[k] = False
                events.append(Event(t, int(nums[k]), OPEN))
            else:
                self._closed[k] = True
                events.append(Event(t, int(nums[k]), CLOSE))
        self.stats["events"] += len(ks)

    @staticmethod
    def _outside(g, gd):
        """Contacts that must switch now: beyond their switching point by more than
        ``STATE_TOL`` (the state invariant), or on or over it and moving outward."""
        return (g < -STATE_TOL) | ((g <= 0.0) & (gd < 0.0))

    def _chatter_guard(self, count: dict, t, ks, y):
        """The chatter guard: count one switch of each contact in ``ks`` at time ``t`` in
        ``count[(t, k)]``; a contact switching more than ``MAX_SWITCHES_AT_ONE_INSTANT`` times
        at one instant (Zeno chatter, module doc) stops the run with :class:`IntegrationError`
        naming it."""
        for k in ks:
            count[(t, k)] = count.get((t, k), 0) + 1
            if count[(t, k)] > MAX_SWITCHES_AT_ONE_INSTANT:
                raise IntegrationError(
                    f"contact {self.model.contact_numbers[k]} chatters at t = {t:.12g}: "
                    f"it switches state more than {MAX_SWITCHES_AT_ONE_INSTANT} times "
                    f"at one instant (delta = {self.model.compressions(y[:self.n])[k]:.3g})")

    def _settle(self, t, y, events) -> int:
        """Switch at once every contact that is :meth:`_outside` its state; returns how many
        switches were made.  This is what keeps the state invariant: it runs after every
        event, at every accepted step that ends with a contact outside, and before every
        frame, so a violation is never carried into the next step."""
        count = {}
        switched = 0
        while True:
            g, gd = self._g(y, self._closed)
            ks = np.flatnonzero(self._outside(g, gd))
            if ks.size == 0:
                return switched
            switched += ks.size
            self._chatter_guard(count, t, ks, y)
            self._switch(t, y, ks, events)

    # ---- main loop -----------------------------------------------------------------------
    def checkpoint_state(self) -> dict | None:
        """Everything needed to continue exactly from the last yielded frame (the solver
        restarts at every output time, so this is the whole hidden state); None before the
        first frame."""
        snapshot = getattr(self, "_snapshot", None)
        return None if snapshot is None else dict(snapshot)

    def frames(self, resume: dict | None = None):
        """Integrate the scene; yield a Frame at every output time.

        A flat loop over named steps, on one :class:`_Loop` state:

        1. :meth:`_integrate`: DOP853 from ``(t, y)`` towards ``target``, the next output
           time, so that every stored frame is the integrator's own state, not an
           interpolant.  When an accepted step ``[t0, t1]`` contains an event at ``te < t1``
           (:meth:`_locate`), the step is discarded and integration restarts from ``(t0, y0)``
           with ``target = te``, so the solver's own step-size control resolves the approach
           to the event (at snap-off the force has a square-root singularity that a
           dense-output polynomial across the kink would smear).
        2. :meth:`_arrive`: on reaching an event's target, the pending contacts switch if they
           stand on their switching point (``g <= EVENT_G_TOL``); if they fall short, the
           target moves on by ``g / |g'|``.
        3. :meth:`_settle` (inside both): contacts outside their state switch at once.
        4. :meth:`_output`: on reaching an output time, the frame and the checkpoint.
        """
        out_times = self.output_times()
        wall0 = _time.perf_counter()
        if resume is None:
            s = self._start()
            yield self._output(s, 0.0)
        else:
            s = self._resume(resume)
            s.i_out += 1
        if s.i_out >= len(out_times):
            return
        s.target = self._next_target(s.t, out_times[s.i_out])
        s.rhs = self._rhs_factory(self._closed.copy())
        s.watch_t, s.watch_n = s.t, 0  # the watchdog (module doc)
        while True:
            if s.target > s.t and not self._integrate(s):
                continue  # stopped short of the target: go on from where it stopped
            if s.pending is not None:  # at the end of an event's approach
                self._arrive(s, out_times[s.i_out])
                continue
            if s.t < out_times[s.i_out]:  # at a pulse's start or end
                s.target = self._next_target(s.t, out_times[s.i_out])
                continue
            yield self._output(s, out_times[s.i_out])  # at an output time
            if s.i_out == len(out_times):
                break
            s.target = self._next_target(s.t, out_times[s.i_out])
        self.stats["wall_time_s"] = _time.perf_counter() - wall0

    def _next_target(self, t, t_out) -> float:
        """Where a segment from ``t`` aims: the output time ``t_out``, or a force pulse's
        start or end before it."""
        target = float(t_out)
        if self._pulse is not None:
            for edge in self._pulse[:2]:
                if t < edge < target:
                    target = edge
        return target

    def _max_step(self, t0, t1) -> float:
        """The longest step of a segment ``[t0, t1]``: a share of a force pulse's duration
        inside it (:data:`PULSE_STEP_SHARE`), else unbounded."""
        p = self._pulse
        if p is not None and t0 < p[1] and t1 > p[0]:
            return p[2]
        return np.inf

    def _start(self) -> _Loop:
        """The initial state (the scene's impulse), settled: the state of frame 0."""
        imp = self.scene.impulse
        x, v, closed = self.model.initial_state(int(imp.bead), float(imp.velocity))
        self._closed = closed
        self._d_hyst = 0.0
        ledger = [0.0, 0.0] if self.model.drive is not None else [0.0]  # D_viscous (, W)
        s = _Loop(t=0.0, y=np.concatenate([x, v, ledger]))
        self._settle(s.t, s.y, s.events)
        s.armed_out = self._g(s.y, self._closed)[0] <= 0.0
        return s

    def _resume(self, resume: dict) -> _Loop:
        """The state of a checkpoint (:meth:`checkpoint_state`) of the frame ``i_out``."""
        self._closed = np.array(resume["closed"], dtype=bool)
        self._d_hyst = float(resume["d_hyst"])
        return _Loop(t=float(resume["t"]), y=np.array(resume["y"], dtype=float),
                     h_last=None if resume["h_last"] is None else float(resume["h_last"]),
                     armed_out=np.array(resume["armed_out"], dtype=bool),
                     post_event=bool(resume["post_event"]), i_out=int(resume["i_out"]))

    def _output(self, s: _Loop, t_out) -> Frame:
        """The frame ``s.i_out`` at output time ``t_out`` (the solver's own state): stores the
        checkpoint, clears the events and moves ``i_out`` on to the next output time."""
        self._snapshot = self._snap(s)
        frame = self._frame(s.i_out, t_out, s.y, s.events)
        s.events = []
        s.i_out += 1
        return frame

    # ---- step 1: integrate to the next boundary (an output time or an event) -------------
    def _integrate(self, s: _Loop) -> bool:
        """One solver segment from ``(s.t, s.y)`` towards ``s.target``; True when it reached
        the target.  Otherwise it stopped at an event inside a step (``s`` now restarts from
        that step's start with the event as target and its contacts pending), at a step that
        ended with a contact outside its state, or to tighten the tolerance before a
        snap-off.  Contacts outside their state at the end are switched (:meth:`_settle`)."""
        self.stats["segments"] += 1
        solver, tight, g0, gd0 = self._open_solver(s)
        restart, tighten = self._steps(s, solver, tight, g0, gd0)
        self.stats["rhs_evals"] += solver.nfev
        if restart is not None:
            s.t, s.y, s.target, s.pending = restart
            return False
        s.t, s.y = solver.t, solver.y.copy()
        s.h_last = getattr(solver, "h_abs", None) or solver.step_size or s.h_last
        if self._settle(s.t, s.y, s.events):
            self._rearm(s)
        return not (tighten or s.t < s.target)

    def _open_solver(self, s: _Loop):
        """A DOP853 solver from ``(s.t, s.y)`` to ``s.target``; returns ``(solver, tight, g,
        g')``.  Tighter tolerance (``EVENT_TIGHTEN``) for: the approach to an event (pending)
        and steps predicted to reach a singular switching point, where the force has a sqrt or
        delta^(3/2) singularity and a step's error estimate is weakest; and the steps up to
        the next output time after a switch (measured: micro-star to t = 60, ledger error
        1.4e-9 -> 7.6e-11 of E_imp for 0.4 % more steps)."""
        g0, gd0 = self._g(s.y, self._closed)
        tight = s.pending is not None or s.post_event or self._near_snap_off(g0, gd0, s.h_last)
        s.post_event = False
        tl = self.tol * EVENT_TIGHTEN if tight else self.tol
        with np.errstate(all="ignore"):  # overflow: the checks in _step say it, one line
            cap = self._max_step(s.t, s.target)
            solver = DOP853(s.rhs, s.t, s.y, s.target, rtol=max(tl, RTOL_FLOOR), atol=tl,
                            max_step=cap, first_step=min(s.h_last, s.target - s.t, cap)
                            if s.h_last else None)
        return solver, tight, g0, gd0

    def _steps(self, s: _Loop, solver, tight: bool, g0, gd0):
        """Step ``solver`` until it finishes or a step calls for a stop; returns ``(restart,
        tighten)``: ``restart = (t0, y0, te, pending)`` when a step contains an event
        (:meth:`_locate`), ``tighten`` when a not yet tight segment nears a snap-off.  A step
        accepted with a contact outside its state (a root within ``SIMULTANEOUS`` of the step
        end, or over its point) also stops it: :meth:`_integrate` switches it there."""
        while solver.status == "running":
            t0, y0 = solver.t, solver.y.copy()
            y1 = self._step(s, solver)
            g1, gd1 = self._g(y1, self._closed)
            restart = self._locate(s, solver, t0, y0, g0, gd0, g1, gd1)
            if restart is not None:
                return restart, False
            if np.any(self._outside(g1, gd1)):
                break
            g0, gd0 = g1, gd1
            s.armed_out &= g1 <= 0.0
            if not tight and self._near_snap_off(g1, gd1, solver.h_abs):
                return None, True
        return None, False

    def _step(self, s: _Loop, solver):
        """One solver step; returns the new state.  Raises :class:`IntegrationError` when the
        solver fails, the state is not finite, or the watchdog (:meth:`_watch`) fires."""
        t0 = solver.t
        with np.errstate(all="ignore"):  # overflow: the checks below say it, one line
            msg = solver.step()
        if solver.status == "failed":
            raise IntegrationError(f"integrator failed at t = {t0:.12g}: {msg}")
        self.stats["steps"] += 1
        t1, y1 = solver.t, solver.y
        if not np.all(np.isfinite(y1)):
            bad = int(np.flatnonzero(~np.isfinite(y1[:2 * self.n]))[0] % self.n) + 1
            raise IntegrationError(f"non-finite state at t = {t1:.12g}, bead {bad}")
        self._watch(s, t1 - t0, t1, y1)
        return y1

    def _watch(self, s: _Loop, step, t1, y1):
        """The watchdog (module doc): every ``WATCH_STEPS`` steps, ``t`` must have advanced by
        ``WATCH_STEPS * STEP_FLOOR * (1 + |t|)``, else :class:`IntegrationError`."""
        s.watch_n += 1
        if s.watch_n >= WATCH_STEPS:
            if t1 - s.watch_t < WATCH_STEPS * STEP_FLOOR * (1.0 + abs(t1)):
                raise IntegrationError(self._stalled(t1, y1, step, t1 - s.watch_t, s.rhs,
                                                     s.pending))
            s.watch_t, s.watch_n = t1, 0

    # ---- step 2: locate an event inside an accepted step ---------------------------------
    def _locate(self, s: _Loop, solver, t0, y0, g0, gd0, g1, gd1):
        """The restart ``(t0, y0, te, {contact: was_closed})`` when the accepted step ``[t0,
        t1]`` contains an event at ``te`` before its end (by more than ``SIMULTANEOUS``), the
        contacts being those within ``SIMULTANEOUS`` of ``te``; else None.  Sets
        ``s.h_last`` for the redone step up to the event."""
        if not (np.any(g1 < 0.0) or np.any((gd0 < 0.0) & (gd1 > 0.0))):
            return None
        t1 = solver.t
        cands = self._candidates(solver.dense_output(), t0, t1, g0, gd0, g1, gd1, s.armed_out)
        if not cands:
            return None
        te = min(c[0] for c in cands)
        if not te < t1 - SIMULTANEOUS * (1.0 + abs(t1)):
            return None
        ks = {k: bool(self._closed[k]) for tc, k in cands
              if tc <= te + SIMULTANEOUS * (1.0 + abs(te))}
        s.h_last = max(te - t0, 1e-3 * (solver.step_size or 1.0))
        return t0, y0, te, ks

    # ---- step 3: switch the pending contacts at the end of an event's approach -----------
    def _arrive(self, s: _Loop, t_out):
        """At the target of an event's approach: switch the pending contacts still in the
        state they were located in (a settle on the way may have switched them already), then
        settle, and aim at the output time ``t_out`` again; or, if they fall short of their
        switching point, move the target on (:meth:`_short_of_point`)."""
        ks = sorted(k for k, was_closed in s.pending.items() if self._closed[k] == was_closed)
        if ks:
            g, gd = self._g(s.y, self._closed)
            if self._short_of_point(s, ks, g, gd, t_out):
                return
            ks = [k for k in ks if g[k] <= EVENT_G_TOL or gd[k] < 0.0]
            self._chatter_guard(s.switches_here, s.t, ks, s.y)
            if len(s.switches_here) > 256:
                s.switches_here.clear()
            self._switch(s.t, s.y, ks, s.events)
            self._settle(s.t, s.y, s.events)
            self._rearm(s)
        s.target, s.pending = self._next_target(s.t, t_out), None

    def _short_of_point(self, s: _Loop, ks, g, gd, t_out) -> bool:
        """True (and ``s.target`` moved on by the largest ``g / |g'|``, at most to ``t_out``)
        when pending contacts ``ks`` still approach their switching point from more than
        ``EVENT_G_TOL`` away, and the time to reach it is above ``4 eps max(1, |t|)``."""
        short = [k for k in ks if g[k] > EVENT_G_TOL and gd[k] < 0.0]
        if not short:
            return False
        ahead = max(g[k] / -gd[k] for k in short)
        if not ahead > 4e-16 * max(1.0, abs(s.t)):
            return False
        s.target = min(self._next_target(s.t, t_out), s.t + ahead)
        return True

    def _rearm(self, s: _Loop):
        """After a switch: re-arm the further-out candidates (contacts on or over their point),
        rebuild the right-hand side for the new contact states, tighten the next segment."""
        s.armed_out = self._g(s.y, self._closed)[0] <= 0.0
        s.rhs = self._rhs_factory(self._closed.copy())
        s.post_event = True

    def _stalled(self, t, y, step, advance, rhs, pending) -> str:
        """The watchdog's one-line message: what collapsed, when, and where."""
        n = self.n
        with np.errstate(all="ignore"):
            acc = np.abs(rhs(t, y)[n:2 * n])
        bead = int(np.argmax(np.where(np.isfinite(acc), acc, np.inf))) + 1
        where = f"bead {bead} has the largest acceleration, {acc[bead - 1]:.3g}"
        if pending:
            nums = ", ".join(str(int(self.model.contact_numbers[k])) for k in sorted(pending))
            where += f"; locating the event of contact {nums}"
        return (f"step size collapsed at t = {t:.12g}: {WATCH_STEPS} steps advanced t by "
                f"{advance:.3g} (last step {step:.3g}), below the floor {STEP_FLOOR:g} (1 + |t|)"
                f" per step; {where}")

    def _snap(self, s: _Loop) -> dict:
        """The checkpoint of the loop state ``s`` (keys and values stored by checkpoints)."""
        return {"t": float(s.t), "y": np.array(s.y), "closed": self._closed.copy(),
                "d_hyst": self._d_hyst, "h_last": s.h_last, "armed_out": np.array(s.armed_out),
                "post_event": bool(s.post_event), "i_out": int(s.i_out)}

    def _frame(self, step, t, y, events):
        n = self.n
        return Frame(step=step, time=float(t), x=np.array(y[:n]), v=np.array(y[n:2 * n]),
                     closed=self._closed.copy(), dissipated_viscous=float(y[2 * n]),
                     dissipated_hysteresis=self._d_hyst, events=list(events),
                     external_work=float(y[2 * n + 1]) if len(y) > 2 * n + 1 else 0.0)
