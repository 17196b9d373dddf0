"""The H5MD file's layout: which series it holds, how they are chunked and buffered, and the
groups and datasets of a new file or of one reopened to go on (``docs/output.md``).

Functions of the scene's output settings and the chain's numbering only: the writer
(:class:`~mdgran.output.h5md_writer.H5MDWriter`) fills what they create.
"""
from __future__ import annotations

import json
import os

import numpy as np

from ..rest_blocks import BLOCK
from .run_record import LEDGER_NAMES
from .run_environment import software_versions

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
#: the per-bead series under /particles/chain
BEAD_SERIES = ("displacement", "velocity", "position")
SERIES_KEYS = ("step", "time", "value")
EVENT_FIELDS = (("time", "f8"), ("contact", "i8"), ("kind", "i1"))


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


def frame_bytes(beads: int, contacts: int, positions: bool, detail: bool) -> int:
    """Bytes of per-bead and per-contact values one frame adds to the writer's buffer, with
    ``beads`` and ``contacts`` stored: x and v, their positions at a flush (3 values,
    ``positions``), 1 byte per contact for its state and 16 more with ``detail``
    (``output.contacts``)."""
    return (8 * (2 + (3 if positions else 0)) * beads + (17 if detail else 1) * contacts)


def stored_beads(n: int, stride: int) -> np.ndarray:
    """1-based numbers of the beads whose series a file stores (``output.bead_stride``):
    ``1, 1 + k, ...`` up to ``n`` for stride ``k >= 1``; none for stride 0."""
    return np.arange(1, n + 1, stride, dtype=np.int64) if stride else np.zeros(0, np.int64)


def stored_bead_count(n: int, stride: int) -> int:
    """``len(stored_beads(n, stride))`` without building the array: ``ceil(n / stride)``."""
    return len(range(0, n, stride)) if stride else 0


def stored_contacts(n_contacts: int, stride: int) -> slice:
    """Stored columns of the per-contact series: every ``stride``-th contact from the first
    (none for stride 0)."""
    return slice(0, n_contacts if stride else 0, stride or 1)


