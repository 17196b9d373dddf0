"""Sweeps survive their cases' faults and stop when told, with real signals to real processes.

Every test runs ``python -m mdgran sweep`` as a subprocess.  Faults are put into the workers by
a ``sitecustomize`` module that the test writes and puts on the subprocess's PYTHONPATH (test
code only: the library has no fault switch): it wraps ``mdgran.studies.sweep.run_case`` so that
chosen cases raise, kill their own worker with SIGKILL, or sleep first (slow cases, for signals sent
mid-sweep).  Worker pids are read from /proc (the main process's children), not from psutil.
"""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="reads worker pids from /proc (Linux)")

SITECUSTOMIZE = '''
import os
import signal
import time

_spec = os.environ.get("MDGRAN_TEST_FAULTS")
if _spec:
    import mdgran.studies.sweep as _sw
    from mdgran.model.scene import SceneError

    _real = _sw.run_case

    def run_case(scene_spec, backend, case, out_dir, *rest):
        for item in _spec.split(","):
            what, _, idx = item.partition(":")
            if idx in ("*", str(case["index"])):
                if what == "raise":
                    raise RuntimeError(f"injected failure in case {case['index']}")
                if what == "sceneerror":  # an exception that does not pickle back
                    raise SceneError("chain.n", "injected spec error in a worker")
                if what == "die":
                    os.kill(os.getpid(), signal.SIGKILL)
                if what.startswith("sleep"):
                    time.sleep(float(what[5:]))
        return _real(scene_spec, backend, case, out_dir, *rest)

    _sw.run_case = run_case
'''


def _sweep_file(tmp_path, n_cases: int, duration: float = 10.0) -> Path:
    path = tmp_path / "faults.toml"
    values = ", ".join(f"{1.0 + k:.1f}" for k in range(n_cases))
    path.write_text(f'[sweep]\nscene = "micro-star"\nbackend = "reference"\n\n[fixed]\n'
                    f'"run.duration" = {duration}\n\n[grid]\n"impulse.velocity" = [{values}]\n')
    return path


