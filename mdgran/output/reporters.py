"""Reporters: what happens to each frame, kept apart from the stepping (OpenMM's pattern).

The driver (:func:`mdgran.simulation.run`) hands every block of frames to each reporter's
``report_block(block)`` (or every frame and its ledger to ``report(frame, ledger)``), and calls
``close(status)`` once at the end (``status`` is ``"complete"``, ``"ledger-exceeded: ..."``
(the ledger error is above the backend's declared bound), ``"failed: ..."``, or
``"interrupted"``).  This module gathers the package's reporters:

* :class:`~mdgran.output.h5md_writer.H5MDWriter` writes the contract's H5MD file atomically (its
  layout: :mod:`mdgran.output.h5md_layout`; the checkpoints it stores:
  :mod:`mdgran.output.checkpoint`).
* :class:`~mdgran.output.memory_reporter.MemoryReporter` collects a
  :class:`~mdgran.output.run_record.Run` (with the contacts' states per frame).
* :class:`~mdgran.output.progress.ProgressReporter` draws a labelled progress bar on stderr.
"""
from __future__ import annotations

from .h5md_layout import (  # noqa: F401 - the file layout's names, imported from here too
    CHUNK_BYTES, COMPRESSION, CONTACT_DETAIL, CONTACT_SERIES, H5_LIBVER, H5MD_BLOCK,
    H5MD_BUFFER_BYTES, buffer_frames, chunk_shape, stored_bead_count, stored_beads)
from .h5md_writer import H5MDWriter  # noqa: F401
from .memory_reporter import MemoryReporter  # noqa: F401
from .progress import ProgressReporter  # noqa: F401
from .run_environment import software_versions  # noqa: F401
