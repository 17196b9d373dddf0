"""The MDAnalysis recipe of docs/output.md ("With MDAnalysis") works as written: an empty
Universe of chain.n atoms loads the H5MD file as its trajectory and sees every frame, with the
file's times and the beads' places, against the same file read with h5py and against the
displacements of ``mdgran.read`` converted to SI with the scene's length unit.  MDAnalysis is
in the ``docs`` extra; without it the tests skip.
"""
import h5py
import numpy as np
import pytest

import mdgran

mda = pytest.importorskip("MDAnalysis")


def open_as_in_docs(path):
    """docs/output.md's recipe, verbatim but for the loop: the Universe."""
    with h5py.File(path, "r") as f:
        n = f["particles/beads/position/value"].shape[1]  # = chain.n
        has_units = "unit" in f["particles/beads/position/value"].attrs
    u = mda.Universe.empty(n, trajectory=True)
    u.load_new(str(path), format="H5MD", convert_units=has_units)
    return u, has_units


def frames_of(u):
    """Per frame: time, the x coordinates of the atoms, and the kinetic energy of ts.data."""
    times, xs, kinetic = [], [], []
    for ts in u.trajectory:
        times.append(ts.time)
        xs.append(ts.positions[:, 0].astype(float))
        kinetic.append(ts.data["kinetic_energy"])
    return np.array(times), np.array(xs), np.array(kinetic)


def test_with_a_material_positions_in_angstrom(tmp_path):
    """micro-star (a [material]: nm and ps in the file): MDAnalysis converts to Angstrom."""
    path = tmp_path / "ms.h5"
    mdgran.run("micro-star", "reference", out=path, set={"run.duration": 10.0})
    u, has_units = open_as_in_docs(path)
    assert has_units
    with h5py.File(path, "r") as f:
        pos_nm = f["particles/beads/position/value"][()]
        time_ps = f["particles/beads/position/time"][()]
        kinetic = f["observables/kinetic_energy/value"][()]
    times, xs, ke = frames_of(u)
    assert u.atoms.n_atoms == 20 and len(xs) == len(pos_nm) == 101
    np.testing.assert_allclose(times, time_ps, rtol=1e-12)
    # MDAnalysis holds positions in float32: 6e-8 of ~5e4 A
    np.testing.assert_allclose(xs / 10.0, pos_nm[:, :, 0], rtol=2e-7, atol=0)
    np.testing.assert_array_equal(ke, kinetic)
    # the beads moved, and by what mdgran's own reader says (displacement x p, in nm)
    run = mdgran.read(path)
    moved_nm = run.x * run.scene.scales.p_m * 1e9
    assert np.max(np.abs(moved_nm)) > 1e-3
    np.testing.assert_allclose(xs / 10.0 - xs[0] / 10.0, moved_nm, rtol=0, atol=5e-3)


def test_without_units_positions_as_stored(tmp_path):
    """A scene without [material]: no units in the file, positions read as stored (p)."""
    path = tmp_path / "plain.h5"
    scene = {"chain": {"n": 6}, "impulse": {"velocity": 3.0}, "run": {"duration": 5.0}}
    mdgran.run(scene, "reference", out=path)
    u, has_units = open_as_in_docs(path)
    assert not has_units
    with h5py.File(path, "r") as f:
        pos = f["particles/beads/position/value"][()]
    times, xs, _ = frames_of(u)
    assert u.atoms.n_atoms == 6 and len(xs) == len(pos)
    np.testing.assert_allclose(xs, pos[:, :, 0], rtol=2e-7, atol=0)
    np.testing.assert_allclose(xs - xs[0], mdgran.read(path).x, rtol=0, atol=1e-4)
