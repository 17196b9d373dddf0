"""Scene overrides: load_scene(name, overrides) and Scene.with_overrides accept the same keys."""
import dataclasses
import keyword
import pickle

import pytest

from mdgran.model.scene import SCHEMA, SceneError, builtin_scenes, load_scene

# keys with two ways of being given (fc for lambda; SI for nondimensional); micro-star has a
# [material] and a schwarz law
OTHER_WAY = [("contact.fc", -1.8), ("contact.lambda", 1.5), ("impulse.velocity_si", 0.3),
             ("substrate.k1_si", 10.0), ("substrate.k3_si", 1e9), ("contact.damping_si", 2e-7),
             ("run.duration_si", 1e-6), ("substrate.k1", 0.02), ("run.dt", 0.005)]


@pytest.mark.parametrize("key, value", OTHER_WAY)
def test_with_overrides_accepts_what_load_scene_accepts(key, value):
    loaded = load_scene("micro-star", [(key, value)])
    assert load_scene("micro-star").with_overrides([(key, value)]).data == loaded.data
    assert loaded.with_overrides([("run.dt", 0.001)]).data["run"]["dt"] == 0.001  # re-resolves


def test_with_overrides_of_si_key_on_a_scene_without_material_names_it():
    with pytest.raises(SceneError, match=r"substrate\.k1_si: needs a \[material\]"):
        load_scene("collision-pair").with_overrides([("substrate.k1_si", 1.0)])


@pytest.mark.parametrize("key", ["contact.fcc", "substrate.k1si", "runs.dt", "dt"])
def test_with_overrides_rejects_bad_key_naming_it(key):
    with pytest.raises(SceneError) as exc:
        load_scene("micro-star").with_overrides([(key, 1.0)])
    assert exc.value.key == key and str(exc.value).startswith(f"{key}: ")
    with pytest.raises(SceneError) as exc2:
        load_scene("micro-star", [(key, 1.0)])
    assert str(exc2.value) == str(exc.value)


@pytest.mark.parametrize("name", ["macro-hertz", "hard/jkr-force", "hard/dmt", "micro-star"])
def test_a_resolved_scene_resolves_again_to_itself(name):
    """Resolved data stores absent keys as None (lambda of a jkr, dmt or hertz scene); resolving
    it again, as native_lammps.probe_force does with a modified copy, gives the same data."""
    from mdgran.model.scene import resolve

    sc = load_scene(name)
    data = {k: dict(v) for k, v in sc.data.items()}
    if data["contact"].get("fc") is not None:  # a scene that gives fc: lambda is only its default
        data["contact"].pop("lambda", None)
    assert resolve(data) == sc.data


def test_numpy_numbers_are_numbers():
    """A scene given as a dict may hold NumPy integers, floats and booleans (values computed
    with NumPy): they are read as the Python numbers they are."""
    import numpy as np

    from mdgran.api import run as api_run

    res = api_run({"chain": {"n": np.int64(4)}, "impulse": {"velocity": np.float32(2.0)},
                   "run": {"duration": np.float64(1.0)}, "output": {"contacts": np.bool_(True)}})
    assert res.status == "complete"
    assert res.trajectory.x.shape[1] == 4


def test_the_impulse_velocity_message_names_its_limit(capsys):
    """The one-line refusal of impulse.velocity names the limit the check applies (5e3)."""
    from mdgran.cli import main

    assert main(["info", "micro-star", "--set", "impulse.velocity=5001"]) == 2
    err = capsys.readouterr().err
    assert "|v| <= 5e3" in err and "5001" in err


def _record_value(record, key: str):
    """``record``'s field for scene key ``key`` (``lambda`` is the field ``lambda_``)."""
    return getattr(record, key + "_" if keyword.iskeyword(key) else key)


@pytest.mark.parametrize("name", sorted(builtin_scenes()))
def test_section_records_hold_the_scene_data(name):
    """Every key of every section of a built-in scene is a field of the section's record
    (``scene.run.dt``) with the value ``scene.data`` holds (a list as a tuple of the same
    numbers), and nothing else is; records and the scene refuse assignment."""
    scene = load_scene(name)
    assert set(scene.data) == set(SCHEMA)
    for sec, table in scene.data.items():
        record = getattr(scene, sec)
        assert [f.name.rstrip("_") for f in dataclasses.fields(record)] == list(table)
        for key, value in table.items():
            got = _record_value(record, key)
            if isinstance(value, list):
                assert isinstance(got, tuple) and list(got) == value, f"{sec}.{key}"
            else:
                assert type(got) is type(value) and got == value, f"{sec}.{key}"
        first = dataclasses.fields(record)[0].name
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(record, first, getattr(record, first))
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.run = scene.run


def test_section_records_follow_overrides_and_copies():
    """An override, a pickled copy and a run's own copy (after ``data`` was changed) each
    build their records from their own data."""
    scene = load_scene("driven/shaken", [("run.dt", 0.005), ("contact.lambda", 1.25)])
    assert (scene.run.dt, scene.contact.lambda_) == (0.005, 1.25)
    assert scene.base.values[:3] == tuple(scene.data["base"]["values"][:3])
    back = pickle.loads(pickle.dumps(scene))
    assert back == scene and back.run == scene.run and back.base == scene.base
    scene.data["impulse"]["velocity"] = 3.0
    assert scene.own_copy().impulse.velocity == 3.0
