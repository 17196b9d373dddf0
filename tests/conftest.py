import numpy as np
import pytest

from mdgran.scene import Scene, resolve


def make_scene(**sections) -> Scene:
    """A scene from keyword tables, e.g. make_scene(chain={"n": 2}, run={"duration": 5.0})."""
    return Scene("test", resolve({k: dict(v) for k, v in sections.items()}))


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
