"""mdgran's laws against LAMMPS's own granular models (no hook), at the documented mapping.

Tolerances: the static force checks are round-off (positions in metres: 1e-9 relative for
the macro bead); the dynamics are step-quantized at snap events in LAMMPS (first order in dt),
so each dynamic check either runs two dt and asserts that the error shrinks by the expected
factor, or holds the error to a bound derived from one step of quantization.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from mdgran.model.scene import load_scene
from mdgran.simulation import run

sys.path.append(str(Path(__file__).resolve().parents[1] / "benchmarks"))

import native_lammps as nl  # noqa: E402  benchmarks/native_lammps.py, beside its study

pytestmark = pytest.mark.lammps


def jkr_pair(v0, snap_off="force", duration=5.0):
    return load_scene("collision-pair", [("contact.law", "jkr"), ("contact.snap_off", snap_off),
                                         ("impulse.velocity", v0),
                                         ("run.duration", duration)])


def test_mapping_constants():
    """E_mix = 3K/4 and gamma = w/2; under the table convention E_lammps = 3E/4."""
    m = nl.native_mapping(load_scene("macro-hertz")).as_dict()
    assert m["E_mix_over_K"] == pytest.approx(0.75, rel=1e-14)
    assert m["E_lammps_Pa"] == pytest.approx(0.75 * 338e9, rel=1e-14)
    j = nl.native_mapping(jkr_pair(3.0))
    assert j.gamma == pytest.approx(0.5 * j.scales.w)
    text = load_scene("macro-hertz", [("material.modulus", "text")])
    assert nl.native_mapping(text).E == pytest.approx(338e9, rel=1e-14)


def test_jkr_force_law_and_snap_off_rule():
    """LAMMPS jkr = mdgran's JKR law on the attached branch to round-off, and it lets go at
    the tensile force maximum (snap_off = "force"), not at delta_min (displacement rule)."""
    sc = jkr_pair(3.0)
    law = sc.law
    d = np.linspace(5.0, law.delta_off + 1e-9, 300)
    assert np.max(np.abs(nl.probe_force(sc, d) - law.force(d))) < 1e-10
    off = law.delta_off
    f = nl.probe_force(sc, [1.0, off + 1e-7, off - 1e-7])
    assert f[1] == pytest.approx(-1.5, abs=1e-9) and f[2] == 0.0
    m = nl.native_mapping(sc)
    assert nl.lammps_pulloff_distance(m) / m.scales.p == pytest.approx(-law.delta_force_max,
                                                                       rel=1e-12)
    assert law.delta_min < off - 0.4  # the displacement rule would hold on much longer


def test_hertz_and_dmt_force_laws():
    hz = load_scene("macro-hertz")
    d = np.linspace(10.0, 0.1, 100)
    assert np.max(np.abs(nl.probe_force(hz, d) / hz.law.force(d) - 1.0)) < 1e-8
    raw = nl.probe_force(hz, d, nl.native_mapping(hz, raw_modulus=True))
    np.testing.assert_allclose(raw / hz.law.force(d), 4.0 / 3.0, rtol=1e-8)
    dmt = load_scene("collision-pair", [("contact.law", "dmt")])
    d = np.linspace(3.0, -0.2, 60)
    expect = np.where(d > 0, dmt.law.force(d), 0.0)
    assert np.max(np.abs(nl.probe_force(dmt, d) - expect)) < 1e-10


def test_jkr_bounce_matches_force_rule():
    """v0 = 3 (above both escape speeds): same events; contact duration error halves with dt
    (first order); rebound speed within the one-step quantization bound; the displacement
    rule's rebound speed is 0.57 away."""
    sc = jkr_pair(3.0)
    ref = run(sc, "reference").trajectory
    a, b = (nl.compare_pair(sc, dt, ref) for dt in (1e-3, 5e-4))
    for r in (a, b):
        assert r["same_outcome"] and r["lammps"]["separated"]
        bound = nl.quantization_bound(sc.law, 3.0, r["lammps"]["rebound_speed"], r["dt"])
        assert r["rebound_speed_error"] < bound
    assert 1.6 < a["contact_duration_error"] / b["contact_duration_error"] < 2.5
    assert b["contact_duration_error"] < 2e-4
    disp = run(jkr_pair(3.0, "displacement"), "reference").trajectory
    v_disp = disp.v[-1, 1] - disp.v[-1, 0]
    assert abs(b["lammps"]["rebound_speed"] - v_disp) > 0.5
    assert b["lammps"]["rebound_speed"] == pytest.approx(
        np.sqrt(9.0 - 4.0 * sc.law.loop_energy), abs=nl.quantization_bound(
            sc.law, 3.0, 2.5, 5e-4))


