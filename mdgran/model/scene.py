"""Scenes: TOML files with the contract's nondimensional keys, validated, with overrides.

A scene is a built-in name (``mdgran scenes`` lists them; files in ``mdgran/scenes/``), a
path to a TOML file, or a nested mapping with the TOML's keys.  Missing keys take the defaults
of :data:`SCHEMA`; ``--set a.b=VALUE`` overrides any key (VALUE is read as a TOML value, or as
a bare string).  Every problem raises :class:`SceneError` naming the key and what is allowed,
before anything runs.  ``docs/scenes.md`` explains the rules with a worked SI example;
``docs/scene_keys.md`` lists every key, generated from :data:`SCHEMA` by
:func:`key_reference` (``python reference/make_scene_keys.py``).

**SI and nondimensional keys.**  Keys of ``[material]`` are SI (the beads' material).  In the
other sections a key ending in ``_si`` is SI and needs a ``[material]``; every other key is
nondimensional (units of docs/physics.md section 1).  A value may be given one way only: ``k1`` or
``k1_si``, not both.  The SI keys are ``substrate.k1_si`` (N/m), ``substrate.k3_si``
(N/m^3), ``contact.damping_si`` (Ns/m), ``impulse.velocity_si`` (m/s), ``run.duration_si`` (s),
and per bead (a number or a list of chain.n) ``beads.E`` (Pa), ``beads.nu``, ``beads.w``
(J/m^2), named as the ``[material]`` keys they repeat, and ``beads.density_si`` (kg/m^3): they
set the ratios ``beads.modulus``, ``adhesion``, ``density`` (:func:`_derive_beads`), as the
nondimensional ``beads.mass`` sets ``beads.density``.

**A material means what it says.**  A ``[material]`` table must be complete: ``diameter`` (m),
``E`` (Pa) or ``K`` (Pa), ``nu``, ``w`` (J/m^2), ``density`` (kg/m^3); only ``modulus``
("table", default, or "text") and ``D0`` (m, default 0.165e-9, the paper's) have defaults.
It then sets ``contact.lambda`` too (its Maugis parameter,
:attr:`mdgran.model.units.Scales.maugis_lambda`), unless the scene gives ``contact.lambda`` or
``contact.fc`` itself.  Where each value came from is in :attr:`Scene.sources` (and
``lambda_source`` in ``mdgran info``).

**Limits** (:data:`LIMITS`).  Besides being finite, a few values have ranges outside which the
backends cannot work or the numbers are not representable; they are checked on the
nondimensional values, so also after the SI conversion (an error then names both keys):

* ``|impulse.velocity| <= 5e3`` (p per time unit, 80x the paper's largest; the macro chain
  matched to micro-star in m/s needs 3.8e3): faster impulses compress contacts by thousands of
  p, where double precision no longer resolves the reference's absolute event tolerance
  (1e-13 p) and its event location stalls (measured: v0 = 1e4 stalls at t = 1.58 on
  micro-star; +-5e3 runs on micro-star, 3.8e3 on macro-hertz).
* ``substrate.k1 <= 1e6`` and ``substrate.k3 <= 1e6`` (eta/p and eta/p^3; the contact's own
  stiffness is of order 1): stiffer, the substrate period ``2 pi / sqrt(k1)`` falls below 6e-3
  time units and a run needs many millions of steps (at 1e300 the step size underflows).
* ``contact.damping <= 1e3`` (sqrt(m eta / p), 7.5e4 x the paper's): a closed contact then
  relaxes in 1e-3 time units, which bounds the step of the explicit integrators (DOP853 at 1e6:
  1.6e-6 per step, 2.5e8 steps to t = 400).
* ``[material]``: diameter in [1e-9, 10] m, E and K in [1e3, 1e13] Pa, w in [1e-6, 1e3] J/m^2,
  density in [1, 1e5] kg/m^3, D0 in [1e-12, 1e-6] m (physical materials; far outside, the
  scales overflow or underflow).

``contact.lambda`` and ``contact.fc_rule`` are used by law ``schwarz`` only (and not when
``contact.fc`` is given); a scene that gives them where they have no effect is refused
(``--set contact.law=jkr`` on a scene file that gives lambda drops the file's lambda).
"""
from __future__ import annotations

import copy
import math
import sys
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from .contact import FC_RULES, LAWS, SNAP_OFF_RULES, ContactLaw, law_from_contact_table
from .scene_records import record_types, section_records
from .units import D0_DEFAULT, missing_material_keys, scales_from_material

SCENE_DIR = Path(__file__).parents[1] / "scenes"


