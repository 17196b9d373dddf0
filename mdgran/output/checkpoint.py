"""Checkpoints: the backend's state at the last written frame, kept in the run's temporary
H5MD file ``NAME.partial`` so that an interrupted run resumes bitwise identically.

The state is opaque here: a flat dict from the backend's ``checkpoint_state()`` whose values
are arrays (stored as datasets) or JSON scalars (stored in the ``meta`` attribute); only
``i_out`` (index of the last frame) is common to every backend.  A checkpoint is the group
``/checkpoint`` with one JSON attribute ``meta``::

    {"backend": "reference", "scene_sha256": ..., "frames": 402, "events": 57,
     "scalars": {...}, "arrays": [...], "state_sha256": ..., "data_sha256": {path: ...}}

``data_sha256`` holds the SHA-256 of the first ``frames`` rows of every frame dataset (and of
the first ``events`` events): the frames the checkpoint continues.  A dataset stored by column
blocks (:mod:`mdgran.rest_blocks`: a long chain's per-bead series) is hashed row by row over its
blocks that differ from the fill value, each with its index (``"data_digest": "blocks"``), so
that the running hash costs what the writer writes; a checkpoint without that key hashed every
value.  :func:`load` refuses with
one line (:class:`CheckpointError`) a checkpoint of another backend or scene, a file that is
not HDF5, and any checksum that does not match what is stored: a damaged checkpoint is never
resumed, and it is left as it was.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import numpy as np

GROUP = "checkpoint"
ROWS = 4096  # rows hashed at a time when a checkpoint is verified ...
READ_BYTES = 64 << 20  # ... and at most this many bytes of them
#: ``meta["data_digest"]`` of a checkpoint whose column-block datasets are hashed by blocks
BLOCKS = "blocks"
EMPTY = hashlib.sha256().hexdigest()


class CheckpointError(ValueError):
    """A checkpoint that cannot be resumed: one line saying why (the file is kept)."""


def scene_digest(scene_toml: str) -> str:
    return hashlib.sha256(scene_toml.encode("utf-8")).hexdigest()


def state_digest(scalars: dict, arrays: dict) -> str:
    """SHA-256 of a state: its scalars (as sorted JSON), then each array's dtype, shape and
    bytes, in name order."""
    h = hashlib.sha256(json.dumps(scalars, sort_keys=True).encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


class DataDigest:
    """Running SHA-256 of datasets that only grow by appended rows: hashing the rows as they
    are appended gives the same digest as hashing the dataset's first rows at once.

    A dataset stored by column blocks (:func:`mdgran.rest_blocks.sparse_width`) is hashed by
    :meth:`update_blocks`: per row, each block holding a value other than the fill value, as
    its index then its bytes, then a row mark; blocks of fill values (never written) cost
    nothing."""

    ROW = b"\x00row"

    def __init__(self, blocks: bool = True):
        self._h = {}
        self.blocks = blocks  # column-block datasets hashed by blocks (False: a resumed
        #                       checkpoint that hashed every value goes on doing so)

    def update(self, path: str, rows, dtype):
        h = self._h.setdefault(path, hashlib.sha256())
        h.update(np.ascontiguousarray(rows, dtype=dtype).tobytes())

    def update_blocks(self, path: str, rows, width: int, mask):
        """Hash ``rows`` [F, n] by blocks of ``width`` columns, those set in ``mask``
        [F, blocks] (:func:`mdgran.rest_blocks.block_mask`)."""
        h = self._h.setdefault(path, hashlib.sha256())
        for r in range(len(rows)):
            for j in np.flatnonzero(mask[r]).tolist():
                h.update(j.to_bytes(8, "little"))
                h.update(np.ascontiguousarray(rows[r, j * width:(j + 1) * width]).tobytes())
            h.update(self.ROW)

    def hexdigests(self) -> dict:
        return {path: h.hexdigest() for path, h in self._h.items()}

    @classmethod
    def of_file(cls, f, counts: dict, blocks: bool = False) -> "DataDigest":
        """The digest of the first ``counts[path]`` rows of each dataset ``f[path]``; with
        ``blocks``, column-block datasets hashed by blocks (:meth:`update_blocks`)."""
        from ..rest_blocks import block_mask, sparse_width

        d = cls(blocks)
        for path, k in counts.items():
            ds = f[path]
            d._h[path] = hashlib.sha256()
            width = sparse_width(ds) if blocks else None
            row_bytes = ds.dtype.itemsize * int(np.prod(ds.shape[1:], dtype=np.int64))
            step = max(1, min(ROWS, READ_BYTES // max(1, row_bytes)))
            for i in range(0, k, step):
                rows = ds[i:min(k, i + step)]
                if width is None:
                    d.update(path, rows, ds.dtype)
                else:
                    d.update_blocks(path, rows, width, block_mask(rows, width, ds.fillvalue))
        return d


def split_state(state: dict):
    arrays = {k: np.asarray(v) for k, v in state.items() if isinstance(v, np.ndarray)}
    scalars = {k: (v.item() if isinstance(v, np.generic) else v)
               for k, v in state.items() if k not in arrays}
    return scalars, arrays


def save(f, state: dict, *, backend: str, scene_toml: str, frames: int, events: int,
         data: DataDigest):
    """Replace ``f``'s checkpoint by ``state`` (``data``: the frame datasets' digest)."""
    scalars, arrays = split_state(state)
    if GROUP in f:
        del f[GROUP]
    g = f.create_group(GROUP)
    for k, a in arrays.items():
        g.create_dataset(k, data=a)
    meta = {"backend": backend, "scene_sha256": scene_digest(scene_toml), "frames": int(frames),
            "events": int(events), "scalars": scalars, "arrays": sorted(arrays),
            "state_sha256": state_digest(scalars, arrays), "data_sha256": data.hexdigests()}
    if data.blocks:
        meta["data_digest"] = BLOCKS
    g.attrs["meta"] = json.dumps(meta)


@dataclass(frozen=True)
class Resumed:
    """What a run resumed from a checkpoint goes on from: the backend's ``state`` (handed
    back to :meth:`~mdgran.backends.base.Backend.blocks`), the first frame's total energy
    ``e0``, the largest ``|E - E0|`` over the frames before it (``max_error``, units eta p)
    and the largest ``|ledger term|`` (``term_max``: the round-off floor's scale)."""

    state: dict
    e0: float
    max_error: float
    term_max: float


def resumed(state: dict, ledger: dict) -> Resumed:
    """:class:`Resumed` from the checkpoint's ``state`` and the ledger series written before
    it (``{term: [frames] array}``, ``total_energy`` among them)."""
    tot = np.asarray(ledger["total_energy"], dtype=float)
    if not len(tot):
        return Resumed(state, float("nan"), 0.0, 0.0)
    return Resumed(state, float(tot[0]), float(np.max(np.abs(tot - tot[0]))),
                   max(float(np.max(np.abs(np.asarray(v)))) for v in ledger.values()))


def resume(path, *, backend: str, scene_toml: str) -> tuple[Resumed, dict, DataDigest]:
    """Verify the checkpoint in the H5MD file ``path`` (:func:`load`, read-only) and return
    ``(resumed, meta, digest)``: what the run goes on from (:class:`Resumed`, for the
    driver), and what the writer goes on with: ``meta["frames"]`` and ``meta["events"]``, the
    frames and events the checkpoint continues, and ``digest``, their running hashes.
    Raises :class:`CheckpointError`."""
    state, meta, digest = load(path, backend=backend, scene_toml=scene_toml,
                               counts=lambda meta: series_rows(path, meta))
    return resumed(state, ledger_before(path, int(meta["frames"]))), meta, digest


def series_rows(path, meta) -> dict:
    """Dataset path -> rows that a checkpoint with ``meta`` continues (checksummed): every
    time series' step, time and value (:func:`~mdgran.output.h5md_layout.series_paths`) and the
    events."""
    import h5py

    from .h5md_layout import series_paths

    with h5py.File(path, "r") as f:
        groups = series_paths(f)
    rows = {f"{g}/{k}": int(meta["frames"]) for g in groups for k in ("step", "time", "value")}
    rows.update({f"events/{k}": int(meta["events"]) for k in ("time", "contact", "kind")})
    return rows


def ledger_before(path, frames: int) -> dict:
    """``{term: [frames] array}``: the ledger series of the first ``frames`` frames of the
    H5MD file ``path`` (the terms it holds)."""
    import h5py

    from .run_record import LEDGER_NAMES

    with h5py.File(path, "r") as f:
        obs = f["observables"]
        return {name: obs[f"{name}/value"][:frames] for name in LEDGER_NAMES if name in obs}


def has_checkpoint(path) -> bool:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return GROUP in f
    except (OSError, RuntimeError):
        return False


def load(path, *, backend: str, scene_toml: str, counts) -> tuple[dict, dict, DataDigest]:
    """Read and verify the checkpoint in the file ``path``; returns ``(state, meta, digest)``
    where ``digest`` continues the frame datasets' running hashes.  ``counts(meta)`` gives
    ``{dataset path: rows the checkpoint continues}``.  Raises :class:`CheckpointError`."""
    import h5py

    try:
        f = h5py.File(path, "r")
    except (OSError, RuntimeError) as exc:
        raise CheckpointError(f"{path} is not a readable HDF5 file ({_first_line(exc)}); it "
                              "was kept: delete it to start afresh") from None
    try:
        with f:
            if GROUP not in f:
                raise CheckpointError(f"{path} holds no checkpoint (the run stopped before its "
                                      "first); delete it to start afresh")
            g = f[GROUP]
            meta = json.loads(g.attrs["meta"])
            if meta.get("backend") != backend:
                raise CheckpointError(f"{path} is a checkpoint of backend "
                                      f"{meta.get('backend')!r}, not {backend!r}: resume it on "
                                      f"{meta.get('backend')!r}, or delete it to start afresh")
            if meta.get("scene_sha256") != scene_digest(scene_toml):
                raise CheckpointError(f"{path} holds a run of another scene; delete it or use "
                                      "another output name")
            arrays = {k: g[k][()] for k in meta["arrays"]}
            if state_digest(meta["scalars"], arrays) != meta["state_sha256"]:
                raise CheckpointError(f"{path}: the checkpoint's state does not match its "
                                      "checksum (the file is damaged); it was kept")
            read_structure(f)
            want = counts(meta)
            for p, k in want.items():
                if p not in f or f[p].shape[0] < k:
                    raise CheckpointError(f"{path}: {p} holds fewer rows than the checkpoint's "
                                          f"{k} (the file is damaged); it was kept")
            digest = DataDigest.of_file(f, want, blocks=meta.get("data_digest") == BLOCKS)
            stored = meta["data_sha256"]  # a dataset never appended to has the empty digest
            bad = sorted(p for p, h in digest.hexdigests().items() if stored.get(p, EMPTY) != h)
            if bad:
                raise CheckpointError(f"{path}: the stored frames do not match the checkpoint's "
                                      f"checksum ({', '.join(bad[:3])}; the file is damaged); "
                                      "it was kept")
    except CheckpointError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
        raise CheckpointError(f"{path}: the checkpoint cannot be read ({_first_line(exc)}); "
                              "it was kept: delete it to start afresh") from None
    return {**meta["scalars"], **arrays}, meta, digest


def read_structure(f):
    """Open every group and dataset of the HDF5 file ``f`` and read every attribute: a damaged
    object header or attribute raises here (h5py checks their checksums), so that a resume
    refuses the file before it runs, not when the writer reaches that object at the end (a
    byte flipped in ``/parameters``' header crashed the finished run with a traceback)."""
    def touch(obj):
        for key in obj.attrs:
            obj.attrs[key]

    touch(f)
    f.visititems(lambda name, obj: touch(obj))


def _first_line(exc) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0][:200]
