"""The Python API: ``mdgran.run``/``read``/``scenes``/``load_scene``/``Scene``, short
reprs, errors that name Python parameters, and a light ``import mdgran``."""
import math
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import mdgran
from mdgran.model.scene import SCENE_DIR, SceneError
from mdgran.simulation import RunResult
from mdgran.output.run_record import LEDGER_NAMES, Run

SHORT = {"run.duration": 3.0}  # micro-star to t = 3: the primary pulse, ~0.5 s on reference


def same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def assert_same_trajectory(a: Run, b: Run):
    for name in ("time", "x", "v", "ev_time", "ev_contact", "ev_kind"):
        assert same_bits(getattr(a, name), getattr(b, name)), name
    for name in LEDGER_NAMES:
        assert same_bits(a.ledger[name], b.ledger[name]), name
    assert a.scene_toml == b.scene_toml
    assert a.backend == b.backend


def test_import_mdgran_imports_nothing_heavy():
    code = ("import sys, mdgran; "
            "print(sorted(m for m in ('numpy', 'scipy', 'h5py', 'matplotlib', 'numba') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout.strip()
    assert out == "[]"


def test_public_names():
    for name in ("run", "read", "scenes", "load_scene", "Scene", "SceneError", "RunResult",
                 "Run", "Trajectory", "IntegrationError", "BackendUnavailable"):
        assert name in mdgran.__all__ and name in dir(mdgran)
        assert getattr(mdgran, name) is not None
    assert mdgran.Scene is mdgran.model.scene.Scene
    assert mdgran.Trajectory is mdgran.Run  # the former name, an alias
    assert "micro-star" in mdgran.scenes() and "hard/tiny" in mdgran.scenes()
    with pytest.raises(AttributeError, match="no_such_name"):
        mdgran.no_such_name  # noqa: B018


def test_run_by_name_path_dict_scene_is_bitwise_identical():
    path = SCENE_DIR / "micro-star.toml"
    data = tomllib.loads(path.read_text())
    forms = {
        "name": "micro-star",
        "path str": str(path),
        "pathlib": path,
        "dict": data,
        "Scene": mdgran.load_scene("micro-star"),
    }
    results = {k: mdgran.run(v, "reference", set=SHORT) for k, v in forms.items()}
    base = results["name"].trajectory
    assert base.frames == 31 and base.n == 20
    for k, res in results.items():
        assert res.status == "complete", k
        assert_same_trajectory(base, res.trajectory)
    assert data == tomllib.loads(path.read_text())  # the caller's mapping is left as it was


@pytest.mark.parametrize("given", [
    {"run.duration": 3.0, "impulse.velocity": 5},
    {"run": {"duration": 3.0}, "impulse": {"velocity": 5}},
    [("run.duration", 3.0), ("impulse.velocity", 5)],
    ["run.duration=3.0", "impulse.velocity=5"],
])
def test_set_forms_give_the_same_scene(given):
    from mdgran.api import as_scene, _overrides

    expected = mdgran.load_scene("micro-star", [("run.duration", 3.0), ("impulse.velocity", 5)])
    assert as_scene("micro-star", _overrides(given)).data == expected.data
    assert as_scene(mdgran.load_scene("micro-star"), _overrides(given)).data == expected.data


def test_unknown_keyword_is_refused_naming_it(tmp_path):
    out = tmp_path / "r.h5"
    with pytest.raises(TypeError, match="'bogus_option'"):
        mdgran.run("micro-star", "reference", out, bogus_option=1)
    with pytest.raises(TypeError, match="'dt'.*backend 'reference' takes tolerance"):
        mdgran.run("micro-star", "reference", out, dt=0.01)  # a fast/lammps option
    with pytest.raises(TypeError, match=r"'duration'.*set=\{'run.duration'"):
        mdgran.run("micro-star", "reference", out, duration=3.0)  # a scene key: use set=
    with pytest.raises(TypeError):  # out and backend only by position or name, set by name
        mdgran.run("micro-star", "reference", out, SHORT)
    assert not list(tmp_path.iterdir())  # refused before anything ran


@pytest.mark.parametrize("kwargs,key", [
    ({"scene": "no-such-scene"}, "scene"),
    ({"scene": 42}, "scene"),
    ({"scene": "micro-star", "backend": "nope"}, "backend"),
    ({"scene": "micro-star", "out": "OUTDIR/"}, "out"),
    ({"scene": "micro-star", "set": "run.duration=3"}, "set"),
    ({"scene": "micro-star", "set": {"run.durationx": 3}}, "run.durationx"),
    ({"scene": {"chain": {"n": 0}}}, "chain.n"),
    ({"scene": {"chain": 5}}, "chain"),
])
def test_bad_input_names_the_python_parameter(kwargs, key, tmp_path):
    if "out" in kwargs:
        kwargs["out"] = str(tmp_path) + "/"
    with pytest.raises(SceneError) as info:
        mdgran.run(**kwargs)
    assert info.value.key == key
    assert str(info.value).startswith(f"{key}: ")
    assert "--" not in str(info.value) and "SCENE" not in str(info.value)


def test_read_equals_the_run_in_memory(tmp_path):
    out = tmp_path / "ms.h5"
    res = mdgran.run("micro-star", "reference", out=out, set=SHORT)
    back = mdgran.read(out)
    assert isinstance(back, Run)
    assert_same_trajectory(res.trajectory, back)
    assert back.attrs["status"] == res.trajectory.attrs["status"] == "complete"
    assert back.attrs["scene_name"] == "micro-star"
    assert back.scene.data == mdgran.load_scene("micro-star", list(SHORT.items())).data
    assert repr(back) == repr(res.trajectory)


def test_read_refuses_other_files(tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(ValueError, match="not an mdgran H5MD file"):
        mdgran.read(other)
    with pytest.raises(FileNotFoundError):
        mdgran.read(tmp_path / "missing.h5")


def synthetic(frames: int, n: int, events: int, status: str) -> Run:
    return Run(time=np.linspace(0.0, 400.0, frames), x=np.zeros((frames, n)),
               v=np.zeros((frames, n)),
               ledger={k: np.zeros(frames) for k in LEDGER_NAMES},
               ev_time=np.zeros(events), ev_contact=np.zeros(events, np.int64),
               ev_kind=np.zeros(events, np.int8), scene_toml="[chain]\nn = 1000\n",
               backend="fast", attrs={"status": status, "scene_name": "long-chain"})


def test_reprs_are_short():
    long_status = "failed: " + "the step size collapsed at t = 12.3 near bead 999 " * 10
    for status in ("complete", long_status):
        tr = synthetic(4001, 1000, 50_000, status)
        res = RunResult(tr, {"events": 50_000}, status, 3.1e-9, None, 4.0e-7)
        for text in (repr(tr), repr(res)):
            assert len(text) < 300 and "array" not in text and "\n" not in text
        assert "frames=4001, n=1000" in repr(res)
        assert "ledger_error=3.1e-09 (bound 4.0e-07)" in repr(res)
    res = RunResult(None, {"events": 7}, "complete", math.nan)  # keep=False
    assert repr(res).startswith("RunResult(status='complete', events=7")


def test_repr_of_a_real_1000_bead_run():
    res = mdgran.run("micro-star", "reference",
                     set={"chain.n": 1000, "run.duration": 0.2, "run.output_interval": 0.1})
    assert res.trajectory.n == 1000
    text = repr(res)
    assert len(text) < 300 and len(repr(res.trajectory)) < 300
    assert text.startswith("RunResult(scene='micro-star', backend='reference', "
                           "status='complete', frames=3, n=1000")


def test_cli_scenes_still_works():
    p = subprocess.run([sys.executable, "-m", "mdgran", "scenes"], capture_output=True,
                       text=True, timeout=60, env={**os.environ})
    assert p.returncode == 0 and "micro-star" in p.stdout


@pytest.mark.parametrize("side", ["api", "cli"])
def test_an_unfinished_run_is_named_by_the_parameter_or_the_flag(side, tmp_path, capsys):
    """A checkpointed run onto an output whose .partial is there is refused before it runs:
    the API names resume=True, the command line --resume, in the key and the text alike."""
    out = tmp_path / "x.h5"
    partial = tmp_path / "x.h5.partial"
    partial.write_bytes(b"")
    tail = f"{partial} holds an unfinished run: resume it ({{}}), or delete it to start afresh"
    if side == "api":
        with pytest.raises(SceneError) as info:
            mdgran.run("micro-star", "reference", out, set=SHORT, checkpoint_every=60.0)
        assert str(info.value) == "resume: " + tail.format("resume=True")
    else:
        from mdgran.cli import main

        assert main(["run", "micro-star", "--out", str(out), "--set", "run.duration=0.1",
                     "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err == "mdgran: error: --resume: " + tail.format("--resume") + "\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.h5.partial"]


def test_the_cli_shows_a_parameter_named_in_a_message_as_its_flag():
    from mdgran.cli import flag_message

    exc = SceneError("chain.n, run.output_interval", "1 GiB are free at / (out); make chain.n "
                     "smaller")
    assert flag_message(exc) == ("chain.n, run.output_interval: 1 GiB are free at / (--out); "
                                 "make chain.n smaller")
    assert flag_message(SceneError("scene", "'x' is neither")) == "SCENE: 'x' is neither"
    same = SceneError("chain.n", "must be an integer >= 1, not 0")
    assert flag_message(same) == str(same)


def test_the_python_api_runs_without_the_command_line_module():
    code = ("import sys, mdgran\n"
            "try:\n    mdgran.run('micro-star', out='')\nexcept ValueError as exc:\n"
            "    print(exc)\n"
            "print('mdgran.cli' in sys.modules)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.stdout.splitlines() == ["out: must name an output file, e.g. run.h5", "False"]


def test_a_run_keeps_its_own_scene():
    """A Scene changed after a run does not change the run's record, and a change that
    breaks it is refused in one line (it ran into NumPy errors)."""
    from mdgran.model.scene import SceneError, load_scene

    sc = load_scene("micro-star", [("run.duration", 2.0)])
    r1 = mdgran.run(sc, "reference")
    err1 = r1.trajectory.max_ledger_error
    sc.data["impulse"]["velocity"] = 5.0
    r2 = mdgran.run(sc, "reference")
    assert r1.trajectory.scene.data["impulse"]["velocity"] == 12.0
    assert r1.trajectory.max_ledger_error == err1
    assert r2.trajectory.scene.impulse_energy == 12.5 and r1.trajectory.scene.impulse_energy == 72.0
    sc.data["chain"]["n"] = -3
    with pytest.raises(SceneError, match="chain.n"):
        mdgran.run(sc, "reference")
