"""The fast backend against independent values: the reference backend (trajectories, event
sequences), conservation laws (energy ledger, momentum, loop energy per snap-off), and itself
(determinism, checkpoint-resume).  Numba compiles each variant once (cached on disk)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mdgran.backends import fast_kernel as fk
from mdgran.backends.base import IntegrationError
from mdgran.model.scene import SceneError, load_scene
from mdgran.simulation import run

from conftest import assert_same_runs, make_scene


def _slope(dts, errs):
    """Least-squares order p of err ~ dt^p."""
    return float(np.polyfit(np.log(dts), np.log(errs), 1)[0])


def _errors(name, duration, dts, locate, ref_tol):
    over = [("run.duration", duration)]
    ref = run(load_scene(name, over + [("run.tolerance", ref_tol)]), "reference").trajectory
    errs = []
    for dt in dts:
        tr = run(load_scene(name, over + [("run.dt", dt)]), "fast",
                 locate_events=locate).trajectory
        assert len(tr.ev_time) == len(ref.ev_time) > 0  # the window holds events
        errs.append(np.max(np.abs(tr.x - ref.x)))
    return np.array(errs)


# collision-pair: a snap-in and a snap-off (the force ~ sqrt(delta - delta_min) singularity);
# micro-star to t = 20: a wall contact opens and closes; dt divides output_interval
CASES = {"collision-pair": (20.0, [0.002, 0.001, 0.0005, 0.00025], 1e-12),
         "micro-star": (20.0, [0.005, 0.0025, 0.00125, 0.000625], 1e-11)}


@pytest.mark.parametrize("name", sorted(CASES))
def test_second_order_with_located_events_first_order_without(name):
    duration, dts, tol = CASES[name]
    located = _errors(name, duration, dts, True, tol)
    quantized = _errors(name, duration, dts, False, tol)
    p_loc, p_q = _slope(dts, located), _slope(dts, quantized)
    pairwise = np.log2(located[:-1] / located[1:])
    assert p_loc >= 1.8 and pairwise.min() >= 1.6, (located, pairwise)
    assert p_q <= 1.5, quantized  # step-quantized switching: first order through events
    assert quantized[-1] > 10 * located[-1]


@pytest.mark.parametrize("name", ["micro-star", "dmt-chain", "macro-hertz"])
def test_same_event_sequence_as_reference(name):
    over = [("run.duration", 40.0)]
    ref = run(load_scene(name, over), "reference").trajectory
    fast = [run(load_scene(name, over + [("run.dt", dt)]), "fast").trajectory
            for dt in (0.0025, 0.00125)]
    lags = []
    for tr in fast:
        assert len(tr.ev_time) == len(ref.ev_time) > 5
        assert np.array_equal(tr.ev_contact, ref.ev_contact)
        assert np.array_equal(tr.ev_kind, ref.ev_kind)
        lags.append(np.max(np.abs(tr.ev_time - ref.ev_time)))
    assert lags[0] < 0.01 and lags[1] < lags[0] / 3, lags  # event times converge ~ dt^2


def test_thermal_chain_second_order_and_reference_events():
    """300 beads with thermal velocities (T = 2) to t = 4: 149 events all along the chain,
    each handled in its own window of beads (some windows widened: a neighbour's contact
    switching in the same step).  Against the reference (tolerance 1e-10): the same event
    sequence, and trajectory and ledger errors of second order (measured 1.73e-4, 4.28e-5,
    1.07e-5 for the trajectory; 3.1e-5, 8.0e-6, 2.0e-6 for the ledger)."""
    over = [("chain.n", 300), ("thermal.temperature", 2.0), ("thermal.seed", 1),
            ("run.duration", 4.0), ("run.output_interval", 0.5)]
    ref = run(load_scene("micro-star", over + [("run.tolerance", 1e-10)]), "reference")
    dts = [0.005, 0.0025, 0.00125]
    errs, ledger, widened = [], [], 0
    for dt in dts:
        res = run(load_scene("micro-star", over + [("run.dt", dt)]), "fast")
        tr = res.trajectory
        assert len(tr.ev_time) == len(ref.trajectory.ev_time) > 100
        assert np.array_equal(tr.ev_contact, ref.trajectory.ev_contact)
        assert np.array_equal(tr.ev_kind, ref.trajectory.ev_kind)
        assert res.stats["event_windows"] > 100
        widened += res.stats["event_windows_widened"]
        errs.append(np.max(np.abs(tr.x - ref.trajectory.x)))
        ledger.append(res.max_ledger_error)
    assert widened > 0
    for e in (errs, ledger):
        assert np.log2(e[0] / e[1]) >= 1.8 and np.log2(e[1] / e[2]) >= 1.8, (errs, ledger)


@settings(max_examples=12, deadline=None)
@given(n=st.integers(3, 120), seed=st.integers(0, 10**6), gap=st.sampled_from([0.0, 0.01]),
       segment=st.sampled_from([7, 1 << 30]))
def test_momentum_is_kept_through_events(n, seed, gap, segment):
    """A free chain without substrate or damping, its beads given thermal velocities: no
    external force, so the total momentum stays what it was through every event, to
    round-off (the neighbours of an event window take the window's impulse on the contact
    they share), whatever the pass's segments."""
    scene = make_scene(chain={"n": n, "boundary": "free", "initial_gap": gap},
                       substrate={"k1": 0.0}, contact={"damping": 0.0},
                       thermal={"temperature": 2.0, "seed": seed}, impulse={"velocity": 0.0},
                       run={"duration": 5.0, "output_interval": 0.5, "dt": 0.0025})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fk, "SEGMENT", segment)
        res = run(scene, "fast", threads=1)
    assert res.status == "complete"
    p = res.trajectory.v.sum(axis=1)
    scale = np.abs(res.trajectory.v).sum(axis=1).max()
    assert np.max(np.abs(p - p[0])) <= 1e-13 * n * scale, (res.stats["events"], p - p[0])


