"""The driver takes frames by blocks: a reporter with ``report_block`` gets each
block whole, one with ``report`` alone gets the same frames one by one, with the ledger that
ChainModel.ledger gives each frame; the run's ledger error is the largest over every frame,
and NaN once any frame's is NaN; the fast backend's calls on a thread of their own change
nothing."""
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import assert_same_runs

from mdgran.backends.base import CLOSE, OPEN, Event, Events
from mdgran.model.chain import model_from_scene
from mdgran.model.scene import load_scene
from mdgran.simulation import run, worst


class ByFrame:
    def __init__(self):
        self.frames, self.ledgers = [], []

    def report(self, frame, ledger):
        self.frames.append(frame)
        self.ledgers.append(ledger)

    def close(self, status):
        self.status = status


class ByBlock:
    def __init__(self):
        self.blocks = []

    def report_block(self, block):
        self.blocks.append(block)

    def close(self, status):
        self.status = status


def test_block_and_frame_reporters_see_the_same_frames():
    sc = load_scene("micro-star", [("run.duration", 60.0)])
    one, whole = ByFrame(), ByBlock()
    res = run(sc, "fast", reporters=[one, whole])
    assert one.status == whole.status == res.status == "complete"
    tr = res.trajectory
    assert len(one.frames) == sum(map(len, whole.blocks)) == len(tr.time) == 601
    assert len(whole.blocks) < len(one.frames)  # by blocks indeed
    x = np.array([f.x for f in one.frames])
    assert x.tobytes() == np.concatenate([b.x for b in whole.blocks]).tobytes() == tr.x.tobytes()
    events = [(e.time, e.contact, e.kind) for f in one.frames for e in f.events]
    assert events == list(zip(tr.ev_time, tr.ev_contact, tr.ev_kind)) and len(events) > 5
    for f in one.frames:  # each frame's events in (previous frame, frame]
        assert all(f.time - 0.1 < e.time <= f.time for e in f.events)
    m = model_from_scene(sc)
    for f, led in zip(one.frames, one.ledgers):
        own = m.ledger(f.x, f.v, f.closed, f.dissipated_viscous, f.dissipated_hysteresis)
        assert [float(a).hex() for a in led.values()] == [float(b).hex() for b in own.values()]
    for name in tr.ledger:
        col = np.array([led[name] for led in one.ledgers])
        assert col.tobytes() == tr.ledger[name].tobytes(), name


errors = st.lists(st.lists(st.floats(0.0, 1e3) | st.just(float("nan")), min_size=1,
                           max_size=5), min_size=1, max_size=6)


@given(errors)
def test_worst_error_is_the_max_over_every_frame_and_nan_once_any_is(blocks):
    got = 0.0
    for b in blocks:
        got = worst(got, np.array(b))
    flat = [e for b in blocks for e in b]
    if any(e != e for e in flat):
        assert got != got
    else:
        assert got == max([0.0, *flat])


@pytest.mark.parametrize("options", [{}, {"delta_max": 2.0}])
def test_kernel_thread_changes_nothing(monkeypatch, tmp_path, options):
    """The fast backend runs its next call of the compiled loop on a thread of its own while
    the driver takes the block before (with two cores or more): the same frames, events,
    ledgers, file and status as calls in line, also when a call ends the run with an error
    (delta_max = 2: the table is left at t = 0.17, in the second call, on the thread)."""
    import mdgran.backends.fast as fast

    submitted = []

    class Counting(fast.ThreadPoolExecutor):
        def submit(self, *args, **kw):
            submitted.append(args[1:])
            return super().submit(*args, **kw)

    sc = load_scene("micro-star", [("run.duration", 40.0)])
    monkeypatch.setattr(fast, "BLOCK_BEAD_STEPS", 800)  # a frame a call
    monkeypatch.setattr(fast, "ThreadPoolExecutor", Counting)
    results = []
    for cores in (2, 1):
        monkeypatch.setattr(fast, "usable_threads", lambda threads, c=cores: c)
        res = run(sc, "fast", out=tmp_path / f"{cores}.h5", raise_errors=False, **options)
        results.append(res)
        if cores == 2:
            assert len(submitted) >= (1 if options else 2)  # the thread ran calls
            submitted.clear()
    assert not submitted  # one core: every call in line
    a, b = (r.trajectory for r in results)
    assert results[0].status == results[1].status
    assert (results[0].status == "complete") == (not options), results[0].status
    assert_same_runs(a, b, tmp_path / "2.h5", tmp_path / "1.h5")


event_lists = st.lists(st.builds(
    Event, st.floats(0.0, 1e3, allow_nan=False), st.integers(1, 10**6),
    st.sampled_from([CLOSE, OPEN])), max_size=30)


@given(event_lists, st.integers(0, 30), st.integers(0, 30))
def test_events_as_arrays_are_the_list_of_events(events, cut, stop):
    """Events (the arrays blocks carry) behave as the list of Event s they hold: items,
    slices, iteration, joining and comparison; and back to the same arrays."""
    arrays = Events.of(events)
    assert len(arrays) == len(events) and list(arrays) == events and arrays == events
    assert [arrays[k] for k in range(len(events))] == events
    assert list(arrays[cut:stop]) == events[cut:stop]
    joined = Events.join([events[:cut], arrays[cut:stop], Events.of(events[stop:])])
    assert joined == events[:cut] + events[cut:stop] + events[stop:]
    assert list(arrays[:cut] + events[cut:]) == events
    assert Events.of(list(arrays)).time.tobytes() == arrays.time.tobytes()
    assert arrays.kind.dtype == np.int8 and arrays.contact.dtype == np.int64
    if events:
        other = list(events)
        other[-1] = Event(other[-1].time, other[-1].contact, 1 - other[-1].kind)
        assert arrays != other
