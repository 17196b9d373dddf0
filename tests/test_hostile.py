"""Hostile input, unattended: every value the backends cannot handle is refused up
front (exit 2, one line naming the key, no traceback, no file); a run that stops progressing
fails (exit 1, one line, the frames so far written) instead of hanging.

Most cases run real ``mdgran`` subprocesses (the CLI behaviour is the point); the watchdog runs
in-process with the scene limits lifted, since no allowed scene trips it."""
import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from mdgran.cli import main
from mdgran.model.scene import SceneError, load_scene

MDGRAN = [sys.executable, "-m", "mdgran"]


def mdgran(args, cwd, timeout=60):
    """Run ``mdgran ARGS`` in ``cwd``; returns (exit status, stdout, stderr)."""
    p = subprocess.run(MDGRAN + [str(a) for a in args], cwd=cwd, capture_output=True,
                       timeout=timeout)
    return p.returncode, p.stdout.decode(errors="replace"), p.stderr.decode(errors="replace")


def assert_refused(status, err, key):
    assert status == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert key in err, err


# (extra args of `mdgran run micro-star --out x.h5`, key the error must name)
REFUSED_VALUES = [
    (["--set", "substrate.k1=1e300"], "substrate.k1"),  # hung: step collapse to 1e-150
    (["--set", "substrate.k3=1e12"], "substrate.k3"),  # hung: 1e4 hours of steps
    (["--set", "contact.damping=1e6"], "contact.damping"),  # hung: 2.5e8 steps
    (["--set", "impulse.velocity=1e6"], "impulse.velocity"),  # hung: event location stalled
    (["--set", "impulse.velocity=1e200"], "impulse.velocity"),  # OverflowError
    (["--set", "impulse.velocity_si=1e308"], "impulse.velocity_si"),  # converted to inf
    (["--set", "substrate.k1_si=1e308"], "substrate.k1_si"),
    (["--set", "contact.damping_si=1e308"], "contact.damping_si"),
    (["--set", "material.diameter=1e-300"], "material.diameter"),  # ZeroDivisionError
    (["--set", "material.diameter=1e300"], "material.diameter"),  # OverflowError
    (["--set", "chain.n=1000000000"], "chain.n"),  # MemoryError after the run started
    (["--set", "chain.n=1000000000000"], "chain.n"),
    # 1e5 beads x 9.9e7 frames: at least 6.4e3 GiB on disk (one block of 4096 beads a frame
    # of each long series), more than any disk holds (8e7 frames of micro-star need 55 GB:
    # refused only where less is free)
    (["--backend", "fast", "--set", "chain.n=100000", "--set", "run.duration=9.9e5", "--set",
      "run.output_interval=0.01", "--set", "run.dt=0.01"], "run.output_interval"),
    (["--set", "contact.law=jkr", "--set", "contact.lambda=1.5"], "contact.lambda"),
    (["--set", "chain.n=" + "[" * 2000 + "]" * 2000], "chain.n"),  # RecursionError
]


@pytest.mark.parametrize("args,key", REFUSED_VALUES, ids=[k for _, k in REFUSED_VALUES])
def test_values_the_backends_cannot_handle_are_refused(args, key, tmp_path):
    status, _, err = mdgran(["run", "micro-star", "--out", "x.h5", "--quiet", *args],
                            tmp_path)
    assert_refused(status, err, key)
    assert not list(tmp_path.iterdir())


def test_refused_out_paths(tmp_path):
    """--out that could not be written at the end of the run is refused before it starts."""
    (tmp_path / "d").mkdir()
    (tmp_path / "f").write_text("x")
    (tmp_path / "scene.toml").write_text("[chain]\nn = 2\n[run]\nduration = 1.0\n")
    cases = [("d", "is a folder"), ("f/x.h5", "is a file"), ("", "must name"),
             (".", "is a folder"), ("new/", "is a folder"), ("a" * 247 + ".h5", "bytes"),
             ("scene.toml", "is the scene file")]
    before = sorted(os.listdir(tmp_path))
    for out, why in cases:
        scene = "scene.toml" if out == "scene.toml" else "micro-star"
        status, _, err = mdgran(["run", scene, "--out", out, "--quiet"], tmp_path)
        assert_refused(status, err, "--out")
        assert why in err, (out, err)
    assert sorted(os.listdir(tmp_path)) == before  # nothing made, nothing overwritten
    assert (tmp_path / "scene.toml").read_text().startswith("[chain]")


