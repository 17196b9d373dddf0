"""Run-time invariants every backend must keep, as pure check functions.

The idea: after every accepted step, hence at every stored frame, each contact's state agrees
with its compression ``delta`` (units of p):

* a CLOSED contact is not below its switching point: ``delta >= law.delta_off - tol``
  (``delta_min`` for the displacement snap-off rule, the force-maximum point for the
  ``"force"`` rule, 0 for DMT and Hertz);
* an OPEN contact is not past contact: ``delta <= tol``.  An open contact with ``delta > tol``
  means the beads overlap with no force between them (beads passing through each other).

Two consequences are checked too: the energy ledger closes (``total_energy`` stays at its
initial value, error relative to the impulse energy ``E_imp = v0^2 / 2``, units eta p), and
with the displacement rule every opening loses exactly the loop energy
(``D_hysteresis = opens * W``; for unlike beads each opening its own contact's).

:func:`check_run` runs a scene through the driver with a reporter that checks every frame
and returns a :class:`RunCheck` with everything found; tests and
``benchmarks/invariant_campaign.py`` use it.  :func:`matched_events` compares two runs' event
sequences.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

#: Default tolerance on delta (units of p) for the state invariant.
STATE_TOL = 1e-9
#: Kinds of violation reported by :func:`frame_violations`.
CLOSED_BELOW = "closed_below_off"
OPEN_OVERLAP = "open_overlap"
#: Keep at most this many example violations per run (all are counted).
MAX_EXAMPLES = 10


def closed_below_off(model, frame, tol: float = STATE_TOL) -> list:
    """Closed contacts with ``delta < delta_off - tol``: ``[(contact number, kind, delta)]``."""
    delta = model.compressions(frame.x)
    bad = np.asarray(frame.closed) & (delta < model.delta_off - tol)  # per contact if mixed
    nums = model.contact_numbers
    return [(int(nums[k]), CLOSED_BELOW, float(delta[k])) for k in np.flatnonzero(bad)]


def interpenetration(model, frame, tol: float = STATE_TOL) -> list:
    """Open contacts with ``delta > tol`` (overlapping beads that carry no force):
    ``[(contact number, kind, delta)]``."""
    delta = model.compressions(frame.x)
    bad = ~np.asarray(frame.closed) & (delta > tol)
    nums = model.contact_numbers
    return [(int(nums[k]), OPEN_OVERLAP, float(delta[k])) for k in np.flatnonzero(bad)]


def frame_violations(model, frame, tol: float = STATE_TOL) -> list:
    """Every contact whose state disagrees with its compression beyond ``tol`` (units of p):
    ``[(contact number, kind, delta)]``, kind :data:`CLOSED_BELOW` or :data:`OPEN_OVERLAP`."""
    return closed_below_off(model, frame, tol) + interpenetration(model, frame, tol)


def expected_hysteresis(model, events) -> float:
    """``sum over the openings of V(delta_off)`` of the opening contact (units eta p):
    ``opens * W`` for one law, each contact's own loop energy for unlike beads; ``events``
    ``(time, contact number, kind)``."""
    loops = np.broadcast_to(np.asarray(model.loop_energy, dtype=float), (model.n_contacts,))
    column = {int(c): k for k, c in enumerate(model.contact_numbers)}
    return float(sum(loops[column[int(c)]] for _, c, kind in events if kind == 0))


def hysteresis_check(expected: float, d_hysteresis: float, rtol: float = 1e-6,
                     atol: float = 1e-12) -> tuple:
    """``D_hysteresis`` against the openings' ``V(delta_off)`` (:func:`expected_hysteresis`).

    ``law.loop_energy`` is ``V(delta_off)``: the loop energy ``W`` for the displacement rule,
    ``V`` at the force maximum for the force rule, 0 for DMT and Hertz.  Exact only if every
    opening happens at ``delta_off`` (an opening found late, below it, loses a different
    energy for the force rule; for the displacement rule ``V`` is clamped below
    ``delta_min``, so a late opening shows in the ledger instead).  Returns ``(ok, expected,
    relative error)``; ``ok`` when ``|D - expected| <= rtol * expected + atol``.
    """
    err = abs(d_hysteresis - expected)
    rel = err / expected if expected else err
    return bool(err <= rtol * expected + atol), expected, float(rel)


@dataclass
class RunCheck:
    """What :func:`check_run` found in one run.

    ``violations`` holds up to :data:`MAX_EXAMPLES` examples ``(time, contact, kind, delta)``;
    ``counts`` counts every violating (frame, contact) by kind.  ``events`` is the run's event
    list ``(time, contact, kind)`` (kind 1 close, 0 open).  ``ledger_error`` is the largest
    ``|total - total(t=0)| / E_imp`` over the frames, ``ledger_bound`` the backend's declared
    bound of it (:meth:`~mdgran.backends.base.Backend.ledger_bound`).  ``status`` is the driver's
    (``"complete"``, ``"ledger-exceeded: ..."``, ``"failed: ..."``) or ``"error: ..."``.
    """

    backend: str
    frames: int = 0
    violations: list = field(default_factory=list)
    counts: dict = field(default_factory=dict)
    first_violation_time: float | None = None
    events: list = field(default_factory=list)
    ledger_error: float = 0.0
    ledger_bound: float = float("inf")  # the backend's declared bound (Backend.ledger_bound)
    d_hysteresis: float = 0.0
    hysteresis: tuple | None = None
    status: str = "complete"
    wall_s: float = 0.0

    @property
    def n_violations(self) -> int:
        return sum(self.counts.values())

    @property
    def opens(self) -> int:
        return sum(1 for e in self.events if e[2] == 0)


def _record(res: RunCheck, t: float, found: list):
    for num, kind, delta in found:
        res.counts[kind] = res.counts.get(kind, 0) + 1
        if res.first_violation_time is None:
            res.first_violation_time = t
        if len(res.violations) < MAX_EXAMPLES:
            res.violations.append((t, num, kind, delta))


class _FrameCheck:
    """A reporter for :func:`mdgran.simulation.run`: the state invariant and the events of
    every frame, into a :class:`RunCheck`."""

    def __init__(self, res: RunCheck, model, tol: float):
        self.res, self.model, self.tol = res, model, tol

    def report(self, frame, ledger):
        res = self.res
        res.frames += 1
        res.events += [(e.time, e.contact, e.kind) for e in frame.events]
        _record(res, frame.time, frame_violations(self.model, frame, self.tol))
        res.d_hysteresis = frame.dissipated_hysteresis

    def close(self, status):
        pass


def check_run(scene, backend: str, tol: float = STATE_TOL, hyst_rtol: float = 1e-6,
              **options) -> RunCheck:
    """Run ``scene`` on ``backend`` through the driver (``options`` go to the backend) and
    check every frame.

    State invariant at ``tol`` (units of p) on every frame; the ledger error and its bound are
    the driver's (``max |E - E0| / E_imp``, :meth:`~mdgran.backends.base.Backend.ledger_bound`),
    and so is ``status``; at the end :func:`hysteresis_check` at ``hyst_rtol``.  A run that
    raises anything else is recorded as ``"error: ..."`` with the frames checked so far.
    """
    from mdgran.model.chain import model_from_scene
    from mdgran.simulation import run

    res = RunCheck(backend)
    wall0 = _time.perf_counter()
    model = model_from_scene(scene)
    try:
        result = run(scene, backend, keep=False, raise_errors=False,
                     reporters=[_FrameCheck(res, model, tol)], **options)
        res.status = result.status
        res.ledger_error, res.ledger_bound = result.max_ledger_error, result.ledger_bound
    except Exception as exc:  # noqa: BLE001 - a crash is a finding, recorded not raised
        res.status = f"error: {type(exc).__name__}: {exc}"
    res.hysteresis = hysteresis_check(expected_hysteresis(model, res.events), res.d_hysteresis,
                                      hyst_rtol)
    res.wall_s = _time.perf_counter() - wall0
    return res


def event_sequence(events: list) -> list:
    """``(contact, kind)`` in time order (ties by contact number)."""
    return [(c, k) for _, c, k in sorted(events, key=lambda e: (e[0], e[1]))]


def matched_events(a: list, b: list) -> int:
    """Number of leading events the two runs share (same contact, same kind, in time order)."""
    sa, sb = event_sequence(a), event_sequence(b)
    n = 0
    for ea, eb in zip(sa, sb):
        if ea != eb:
            break
        n += 1
    return n
