"""Appending rows to the H5MD file's time series and events, each dataset's rows hashed as
they are appended when a checkpoint's running digest is kept
(:class:`~mdgran.output.checkpoint.DataDigest`)."""
from __future__ import annotations

import numpy as np

from ..backends.base import Events
from ..rest_blocks import sparse_width, write_blocks


def append_rows(path: str, series: dict, steps, times, values, digest=None, within=None):
    """Append ``steps``, ``times`` and ``values`` [F, ...] to ``series`` (``{"step", "time",
    "value"}`` datasets of the group ``path``); a ``step`` or ``time`` shared with a series
    appended before in this flush (:func:`~mdgran.output.h5md_layout.make_series`) already has
    them.  A ``value`` stored by column blocks gets only its blocks that differ from the fill
    value (:func:`~mdgran.rest_blocks.write_blocks`), looked for in its columns ``within =
    (c0, c1)`` if given (the others hold the fill value)."""
    k0 = series["value"].shape[0]
    k1 = k0 + len(steps)
    for key, data in (("step", steps), ("time", times), ("value", values)):
        ds = series[key]
        width = sparse_width(ds) if key == "value" else None
        if width is None:
            if ds.shape[0] != k1:
                ds.resize(k1, axis=0)
                ds[k0:k1] = data
            if digest is not None:
                digest.update(f"{path}/{key}", data, ds.dtype)
            continue
        data = np.asarray(data, dtype=ds.dtype)
        mask = write_blocks(ds, k0, data, width, within)
        if digest is not None:
            if digest.blocks:
                digest.update_blocks(f"{path}/{key}", data, width, mask)
            else:
                digest.update(f"{path}/{key}", data, ds.dtype)


def append_events(datasets: dict, events, digest=None):
    """Append ``events`` (:class:`~mdgran.backends.base.Events`, or a sequence of
    :class:`~mdgran.backends.base.Event` s) to the ``/events`` ``datasets`` (``{"time",
    "contact", "kind"}``)."""
    events = Events.of(events)
    k0 = datasets["time"].shape[0]
    for key in ("time", "contact", "kind"):
        vals = getattr(events, key)
        ds = datasets[key]
        ds.resize(k0 + len(events), axis=0)
        ds[k0:] = vals
        if digest is not None:
            digest.update(f"events/{key}", vals, ds.dtype)
