"""The primary pulse in long chains (mdgran.studies.long_chain): the tracker against the frames it
saw, the beads' energies against the ledger, and the measures against chain length."""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import make_scene

from mdgran.model.chain import model_from_scene
from mdgran.studies.long_chain import PulseTracker, bead_energies, pulse_profile, run_pulse
from mdgran.simulation import run


@settings(max_examples=6, deadline=None)
@given(n=st.integers(20, 400), free=st.booleans(), gap=st.sampled_from([0.0, 0.002]),
       law=st.sampled_from(["schwarz", "dmt", "hertz"]), v0=st.sampled_from([5.0, 40.0]))
def test_the_tracker_keeps_what_the_frames_show(n, free, gap, law, v0):
    """The tracker's largest speeds and their first times are those of the frames kept in
    memory; its snap-offs and open contacts those of the record, for fixed and free chains,
    with and without a gap, three laws."""
    scene = make_scene(chain={"n": n, "boundary": "free" if free else "fixed",
                              "initial_gap": gap},
                       contact={"law": law}, impulse={"velocity": v0},
                       run={"duration": 5.0, "output_interval": 0.25, "dt": 0.0025})
    tracker = PulseTracker(n)
    res = run(scene, "fast", reporters=[tracker], threads=1)
    tr = res.trajectory
    speed = np.abs(tr.v)
    assert np.array_equal(tracker.peak_v, speed.max(axis=0))
    moved = speed.max(axis=0) > 0
    first = tr.time[np.argmax(speed, axis=0)]
    assert np.array_equal(tracker.peak_t[moved], first[moved])
    assert np.isnan(tracker.peak_t[~moved]).all()
    prof = pulse_profile(tracker, model_from_scene(scene), v0)
    assert prof["snapoffs_total"] == int(np.sum(tr.ev_kind == 0))
    assert prof["open_contacts"] == int((~tr.closed[-1]).sum())


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 60), free=st.booleans(), gap=st.sampled_from([0.0, 0.002]),
       law=st.sampled_from(["schwarz", "dmt", "hertz"]), k3=st.sampled_from([0.0, 0.5]),
       seed=st.integers(0, 1000))
def test_bead_energies_add_up_to_the_ledger(n, free, gap, law, k3, seed):
    """Each bead's energy (its kinetic and substrate energy and half of each of its closed
    contacts') summed over the beads is the ledger's kinetic + contact + substrate energy,
    for random states of fixed and free chains, with and without a gap, three laws, a linear
    and cubic substrate."""
    if free and n < 2:
        n = 2
    model = model_from_scene(make_scene(
        chain={"n": n, "boundary": "free" if free else "fixed", "initial_gap": gap},
        contact={"law": law}, substrate={"k1": 0.3, "k3": k3}))
    rng = np.random.default_rng(seed)
    x, v = rng.normal(0.0, 0.05, n), rng.normal(0.0, 1.0, n)
    closed = rng.random(model.n_contacts) < 0.7
    e = bead_energies(model, x, v, closed)
    led = model.ledger(x, v, closed, 0.0, 0.0)
    mech = led["kinetic_energy"] + led["contact_energy"] + led["substrate_energy"]
    assert len(e) == n and abs(e.sum() - mech) <= 1e-12 * max(1.0, abs(mech))


def test_measures_do_not_depend_on_length_beyond_the_reach():
    """micro-star's pulse to t = 20 reaches ~60 beads: chains of 300 and 30,000 beads give the
    same largest speeds bit for bit, the same reach, speed, open contacts and energy left."""
    a, ra = run_pulse(300, 12.0, None, 20.0)
    b, rb = run_pulse(30_000, 12.0, None, 20.0)
    assert ra.status == rb.status == "complete"
    assert 10 < a["reach"] < 300 and a["reach"] == b["reach"]
    assert np.array_equal(a["peak_v"], b["peak_v"][:300]) and not b["peak_v"][300:].any()
    assert a["speed_beads_per_time"] == b["speed_beads_per_time"] > 0
    assert a["open_contacts"] == b["open_contacts"]
    assert np.array_equal(a["energy_left"][:a["reach"]], b["energy_left"][:a["reach"]])


def test_the_native_fix_carries_the_same_pulse(plugin):
    """The cross-check of the long-chain study: micro-star's pulse to t = 20 on 30,000 beads
    split over 2 MPI ranks on the native LAMMPS fix (each frame gathers the moved beads alone)
    against the fast backend's on 3,000: per-bead largest speeds within 1e-8 v0 (round-off:
    the fix works in absolute positions; measured 2.3e-12), the same reach and snap-offs.  A
    disagreeing check is a run that is not complete in the report."""
    from mdgran.studies.long_chain import compare_backends
    from mdgran.studies.paper_study import long_chain_markdown

    fast = run_pulse(3000, 12.0, None, 20.0)
    check = compare_backends(fast, 30_000, 20.0, "lammps:native", ranks=2)
    assert check["agree"] and check["status"] == "complete", check
    assert check["max_peak_v_difference_over_v0"] < 1e-8
    assert 10 < check["reach"][1] < 300
    bad = dict(check, agree=False)
    study = {"runs": [], "converged_peak_v": {}, "duration": 20.0, "cross_check": bad}
    assert any("DISAGREES" in line for line in long_chain_markdown(study))
    # ranks that stop without measures (a chain of no beads is refused on every rank) are a
    # check that failed, not one that could not run
    failed = compare_backends(fast, 0, 20.0, "lammps:native", ranks=2)
    assert "unavailable" not in failed and not failed["agree"]
    assert failed["status"].startswith("failed: 2 ranks exited"), failed["status"]
