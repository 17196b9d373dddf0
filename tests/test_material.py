"""Scenes in SI that mean what they say: a [material] derives lambda, is complete or
an error, SI keys follow one rule, load_scene takes mappings and Scenes, and the key reference
docs/scene_keys.md is generated from the schema."""
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from mdgran.cli import main, scene_info
from mdgran.model.contact import fc_from_lambda
from mdgran.model.scene import Scene, SceneError, key_reference, load_scene, tomllib
from mdgran.model.units import INFO_KEYS, scales_from_material

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "scenes.md"


def silica_from_docs() -> str:
    """The worked example of docs/scenes.md, as a user would copy it."""
    text = DOC.read_text(encoding="utf-8")
    block = re.search(r"## Worked example.*?```toml\n(.*?)```", text, re.S)
    assert block, "docs/scenes.md has no worked TOML example"
    return block.group(1)


def lambda_by_hand(d, E, nu, w, D0=0.165e-9):
    """docs/physics.md section 1: lambda = 2.06 / D0 (R w^2 / (pi K^2))^(1/3), R = d/4,
    K = E / (2 (1 - nu^2))."""
    K = E / (2.0 * (1.0 - nu * nu))
    return 2.06 / D0 * ((d / 4.0) * w * w / (math.pi * K * K)) ** (1.0 / 3.0)


SILICA = {"diameter": 5e-6, "E": 73e9, "nu": 0.17, "w": 0.05, "density": 2200.0}


@pytest.fixture
def silica_file(tmp_path):
    f = tmp_path / "silica.toml"
    f.write_text(silica_from_docs())
    return f


