"""Scenes: TOML files with the contract's nondimensional keys, validated, with overrides.

A scene is a built-in name (``mdgran scenes`` lists them; files in ``mdgran/scenes/``) or a
path to a TOML file.  Missing keys take the defaults below; ``--set a.b=VALUE`` overrides any
key (VALUE is read as a TOML value, or as a bare string).  Every problem raises
:class:`SceneError` naming the key and what is allowed, before anything runs.

An optional ``[material]`` table (SI: ``diameter`` m, ``E`` Pa, ``nu``, ``w`` J/m^2, ``density``
kg/m^3, ``modulus`` = "table" | "text", or ``K`` Pa) gives the scales; the SI keys
``substrate.k1_si`` (N/m), ``substrate.k3_si`` (N/m^3), ``contact.damping_si`` (Ns/m),
``impulse.velocity_si`` (m/s) and ``run.duration_si`` (s) then set the nondimensional ones.

**Limits** (:data:`LIMITS`).  Besides being finite, a few values have ranges outside which the
backends cannot work or the numbers are not representable; they are checked on the
nondimensional values, so also after the SI conversion (an error then names both keys):

* ``|impulse.velocity| <= 1e3`` (p per time unit, 15x the paper's largest): faster impulses
  compress contacts by hundreds of p, where double precision no longer resolves the reference's
  absolute event tolerance (1e-13 p) and its event location stalls (measured: v0 = 1e4 stalls
  at t = 1.58 on micro-star; 1e3 runs).
* ``substrate.k1 <= 1e6`` and ``substrate.k3 <= 1e6`` (eta/p and eta/p^3; the contact's own
  stiffness is of order 1): stiffer, the substrate period ``2 pi / sqrt(k1)`` falls below 6e-3
  time units and a run needs many millions of steps (at 1e300 the step size underflows).
* ``contact.damping <= 1e3`` (sqrt(m eta / p), 7.5e4 x the paper's): a closed contact then
  relaxes in 1e-3 time units, which bounds the step of the explicit integrators (DOP853 at 1e6:
  1.6e-6 per step, 2.5e8 steps to t = 400).
* ``[material]``: diameter in [1e-9, 10] m, E and K in [1e3, 1e13] Pa, w in [1e-6, 1e3] J/m^2,
  density in [1, 1e5] kg/m^3, D0 in [1e-12, 1e-6] m (physical materials; far outside, the
  scales overflow or underflow).

``contact.lambda`` is used by law ``schwarz`` only; a scene that gives it with another law is
refused (``--set contact.law=jkr`` on a scene file that gives lambda drops the file's lambda).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from .contact import LAWS, SNAP_OFF_RULES, ContactLaw, law_from_contact_table

SCENE_DIR = Path(__file__).parent / "scenes"


class SceneError(ValueError):
    """Bad scene input: one line naming the key and what is allowed (exit status 2)."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key


#: key -> (lowest, highest) allowed (see the module doc; ``velocity`` bounds |v|)
LIMITS = {
    "impulse.velocity": (-1e3, 1e3),
    "substrate.k1": (0.0, 1e6),
    "substrate.k3": (0.0, 1e6),
    "contact.damping": (0.0, 1e3),
    "material.diameter": (1e-9, 10.0),
    "material.E": (1e3, 1e13),
    "material.K": (1e3, 1e13),
    "material.w": (1e-6, 1e3),
    "material.density": (1.0, 1e5),
    "material.D0": (1e-12, 1e-6),
}