def _start(tmp_path, spec, out, faults="", workers=2, **kw):
    inject = tmp_path / "inject"
    inject.mkdir(exist_ok=True)
    (inject / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = dict(os.environ, MDGRAN_TEST_FAULTS=faults,
               PYTHONPATH=os.pathsep.join([str(inject)] + [p for p in [
                   os.environ.get("PYTHONPATH")] if p]))
    return subprocess.Popen([sys.executable, "-m", "mdgran", "sweep", str(spec), "--out",
                             str(out), "--workers", str(workers), "--quiet"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _stat(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()
    except OSError:
        return None


def _children(pid) -> list:
    kids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            st = _stat(d)
            if st is not None and int(st[1]) == pid:
                kids.append(int(d))
    return kids


def _alive(pid) -> bool:
    """A process that exists and is not a zombie (an exited child not yet reaped)."""
    st = _stat(pid)
    return st is not None and st[0] not in ("Z", "X")


def _wait_for(cond, proc, timeout=60.0, what=""):
    deadline = time.time() + timeout
    while not cond():
        assert proc.poll() is None, f"sweep ended early: {proc.communicate()}"
        assert time.time() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def _gone_within(pids, seconds) -> float:
    t0 = time.time()
    while any(_alive(p) for p in pids):
        assert time.time() - t0 < seconds, f"workers still running: {pids}"
        time.sleep(0.05)
    return time.time() - t0


def test_failing_cases_are_recorded_and_the_sweep_goes_on(tmp_path):
    """A case raising (even an exception that cannot be pickled back) and a case that kills
    its worker every time are recorded failed with a one-line reason; the others complete."""
    spec, out = _sweep_file(tmp_path, 6), tmp_path / "sw"
    proc = _start(tmp_path, spec, out, "raise:1,die:2,sceneerror:4")
    stdout, stderr = proc.communicate(timeout=240)
    assert proc.returncode == 1, stderr
    assert "Traceback" not in stderr and "BrokenProcessPool" not in stderr
    summ = json.loads((out / "summary.json").read_text())
    assert summ["cases"] == 6 and summ["complete"] == 3
    failed = {r["index"]: r["status"] for r in summ["failed"]}
    assert sorted(failed) == [1, 2, 4]
    assert failed[1] == "failed: RuntimeError: injected failure in case 1"
    assert failed[2].startswith("failed: its worker process died 2 times")
    assert "SIGKILL" in failed[2]
    assert failed[4] == "failed: SceneError: chain.n: injected spec error in a worker"
    for i, status in failed.items():
        case = json.loads((out / "cases" / f"{i:04d}.json").read_text())
        assert case["status"] == status and "\n" not in status
        assert f"case {i:04d}" in stdout and status in stdout
    for i in (0, 3, 5):
        assert json.loads((out / "cases" / f"{i:04d}.json").read_text())["status"] == "complete"
        assert (out / "cases" / f"{i:04d}.h5").exists()
    assert not list((out / "cases").glob("*.tmp-*"))
    # mdgran report takes the sweep and names the failed cases in its run status
    from mdgran.studies.paper_study import check_sweep_files, status_markdown

    failed_rows = check_sweep_files(out)
    assert [r["index"] for r in failed_rows] == [1, 2, 4]
    text = "\n".join(status_markdown({"status": {"runs": {}, "sweep_not_complete": failed_rows}}))
    assert "case 0001" in text and "injected failure" in text
    # the same command again, the faults gone: the failed cases are redone, the others kept
    stamps = {i: (out / "cases" / f"{i:04d}.h5").stat().st_mtime_ns for i in (0, 3, 5)}
    again = _start(tmp_path, spec, out, "")
    stdout, stderr = again.communicate(timeout=240)
    assert again.returncode == 0, stderr
    assert json.loads((out / "summary.json").read_text())["complete"] == 6
    assert all((out / "cases" / f"{i:04d}.h5").stat().st_mtime_ns == st
               for i, st in stamps.items())


def test_a_worker_killed_from_outside_is_replaced_and_its_case_redone(tmp_path):
    spec, out = _sweep_file(tmp_path, 4), tmp_path / "sw"
    proc = _start(tmp_path, spec, out, "sleep2:*")
    _wait_for(lambda: len(_children(proc.pid)) >= 2, proc, what="two workers")
    time.sleep(0.5)
    victim = _children(proc.pid)[0]
    os.kill(victim, signal.SIGKILL)
    stdout, stderr = proc.communicate(timeout=240)
    assert proc.returncode == 0, stderr
    summ = json.loads((out / "summary.json").read_text())
    assert summ == {"cases": 4, "complete": 4, "ledger_exceeded": [], "failed": []}
    assert not _alive(victim)


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "SIGINT to the group"])
def test_interrupt_stops_promptly_kills_workers_and_resumes(tmp_path, how):
    """Ctrl-C (SIGINT to the main process, or to the whole process group as a terminal sends
    it) and SIGTERM stop the sweep within seconds: queued cases are not started, running ones
    are killed, finished ones stay; the same command then runs only the rest."""
    spec, out = _sweep_file(tmp_path, 5), tmp_path / "sw"
    proc = _start(tmp_path, spec, out, "sleep60:2,sleep60:3,sleep60:4",
                  start_new_session=True)
    done = [out / "cases" / f"{i:04d}.json" for i in (0, 1)]
    _wait_for(lambda: all(p.exists() for p in done), proc, what="cases 0 and 1")
    workers = _children(proc.pid)
    assert len(workers) == 2
    stamps = {p: p.stat().st_mtime_ns for p in done}
    time.sleep(0.3)  # both workers are in cases 2 and 3 now, case 4 is queued
    sig = signal.SIGTERM if how == "SIGTERM" else signal.SIGINT
    t0 = time.time()
    if how.endswith("group"):
        os.killpg(proc.pid, sig)
    else:
        os.kill(proc.pid, sig)
    stdout, stderr = proc.communicate(timeout=30)
    took = time.time() - t0
    assert took < 5.0, f"took {took:.1f} s to stop"
    assert proc.returncode in (130, 128 + sig), (proc.returncode, stderr)
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    _gone_within(workers, 3.0)
    assert sorted(p.name for p in (out / "cases").glob("*.json")) == ["0000.json", "0001.json"]
    assert not list((out / "cases").glob("*.tmp-*"))
    if how == "SIGTERM":  # an unfinished sweep is refused by mdgran report, in one line
        from mdgran.cli import main

        assert main(["report", str(tmp_path / "rep"), "--sweep-dir", str(out), "--quiet"]) == 2
    again = _start(tmp_path, spec, out, "")
    stdout, stderr = again.communicate(timeout=240)
    assert again.returncode == 0, stderr
    assert json.loads((out / "summary.json").read_text())["complete"] == 5
    for p, st in stamps.items():  # finished cases were not redone
        assert p.stat().st_mtime_ns == st


def test_workers_exit_when_the_main_process_is_killed(tmp_path):
    spec, out = _sweep_file(tmp_path, 4), tmp_path / "sw"
    proc = _start(tmp_path, spec, out, "sleep60:*", start_new_session=True)
    _wait_for(lambda: len(_children(proc.pid)) >= 2, proc, what="two workers")
    workers = _children(proc.pid)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    took = _gone_within(workers, 5.0)
    assert took < 5.0
