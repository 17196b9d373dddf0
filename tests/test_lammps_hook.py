"""The compiled Python hook of the LAMMPS backend, per MPI rank, against the native contact.

The hook's kernel (mdgran/backends/lammps/hook.py) performs fix mdgran/chain's operations in its
order, so in the step-quantized mode the two are bitwise equal: one rank and two, with atoms
(and the contact states they carry) migrating between ranks and contacts switching at the
boundary between ranks.  Its law functions are ContactLaw's and ContactTable's, bit for bit.
"""
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mdgran.backends.lammps import hook as kernel
from mdgran.model.contact import ContactLaw, ContactTable, fc_from_lambda
from mdgran.model.scene import load_scene
from mdgran.simulation import run

pytestmark = pytest.mark.lammps

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import lammps_ranks_worker as worker  # noqa: E402

MPIEXEC = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))


class _Model:  # what lammps_hook.chain_constants reads of a chain model
    gap = damping = k1 = k3 = 0.0
    walls, n = True, 10


@pytest.mark.parametrize("law", [
    ContactLaw("schwarz", fc_from_lambda(0.64), "displacement"),
    ContactLaw("schwarz", -1.5, "force"),  # JKR, force rule
    ContactLaw("schwarz", -2.0, "displacement"),  # DMT: t_min = 0
    ContactLaw("hertz", 0.0, "displacement"),
])
def test_kernel_law_is_the_contact_module_bit_for_bit(law):
    """Force from the table, exact force and energy at 3000 compressions from below snap-off
    to the table's end: the kernel's scalar functions with its records of the law give
    ContactLaw's and ContactTable's values exactly, and the spline the value of numpy's
    arithmetic written out."""
    table = ContactTable(law)
    chain = kernel.chain_constants(_Model(), law, table, 0.01)
    hertz = law.kind == "hertz"
    d = np.concatenate([np.linspace(law.delta_off - 0.5, 2.0, 2000),
                        np.geomspace(2.0, table.delta_max, 1000)])
    spline = np.array([kernel.spline_force(chain.table, x) for x in d])
    w = np.sqrt(np.maximum(d - table.base, 0.0))  # the spline in numpy, written out here
    s = np.minimum(w * table._scale, table.n - 1 - 1e-9)
    i = s.astype(np.int64)
    x, c = (s - i) * table._h, table.f_coef
    assert np.array_equal(spline, ((c[i, 0] * x + c[i, 1]) * x + c[i, 2]) * x + c[i, 3])
    exact = np.array([kernel.exact_force(hertz, chain.law, x) for x in d])
    energy = np.array([kernel.law_energy(hertz, chain.law, x) for x in d])
    assert np.array_equal(spline, table.force(d))
    assert np.array_equal(exact, law.force(d))
    assert np.array_equal(energy, law.energy(d))


def same_bits(a, b):
    """Two runs: identical positions, velocities, events and ledger, bit for bit."""
    ta, tb = a.trajectory, b.trajectory
    assert np.array_equal(ta.x, tb.x) and np.array_equal(ta.v, tb.v)
    assert list(zip(ta.ev_contact, ta.ev_kind)) == list(zip(tb.ev_contact, tb.ev_kind))
    assert np.array_equal(ta.ev_time, tb.ev_time)
    for k in ta.ledger:
        assert np.array_equal(ta.ledger[k], tb.ledger[k]), k


@pytest.mark.parametrize("name, overrides, options", [
    ("micro-star", [], {}),  # Schwarz lambda 0.64, walls, damping, table
    ("collision-pair", [], {"contact_eval": "exact"}),  # free pair across a gap, Newton law
    ("hard/jkr-force", [("substrate.k3", 0.05)], {}),  # force rule, cubic substrate
])
def test_hook_is_native_bitwise_on_one_rank(plugin, name, overrides, options):
    sc = load_scene(name, [("run.duration", 10.0), *overrides])
    hook = run(sc, "lammps", **options)
    native = run(sc, "lammps", contact="native", events="quantized", **options)
    assert len(hook.trajectory.ev_kind) > 0
    same_bits(hook, native)


