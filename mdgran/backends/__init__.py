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
    "lammps": "mdgran.backends.lammps.backend:LammpsBackend",
    "fast": "mdgran.backends.fast:FastBackend",
}

#: backend -> word -> (option, value): the short words of a backend spec
SPEC_WORDS = {
    "lammps": {"hook": ("contact", "hook"), "native": ("contact", "native"),
               "located": ("events", "located"), "quantized": ("events", "quantized")},
    "fast": {"located": ("locate_events", True), "quantized": ("locate_events", False)},
}


#: option -> (kind, what is allowed): the options a spec or a keyword may give a backend, checked
#: as scene keys are (:mod:`mdgran.model.scene`'s kinds; ``OPTION_LIMITS`` bounds numbers) before
# the
#: backend is built; options that are objects (``comm``, ``extra_commands``, ``table_file``)
#: are the backend's to check, and one a backend does not take is refused by it
OPTION_RULES = {
    "dt": ("float>0", "a finite number > 0 that divides run.output_interval"),
    "threads": ("int>=0", "an integer >= 0 (0: every core the process may use)"),
    "tolerance": ("tol", "a number in [1e-14, 1e-3]"),
    "locate_events": ("bool", "true or false"),
    "contact_eval": (("table", "exact"), "'table' or 'exact'"),
    "table_points": ("int>=1", "an integer from 16 to 1000000"),
    "delta_max": ("float>0", "a number from 1 to 1e4 (p)"),
    "contact": (("hook", "native"), "'hook' or 'native'"),
    "events": (("located", "quantized"), "'located' or 'quantized'"),
}
OPTION_LIMITS = {"table_points": (16, 1_000_000), "delta_max": (1.0, 1e4)}


def check_options(name: str, options: dict) -> dict:
    """``options`` of backend ``name`` checked against :data:`OPTION_RULES` (numbers as the
    numbers they are); a bad one is a :class:`~mdgran.model.scene.SceneError` on key
    ``NAME:OPTION``, one line saying what is allowed."""
    from ..model.scene import SceneError, _check_value

    out = dict(options)
    for key, value in options.items():
        if key not in OPTION_RULES:
            continue
        kind, allowed = OPTION_RULES[key]
        label = f"{name}:{key}"
        value = _check_value(label, value, kind, allowed)
        lo, hi = OPTION_LIMITS.get(key, (None, None))
        if lo is not None and not lo <= value <= hi:
            raise SceneError(label, f"must be {allowed}, not {value}")
        out[key] = value
    return out


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
