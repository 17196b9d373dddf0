"""Column blocks of a long series that hold anything but the fill value: output that grows
with what moved.

A long chain struck at one end is mostly at rest: beyond the pulse its displacements and
velocities are exact zeros and its contacts sit in their rest state, frame after frame.  The
writer (:class:`mdgran.output.h5md_writer.H5MDWriter`) stores a per-bead or per-contact series of
more than :data:`BLOCK` columns in HDF5 chunks of one frame by :data:`BLOCK` columns and writes only
the blocks that hold a value other than the dataset's fill value (0, or the contacts' rest
state).  HDF5 reads a chunk that was never written as its fill value, so every reader sees
every value, bitwise as if it had been written; the file, the writer's time and the
checkpoint's running checksum (:class:`mdgran.output.checkpoint.DataDigest`, which hashes the same
blocks) grow with the beads that moved, not with the chain.

"Differs" is bitwise: ``-0.0`` differs from a fill of ``0.0`` and is written.
"""
from __future__ import annotations

import numpy as np

#: columns of one chunk of a long per-bead or per-contact series (32 KiB of doubles): the
#: grain at which resting beads are left out
BLOCK = 4096


def sparse_width(ds) -> int | None:
    """The block width of an HDF5 dataset stored by column blocks (chunks of one row and
    fewer columns than the dataset has), else None."""
    chunks = ds.chunks
    if ds.ndim != 2 or chunks is None or chunks[0] != 1 or chunks[1] >= ds.shape[1]:
        return None
    return int(chunks[1])


def differs(rows: np.ndarray, fill) -> np.ndarray:
    """``[F, n]`` bool: the values of ``rows`` [F, n] whose bits are not those of ``fill``."""
    rows = np.ascontiguousarray(rows)
    if rows.dtype.kind == "f":
        bits = rows.view(f"u{rows.dtype.itemsize}")
        return bits != np.asarray(fill, dtype=rows.dtype).view(bits.dtype)
    return rows != np.asarray(fill).astype(rows.dtype)


def block_mask(rows: np.ndarray, width: int, fill) -> np.ndarray:
    """``[F, ceil(n / width)]`` bool: which blocks of ``width`` columns of each row of ``rows``
    hold a value other than ``fill``."""
    d = differs(rows, fill)
    if d.shape[1] == 0:
        return np.zeros((d.shape[0], 0), dtype=bool)
    return np.logical_or.reduceat(d, np.arange(0, d.shape[1], width), axis=1)


def column_runs(blocks: np.ndarray, width: int, n: int) -> list:
    """``[(c0, c1), ...]``: the column ranges of the blocks set in ``blocks`` [nb] (one row of
    :func:`block_mask`, or their ``any``), adjacent blocks joined, the last cut at ``n``."""
    idx = np.flatnonzero(blocks)
    if not len(idx):
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate(([idx[0]], idx[breaks + 1]))
    ends = np.concatenate((idx[breaks], [idx[-1]]))
    return [(int(a) * width, min(n, (int(b) + 1) * width)) for a, b in zip(starts, ends)]


#: arrays of at least this many bytes are mapped fresh by :func:`lazy_zeros`
LAZY_BYTES = 1 << 20


def lazy_zeros(shape, dtype=float) -> np.ndarray:
    """``np.zeros(shape, dtype)`` whose memory costs what is written to it: a large one is a
    fresh anonymous memory map of small pages (mapped zero as they are first touched, and
    unmapped when the array goes).  ``np.zeros`` of a large array costs a ``memset`` of all of
    it once the C library reuses freed memory for it (glibc's adaptive mmap threshold): ~1 ms
    per frame of a 1e6-bead chain."""
    import mmap

    dtype = np.dtype(dtype)
    size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if size < LAZY_BYTES:
        return np.zeros(shape, dtype)
    buf = mmap.mmap(-1, size)
    if hasattr(mmap, "MADV_NOHUGEPAGE"):  # a first touch maps 4 kB, not 2 MB to be zeroed
        buf.madvise(mmap.MADV_NOHUGEPAGE)
    return np.frombuffer(buf, dtype=dtype).reshape(shape)


def block_mask_within(rows: np.ndarray, width: int, fill, within) -> np.ndarray:
    """:func:`block_mask` of ``rows``, looked for in the blocks that meet its columns
    ``within = (c0, c1)`` only (the others are taken to hold ``fill``); None: all."""
    if within is None:
        return block_mask(rows, width, fill)
    nb = -(-rows.shape[1] // width)
    mask = np.zeros((len(rows), nb), dtype=bool)
    j0, j1 = within[0] // width, -(-within[1] // width)
    if j0 < j1:
        mask[:, j0:j1] = block_mask(rows[:, j0 * width:j1 * width], width, fill)
    return mask


def gather_rows(parts, within) -> np.ndarray:
    """The rows of ``parts`` (arrays ``[F_k, n]``) together; with ``within = (c0, c1)`` (the
    columns outside hold zeros) only those columns are copied, into :func:`lazy_zeros` that
    cost nothing until written."""
    if within is None:
        return np.concatenate(parts)
    out = lazy_zeros((sum(len(p) for p in parts), parts[0].shape[1]))
    k = 0
    for p in parts:
        out[k:k + len(p), within[0]:within[1]] = p[:, within[0]:within[1]]
        k += len(p)
    return out


def write_blocks(ds, k0: int, rows: np.ndarray, width: int, within=None) -> np.ndarray:
    """Write ``rows`` [F, n] as rows ``k0 .. k0 + F - 1`` of the HDF5 dataset ``ds`` stored by
    blocks of ``width`` columns (resized to hold them): only the column runs of the blocks
    that hold a value other than its fill value (:func:`block_mask_within`); returns that
    mask ``[F, blocks]``."""
    ds.resize(k0 + len(rows), axis=0)
    mask = block_mask_within(rows, width, ds.fillvalue, within)
    for c0, c1 in column_runs(mask.any(axis=0), width, rows.shape[1]):
        ds[k0:k0 + len(rows), c0:c1] = rows[:, c0:c1]
    return mask
