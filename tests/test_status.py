"""Honest status: a run whose energy-ledger error exceeds its backend's declared bound is not
"complete" (RunResult, the H5MD file, ``mdgran run``'s exit line and status, sweep summaries,
``mdgran report``, ``mdgran compare``); a correct run stays complete.

The ledger errors checked here are recomputed from the file's observables, not taken from the
driver; the injected defect's size is known (backends_for_tests.LedgerDefect)."""
import json

import h5py
import numpy as np
import pytest

from mdgran.backends import BACKENDS
from mdgran.cli import main
from mdgran.model.scene import load_scene
from mdgran.simulation import LEDGER_EXCEEDED, run

DEFECT = "ledger-defect"


@pytest.fixture
def defect_backend(monkeypatch):
    import sys
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).parent))
    monkeypatch.setitem(BACKENDS, DEFECT, "backends_for_tests:LedgerDefect")
    yield
    sys.modules.pop("backends_for_tests", None)


def file_status_and_error(path, e_imp):
    """``/parameters@status`` and ``max |E - E0| / E_imp`` recomputed from the file."""
    with h5py.File(path) as f:
        tot = f["observables/total_energy/value"][()]
        return f["parameters"].attrs["status"], float(np.max(np.abs(tot - tot[0])) / e_imp)


def test_fast_at_a_huge_step_is_not_complete(tmp_path, capsys):
    """micro-star on fast at dt = 0.25: on its dt^2 curve, but 12% of E_imp off (measured
    0.12 to t = 400), above the fixed-step cap of 3% of E_s = E_imp + N_c W_loop; the run
    writes every frame, says why in the file, and exits 1 with one line on stderr."""
    out = tmp_path / "big.h5"
    code = main(["run", "micro-star", "--backend", "fast", "--out", str(out), "--set",
                 "run.dt=0.25", "--set", "run.output_interval=0.5", "--set",
                 "run.duration=100", "--checkpoint", "0"])
    cap = capsys.readouterr()
    sc = load_scene("micro-star")
    status, err = file_status_and_error(out, sc.impulse_energy)
    e_s = sc.impulse_energy + 21 * sc.law.loop_energy  # 21 contacts with the walls
    assert err > 0.03 * e_s / sc.impulse_energy * 2  # independent: well above the cap
    assert status.startswith(LEDGER_EXCEEDED) and f"{err:.3g}" in status
    assert code == 1
    last = cap.err.strip().splitlines()[-1]
    assert last.startswith(f"mdgran: error: {LEDGER_EXCEEDED}") and str(out) in last
    assert "bound" in cap.out and f"{err:.2e}" in cap.out  # the exit line shows both numbers
    with h5py.File(out) as f:
        assert f["particles/chain/displacement/time"][-1] == pytest.approx(100.0)


def test_correct_runs_stay_complete(tmp_path):
    sc = load_scene("micro-star", [("run.duration", 40.0)])
    for backend in ("fast", "reference"):
        out = tmp_path / f"{backend}.h5"
        res = run(sc, backend, out=out)
        status, err = file_status_and_error(out, sc.impulse_energy)
        assert res.status == status == "complete"
        assert res.max_ledger_error == pytest.approx(err, rel=1e-12)
        assert err < res.ledger_bound < 1e-2


def test_injected_ledger_defect_is_flagged(defect_backend, tmp_path, capsys):
    from backends_for_tests import LedgerDefect

    sc = load_scene("micro-star", [("run.duration", 10.0)])
    out = tmp_path / "d.h5"
    res = run(sc, DEFECT, out=out)
    status, err = file_status_and_error(out, sc.impulse_energy)
    assert err == pytest.approx(LedgerDefect.DEFECT, rel=1e-3)  # the defect is what shows
    assert res.ledger_bound < err
    assert res.status == status and status.startswith(LEDGER_EXCEEDED)
    assert res.error is None  # not a failure of the integration: the frames are all there
    # the same run without the defect is complete: the bound sits between the two
    clean = run(sc, "reference")
    assert clean.status == "complete" and clean.max_ledger_error < clean.ledger_bound
    assert clean.ledger_bound == pytest.approx(res.ledger_bound, rel=1e-6)

    code = main(["run", "micro-star", "--backend", DEFECT, "--out", str(tmp_path / "c.h5"),
                 "--set", "run.duration=10", "--quiet", "--checkpoint", "0"])
    err_text = capsys.readouterr().err
    assert code == 1 and err_text.count("\n") == 1
    assert err_text.startswith(f"mdgran: error: {LEDGER_EXCEEDED}")


def test_sweep_and_report_list_cases_over_their_bound(defect_backend, tmp_path, capsys):
    from mdgran.studies.paper_study import run_status, status_markdown, sweep_cases

    spec = tmp_path / "defect.toml"
    spec.write_text(f'[sweep]\nscene = "micro-star"\nbackend = "{DEFECT}"\n'
                    '[fixed]\n"run.duration" = 6.0\n'
                    '[grid]\n"impulse.velocity" = [10.0, 12.0]\n')
    out = tmp_path / "sweep"
    assert main(["sweep", str(spec), "--out", str(out), "--workers", "1", "--quiet"]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert "0 of 2 cases complete" in lines[0] and "2 exceeded their ledger bound" in lines[0]
    assert sum(LEDGER_EXCEEDED in ln for ln in lines[1:]) == 2
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] == 0 and [c["index"] for c in summary["ledger_exceeded"]] == [0, 1]
    case = json.loads((out / "cases" / "0001.json").read_text())
    assert case["ledger_error"] > case["ledger_bound"]
    # mdgran report's status section, from the files
    cases = sweep_cases(out)

    class Run:  # a flagship run as read back: only its status matters here
        status = "complete"

    md = "\n".join(status_markdown({"status": run_status({"micro-star": Run()}, cases)}))
    assert "case 0000" in md and "case 0001" in md and md.count(LEDGER_EXCEEDED) == 2
    ok = "\n".join(status_markdown({"status": run_status({"micro-star": Run()}, [])}))
    assert LEDGER_EXCEEDED not in ok and "Every run and sweep case is complete" in ok


def test_compare_does_not_pass_a_run_over_its_bound(defect_backend):
    from mdgran.crosscheck.compare import compare

    sc = load_scene("micro-star", [("run.duration", 10.0)])
    rep = compare(sc, ("reference", DEFECT), ensemble=0)
    v = {c["name"]: c for c in rep["criteria"]}
    assert v["ledger reference"]["passed"]
    assert not v[f"ledger {DEFECT}"]["passed"] and not rep["passed"]
    assert rep["runs"][DEFECT]["status"].startswith(LEDGER_EXCEEDED)
