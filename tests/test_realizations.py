"""Realizations: a sweep runs each grid point K times with the impulse velocity
perturbed, v0 (1 + r eps); the report gives each statistic per realization with its mean and
interval.  The case list, its numbering, the refusals, the interval on numbers with a known
answer, and a tiny sweep of 3 grid points x 3 realizations end to end (fast backend)."""
import json
import math

import numpy as np
import pytest

from mdgran.model.scene import SceneError
from mdgran.studies.paper_study import (interval_over_realizations, realization_groups,
                          realization_statistics, realizations_markdown, sweep_cases)
from mdgran.studies.sweep import load_sweep, run_sweep

GRID = """
[fixed]
"run.duration" = 60.0

[grid]
"substrate.k1_si" = [4.6, 21.5]
"impulse.velocity" = [2.0, 16.0]
"""


def spec(tmp_path, head="", body=GRID, name="sw.toml"):
    path = tmp_path / name
    path.write_text(f'[sweep]\nscene = "micro-star"\nbackend = "fast"\n{head}\n{body}')
    return str(path)


def velocity(case):
    from mdgran.model.scene import load_scene

    return load_scene("micro-star", case["overrides"]).data["impulse"]["velocity"]


def test_realizations_are_the_slowest_axis_with_the_documented_velocities(tmp_path):
    plain = load_sweep(spec(tmp_path, name="plain.toml"))
    eps = 2.5e-3
    sw = load_sweep(spec(tmp_path, f"realizations = 3\nperturbation = {eps!r}"))
    g = len(plain["cases"])
    assert g == 4 and len(sw["cases"]) == 3 * g
    assert sw["realizations"] == 3 and sw["perturbation"] == eps
    assert [c["index"] for c in sw["cases"]] == list(range(3 * g))
    for r in range(3):
        for k, base in enumerate(plain["cases"]):
            c = sw["cases"][r * g + k]
            assert c["params"] == {**base["params"], "realization": r}
            v0 = base["params"]["impulse.velocity"]
            assert velocity(c) == v0 * (1 + r * eps)  # exactly
            if r == 0:  # realization 0 is the unperturbed case, overrides and all
                assert c["overrides"] == base["overrides"]
            else:
                assert [o for o in c["overrides"] if o[0] == "impulse.velocity"] == \
                    [("impulse.velocity", v0 * (1 + r * eps))]
    # v0 from the fixed keys or the scene file, not only from the grid; the default eps
    body = '[grid]\n"substrate.k1_si" = [4.6, 21.5]\n'
    sw = load_sweep(spec(tmp_path, "realizations = 2", body), realizations=None)
    assert [velocity(c) for c in sw["cases"]] == [12.0, 12.0, 12.0 * 1.001, 12.0 * 1.001]
    sw = load_sweep(spec(tmp_path, "realizations = 2", '[fixed]\n"impulse.velocity_si" = 0.5\n'
                         + body))
    v0 = velocity(sw["cases"][0])
    assert v0 != 12.0 and velocity(sw["cases"][3]) == v0 * 1.001
    # run_sweep's (and load_sweep's) realizations replace the file's
    assert len(load_sweep(spec(tmp_path, "realizations = 3"), realizations=2)["cases"]) == 8


def test_one_realization_is_exactly_the_old_sweep(tmp_path):
    plain = load_sweep(spec(tmp_path, name="plain.toml"))
    one = load_sweep(spec(tmp_path, "realizations = 1\nperturbation = 0.01"))
    assert one["cases"] == plain["cases"]
    assert "realizations" not in one and "realization" not in one["cases"][0]["params"]
    for name in ("paper-robustness", "lambda-range"):
        assert load_sweep(name, realizations=1) == load_sweep(name)
    assert load_sweep("paper-robustness", small=True, realizations=2)["cases"][:4] == [
        {**c, "params": {**c["params"], "realization": 0}}
        for c in load_sweep("paper-robustness", small=True)["cases"]]
    # the built-in sweep in realizations: 2 in its small version
    small = load_sweep("paper-realizations", small=True)
    assert small["realizations"] == 2 and len(small["cases"]) == 6


@pytest.mark.parametrize("head, key", [
    ("realizations = 0", "sweep.realizations"),
    ("realizations = -2", "sweep.realizations"),
    ("realizations = 2.0", "sweep.realizations"),
    ('realizations = "3"', "sweep.realizations"),
    ("realizations = true", "sweep.realizations"),
    ("realizations = 2\nperturbation = 0", "sweep.perturbation"),
    ("realizations = 2\nperturbation = -1e-3", "sweep.perturbation"),
    ("realizations = 2\nperturbation = 0.5", "sweep.perturbation"),
    ("realizations = 2\nperturbation = nan", "sweep.perturbation"),
    ("realizations = 2\nperturbation = inf", "sweep.perturbation"),
    ('realizations = 2\nperturbation = "1e-3"', "sweep.perturbation"),
    ("perturbation = true", "sweep.perturbation"),
])
def test_bad_realization_keys_are_refused_in_one_line(tmp_path, head, key):
    with pytest.raises(SceneError) as exc:
        load_sweep(spec(tmp_path, head))
    msg = str(exc.value)
    assert exc.value.key == key and msg.startswith(key + ": ") and "\n" not in msg


