"""The fast backend's pass cut into segments and run on several threads.

A pass over the chain is cut into segments of ``fast_kernel.SEGMENT`` contacts; the segments
may run on any thread, and their results are joined in segment order.  What must hold:

* the thread count changes nothing: 1 and 2 threads give bitwise the same file contents
  (positions, velocities, contact states, events, every ledger term), located and
  step-quantized events alike, with events in several segments and many event windows a
  step (stepped in lanes on the threads);
* the segment size changes nothing but the order in which the damping power is summed:
  positions, velocities, states and events are bitwise those of the one-segment (serial)
  pass, and ``D_viscous`` agrees to round-off;
* the threads take segments and lanes from one shared counter (``backends.atomic``): every
  item is taken exactly once, whatever the count, the claim size and the threads.
"""
import numba
import numpy as np
import pytest
from numba import njit, prange
from hypothesis import given, settings, strategies as st

from mdgran.backends import fast_kernel as fk
from mdgran.backends.atomic import fetch_add
from mdgran.backends.fast import note_threads_ran
from mdgran.model.scene import load_scene
from mdgran.simulation import run

from conftest import make_scene


def fast_run(scene, segment, threads, monkeypatch, **options):
    """The in-memory record of ``scene`` on the fast backend, its pass cut into segments of
    ``segment`` contacts, on ``threads`` threads."""
    monkeypatch.setattr(fk, "SEGMENT", segment)
    res = run(scene, "fast", threads=threads, **options)
    assert res.status == "complete", res.status
    return res


def assert_same_trajectory(a, b):
    """Positions, velocities, contact states and events bitwise equal."""
    ta, tb = a.trajectory, b.trajectory
    for name in ("x", "v", "closed", "ev_time", "ev_contact", "ev_kind"):
        assert np.array_equal(getattr(ta, name), getattr(tb, name)), name


def assert_bitwise(a, b):
    """Everything the record holds bitwise equal, every ledger term included."""
    assert_same_trajectory(a, b)
    for term, values in a.trajectory.ledger.items():
        assert np.array_equal(values, b.trajectory.ledger[term]), term


DRIVEN = [("pulse.amplitude", 5.0), ("pulse.duration", 2.0), ("pulse.bead", 7)]


@pytest.mark.parametrize("name, options, extra", [
    ("micro-star", {}, []), ("macro-hertz", {"locate_events": False}, []),
    ("driven/shaken", {}, DRIVEN)])
def test_two_threads_give_the_one_thread_result_bitwise(name, options, extra, monkeypatch):
    """micro-star (located events), macro-hertz (step-quantized) and a chain driven by a base
    motion and a pulse on bead 7 (in the second segment), 20 beads cut into segments of 6
    contacts: 1 and 2 threads bitwise equal; and, against the uncut pass, the same trajectory
    with D_viscous to round-off."""
    scene = load_scene(name, [("run.duration", 60.0)] + extra)
    one = fast_run(scene, 6, 1, monkeypatch, **options)
    two = fast_run(scene, 6, 2, monkeypatch, **options)
    assert two.stats["threads"] == 2 and one.stats["threads"] == 1
    assert one.stats["events"] > 0
    assert_bitwise(one, two)
    serial = fast_run(scene, 1 << 30, 1, monkeypatch, **options)
    assert_same_trajectory(serial, one)
    d0 = np.asarray(serial.trajectory.ledger["dissipated_viscous"])
    d1 = np.asarray(one.trajectory.ledger["dissipated_viscous"])
    assert np.max(np.abs(d1 - d0)) <= 64 * np.finfo(float).eps * max(d0.max(), 1e-300)


