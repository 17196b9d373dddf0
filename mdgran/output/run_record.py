"""One run's record: frames, contact states, ledger, events, scene and status, in memory.

:class:`Run` is what every later stage reads (analysis, ``budget``, ``compare``, ``study``,
``sweep``, the paper's figures): it is filled by
:class:`~mdgran.output.memory_reporter.MemoryReporter` during a run, or read back from an H5MD file
by :func:`read_h5` (``mdgran.read``), and it holds everything those stages need, so none of them
rebuilds the scene or the contact states. Everything is nondimensional (docs/physics.md section 1):
length ``p``, time ``1/q``, velocity ``p q``, energy ``eta p`` (force ``eta = pi R w``, bead mass
1).
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from ..model.chain import contact_numbers, initial_states, replay_states

LEDGER_NAMES = ("kinetic_energy", "contact_energy", "substrate_energy",
                "dissipated_viscous", "dissipated_hysteresis", "external_work", "total_energy")

#: ledger terms that files written before them lack (read as 0 at every frame)
OPTIONAL_TERMS = ("external_work",)


def ledger_terms(scene) -> tuple:
    """The ledger terms a file of ``scene`` stores: :data:`LEDGER_NAMES`, without
    ``external_work`` for a scene without excitations (it would be 0 at every frame)."""
    if scene.drive is not None:
        return LEDGER_NAMES
    return tuple(name for name in LEDGER_NAMES if name not in OPTIONAL_TERMS)


class DecimatedRecord(ValueError):
    """A record that stores some beads only (``output.bead_stride``) was asked for every
    bead: one line naming the key."""


def ledger_scale(impulse_energy: float, e0: float) -> float:
    """The energy that ledger errors are measured in (units of eta p): the impulse energy
    ``E_imp = v0^2 / 2``, or ``max(|E0|, 1)`` for a scene without an impulse."""
    return float(impulse_energy) if impulse_energy else max(abs(float(e0)), 1.0)


def relative_ledger_error(total, e0: float, scale: float):
    """The ledger error ``(E(t) - E0) / scale`` of total energies ``total`` (a number or an
    array; units of eta p), with ``scale`` from :func:`ledger_scale`: the one definition that
    the driver (frame by frame) and :meth:`Run.ledger_error` (over the frames) use."""
    return (total - e0) / scale


def scene_from_toml(text: str, name: str = "scene"):
    """The :class:`~mdgran.model.scene.Scene` of a stored resolved scene's TOML text.

    A resolved scene without a material stores the default ``[material] modulus = "table"``,
    which alone does not resolve (a material needs its diameter): such a table is dropped.  A
    stored ``[material]`` with a diameter but without E, nu, w or density was written by an
    mdgran that took the paper's alumina for them (it stored only what the scene file gave);
    those values are filled in, as that run used them."""
    from ..model.scene import Scene, resolve, tomllib
    from ..model.units import ALUMINA

    data = tomllib.loads(text)
    mat = data.get("material")
    if isinstance(mat, dict) and "diameter" not in mat:
        del data["material"]
    elif isinstance(mat, dict) and "K" not in mat:
        for key in ("E", "nu", "w", "density"):
            mat.setdefault(key, ALUMINA[key])
    return Scene(name, resolve(data))


class Run:
    """One run's record (nondimensional units, docs/physics.md section 1).

    Attributes:
        time: ``[F]`` frame times (units of ``1/q``), the first 0, one per
            ``run.output_interval``.
        x: ``[F, n]`` bead displacements from their rest places (units of ``p``); bead ``i``
            (1-based in the scene's keys) is column ``i - 1``.  A record of a file written
            with ``output.bead_stride`` != 1 holds some beads only: ``x`` and ``v`` then raise
            :class:`DecimatedRecord` (one line), as every analysis of them needs every bead.
        v: ``[F, n]`` bead velocities (units of ``p q``).
        bead_ids: ``[B]`` 1-based numbers of the stored beads (``1, 1 + k, ...`` for
            ``output.bead_stride = k``; empty for 0); None: every bead.
        x_stored, v_stored: ``[F, B]`` displacements and velocities of the beads
            ``bead_ids`` (``x`` and ``v`` for a record of every bead).
        closed: ``[F, n_contacts]`` bool, the state of every contact at every frame (True =
            closed), column ``j`` being contact number ``contact_numbers[j]``.  Stored by the
            run; for a file written without them (by an older mdgran), rebuilt from the events
            (:func:`~mdgran.model.chain.replay_states`).
        ledger: energy ledger per frame (units of ``eta p``), name -> ``[F]`` array, for each of
            ``LEDGER_NAMES``: ``kinetic_energy``, ``contact_energy``, ``substrate_energy``,
            ``dissipated_viscous``, ``dissipated_hysteresis``, and ``total_energy`` (their sum,
            constant up to the backend's error).
        ev_time: ``[E]`` times of the contact events, in order.
        ev_contact: ``[E]`` contact of each event: contact ``i`` joins bead ``i-1`` and bead
            ``i`` (1..n+1 with walls, beads 0 and n+1 being the walls; 2..n for a free chain).
        ev_kind: ``[E]`` 1 = close (snap to contact), 0 = open (snap-off).
        scene: the run's resolved :class:`~mdgran.model.scene.Scene` (parsed once, on first use, for
            a record read from a file); ``scene_toml`` its TOML text, as stored.
        backend: name of the backend that computed the run.
        status: ``"complete"``, ``"failed: ..."``, ``"ledger-exceeded: ..."`` (``attrs``).
        attrs: more about the run: ``status``, ``scene_name``; read from a file, every attribute
            of its ``/parameters`` group (versions, units, backend_stats, ``mpi_ranks``, ...).
        path: the file the record was read from (:func:`read_h5`; "" for a run in memory).
        measures: the paper's measures of this run, each computed once
            (:class:`~mdgran.output.measures.Measures`).
    """

    def __init__(self, time, x, v, ledger, ev_time, ev_contact, ev_kind, scene_toml: str = "",
                 backend: str = "", attrs: dict | None = None, closed=None, scene=None,
                 bead_ids=None):
        self.time, self.x_stored, self.v_stored = time, x, v
        self.bead_ids = None if bead_ids is None else np.asarray(bead_ids, dtype=np.int64)
        self.path = ""  # the file it was read from (read_h5)
        self.ledger = ledger
        self.ev_time, self.ev_contact, self.ev_kind = ev_time, ev_contact, ev_kind
        self.scene_toml = scene_toml or (scene.to_toml() if scene is not None else "")
        self.backend = backend
        self.attrs = {} if attrs is None else attrs
        if scene is not None:
            self.__dict__["scene"] = scene  # the cached property's slot: no parsing
        self._closed = closed

    @property
    def decimated(self) -> bool:
        """True for a record that stores some beads only (``output.bead_stride`` != 1)."""
        return self.bead_ids is not None

    def _every_bead(self, name: str) -> np.ndarray:
        if self.decimated:
            k = int(self._data.get("output", {}).get("bead_stride", -1))
            where = f"{self.path}: " if self.path else ""
            raise DecimatedRecord(
                f"{where}output.bead_stride = {k}: the record stores {len(self.bead_ids)} of "
                f"{self.n} beads, and Run.{name} (every bead, which this analysis needs) is "
                "not there; run again with output.bead_stride = 1, or read Run.bead_ids and "
                f"Run.{name}_stored")
        return self.x_stored if name == "x" else self.v_stored

    @property
    def x(self) -> np.ndarray:
        """``[F, n]`` displacements of every bead (see the class docstring)."""
        return self._every_bead("x")

    @x.setter
    def x(self, value):
        self.x_stored = value

    @property
    def v(self) -> np.ndarray:
        """``[F, n]`` velocities of every bead (see the class docstring)."""
        return self._every_bead("v")

    @v.setter
    def v(self, value):
        self.v_stored = value

    @property
    def closed(self) -> np.ndarray:
        """``[F, n_contacts]`` bool contact states (see the class docstring): as stored, or
        replayed from the events on first use for a record that has none."""
        if self._closed is None:
            self._closed = self.replayed_states()
        return self._closed

    @closed.setter
    def closed(self, value):
        self._closed = value

    # ---- the scene ---------------------------------------------------------------------------
    @cached_property
    def scene(self):
        """The run's resolved :class:`~mdgran.model.scene.Scene` (None if the record holds no
        scene), parsed once from :attr:`scene_toml` (:func:`scene_from_toml`)."""
        if not self.scene_toml:
            return None
        return scene_from_toml(self.scene_toml, str(self.attrs.get("scene_name", "") or "scene"))

    @cached_property
    def _data(self) -> dict:
        """The scene's tables (parsed scene if there is one, else the raw TOML): what the
        layout and the ledger scale need, without resolving the scene."""
        if "scene" in self.__dict__ and self.scene is not None:
            return self.scene.data
        if not self.scene_toml:
            return {}
        from ..model.scene import tomllib

        return tomllib.loads(self.scene_toml)

    @property
    def walls(self) -> bool:
        """Fixed walls at both ends (``chain.boundary = "fixed"``; fixed if unknown)."""
        return self._data.get("chain", {}).get("boundary", "fixed") == "fixed"

    @property
    def impulse_energy(self) -> float:
        """``E_imp = m_b v0^2 / 2`` of the scene's impulse, ``m_b`` the struck bead's mass
        (:attr:`mdgran.model.scene.Scene.impulse_energy`; ``v0^2 / 2`` for a record without its
        scene; 0 without an impulse; units of eta p)."""
        scene = self.scene
        if scene is not None:
            return scene.impulse_energy
        return 0.5 * float(self._data.get("impulse", {}).get("velocity", 0.0)) ** 2

    # ---- sizes, numbering, states ------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of moving beads (the scene's ``chain.n`` for a decimated record)."""
        if self.decimated:
            return int(self._data["chain"]["n"])
        return self.x_stored.shape[1]

    @property
    def frames(self) -> int:
        """Number of stored frames."""
        return len(self.time)

    @property
    def status(self) -> str:
        """The run's status (``attrs["status"]``; "" if unknown)."""
        return str(self.attrs.get("status") or "")

    @property
    def contact_numbers(self) -> np.ndarray:
        """Contract numbers of the contacts, the columns of :attr:`closed`
        (:func:`~mdgran.model.chain.contact_numbers`)."""
        return contact_numbers(self.n, self.walls)

    def initial_states(self) -> np.ndarray:
        """The contact states before the first event: all closed, or all open with an initial
        gap (:func:`~mdgran.model.chain.initial_states`)."""
        gap = float(self._data.get("chain", {}).get("initial_gap", 0.0) or 0.0)
        return initial_states(self.n, self.walls, gap)

    def replayed_states(self, times=None) -> np.ndarray:
        """The contact states at ``times`` (default: the frames) rebuilt from the events
        (:func:`~mdgran.model.chain.replay_states`); on a record that stored them, equal to
        :attr:`closed` at the frames."""
        return replay_states(self.initial_states(), self.ev_time, self.ev_contact, self.ev_kind,
                             self.time if times is None else times, self.walls)

    # ---- energy ------------------------------------------------------------------------------
    @property
    def e0(self) -> float:
        """Total energy of the first frame (``eta p``)."""
        return float(self.ledger["total_energy"][0])

    def ledger_scale(self) -> float:
        """The energy ledger errors are measured in (:func:`ledger_scale`)."""
        drive = (bool(self._data.get("pulse", {}).get("amplitude"))
                 or self._data.get("base", {}).get("kind", "none") != "none")
        e_in = self.scene.energy_scale if drive and self.scene is not None else (
            self.impulse_energy)
        return ledger_scale(e_in, self.e0)

    def ledger_error(self, scale: float | None = None) -> np.ndarray:
        """``(total_energy(t) - E0) / scale`` over the frames; ``scale`` defaults to
        :meth:`ledger_scale` (``E_imp``, or ``max(|E0|, 1)`` without an impulse), the scale of
        the driver's ``max_ledger_error`` and of the backends' declared bounds."""
        tot = self.ledger["total_energy"]
        return relative_ledger_error(tot, tot[0], self.ledger_scale() if scale is None else scale)

    @property
    def max_ledger_error(self) -> float:
        """``max_t |E(t) - E0| / E_imp`` (:meth:`ledger_error`; 0 for an empty record)."""
        err = self.ledger_error()
        return float(np.max(np.abs(err))) if len(err) else 0.0

    def potential_energy(self) -> np.ndarray:
        """Contact plus substrate energy per frame (``eta p``)."""
        return self.ledger["contact_energy"] + self.ledger["substrate_energy"]

    # ---- analysis ----------------------------------------------------------------------------
    @cached_property
    def measures(self):
        """The paper's measures of this run, computed once each on first use
        (:class:`~mdgran.output.measures.Measures`)."""
        from .measures import Measures

        return Measures(self)

    def __repr__(self) -> str:
        parts = []
        if self.attrs.get("scene_name"):
            parts.append(f"scene={str(self.attrs['scene_name'])!r}")
        parts.append(f"backend={self.backend!r}")
        if self.status:
            status = self.status
            parts.append(f"status={status if len(status) <= 60 else status[:57] + '...'!r}")
        t = np.asarray(self.time)
        span = f"t=[{float(t[0]):.6g}, {float(t[-1]):.6g}]" if t.size else "t=[]"
        n = self.n if self.decimated or np.ndim(self.x_stored) == 2 else 0
        beads = f" (beads stored: {len(self.bead_ids)})" if self.decimated else ""
        parts += [f"frames={t.size}", f"n={n}{beads}", span, f"events={len(self.ev_time)}"]
        return f"Run({', '.join(parts)})"


