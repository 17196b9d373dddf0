"""Per-contact output: ``output.contacts`` adds /observables/contacts/{compression,
force, closed} as H5MD time series, each checked here against an independent computation from
the stored displacements, velocities and events; a run resumed from a checkpoint writes them
bitwise as an uninterrupted run does; the file records its MPI ranks; a resumed CLI run's
summary counts every event of the file.
"""
import shutil

import h5py
import numpy as np
import pytest

from conftest import InterruptAt

from mdgran.model.chain import model_from_scene
from mdgran.output.reporters import H5MDWriter
from mdgran.model.scene import load_scene
from mdgran.simulation import run
from mdgran.output.run_record import dataset_paths, read_h5

T_END, T_STOP = 40.0, 30.0  # micro-star: 14 events by t = 40 (snap-offs and a re-closure)
SERIES = ("compression", "force", "closed")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """micro-star to t = 40 with contacts on: uninterrupted, and interrupted at t = 30 with a
    checkpoint at every frame (a copy of its OUT.partial kept for the CLI test)."""
    d = tmp_path_factory.mktemp("contacts")
    sc = load_scene("micro-star", [("run.duration", T_END), ("output.contacts", True)])
    whole = d / "whole.h5"
    res = run(sc, "reference", out=whole)
    with pytest.raises(KeyboardInterrupt):
        run(sc, "reference", out=d / "r.h5", checkpoint_every=0.0, reporters=[InterruptAt(T_STOP)])
    (d / "cli").mkdir()
    shutil.copy(d / "r.h5.partial", d / "cli" / "r.h5.partial")
    return {"scene": sc, "whole": whole, "result": res, "dir": d}


def _replay(tr, n_contacts):
    """Contact states at every frame, replayed from the stored events alone: all closed at
    t = 0 (the paper's start, no initial gap), each event switching its contact, an event
    belonging to the first frame at or after it."""
    numbers = tr.contact_numbers
    state = np.ones(n_contacts, dtype=bool)
    out = np.empty((tr.frames, n_contacts), dtype=bool)
    k = 0
    for i, t in enumerate(tr.time):
        while k < len(tr.ev_time) and tr.ev_time[k] <= t:
            j = int(np.flatnonzero(numbers == tr.ev_contact[k])[0])
            assert state[j] != bool(tr.ev_kind[k])  # an event changes the state
            state[j] = bool(tr.ev_kind[k])
            k += 1
        out[i] = state
    assert k == len(tr.ev_time)
    return out


def test_contact_series_match_independent_values(runs):
    sc, path = runs["scene"], runs["whole"]
    model = model_from_scene(sc)
    nc = model.n_contacts
    tr = read_h5(path)
    with h5py.File(path, "r") as f:
        g = f["observables/contacts"]
        np.testing.assert_array_equal(g.attrs["contact"], np.arange(1, sc.data["chain"]["n"] + 2))
        assert "contact i joins bead i-1 and bead i" in g.attrs["numbering"]
        data = {}
        for name in SERIES:
            s = g[name]
            np.testing.assert_array_equal(s["step"][()], f["observables/total_energy/step"][()])
            np.testing.assert_array_equal(s["time"][()], tr.time)
            assert s["value"].shape == (tr.frames, nc)
            data[name] = s["value"][()]
        assert g["compression/value"].attrs["unit"] == "p"
        assert g["force/value"].attrs["unit"] == "eta"
        assert g["closed/value"].dtype == np.int8
        assert g["force"].attrs["includes_damping"] == 1
    assert len(tr.ev_time) >= 10 and set(tr.ev_kind) == {0, 1}

    # compression: the model's, from the stored displacements
    comp = np.array([model.compressions(x) for x in tr.x])
    np.testing.assert_array_equal(data["compression"], comp)
    # closed: replayed from the stored events (an independent record)
    closed = _replay(tr, nc)
    assert closed.sum() < closed.size  # some contacts open in the run
    np.testing.assert_array_equal(data["closed"].astype(bool), closed)
    np.testing.assert_array_equal(tr.closed, closed)  # read_h5 reads them back
    np.testing.assert_array_equal(runs["result"].trajectory.closed, closed)  # MemoryReporter
    # force: the contact law at that compression plus the unilateral damping, where closed
    walls = np.zeros((tr.frames, 1))
    vv = np.hstack([walls, tr.v, walls])
    ddelta_dt = vv[:, :-1] - vv[:, 1:]
    law = model.law.force(comp) + float(sc.data["contact"]["damping"]) * ddelta_dt
    np.testing.assert_allclose(data["force"], np.where(closed, law, 0.0), rtol=1e-13, atol=1e-13)
    assert np.all(data["force"][~closed] == 0.0)
    # ... which is the force the integrator uses: F_i - F_(i+1) - k1 x_i = the model's x''
    f = data["force"]
    acc = f[:, :-1] - f[:, 1:] - model.k1 * tr.x
    want = np.array([model.acceleration(x, v, c) for x, v, c in zip(tr.x, tr.v, closed)])
    np.testing.assert_allclose(acc, want, rtol=1e-12, atol=1e-12)