def test_capture_threshold_follows_force_rule():
    """v0 = 2 lies between the escape speeds of the force rule (1.587) and the displacement
    rule (2.258): LAMMPS and the force rule let the pair go, the displacement rule keeps it."""
    law_f, law_d = jkr_pair(2.0).law, jkr_pair(2.0, "displacement").law
    assert nl.escape_speed(law_f) < 2.0 < nl.escape_speed(law_d)
    nat = nl.run_native(jkr_pair(2.0), 1e-3)
    assert list(nat.ev_kind) == [1, 0]
    for snap, separates in (("force", True), ("displacement", False)):
        ref = run(jkr_pair(2.0, snap), "reference").trajectory
        assert (0 in list(ref.ev_kind[ref.ev_contact > 0])) is separates


def test_jkr_capture_converges_first_order():
    """v0 = 1.2 (below both escape speeds): the pair sticks and oscillates in the well in
    both codes; the trajectory error halves with dt (closing is quantized to the step)."""
    sc = jkr_pair(1.2)
    ref = run(sc, "reference").trajectory
    a, b = (nl.compare_pair(sc, dt, ref) for dt in (1e-3, 5e-4))
    for r in (a, b):
        assert r["same_outcome"] and not r["lammps"]["separated"]
    assert 1.7 < a["v_max_abs_error"] / b["v_max_abs_error"] < 2.3
    assert b["x_max_abs_error"] < 2e-4


def test_hertz_chain_matches_reference():
    """macro-hertz physics for 30 time units.  Without damping velocity Verlet is second order
    (error / 4 per halving); with the scene's damping it is first order (the dashpot switches
    at step-quantized events and LAMMPS evaluates it with v(t + dt/2)).  The naive mapping
    (LAMMPS given E = 338 GPa) is off by order 1."""
    sc = load_scene("macro-hertz", [("run.duration", 30.0), ("contact.damping", 0.0),
                                    ("run.tolerance", 1e-11)])
    ref = run(sc, "reference").trajectory
    e = [nl.compare_chain(sc, dt, 30.0, ref)["x_max_abs_error"] for dt in (0.005, 0.0025)]
    assert 3.3 < e[0] / e[1] < 4.7 and e[1] < 5e-4
    damped = load_scene("macro-hertz", [("run.duration", 30.0), ("run.tolerance", 1e-11)])
    ref = run(damped, "reference").trajectory
    e = [nl.compare_chain(damped, dt, 30.0, ref)["x_max_abs_error"]
         for dt in (0.0025, 0.00125)]
    assert 1.6 < e[0] / e[1] < 2.6 and e[1] < 1.5e-3
    naive = nl.compare_chain(damped, 0.0025, 30.0, ref,
                             nl.native_mapping(damped, raw_modulus=True))
    assert naive["x_max_abs_error"] > 1.0


def test_jkr_chain_starts_closed():
    """A chain whose contacts start closed at delta = 0 (LAMMPS's touch history primed):
    jkr-chain with the force rule agrees over 10 time units."""
    sc = load_scene("jkr-chain", [("run.duration", 10.0), ("contact.snap_off", "force")])
    ref = run(sc, "reference").trajectory
    assert nl.compare_chain(sc, 0.00125, 10.0, ref)["x_max_abs_error"] < 2e-3
