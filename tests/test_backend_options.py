"""Backend options: a misspelt one is rejected by name on every backend; the Richardson factor
of a fixed-step run follows the order of the backend as constructed."""
import pytest

from mdgran.backends import get_backend
from mdgran.model.scene import SceneError, load_scene
from mdgran.simulation import make_backend, run

SCENE = load_scene("collision-pair", [("run.duration", 0.1)])


@pytest.mark.parametrize("backend, bad", [
    ("reference", "tolerence"),
    ("fast", "locate_event"),
    pytest.param("lammps", "table_point", marks=pytest.mark.lammps),
])
def test_misspelt_option_is_rejected_by_name(backend, bad):
    with pytest.raises(SceneError) as exc:
        run(SCENE, backend, **{bad: False})
    msg = str(exc.value)
    assert exc.value.key == bad and msg.startswith(f"{bad}: ") and "\n" not in msg
    for name in get_backend(backend).accepted_options:  # what is allowed
        assert name in msg


@pytest.mark.parametrize("backend, options", [
    ("reference", {"tolerance": 1e-9}),
    ("fast", {"locate_events": False, "contact_eval": "exact", "table_points": 2001,
              "delta_max": 50.0, "dt": 0.005}),
])
def test_accepted_options_still_run(backend, options):
    assert run(SCENE, backend, **options).status == "complete"


def test_richardson_factor_follows_the_order_as_constructed():
    step = make_backend(SCENE, "fast", locate_events=False)
    assert step.order == 1 and step.refinement(SCENE)[1] == pytest.approx(2.0)
    located, factor = make_backend(SCENE, "fast").refinement(SCENE)
    assert located == [("run.dt", 0.005)] and factor == pytest.approx(4.0 / 3.0)
    assert make_backend(SCENE, "fast").refinement()[1] == pytest.approx(4.0 / 3.0)
    assert make_backend(SCENE, "reference").refinement(SCENE) == ([("run.tolerance", 1e-12)], 1.0)


# ---- backend specs: "fast:quantized", "lammps:native", "fast:dt=0.005" ---------------------

def test_spec_runs_what_the_explicit_options_run():
    import numpy as np

    by_spec = run(SCENE, "fast:quantized:dt=0.005")
    explicit = run(SCENE, "fast", locate_events=False, dt=0.005)
    default = run(SCENE, "fast")
    assert np.array_equal(by_spec.trajectory.x, explicit.trajectory.x)
    assert not np.array_equal(by_spec.trajectory.x, default.trajectory.x)  # the spec mattered
    assert by_spec.stats["options"] == {"locate_events": False, "dt": 0.005}
    assert "options" not in default.stats  # a run with no options stores none


@pytest.mark.parametrize("spec, words", [
    ("fats", "reference, lammps, fast"),
    ("fast:native", "located, quantized, or KEY=VALUE"),
    ("reference:quantized", "KEY=VALUE"),
    ("fast:dt=0.005:dt_max=1", "dt_max"),  # an option the backend does not take
])
def test_bad_spec_is_one_line_naming_what_is_allowed(spec, words):
    with pytest.raises(SceneError) as exc:
        run(SCENE, spec)
    msg = str(exc.value)
    assert "\n" not in msg and words in msg


def test_spec_and_keyword_must_agree():
    with pytest.raises(SceneError) as exc:
        run(SCENE, "fast:quantized", locate_events=True)
    assert exc.value.key == "backend" and "locate_events" in str(exc.value)
    assert run(SCENE, "fast:quantized", locate_events=False).status == "complete"


def test_cli_backend_spec_and_contact_flag(tmp_path, capsys):
    import json

    import h5py

    from mdgran.cli import main

    out = tmp_path / "q.h5"
    assert main(["run", "collision-pair", "--set", "run.duration=0.1", "--backend",
                 "fast:quantized", "--out", str(out), "--quiet"]) == 0
    with h5py.File(out) as f:
        stats = json.loads(f["parameters"].attrs["backend_stats"])
    assert stats["options"] == {"locate_events": False}
    # --contact belongs to lammps: another backend rejects it by its flag, nothing written
    assert main(["run", "collision-pair", "--backend", "fast", "--contact", "native",
                 "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mdgran: --contact") or "--contact" in err.splitlines()[-1]
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize("spec, key", [
    ("fast:table_points=1", "fast:table_points"), ("fast:delta_max=-5", "fast:delta_max"),
    ("fast:dt=0", "fast:dt"), ("lammps:dt=nan", "lammps:dt"),
    ("reference:tolerance=x", "reference:tolerance"),
    ("fast:locate_events=maybe", "fast:locate_events"),
    ("reference:tolerance=0", "reference:tolerance"),  # never ended
    ("reference:tolerance=1", "reference:tolerance"),  # a bound of 64 E_imp
    ("lammps:events=sometimes", "lammps:events")])
def test_bad_option_value_is_one_line_exit_2(spec, key, tmp_path, capsys):
    """An option's value goes through the checks of a scene key: one line naming
    BACKEND:OPTION and what is allowed, exit 2, before anything runs (these gave tracebacks,
    or were accepted)."""
    from mdgran.cli import main

    out = tmp_path / "r.h5"
    assert main(["run", "micro-star", "--backend", spec, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{key}: must be" in err[0], err
    assert not out.exists()
    with pytest.raises(SceneError, match=key):
        make_backend(load_scene("micro-star"), spec)


@pytest.mark.parametrize("backend", ["fast", pytest.param("lammps", marks=pytest.mark.lammps)])
@pytest.mark.parametrize("dt", [0.003, 0.02])
def test_a_step_that_does_not_divide_the_output_interval_is_refused(backend, dt):
    """collision-pair writes every 0.01: dt = 0.003 (3.33 steps a frame) and dt = 0.02 (half a
    step) cannot land on the output times; the fixed-step backends refuse both by run.dt."""
    with pytest.raises(SceneError) as exc:
        make_backend(SCENE, backend, dt=dt)
    assert exc.value.key == "run.dt"
    assert str(exc.value) == f"run.dt: must divide run.output_interval = 0.01 (dt = {dt})"


def test_steps_per_frame_counts_the_steps_of_an_output_interval():
    from mdgran.backends.base import steps_per_frame

    assert steps_per_frame(0.001, 0.01) == 10
    assert steps_per_frame(0.1 / 3, 0.1) == 3  # within round-off of the interval
    assert steps_per_frame(0.01, 0.01) == 1