@pytest.mark.parametrize("n, segment, locate", [(100_000, None, False), (3000, 64, True)])
def test_long_chain_with_events_in_many_segments(n, segment, locate, monkeypatch):
    """Chains whose contacts start open and whose beads get thermal velocities, so that
    contacts close all along them: 10^5 beads in 49 segments of the default size with
    step-quantized events, and 3000 beads in 47 segments of 64 with located events (event
    windows in many segments, some across their edges).  2 threads give the 1-thread result
    bitwise."""
    segment = segment or fk.SEGMENT
    scene = load_scene("micro-star", [("chain.n", n), ("chain.initial_gap", 0.002),
                                      ("thermal.temperature", 1e-3), ("run.duration", 1.0),
                                      ("run.output_interval", 0.25)])
    one = fast_run(scene, segment, 1, monkeypatch, locate_events=locate)
    two = fast_run(scene, segment, 2, monkeypatch, locate_events=locate)
    assert two.stats["threads"] == 2
    assert_bitwise(one, two)
    segments = np.unique((one.trajectory.ev_contact - 1) // segment)
    assert len(segments) >= 40, segments


def test_many_event_windows_a_step_stepped_on_the_threads(monkeypatch):
    """A thermal chain of 3 10^4 beads at T = 2, where contacts snap shut and apart all along
    it: more than fast_kernel.PARALLEL_WINDOWS event windows a step, so that two threads
    step them in lanes at once, some widened and stepped again.  2 threads give the
    1-thread result bitwise."""
    scene = load_scene("micro-star", [("chain.n", 30_000), ("thermal.temperature", 2.0),
                                      ("thermal.seed", 1), ("run.duration", 0.5),
                                      ("run.output_interval", 0.25)])
    one = fast_run(scene, fk.SEGMENT, 1, monkeypatch)
    two = fast_run(scene, fk.SEGMENT, 2, monkeypatch)
    assert two.stats["threads"] == 2
    assert_bitwise(one, two)
    steps = 0.5 / scene.run.dt
    assert one.stats["event_windows"] / steps > 2 * fk.PARALLEL_WINDOWS
    assert one.stats["event_windows_widened"] > 0


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 40), segment=st.integers(1, 45), free=st.booleans(),
       locate=st.booleans(), gap=st.sampled_from([0.0, 0.3]))
def test_any_segment_size_keeps_the_trajectory(n, segment, free, locate, gap):
    """Chains of 2-40 beads, fixed or free, gap or none, located or quantized events, any
    segment size: the trajectory is bitwise that of the uncut pass, D_viscous agrees to
    round-off, and the ledger closes as well."""
    scene = make_scene(chain={"n": n, "boundary": "free" if free else "fixed",
                              "initial_gap": gap},
                       impulse={"bead": 1, "velocity": 2.0},
                       run={"duration": 20.0, "output_interval": 0.5, "dt": 0.005})
    with pytest.MonkeyPatch.context() as mp:
        cut = fast_run(scene, segment, 1, mp, locate_events=locate)
        whole = fast_run(scene, 1 << 30, 1, mp, locate_events=locate)
    assert_same_trajectory(whole, cut)
    d0 = np.asarray(whole.trajectory.ledger["dissipated_viscous"])
    d1 = np.asarray(cut.trajectory.ledger["dissipated_viscous"])
    assert np.max(np.abs(d1 - d0)) <= 64 * np.finfo(float).eps * max(d0.max(), 1e-300)
    assert abs(cut.max_ledger_error - whole.max_ledger_error) <= 1e-12


def _forked_case(_):
    scene = load_scene("micro-star", [("chain.n", 5000), ("run.duration", 1.0)])
    res = run(scene, "fast", threads=2)
    return res.status, res.stats["threads"], res.trajectory.x[-1]


def test_a_process_forked_after_threads_runs_on_one():
    """GNU OpenMP stops a forked child that starts threads again (a sweep's workers are
    forked): after this process ran threads, a forked child runs the pass on one thread and
    gets the same result."""
    import multiprocessing

    status, threads, x = _forked_case(0)
    assert (status, threads) == ("complete", 2)
    with multiprocessing.get_context("fork").Pool(1) as pool:
        [(c_status, c_threads, c_x)] = pool.map(_forked_case, [0], chunksize=1)
    from numba import threading_layer
    assert c_status == "complete"
    assert c_threads == (1 if threading_layer() == "omp" else 2)
    assert np.array_equal(c_x, x)


@njit(parallel=True)
def _claim_all(counter, taken, chunk, threads):
    """Items 0 .. len(taken) - 1 claimed ``chunk`` at a time from ``counter[0]`` by
    ``threads`` loops on numba's threads, as the pass claims its segments."""
    counter[0] = 0
    for _ in prange(threads):
        s = fetch_add(counter, 0, chunk)
        while s < taken.size:
            for k in range(s, min(s + chunk, taken.size)):
                taken[k] += 1
            s = fetch_add(counter, 0, chunk)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(0, 200_000), chunk=st.integers(1, 64), threads=st.integers(1, 4))
def test_threads_claiming_from_one_counter_take_each_item_once(n, chunk, threads):
    """Each item is taken once in each of 20 rounds, and the counter ends at the claims
    made: one per chunk, and one more per loop that found nothing left (a lost update of
    the counter would take an item twice or leave the count short)."""
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    counter, taken = np.zeros(1, dtype=np.int64), np.zeros(n, dtype=np.int64)
    for _ in range(20):
        _claim_all(counter, taken, chunk, threads)
        assert counter[0] == (-(-n // chunk) + threads) * chunk
    note_threads_ran()
    assert np.all(taken == 20)
