"""Beads of real materials: beads.E, nu, w, density_si (SI, with a [material]) and
beads.mass set the per-bead ratios.  The expected values are computed here from SI by hand:
the Hertz effective modulus 1/E* = (1 - nu_1^2)/E_1 + (1 - nu_2^2)/E_2, R = d/4,
w_12 = sqrt(w_1 w_2), masses rho pi d^3 / 6, and the Maugis parameter of the pair, not from
mdgran.model.mixture."""
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mdgran.model.chain import model_from_scene
from mdgran.cli import main
from mdgran.model.contact import fc_from_lambda
from mdgran.model.scene import SceneError, load_scene, tomllib

D = 2.5e-6  # m, micro-star's beads
ALUMINA = {"diameter": D, "E": 338e9, "nu": 0.21, "w": 0.146, "density": 3900.0}
STEEL_LIKE = (200e9, 0.3)  # Pa, -: a second material, given as numbers
#: K = c E* of two beads, c per material.modulus (docs/physics.md section 1, "The modulus
#: convention": table K = E / (2 (1 - nu^2)), text K = (2/3) E / (1 - nu^2); E* of two equal
#: beads is E / (2 (1 - nu^2)))
C = {"table": 1.0, "text": 4.0 / 3.0}


def e_star(E1, nu1, E2, nu2):
    """Hertz effective modulus (Pa) of two unlike beads."""
    return 1.0 / ((1 - nu1**2) / E1 + (1 - nu2**2) / E2)


def pair_scene(law="hertz", modulus="table", **beads):
    """Two free beads of ALUMINA's [material] with the given [beads] keys."""
    return load_scene({"material": {**ALUMINA, "modulus": modulus},
                       "chain": {"n": 2, "boundary": "free"}, "contact": {"law": law},
                       "beads": beads})


def hertz_force_si(scene, delta_m):
    """The scene's contact force (N) at compression ``delta_m`` (m)."""
    sc = scene.scales
    return model_from_scene(scene).law_force(np.array([delta_m / sc.p]))[0] * sc.eta


@pytest.mark.parametrize("modulus", ["table", "text"])
def test_unlike_pair_has_the_hertz_effective_modulus(modulus):
    """Alumina against a steel-like bead: the pair's Hertz force is c E* sqrt(R) delta^(3/2)
    with E* from both materials' E and nu (c: the modulus convention), to 1e-12."""
    E2, nu2 = STEEL_LIKE
    scene = pair_scene(modulus=modulus, E=[338e9, E2], nu=[0.21, nu2])
    delta = 3e-10  # m
    expect = C[modulus] * e_star(338e9, 0.21, E2, nu2) * math.sqrt(D / 4) * delta**1.5
    assert hertz_force_si(scene, delta) == pytest.approx(expect, rel=1e-12)


@settings(max_examples=80, deadline=None)
@given(E=st.lists(st.floats(1e9, 1e12), min_size=2, max_size=2),
       nu=st.lists(st.floats(0.0, 0.49, allow_subnormal=False), min_size=2, max_size=2),
       modulus=st.sampled_from(["table", "text"]))
def test_pair_modulus_is_the_hand_formula(E, nu, modulus):
    """Any two materials: the scene's pair modulus is c E*(E1, nu1, E2, nu2)."""
    scene = pair_scene(modulus=modulus, E=E, nu=nu)
    delta = 1e-10
    expect = C[modulus] * e_star(E[0], nu[0], E[1], nu[1]) * math.sqrt(D / 4) * delta**1.5
    assert hertz_force_si(scene, delta) == pytest.approx(expect, rel=1e-12)


