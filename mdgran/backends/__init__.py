"""Backends: each integrates a scene and yields :class:`~mdgran.backends.base.Frame` objects.

``BACKENDS`` maps a name to ``"module:Class"``; modules are imported only when used, so the
reference backend works without LAMMPS installed.
"""
from __future__ import annotations

import importlib

BACKENDS = {
    "reference": "mdgran.backends.reference:ReferenceBackend",
    "lammps": "mdgran.backends.lammps:LammpsBackend",
    "fast": "mdgran.backends.fast:FastBackend",
}


def get_backend(name: str):
    """The backend class registered under ``name`` (raises KeyError for an unknown name)."""
    module, cls = BACKENDS[name].split(":")
    return getattr(importlib.import_module(module), cls)
