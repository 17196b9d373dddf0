"""Sweeps: the small version of the paper's robustness study runs in parallel; a sweep killed
mid-way resumes without redoing finished cases."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mdgran.model.scene import SceneError
from mdgran.studies.sweep import load_sweep, run_sweep


def test_paper_robustness_spec():
    sw = load_sweep("paper-robustness")
    assert len(sw["cases"]) == 91
    k1 = sorted({c["params"]["substrate.k1_si"] for c in sw["cases"]})
    assert k1[0] == 4.6 and k1[-1] == 21.5 and len(k1) == 7
    assert len(load_sweep("paper-robustness", small=True)["cases"]) == 4


def test_small_sweep_runs_in_parallel(tmp_path):
    res = run_sweep("paper-robustness", tmp_path, workers=2, small=True, progress=False)
    assert len(res) == 4 and all(r["status"] == "complete" for r in res)
    assert all(r["ledger_error"] < 1e-8 for r in res)
    # more impulse, more snap-offs: the sweep's two ends behave as the spec says
    by = {(r["params"]["substrate.k1_si"], r["params"]["impulse.velocity"]): r for r in res}
    for k1 in (4.6, 21.5):
        assert by[(k1, 16.0)]["opens"] > 2 * by[(k1, 2.0)]["opens"]


def test_killed_sweep_resumes_without_redoing(tmp_path):
    out = tmp_path / "sw"
    proc = subprocess.Popen([sys.executable, "-m", "mdgran", "sweep", "paper-robustness",
                             "--small", "--workers", "1", "--quiet", "--out", str(out)],
                            start_new_session=True)
    first = out / "cases" / "0000.json"
    deadline = time.time() + 120
    while not first.exists():
        assert time.time() < deadline and proc.poll() is None
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    done = sorted(p.name for p in (out / "cases").glob("*.json"))
    assert 1 <= len(done) < 4
    stamps = {n: (out / "cases" / n).stat().st_mtime_ns for n in done}
    res = run_sweep("paper-robustness", out, workers=1, small=True, progress=False)
    assert len(res) == 4
    for n, st in stamps.items():  # finished cases were not redone
        assert (out / "cases" / n).stat().st_mtime_ns == st
    assert not list((out / "cases").glob("*.tmp-*"))
    for r in res:
        assert json.loads((out / "cases" / f"{r['index']:04d}.json").read_text())["status"] \
            == "complete"


def test_sweep_on_another_backend_and_no_mixing(tmp_path, capsys):
    """--backend runs every case on the fast backend; resuming that folder on another backend
    is refused (exit 2, one line), so a sweep's cases never mix backends."""
    from mdgran.cli import main

    out = tmp_path / "s"
    args = ["sweep", "paper-robustness", "--small", "--quiet", "--workers", "2", "--out", str(out)]
    assert main(args + ["--backend", "fast"]) == 0
    spec = json.loads((out / "sweep.json").read_text())
    assert spec["backend"] == "fast"
    from mdgran.output.run_record import read_h5

    assert read_h5(out / "cases" / "0000.h5").backend == "fast"
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0]


def test_a_sweep_keeps_to_its_scene(tmp_path, monkeypatch):
    """The scene path of a sweep file is read from the sweep file's folder; a resume on a
    scene file changed since the sweep started is refused in one line, and a case started
    after the change fails rather than run another scene (cases of chain.n 10 and 12 were
    mixed in one sweep, all complete)."""
    from mdgran.studies.sweep import load_sweep, run_case, scene_digest

    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "chain.toml").write_text("[chain]\nn = 10\n[run]\nduration = 2.0\n")
    (folder / "s.toml").write_text('[sweep]\nscene = "chain.toml"\n[grid]\n'
                                   '"impulse.velocity" = [1.0, 2.0]\n')
    monkeypatch.chdir(tmp_path)  # not the sweep file's folder
    sw = load_sweep(str(folder / "s.toml"))
    assert Path(sw["scene"]) == folder / "chain.toml"
    out = tmp_path / "out"
    run_sweep(str(folder / "s.toml"), out, progress=False)
    (folder / "chain.toml").write_text("[chain]\nn = 12\n[run]\nduration = 2.0\n")
    with pytest.raises(SceneError, match="changed since the sweep"):
        run_sweep(str(folder / "s.toml"), out, progress=False)
    with pytest.raises(SceneError, match="changed since the sweep started"):
        run_case(sw["scene"], "reference", sw["cases"][0], str(out),
                 scene_sha256=sw["scene_sha256"])
    assert scene_digest(sw["scene"]) != sw["scene_sha256"]


def test_one_sweep_per_folder_at_a_time(tmp_path):
    """A second sweep on a folder another is running in is refused in one line (two sweeps
    on one folder recorded a case 'failed: FileNotFoundError', each removing the other's
    temporaries); the folder is free again once the first ends."""
    from mdgran.output.storage import OutputLock

    spec = tmp_path / "s.toml"
    spec.write_text('[sweep]\nscene = "micro-star"\n[fixed]\n"run.duration" = 1.0\n[grid]\n'
                    '"impulse.velocity" = [1.0]\n')
    out = tmp_path / "out"
    out.mkdir()
    first = OutputLock(out / "sweep")  # the other sweep, running
    try:
        with pytest.raises(SceneError, match="another sweep is running in this folder"):
            run_sweep(str(spec), out, progress=False)
    finally:
        first.release()
    assert run_sweep(str(spec), out, progress=False)[0]["status"] == "complete"
    assert not (out / "sweep.lock").exists()


def test_an_unreadable_case_file_is_refused_by_report_and_redone_by_sweep(tmp_path, capsys):
    """A case file cut short: mdgran report --sweep-dir refuses the folder up front in one line
    naming the case (it ran a minute, then a traceback), and the same mdgran sweep command
    redoes that case (it said all complete)."""
    from mdgran.cli import main

    spec = tmp_path / "s.toml"
    spec.write_text('[sweep]\nscene = "micro-star"\n[fixed]\n"run.duration" = 1.0\n[grid]\n'
                    '"impulse.velocity" = [1.0, 2.0]\n')
    out = tmp_path / "sw"
    run_sweep(str(spec), out, progress=False)
    case = out / "cases" / "0001.h5"
    case.write_bytes(case.read_bytes()[:1000])
    assert main(["report", str(tmp_path / "rep"), "--sweep-dir", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot be read" in err[0] and "0001" in err[0]
    kept = (out / "cases" / "0000.h5").stat().st_mtime_ns
    res = run_sweep(str(spec), out, progress=False)
    assert [r["status"] for r in res] == ["complete", "complete"]
    assert (out / "cases" / "0000.h5").stat().st_mtime_ns == kept
    assert case.stat().st_size > 1000
