"""Cross-checks on every CI run: shortened versions of the two flagship comparisons,
reference against LAMMPS, must pass every criterion of the harness."""
import pytest

from mdgran.compare import compare
from mdgran.scene import load_scene


@pytest.mark.lammps
@pytest.mark.parametrize("name", ["micro-star", "macro-hertz"])
def test_flagship_comparison_short(name, tmp_path):
    sc = load_scene(name, [("run.duration", 30.0)])
    rep = compare(sc, ("reference", "lammps"), out_dir=tmp_path)
    failed = [c for c in rep["criteria"] if not c["passed"]]
    assert not failed, failed
    pair = rep["pairs"]["lammps"]
    assert pair["events_compared"] >= 1
    assert (tmp_path / "report.md").exists()


@pytest.mark.parametrize("name", ["micro-star", "macro-hertz"])
def test_fast_backend_passes_the_harness(name, tmp_path):
    """The fast backend (event-located Verlet) against the reference, every criterion."""
    sc = load_scene(name, [("run.duration", 60.0)])
    rep = compare(sc, ("reference", "fast"), out_dir=tmp_path, ensemble=1)
    failed = [c for c in rep["criteria"] if not c["passed"]]
    assert not failed, failed
    assert rep["pairs"]["fast"]["events_compared"] >= 3
