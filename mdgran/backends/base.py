"""What every backend yields, and the errors it raises.

A backend is constructed from a resolved scene and iterated: ``for frame in backend.frames()``
yields one :class:`Frame` per stored output time, the first at ``t = 0``.  Each frame carries
the contact events since the previous frame.  The ledger (energies) is computed from the frame
by the shared :class:`~mdgran.chain.ChainModel`, so every backend's ledger means the same thing.
Writing output, progress and energy checks are reporters (see :mod:`mdgran.simulation`), not
the backend's business.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

CLOSE, OPEN = 1, 0


class IntegrationError(RuntimeError):
    """A run failed (blow-up, step collapse, out-of-table compression): exit status 1.

    The message is one line naming the time, and the bead or contact where known.
    """


@dataclass
class Event:
    time: float
    contact: int  # contract numbering: contact i joins bead i-1 and bead i
    kind: int  # CLOSE = 1, OPEN = 0


@dataclass
class Frame:
    step: int
    time: float
    x: np.ndarray  # [n] displacement
    v: np.ndarray  # [n] velocity
    closed: np.ndarray  # [n_contacts] bool
    dissipated_viscous: float
    dissipated_hysteresis: float
    events: list = field(default_factory=list)  # Events in (previous frame time, time]


class Backend:
    """Base class: holds the scene and model; subclasses implement :meth:`frames`."""

    name = "base"

    def __init__(self, scene, **options):
        from ..chain import model_from_scene

        self.scene = scene
        self.model = model_from_scene(scene)
        self.options = options
        self.stats: dict = {}

    #: order of convergence in ``run.dt`` for fixed-step backends (used for error estimates)
    order = 2

    @classmethod
    def refinement(cls, scene):
        """Overrides for a more accurate run of the same scene, and the factor that turns the
        difference between the two runs into an error estimate of the nominal one.

        Fixed-step backends of order ``p`` halve ``run.dt``: Richardson gives
        ``error(dt) ~ |x_dt - x_dt/2| * 2^p / (2^p - 1)``.
        """
        dt = float(scene.data["run"]["dt"])
        return [("run.dt", dt / 2)], 2.0**cls.order / (2.0**cls.order - 1.0)

    def frames(self, resume: dict | None = None) -> Iterator[Frame]:  # pragma: no cover
        """Yield frames from t = 0, or from just after a checkpoint (``resume``)."""
        raise NotImplementedError

    def checkpoint_state(self) -> dict | None:
        """The state to continue from the last yielded frame, or None if the backend cannot
        checkpoint (then runs are not resumable)."""
        return None

    def output_times(self) -> np.ndarray:
        run = self.scene.data["run"]
        dt_out = float(run["output_interval"])
        n_out = int(np.floor(float(run["duration"]) / dt_out + 1e-9))
        return dt_out * np.arange(n_out + 1)
