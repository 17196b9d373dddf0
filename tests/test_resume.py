"""Resuming from a checkpoint: a run interrupted (Ctrl-C, SIGKILL) and resumed writes the file
of a run straight through, bit for bit, on the reference and fast backends, from the Python API
and the command line; an interrupt before the first frame leaves nothing to resume from.

Resumes that need a file's own fixtures stay with them: contact output
(test_contact_output.py), decimated output (test_output_decimation.py), driven runs
(test_drive.py), long chains at rest (test_rest_blocks.py), signals and damaged checkpoints
(test_faults.py), the reference loop's state (test_reference_steps.py), sweeps (test_sweep.py,
test_sweep_faults.py).
"""
import json
import os
import signal
import subprocess
import sys
import time

import h5py
import pytest

from conftest import h5_datasets
from mdgran.cli import main
from mdgran.model.scene import load_scene
from mdgran.simulation import run


def test_resume_without_new_checkpoints_uses_the_partial_file(tmp_path, interrupt_at):
    """``--resume --checkpoint 0`` goes on from OUT.partial (it ran the whole run again in a
    temporary of its own and left OUT.partial behind, so that the next run on that name was
    refused as unfinished): the file is the uninterrupted run's, bit for bit, and the partial
    file is gone."""
    sc = load_scene("micro-star", [("run.duration", 40.0)])
    whole = tmp_path / "whole.h5"
    run(sc, "fast", out=whole)
    out = tmp_path / "r.h5"
    with pytest.raises(KeyboardInterrupt):
        run(sc, "fast", out=out, checkpoint_every=0.0, reporters=[interrupt_at(20.05)])
    partial = tmp_path / "r.h5.partial"
    assert partial.exists() and not out.exists()
    assert main(["run", "micro-star", "--backend", "fast", "--out", str(out), "--set",
                 "run.duration=40.0", "--resume", "--checkpoint", "0", "--quiet"]) == 0
    assert out.exists() and not partial.exists()
    a, b = h5_datasets(whole), h5_datasets(out)
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].tobytes() == b[k].tobytes(), k


def test_deterministic_and_checkpoint_resume_is_identical(tmp_path, interrupt_at):
    """Fast backend: two runs of a scene write the same file, and so does a run interrupted at
    t = 20 and resumed from its checkpoint."""
    sc = load_scene("micro-star", [("run.duration", 40.0)])
    paths = [tmp_path / "a.h5", tmp_path / "b.h5"]
    for p in paths:
        run(sc, "fast", out=p)
    da, db = h5_datasets(paths[0]), h5_datasets(paths[1])
    assert da.keys() == db.keys() and "events/time" in da and len(da["events/time"]) > 5
    for k in da:
        assert da[k].tobytes() == db[k].tobytes(), k
    parts = tmp_path / "parts.h5"
    with pytest.raises(KeyboardInterrupt):
        run(sc, "fast", out=parts, checkpoint_every=0.0, reporters=[interrupt_at(20.05)])
    assert not parts.exists() and (tmp_path / "parts.h5.partial").exists()
    res = run(sc, "fast", out=parts, checkpoint_every=0.0, resume=True)
    assert res.trajectory.time[0] > 20  # it did resume, not restart
    dp = h5_datasets(parts)
    assert dp.keys() == da.keys()
    for k in da:
        assert da[k].tobytes() == dp[k].tobytes(), k


def test_checkpoint_restart_is_identical(tmp_path, interrupt_at):
    """Reference backend, Python API: interrupted at t = 31 after a checkpoint at every frame,
    resumed from it (not restarted), the file equals the uninterrupted run's."""
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
    da, db = h5_datasets(whole), h5_datasets(parts)
    assert da.keys() == db.keys()
    for k in da:
        assert da[k].tobytes() == db[k].tobytes(), k


def test_sigkill_then_resume_matches_uninterrupted_run(tmp_path):
    """Command line: a run killed with SIGKILL past a checkpoint resumes (--resume) to the file
    of a run straight through."""
    args = ["run", "micro-star", "--quiet", "--set", "run.duration=150"]
    out = tmp_path / "k.h5"
    proc = subprocess.Popen([sys.executable, "-m", "mdgran", *args, "--out", str(out),
                             "--checkpoint", "0.2"])
    time.sleep(0.5)
    deadline = time.time() + 60
    while proc.poll() is None and time.time() < deadline:
        if (tmp_path / "k.h5.partial").exists():
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
    with h5py.File(tmp_path / "k.h5.partial", "r") as f:  # resume has something to resume
        assert json.loads(f["checkpoint"].attrs["meta"])["scalars"]["i_out"] > 0
    assert main([*args, "--out", str(out), "--resume", "--checkpoint", "0.2"]) == 0
    whole = tmp_path / "whole.h5"
    assert main([*args, "--out", str(whole), "--checkpoint", "0"]) == 0
    da, db = h5_datasets(whole), h5_datasets(out)
    for k in da:
        assert da[k].tobytes() == db[k].tobytes(), k


@pytest.mark.parametrize("backend", ["reference", "fast"])
def test_interrupt_before_the_first_frame_with_checkpoints(tmp_path, monkeypatch, backend):
    """Ctrl-C before the first frame (a first compile takes 15-25 s) with checkpoints on: the
    interrupt propagates as itself (it was a TypeError of the checkpoint, a traceback), and
    nothing is left to resume from: no output, no NAME.partial."""
    from mdgran.model.chain import ChainModel

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(ChainModel, "initial_state", stop)
    out = tmp_path / "r.h5"
    with pytest.raises(KeyboardInterrupt):
        run(load_scene("micro-star"), backend, out=out, checkpoint_every=0.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == []
