"""The reference loop's named steps: checkpoint contents, resume, the chatter guard,
the move of an event's target, and the integrate step's stopping rules, each on a small case."""
import numpy as np
import pytest

from mdgran.backends import reference as ref_mod
from mdgran.backends.base import IntegrationError
from mdgran.model.scene import load_scene
from mdgran.simulation import make_backend

KEYS = ["t", "y", "closed", "d_hyst", "h_last", "armed_out", "post_event", "i_out"]


def pair(duration=2.0):
    return make_backend(load_scene("collision-pair", [("run.duration", duration)]), "reference")


def test_checkpoint_keys_and_a_resume_are_exact():
    """The checkpoint stores exactly the loop state it always stored, and a resume from the
    middle of a run (after the closing event) gives the same frames, bit for bit."""
    b = pair()
    frames, states = [], []
    for fr in b.frames():
        frames.append(fr)
        states.append(b.checkpoint_state())
    assert list(states[0]) == KEYS and states[0]["i_out"] == 0
    assert sum(len(f.events) for f in frames) >= 1
    mid = len(frames) // 2
    again = pair()
    rest = list(again.frames(resume=states[mid]))
    assert len(rest) == len(frames) - mid - 1
    for a, b2 in zip(frames[mid + 1:], rest):
        assert a.time == b2.time and a.x.tobytes() == b2.x.tobytes()
        assert a.v.tobytes() == b2.v.tobytes() and a.closed.tolist() == b2.closed.tolist()
        assert a.dissipated_viscous == b2.dissipated_viscous
        assert [(e.time, e.contact, e.kind) for e in a.events] == \
               [(e.time, e.contact, e.kind) for e in b2.events]


def test_chatter_guard_counts_per_instant():
    """Up to MAX_SWITCHES_AT_ONE_INSTANT switches of one contact at one instant pass; one more
    stops the run naming the contact; another instant starts a new count."""
    b = pair()
    next(b.frames())  # builds the state
    y = b.checkpoint_state()["y"]
    count = {}
    for _ in range(ref_mod.MAX_SWITCHES_AT_ONE_INSTANT):
        b._chatter_guard(count, 1.0, [0], y)
    b._chatter_guard(count, 2.0, [0], y)
    num = int(b.model.contact_numbers[0])
    with pytest.raises(IntegrationError, match=rf"contact {num} chatters at t = 1: "):
        b._chatter_guard(count, 1.0, [0], y)


def test_short_of_point_moves_the_target():
    """A pending contact still approaching (g > EVENT_G_TOL, g' < 0) moves the target on by
    g / |g'|, at most to the output time; one on its point does not."""
    b = pair()
    s = ref_mod._Loop(t=1.0, y=np.zeros(5), target=1.0)
    g, gd = np.array([1e-6]), np.array([-1.0])
    assert b._short_of_point(s, [0], g, gd, 2.0) and s.target == 1.0 + 1e-6
    assert b._short_of_point(s, [0], g, gd, 1.0 + 1e-7) and s.target == 1.0 + 1e-7
    s.target = 1.0
    assert not b._short_of_point(s, [0], np.array([1e-14]), gd, 2.0) and s.target == 1.0
    assert not b._short_of_point(s, [0], g, np.array([1.0]), 2.0)


def test_integrate_stops_at_the_event_then_arrive_switches_it():
    """collision-pair (gap 0.5, v0 = 3): the first segment towards the first output time
    contains the closing at t = 1/6, so it ends as a restart with contact 0 pending and the
    event as target; integrating to it and arriving switches the contact there."""
    b = pair()
    gen = b.frames()
    next(gen)
    s = ref_mod._Loop(**{k: v for k, v in b.checkpoint_state().items()
                         if k not in ("closed", "d_hyst")})
    s.target = 1.0  # past the event (beyond the scene's first output time)
    s.rhs = b._rhs_factory(b._closed.copy())
    while s.pending is None:
        assert not b._integrate(s)
    assert set(s.pending) == {0} and s.target == pytest.approx(0.5 / 3.0, abs=1e-12)
    while s.target > s.t and not b._integrate(s):
        pass
    b._arrive(s, 1.0)
    assert s.pending is None and s.target == 1.0 and s.post_event
    assert b._closed.tolist() == [True] and [e.kind for e in s.events] == [1]
    assert s.events[0].time == pytest.approx(0.5 / 3.0, abs=1e-12)
