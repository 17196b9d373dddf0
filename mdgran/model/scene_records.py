"""Typed records of a resolved scene: one frozen dataclass per section, generated from the
schema (:data:`mdgran.model.scene.SCHEMA`), so that modules read ``scene.run.dt`` rather than
``scene.data["run"]["dt"]``.

A record has one field per key of its section, in the schema's order, typed after the key's
kind (``int``, ``float``, ``str``, ``bool``; ``| None`` where the key may be absent; a number
or a tuple of numbers for the per-bead keys); ``record.table()`` is the section as a table,
key -> value, for the functions that take one.  Records are immutable: assigning a field raises
``dataclasses.FrozenInstanceError``, and a list value of the scene's data (per-bead
ratios, ``base.values``) is held as a tuple.  A key that is a Python keyword gets a trailing
underscore: ``contact.lambda`` is ``scene.contact.lambda_``.  Records are built from
``Scene.data`` when the scene is made; ``data`` stays what is written into output files and
what :meth:`~mdgran.model.scene.Scene.with_overrides` resolves again.
"""
from __future__ import annotations

import keyword
from dataclasses import fields, make_dataclass

#: scalar kind names of the schema (:func:`mdgran.model.scene._check_value`) -> the field's type
_KIND_TYPES = {"int": int, "float": float, "bool": bool, "str": str, "fc": float, "tol": float,
               "nu": float, "ratio": float}


def field_type(kind) -> object:
    """The type annotation of a key of schema ``kind``: a tuple of choices is ``str``; a
    trailing ``?`` (or ``fc``) may be ``None``; ``ratios`` and ``list:KIND`` are a number or a
    tuple of them; ``values?`` a tuple of numbers."""
    if isinstance(kind, tuple):
        return str
    base = kind.rstrip("?")
    if base == "values":
        typ = tuple[float, ...]
    elif base == "ratios" or base.startswith("list:"):
        typ = float | tuple[float, ...]
    else:
        typ = _KIND_TYPES[next(k for k in _KIND_TYPES if base.startswith(k))]
    return typ | None if kind.endswith("?") or kind == "fc" else typ


def field_name(key: str) -> str:
    """A key's field name: the key, with ``_`` appended to a Python keyword (``lambda_``)."""
    return key + "_" if keyword.iskeyword(key) else key


def key_name(field: str) -> str:
    """The scene key of a record's field (the inverse of :func:`field_name`)."""
    return field[:-1] if field.endswith("_") and keyword.iskeyword(field[:-1]) else field


def record_name(section: str) -> str:
    """The class name of a section's record: ``run`` -> ``RunSection``."""
    return section.capitalize() + "Section"


def record_table(record) -> dict:
    """The record as its section's table, key -> value (``lambda``, not ``lambda_``): for the
    functions that take a table, shared with the scene's resolution (such as
    :func:`mdgran.model.contact.law_from_contact_table`)."""
    return {key_name(f.name): getattr(record, f.name) for f in fields(record)}


def record_type(section: str, keys: dict, module: str) -> type:
    """The frozen dataclass of ``section``, one field per key of ``keys`` (name -> schema
    :class:`~mdgran.model.scene.Key`), its docstring listing each key's unit and meaning.
    ``module``: where the class is importable from (records pickle by reference)."""
    cls = make_dataclass(record_name(section),
                         [(field_name(name), field_type(key.kind)) for name, key in keys.items()],
                         frozen=True, namespace={"table": record_table})
    cls.__module__ = module
    cls.__doc__ = f"The resolved ``[{section}]`` of a scene (frozen):\n\n" + "\n".join(
        f"* ``{name}`` ({key.unit or '-'}): {key.doc}" for name, key in keys.items())
    return cls


def record_types(schema: dict, module: str) -> dict:
    """Section -> its record type, for every section of ``schema``."""
    return {sec: record_type(sec, keys, module) for sec, keys in schema.items()}


def frozen_value(value):
    """A scene value as a record holds it: a list (and any list inside it) as a tuple."""
    if isinstance(value, list):
        return tuple(frozen_value(v) for v in value)
    return value


def section_records(types: dict, data: dict) -> dict:
    """Section -> its record, built from resolved scene ``data`` (every key present, as
    :func:`mdgran.model.scene.resolve` leaves it).  A missing section or key raises ``KeyError``
    naming it."""
    out = {}
    for sec, cls in types.items():
        table = data.get(sec)
        if table is None:
            raise KeyError(f"{sec}: missing from the scene's data (a Scene holds resolved data)")
        names = {f.name: key_name(f.name) for f in fields(cls)}
        missing = [key for key in names.values() if key not in table]
        if missing:
            raise KeyError(f"{sec}.{missing[0]}: missing from the scene's data (a Scene holds "
                           "resolved data)")
        out[sec] = cls(**{f: frozen_value(table[key]) for f, key in names.items()})
    return out