def _datasets(path):
    with h5py.File(path, "r") as f:
        out = {name: f[name][()] for name in dataset_paths(f)
               if not name.startswith("checkpoint")}
        attrs = {k: v for k, v in f["parameters"].attrs.items() if k != "backend_stats"}
    return out, attrs


def test_resume_with_contacts_is_bitwise(runs):
    d = runs["dir"]
    part = d / "r.h5.partial"
    with h5py.File(part, "r") as f:  # the checkpoint covers the contact series
        import json

        meta = json.loads(f["checkpoint"].attrs["meta"])
        assert 0 < meta["frames"] < int(T_END / 0.1) + 1
        assert {f"observables/contacts/{n}/{k}" for n in SERIES
                for k in ("step", "time", "value")} <= set(meta["data_sha256"])
    run(runs["scene"], "reference", out=d / "r.h5", checkpoint_every=0.0, resume=True,
        keep=False)
    a, a_attrs = _datasets(d / "r.h5")
    b, b_attrs = _datasets(runs["whole"])
    assert sorted(a) == sorted(b) and any(k.startswith("observables/contacts/") for k in a)
    for key in b:
        assert a[key].dtype == b[key].dtype and a[key].tobytes() == b[key].tobytes(), key
    assert a_attrs["status"] == "complete" and a_attrs["mpi_ranks"] == b_attrs["mpi_ranks"] == 1


def test_a_damaged_contact_series_is_refused(runs, tmp_path):
    """The checksums cover the new series: one changed state makes the resume refuse."""
    from mdgran.model.scene import SceneError

    p = tmp_path / "r.h5.partial"
    shutil.copy(runs["dir"] / "cli" / "r.h5.partial", p)
    with h5py.File(p, "r+") as f:
        f["observables/contacts/closed/value"][5, 3] ^= 1
    with pytest.raises(SceneError, match="observables/contacts/closed"):
        run(runs["scene"], "reference", out=tmp_path / "r.h5", checkpoint_every=0.0,
            resume=True, keep=False)


def test_default_file_has_the_states_only_and_one_rank(tmp_path, monkeypatch):
    """Without output.contacts the file holds the contact states (1 byte per contact and frame)
    and neither compression nor force; read back, they are the run's own."""
    for var in ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE"):
        monkeypatch.delenv(var, raising=False)
    out = tmp_path / "d.h5"
    res = run(load_scene("micro-star", [("run.duration", 2.0)]), "reference", out=out)
    with h5py.File(out, "r") as f:
        assert sorted(f["observables/contacts"]) == ["closed"]
        assert sorted(f["observables"]) == sorted(
            ["kinetic_energy", "contact_energy", "substrate_energy", "dissipated_viscous",
             "dissipated_hysteresis", "total_energy", "contacts"])
        assert f["parameters"].attrs["mpi_ranks"] == 1
    assert res.trajectory.closed.shape == (21, 21)
    np.testing.assert_array_equal(read_h5(out).closed, res.trajectory.closed)


def test_mpi_ranks_rule(monkeypatch):
    """The backend's communicator if it has one, else 1 for a backend that takes none, else
    the launcher's world size."""
    class Comm:
        def Get_size(self):
            return 3

    class Mpi:
        accepted_options = ("comm",)
        comm = None

    class Serial:
        accepted_options = ("tolerance",)

    for var in ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE"):
        monkeypatch.delenv(var, raising=False)
    assert H5MDWriter.mpi_ranks_of(None) == 1
    monkeypatch.setenv("PMI_SIZE", "4")
    assert H5MDWriter.mpi_ranks_of(None) == 4
    assert H5MDWriter.mpi_ranks_of(Mpi()) == 4
    assert H5MDWriter.mpi_ranks_of(Serial()) == 1
    with_comm = Mpi()
    with_comm.comm = Comm()
    assert H5MDWriter.mpi_ranks_of(with_comm) == 3
    monkeypatch.delenv("PMI_SIZE")
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    assert H5MDWriter.mpi_ranks_of(Mpi()) == 2


