"""The reference backend: event-driven integration, as the paper integrates (Sec. II, end).

Between contact events the equations of motion are smooth and are integrated with SciPy's
DOP853 (explicit Runge-Kutta of order 8, dense output of order 7) at ``rtol = atol =
run.tolerance``.  The state vector is ``[x (n), v (n), D_viscous]``: the viscous dissipation is
integrated with the motion, so the energy ledger closes to the integrator's accuracy.

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

import numpy as np
from scipy.integrate import DOP853
from scipy.optimize import brentq

from .base import (CLOSE, LEDGER_TOL_FLOOR, LEDGER_TOL_MULTIPLE, LEDGER_TOL_TIME, OPEN, Backend,
                   Event, Frame, IntegrationError)

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


class ReferenceBackend(Backend):
    """Event-driven DOP853 integration at ``run.tolerance``; the accuracy oracle."""

    name = "reference"

    def __init__(self, scene, **options):
        super().__init__(scene, **options)
        self.tol = float(options.get("tolerance", scene.data["run"]["tolerance"]))
        m = self.model
        self.n = m.n
        self.delta_off = m.law.delta_off
        law = m.law
        if law.kind == "hertz" or law.fc == -2.0:
            self._singular = "both"  # f - f(0) ~ delta^(3/2) at delta = 0
        elif law.snap_off == "displacement":
            self._singular = "approach"  # f - f_off ~ sqrt(delta - delta_min)
        else:
            self._singular = None  # the force maximum is a regular point of the branch
        self.stats = {"steps": 0, "rhs_evals": 0, "events": 0, "segments": 0,
                      "wall_time_s": 0.0, "method": "DOP853 event-driven", "tolerance": self.tol}

    @classmethod
    def refinement(cls, scene):
        """The same scene at 1/100 of the tolerance; its difference from the nominal run is
        taken as the nominal run's error."""
        return [("run.tolerance", max(float(scene.data["run"]["tolerance"]) / 100, 1e-14))], 1.0

    def ledger_model(self) -> float:
        """Ledger bound per unit of the energy scale: ``LEDGER_TOL_MULTIPLE * max(tol,
        LEDGER_TOL_FLOOR) * (1 + T / LEDGER_TOL_TIME)``, ``T`` the run's duration: step control
        is local, so the ledger error of a long run grows with ``T`` (constants and their
        calibration in :mod:`mdgran.backends.base`)."""
        t = float(self.scene.data["run"]["duration"])
        return (LEDGER_TOL_MULTIPLE * max(self.tol, LEDGER_TOL_FLOOR)
                * (1.0 + t / LEDGER_TOL_TIME))

    # ---- right-hand side and event functions ---------------------------------------------
    def _rhs_factory(self, closed):
        m = self.model
        n = self.n
        any_closed = bool(closed.any())

        def rhs(t, y):
            x = y[:n]
            v = y[n:2 * n]
            out = np.empty_like(y)
            out[:n] = v
            if any_closed:
                out[n:2 * n] = m.acceleration(x, v, closed)
            else:
                s = m.substrate_force(x)
                out[n:2 * n] = 0.0 if s is None else s
            out[2 * n] = m.viscous_power(v, closed)
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
            h = float(self.scene.data["run"]["output_interval"])
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
                self._d_hyst += float(m.law.energy(delta[k]))
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
            for k in ks:
                count[k] = count.get(k, 0) + 1
                if count[k] > MAX_SWITCHES_AT_ONE_INSTANT:
                    raise IntegrationError(
                        f"contact {self.model.contact_numbers[k]} chatters at t = {t:.12g}: "
                        f"it switches state more than {MAX_SWITCHES_AT_ONE_INSTANT} times "
                        f"at one instant (delta = {self.model.compressions(y[:self.n])[k]:.3g})")
            self._switch(t, y, ks, events)

    # ---- main loop -----------------------------------------------------------------------
    def checkpoint_state(self) -> dict:
        """Everything needed to continue exactly from the last yielded frame (the solver
        restarts at every output time, so this is the whole hidden state)."""
        return dict(self._snapshot)

    def frames(self, resume: dict | None = None):
        """Integrate the scene; yield a Frame at every output time.

        The loop runs DOP853 from ``(t, y)`` towards ``target``: the next output time, so that
        every stored frame is the integrator's own state, not an interpolant.  When an accepted step
        ``[t0, t1]`` contains an event at ``te < t1``, the step is discarded and integration
        restarts from ``(t0, y0)`` with ``target = te``, so the solver's own step-size control
        resolves the approach to the event (at snap-off the force has a square-root
        singularity that a dense-output polynomial across the kink would smear).  On reaching
        the target, the pending contacts switch if they stand on their switching point
        (``g <= EVENT_G_TOL``); if they fall short, the target moves on by ``g / |g'|``.
        """
        m, n, tol = self.model, self.n, self.tol
        out_times = self.output_times()
        events: list = []
        wall0 = _time.perf_counter()
        if resume is None:
            imp = self.scene.data["impulse"]
            x, v, closed = m.initial_state(int(imp["bead"]), float(imp["velocity"]))
            self._closed = closed
            self._d_hyst = 0.0
            y = np.concatenate([x, v, [0.0]])
            t = 0.0
            self._settle(t, y, events)
            h_last, post_event, i_out = None, False, 0
            armed_out = self._g(y, self._closed)[0] <= 0.0
            self._snapshot = self._snap(t, y, h_last, armed_out, post_event, i_out)
            yield self._frame(0, 0.0, y, events)
            events = []
        else:
            t, y = float(resume["t"]), np.array(resume["y"], dtype=float)
            self._closed = np.array(resume["closed"], dtype=bool)
            self._d_hyst = float(resume["d_hyst"])
            h_last = None if resume["h_last"] is None else float(resume["h_last"])
            armed_out = np.array(resume["armed_out"], dtype=bool)
            post_event, i_out = bool(resume["post_event"]), int(resume["i_out"])
        i_out += 1
        if i_out >= len(out_times):
            return
        target, pending = float(out_times[i_out]), None
        rhs = self._rhs_factory(self._closed.copy())
        switches_here = {}
        watch_t, watch_n = t, 0  # the watchdog (module doc)
        while True:
            restart = None
            if target > t:
                self.stats["segments"] += 1
                # Tighter tolerance (EVENT_TIGHTEN) for: the approach to an event (pending) and
                # steps predicted to reach a singular switching point, where the force has a
                # sqrt or delta^(3/2) singularity and a step's error estimate is weakest; and
                # the steps up to the next output time after a switch (measured: micro-star to
                # t = 60, ledger error 1.4e-9 -> 7.6e-11 of E_imp for 0.4 % more steps).
                g0, gd0 = self._g(y, self._closed)
                tight = pending is not None or post_event or self._near_snap_off(g0, gd0, h_last)
                post_event = False
                tl = tol * EVENT_TIGHTEN if tight else tol
                with np.errstate(all="ignore"):  # overflow: the checks below say it, one line
                    solver = DOP853(rhs, t, y, target, rtol=max(tl, RTOL_FLOOR), atol=tl,
                                    first_step=min(h_last, target - t) if h_last else None)
                accept_and_tighten = False
                while solver.status == "running":
                    t0, y0 = solver.t, solver.y.copy()
                    with np.errstate(all="ignore"):  # overflow: the checks below say it, one line
                        msg = solver.step()
                    if solver.status == "failed":
                        raise IntegrationError(f"integrator failed at t = {t0:.12g}: {msg}")
                    self.stats["steps"] += 1
                    t1, y1 = solver.t, solver.y
                    if not np.all(np.isfinite(y1)):
                        bad = int(np.flatnonzero(~np.isfinite(y1[:2 * n]))[0] % n) + 1
                        raise IntegrationError(f"non-finite state at t = {t1:.12g}, bead {bad}")
                    watch_n += 1
                    if watch_n >= WATCH_STEPS:
                        if t1 - watch_t < WATCH_STEPS * STEP_FLOOR * (1.0 + abs(t1)):
                            raise IntegrationError(self._stalled(t1, y1, t1 - t0, t1 - watch_t,
                                                                 rhs, pending))
                        watch_t, watch_n = t1, 0
                    g1, gd1 = self._g(y1, self._closed)
                    sol = None
                    if np.any(g1 < 0.0) or np.any((gd0 < 0.0) & (gd1 > 0.0)):
                        sol = solver.dense_output()
                        cands = self._candidates(sol, t0, t1, g0, gd0, g1, gd1, armed_out)
                        if cands:
                            te = min(c[0] for c in cands)
                            if te < t1 - SIMULTANEOUS * (1.0 + abs(t1)):
                                ks = {k: bool(self._closed[k]) for tc, k in cands
                                      if tc <= te + SIMULTANEOUS * (1.0 + abs(te))}
                                restart = (t0, y0, te, ks)
                                h_last = max(te - t0, 1e-3 * (solver.step_size or 1.0))
                                break
                    if np.any(self._outside(g1, gd1)):
                        break  # accepted with a contact outside (a root within SIMULTANEOUS
                        # of the step end, or over its point): switch it there, below
                    g0, gd0 = g1, gd1
                    armed_out &= g1 <= 0.0
                    if not tight and self._near_snap_off(g1, gd1, solver.h_abs):
                        accept_and_tighten = True
                        break
                self.stats["rhs_evals"] += solver.nfev
                if restart is None:
                    t, y = solver.t, solver.y.copy()
                    h_last = getattr(solver, "h_abs", None) or solver.step_size or h_last
                    if self._settle(t, y, events):
                        armed_out = self._g(y, self._closed)[0] <= 0.0
                        rhs = self._rhs_factory(self._closed.copy())
                        post_event = True
                    if accept_and_tighten or t < target:
                        continue
            if restart is not None:
                t, y, target, pending = restart
                continue
            if pending is None:  # reached an output time: the frame is the solver's own state
                self._snapshot = self._snap(t, y, h_last, armed_out, post_event, i_out)
                yield self._frame(i_out, out_times[i_out], y, events)
                events = []
                i_out += 1
                if i_out == len(out_times):
                    break
                target = float(out_times[i_out])
                continue
            # the pending contacts still in the state they were located in (a settle on the
            # way may have switched them already)
            ks = sorted(k for k, was_closed in pending.items() if self._closed[k] == was_closed)
            if not ks:
                target, pending = float(out_times[i_out]), None
                continue
            g, gd = self._g(y, self._closed)
            short = [k for k in ks if g[k] > EVENT_G_TOL and gd[k] < 0.0]
            if short and (max(g[k] / -gd[k] for k in short) > 4e-16 * max(1.0, abs(t))):
                target = min(float(out_times[i_out]), t + max(g[k] / -gd[k] for k in short))
                continue
            ks = [k for k in ks if g[k] <= EVENT_G_TOL or gd[k] < 0.0]
            for k in ks:
                switches_here[(t, k)] = switches_here.get((t, k), 0) + 1
                if switches_here[(t, k)] > MAX_SWITCHES_AT_ONE_INSTANT:
                    raise IntegrationError(f"contact {m.contact_numbers[k]} chatters at "
                                           f"t = {t:.12g}")
            if len(switches_here) > 256:
                switches_here.clear()
            self._switch(t, y, ks, events)
            self._settle(t, y, events)
            armed_out = self._g(y, self._closed)[0] <= 0.0
            rhs = self._rhs_factory(self._closed.copy())
            target, pending = float(out_times[i_out]), None
            post_event = True
        self.stats["wall_time_s"] = _time.perf_counter() - wall0

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

    def _snap(self, t, y, h_last, armed_out, post_event, i_out) -> dict:
        return {"t": float(t), "y": np.array(y), "closed": self._closed.copy(),
                "d_hyst": self._d_hyst, "h_last": h_last, "armed_out": np.array(armed_out),
                "post_event": bool(post_event), "i_out": int(i_out)}

    def _frame(self, step, t, y, events):
        n = self.n
        return Frame(step=step, time=float(t), x=np.array(y[:n]), v=np.array(y[n:2 * n]),
                     closed=self._closed.copy(), dissipated_viscous=float(y[2 * n]),
                     dissipated_hysteresis=self._d_hyst, events=list(events))