# key -> (default, kind, constraint text); kinds are checked in _check_value
SCHEMA = {
    "chain": {
        "n": (20, "int>=1", "an integer >= 1"),
        "boundary": ("fixed", ("fixed", "free"), "'fixed' or 'free'"),
        "initial_gap": (0.0, "float>=0", "a finite number >= 0"),
    },
    "contact": {
        "law": ("schwarz", LAWS, "one of " + ", ".join(repr(x) for x in LAWS)),
        "lambda": (0.64, "float>=0", "a finite number >= 0 (Maugis parameter)"),
        "fc": (None, "fc", "a number in [-2, -1.5] (units of pi R w)"),
        "damping": (0.013285, "float>=0", "a number in [0, 1e3] (heavier damping needs steps "
                    "below 1e-3 time units)"),
        "snap_off": ("displacement", SNAP_OFF_RULES, "'displacement' or 'force'"),
        "damping_si": (None, "float>=0?", "a finite number >= 0 in Ns/m (needs [material])"),
    },
    "substrate": {
        "k1": (0.012107, "float>=0", "a number in [0, 1e6] (stiffer, the substrate period "
               "falls below 6e-3 time units)"),
        "k3": (0.0, "float>=0", "a number in [0, 1e6] (stiffer, the substrate period falls "
               "below 6e-3 time units)"),
        "k1_si": (None, "float>=0?", "a finite number >= 0 in N/m (needs [material])"),
        "k3_si": (None, "float>=0?", "a finite number >= 0 in N/m^3 (needs [material])"),
    },
    "impulse": {
        "bead": (1, "int>=1", "an integer from 1 to chain.n"),
        "velocity": (1.0, "float", "a number with |v| <= 1e3 (p per time unit; faster "
                     "impulses leave the precision the event location needs)"),
        "velocity_si": (None, "float?", "a finite number in m/s (needs [material])"),
    },
    "run": {
        "duration": (400.0, "float>0", "a finite number > 0"),
        "output_interval": (0.1, "float>0", "a finite number > 0, at most run.duration"),
        "tolerance": (1e-8, "tol", "a number in [1e-14, 1e-3]"),
        "dt": (0.01, "float>0", "a finite number > 0 (step of fixed-step backends)"),
        "duration_si": (None, "float>0?", "a finite number > 0 in s (needs [material])"),
    },
    "output": {
        "positions": (True, "bool", "true or false (store H5MD position; false for long chains)"),
    },
    "material": {
        "diameter": (None, "float>0?", "a number in [1e-9, 10] (m)"),
        "E": (None, "float>0?", "a number in [1e3, 1e13] (Pa)"),
        "nu": (None, "nu?", "a number in [0, 0.5)"),
        "w": (None, "float>0?", "a number in [1e-6, 1e3] (J/m^2)"),
        "density": (None, "float>0?", "a number in [1, 1e5] (kg/m^3)"),
        "modulus": ("table", ("table", "text"), "'table' (K = E/(2(1-nu^2))) or 'text'"),
        "K": (None, "float>0?", "a number in [1e3, 1e13] (Pa)"),
        "D0": (None, "float>0?", "a number in [1e-12, 1e-6] (m)"),
    },
    "meta": {
        "description": ("", "str", "a string"),
    },
}


