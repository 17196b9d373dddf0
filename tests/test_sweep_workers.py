"""A sweep's workers are persistent (one process runs many cases, keeping what it loaded and
cached), and that changes no result; several workers share the cores between them."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mdgran.studies.sweep import run_case, run_sweep, worker_cores

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "reference"))
from check_bitwise import datasets, same  # noqa: E402


def _sweep_file(tmp_path, velocities, k1=(4.6,), duration=20.0, backend="fast"):
    path = tmp_path / "small.toml"
    path.write_text(f'[sweep]\nscene = "micro-star"\nbackend = "{backend}"\n\n[fixed]\n'
                    f'"run.duration" = {duration}\n\n[grid]\n'
                    f'"substrate.k1_si" = {list(k1)}\n"impulse.velocity" = {list(velocities)}\n')
    return path


def test_one_worker_runs_every_case_as_a_run_of_its_own(tmp_path):
    """Four cases (two substrates, two impulses) in one persistent worker, which loads the
    kernel and builds the contact table once: each case's file holds bitwise the datasets of
    the same case run alone by ``mdgran run`` in a fresh process, and its summary is the one
    run_case writes for that case alone in this process."""
    spec = _sweep_file(tmp_path, [2.0, 16.0], k1=(4.6, 21.5))
    res = run_sweep(str(spec), tmp_path / "sw", workers=1, progress=False)
    assert [r["status"] for r in res] == ["complete"] * 4
    for r in res:
        stem = f"{r['index']:04d}"
        alone = tmp_path / f"alone-{stem}.h5"
        sets = [f"--set={k}={v}" for k, v in [("run.duration", 20.0), *r["params"].items()]]
        subprocess.run([sys.executable, "-m", "mdgran", "run", "micro-star", "--backend", "fast",
                        "--out", str(alone), "--quiet", *sets], check=True)
        a, b = datasets(tmp_path / "sw" / "cases" / f"{stem}.h5"), datasets(alone)
        assert sorted(a) == sorted(b)
        assert all(same(a[k], b[k]) for k in a), [k for k in a if not same(a[k], b[k])]
    one = tmp_path / "one"
    (one / "cases").mkdir(parents=True)
    case = json.loads((tmp_path / "sw" / "sweep.json").read_text())["cases"][3]
    summary = run_case("micro-star", "fast", case, str(one))
    kept = json.loads((tmp_path / "sw" / "cases" / "0003.json").read_text())
    for key in ("wall_s",):  # a timing
        summary.pop(key), kept.pop(key)
    assert summary == kept


def test_worker_cores_share():
    cores = [0, 1, 2, 3]
    assert worker_cores(0, 1, cores) == cores
    assert [worker_cores(k, 2, cores) for k in range(2)] == [[0, 1], [2, 3]]
    assert [worker_cores(k, 3, cores) for k in range(3)] == [[0], [1], [2, 3]]
    assert [worker_cores(k, 6, cores) for k in range(6)] == [[0], [1], [2], [3], [0], [1]]
    assert worker_cores(1, 2, [5]) == [5] and worker_cores(0, 2, []) == []


def where_it_ran(scene_spec, backend, case, out_dir, *rest):
    """A sweep case (run_case's arguments) that records the process and cores it ran on."""
    from pathlib import Path

    import gc

    summary = {"index": case["index"], "params": case["params"], "status": "complete",
               "pid": os.getpid(), "cores": sorted(os.sched_getaffinity(0)),
               "frozen": gc.get_freeze_count()}
    (Path(out_dir) / "cases" / f"{case['index']:04d}.json").write_text(json.dumps(summary))
    return summary


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs two usable cores")
def test_two_workers_run_on_disjoint_shares_of_the_cores(tmp_path):
    spec = _sweep_file(tmp_path, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    res = run_sweep(str(spec), tmp_path / "sw", workers=2, progress=False,
                    case_fn=where_it_ran)
    cores = sorted(os.sched_getaffinity(0))
    by_pid = {}
    for r in res:
        by_pid.setdefault(r["pid"], set()).add(tuple(r["cores"]))
    assert 1 <= len(by_pid) <= 2 and all(len(c) == 1 for c in by_pid.values())
    shares = [list(c.pop()) for c in by_pid.values()]
    assert all(s in (worker_cores(0, 2, cores), worker_cores(1, 2, cores)) for s in shares)
    if len(shares) == 2:
        assert not set(shares[0]) & set(shares[1])
    one = run_sweep(str(spec), tmp_path / "one", workers=1, progress=False,
                    case_fn=where_it_ran)
    assert len({r["pid"] for r in one}) == 1  # one persistent worker ran every case
    assert all(r["cores"] == cores for r in one)  # ... on every core
    # ... and after its first case, what it holds is out of the collector's full passes
    assert one[0]["frozen"] == 0 and all(r["frozen"] > 1000 for r in one[1:])
    assert np.all([r["status"] == "complete" for r in res + one])