@pytest.mark.parametrize("threads", [1, 2])
def test_beads_at_rest_are_skipped_exactly(threads):
    """micro-star struck at bead 1, chains of 2,000 and 100,000 beads to t = 20: the pulse
    never reaches bead 2,000 (38 beads move), so the two chains' beads 1-2,000 have the same
    motion, bit for bit; the long chain steps only the segments its activity front covers
    (its 2,000-bead twin is one segment, stepped whole every step)."""
    over = [("run.duration", 20.0), ("run.output_interval", 1.0)]
    short = run(load_scene("micro-star", over + [("chain.n", 2000)]), "fast", threads=1)
    long = run(load_scene("micro-star", over + [("chain.n", 100_000)]), "fast",
               threads=threads)
    a, b = short.trajectory, long.trajectory
    assert not (a.v[:, 1500:] != 0).any() and (a.v[:, 30] != 0).any()
    for name in ("x", "v"):
        assert np.array_equal(getattr(a, name), getattr(b, name)[:, :2000]), name
        assert not getattr(b, name)[:, 2000:].any(), name
    assert np.array_equal(a.closed, b.closed[:, :2001])
    for name in ("ev_time", "ev_contact", "ev_kind"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert short.stats["bead_steps"] == 2000 * short.stats["steps"]
    assert long.stats["bead_steps"] < 0.03 * 100_000 * long.stats["steps"]


@settings(max_examples=15, deadline=None)
@given(n=st.integers(8, 60), segment=st.integers(2, 9), free=st.booleans(),
       gap=st.sampled_from([0.0, 0.002]), start=st.sampled_from([0.0, 1.5]),
       bead=st.integers(1, 60), mixed=st.booleans())
def test_a_pulse_anywhere_is_stepped_as_the_whole_chain(n, segment, free, gap, start, bead,
                                                        mixed):
    """A force pulse on any bead of a chain at rest (from t = 0 or later), fixed or free,
    with or without a gap, of like or unlike beads, its pass cut into segments of 2-9
    contacts so that the activity front skips the segments at rest: positions, velocities,
    contact states and events bitwise those of the uncut pass, which steps every bead."""
    sections = dict(chain={"n": n, "boundary": "free" if free else "fixed",
                           "initial_gap": gap},
                    impulse={"velocity": 0.0},
                    pulse={"amplitude": 3.0, "duration": 0.5, "start": start,
                           "bead": min(bead, n)},
                    run={"duration": 8.0, "output_interval": 0.5, "dt": 0.005})
    if mixed:
        sections["beads"] = {"density": [1.0 + (i % 2) for i in range(n)]}
    scene = make_scene(**sections)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fk, "SEGMENT", segment)
        cut = run(scene, "fast", threads=1)
        mp.setattr(fk, "SEGMENT", 1 << 30)
        whole = run(scene, "fast", threads=1)
    assert cut.status == whole.status == "complete"
    for name in ("x", "v", "closed", "ev_time", "ev_contact", "ev_kind"):
        assert np.array_equal(getattr(cut.trajectory, name), getattr(whole.trajectory, name))
    assert cut.stats["bead_steps"] <= whole.stats["bead_steps"]


