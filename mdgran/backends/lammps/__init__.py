"""The LAMMPS backend, in one room: :mod:`~mdgran.backends.lammps.backend` (the
:class:`LammpsBackend`, which sets up ``chain.in`` and steps it), :mod:`~.hook` (the Python
contact, compiled, that ``fix external`` calls), :mod:`~.plugin` (building and finding the
native contact ``fix mdgran/chain``, whose C++ sources are in ``fix/``) and :mod:`~.env`
(finding and loading LAMMPS)."""
from __future__ import annotations


def __getattr__(name):
    """``LammpsBackend`` loads its module on first use: the plugin's build (``setup.py``, the
    ``lammps.plugins`` entry point) imports :mod:`~.plugin` without it."""
    if name == "LammpsBackend":
        from .backend import LammpsBackend

        return LammpsBackend
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