def test_silica_from_the_docs_takes_lambda_from_its_material(silica_file, capsys):
    by_hand = lambda_by_hand(5e-6, 73e9, 0.17, 0.05)
    assert by_hand == pytest.approx(1.1107, abs=1e-4)
    scene = load_scene(str(silica_file))
    assert scene.data["contact"]["lambda"] == pytest.approx(by_hand, rel=1e-12)
    assert scene.lambda_source == "material" and scene.sources["contact.lambda"] == "material"
    # the contact law uses it
    assert scene.law.fc == fc_from_lambda(scene.data["contact"]["lambda"])
    assert scene.law.fc == pytest.approx(-1.72901, abs=1e-5)
    info = scene_info(scene)
    assert info["maugis_lambda"] == pytest.approx(1.1107, abs=1e-3)
    assert info["contact_lambda"] == pytest.approx(1.1107, abs=1e-3)
    assert info["lambda_source"] == "material" and info["fc_rule"] == "cos"
    # and so does mdgran info
    assert main(["info", str(silica_file), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["contact_lambda"] == pytest.approx(1.1107, abs=1e-3)
    assert out["lambda_source"] == "material" and out["fc"] == pytest.approx(-1.72901, abs=1e-5)
    # the SI keys of the example mean SI
    assert out["impulse_velocity_m_per_s"] == pytest.approx(0.5, rel=1e-12)
    assert out["k1_N_per_m"] == pytest.approx(21.5, rel=1e-12)
    assert scene.data["run"]["duration"] * scene.scales.time_unit_s == pytest.approx(1e-6)


def test_the_docs_print_what_mdgran_info_prints(silica_file, capsys):
    """The info output quoted in docs/scenes.md is the current one."""
    assert main(["info", str(silica_file)]) == 0
    printed = capsys.readouterr().out.replace(str(silica_file.stem), "silica")
    quoted = re.search(r"`mdgran info silica.toml` prints:\n\n```\n(.*?)```",
                       DOC.read_text(encoding="utf-8"), re.S).group(1)
    assert quoted == printed


@pytest.mark.parametrize("given, source, lam", [
    ({"lambda": 0.3}, "scene", 0.3),
    ({"fc": -1.8}, None, None),
    ({}, "material", 1.1107015695959759),
])
def test_an_explicit_lambda_or_fc_wins_over_the_material(given, source, lam):
    sc = load_scene({"material": dict(SILICA), "contact": given})
    assert sc.lambda_source == source
    if lam is None:
        assert sc.data["contact"]["lambda"] is None and sc.law.fc == -1.8
    else:
        assert sc.data["contact"]["lambda"] == pytest.approx(lam, rel=1e-12)


def test_overrides_set_or_rederive_lambda():
    sc = load_scene({"material": dict(SILICA)})
    # a material override derives lambda again, as loading with it would
    bigger = sc.with_overrides([("material.diameter", 40e-6)])
    assert bigger.data["contact"]["lambda"] == pytest.approx(
        lambda_by_hand(40e-6, 73e9, 0.17, 0.05), rel=1e-12)
    assert bigger.data == load_scene({"material": dict(SILICA)},
                                     [("material.diameter", 40e-6)]).data
    given = sc.with_overrides([("contact.lambda", 0.64)])
    assert given.data["contact"]["lambda"] == 0.64 and given.lambda_source == "scene"
    # SI keys are converted again at the new scales too
    si = load_scene({"material": dict(SILICA), "substrate": {"k1_si": 21.5}})
    moved = si.with_overrides([("material.diameter", 40e-6)])
    assert moved.data["substrate"]["k1"] * moved.scales.stiffness == pytest.approx(21.5)


def test_without_material_lambda_is_the_default():
    sc = load_scene({})
    assert sc.data["contact"]["lambda"] == 0.64 and sc.lambda_source == "default"
    assert scene_info(sc)["lambda_source"] == "default"


@pytest.mark.parametrize("drop, key, names", [
    (("density",), "material.density", "missing:"),
    (("E", "nu"), "material", "missing E, nu:"),
    (("diameter", "w"), "material", "missing diameter, w:"),
])
def test_an_incomplete_material_is_one_line_naming_what_is_missing(drop, key, names, tmp_path,
                                                                   capsys):
    mat = {k: v for k, v in SILICA.items() if k not in drop}
    with pytest.raises(SceneError) as exc:
        load_scene({"material": mat})
    msg = str(exc.value)
    assert exc.value.key == key and msg.startswith(f"{key}: {names}") and "\n" not in msg
    for allowed in ("diameter", "E (Pa) or K", "nu", "w (J/m^2)", "density", "modulus", "D0"):
        assert allowed in msg
    f = tmp_path / "m.toml"
    f.write_text("[material]\n" + "".join(f"{k} = {v!r}\n" for k, v in mat.items()))
    assert main(["info", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and key in err and "Traceback" not in err


def test_material_k_instead_of_e():
    K = 73e9 / (2 * (1 - 0.17**2))
    mat = {k: v for k, v in SILICA.items() if k != "E"} | {"K": K}
    sc = load_scene({"material": mat})
    assert sc.data["contact"]["lambda"] == pytest.approx(1.1107015695959759, rel=1e-12)
    assert sc.data["material"]["modulus"] is None
    with pytest.raises(SceneError, match=r"^material\.K: give material\.E"):
        load_scene({"material": dict(SILICA, K=K)})
    with pytest.raises(SceneError, match=r"^material\.modulus: "):
        load_scene({"material": dict(mat, modulus="text")})
    # an override of K replaces the file's E (and its modulus), and back
    swapped = load_scene({"material": dict(SILICA, modulus="table")}, [("material.K", K)])
    assert swapped.data["material"]["E"] is None
    assert swapped.data["contact"]["lambda"] == pytest.approx(1.1107015695959759, rel=1e-12)
    back = swapped.with_overrides([("material.E", 73e9)])
    assert back.data["material"]["K"] is None and back.data["material"]["modulus"] == "table"


@pytest.mark.parametrize("key", ["modulus", "D0"])
def test_material_refinements_alone_are_refused(key):
    with pytest.raises(SceneError, match=rf"^material\.{key}: refines a \[material\]"):
        load_scene({"material": {key: "text" if key == "modulus" else 1e-10}})
    # what every resolved scene without a material stores, modulus = "table", is accepted
    assert load_scene({"material": {"modulus": "table"}}).scales is None


@pytest.mark.parametrize("si, plain, value", [
    ("impulse.velocity_si", "impulse.velocity", 0.5),
    ("substrate.k1_si", "substrate.k1", 21.5),
    ("contact.damping_si", "contact.damping", 1e-7),
    ("run.duration_si", "run.duration", 1e-6),
    ("substrate.k3_si", "substrate.k3", 1e9),
])
def test_si_rule(si, plain, value):
    sec, name = si.split(".")
    with pytest.raises(SceneError, match=rf"^{re.escape(si)}: needs a \[material\]"):
        load_scene({sec: {name: value}})
    both = {"material": dict(SILICA), sec: {name: value, plain.split(".")[1]: 1.0}}
    with pytest.raises(SceneError, match=rf"^{re.escape(si)}: give {re.escape(plain)} or "):
        load_scene(both)
    sc = load_scene({"material": dict(SILICA), sec: {name: value}})
    assert sc.sources[plain] == si and sc.data[sec][name] is None


def test_load_scene_takes_a_mapping_and_a_scene():
    mapping = {"chain": {"n": 3}, "material": dict(SILICA)}
    sc = load_scene(mapping, [("impulse.velocity", 2.0)])
    assert sc.name == "custom" and sc.data["chain"]["n"] == 3
    assert mapping == {"chain": {"n": 3}, "material": dict(SILICA)}  # left as it was
    assert load_scene(sc) is sc
    again = load_scene(sc, [("chain.n", 5)])
    assert again.data["chain"]["n"] == 5 and again.data["impulse"]["velocity"] == 2.0
    assert load_scene(mapping, name="silica").name == "silica"
    # the same scene as a file and as a mapping
    assert load_scene("micro-star").data == load_scene(
        tomllib.loads((ROOT / "mdgran/scenes/micro-star.toml").read_text())).data


@pytest.mark.parametrize("bad, key", [
    ({"chain": 3}, "chain"),
    ({"chain": {"m": 3}}, "chain.m"),
    ({"chains": {}}, "chains"),
    ({"contact": {"lambda": -1.0}}, "contact.lambda"),
    ({"material": dict(SILICA, nu=0.6)}, "material.nu"),
])
def test_mapping_errors_name_the_key(bad, key):
    with pytest.raises(SceneError) as exc:
        load_scene(bad)
    assert exc.value.key == key and str(exc.value).startswith(f"{key}: ")


def test_load_scene_refuses_other_types():
    with pytest.raises(SceneError, match=r"^scene: must be a built-in scene name"):
        load_scene(42)


def test_scales_attributes_are_the_info_keys():
    """mdgran info's keys from Scales.as_dict are attributes of the same names and values."""
    s = load_scene("micro-star").scales
    d = s.as_dict()
    assert tuple(d) == INFO_KEYS
    for k, v in d.items():
        assert getattr(s, k) == v, k
    assert s.time_unit_s == s.time and s.eta_N == s.eta and s.p_m == s.p
    info = scene_info(load_scene("micro-star"))
    for k in ("eta_N", "p_m", "stiffness_scale_N_per_m", "damping_scale_Ns_per_m",
              "time_unit_s", "maugis_lambda"):  # docs/cli.md's documented info keys
        assert info[k] == getattr(s, k)


def test_scales_from_material_strict():
    with pytest.raises(ValueError, match="material lacks E, nu, w, density"):
        scales_from_material({"diameter": 1e-6}, fill=None)
    s = scales_from_material(dict(SILICA), fill=None)
    assert s.D0 == 0.165e-9 and s.maugis_lambda == pytest.approx(1.1107015695959759)


# the built-in scenes keep their numbers: values recorded before the material change
BUILTIN = {
    "micro-star": {"fc": -1.8518239686741345, "lambda": 0.64, "k1": 0.012106948922495099,
                   "damping": 0.013284845176951263, "maugis_lambda": 0.6415232484019778,
                   "time_unit_s": 4.2387690324675206e-09, "source": "scene"},
    "macro-hertz": {"fc": None, "lambda": None, "k1": 0.012106948922495095,
                    "damping": 0.013275276642510481, "source": None},
    "collision-pair": {"fc": -1.8518239686741345, "lambda": 0.64, "source": "scene"},
}


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_builtin_scenes_keep_their_numbers(name):
    sc = load_scene(name)
    want = BUILTIN[name]
    info = scene_info(sc)
    assert info["fc"] == want["fc"] and sc.data["contact"]["lambda"] == want["lambda"]
    assert sc.lambda_source == want["source"] and info["fc_rule"] == (
        "cos" if want["fc"] is not None else None)
    for k in ("k1", "damping", "maugis_lambda", "time_unit_s"):
        if k in want:
            assert info[k] == want[k], k


def test_key_reference_is_generated_and_current():
    """docs/scene_keys.md is what reference/make_scene_keys.py writes from the schema."""
    text = (ROOT / "docs" / "scene_keys.md").read_text(encoding="utf-8")
    assert text == key_reference(), "docs/scene_keys.md is stale: python reference/make_scene_keys.py"
    for key in ("contact.fc_rule", "impulse.velocity_si", "material.D0", "contact.lambda"):
        assert f"`{key}`" in text
    r = subprocess.run([sys.executable, str(ROOT / "reference" / "make_scene_keys.py"),
                        "--check"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_a_scene_from_resolved_data_still_works():
    sc = load_scene("micro-star")
    bare = Scene(sc.name, sc.data)
    assert bare.law == sc.law and bare.lambda_source == "scene"
    assert bare.with_overrides([("chain.n", 4)]).data["chain"]["n"] == 4