def test_two_ranks_migration_and_boundary_events(plugin, tmp_path):
    """mpiexec -n 2: the struck middle bead sits on the boundary between the ranks' slabs and
    moves to the other rank (so do the 4, then 9 atoms that two moves of the boundary send
    over, each with the states of its contacts); contacts at the boundary snap off.  Hook and
    native on 2 ranks are the 1-rank runs bit for bit (positions, velocities, states, events,
    D_hysteresis); D_viscous is summed per rank (round-off, 1.4e-13 measured; hook and native
    on 2 ranks: bitwise).  Each rank holds
    a few ghosts, not the chain; LAMMPS's energy (fix external's, summed over the ranks) is
    the ledger's contact energy."""
    out = tmp_path / "two.npz"
    res = subprocess.run([MPIEXEC, "-n", "2", sys.executable, str(HERE / "lammps_ranks_worker.py"),
                          str(out)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    two = np.load(out)
    one = worker.collect("hook", balance=False)
    assert len(one["events"]) >= 5
    for contact in ("hook", "native"):
        def got(key):
            return two[f"{contact}_{key}"]

        for key in ("x", "v", "closed", "events", "d_hyst"):
            assert np.array_equal(got(key), one[key]), (contact, key)
        np.testing.assert_allclose(got("d_visc"), one["d_visc"], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(got("pe"), one["pe"], rtol=1e-12, atol=1e-12)
        owner = got("owner")
        assert owner[0, 12] == 1 and owner[1, 12] == 0  # the struck bead changed rank by itself
        moved = [np.flatnonzero(owner[k + 1] != owner[k]) for k in worker.BALANCE]
        assert [len(m) for m in moved] == [5, 9]  # the two moves of the boundary
        assert got("unsorted").any()  # a rank's atoms out of tag order: contacts found by tag
        assert 0 < got("nghost").max() <= 6
        # events on a contact whose beads were on different ranks at the end of the frame
        frame = np.searchsorted(np.arange(len(owner)) * 0.1, got("events")[:, 0])
        left = got("events")[:, 1].astype(int)  # contact k joins tags k and k + 1 (walls)
        assert np.any(owner[frame, left] != owner[frame, left + 1])
    assert np.array_equal(two["hook_d_visc"], two["native_d_visc"])  # same sums, same order
    # LAMMPS's pe (per atom in lj units) is the contact energy of the closed contacts
    law = load_scene("micro-star").law
    x = np.pad(one["x"], ((0, 0), (1, 1)))  # the walls
    delta = x[:, :-1] - x[:, 1:]
    ledger = np.where(one["closed"], law.energy(delta), 0.0).sum(axis=1)
    np.testing.assert_allclose(one["pe"] * x.shape[1], ledger, rtol=1e-10, atol=1e-10)


def test_an_error_on_one_rank_stops_both(tmp_path):
    """A compression beyond the table near bead 1 (one rank's slab): both ranks stop after the
    chunk with the same one-line error (exit 1), and rank 0 writes the frames so far."""
    out = tmp_path / "x.h5"
    res = subprocess.run([MPIEXEC, "-n", "2", sys.executable, "-m", "mdgran", "run", "micro-star",
                          "--backend", "lammps", "--quiet", "--checkpoint", "0", "--set",
                          "impulse.velocity=400", "--set", "run.duration=20", "--out", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 1, res.stdout[-2000:] + res.stderr[-2000:]
    lines = [ln for ln in res.stderr.splitlines() if "beyond the contact table" in ln]
    assert len(lines) == 2 and lines[0] == lines[1]  # once per rank, the same words
    import h5py

    with h5py.File(out) as f:
        assert f["parameters"].attrs["status"].startswith("failed")
