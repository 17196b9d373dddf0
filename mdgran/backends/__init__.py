"""Backends: each integrates a scene and yields :class:`~mdgran.backends.base.Frame` objects.

``BACKENDS`` maps a name to ``"module:Class"``; modules are imported only when used, so the
reference backend works without LAMMPS installed.

A *backend spec* names a backend and, optionally, its options, wherever a backend name is taken
(``mdgran run --backend``, ``mdgran compare --backends``, sweeps, ``mdgran.run``)::

    lammps                      the LAMMPS backend with its defaults (Python contact hook)
    lammps:native               contact="native" (the C++ plugin)
    lammps:native:quantized     ... with step-quantized events
    fast:quantized              locate_events=False
    fast:dt=0.005               any option as KEY=VALUE (numbers and true/false converted)

The words a backend understands are in ``SPEC_WORDS``; anything else must be ``KEY=VALUE``.
"""
from __future__ import annotations

import importlib

BACKENDS = {
    "reference": "mdgran.backends.reference:ReferenceBackend",
    "lammps": "mdgran.backends.lammps:LammpsBackend",
    "fast": "mdgran.backends.fast:FastBackend",
}

#: backend -> word -> (option, value): the short words of a backend spec
SPEC_WORDS = {
    "lammps": {"hook": ("contact", "hook"), "native": ("contact", "native"),
               "located": ("events", "located"), "quantized": ("events", "quantized")},
    "fast": {"located": ("locate_events", True), "quantized": ("locate_events", False)},
}


class BadSpec(ValueError):
    """A backend spec that names no backend or an unknown word: one line saying what is allowed."""


def get_backend(name: str):
    """The backend class registered under ``name`` (raises KeyError for an unknown name)."""
    module, cls = BACKENDS[name].split(":")
    return getattr(importlib.import_module(module), cls)


def _value(text: str):
    """``KEY=VALUE``'s value: int, float, bool (true/false, yes/no) or the text itself."""
    low = text.lower()
    if low in ("true", "yes"):
        return True
    if low in ("false", "no"):
        return False
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_spec(spec: str) -> tuple[str, dict]:
    """``"lammps:native:quantized"`` -> ``("lammps", {"contact": "native", "events":
    "quantized"})``.  Raises :class:`BadSpec` for an unknown backend or word; the options
    themselves are checked by the backend (``accepted_options``)."""
    if not isinstance(spec, str) or not spec.strip():
        raise BadSpec(f"must be one of {', '.join(BACKENDS)} (optionally with :options), not "
                      f"{spec!r}")
    name, *parts = spec.strip().split(":")
    if name not in BACKENDS:
        raise BadSpec(f"must be one of {', '.join(BACKENDS)} (optionally with :options), not "
                      f"{spec!r}")
    words = SPEC_WORDS.get(name, {})
    options = {}
    for part in parts:
        key, eq, value = part.partition("=")
        if eq and key:
            options[key] = _value(value)
        elif part in words:
            options[words[part][0]] = words[part][1]
        else:
            allowed = ", ".join(words) + (", or " if words else "") + "KEY=VALUE"
            raise BadSpec(f"{spec!r}: {part!r} is not an option of {name}; use {allowed}")
    return name, options


def spec_stem(spec: str) -> str:
    """A file-name stem for a spec: ``lammps:native`` -> ``lammps-native``."""
    return spec.strip().replace(":", "-").replace("=", "-")
