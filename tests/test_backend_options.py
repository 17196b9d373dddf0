"""Backend options: a misspelt one is rejected by name on every backend; the Richardson factor
of a fixed-step run follows the order of the backend as constructed."""
import pytest

from mdgran.backends import get_backend
from mdgran.scene import SceneError, load_scene
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
