"""The in-memory reporter: every block of a run kept, returned as a
:class:`~mdgran.output.run_record.Run` (what ``mdgran.run`` gives back as ``result.trajectory``)."""
from __future__ import annotations

import numpy as np

from ..backends.base import Events
from .run_record import LEDGER_NAMES, Run


class MemoryReporter:
    """Keeps every frame in memory; :meth:`record` returns them as a
    :class:`~mdgran.output.run_record.Run`, with the contacts' states (``Run.closed``,
    ``[frames, n_contacts]`` bool)."""

    def __init__(self):
        self.blocks = []  # the blocks of frames (mdgran.backends.base.Frames) as they came
        self.status = None

    def report_block(self, block):
        """Keep the block as it is (a backend hands every block arrays of its own, which it
        does not change after) with its ledger."""
        block.ledger()
        self.blocks.append(block)

    def close(self, status):
        self.status = status

    def record(self, scene=None, backend="") -> Run:
        """The frames so far as a :class:`~mdgran.output.run_record.Run` of ``scene`` (a
        :class:`~mdgran.model.scene.Scene`) on ``backend``."""
        blocks = self.blocks

        def joined(name, dtype=float):
            parts = [getattr(b, name) for b in blocks]
            return np.concatenate(parts).astype(dtype, copy=False) if parts else np.array(
                [], dtype=dtype)

        ev = Events.join([b.events for b in blocks])
        return Run(
            time=joined("time"), x=joined("x"), v=joined("v"),
            ledger={k: np.concatenate([b.ledger()[k] for b in blocks]) if blocks
                    else np.array([]) for k in LEDGER_NAMES},
            ev_time=ev.time.copy(), ev_contact=ev.contact.copy(), ev_kind=ev.kind.copy(),
            scene=scene, backend=backend, attrs={"status": self.status},
            closed=joined("closed", bool) if blocks else None)