def test_refused_scene_and_sweep_files(tmp_path):
    (tmp_path / "deep.toml").write_text("[chain]\nn = " + "[" * 5000 + "]" * 5000 + "\n")
    (tmp_path / "three.toml").write_text("sweep = 3\n")
    (tmp_path / "bin.toml").write_bytes(bytes(range(256)) * 4)
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage" / "sweep.json").write_text("{garbage")
    (tmp_path / "afile").write_text("x")
    bad_name = os.fsdecode(b"s\xff.toml")
    (tmp_path / bad_name).write_text("[chain]\nn = 2\n")
    cases = [(["run", "deep.toml", "--out", "x.h5"], "SCENE"),
             (["run", bad_name, "--out", "x.h5"], "SCENE"),
             (["sweep", "three.toml", "--out", "sw"], "sweep"),
             (["sweep", "bin.toml", "--out", "sw"], "SWEEP"),
             (["sweep", "paper-robustness", "--small", "--out", "garbage"], "--out"),
             (["sweep", "paper-robustness", "--small", "--out", "afile"], "--out")]
    before = sorted(os.listdir(tmp_path))
    for args, key in cases:
        status, _, err = mdgran([*args, "--quiet"], tmp_path)
        assert_refused(status, err, key)
    assert sorted(os.listdir(tmp_path)) == before
    assert (tmp_path / "garbage" / "sweep.json").read_text() == "{garbage"


def test_info_json_is_json(tmp_path):
    """JSON has no Infinity: jkr-chain's contact_lambda (the JKR limit) prints as null."""
    status, out, err = mdgran(["info", "jkr-chain", "--json"], tmp_path)
    assert status == 0, err
    assert "Infinity" not in out and "NaN" not in out
    info = json.loads(out)
    assert info["contact_lambda"] is None and info["fc"] == -1.5


def test_law_override_drops_the_files_lambda():
    """`--set contact.law=jkr` on a scene file that gives lambda is the jkr scene; lambda given
    with a law that does not use it is refused, in a file or as an override."""
    sc = load_scene("collision-pair", [("contact.law", "jkr")])
    assert sc.law.fc == -1.5 and "lambda" not in sc.to_toml()
    assert load_scene("jkr-chain").with_overrides([("run.dt", 0.005)]).law.fc == -1.5
    for ov in ([("contact.law", "jkr"), ("contact.lambda", 1.5)],
               [("contact.lambda", 1.5), ("contact.law", "dmt")]):
        with pytest.raises(SceneError, match=r"^contact\.lambda: not used by law"):
            load_scene("collision-pair", ov)


def test_limits_are_inclusive_and_si_values_are_rechecked():
    for key, value in (("impulse.velocity", -5e3), ("substrate.k1", 1e6),
                       ("substrate.k3", 1e6), ("contact.damping", 1e3)):
        load_scene("micro-star", [(key, value)])
    with pytest.raises(SceneError, match=r"^substrate\.k3_si: 1e\+30 gives substrate\.k3: "
                       r"must be a number in \[0, 1e6\]"):
        load_scene("micro-star", [("substrate.k3_si", 1e30)])  # 1.5e7 eta/p^3


def test_watchdog_stops_a_collapsed_step(tmp_path, capsys, monkeypatch):
    """Past the limits (lifted here), the reference's step collapses to 1e-150: the watchdog
    stops the run within seconds, exit 1, one line naming the time, the step and the bead, and
    the file holds the frames so far with the failure as its status."""
    import mdgran.model.scene as scene_mod

    monkeypatch.setattr(scene_mod, "LIMITS", {})
    out = tmp_path / "x.h5"
    assert main(["run", "micro-star", "--out", str(out), "--quiet",
                 "--set", "substrate.k1=1e300"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "step size collapsed at t = " in err and "below the floor 1e-12 (1 + |t|)" in err
    assert "bead 1" in err
    with h5py.File(out) as f:
        assert f["parameters"].attrs["status"].startswith("failed: step size collapsed")
        assert f["particles/chain/displacement/time"][:].tolist() == [0.0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.h5"]


def test_watchdog_stops_a_stalled_event_location(monkeypatch):
    """An event location that creeps on by 1e-14 per step stops the run, naming the contact.

    Seen with v0 = 1e4 (over the limit) on AVX2 machines: positions of ~1e3 p cannot resolve
    the 1e-13 p event tolerance.  Whether that case stalls depends on the last bits of numpy's
    CPU dispatch (on AVX-512 it runs through), so the creep is injected: each approach to the
    pending contact's point falls short and moves the target on by 1e-14 (1 + |t|), and no
    contact is found outside its state on the way (as when the position cannot resolve it)."""
    from mdgran.backends.base import IntegrationError
    from mdgran.backends.reference import ReferenceBackend
    from mdgran.simulation import run

    def creep(self, s, ks, g, gd, t_out):
        s.target = min(float(t_out), s.t + 1e-14 * (1.0 + abs(s.t)))
        return True

    monkeypatch.setattr(ReferenceBackend, "_short_of_point", creep)
    monkeypatch.setattr(ReferenceBackend, "_outside",
                        staticmethod(lambda g, gd: np.zeros(len(g), dtype=bool)))
    sc = load_scene("micro-star", [("run.duration", 5.0)])
    with pytest.raises(IntegrationError, match=r"locating the event of contact \d+"):
        run(sc, "reference", keep=False)


def test_fast_backend_reads_output_times_once(monkeypatch):
    from mdgran.backends.fast import FastBackend
    from mdgran.simulation import run

    calls = []
    real = FastBackend.output_times
    monkeypatch.setattr(FastBackend, "output_times",
                        lambda self: calls.append(1) or real(self))
    res = run(load_scene("collision-pair", [("run.duration", 2.0)]), "fast")
    assert len(res.trajectory.time) > 10 and len(calls) == 1
    assert np.all(np.isfinite(res.trajectory.x))
