"""A run's results in memory: frame times, displacements, velocities, the ledger and events.

:class:`Trajectory` is what analysis and comparison work on; it is filled by
:class:`~mdgran.reporters.MemoryReporter` during a run or read back from an H5MD file with
:func:`read_h5` (``mdgran.read``).  Everything is nondimensional (physics.md section 1):
length ``p``, time ``1/q``, velocity ``p q``, energy ``eta p`` (force ``eta = pi R w``, bead
mass 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LEDGER_NAMES = ("kinetic_energy", "contact_energy", "substrate_energy",
                "dissipated_viscous", "dissipated_hysteresis", "total_energy")


@dataclass(repr=False)
class Trajectory:
    """One run's frames and events (nondimensional units, physics.md section 1).

    Attributes:
        time: ``[F]`` frame times (units of ``1/q``), the first 0, one per
            ``run.output_interval``.
        x: ``[F, n]`` bead displacements from their rest places (units of ``p``); bead ``i``
            (1-based in the scene's keys) is column ``i - 1``.
        v: ``[F, n]`` bead velocities (units of ``p q``).
        ledger: energy ledger per frame (units of ``eta p``), name -> ``[F]`` array, for each of
            ``LEDGER_NAMES``: ``kinetic_energy``, ``contact_energy``, ``substrate_energy``,
            ``dissipated_viscous``, ``dissipated_hysteresis``, and ``total_energy`` (their sum,
            constant up to the backend's error).
        ev_time: ``[E]`` times of the contact events, in order.
        ev_contact: ``[E]`` contact of each event: contact ``i`` joins bead ``i-1`` and bead
            ``i`` (1..n+1 with walls, beads 0 and n+1 being the walls; 2..n for a free chain).
        ev_kind: ``[E]`` 1 = close (snap to contact), 0 = open (snap-off).
        scene_toml: the resolved scene as TOML text (:attr:`scene` parses it).
        backend: name of the backend that computed the run.
        attrs: more about the run: ``status`` (``"complete"``, ``"failed: ..."``,
            ``"ledger-exceeded: ..."``), ``scene_name``; read from a file, every attribute of
            its ``/parameters`` group (versions, units, backend_stats, ``mpi_ranks``, ...).
        closed: ``[F, n_contacts]`` bool, the state of every contact at every frame (True =
            closed), column ``j`` being contact number ``contact_numbers[j]``; or None (a file
            written without ``output.contacts``).  Filled by a run in memory, and read from
            ``/observables/contacts/closed`` by :func:`read_h5`.
    """

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
    closed: np.ndarray | None = None  # [F, n_contacts] bool, or None

    @property
    def n(self) -> int:
        """Number of moving beads."""
        return self.x.shape[1]

    @property
    def frames(self) -> int:
        """Number of stored frames."""
        return len(self.time)

    @property
    def contact_numbers(self) -> np.ndarray:
        """Contract numbers of the contacts, the columns of :attr:`closed`: 1..n+1 with walls,
        2..n for a free chain (from the stored scene's ``chain.boundary``; fixed if unknown)."""
        free = False
        if self.scene_toml:
            from .scene import tomllib

            free = tomllib.loads(self.scene_toml).get("chain", {}).get("boundary") == "free"
        return np.arange(2, self.n + 1) if free else np.arange(1, self.n + 2)

    @property
    def e0(self) -> float:
        """Total energy of the first frame (``eta p``)."""
        return float(self.ledger["total_energy"][0])

    @property
    def scene(self):
        """The run's resolved :class:`~mdgran.scene.Scene`, parsed from :attr:`scene_toml`
        (None if the trajectory holds no scene).  A stored ``[material]`` without E, nu, w or
        density was written by an mdgran that took the paper's alumina for them (it stored
        only what the scene file gave); those values are filled in, as that run used them."""
        if not self.scene_toml:
            return None
        from .scene import Scene, resolve, tomllib
        from .units import ALUMINA

        data = tomllib.loads(self.scene_toml)
        mat = data.get("material")
        if isinstance(mat, dict) and "K" not in mat:
            for key in ("E", "nu", "w", "density"):
                mat.setdefault(key, ALUMINA[key])
        return Scene(str(self.attrs.get("scene_name", "") or "scene"), resolve(data))

    def ledger_error(self, scale: float) -> np.ndarray:
        """``(total_energy(t) - E0) / scale`` over the frames."""
        tot = self.ledger["total_energy"]
        return (tot - tot[0]) / scale

    def potential_energy(self) -> np.ndarray:
        """Contact plus substrate energy per frame (``eta p``)."""
        return self.ledger["contact_energy"] + self.ledger["substrate_energy"]

    def __repr__(self) -> str:
        parts = []
        if self.attrs.get("scene_name"):
            parts.append(f"scene={str(self.attrs['scene_name'])!r}")
        parts.append(f"backend={self.backend!r}")
        if self.attrs.get("status"):
            status = str(self.attrs["status"])
            parts.append(f"status={status if len(status) <= 60 else status[:57] + '...'!r}")
        t = np.asarray(self.time)
        span = f"t=[{float(t[0]):.6g}, {float(t[-1]):.6g}]" if t.size else "t=[]"
        parts += [f"frames={t.size}", f"n={np.shape(self.x)[-1] if np.ndim(self.x) == 2 else 0}",
                  span, f"events={len(self.ev_time)}"]
        return f"Trajectory({', '.join(parts)})"


def read_h5(path) -> Trajectory:
    """Read an mdgran H5MD file back into a :class:`Trajectory` (also ``mdgran.read``)."""
    import h5py

    with h5py.File(path, "r") as f:
        missing = [g for g in ("particles/chain", "events", "parameters") if g not in f]
        missing += [f"observables/{name}" for name in LEDGER_NAMES
                    if f"observables/{name}" not in f]
        if missing:
            raise ValueError(f"{path}: not an mdgran H5MD file (no /{missing[0]})")
        chain = f["particles/chain"]
        led = {name: f[f"observables/{name}/value"][()] for name in LEDGER_NAMES}
        attrs = {k: (v.decode() if isinstance(v, bytes) else v)
                 for k, v in f["parameters"].attrs.items()}
        closed = None
        if "observables/contacts/closed/value" in f:
            closed = f["observables/contacts/closed/value"][()].astype(bool)
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
            closed=closed,
        )
