"""Excitations beyond the ideal impulse: substrate damping and initial random
velocities, on the reference, fast and LAMMPS (hook and native) backends, against analytic
results."""
import math

import numpy as np
import pytest

from mdgran import run
from mdgran.model.chain import model_from_scene

from conftest import make_scene


@pytest.mark.parametrize("backend", ["reference", "fast",
                                     pytest.param("lammps", marks=pytest.mark.lammps),
                                     pytest.param("lammps:native", marks=pytest.mark.lammps)])
@pytest.mark.parametrize("density", [0.5, 2.5])  # both mixed: one kernel variant
def test_substrate_damping_is_a_damped_oscillator(backend, density):
    """Two beads far apart (every contact open), bead 1 struck: ``m x'' = -k1 x - c_s x'``,
    so ``x = v0 / w_d exp(-g t) sin(w_d t)`` with ``g = c_s / (2 m)``, ``w_d = sqrt(k1 / m -
    g^2)``; the damping's dissipation closes the ledger (in dissipated_viscous)."""
    k1, cs, v0 = 0.5, 0.2, 0.01
    sc = make_scene(chain={"n": 2, "boundary": "free", "initial_gap": 10.0},
                    substrate={"k1": k1, "damping": cs}, impulse={"velocity": v0},
                    beads={"density": [density, 1.0]},
                    run={"duration": 20.0, "output_interval": 0.5, "dt": 0.001,
                         "tolerance": 1e-11})
    res = run(sc, backend)
    tr = res.trajectory
    g = cs / (2 * density)
    wd = math.sqrt(k1 / density - g * g)
    x = v0 / wd * np.exp(-g * tr.time) * np.sin(wd * tr.time)
    tol = 1e-9 if backend == "reference" else 1e-7
    assert np.abs(tr.x[:, 0] - x).max() < tol * v0 * 10
    assert np.all(tr.x[:, 1] == 0.0)
    e_left = 0.5 * density * tr.v[-1, 0] ** 2 + 0.5 * k1 * tr.x[-1, 0] ** 2
    assert tr.ledger["dissipated_viscous"][-1] == pytest.approx(
        0.5 * density * v0**2 - e_left, rel=1e-6)
    assert res.status == "complete"


def test_thermal_velocities_have_the_temperature():
    """``v_i = sqrt(T / m_i) N_i``: the mean kinetic energy per bead is T / 2 within 4 standard
    deviations (``T / sqrt(2 n)``) of the chi-square; the same seed gives the same velocities,
    another seed others."""
    n, temp = 4000, 0.3
    masses = np.where(np.arange(n) % 2 == 0, 1.0, 0.25)
    sc = make_scene(chain={"n": n}, thermal={"temperature": temp, "seed": 7},
                    beads={"density": list(masses)})
    m = model_from_scene(sc)
    v = m.thermal_velocities()
    ke = 0.5 * masses * v * v
    assert abs(ke.mean() - temp / 2) < 4 * temp / math.sqrt(2 * n)
    for part in (ke[0::2], ke[1::2]):  # equipartition between the two masses
        assert abs(part.mean() - temp / 2) < 4 * temp / math.sqrt(n)
    assert np.array_equal(v, model_from_scene(sc).thermal_velocities())
    other = make_scene(chain={"n": n}, thermal={"temperature": temp, "seed": 8},
                       beads={"density": list(masses)})
    assert not np.array_equal(v, model_from_scene(other).thermal_velocities())


def test_thermal_start_is_the_same_on_both_backends():
    """micro-star at temperature 0.5 (seed 3): the same first frame on reference and fast, the
    impulse added on bead 1, E0 = the kinetic energy of those velocities."""
    sc = make_scene(chain={"n": 20}, thermal={"temperature": 0.5, "seed": 3},
                    impulse={"velocity": 2.0}, run={"duration": 1.0, "output_interval": 0.5})
    a = run(sc, "reference").trajectory
    b = run(sc, "fast").trajectory
    v = model_from_scene(sc).thermal_velocities()
    v[0] += 2.0
    assert np.array_equal(a.v[0], v) and np.array_equal(b.v[0], v)
    assert a.ledger["kinetic_energy"][0] == pytest.approx(0.5 * v @ v, rel=1e-14)