def test_refusals_of_the_override_and_of_a_velocity_out_of_range(tmp_path):
    with pytest.raises(SceneError) as exc:
        run_sweep(spec(tmp_path), tmp_path / "out", realizations=0, progress=False)
    assert str(exc.value).startswith("realizations: must be an integer >= 1")
    body = '[grid]\n"impulse.velocity" = [4900.0]\n'
    with pytest.raises(SceneError) as exc:
        load_sweep(spec(tmp_path, "realizations = 2\nperturbation = 0.1", body))
    assert exc.value.key == "sweep.perturbation" and "\n" not in str(exc.value)
    assert not (tmp_path / "out").exists()


def test_interval_on_numbers_with_a_known_answer():
    # K identical values: zero width, exactly
    same = interval_over_realizations([0.1] * 7)
    assert same["mean"] == 0.1 and same["sd"] == 0.0 and same["half_width"] == 0.0
    assert same["interval"] == [0.1, 0.1] and same["K"] == same["n"] == 7
    # 1, 2, 3: mean 2, sd 1, t(0.975, 2) = 4.302652729749464
    r = interval_over_realizations([3.0, 1.0, 2.0])
    assert r["mean"] == 2.0 and r["sd"] == pytest.approx(1.0, rel=1e-15)
    assert r["half_width"] == pytest.approx(4.302652729749464 / math.sqrt(3), rel=1e-12)
    assert (r["min"], r["max"]) == (1.0, 3.0)
    # a normal sample: the t-interval of scipy, and 95% coverage of the true mean
    from scipy import stats

    rng = np.random.default_rng(3)
    x = rng.normal(5.0, 2.0, 8)
    r = interval_over_realizations(x)
    lo, hi = stats.t.interval(0.95, 7, loc=x.mean(), scale=stats.sem(x))
    assert r["interval"] == pytest.approx([lo, hi], rel=1e-12)
    hits = [lo <= 5.0 <= hi for lo, hi in
            (interval_over_realizations(rng.normal(5.0, 2.0, 5))["interval"]
             for _ in range(4000))]
    assert 0.94 < np.mean(hits) < 0.96  # binomial sd 0.0034
    # undefined values are left out; fewer than two: no interval
    r = interval_over_realizations([1.0, float("nan"), 3.0])
    assert (r["K"], r["n"], r["mean"]) == (3, 2, 2.0)
    one = interval_over_realizations([4.0, float("nan")])
    assert one["mean"] == 4.0 and one["interval"] is None and one["sd"] is None


def test_tiny_sweep_in_realizations_and_its_statistics(tmp_path):
    """3 grid points x 3 realizations on the fast backend: a folder run with 1 realization is
    extended (its cases not redone), and the report's statistics come per realization."""
    body = '[fixed]\n"run.duration" = 60.0\n\n[grid]\n"impulse.velocity" = [8.0, 16.0, 32.0]\n'
    path = spec(tmp_path, "realizations = 3\nperturbation = 1e-3", body)
    out = tmp_path / "sw"
    first = run_sweep(path, out, workers=2, progress=False, realizations=1)
    assert len(first) == 3 and "realization" not in first[0]["params"]
    stamps = {i: (out / "cases" / f"{i:04d}.h5").stat().st_mtime_ns for i in range(3)}
    res = run_sweep(path, out, workers=2, progress=False)
    assert len(res) == 9 and all(r["status"] == "complete" for r in res)
    assert [r["params"]["realization"] for r in res] == [0] * 3 + [1] * 3 + [2] * 3
    assert all((out / "cases" / f"{i:04d}.h5").stat().st_mtime_ns == st
               for i, st in stamps.items())  # realization 0 was not run again
    spec_json = json.loads((out / "sweep.json").read_text())
    assert spec_json["realizations"] == 3 and spec_json["perturbation"] == 1e-3
    # a folder with more realizations is not shrunk by a call with fewer
    with pytest.raises(SceneError):
        run_sweep(path, out, progress=False, realizations=2)

    cases = sweep_cases(out)
    assert list(realization_groups(cases)) == [0, 1, 2]
    rz = realization_statistics(cases, small=True, pooled={"Fig. 7 slope (after the impact "
                                                           "transient)": 1.5})
    assert rz["K"] == 3 and rz["realizations"] == [0, 1, 2]
    st = rz["statistics"]
    assert "null z: Fig. 7 slope against C_eff shifted in time" in st
    for name, s in st.items():
        assert len(s["values"]) == 3, name
        fin = [v for v in s["values"] if np.isfinite(v)]
        if len(fin) >= 2:
            lo, hi = s["interval"]
            assert lo <= s["mean"] <= hi and s["min"] <= s["mean"] <= s["max"]
            assert s["mean"] == pytest.approx(np.mean(fin))
    slope = st["Fig. 7 slope (after the impact transient)"]
    assert slope["pooled"] == 1.5 and all(np.isfinite(slope["values"]))
    frac = st["pooled coincidence fraction (T_c/4, active part)"]
    assert all(0 <= v <= 1 for v in frac["values"])
    text = "\n".join(realizations_markdown({**rz, "perturbation": 1e-3}))
    assert text.startswith("## Realizations") and "| Fig. 7 slope" in text
    assert "3 realizations" in text
    one = realizations_markdown({"K": 1, "statistics": {}})
    assert "One realization" in "\n".join(one) and "|" not in "\n".join(one)
