"""Hard cases (mdgran/scenes/hard/) on the reference backend, each with its pass condition.

The ledger error is judged against the motion's energy scale, max(E_imp, max_t T(t)): in the
grazing case the contact energy released at snap-in is ~800 E_imp.  Long studies run a short
version unless MDGRAN_FULL=1.
"""
import math
import os

import numpy as np
import pytest

from mdgran.model.scene import load_scene
from mdgran.simulation import run

FULL = os.environ.get("MDGRAN_FULL") == "1"


def ledger_rel(res, scene):
    tr = res.trajectory
    scale = max(scene.impulse_energy, float(tr.ledger["kinetic_energy"].max()))
    return float(np.abs(tr.ledger_error(scale)).max())


@pytest.mark.parametrize("name,duration,bound", [
    ("hard/dmt", 100.0, 1e-8),
    ("hard/near-dmt", 100.0, 1e-8),
    ("hard/violent-50", 30.0, 1e-8),
    ("hard/violent-200", 15.0, 1e-8),
    ("hard/stiff-substrate", 100.0, 1e-8),
    ("hard/no-substrate", 100.0, 1e-8),
    ("hard/jkr-displacement", 100.0, 1e-8),
    ("hard/jkr-force", 100.0, 1e-8),
])
def test_hard_case_completes_and_closes_ledger(name, duration, bound):
    sc = load_scene(name, [("run.duration", duration)])
    res = run(sc, "reference")
    assert res.status == "complete"
    assert ledger_rel(res, sc) < bound
    tr = res.trajectory
    n_open = int(np.sum(tr.ev_kind == 0))
    # every open event books exactly the law's snap-off energy
    assert tr.ledger["dissipated_hysteresis"][-1] == pytest.approx(
        n_open * sc.law.loop_energy, rel=1e-9, abs=1e-12)


def test_grazing_contact():
    sc = load_scene("hard/grazing")
    res = run(sc, "reference")
    tr = res.trajectory
    k1, gap = 0.01, 0.5
    w = math.sqrt(k1)
    amp = sc.data["impulse"]["velocity"] / w
    assert tr.ev_kind[0] == 1
    assert tr.ev_time[0] == pytest.approx(math.asin(gap / amp) / w, abs=1e-4)
    assert ledger_rel(res, sc) < 1e-7


def test_tiny_impulse_matches_damped_normal_modes():
    """Linearized about the pre-tensioned state the chain is a damped linear chain whose modes
    are known in closed form (mdgran.analysis.modes.damped_impulse_response)."""
    from mdgran.analysis.modes import damped_impulse_response

    sc = load_scene("hard/tiny")
    tr = run(sc, "reference").trajectory
    d = sc.data
    x = damped_impulse_response(d["chain"]["n"], float(sc.law.stiffness(0.0)),
                                d["substrate"]["k1"], d["contact"]["damping"],
                                d["impulse"]["velocity"], d["impulse"]["bead"], tr.time)
    assert np.abs(tr.x - x).max() < 1e-4 * np.abs(x).max()


#: measured max ledger error of hard/undamped-long on the reference (tol 1e-8), relative to the
#: energy scale: 4.7e-9 to t = 400; 2.0e-8, 4.6e-7, 5.6e-6 to t = 1e3, 1e4, 1e5 (a linear drift
#: of 5.6e-11 per time unit once established; 8.6 minutes for 1e5); bounds with a factor 2 margin
UNDAMPED_BOUND = {400.0: 1e-8, 1e5: 1.2e-5}


def test_undamped_long_run_energy_drift():
    """No damping: the ledger error of the (non-symplectic) reference grows linearly in time
    and must stay within the measured rate (a growing drift would be a bookkeeping error).
    MDGRAN_FULL=1 runs 1e5 time units (about 8 minutes)."""
    duration = 1e5 if FULL else 400.0
    sc = load_scene("hard/undamped-long", [("run.duration", duration)])
    res = run(sc, "reference")
    drift = ledger_rel(res, sc)
    print(f"undamped drift over {duration:g}: {drift:.2e} of the energy scale")
    assert drift < UNDAMPED_BOUND[duration]


@pytest.mark.skipif(not FULL, reason="1e5 beads: about a minute; MDGRAN_FULL=1 runs it")
def test_long_chain():
    sc = load_scene("hard/long-chain")
    res = run(sc, "reference")
    assert ledger_rel(res, sc) < 1e-8


FIXED_STEP = ["lammps", "fast"]
STEP_QUANTIZED_HYSTERESIS = {"lammps": 0.1}


def _available(backend):
    from mdgran.simulation import BackendUnavailable, make_backend

    try:
        make_backend(load_scene("collision-pair"), backend)
    except (BackendUnavailable, ImportError) as exc:
        return str(exc)
    return None


@pytest.mark.parametrize("backend", FIXED_STEP)
@pytest.mark.parametrize("name,duration", [
    ("hard/dmt", 20.0), ("hard/near-dmt", 20.0), ("hard/violent-50", 10.0),
    ("hard/violent-200", 5.0), ("hard/stiff-substrate", 20.0), ("hard/no-substrate", 20.0),
    ("hard/jkr-displacement", 20.0), ("hard/jkr-force", 20.0), ("hard/grazing", 40.0),
    ("hard/tiny", 20.0),
])
def test_hard_case_on_fixed_step_backend(backend, name, duration):
    """Pass condition for a fixed-step backend at the scene's dt: the run completes, its ledger
    closes within 1e-2 of the energy scale (the harness's fixed-step bound), every open event
    books the loop energy (exactly where the backend locates events in the step; within 10% in
    all for LAMMPS, whose step-quantized opens book ``V(delta)`` one step past snap-off:
    measured 5% excess on jkr-force, where the force at snap-off is not zero), and up to t = 2 (well inside every case's horizon) each
    contact has the reference's sequence of closes and opens."""
    why = _available(backend)
    if why:
        pytest.skip(why)
    from mdgran.crosscheck.compare import compare_events

    sc = load_scene(name, [("run.duration", duration)])
    res = run(sc, backend)
    ref = run(sc, "reference").trajectory
    tr = res.trajectory
    assert res.status == "complete"
    if name == "hard/tiny":
        # E_imp = 5e-13 is below the round-off of the contact energies (V(0) ~ 1, and LAMMPS
        # holds absolute positions of order 1: 1 ulp = 2e-16 p, times the pre-tension 1.8,
        # over 21 contacts, ~1% of E_imp).  The motion is judged instead: measured 1.4e-6 of
        # its amplitude at dt = 0.0025 (second order: 5.4e-6 at dt = 0.005).
        assert np.abs(tr.x - ref.x).max() < 1e-4 * np.abs(ref.x).max()
    else:
        assert ledger_rel(res, sc) < 1e-2
    n_open = int(np.sum(tr.ev_kind == 0))
    assert tr.ledger["dissipated_hysteresis"][-1] == pytest.approx(
        n_open * sc.law.loop_energy, rel=STEP_QUANTIZED_HYSTERESIS.get(backend, 1e-9), abs=1e-12)
    t_cmp = 2.0

    def upto(t):
        k = t.ev_time <= t_cmp
        return t.ev_time[k], list(zip(t.ev_contact[k].tolist(), t.ev_kind[k].tolist()))

    ev = compare_events(*upto(ref), *upto(tr), t_cmp, 10 * float(sc.data["run"]["dt"]))
    assert ev["disagreement"] is None, ev