def _check_value(key: str, value, kind, allowed: str):
    if value is None:
        if isinstance(kind, str) and (kind.endswith("?") or kind == "fc"):
            return None
        raise SceneError(key, f"must be {allowed}")
    if isinstance(kind, tuple):
        if value not in kind:
            raise SceneError(key, f"must be {allowed}, not {value!r}")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise SceneError(key, f"must be {allowed}")
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise SceneError(key, f"must be {allowed}, not {value!r}")
        return value
    if kind.startswith("int"):
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and math.isfinite(value) and value.is_integer():
                value = int(value)
            else:
                raise SceneError(key, f"must be {allowed}, not {value!r}")
        if value < 1:
            raise SceneError(key, f"must be {allowed}, not {value}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(key, f"must be {allowed}, not {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(key, f"must be {allowed}, not {value}")
    base = kind.rstrip("?")
    bad = ((base == "float>=0" and value < 0) or (base == "float>0" and value <= 0)
           or (base == "fc" and not -2.0 <= value <= -1.5)
           or (base == "tol" and not 1e-14 <= value <= 1e-3)
           or (base == "nu" and not 0.0 <= value < 0.5))
    lo, hi = LIMITS.get(key, (-math.inf, math.inf))
    if bad or not lo <= value <= hi:
        raise SceneError(key, f"must be {allowed}, not {value}")
    return value


def defaults() -> dict:
    return {sec: {k: v[0] for k, v in keys.items()} for sec, keys in SCHEMA.items()}


def parse_override(text: str):
    """``"a.b=VALUE"`` -> ``("a.b", value)``; VALUE is a TOML value or a bare string."""
    if "=" not in text:
        raise SceneError(text, "an override must look like KEY=VALUE, e.g. contact.lambda=1.5")
    key, raw = text.split("=", 1)
    key, raw = key.strip(), raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    except RecursionError:
        raise SceneError(key, "the value is nested too deeply") from None
    return key, value


def builtin_scenes() -> dict:
    """Built-in scene name -> path (``hard/...`` for the hard cases)."""
    out = {}
    for path in sorted(SCENE_DIR.rglob("*.toml")):
        out[path.relative_to(SCENE_DIR).with_suffix("").as_posix()] = path
    return out


@dataclass(frozen=True)
class Scene:
    """A resolved, validated scene: ``data`` holds every key (defaults filled in)."""

    name: str
    data: dict = field(repr=False)

    @property
    def law(self) -> ContactLaw:
        return law_from_contact_table(self.data["contact"])

    @property
    def scales(self):
        from .units import scales_from_material

        mat = self.data.get("material", {})
        return scales_from_material(mat) if mat.get("diameter") is not None else None

    @property
    def impulse_energy(self) -> float:
        return 0.5 * float(self.data["impulse"]["velocity"]) ** 2

    def with_overrides(self, overrides) -> "Scene":
        """This scene with ``(key, value)`` overrides: the same keys and rules as
        :func:`load_scene`'s."""
        data = {sec: {k: v for k, v in table.items() if v is not None}
                for sec, table in copy.deepcopy(self.data).items()}
        if data["contact"].get("fc") is not None:  # fc was given: lambda is only the default
            data["contact"].pop("lambda", None)
        return Scene(self.name, resolve(apply_overrides(data, overrides)))

    def to_toml(self) -> str:
        return dump_toml(self.data)


def apply_overrides(raw: dict, overrides) -> dict:
    """Set ``(key, value)`` overrides in unresolved scene data (in place; returned).  An
    override of one way of giving a value (``contact.fc``/``lambda``, ``X_si``/``X``)
    replaces the other way; an override of ``contact.law`` with another law than schwarz drops
    the ``lambda`` and ``fc`` the scene file gives (only schwarz uses them)."""
    given = set()
    for key, value in overrides:
        _set_key(raw, key, value)
        given.add(key)
        sec, name = key.split(".")
        other = {"contact.fc": "lambda", "contact.lambda": "fc"}.get(key) or (
            name[:-3] if name.endswith("_si") else f"{name}_si")
        raw.get(sec, {}).pop(other, None)
    if raw.get("contact", {}).get("law", "schwarz") != "schwarz" and "contact.law" in given:
        for name in ("lambda", "fc"):
            if f"contact.{name}" not in given:
                raw["contact"].pop(name, None)
    return raw


def _set_key(data: dict, key: str, value):
    parts = key.split(".")
    if len(parts) != 2 or parts[0] not in SCHEMA:
        raise SceneError(key, "keys are SECTION.NAME with SECTION one of " + ", ".join(SCHEMA))
    sec, name = parts
    if name not in SCHEMA[sec]:
        raise SceneError(key, f"unknown key; {sec} allows " + ", ".join(SCHEMA[sec]))
    data.setdefault(sec, {})[name] = value


def resolve(raw: dict) -> dict:
    """Fill defaults, check every key and value, derive SI keys; returns the resolved data."""
    for sec, table in raw.items():
        if sec not in SCHEMA:
            raise SceneError(sec, "unknown section; allowed: " + ", ".join(SCHEMA))
        if not isinstance(table, dict):
            raise SceneError(sec, "must be a table")
        for name in table:
            if name not in SCHEMA[sec]:
                raise SceneError(f"{sec}.{name}", f"unknown key; {sec} allows "
                                 + ", ".join(SCHEMA[sec]))
    # a key whose value is None is not given (a resolved scene stores absent keys as None, and
    # callers re-resolve modified copies of it)
    raw = {sec: {k: v for k, v in table.items() if v is not None} for sec, table in raw.items()}
    data = defaults()
    for sec, table in raw.items():
        data[sec].update(table)
    for sec, keys in SCHEMA.items():
        for name, (_, kind, allowed) in keys.items():
            data[sec][name] = _check_value(f"{sec}.{name}", data[sec][name], kind, allowed)
    _derive_si(data, raw)
    c, ch = data["contact"], data["chain"]
    if c["fc"] is not None and c["law"] != "schwarz":
        raise SceneError("contact.fc", f"applies to law 'schwarz' only (law is {c['law']!r})")
    if c["fc"] is not None and "lambda" in raw.get("contact", {}):
        raise SceneError("contact.fc", "give contact.lambda or contact.fc, not both")
    if c["law"] != "schwarz":
        if "lambda" in raw.get("contact", {}):
            raise SceneError("contact.lambda", f"not used by law {c['law']!r} (only by "
                             "'schwarz'); leave it out")
        c["lambda"] = None  # not part of this scene (nor of its stored TOML)
    if ch["boundary"] == "free" and ch["n"] < 2:
        raise SceneError("chain.n", "must be >= 2 for a free chain")
    if data["impulse"]["bead"] > ch["n"]:
        raise SceneError("impulse.bead", f"must be an integer from 1 to chain.n = {ch['n']}, "
                         f"not {data['impulse']['bead']}")
    r = data["run"]
    if r["output_interval"] > r["duration"]:
        raise SceneError("run.output_interval", f"must be at most run.duration = {r['duration']}")
    if r["duration"] / r["output_interval"] > 1e8:
        raise SceneError("run.output_interval", "gives more than 1e8 frames; make it larger")
    return data


def _derive_si(data: dict, raw: dict):
    si = {("substrate", "k1_si"): ("substrate", "k1", "stiffness", 1),
          ("substrate", "k3_si"): ("substrate", "k3", "stiffness", 3),
          ("contact", "damping_si"): ("contact", "damping", "damping", 1),
          ("impulse", "velocity_si"): ("impulse", "velocity", "velocity", 1),
          ("run", "duration_si"): ("run", "duration", "time", 1)}
    given = [k for k in si if data[k[0]][k[1]] is not None]
    if not given:
        return
    if data["material"]["diameter"] is None:
        sec, name = given[0]
        raise SceneError(f"{sec}.{name}", "needs a [material] table with a diameter")
    scales = Scene("", data).scales
    for (sec, name) in given:
        tsec, tname, unit, power = si[(sec, name)]
        if tname in raw.get(tsec, {}):
            raise SceneError(f"{sec}.{name}", f"give {tsec}.{tname} or {sec}.{name}, not both")
        value = data[sec][name] / getattr(scales, unit)
        if power == 3:  # K3 x^3: K3_hat = K3 p^2 / (eta/p)
            value = data[sec][name] * scales.p**2 / scales.stiffness
        _, kind, allowed = SCHEMA[tsec][tname]
        try:  # the converted value obeys the nondimensional key's rules and limits
            value = _check_value(f"{tsec}.{tname}", value, kind, allowed)
        except SceneError as exc:
            raise SceneError(f"{sec}.{name}", f"{data[sec][name]:g} gives {exc}") from None
        data[tsec][tname] = value
        data[sec][name] = None  # consumed: the resolved scene holds the nondimensional key


def load_scene(spec: str, overrides=()) -> Scene:
    """Load a built-in scene by name or a TOML file by path; apply ``(key, value)`` overrides."""
    scenes = builtin_scenes()
    try:
        spec.encode("utf-8")
    except UnicodeEncodeError:
        raise SceneError("SCENE", f"{spec!r}: the path is not valid UTF-8 (the scene's name "
                         "goes into the output file); rename the file") from None
    if spec in scenes:
        path, name = scenes[spec], spec
    else:
        path, name = Path(spec), Path(spec).stem
        if not path.suffix == ".toml" or not path.is_file():
            raise SceneError("SCENE", f"{spec!r} is neither a built-in scene ("
                             + ", ".join(scenes) + ") nor a readable .toml file")
    raw = read_toml(path, "SCENE")
    return Scene(name, resolve(apply_overrides(raw, overrides)))


def read_toml(path: Path, key: str) -> dict:
    """A TOML file's tables; anything unreadable raises :class:`SceneError` naming ``key``."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SceneError(key, f"{path} is not valid TOML: {exc}") from None
    except RecursionError:
        raise SceneError(key, f"{path} is not valid TOML: values nested too deeply") from None
    except OSError as exc:
        raise SceneError(key, f"{path} cannot be read: {exc.strerror}") from None


def describe(spec: str) -> str:
    """First line of a built-in scene's ``meta.description``."""
    raw = tomllib.loads(builtin_scenes()[spec].read_text())
    return raw.get("meta", {}).get("description", "").strip().splitlines()[0:1][0] \
        if raw.get("meta", {}).get("description") else ""


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    s = str(v).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    return f'"{s}"'


def dump_toml(data: dict) -> str:
    """The resolved scene as TOML text (keys with no value are left out)."""
    lines = []
    for sec, table in data.items():
        items = [(k, v) for k, v in table.items() if v is not None]
        if not items:
            continue
        lines.append(f"[{sec}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in items]
        lines.append("")
    return "\n".join(lines)
