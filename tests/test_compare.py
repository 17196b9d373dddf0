"""The comparison harness: it passes a correct second backend and fails broken ones on the
right criterion (the harness can fail)."""
import json

import pytest

from mdgran.backends import BACKENDS
from mdgran.crosscheck.compare import compare
from mdgran.model.scene import load_scene

TEST_BACKENDS = {
    "tight-reference": "backends_for_tests:TightReference",
    "flipped-damping": "backends_for_tests:FlippedDamping",
    "wrong-snap-off": "backends_for_tests:WrongSnapOff",
}


@pytest.fixture
def test_backends(monkeypatch):
    import sys
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).parent))
    for k, v in TEST_BACKENDS.items():
        monkeypatch.setitem(BACKENDS, k, v)
    yield
    sys.modules.pop("backends_for_tests", None)


def verdicts(report):
    return {c["name"]: c["passed"] for c in report["criteria"]}


def test_correct_backend_passes_and_report_is_written(test_backends, tmp_path):
    sc = load_scene("micro-star", [("run.duration", 30.0)])
    rep = compare(sc, ("reference", "tight-reference"), out_dir=tmp_path)
    assert rep["passed"], [c for c in rep["criteria"] if not c["passed"]]
    for f in ("report.md", "report.json", "energies.png", "ledger_error.png", "difference.png",
              "events.png", "reference.h5", "tight-reference.h5"):
        assert (tmp_path / f).exists(), f
    assert json.loads((tmp_path / "report.json").read_text())["passed"] is True
    assert rep["predictability"]["amplification"] > 1


def test_flipped_damping_fails_on_dissipation(test_backends):
    sc = load_scene("micro-star", [("run.duration", 30.0)])
    v = verdicts(compare(sc, ("reference", "flipped-damping"), ensemble=0))  # no cluster stats
    assert not v["dissipation never decreases (flipped-damping)"]
    assert not v["trajectory flipped-damping vs reference"]
    assert v["dissipation never decreases (reference)"]


def test_wrong_snap_off_fails_on_events(test_backends):
    sc = load_scene("micro-star", [("run.duration", 30.0)])
    v = verdicts(compare(sc, ("reference", "wrong-snap-off"), ensemble=0))
    assert not v["events wrong-snap-off vs reference"]
    assert not v["dissipated_hysteresis at horizon"]
    assert v["dissipation never decreases (wrong-snap-off)"]  # its own books are consistent


def test_cli_compare_exit_status(test_backends, tmp_path, capsys):
    from mdgran.cli import main

    args = ["compare", "micro-star", "--set", "run.duration=10", "--quiet", "--out"]
    assert main(args + [str(tmp_path / "ok"), "--backends", "reference,tight-reference"]) == 0
    assert main(args + [str(tmp_path / "bad"), "--backends", "reference,flipped-damping"]) == 3
    assert "FAIL" in capsys.readouterr().out


def test_event_comparison_is_per_contact():
    from mdgran.crosscheck.compare import compare_events

    ta = [1.0, 1.001, 2.0, 5.0]
    sa = [(3, 1), (5, 1), (3, 0), (5, 0)]
    # two near-simultaneous closes on different contacts in the other order: same physics
    ev = compare_events([1.001, 1.0, 2.0, 5.0], [(5, 1), (3, 1), (3, 0), (5, 0)], ta, sa,
                        10.0, 0.01)
    assert ev["disagreement"] is None and ev["matched"] == 4
    assert ev["max_offset"] == 0.0
    # an open missing on contact 3: a disagreement naming it
    ev = compare_events(ta, sa, [1.0, 1.001, 5.0], [(3, 1), (5, 1), (5, 0)], 10.0, 0.01)
    assert ev["contacts_differing"] == 1 and "contact 3 open" in ev["disagreement"]
    # the same event just inside the horizon in one backend, just outside in the other: edge
    ev = compare_events(ta, sa, ta[:3], sa[:3], 5.005, 0.01)
    assert ev["disagreement"] is None


def test_wrong_snap_off_fails_cluster_statistics(test_backends):
    """Past the first cluster (t ~ 29) the wrong snap-off rule changes the clusters' statistics:
    measured KS p = 0.004 on sizes (mean 5.06 vs 4.96 beads) over 100 time units; a correct
    backend passes them (see the cross-check tests)."""
    sc = load_scene("micro-star", [("run.duration", 100.0)])
    rep = compare(sc, ("reference", "wrong-snap-off"), ensemble=1)
    stats = [c for c in rep["criteria"] if c["name"].startswith("cluster ")]
    assert len(stats) == 2 and all(c["judged"] for c in stats)
    assert not all(c["passed"] for c in stats)


def test_an_unmatched_event_is_excused_only_when_undecidable():
    """A surplus close of contact 3 at t = 2 is a disagreement, unless the grazing test says
    the other backend came within its error of that switch (then it is counted apart)."""
    from mdgran.crosscheck.compare import compare_events

    ta, sa = [1.0, 2.0], [(3, 0), (3, 1)]
    tb, sb = [1.0], [(3, 0)]
    seen = []
    ev = compare_events(ta, sa, tb, sb, 10.0, 0.01,
                        lambda *r: seen.append(r) or False)
    assert ev["disagreement"] is not None and ev["undecidable"] == 0
    assert seen == [(2.0, 3, 1, "first", 0.01)]
    ev = compare_events(ta, sa, tb, sb, 10.0, 0.01, lambda *r: True)
    assert ev["disagreement"] is None and ev["undecidable"] == 1


def test_a_backend_that_fails_is_named_in_the_report(tmp_path, capsys):
    """The fast backend leaves its contact table at v0 = 3000 and dt = 0.01: the comparison
    writes a report saying which backend failed and why, exits 1 with one line (it was a
    traceback and no report), and clears what an earlier comparison left in the folder (a
    run of another backend, a figure) but not files of the user's."""
    from mdgran.cli import main

    out = tmp_path / "cmp"
    (out / "figures").mkdir(parents=True)
    for stale in ("lammps.h5", "report.md", "figures/old.png", "mine.h5"):
        (out / stale).write_text("from before")
    code = main(["compare", "micro-star", "--backends", "reference,fast", "--set",
                 "impulse.velocity=3000", "--set", "run.dt=0.01", "--set", "run.duration=1",
                 "--ensemble", "0", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and "backend fast failed" in err[0]
    report = json.loads((out / "report.json").read_text())
    assert report["passed"] is False and report["failed"]["backend"] == "fast"
    assert "contact table" in report["failed"]["error"]
    assert report["runs"]["reference"]["status"] == "complete"
    assert "The run on **fast** failed" in (out / "report.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["fast.h5", "figures", "mine.h5",
                                                     "reference.h5", "report.json",
                                                     "report.md"]
    assert not list((out / "figures").iterdir())