def test_schwarz_pair_scales_and_lambda_from_si():
    """The Schwarz pair of alumina and a steel-like bead with its own w: force unit pi R w_12,
    length unit (pi^2 R w_12^2 / K_12^2)^(1/3) and fc from the pair's own Maugis parameter
    2.06 / D0 (R w_12^2 / (pi K_12^2))^(1/3), all from SI by hand."""
    E2, nu2 = STEEL_LIKE
    w2 = 0.05
    scene = pair_scene(law="schwarz", E=[338e9, E2], nu=[0.21, nu2], w=[0.146, w2])
    mix, sc = scene.mixture, scene.scales
    R, K, w = D / 4, e_star(338e9, 0.21, E2, nu2), math.sqrt(0.146 * w2)
    assert mix.force_scale[0] * sc.eta == pytest.approx(math.pi * R * w, rel=1e-12)
    p12 = (math.pi**2 * R * w**2 / K**2) ** (1 / 3)
    assert mix.length_scale[0] * sc.p == pytest.approx(p12, rel=1e-12)
    lam = 2.06 / 0.165e-9 * (R * w**2 / (math.pi * K**2)) ** (1 / 3)
    assert mix.fc[0] == pytest.approx(fc_from_lambda(lam), rel=1e-11)


def test_density_si_and_mass_set_the_masses():
    """beads.density_si (kg/m^3) gives masses rho pi d^3 / 6 (kg); beads.mass (over the
    reference bead's) gives those masses on any diameters."""
    scene = pair_scene(density_si=[3900.0, 7800.0])
    kg = model_from_scene(scene).masses * scene.scales.mass
    assert kg == pytest.approx([rho * math.pi * D**3 / 6 for rho in (3900.0, 7800.0)],
                               rel=1e-14)
    dimer = {"chain": {"n": 4, "boundary": "free"},
             "beads": {"pattern": "dimer", "ratio": 0.5, "mass": [1.0, 0.5, 2.0, 0.25]}}
    scene = load_scene(dimer)  # no [material]: masses are ratios
    assert model_from_scene(scene).masses == pytest.approx([1.0, 0.5, 2.0, 0.25], rel=1e-15)
    assert scene.data["beads"]["density"] == pytest.approx([1.0, 4.0, 2.0, 2.0], rel=1e-15)


def test_one_value_stands_for_every_bead_and_the_material_fills_in():
    """E without nu takes material.nu (and nu without E material.E); the same material as the
    [material] is ratio 1, the homogeneous chain."""
    nu_only = pair_scene(nu=0.3).data["beads"]["modulus"]
    assert nu_only == pytest.approx((1 - 0.21**2) / (1 - 0.3**2), rel=1e-14)
    e_only = pair_scene(E=[338e9, 169e9]).data["beads"]["modulus"]
    assert e_only == pytest.approx([1.0, 0.5], rel=1e-14)
    same = pair_scene(law="schwarz", E=338e9, nu=0.21, w=0.146, density_si=3900.0)
    assert same.mixture is None
    assert same.data["beads"]["adhesion"] == 1.0 and same.data["beads"]["density"] == 1.0


def test_resolved_scene_holds_the_ratios():
    """The SI keys are consumed: the stored TOML has the ratios, which load back to the same
    data; sources say where each ratio came from."""
    scene = pair_scene(E=[338e9, 200e9], w=0.1, mass=[1.0, 2.0])
    b = scene.data["beads"]
    assert all(b[k] is None for k in ("E", "nu", "w", "density_si", "mass"))
    assert scene.sources["beads.modulus"] == "beads.E"
    assert scene.sources["beads.adhesion"] == "beads.w"
    assert scene.sources["beads.density"] == "beads.mass"
    text = scene.to_toml()
    assert "E = [" not in text and "mass" not in text and "modulus = [" in text
    again = load_scene(tomllib.loads(text))
    assert again.data == scene.data


# ---- refusals --------------------------------------------------------------------------------
MAT_FILE = """[material]
diameter = 2.5e-6
E = 338e9
nu = 0.21
w = 0.146
density = 3900.0
[chain]
n = 2
boundary = "free"
[beads]
"""