class SceneError(ValueError):
    """Bad scene input: one line naming the key and what is allowed (exit status 2)."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key


#: key -> (lowest, highest) allowed (see the module doc; ``velocity`` bounds ``|v|``)
LIMITS = {
    "impulse.velocity": (-5e3, 5e3),
    "substrate.k1": (0.0, 1e6),
    "substrate.k3": (0.0, 1e6),
    "contact.damping": (0.0, 1e3),
    "material.diameter": (1e-9, 10.0),
    "material.E": (1e3, 1e13),
    "material.K": (1e3, 1e13),
    "material.w": (1e-6, 1e3),
    "material.density": (1.0, 1e5),
    "material.D0": (1e-12, 1e-6),
    "beads.spread": (0.0, 0.9),
    "substrate.damping": (0.0, 1e3),
    "thermal.temperature": (0.0, 1e6),
    "pulse.amplitude": (-1e4, 1e4),
    "base.values": (-1e6, 1e6),
    "beads.E": (1e3, 1e13),
    "beads.w": (1e-6, 1e3),
    "beads.density_si": (1.0, 1e5),
}

class Key(NamedTuple):
    """One scene key: its default, its kind (checked by ``_check_value``), what is allowed (the
    text of error messages), its unit, and a one-line description.  ``shown`` replaces the
    default in the key reference where the default depends on the scene."""

    default: object
    kind: object
    allowed: str
    unit: str = ""
    doc: str = ""
    shown: str | None = None


_FREQ = "(stiffer, the substrate period falls below 6e-3 time units)"
#: ratios to the reference bead (diameter, density, modulus, adhesion): within 1e3 either way,
#: so that masses (diameter^3) and the pairs' force and length units stay within 1e9
_RATIO = "[1e-3, 1e3]"
#: beads.pattern values (mdgran.model.mixture.pattern_diameters)
PATTERNS = ("uniform", "dimer", "tapered", "intruder", "random")
#: base.kind values (mdgran.model.drive)
BASE_KINDS = ("none", "displacement", "acceleration")
_MAT = "required in a [material]"
_SI_LIST = "a number or a list of chain.n numbers"

#: output.positions defaults to true up to this many stored beads (240 kB a frame), false above:
#: every position is written, where a long chain's displacement and velocity cost the beads
#: that moved (mdgran.rest_blocks)
POSITIONS_AUTO_BEADS = 10000

#: section -> key -> :class:`Key`.  The one source of the keys, their defaults, ranges and units
#: (``docs/scene_keys.md`` is generated from it).
SCHEMA = {
    "chain": {
        "n": Key(20, "int>=1", "an integer >= 1", "", "number of moving beads"),
        "boundary": Key("fixed", ("fixed", "free"), "'fixed' or 'free'", "",
                        "'fixed': wall beads at both ends; 'free': no walls"),
        "initial_gap": Key(0.0, "float>=0", "a finite number >= 0", "p",
                           "> 0: every contact starts open, separated by this gap"),
    },
    "contact": {
        "law": Key("schwarz", LAWS, "one of " + ", ".join(repr(x) for x in LAWS), "",
                   "contact law; jkr and dmt are Schwarz with fc = -1.5 and -2"),
        "lambda": Key(0.64, "float>=0", "a finite number >= 0 (Maugis parameter)", "",
                      "Maugis parameter (schwarz only); not given: the [material]'s, else "
                      "0.64 (the paper's)", "0.64, or from [material]"),
        "fc": Key(None, "fc", "a number in [-2, -1.5] (units of pi R w)", "eta = pi R w",
                  "pull-off force, instead of contact.lambda (schwarz only)", "from lambda"),
        "fc_rule": Key("cos", FC_RULES, "one of " + ", ".join(repr(x) for x in FC_RULES), "",
                       "how fc follows from lambda: 'cos' the paper's Carpick-Ogletree-Salmeron "
                       "fit, 'maugis-dugdale' Maugis's equations solved exactly (schwarz, "
                       "without contact.fc)"),
        "damping": Key(0.013285, "float>=0", "a number in [0, 1e3] (heavier damping needs "
                       "steps below 1e-3 time units)", "sqrt(m eta / p)",
                       "C_hat, unilateral: acts on closed contacts only"),
        "snap_off": Key("displacement", SNAP_OFF_RULES, "'displacement' or 'force'", "",
                        "'displacement': open at delta_min (the paper's); 'force': at the "
                        "tensile force maximum f = fc (LAMMPS granular jkr's)"),
        "damping_si": Key(None, "float>=0?", "a finite number >= 0 in Ns/m (needs [material])",
                          "Ns/m", "contact.damping in SI (needs [material])"),
    },
    "substrate": {
        "k1": Key(0.012107, "float>=0", f"a number in [0, 1e6] {_FREQ}", "eta / p",
                  "linear substrate stiffness K1_hat"),
        "k3": Key(0.0, "float>=0", f"a number in [0, 1e6] {_FREQ}", "eta / p^3",
                  "cubic substrate stiffness K3_hat"),
        "damping": Key(0.0, "float>=0", "a number in [0, 1e3] (heavier damping needs steps "
                       "below 1e-3 time units)", "sqrt(m eta / p)",
                       "viscous damping of each bead on the substrate, force -c_s v (its "
                       "dissipation is counted in dissipated_viscous); 0: none"),
        "k1_si": Key(None, "float>=0?", "a finite number >= 0 in N/m (needs [material])",
                     "N/m", "substrate.k1 in SI (needs [material])"),
        "k3_si": Key(None, "float>=0?", "a finite number >= 0 in N/m^3 (needs [material])",
                     "N/m^3", "substrate.k3 in SI (needs [material])"),
    },
    "impulse": {
        "bead": Key(1, "int>=1", "an integer from 1 to chain.n", "",
                    "bead that gets the impulse (1-based)"),
        "velocity": Key(1.0, "float", "a number with |v| <= 5e3 (p per time unit; faster "
                        "impulses leave the precision the event location needs)", "p q",
                        "v0, positive from bead 1 towards bead n; E_imp = m v0^2 / 2"),
        "velocity_si": Key(None, "float?", "a finite number in m/s (needs [material])", "m/s",
                           "impulse.velocity in SI (needs [material])"),
    },
    "run": {
        "duration": Key(400.0, "float>0", "a finite number > 0", "1/q", "time simulated"),
        "output_interval": Key(0.1, "float>0", "a finite number > 0, at most run.duration",
                               "1/q", "time between stored frames"),
        "tolerance": Key(1e-8, "tol", "a number in [1e-14, 1e-3]", "",
                         "accuracy target of adaptive backends (reference)"),
        "dt": Key(0.01, "float>0", "a finite number > 0 (step of fixed-step backends)", "1/q",
                  "step of fixed-step backends (fast, lammps)"),
        "duration_si": Key(None, "float>0?", "a finite number > 0 in s (needs [material])", "s",
                           "run.duration in SI (needs [material])"),
        "threads": Key(0, "int>=0", "an integer >= 0 (0: every core the process may use)", "",
                       "threads of the fast backend's pass over a long chain (results do not "
                       "depend on it); 0: every core the process may use"),
    },
    "output": {
        "positions": Key(None, "bool?", "true or false (store H5MD position)", "",
                         "store the H5MD position element (24 bytes per bead and frame, "
                         f"every value written); default: true up to {POSITIONS_AUTO_BEADS} "
                         "stored beads, false above (a long chain's displacement and velocity "
                         "cost the beads that moved, docs/output.md)",
                         shown=f"true up to {POSITIONS_AUTO_BEADS} stored beads"),
        "contacts": Key(False, "bool", "true or false (store per-contact compression and "
                        "force; 16 bytes per contact per frame)", "",
                        "also store /observables/contacts/{compression,force} per frame "
                        "(docs/output.md); off by default: 16 bytes x contacts per frame (the "
                        "contact states, /observables/contacts/closed, are always stored)"),
        "bead_stride": Key(1, "int>=0", "an integer >= 0 (1: every bead; k > 1: beads 1, 1+k, "
                           "...; 0: no per-bead series, observables and events only)", "",
                           "store every k-th bead's displacement, velocity and position (beads "
                           "1, 1+k, ..., listed in /particles/chain/id) and every k-th contact's "
                           "series; 0: none; the observables and events stay complete "
                           "(docs/output.md)"),
        "compression": Key("none", ("none", "gzip", "lzf"), "'none', 'gzip' (level 4) or "
                           "'lzf'", "", "HDF5 filter (with byte shuffle) of the per-bead and "
                           "per-contact series; 'lzf' is fast, 'gzip' smaller and readable "
                           "everywhere"),
    },
    "material": {
        "diameter": Key(None, "float>0?", "a number in [1e-9, 10] (m)", "m", "bead diameter",
                        _MAT),
        "E": Key(None, "float>0?", "a number in [1e3, 1e13] (Pa)", "Pa",
                 "Young's modulus (K follows by material.modulus)", _MAT + " (or K)"),
        "nu": Key(None, "nu?", "a number in [0, 0.5)", "", "Poisson's ratio", _MAT),
        "w": Key(None, "float>0?", "a number in [1e-6, 1e3] (J/m^2)", "J/m^2",
                 "work of adhesion", _MAT),
        "density": Key(None, "float>0?", "a number in [1, 1e5] (kg/m^3)", "kg/m^3",
                       "bead density", _MAT),
        "modulus": Key("table", ("table", "text"), "'table' (K = E/(2(1-nu^2))) or 'text'", "",
                       "K from E and nu: 'table' E/(2(1-nu^2)), reproduces the paper's Table I "
                       "and lambda 0.64; 'text' (2/3)E/(1-nu^2), as the paper's text writes"),
        "K": Key(None, "float>0?", "a number in [1e3, 1e13] (Pa)", "Pa",
                 "contact modulus, instead of E and modulus", "instead of E"),
        "D0": Key(None, "float>0?", "a number in [1e-12, 1e-6] (m)", "m",
                  "interfacial contact separation (enters the Maugis parameter only)",
                  f"{D0_DEFAULT!r} (with a material)"),
    },
    "beads": {
        "pattern": Key("uniform", PATTERNS, "one of " + ", ".join(repr(x) for x in PATTERNS),
                       "", "how bead diameters are laid out: 'uniform' (beads.diameter, 1 if "
                       "not given), 'dimer' (beads 2, 4, ... of diameter beads.ratio), "
                       "'tapered' (each bead beads.ratio times the one before), 'intruder' "
                       "(bead beads.index of diameter beads.ratio), 'random' (1 + "
                       "beads.spread (2U - 1), seeded by beads.seed); docs/mixtures.md"),
        "diameter": Key(None, "ratios?", f"a number or a list of chain.n numbers in {_RATIO}",
                        "d0", "diameter of each bead over the reference bead's (pattern "
                        "'uniform')", "1"),
        "ratio": Key(None, "ratio?", f"a number in {_RATIO}", "-",
                     "pattern's diameter ratio: dimer's second bead, tapered's d_(i+1)/d_i, "
                     "the intruder's d/d0", "needed by dimer, tapered, intruder"),
        "index": Key(None, "int>=1?", "an integer from 1 to chain.n", "",
                     "the intruder's bead (1-based)", "the middle bead"),
        "spread": Key(None, "float>=0?", "a number in [0, 0.9]", "",
                      "pattern 'random': diameters 1 + spread (2U - 1)", "0"),
        "seed": Key(None, "int>=0?", "an integer >= 0", "",
                    "pattern 'random': the generator's seed", "0"),
        "density": Key(1.0, "ratios", f"a number or a list of chain.n numbers in {_RATIO}",
                       "rho0", "density of each bead over the reference bead's (mass "
                       "m_i = density_i diameter_i^3)"),
        "modulus": Key(1.0, "ratios", f"a number or a list of chain.n numbers in {_RATIO}",
                       "K0", "contact modulus K of two beads of each bead's material, over the "
                       "reference pair's (a pair's K is the harmonic mean)"),
        "adhesion": Key(1.0, "ratios", f"a number or a list of chain.n numbers in {_RATIO}",
                        "w0", "work of adhesion of two of each bead's surfaces over the "
                        "reference pair's (a pair's w is the geometric mean)"),
        "pair_adhesion": Key(None, "ratio?", f"a number in {_RATIO}", "w0",
                             "one work of adhesion for every pair, instead of the means of "
                             "beads.adhesion", "from beads.adhesion"),
        "E": Key(None, "list:float>0?", f"{_SI_LIST} in [1e3, 1e13] (Pa; needs [material])",
                 "Pa", "Young's modulus of each bead's material, instead of beads.modulus: "
                 "sets it to K_ii / K0 (K of two beads of that material by material.modulus, "
                 "with beads.nu, else material.nu; needs material.E)", "not set"),
        "nu": Key(None, "list:nu?", f"{_SI_LIST} in [0, 0.5) (needs [material])", "-",
                  "Poisson's ratio of each bead's material, instead of beads.modulus: sets it "
                  "with beads.E, else material.E", "not set"),
        "w": Key(None, "list:float>0?", f"{_SI_LIST} in [1e-6, 1e3] (J/m^2; needs "
                 "[material])", "J/m^2", "work of adhesion of two of each bead's surfaces, "
                 "instead of beads.adhesion: sets it to w_i / material.w", "not set"),
        "density_si": Key(None, "list:float>0?", f"{_SI_LIST} in [1, 1e5] (kg/m^3; needs "
                          "[material])", "kg/m^3", "density of each bead, instead of "
                          "beads.density: sets it to rho_i / material.density", "not set"),
        "mass": Key(None, "list:float>0?", f"{_SI_LIST} > 0", "m0", "mass of each bead over "
                    "the reference bead's, instead of beads.density: sets it to "
                    "mass_i / diameter_i^3", "not set"),
    },
    "striker": {
        "diameter": Key(None, "ratio?", f"a number in {_RATIO}", "d0",
                        "a striker: bead 1 becomes a free bead (off the substrate) of this "
                        "diameter, launched by the impulse into the chain (needs "
                        "chain.boundary = 'free' and impulse.bead = 1)", "no striker"),
        "density": Key(None, "ratio?", f"a number in {_RATIO}", "rho0",
                       "the striker's density over the reference bead's", "1 (with a striker)"),
    },
    "thermal": {
        "temperature": Key(0.0, "float>=0", "a number in [0, 1e6]", "eta p",
                           "initial random velocities v_i = sqrt(temperature / m_i) N(0, 1), "
                           "added to the impulse: each bead's mean kinetic energy "
                           "temperature / 2; 0: none"),
        "seed": Key(0, "int>=0", "an integer >= 0", "", "seed of those velocities (numpy's "
                    "default_rng)"),
    },
    "pulse": {
        "amplitude": Key(0.0, "float", "a number with |A| <= 1e4 (units of eta; 0: no pulse)",
                         "eta", "half-sine force pulse A sin(pi (t - t0) / T) on pulse.bead for "
                         "t0 <= t <= t0 + T (docs/excitation.md); 0: none"),
        "duration": Key(None, "float>0?", "a finite number > 0", "1/q",
                        "the pulse's duration T", "needed by a pulse"),
        "start": Key(None, "float>=0?", "a finite number >= 0", "1/q", "the pulse's start t0",
                     "0 (with a pulse)"),
        "bead": Key(None, "int>=1?", "an integer from 1 to chain.n", "",
                    "the bead the pulse pushes (1-based; positive A towards bead n)",
                    "1 (with a pulse)"),
    },
    "base": {
        "kind": Key("none", BASE_KINDS, "one of " + ", ".join(repr(x) for x in BASE_KINDS), "",
                    "motion of the substrate's base, whose springs and dampers then act on x - "
                    "u_b and v - u_b' (docs/excitation.md): 'displacement' or 'acceleration' "
                    "samples in base.values; 'none': a fixed base"),
        "interval": Key(None, "float>0?", "a finite number > 0", "1/q",
                        "time between the samples of base.values (the first at t = 0)",
                        "needed by a base motion"),
        "values": Key(None, "values?", "a list of 2 to 1e6 numbers, each within +-1e6", "p or p q^2",
                      "the samples: displacements u_b (the first 0; a clamped cubic spline "
                      "through them) or accelerations u_b'' (linear between samples, "
                      "integrated from rest at 0)", "needed by a base motion"),
        "file": Key(None, "str?", "a path to a text file of numbers or a .npy array", "",
                    "base.values read from a file when the scene is loaded (text: numbers "
                    "separated by spaces, commas or newlines, '#' starts a comment; or a "
                    "1-D .npy): a recorded shaker signal.  A relative path is from the scene "
                    "file's folder (the working directory for a scene given otherwise); the "
                    "stored scene holds the samples read", "none"),
    },
    "meta": {
        "description": Key("", "str", "a string", "", "what the scene is; first line is listed "
                           "by mdgran scenes"),
    },
}

#: section -> its frozen record type (``scene.run`` is a ``RunSection``), generated from
#: :data:`SCHEMA` (:mod:`mdgran.model.scene_records`)
SECTION_TYPES = record_types(SCHEMA, __name__)
globals().update({cls.__name__: cls for cls in SECTION_TYPES.values()})  # records pickle

#: [material] keys that make a material (modulus and D0 alone refine one, they make none)
MATERIAL_KEYS = ("diameter", "E", "K", "nu", "w", "density")

#: key given -> keys of the same quantity given another way, which it replaces in overrides
OTHER_WAYS = {
    "contact.fc": ("lambda", "fc_rule"), "contact.lambda": ("fc",),
    "contact.fc_rule": ("fc",),
    "material.K": ("E", "modulus"), "material.E": ("K",), "material.modulus": ("K",),
    "beads.modulus": ("E", "nu"), "beads.E": ("modulus",), "beads.nu": ("modulus",),
    "beads.adhesion": ("w",), "beads.w": ("adhesion",),
    "beads.density": ("density_si", "mass"), "beads.density_si": ("density", "mass"),
    "beads.mass": ("density", "density_si"),
    "base.file": ("values",), "base.values": ("file",),
}


def _check_value(key: str, value, kind, allowed: str):
    """``value`` of ``key`` checked against its schema ``kind`` (a tuple of choices, or a
    kind name; ``?``: may be absent); a bad one is a :class:`SceneError` saying what is
    ``allowed``.  Returns the value as the scene keeps it."""
    if isinstance(value, np.generic):  # a NumPy number or bool is one
        value = value.item()
    if value is None:
        if isinstance(kind, str) and (kind.endswith("?") or kind == "fc"):
            return None
        raise SceneError(key, f"must be {allowed}")
    if isinstance(kind, tuple):
        if value not in kind:
            raise SceneError(key, f"must be {allowed}, not {value!r}")
        return value
    base = kind.rstrip("?")
    if kind == "str":
        if not isinstance(value, str):
            raise SceneError(key, f"must be {allowed}")
        return value
    if kind.startswith("list:"):  # a number or a list of them, each of kind "list:KIND"
        return _check_list(key, value, kind[5:], allowed)
    if base == "bool":
        if not isinstance(value, bool):
            raise SceneError(key, f"must be {allowed}, not {value!r}")
        return value
    if kind.startswith("int"):
        return _check_int(key, value, base, allowed)
    if kind == "values?":
        if not isinstance(value, list) or not 2 <= len(value) <= 1_000_000:
            raise SceneError(key, f"must be {allowed}")
        return [_check_value(key, v, "float", allowed) for v in value]
    if base == "ratios" and isinstance(value, list):
        return _check_list(key, value, "ratio", allowed)
    return _check_number(key, value, base, allowed)


def _check_list(key: str, value, kind: str, allowed: str):
    """A value of ``kind``, or a non-empty list of them."""
    if not isinstance(value, list):
        return _check_value(key, value, kind, allowed)
    if not value:
        raise SceneError(key, f"must be {allowed}, not an empty list")
    return [_check_value(key, v, kind.rstrip("?"), allowed) for v in value]


def _check_int(key: str, value, base: str, allowed: str) -> int:
    """An integer (a float with an integer value is one) >= 0 (``int>=0``) or >= 1."""
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        else:
            raise SceneError(key, f"must be {allowed}, not {value!r}")
    if value < (0 if base == "int>=0" else 1):
        raise SceneError(key, f"must be {allowed}, not {value}")
    return value


#: the range of each number kind (both ends included unless the test says otherwise)
NUMBER_KINDS = {
    "float>=0": lambda v: v >= 0,
    "float>0": lambda v: v > 0,
    "fc": lambda v: -2.0 <= v <= -1.5,
    "tol": lambda v: 1e-14 <= v <= 1e-3,
    "nu": lambda v: 0.0 <= v < 0.5,
    "ratio": lambda v: 1e-3 <= v <= 1e3,
    "ratios": lambda v: 1e-3 <= v <= 1e3,
}


def _check_number(key: str, value, base: str, allowed: str) -> float:
    """A finite, normal (or zero) number in the range of its kind (:data:`NUMBER_KINDS`;
    ``float``: any) and of its key (:data:`LIMITS`)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(key, f"must be {allowed}, not {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(key, f"must be {allowed}, not {value}")
    if value != 0.0 and abs(value) < sys.float_info.min:
        raise SceneError(key, f"{value!r} is subnormal (below 2.2e-308 in magnitude), which "
                         "LAMMPS cannot read; give 0 or a normal number")
    lo, hi = LIMITS.get(key, (-math.inf, math.inf))
    if not NUMBER_KINDS.get(base, lambda v: True)(value) or not lo <= value <= hi:
        raise SceneError(key, f"must be {allowed}, not {value}")
    return value


def defaults() -> dict:
    return {sec: {k: v.default for k, v in keys.items()} for sec, keys in SCHEMA.items()}


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
    """A resolved, validated scene: ``data`` holds every key (defaults filled in, SI keys
    converted to the nondimensional ones, ``contact.lambda`` derived from the material where
    the scene does not give it).

    ``given`` is what the scene gave (file or mapping, overrides applied), from which
    :meth:`with_overrides` resolves again; ``sources`` says where each value of ``data`` came
    from: ``"scene"`` (given), ``"default"``, ``"material"`` (derived from ``[material]``), or
    the SI key it was converted from (``"substrate.k1_si"``); ``None`` for a key the scene does
    not use.  Both are ``None`` for a Scene made directly from resolved data.

    Each section is also a frozen record (:data:`SECTION_TYPES`, :mod:`mdgran.model.scene_records`),
    an attribute named as the section: ``scene.run.dt``, ``scene.chain.n``,
    ``scene.impulse.velocity``.  The records are built from ``data`` when the Scene is made (a
    later change to ``data`` reaches them through :meth:`own_copy`, as it reaches a run)."""

    name: str
    data: dict = field(repr=False)
    given: dict | None = field(default=None, repr=False, compare=False)
    sources: dict | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        for sec, record in section_records(SECTION_TYPES, self.data).items():
            object.__setattr__(self, sec, record)

    def __reduce__(self):
        """Pickled and copied as its fields: the copy builds its records from its data."""
        return (Scene, (self.name, self.data, self.given, self.sources))

    @property
    def law(self) -> ContactLaw:
        return law_from_contact_table(self.contact.table(), self.lambda_source)

    @property
    def lambda_source(self) -> str | None:
        """Where ``contact.lambda`` came from: ``"scene"``, ``"material"``, ``"default"``;
        ``None`` if the law does not use it (``contact.fc`` given, or a law other than
        schwarz)."""
        if self.contact.lambda_ is None:
            return None
        if self.sources is None:
            return "scene"  # made from resolved data: every value is as given
        return self.sources.get("contact.lambda")

    @property
    def scales(self):
        if self.material.diameter is None:
            return None
        return scales_from_material(self.material.table(), fill=None)

    @cached_property
    def mixture(self):
        """The chain's unlike beads (:class:`mdgran.model.mixture.Mixture`, from ``[beads]`` and
        ``[striker]``), or ``None`` for the homogeneous chain."""
        from .mixture import mixture_from_scene

        return mixture_from_scene(self)

    @property
    def impulse_energy(self) -> float:
        """``E_imp = m_b v0^2 / 2`` (units eta p), ``m_b`` the struck bead's mass (1 but in a
        chain of unlike beads)."""
        v0 = float(self.impulse.velocity)
        mix = self.mixture
        m = 1.0 if mix is None else float(mix.mass[int(self.impulse.bead) - 1])
        return 0.5 * m * v0**2

    @cached_property
    def drive(self):
        """The scene's force pulse and base motion (:class:`mdgran.model.drive.Drive`), or None."""
        from .drive import drive_from_scene

        return drive_from_scene(self)

    @property
    def energy_scale(self) -> float:
        """The energy ledger errors are measured in (units eta p): :attr:`impulse_energy`
        plus the excitations' (:meth:`mdgran.model.drive.Drive.energy`); the impulse energy alone
        for a scene without them."""
        if self.drive is None:
            return self.impulse_energy
        mix = self.mixture
        n = self.chain.n
        mass = np.ones(n) if mix is None else mix.mass
        g = np.ones(n) if mix is None else mix.substrate
        sub = self.substrate
        return self.impulse_energy + self.drive.energy(mass, g, sub.k1, sub.k3,
                                                       float(self.run.duration))

    def own_copy(self) -> "Scene":
        """An independent copy, its data resolved and checked again (what a run keeps: a later
        change to this scene's ``data`` does not reach the run or its record, and a change
        made since this scene was resolved is checked as a scene file is; a bad value is a
        :class:`SceneError`)."""
        return Scene(self.name, resolve(copy.deepcopy(self.data)), copy.deepcopy(self.given),
                     copy.deepcopy(self.sources))

    def with_overrides(self, overrides) -> "Scene":
        """This scene with ``(key, value)`` overrides: the same keys and rules as
        :func:`load_scene`'s (a value the scene derived, such as lambda from the material, is
        derived again)."""
        if self.given is not None:
            data = copy.deepcopy(self.given)
        else:
            data = {sec: {k: v for k, v in table.items() if v is not None}
                    for sec, table in copy.deepcopy(self.data).items()}
        return _make_scene(self.name, apply_overrides(data, overrides))

    def to_toml(self) -> str:
        return dump_toml(self.data)


def _make_scene(name: str, raw: dict) -> Scene:
    raw = _read_base_file(raw, Path.cwd())  # a scene file's own base.file is read already
    data, sources = _resolve(raw)
    return Scene(name, data, given=copy.deepcopy(raw), sources=sources)


def _read_base_file(raw: dict, folder: Path) -> dict:
    """``base.file`` read into ``base.values`` (``raw`` is changed in place; returned), so
    that the stored scene holds the samples themselves; ``folder``: where a relative path
    starts."""
    base = raw.get("base")
    if not isinstance(base, dict) or base.get("file") is None:
        return raw
    given = base.pop("file")
    if not isinstance(given, str) or not given:
        raise SceneError("base.file", f"must be a path (a string), not {given!r}")
    if base.get("values") is not None:
        raise SceneError("base.file", "give the samples in base.values or in base.file, not both")
    path = folder / Path(given).expanduser()
    base["values"] = read_samples(path, "base.file")
    return raw


def read_samples(path: Path, key: str) -> list:
    """A 1-D series of 2 to 1e6 finite numbers from a text file (numbers separated by
    spaces, commas or newlines; ``#`` starts a comment) or a ``.npy`` array; anything else
    raises :class:`SceneError` naming ``key``."""
    try:
        if path.suffix == ".npy":
            values = np.load(path, allow_pickle=False)
        else:
            text = "\n".join(ln.split("#", 1)[0] for ln in path.read_text("utf-8").splitlines())
            values = np.array(text.replace(",", " ").split(), dtype=float)
    except OSError as exc:
        raise SceneError(key, f"{path} cannot be read: {exc.strerror or exc}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise SceneError(key, f"{path} holds something other than numbers: {exc}") from None
    if values.ndim != 1 or values.dtype.kind not in "iuf":
        raise SceneError(key, f"{path} must hold one series of numbers, not an array of "
                         f"shape {values.shape} and type {values.dtype}")
    if not 2 <= len(values) <= 1_000_000 or not np.all(np.isfinite(values)):
        raise SceneError(key, f"{path} must hold 2 to 1e6 finite numbers (it holds "
                         f"{len(values)}, {int(np.sum(~np.isfinite(values)))} not finite)")
    return values.astype(float).tolist()


def apply_overrides(raw: dict, overrides) -> dict:
    """Set ``(key, value)`` overrides in unresolved scene data (in place; returned).  An
    override of one way of giving a value (``contact.fc``/``lambda``, ``X_si``/``X``,
    ``material.K``/``E``) replaces the other way (:data:`OTHER_WAYS`); an override of
    ``contact.law`` with another law than schwarz drops the ``lambda``, ``fc`` and ``fc_rule``
    the scene file gives (only schwarz uses them)."""
    given = set()
    for key, value in overrides:
        _set_key(raw, key, value)
        given.add(key)
        sec, name = key.split(".")
        others = OTHER_WAYS.get(key) or (
            (name[:-3],) if name.endswith("_si") else (f"{name}_si",))
        for other in others:
            raw.get(sec, {}).pop(other, None)
    if raw.get("contact", {}).get("law", "schwarz") != "schwarz" and "contact.law" in given:
        for name in ("lambda", "fc", "fc_rule"):
            if f"contact.{name}" not in given:
                raw["contact"].pop(name, None)
    return raw


def _set_key(data: dict, key: str, value):
    if not isinstance(key, str):
        raise SceneError(str(key), "keys are strings SECTION.NAME")
    parts = key.split(".")
    if len(parts) != 2 or parts[0] not in SCHEMA:
        raise SceneError(key, "keys are SECTION.NAME with SECTION one of " + ", ".join(SCHEMA))
    sec, name = parts
    if name not in SCHEMA[sec]:
        raise SceneError(key, f"unknown key; {sec} allows " + ", ".join(SCHEMA[sec]))
    table = data.setdefault(sec, {})
    if not isinstance(table, dict):
        raise SceneError(sec, "must be a table")
    table[name] = value


def resolve(raw: dict) -> dict:
    """Fill defaults, check every key and value, derive SI keys and the material's lambda;
    returns the resolved data (:func:`load_scene` also keeps where each value came from)."""
    return _resolve(raw)[0]


def _resolve(raw: dict):
    """``(data, sources)``: the resolved data and where each value came from (see
    :class:`Scene`).  The checks run in a fixed order, so a scene with several faults is
    always refused for the same one."""
    _check_sections(raw)
    # a key whose value is None is not given (a resolved scene stores absent keys as None, and
    # callers re-resolve modified copies of it)
    raw = {sec: {k: v for k, v in table.items() if v is not None} for sec, table in raw.items()}
    data = _checked_defaults(raw)
    sources = {f"{sec}.{name}": ("scene" if name in raw.get(sec, {}) else "default")
               for sec, keys in SCHEMA.items() for name in keys}
    scales = _check_material(data, raw, sources)
    _derive_si(data, raw, scales, sources)
    _resolve_adhesion(data["contact"], raw.get("contact", {}), scales, sources)
    _check_counts(data)
    _check_beads(data, raw)
    _derive_beads(data, raw, scales, sources)
    _check_drive(data)
    _resolve_output(data)
    return data, sources


def _check_sections(raw):
    """``raw`` is a mapping of known sections to tables holding known keys only."""
    if not isinstance(raw, Mapping):
        raise SceneError("scene", "a scene is a mapping of sections to tables")
    for sec, table in raw.items():
        if sec not in SCHEMA:
            raise SceneError(str(sec), "unknown section; allowed: " + ", ".join(SCHEMA))
        if not isinstance(table, Mapping):
            raise SceneError(sec, "must be a table")
        for name in table:
            if name not in SCHEMA[sec]:
                raise SceneError(f"{sec}.{name}", f"unknown key; {sec} allows "
                                 + ", ".join(SCHEMA[sec]))


def _checked_defaults(raw: dict) -> dict:
    """The defaults overlaid with ``raw`` (its None values already dropped), every value
    checked against its key's kind and limits (:func:`_check_value`)."""
    data = defaults()
    for sec, table in raw.items():
        data[sec].update(table)
    for sec, keys in SCHEMA.items():
        for name, key in keys.items():
            data[sec][name] = _check_value(f"{sec}.{name}", data[sec][name], key.kind,
                                           key.allowed)
    return data


def _resolve_adhesion(c: dict, given_c: dict, scales, sources: dict):
    """[contact]'s adhesion keys: ``fc`` only for law 'schwarz' and instead of ``lambda``;
    ``lambda`` and ``fc_rule`` only for 'schwarz' and not beside ``fc``; without either,
    ``lambda`` follows from the [material]'s scales when there is one.  Keys that are not
    part of the scene are None, with no source."""
    if c["fc"] is not None and c["law"] != "schwarz":
        raise SceneError("contact.fc", f"applies to law 'schwarz' only (law is {c['law']!r})")
    if c["fc"] is not None and "lambda" in given_c:
        raise SceneError("contact.fc", "give contact.lambda or contact.fc, not both")
    if c["law"] != "schwarz":
        for name in ("lambda", "fc_rule"):
            if name in given_c:
                raise SceneError(f"contact.{name}", f"not used by law {c['law']!r} (only by "
                                 "'schwarz'); leave it out")
        c["lambda"] = c["fc_rule"] = None  # not part of this scene (nor of its stored TOML)
    elif c["fc"] is not None:
        if "fc_rule" in given_c:
            raise SceneError("contact.fc_rule", "sets how fc follows from contact.lambda; with "
                             "contact.fc given, leave it out")
        c["lambda"] = c["fc_rule"] = None
    elif "lambda" not in given_c and scales is not None:
        c["lambda"] = _check_value("contact.lambda", scales.maugis_lambda,
                                   SCHEMA["contact"]["lambda"].kind,
                                   SCHEMA["contact"]["lambda"].allowed)
        sources["contact.lambda"] = "material"
    for name in ("lambda", "fc", "fc_rule"):
        if c[name] is None:
            sources[f"contact.{name}"] = None


def _check_counts(data: dict):
    """Counts that must agree across sections: a free chain has at least 2 beads, the
    impulse's bead is in the chain, and run.output_interval gives between 1 and 1e8 frames
    of run.duration."""
    ch = data["chain"]
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


def _resolve_output(data: dict):
    """[output]: ``positions`` unset means stored when the stored beads (chain.n over
    ``bead_stride``, rounded up) are at most :data:`POSITIONS_AUTO_BEADS`; per-contact
    series need a bead stride >= 1."""
    out = data["output"]
    if out["positions"] is None:
        stored = -(-data["chain"]["n"] // out["bead_stride"]) if out["bead_stride"] else 0
        out["positions"] = stored <= POSITIONS_AUTO_BEADS
    if out["contacts"] and out["bead_stride"] == 0:
        raise SceneError("output.contacts", "must be false with output.bead_stride = 0 (no "
                         "per-bead or per-contact series); give a stride >= 1 to store them")


def _check_drive(data: dict):
    """[pulse] and [base]: the pulse's bead in the chain, keys that refine a pulse only with
    one; a base motion with its interval and samples (a displacement series starting at 0),
    which need a substrate to act through; no base keys without a base motion."""
    p, b, n = data["pulse"], data["base"], data["chain"]["n"]
    if not p["amplitude"]:
        given = [k for k in ("duration", "start", "bead") if p[k] is not None]
        if given:
            raise SceneError(f"pulse.{given[0]}", "refines a pulse and needs pulse.amplitude "
                             "(not 0)")
    else:
        if p["duration"] is None:
            raise SceneError("pulse.duration", "missing: a pulse needs its duration")
        p["start"] = 0.0 if p["start"] is None else p["start"]
        p["bead"] = 1 if p["bead"] is None else p["bead"]
        if p["bead"] > n:
            raise SceneError("pulse.bead", f"must be an integer from 1 to chain.n = {n}, not "
                             f"{p['bead']}")
    if b["kind"] == "none":
        given = [k for k in ("interval", "values") if b[k] is not None]
        if given:
            raise SceneError(f"base.{given[0]}", "describes a base motion and needs base.kind "
                             "= 'displacement' or 'acceleration'")
        return
    for name in ("interval", "values"):
        if b[name] is None:
            raise SceneError(f"base.{name}", f"missing: base.kind = {b['kind']!r} needs "
                             "base.interval and base.values")
    if b["kind"] == "displacement" and b["values"][0] != 0.0:
        raise SceneError("base.values", "a displacement series must start at 0 (the base "
                         f"starts at rest at 0), not {b['values'][0]}")
    s = data["substrate"]
    if not (s["k1"] or s["k3"] or s["damping"]):
        raise SceneError("base.kind", "a base motion acts through the substrate: give "
                         "substrate.k1, substrate.k3 or substrate.damping")


#: beads.* keys each pattern uses besides the per-bead ratios (a key given that the pattern
#: does not use is refused: it would have no effect)
PATTERN_KEYS = {"uniform": ("diameter",), "dimer": ("ratio",), "tapered": ("ratio",),
                "intruder": ("ratio", "index"), "random": ("spread", "seed")}


def _check_beads(data: dict, raw: dict):
    """[beads] and [striker] agree with the chain: lists of chain.n values, the keys the
    pattern needs and no key it ignores, a striker only at the free end bead 1."""
    b, n = data["beads"], data["chain"]["n"]
    given = raw.get("beads", {})
    used = PATTERN_KEYS[b["pattern"]]
    for name in ("diameter", "ratio", "index", "spread", "seed"):
        if name in given and name not in used:
            raise SceneError(f"beads.{name}", f"not used by beads.pattern = {b['pattern']!r} "
                             "(used: " + ", ".join(f"beads.{k}" for k in used) + ")")
    if "ratio" in used and b["ratio"] is None:
        raise SceneError("beads.ratio", f"needed by beads.pattern = {b['pattern']!r}: "
                         f"{SCHEMA['beads']['ratio'].allowed}")
    if b["pattern"] == "tapered" and not 1e-3 <= b["ratio"] ** (n - 1) <= 1e3:
        raise SceneError("beads.ratio", f"{b['ratio']:g}^(chain.n - 1) = "
                         f"{b['ratio'] ** (n - 1):.3g}: the last bead's diameter must stay in "
                         f"{_RATIO} (a ratio closer to 1, or fewer beads)")
    if b["index"] is not None and b["index"] > n:
        raise SceneError("beads.index", f"must be an integer from 1 to chain.n = {n}, "
                         f"not {b['index']}")
    for name in ("diameter", "density", "modulus", "adhesion"):
        if isinstance(b[name], list) and len(b[name]) != n:
            raise SceneError(f"beads.{name}", f"a list must give chain.n = {n} values, not "
                             f"{len(b[name])}")
    if data["striker"]["diameter"] is None:
        if data["striker"]["density"] is not None:
            raise SceneError("striker.density", "refines a striker and needs "
                             "striker.diameter")
        return
    if data["striker"]["density"] is None:
        data["striker"]["density"] = 1.0
    if data["chain"]["boundary"] != "free":
        raise SceneError("striker.diameter", "a striker needs chain.boundary = 'free' (bead 1 "
                         "would start stuck to the wall)")
    if data["impulse"]["bead"] != 1:
        raise SceneError("impulse.bead", "must be 1 with a striker (the striker is bead 1, "
                         f"launched at impulse.velocity), not {data['impulse']['bead']}")


def _check_material(data: dict, raw: dict, sources: dict):
    """A [material] is complete or absent; returns its scales (None without one)."""
    mat, given = data["material"], raw.get("material", {})
    if not any(k in given for k in MATERIAL_KEYS):
        _no_material(mat, given, sources)
        return None
    _check_material_keys(mat, given)
    if "K" in given:
        mat["modulus"] = None
        sources["material.modulus"] = sources["material.E"] = None
    else:
        sources["material.K"] = None
    if mat["D0"] is None:
        mat["D0"] = D0_DEFAULT
    return _material_scales(mat)


def _no_material(mat: dict, given: dict, sources: dict):
    """A scene without a [material]: refuses keys that only refine one (``modulus`` =
    'table' alone is what every resolved scene stores, its default) and leaves the
    material's keys without a source."""
    for name in ("modulus", "D0"):
        if name in given and not (name == "modulus" and given[name] == "table"):
            raise SceneError(f"material.{name}", "refines a [material] and needs one: "
                             "diameter, E (or K), nu, w, density")
    mat["D0"] = None
    for name in SCHEMA["material"]:
        if name != "modulus":
            sources[f"material.{name}"] = None


def _check_material_keys(mat: dict, given: dict):
    """A given [material] has every key without a default, and gives its stiffness one
    way: E (with ``modulus`` turning it into K) or K."""
    missing = missing_material_keys(mat)
    if missing:
        key, what = (f"material.{missing[0]}", "missing") if len(missing) == 1 else (
            "material", "missing " + ", ".join(missing))
        raise SceneError(key, what + ": a [material] gives "
                         "diameter (m), E (Pa) or K (Pa), nu, w (J/m^2) and density (kg/m^3); "
                         f"only modulus ('table') and D0 ({D0_DEFAULT!r} m) have defaults")
    if "K" in given and "E" in given:
        raise SceneError("material.K", "give material.E (K then follows by material.modulus) "
                         "or material.K, not both")
    if "K" in given and "modulus" in given:
        raise SceneError("material.modulus", "sets K from E; with material.K given, leave "
                         "it out")


def _material_scales(mat: dict):
    """The complete [material]'s scales (:func:`scales_from_material`), each finite and
    positive."""
    try:
        scales = scales_from_material(mat, fill=None)
        for name in ("p", "stiffness", "damping", "time", "velocity", "energy",
                     "maugis_lambda"):
            value = getattr(scales, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ArithmeticError(name)
    except (ArithmeticError, ValueError) as exc:  # pragma: no cover - the limits prevent it
        raise SceneError("material", f"its scales cannot be represented ({exc})") from None
    return scales


def _derive_si(data: dict, raw: dict, scales, sources: dict):
    si = {("substrate", "k1_si"): ("substrate", "k1", "stiffness", 1),
          ("substrate", "k3_si"): ("substrate", "k3", "stiffness", 3),
          ("contact", "damping_si"): ("contact", "damping", "damping", 1),
          ("impulse", "velocity_si"): ("impulse", "velocity", "velocity", 1),
          ("run", "duration_si"): ("run", "duration", "time", 1)}
    for sec, name in si:
        sources[f"{sec}.{name}"] = None  # consumed (or absent): data holds the plain key
    given = [k for k in si if data[k[0]][k[1]] is not None]
    if not given:
        return
    if scales is None:
        sec, name = given[0]
        raise SceneError(f"{sec}.{name}", "needs a [material] table with a diameter")
    for (sec, name) in given:
        tsec, tname, unit, power = si[(sec, name)]
        if tname in raw.get(tsec, {}):
            raise SceneError(f"{sec}.{name}", f"give {tsec}.{tname} or {sec}.{name}, not both")
        value = data[sec][name] / getattr(scales, unit)
        if power == 3:  # K3 x^3: K3_hat = K3 p^2 / (eta/p)
            value = data[sec][name] * scales.p**2 / scales.stiffness
        key = SCHEMA[tsec][tname]
        try:  # the converted value obeys the nondimensional key's rules and limits
            value = _check_value(f"{tsec}.{tname}", value, key.kind, key.allowed)
        except SceneError as exc:
            raise SceneError(f"{sec}.{name}", f"{data[sec][name]:g} gives {exc}") from None
        data[tsec][tname] = value
        data[sec][name] = None  # consumed: the resolved scene holds the nondimensional key
        sources[f"{tsec}.{tname}"] = f"{sec}.{name}"


#: beads.* key given in SI (or as masses) -> the ratio key it sets (a value is given one way)
BEAD_WAYS = {"E": "modulus", "nu": "modulus", "w": "adhesion", "density_si": "density",
             "mass": "density"}


def _derive_beads(data: dict, raw: dict, scales, sources: dict):
    """``beads.E``/``nu``, ``w``, ``density_si`` (SI, need a [material]) and ``mass`` become
    the ratios ``beads.modulus``, ``adhesion``, ``density`` (:func:`mdgran.model.mixture.
    modulus_ratios`, ``ratios_to``, ``density_from_mass``); the resolved scene holds the ratios
    only, as for the other SI keys.  A striker keeps its own ``striker.density``."""
    b, n = data["beads"], data["chain"]["n"]
    given = [name for name in BEAD_WAYS if b[name] is not None]
    for name in BEAD_WAYS:
        sources[f"beads.{name}"] = None  # consumed (or absent): data holds the ratio
    for name in given:
        _check_bead_way(data, raw, scales, name)
    if not given:
        return
    from .mixture import density_from_mass, modulus_ratios, pattern_diameters, ratios_to

    mat = data["material"]
    if "E" in given or "nu" in given:
        key = "beads.E" if "E" in given else "beads.nu"
        E = mat["E"] if b["E"] is None else b["E"]
        nu = mat["nu"] if b["nu"] is None else b["nu"]
        _set_ratios(data, sources, "modulus", key,
                    modulus_ratios(E, nu, scales.K, mat["modulus"]))
    if "w" in given:
        _set_ratios(data, sources, "adhesion", "beads.w", ratios_to(b["w"], scales.w))
    if "density_si" in given:
        _set_ratios(data, sources, "density", "beads.density_si",
                    ratios_to(b["density_si"], scales.density))
    if "mass" in given:
        _set_ratios(data, sources, "density", "beads.mass",
                    density_from_mass(b["mass"], pattern_diameters(b, n)))
    for name in given:
        b[name] = None  # consumed: the resolved scene holds the ratios


def _check_bead_way(data: dict, raw: dict, scales, name: str):
    """``beads.<name>`` (a key of :data:`BEAD_WAYS`) is given one way only, as a list of
    chain.n values, with the [material] it needs."""
    key, ratio, n = f"beads.{name}", BEAD_WAYS[name], data["chain"]["n"]
    given, value = raw.get("beads", {}), data["beads"][name]
    if isinstance(value, list) and len(value) != n:
        raise SceneError(key, f"a list must give chain.n = {n} values, not {len(value)}")
    others = [f"beads.{k}" for k in ("density_si", "mass") if k in given and k != name]
    if ratio in given or (ratio == "density" and others):
        other = f"beads.{ratio}" if ratio in given else others[0]
        raise SceneError(key, f"give {other} or {key}, not both")
    if name == "mass":
        return
    if scales is None:
        raise SceneError(key, "needs a [material] table with a diameter")
    if ratio == "modulus" and data["material"]["E"] is None:
        raise SceneError(key, "sets K from E and nu by material.modulus; with material.K "
                         "given, give material.E instead, or beads.modulus")
    if name == "w" and data["beads"]["pair_adhesion"] is not None:
        raise SceneError(key, "has no effect with beads.pair_adhesion (one w for every pair); "
                         "leave one out")


def _set_ratios(data: dict, sources: dict, target: str, key: str, values):
    """Set ``beads.<target>`` to ``values`` (a number or a list, converted from ``key``) if
    every one is a ratio in [1e-3, 1e3]; else name ``key`` and the first bead out of range."""
    many = isinstance(values, list)
    for i, v in enumerate(values if many else [values]):
        if not (math.isfinite(v) and 1e-3 <= v <= 1e3):
            where = f"bead {i + 1} " if many else ""
            raise SceneError(key, f"{where}gives beads.{target} = {v:.6g} (over the "
                             f"reference bead's), which must be in {_RATIO}")
    data["beads"][target] = values
    sources[f"beads.{target}"] = key


def load_scene(spec, overrides=(), name: str | None = None) -> Scene:
    """A scene from a built-in name, a path to a TOML file, a nested mapping with the TOML's
    keys (``{"chain": {"n": 20}, "material": {...}}``; named ``name`` or "custom"), or a
    :class:`Scene` (returned as is, or with the overrides applied); ``(key, value)``
    overrides are applied first.  Problems raise :class:`SceneError` naming the key."""
    if isinstance(spec, Scene):
        return spec.with_overrides(overrides) if overrides else spec
    if isinstance(spec, Mapping):
        raw = {}
        for sec, table in spec.items():
            if not isinstance(sec, str):
                raise SceneError(str(sec), "section names are strings")
            if not isinstance(table, Mapping):
                raise SceneError(sec, "must be a table (a mapping of keys to values)")
            raw[sec] = copy.deepcopy(dict(table))  # the caller's mapping is left as it was
        return _make_scene(name or "custom", apply_overrides(raw, overrides))
    if isinstance(spec, os.PathLike):
        spec = os.fspath(spec)
    if not isinstance(spec, str):
        raise SceneError("scene", "must be a built-in scene name, a path to a .toml file, a "
                         f"mapping or a Scene, not {type(spec).__name__}")
    scenes = builtin_scenes()
    try:
        spec.encode("utf-8")
    except UnicodeEncodeError:
        raise SceneError("scene", f"{spec!r}: the path is not valid UTF-8 (the scene's name "
                         "goes into the output file); rename the file") from None
    if spec in scenes:
        path, stem = scenes[spec], spec
    else:
        path, stem = Path(spec), Path(spec).stem
        if not path.suffix == ".toml" or not path.is_file():
            raise SceneError("scene", f"{spec!r} is neither a built-in scene ("
                             + ", ".join(scenes) + ") nor a readable .toml file")
    raw = _read_base_file(read_toml(path, "scene"), path.resolve().parent)
    return _make_scene(name or stem, apply_overrides(raw, overrides))


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
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
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


def _kind_name(kind) -> str:
    if isinstance(kind, tuple):
        return "string"
    if kind.rstrip("?") == "bool":
        return "boolean"
    if kind == "str":
        return "string"
    if kind.startswith("int"):
        return "integer"
    return "number"


def _num(x: float) -> str:
    s = f"{x:g}"
    return s.replace("e+0", "e").replace("e-0", "e-").replace("e+", "e") if abs(x) >= 1e4 \
        or (x and abs(x) < 1e-4) else s


def _range_text(sec: str, name: str, kind) -> str:
    """The allowed values of a key, from its kind and :data:`LIMITS`."""
    if isinstance(kind, tuple):
        return ", ".join(f'"{x}"' for x in kind)
    if kind.startswith("list:"):
        return _range_text(sec, name, kind[5:]) + ", or a list of chain.n"
    lim = LIMITS.get(f"{sec}.{name}")
    base = kind.rstrip("?")
    if lim is not None:
        if base == "float" and lim[0] == -lim[1]:
            return f"\\|v\\| <= {_num(lim[1])}"
        return f"[{_num(lim[0])}, {_num(lim[1])}]"
    return {"int>=1": ">= 1" if f"{sec}.{name}" not in ("impulse.bead", "beads.index")
            else "1 to chain.n", "ratio": _RATIO, "ratios": _RATIO + ", or a list of chain.n",
            "int>=0": ">= 0", "float>=0": ">= 0", "float>0": "> 0", "float": "finite",
            "fc": "[-2, -1.5]", "tol": "[1e-14, 1e-3]", "nu": "[0, 0.5)", "bool": "true, false",
            "str": "any string"}[base]


def key_reference() -> str:
    """The scene-key reference (Markdown) generated from :data:`SCHEMA` and :data:`LIMITS`:
    ``docs/scene_keys.md`` is this text (``python reference/make_scene_keys.py`` writes it, and
    a test fails when the file differs)."""
    def cell(text) -> str:
        return str(text).replace("|", "\\|")

    lines = [
        "# Scene keys",
        "",
        "<!-- Generated by `python reference/make_scene_keys.py` from `mdgran.model.scene.SCHEMA`",
        "     and `LIMITS`; do not edit by hand (tests/test_material.py fails when this file",
        "     differs from what the script writes). -->",
        "",
        "Every key a scene (TOML file, mapping, or `--set SECTION.KEY=VALUE`) may give. The",
        "rules (SI and nondimensional keys, what a `[material]` derives) are in",
        "[scenes.md](scenes.md). `[material]` keys, keys ending in `_si` and `beads.E`,",
        "`beads.nu`, `beads.w` (named as the `[material]` keys they give per bead) are SI; every",
        "other key is nondimensional, in the units of",
        "[the physics, section 1](physics.md#1-scales-and-units): force",
        "`eta = pi R w`, length `p`, time `1/q = sqrt(m p / eta)`, velocity `p q`, bead mass 1;",
        "\"-\" is a pure number. Values must also be finite; \"range\" is what the checks in",
        "`mdgran/model/scene.py` allow (an SI key's converted value must fit its plain key's",
        "range).",
        "",
    ]
    for sec, keys in SCHEMA.items():
        lines += [f"## [{sec}]", "",
                  "| key | type | default | range | unit | meaning |",
                  "|---|---|---|---|---|---|"]
        for name, key in keys.items():
            if key.shown is not None:
                default = key.shown
            elif key.default is None:
                default = "not set"
            else:
                default = "`" + _toml_value(key.default) + "`"
            lines.append(f"| `{sec}.{name}` | {_kind_name(key.kind)} | {cell(default)} | "
                         f"{_range_text(sec, name, key.kind)} | {cell(key.unit or '-')} | "
                         f"{cell(key.doc)} |")
        lines.append("")
    return "\n".join(lines)