def test_ledger_closure_scales_like_dt_squared():
    over = [("run.duration", 60.0)]
    dts = [0.005, 0.0025, 0.00125]
    errs = []
    for dt in dts:
        r = run(load_scene("micro-star", over + [("run.dt", dt)]), "fast")
        assert r.trajectory.ledger["dissipated_hysteresis"][-1] > 0  # snap-offs happened
        errs.append(r.max_ledger_error)
    assert 1.8 <= _slope(dts, errs) <= 2.3, errs
    assert errs[1] < 1e-4  # of the impulse energy, at the scene's dt


def test_collision_pair_conservation_laws():
    sc = load_scene("collision-pair", [("run.dt", 0.001)])
    from mdgran.model.chain import model_from_scene

    w = model_from_scene(sc).law.loop_energy
    tr = run(sc, "fast").trajectory
    # momentum: contact forces are equal and opposite, no substrate
    assert np.allclose(tr.v.sum(axis=1), 3.0, rtol=0, atol=1e-12)
    # each snap-off loses V(delta_off) = W; the step ends on delta_off to rounding
    n_open = int(np.sum(tr.ev_kind == 0))
    assert n_open == 1
    assert tr.ledger["dissipated_hysteresis"][-1] == pytest.approx(n_open * w, rel=1e-12)


def test_dt_must_divide_output_interval():
    with pytest.raises(SceneError, match="run.dt"):
        run(load_scene("micro-star", [("run.duration", 1.0), ("run.dt", 0.003)]), "fast")


def test_compression_beyond_table_is_an_integration_error():
    sc = load_scene("collision-pair", [("impulse.velocity", 40.0), ("run.duration", 2.0)])
    # at the step's end (compression past 2) or inside it (a trial state past the table)
    with pytest.raises(IntegrationError, match=r"t = .*contact 2|contact 2 left the contact "
                       r"table .* inside the step ending at t = "):
        run(sc, "fast", delta_max=2.0)



@pytest.mark.parametrize("name,locate", [("dmt-chain", True), ("micro-star", False)])
def test_frames_independent_of_kernel_blocks_and_event_log_size(monkeypatch, tmp_path, name,
                                                               locate):
    """The loop runs a block of frames per call and hands the event log back when half full;
    the driver hands the blocks whole to the file and the in-memory record: a block of one
    frame and a 16-event log (full at 8 events, mid-frame) must give the same frames, events,
    ledgers and file, bit for bit, as the defaults (one block for the whole run)."""
    import mdgran.backends.fast as fast

    sc = load_scene(name, [("run.duration", 60.0), ("run.output_interval", 10.0)])
    a = run(sc, "fast", out=tmp_path / "a.h5", locate_events=locate).trajectory
    assert np.diff(np.searchsorted(a.ev_time, a.time)).max() > 8  # some frame fills the log
    monkeypatch.setattr(fast, "EVENT_BUFFER", 16)
    monkeypatch.setattr(fast, "BLOCK_BEAD_STEPS", 1)
    b = run(sc, "fast", out=tmp_path / "b.h5", locate_events=locate).trajectory
    assert_same_runs(a, b, tmp_path / "a.h5", tmp_path / "b.h5")


def test_loop_runs_without_reference_counting(monkeypatch):
    """The compiled loop of a variant is built without numba's reference counting (``_nrt =
    False``: the atomic increments of every array taken out of a record were ~80 % of a
    small chain's step); a variant that needs the runtime after all fails to compile and is
    then built with it, on the same call."""
    from numba.core.errors import NumbaError

    res = run(load_scene("micro-star", [("run.duration", 1.0)]), "fast")
    assert res.status == "complete"
    lean = [k for f, k in fk._KERNELS.items() if hasattr(k, "targetoptions")]
    assert lean and all(k.targetoptions.get("_nrt") is False for k in lean)

    built = []

    def fake_make(flags, nrt):
        built.append(nrt)
        if not nrt:
            def fails(*args):
                raise NumbaError("NRT required but not enabled")
            return fails
        return lambda *args: sum(args)

    monkeypatch.setattr(fk, "_make_advance", fake_make)
    flags = fk.Flags(*([False] * 7))
    monkeypatch.setitem(fk._KERNELS, flags, None)
    del fk._KERNELS[flags]
    assert fk.get_kernel(flags)(1, 2, 3) == 6 and built == [False, True]
    assert fk._KERNELS[flags](4, 5) == 9


def test_flag_indices_name_the_fields_of_flags():
    """The kernel reads a variant's flags by index (``flags[PULSE]``, a tuple of literal
    booleans); each index constant is its field's position in :class:`Flags`."""
    for k, name in enumerate(fk.Flags._fields):
        assert getattr(fk, name.upper()) == k, name


def test_a_call_of_the_loop_keeps_to_its_step_budget(monkeypatch):
    """A signal is honoured between calls of the compiled loop, so a call takes at most its
    step budget (about CALL_SECONDS at the last call's pace; events can make a step cost many
    nominal bead-steps), stopping inside a frame if it must: an active chain run with a budget
    of a few steps is bitwise the run in whole frames, events included."""
    from mdgran.backends import fast as fast_backend

    over = [("chain.n", 3000), ("thermal.temperature", 2.0), ("thermal.seed", 1),
            ("run.duration", 4.0)]  # 8 frames a call, 5 calls
    whole = run(load_scene("micro-star", over), "fast", threads=1)
    calls = []
    real_call = fast_backend.FastBackend._call

    def counted(self, kernel_args, i, nframes):
        budget = self._step_budget()
        step0 = int(self.counters["step"])
        out = real_call(self, kernel_args, i, nframes)
        calls.append((budget, int(self.counters["step"]) - step0, out[1]))
        return out

    monkeypatch.setattr(fast_backend, "CALL_SECONDS", 1e-6)
    monkeypatch.setattr(fast_backend.FastBackend, "_call", counted)
    cut = run(load_scene("micro-star", over), "fast", threads=1)
    assert all(steps <= budget for budget, steps, _ in calls[1:])
    assert sum(done == 0 for _, _, done in calls) > 10  # calls that ended inside a frame
    for name in ("x", "v", "closed", "ev_time", "ev_contact", "ev_kind"):
        assert np.array_equal(getattr(whole.trajectory, name), getattr(cut.trajectory, name))
    assert whole.stats["events"] == cut.stats["events"] > 50