REFUSED = [
    ("modulus = 2.0\nE = 200e9\n", [], "beads.E"),
    ("modulus = 2.0\nnu = 0.3\n", [], "beads.nu"),
    ("adhesion = 2.0\nw = 0.1\n", [], "beads.w"),
    ("density = 2.0\ndensity_si = 7800.0\n", [], "beads.density_si"),
    ("density = 2.0\nmass = 2.0\n", [], "beads.mass"),
    ("density_si = 7800.0\nmass = 2.0\n", [], "beads.density_si"),
    ("E = 1e3\n", [], "beads.E"),  # ratio 3e-9
    ("nu = [0.3, 0.5]\n", [], "beads.nu"),
    ("w = [0.146, 1e-6]\n", [], "beads.w"),  # ratio 7e-6, bead 2
    ("density_si = 1.0\n", [], "beads.density_si"),  # ratio 2.6e-4
    ("mass = 1e4\n", [], "beads.mass"),
    ("E = [338e9, 200e9, 100e9]\n", [], "beads.E"),  # 3 values for 2 beads
    ("w = 0.1\npair_adhesion = 2.0\n", [], "beads.w"),
    ("E = 200e9\n", ["--set", "material.K=1e11"], "beads.E"),
]


@pytest.mark.parametrize("beads, extra, key", REFUSED)
def test_refusals_exit_2_naming_the_key(beads, extra, key, tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(MAT_FILE + beads)
    assert main(["info", str(path), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"error: {key}:" in err


@pytest.mark.parametrize("key, value", [("beads.E", 200e9), ("beads.nu", 0.3),
                                        ("beads.w", 0.1), ("beads.density_si", 7800.0)])
def test_si_keys_need_a_material(key, value, capsys):
    assert main(["info", "collision-pair", "--set", f"{key}={value}"]) == 2
    err = capsys.readouterr().err
    assert f"{key}: needs a [material] table with a diameter" in err


def test_mass_needs_no_material():
    scene = load_scene("collision-pair", [("beads.mass", 2.0)])
    assert scene.data["beads"]["density"] == 2.0


def test_out_of_range_names_the_bead():
    with pytest.raises(SceneError) as err:
        pair_scene(w=[0.146, 1e-6])
    assert err.value.key == "beads.w" and "bead 2 gives beads.adhesion" in str(err.value)


def test_overrides_replace_the_other_way(tmp_path, capsys):
    """--set of one way drops the file's other way (as material.K/E and X/X_si do)."""
    path = tmp_path / "s.toml"
    path.write_text(MAT_FILE + "modulus = 2.0\nadhesion = 2.0\ndensity = 2.0\n")
    by_si = load_scene(str(path), [("beads.E", 200e9), ("beads.w", 0.146),
                                   ("beads.mass", 3.0)]).data["beads"]
    assert by_si["modulus"] == pytest.approx(200e9 / 338e9, rel=1e-14)
    assert by_si["adhesion"] == 1.0 and by_si["density"] == 3.0
    path.write_text(MAT_FILE + "E = 200e9\nnu = 0.3\nw = 0.1\ndensity_si = [3900.0, 7800.0]\n")
    back = load_scene(str(path), [("beads.modulus", 1.5), ("beads.adhesion", 1.5),
                                  ("beads.density", 1.5)]).data["beads"]
    assert (back["modulus"], back["adhesion"], back["density"]) == (1.5, 1.5, 1.5)
    swap = load_scene(str(path), [("beads.mass", 2.0)]).data["beads"]
    assert swap["density"] == 2.0
    assert main(["info", str(path), "--json"]) == 0  # mdgran info prints the mixture
    info = json.loads(capsys.readouterr().out)
    assert info["mixture"]["mass"] == pytest.approx([1.0, 2.0], rel=1e-14)


def test_the_docs_example_loads():
    """The TOML example of docs/mixtures.md, as a user would copy it: every second bead has the
    steel-like modulus ratio and twice the density."""
    from pathlib import Path
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "mixtures.md").read_text()
    block = re.search(r"## Beads of real materials[\s\S]*?\n((?:    \S.*\n)(?:    .*\n|\n)*)",
                      text)
    toml = "\n".join(line[4:] for line in block.group(1).splitlines())
    b = load_scene(tomllib.loads(toml)).data["beads"]
    k = (200e9 / (1 - 0.3**2)) / (338e9 / (1 - 0.21**2))
    assert b["modulus"] == pytest.approx([1.0, k, 1.0, k], rel=1e-14)
    assert b["density"] == pytest.approx([1.0, 2.0, 1.0, 2.0], rel=1e-15)