def dataset_paths(f) -> list:
    """The path of every dataset of the open HDF5 file ``f`` (sorted), one reached by several
    hard links under each: the time series of an mdgran file share one ``step`` and ``time``,
    and ``particles/beads/position`` is ``particles/chain/position``, which ``visititems``
    lists once."""
    import h5py

    out = []

    def walk(group, prefix, above):
        for name in group:
            if not isinstance(group.get(name, getlink=True), h5py.HardLink):
                continue
            item, path = group[name], prefix + name
            if isinstance(item, h5py.Dataset):
                out.append(path)
            elif isinstance(item, h5py.Group) and item.id not in above:  # no cycles
                walk(item, path + "/", above + [item.id])

    walk(f, "", [f.id])
    return sorted(out)


def unreadable(path) -> str | None:
    """Why the run file ``path`` cannot be read (one line), or None: it opens as HDF5 and holds
    the run's ``/parameters`` with its scene and status (a case file cut short or overwritten
    does not)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            par = f["parameters"]
            par.attrs["scene"], par.attrs["status"]
            f["observables/total_energy/value"].shape
    except (OSError, KeyError, RuntimeError, ValueError) as exc:
        return (str(exc).splitlines() or [type(exc).__name__])[0][:200]
    return None


def read_h5(path) -> Run:
    """Read an mdgran H5MD file back into a :class:`Run` (also ``mdgran.read``).  The contact
    states come from ``/observables/contacts/closed``; a file written without them (an older
    mdgran) gets them rebuilt from its events.  A file written with ``output.bead_stride``
    != 1 (``/particles/chain/id`` lists its beads) gives a decimated record
    (:attr:`Run.bead_ids`, :attr:`Run.x_stored`; :attr:`Run.x` raises), whose contact states
    of every contact are rebuilt from its events (complete in every file)."""
    import h5py

    with h5py.File(path, "r") as f:
        missing = [g for g in ("particles/chain", "events", "parameters") if g not in f]
        missing += [f"observables/{name}" for name in LEDGER_NAMES
                    if f"observables/{name}" not in f and name not in OPTIONAL_TERMS]
        if missing:
            raise ValueError(f"{path}: not an mdgran H5MD file (no /{missing[0]})")
        chain = f["particles/chain"]
        led = {name: f[f"observables/{name}/value"][()] for name in LEDGER_NAMES
               if f"observables/{name}" in f}
        for name in OPTIONAL_TERMS:  # a file of an mdgran before them: 0 at every frame
            led.setdefault(name, np.zeros_like(led["total_energy"]))
        led = {name: led[name] for name in LEDGER_NAMES}
        attrs = {k: (v.decode() if isinstance(v, bytes) else v)
                 for k, v in f["parameters"].attrs.items()}
        bead_ids = chain["id"][()] if "id" in chain else None
        closed = None
        if "observables/contacts/closed/value" in f and bead_ids is None:
            closed = f["observables/contacts/closed/value"][()].astype(bool)
        if "displacement" in chain:
            time = chain["displacement/time"][()]
            x, v = chain["displacement/value"][()], chain["velocity/value"][()]
        else:  # output.bead_stride = 0: no per-bead series
            time = f["observables/total_energy/time"][()]
            x = v = np.zeros((len(time), 0))
        rec = Run(
            time=time, x=x, v=v, bead_ids=bead_ids,
            ledger=led,
            ev_time=f["events/time"][()],
            ev_contact=f["events/contact"][()],
            ev_kind=f["events/kind"][()],
            scene_toml=str(attrs.get("scene", "")),
            backend=str(attrs.get("backend", "")),
            attrs=attrs,
            closed=closed,
        )
    rec.path = str(path)
    return rec
