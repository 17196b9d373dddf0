"""A run's results in memory: frame times, displacements, velocities, the ledger and events.

:class:`Trajectory` is what analysis and comparison work on; it is filled by
:class:`~mdgran.reporters.MemoryReporter` during a run or read back from an H5MD file with
:func:`read_h5`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LEDGER_NAMES = ("kinetic_energy", "contact_energy", "substrate_energy",
                "dissipated_viscous", "dissipated_hysteresis", "total_energy")


@dataclass
class Trajectory:
    time: np.ndarray  # [F]
    x: np.ndarray  # [F, n]
    v: np.ndarray  # [F, n]
    ledger: dict  # name -> [F]
    ev_time: np.ndarray  # [E]
    ev_contact: np.ndarray  # [E] contract numbering
    ev_kind: np.ndarray  # [E] 1 close, 0 open
    scene_toml: str = ""
    backend: str = ""
    attrs: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.x.shape[1]

    @property
    def e0(self) -> float:
        return float(self.ledger["total_energy"][0])

    def ledger_error(self, scale: float) -> np.ndarray:
        """``(total_energy(t) - E0) / scale`` over the frames."""
        tot = self.ledger["total_energy"]
        return (tot - tot[0]) / scale

    def potential_energy(self) -> np.ndarray:
        return self.ledger["contact_energy"] + self.ledger["substrate_energy"]


def read_h5(path) -> Trajectory:
    """Read an mdgran H5MD file back into a :class:`Trajectory`."""
    import h5py

    with h5py.File(path, "r") as f:
        chain = f["particles/chain"]
        led = {name: f[f"observables/{name}/value"][()] for name in LEDGER_NAMES}
        attrs = {k: (v.decode() if isinstance(v, bytes) else v)
                 for k, v in f["parameters"].attrs.items()}
        return Trajectory(
            time=chain["displacement/time"][()],
            x=chain["displacement/value"][()],
            v=chain["velocity/value"][()],
            ledger=led,
            ev_time=f["events/time"][()],
            ev_contact=f["events/contact"][()],
            ev_kind=f["events/kind"][()],
            scene_toml=str(attrs.get("scene", "")),
            backend=str(attrs.get("backend", "")),
            attrs=attrs,
        )