def moved_columns(ranges, contact_range, stride: int):
    """``(beads, contacts)``: the stored columns of the per-bead and per-contact series
    outside which buffered frames hold the fill values, given each block's bead range
    ``ranges`` (:attr:`~mdgran.backends.base.Frames.moved`) and ``contact_range(lo, hi)``, the
    contacts that touch the beads ``lo .. hi - 1``; ``(None, None)`` if any range is None."""
    if any(r is None for r in ranges):
        return None, None
    lo, hi = min(r[0] for r in ranges), max(r[1] for r in ranges)
    if lo >= hi:
        return (0, 0), (0, 0)
    c0, c1 = contact_range(lo, hi)
    k = stride or 1
    return (-(-lo // k), -(-hi // k)), (-(-c0 // k), -(-c1 // k))


def position_scales(scales, bead_ids) -> tuple:
    """``(rest, length, time)``: the stored beads' rest positions (nm, or ``p`` units without
    ``scales``), and the factors from ``p`` to nm and from ``1/q`` to ps (1 without)."""
    if scales is None:
        return 1.0 * bead_ids, 1.0, 1.0
    return scales.diameter * 1e9 * bead_ids, scales.p * 1e9, scales.time * 1e12


def contact_names(detail: bool, obs=None) -> list:
    """The per-contact series a file holds: ``closed`` always (unless ``obs``, an existing
    file's observables, lacks it: a checkpoint of an older mdgran), and
    :data:`CONTACT_DETAIL` with ``detail`` (``output.contacts``)."""
    names = [name for name in CONTACT_SERIES if name not in CONTACT_DETAIL or detail]
    return names if obs is None else [name for name in names if f"contacts/{name}" in obs]


def make_series(parent, name, shape, dtype="f8", filters=None, clock=None, fill=0) -> dict:
    """A H5MD time series ``name`` with frames of ``shape``: ``step``, ``time`` and a
    ``value`` chunked by :func:`chunk_shape` whose fill value (what a chunk never written
    reads as: :mod:`mdgran.rest_blocks`) is ``fill``, with the h5py ``filters``
    (:data:`COMPRESSION`) if given.  ``clock``: the ``step`` and ``time`` of a series made
    before, shared by HDF5 hard links (as H5MD allows: written once per flush); None:
    datasets of its own."""
    g = parent.create_group(name)
    if clock is None:
        clock = {k: g.create_dataset(k, (0,), maxshape=(None,), dtype=dt, chunks=(4096,))
                 for k, dt in (("step", "i8"), ("time", "f8"))}
    else:
        g["step"], g["time"] = clock["step"], clock["time"]
    value = g.create_dataset("value", (0,) + shape, maxshape=(None,) + shape, dtype=dtype,
                             chunks=chunk_shape(shape, np.dtype(dtype).itemsize),
                             fillvalue=fill, **(filters or {}))
    return {**clock, "value": value}


def write_header(f, scene, backend_name: str, mpi_ranks: int, mpi_world_size: int):
    """``/h5md`` (version, author, creator) and ``/parameters`` (the scene, the backend, the
    versions, the units, ``status = "running"``, the scales, the MPI job)."""
    h5 = f.create_group("h5md")
    h5.attrs["version"] = np.array([1, 1], dtype=np.int32)
    h5.create_group("author").attrs["name"] = os.environ.get("USER", "mdgran user")
    cr = h5.create_group("creator")
    vers = software_versions()
    cr.attrs["name"] = "mdgran"
    cr.attrs["version"] = vers["mdgran"]
    par = f.create_group("parameters")
    par.attrs["scene"] = scene.to_toml()
    par.attrs["scene_name"] = scene.name
    par.attrs["backend"] = backend_name
    par.attrs["mdgran_version"] = vers["mdgran"]
    par.attrs["versions"] = json.dumps(vers)
    par.attrs["units"] = ("nondimensional (docs/physics.md section 1): length p, force"
                          " eta = pi R w, time 1/q, energy eta p, bead mass 1")
    par.attrs["status"] = "running"
    if scene.scales is not None:
        par.attrs["scales"] = json.dumps(scene.scales.as_dict())
    par.attrs["mpi_ranks"] = np.int64(mpi_ranks)  # again at the end
    par.attrs["mpi_world_size"] = np.int64(mpi_world_size)


def create_series(f, scene, model, terms, bead_ids, stride, positions, detail,
                  filters) -> dict:
    """Create every time series of a new file: the stored beads' displacement and velocity
    (and positions in nm, linked as ``/particles/beads``), the ledger ``terms`` and the
    stored contacts' series (:func:`contact_names`, numbered by ``model``, the chain's
    :class:`~mdgran.model.chain.ChainModel`); returns ``{name: {"step", "time", "value"}}``.  Every
    series but the positions shares the first series' step and time."""
    series, shared = {}, {}

    def make(parent, name, shape, dtype="f8", filters=None, fill=0):
        s = make_series(parent, name, shape, dtype, filters=filters, clock=shared.get("clock"),
                        fill=fill)
        shared.setdefault("clock", {k: s[k] for k in ("step", "time")})
        return s

    chain = f.create_group("particles/chain")
    n = len(bead_ids)
    if stride != 1:
        chain.attrs["bead_stride"] = np.int64(stride)
        ids = chain.create_dataset("id", data=bead_ids)
        ids.attrs["description"] = ("1-based number of the bead of each column of the "
                                    "per-bead series (output.bead_stride); absent: every "
                                    "bead 1..n")
    for name in ("displacement", "velocity")[:2 if n else 0]:
        series[name] = make(chain, name, (n,), filters=filters)
    if positions and n:
        _create_positions(f, chain, scene.scales, series, n, filters)
    obs = f.create_group("observables")
    for name in terms:
        series[name] = make(obs, name, ())
    if not stride:  # no per-contact series
        return series
    g = obs.create_group("contacts")
    g.attrs["contact"] = np.asarray(model.contact_numbers,
                                    dtype=np.int64)[stored_contacts(model.n_contacts, stride)]
    g.attrs["numbering"] = ("value column j is contact number contact[j]; contact i joins "
                            "bead i-1 and bead i (beads 0, n+1: walls), as in /events")
    for name in contact_names(detail):
        dtype, unit, doc = CONTACT_SERIES[name]
        fill = int(model.gap <= 0) if name == "closed" else 0  # the initial state
        s = make(g, name, (len(g.attrs["contact"]),), dtype, filters=filters, fill=fill)
        if unit:
            s["value"].attrs["unit"] = unit
        s["value"].attrs["description"] = doc
        series[f"contacts/{name}"] = s
    if detail:
        g["force"].attrs["damping"] = float(model.damping)
        g["force"].attrs["includes_damping"] = np.int8(bool(model.damping))
    return series


def _create_positions(f, chain, scales, series, n, filters):
    """The stored beads' positions (a series with its own clock, in nm and ps with
    ``scales``) and the standard H5MD view ``/particles/beads`` for generic readers
    (MDAnalysis opens the first particle group and reads its "velocity" as 3-vectors, which
    chain/velocity is not): hard links, not copies."""
    box = chain.create_group("box")
    box.attrs["dimension"] = np.int32(3)
    box.attrs["boundary"] = np.array([b"none"] * 3)
    series["position"] = make_series(chain, "position", (n, 3), filters=filters)
    if scales is not None:
        series["position"]["value"].attrs["unit"] = "nm"
        series["position"]["time"].attrs["unit"] = "ps"
    beads = f.create_group("particles/beads")
    beads["box"] = box
    beads["position"] = chain["position"]


def create_events(f) -> dict:
    """The ``/events`` group: ``{"time", "contact", "kind"}`` datasets, empty."""
    ev = f.create_group("events")
    out = {k: ev.create_dataset(k, (0,), maxshape=(None,), dtype=dt, chunks=(4096,))
           for k, dt in EVENT_FIELDS}
    ev.attrs["kind"] = "1 = close (snap-to-contact), 0 = open (snap-off)"
    ev.attrs["contact"] = "contact i joins bead i-1 and bead i (beads 0, n+1: walls)"
    return out


def open_series(f, frames: int, events: int) -> tuple:
    """``(series, events, terms)`` of an existing file ``f``, opened to go on: every time
    series it holds (as :func:`create_series` gives them) and its event datasets, cut back
    to the first ``frames`` frames and ``events`` events; ``terms``: the ledger series it
    holds."""
    chain, obs = f["particles/chain"], f["observables"]
    series = {name: {k: chain[f"{name}/{k}"] for k in SERIES_KEYS}
              for name in BEAD_SERIES if name in chain}
    terms = tuple(name for name in LEDGER_NAMES if name in obs)
    for name in terms:
        series[name] = {k: obs[f"{name}/{k}"] for k in SERIES_KEYS}
    for name in contact_names("contacts/compression" in obs, obs):
        series[f"contacts/{name}"] = {k: obs[f"contacts/{name}/{k}"] for k in SERIES_KEYS}
    for s in series.values():
        for ds in s.values():
            ds.resize(frames, axis=0)
    ev = {k: f[f"events/{k}"] for k, _ in EVENT_FIELDS}
    for ds in ev.values():
        ds.resize(events, axis=0)
    return series, ev, terms


def series_paths(f) -> list:
    """The paths of the time-series groups the file ``f`` holds, in the order the writer
    appends them: per bead, the ledger (``/observables``), per contact."""
    chain = [f"particles/chain/{name}" for name in BEAD_SERIES if f"particles/chain/{name}" in f]
    contacts = [f"observables/contacts/{name}" for name in CONTACT_SERIES
                if f"observables/contacts/{name}" in f]
    terms = [f"observables/{name}" for name in LEDGER_NAMES if f"observables/{name}" in f]
    return chain + terms + contacts