def test_resumed_cli_run_counts_every_event(runs, capsys):
    from mdgran.cli import main

    d = runs["dir"] / "cli"
    out = d / "r.h5"
    assert main(["run", "micro-star", "--set", f"run.duration={T_END}", "--set",
                 "output.contacts=true", "--out", str(out), "--resume"]) == 0
    line = [ln for ln in capsys.readouterr().out.splitlines() if " events, " in ln]
    total = len(read_h5(runs["whole"]).ev_time)
    before = int(np.sum(read_h5(runs["whole"]).ev_time < T_STOP - 0.1))
    assert 0 < before < total  # the resumed part alone has fewer
    assert len(line) == 1 and f", {total} events, " in line[0], line
    assert len(read_h5(out).ev_time) == total


@pytest.mark.lammps
def test_mpi_ranks_of_a_two_rank_lammps_run(tmp_path):
    """mpiexec -n 2 with the LAMMPS backend: the chain is split over 2 ranks and the file
    says so (its LAMMPS instance's world size)."""
    import os
    import subprocess
    import sys

    mpiexec = shutil.which("mpiexec") or os.path.join(os.path.dirname(sys.executable),
                                                      "mpiexec")
    out = tmp_path / "two.h5"
    subprocess.run([mpiexec, "-n", "2", sys.executable, "-m", "mdgran", "run", "micro-star",
                    "--backend", "lammps", "--quiet", "--checkpoint", "0", "--set",
                    "run.duration=1", "--set", "output.contacts=true", "--out", str(out)],
                   check=True, timeout=300)
    with h5py.File(out, "r") as f:
        assert f["parameters"].attrs["mpi_ranks"] == 2
        assert f["parameters"].attrs["mpi_world_size"] == 2
        assert f["observables/contacts/closed/value"].shape == (11, 21)


def _series_groups(f) -> list:
    """Every time series group (one with a ``value``) by every path that reaches it."""
    return sorted(p[:-len("/value")] for p in dataset_paths(f) if p.endswith("/value"))


def test_series_share_one_clock(runs):
    """Every time series sampled at the frames holds the same step and time datasets (hard
    links: one HDF5 object), the frame numbers and their times; position keeps its own time
    (ps with scales)."""
    with h5py.File(runs["whole"], "r") as f:
        groups = _series_groups(f)
        assert len(groups) >= 10 and "particles/chain/position" in groups
        shared = [g for g in groups if not g.endswith("/position")]
        clock = f[f"{shared[0]}/step"].id, f[f"{shared[0]}/time"].id
        for g in shared:
            assert (f[f"{g}/step"].id, f[f"{g}/time"].id) == clock, g
            assert f[f"{g}/value"].shape[0] == f[f"{g}/step"].shape[0]
        step = f[f"{shared[0]}/step"][()]
        np.testing.assert_array_equal(step, np.arange(int(T_END / 0.1) + 1))
        np.testing.assert_allclose(f[f"{shared[0]}/time"][()], 0.1 * step, rtol=1e-12)
        assert f["particles/chain/position/step"].id != clock[0]


def test_resume_of_a_file_with_a_clock_per_series(runs, tmp_path, monkeypatch):
    """A checkpoint written with a step and time per series (mdgran before the shared clock)
    resumes into the same datasets as an uninterrupted run."""
    import mdgran.output.h5md_layout as layout

    sc = runs["scene"]
    own = layout.make_series
    with monkeypatch.context() as m:
        m.setattr(layout, "make_series", lambda *a, **k: own(*a, **{**k, "clock": None}))
        with pytest.raises(KeyboardInterrupt):
            run(sc, "reference", out=tmp_path / "r.h5", checkpoint_every=0.0,
                reporters=[InterruptAt(T_STOP)])
    with h5py.File(tmp_path / "r.h5.partial", "r") as f:
        assert f["observables/total_energy/step"].id != f["particles/chain/velocity/step"].id
    run(sc, "reference", out=tmp_path / "r.h5", checkpoint_every=0.0, resume=True, keep=False)
    a, _ = _datasets(tmp_path / "r.h5")
    b, _ = _datasets(runs["whole"])
    assert sorted(a) == sorted(b)
    for key in b:
        assert a[key].tobytes() == b[key].tobytes(), key
