"""The H5MD writer: a reporter that writes the contract's H5MD file (``docs/output.md``)
atomically, and only writes: the file's layout is :mod:`mdgran.output.h5md_layout`, the
checkpoints' reading and verifying :mod:`mdgran.output.checkpoint`, what is written and when the
driver's (:func:`mdgran.simulation.run`).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from . import checkpoint
from . import h5md_layout as layout
from .h5md_append import append_events, append_rows
from ..backends.base import Events
from ..model.chain import touching_contacts
from .h5md_layout import CONTACT_SERIES, COMPRESSION, H5_LIBVER
from ..rest_blocks import gather_rows
from .run_environment import mpi_ranks_of, mpi_world_size
from .run_record import ledger_terms
from .storage import OutputLock, StorageError, abandon, reason, temporary_path


class H5MDWriter:
    """Writes the contract's H5MD 1.1 layout, frame by frame, atomically: frames go to a
    temporary file beside the target (``NAME.h5.tmp-PID``), renamed onto the requested name
    only when the run completes or fails (a failed run's file holds every frame so far and
    says so in ``/parameters`` attribute ``status``).  An interrupted or killed run leaves
    nothing under the requested name; with checkpoints on, it leaves ``NAME.h5.partial`` to
    resume from.  ``output.bead_stride`` stores every k-th bead (and contact) only, or none;
    ``output.compression`` compresses those series.

    The writer holds ``NAME.lock`` (:class:`~mdgran.output.storage.OutputLock`) from its start to
    its close, so a second run on the same name is refused.  A write the file system refuses
    (full disk, quota) raises :class:`~mdgran.output.storage.StorageError` after the temporary is
    removed; the requested name is never touched.

    Every contact's state per frame is stored (``/observables/contacts/closed``, from each
    frame's ``closed``); ``contacts`` (default: the scene's ``output.contacts``) adds the
    per-contact time series ``/observables/contacts/{compression,force}``
    (:data:`~mdgran.output.h5md_layout.CONTACT_SERIES`), as each block holds them (the driver
    computes them once per block: :meth:`~mdgran.backends.base.Frames.contact_series`).  The
    writer computes nothing: the chain's numbering comes from ``model`` (the backend's
    :class:`~mdgran.model.chain.ChainModel`), the checkpoints from the driver (:meth:`checkpoint`).
    ``/parameters`` attribute ``mpi_ranks`` records the number of MPI ranks the run was
    split over (:func:`~mdgran.output.run_environment.mpi_ranks_of` of ``backend``)."""

    mpi_world_size = staticmethod(mpi_world_size)
    mpi_ranks_of = staticmethod(mpi_ranks_of)

    def __init__(self, path, scene, backend_name: str, positions: bool | None = None,
                 stats_source=None, checkpoint_every: float | None = None,
                 resume: bool = False, contacts: bool | None = None, backend=None, *, model):
        """``checkpoint_every`` (seconds of wall time, or None) makes the run resumable: the
        file is filled under the fixed name ``NAME.h5.partial``, where :meth:`checkpoint`
        stores the backend's state at the last written frame (:mod:`mdgran.output.checkpoint`), and
        which an interrupted or killed run leaves behind; ``resume=True`` verifies it
        (:func:`~mdgran.output.checkpoint.resume`: backend, scene, checksums), drops the frames
        written after it, and gives what the run goes on from as ``resumed``
        (:class:`~mdgran.output.checkpoint.Resumed`).  Without ``resume``, an existing
        ``NAME.h5.partial`` is refused rather than overwritten
        (:class:`~mdgran.output.checkpoint.CheckpointError`)."""
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
        self.scene, self.model, self.backend = scene, model, backend
        out = scene.output
        self.positions = out.positions if positions is None else positions
        self.contacts = bool(out.contacts) if contacts is None else bool(contacts)
        self.stride = int(out.bead_stride)
        self.filters = COMPRESSION[out.compression]
        self.bead_ids = layout.stored_beads(int(scene.chain.n), self.stride)
        self._beads = slice(0, int(scene.chain.n), self.stride or 1)  # of x, v
        self._cols = layout.stored_contacts(model.n_contacts, self.stride)
        self.mpi_ranks = None  # known once the backend has started (first frame)
        self.stats_source = stats_source
        self.f = None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.lock = OutputLock(self.path)
        # (step, time, x, v, ledger, per-contact series, moved) of each block not yet written,
        # and its events (Events)
        self._buf, self._buffered, self._events = [], 0, []
        self._frames, self._last_step = 0, None
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
                self._guard(self._init_file)
            self._block = layout.buffer_frames(self.frame_bytes())
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

        self.resumed, meta, self._digest = checkpoint.resume(
            self.tmp, backend=self.backend_name, scene_toml=self.scene.to_toml())
        self._frames = int(meta["frames"])
        self.f = self._guard(h5py.File, self.tmp, "r+")
        self._guard(self._open_existing, int(meta["events"]))

    def frame_bytes(self) -> int:
        """Bytes of per-bead and per-contact values one frame adds to the buffer
        (:func:`~mdgran.output.h5md_layout.frame_bytes`)."""
        return layout.frame_bytes(len(self.bead_ids),
                                  len(range(*self._cols.indices(self.model.n_contacts))),
                                  self.positions, self.contacts)

    def _open_existing(self, events: int):
        self._series, self._ev, self.terms = layout.open_series(self.f, self._frames, events)
        self.positions = "position" in self.f["particles/chain"]
        self.contacts = "contacts/compression" in self.f["observables"]
        if self.positions:
            self._rest, self._pos_scale, self._t_scale = layout.position_scales(
                self.scene.scales, self.bead_ids)

    def _init_file(self):
        layout.write_header(self.f, self.scene, self.backend_name,
                            self.mpi_ranks_of(self.backend), self.mpi_world_size())
        self.terms = ledger_terms(self.scene)
        self._series = layout.create_series(
            self.f, self.scene, self.model, self.terms, self.bead_ids, self.stride,
            self.positions, self.contacts, self.filters)
        if "position" in self._series:
            self._rest, self._pos_scale, self._t_scale = layout.position_scales(
                self.scene.scales, self.bead_ids)
        self._ev = layout.create_events(self.f)

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
        self._events.append(block.events)
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

    def _moved_columns(self):
        """:func:`~mdgran.output.h5md_layout.moved_columns` of the buffered blocks."""
        m = self.model
        return layout.moved_columns([b[6] for b in self._buf],
                                    lambda lo, hi: touching_contacts(m.n, m.walls, lo, hi),
                                    self.stride)

    def _flush_beads(self, steps, times, within=None):
        """Append the buffered frames' per-bead series (the stored beads only)."""
        chain = "particles/chain"
        x = gather_rows([b[2] for b in self._buf], within)
        v = gather_rows([b[3] for b in self._buf], within)
        append_rows(f"{chain}/displacement", self._series["displacement"], steps, times, x,
                    self._digest, within)
        append_rows(f"{chain}/velocity", self._series["velocity"], steps, times, v,
                    self._digest, within)
        if self.positions:
            pos = np.zeros(x.shape + (3,))
            pos[..., 0] = self._rest + x * self._pos_scale
            append_rows(f"{chain}/position", self._series["position"], steps,
                        times * self._t_scale, pos, self._digest)

    def _flush(self):
        if self._buf:
            buf = self._buf
            steps = np.concatenate([b[0] for b in buf]).astype(np.int64, copy=False)
            times = np.concatenate([b[1] for b in buf]).astype(float, copy=False)
            beads, contacts = self._moved_columns()
            if "displacement" in self._series:  # not with output.bead_stride = 0
                self._flush_beads(steps, times, beads)
            for name in self.terms:
                append_rows(f"observables/{name}", self._series[name], steps, times,
                            np.concatenate([b[4][name] for b in buf]), self._digest)
            for name in CONTACT_SERIES:
                key = f"contacts/{name}"
                if key in self._series:
                    rows = np.concatenate([b[5][name] for b in buf])
                    values = rows.astype(np.int8)[:, self._cols] if name == "closed" else rows
                    append_rows(f"observables/{key}", self._series[key], steps, times, values,
                                self._digest, contacts if name == "closed" else None)
            self._frames += self._buffered
            self._buf, self._buffered = [], 0
        events, self._events = Events.join(self._events), []
        if len(events):
            append_events(self._ev, events, self._digest)

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
        self._series, self._ev = {}, {}
