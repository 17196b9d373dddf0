"""contact.fc_rule: the paper's COS relation (default) or the exact Maugis-Dugdale pull-off.
fc is in units of eta = pi R w (docs/physics.md section 2), the unit of Maugis's
P = F / (pi w R) in Johnson-Greenwood notation, so the two compare without conversion."""
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mdgran.cli import main, scene_info
from mdgran.model.contact import (FC_RULES, ContactLaw, fc_from_lambda, lambda_from_fc,
                            maugis_dugdale_pulloff)
from mdgran.model.scene import SceneError, load_scene

MD = "maugis-dugdale"
# docs/physics.md section 2: Maugis's equations solved exactly vs the COS relation
CHECK = [(0.3, -1.816, -1.95193), (0.64, -1.672, -1.85182), (1.5, -1.556, -1.65773)]


@pytest.mark.parametrize("lam, md, cos", CHECK)
def test_check_values(lam, md, cos):
    assert maugis_dugdale_pulloff(lam) == pytest.approx(md, abs=2e-3)
    assert fc_from_lambda(lam, MD) == maugis_dugdale_pulloff(lam)
    assert fc_from_lambda(lam) == pytest.approx(cos, abs=5e-6)  # the existing code
    assert fc_from_lambda(lam, "cos") == fc_from_lambda(lam)


def test_cos_overstates_md_by_the_documented_amounts():
    over = {lam: fc_from_lambda(lam) / maugis_dugdale_pulloff(lam) - 1 for lam, _, _ in CHECK}
    assert over[0.64] == pytest.approx(0.108, abs=1e-3)
    assert over[0.3] == pytest.approx(0.075, abs=1e-3)
    assert over[1.5] == pytest.approx(0.066, abs=1e-3)


def test_limits():
    assert maugis_dugdale_pulloff(0.0) == -2.0  # DMT
    assert maugis_dugdale_pulloff(1e-4) == pytest.approx(-2.0, abs=1e-5)
    assert maugis_dugdale_pulloff(1e3) == pytest.approx(-1.5, abs=1e-6)  # JKR
    assert maugis_dugdale_pulloff(math.inf) == -1.5
    assert -2.0 <= maugis_dugdale_pulloff(1e14) <= -1.5  # within ContactLaw's range
    # the COS relation never reaches JKR
    assert fc_from_lambda(1e3) == pytest.approx(-1.5147, abs=1e-4)


def _md_by_area(lam: float) -> float:
    """An independent solution: for each contact radius A on a fine grid, m from Maugis's
    first equation by brentq, the load P from the second; the least P (grid + parabola)."""
    import numpy as np
    from scipy.optimize import brentq

    def eq1(m, A):
        s = math.sqrt(m * m - 1)
        return (lam * A * A / 2 * (s + (m * m - 2) * math.atan(s))
                + 4 * lam * lam * A / 3 * (s * math.atan(s) - m + 1) - 1)

    def load(A):
        m = brentq(eq1, 1 + 1e-15, 1e9, args=(A,), xtol=1e-15, rtol=1e-15)
        s = math.sqrt(m * m - 1)
        return A**3 - lam * A * A * (s + m * m * math.atan(s))

    A = np.linspace(1e-3, 3.0, 3000)
    P = np.array([load(a) for a in A])
    i = int(np.argmin(P))
    if 0 < i < len(A) - 1:  # refine on a finer grid around the minimum
        A = np.linspace(A[i - 1], A[i + 1], 201)
        P = np.array([load(a) for a in A])
    return float(P.min())


@pytest.mark.parametrize("lam", [0.3, 0.64, 1.5, 5.0])
def test_against_an_independent_solution(lam):
    assert maugis_dugdale_pulloff(lam) == pytest.approx(_md_by_area(lam), abs=2e-6)


@settings(max_examples=200, deadline=None)
@given(a=st.floats(0.05, 20.0), b=st.floats(0.05, 20.0))
def test_monotonic_in_lambda(a, b):
    lo, hi = min(a, b), max(a, b)
    f_lo, f_hi = maugis_dugdale_pulloff(lo), maugis_dugdale_pulloff(hi)
    assert -2.0 < f_lo <= f_hi + 1e-13 < -1.5 + 1e-13
    if hi - lo > 1e-6 * hi:
        assert f_lo < f_hi


@pytest.mark.parametrize("lam", [0.01, 0.3, 0.64, 1.5, 20.0])
def test_inverse(lam):
    assert lambda_from_fc(fc_from_lambda(lam, MD), MD) == pytest.approx(lam, rel=1e-8)
    assert lambda_from_fc(-2.0, MD) == 0.0 and lambda_from_fc(-1.5, MD) == math.inf


def test_default_is_cos_and_existing_scenes_do_not_change():
    sc = load_scene("micro-star")
    assert sc.data["contact"]["fc_rule"] == "cos"
    assert sc.law.fc == fc_from_lambda(0.64) == -1.8518239686741345
    assert sc.law == ContactLaw("schwarz", fc_from_lambda(0.64))


def test_scene_key_selects_the_rule_and_info_prints_it(capsys):
    sc = load_scene("micro-star", [("contact.fc_rule", MD)])
    assert sc.law.fc == pytest.approx(-1.672, abs=2e-3)
    assert sc.law.fc == maugis_dugdale_pulloff(0.64)
    info = scene_info(sc)
    assert info["fc_rule"] == MD and info["fc"] == sc.law.fc
    assert main(["info", "micro-star", "--set", "contact.fc_rule=maugis-dugdale"]) == 0
    assert "fc_rule                      maugis-dugdale" in capsys.readouterr().out
    # with a material's lambda too
    mat = {"diameter": 5e-6, "E": 73e9, "nu": 0.17, "w": 0.05, "density": 2200.0}
    sc = load_scene({"material": mat, "contact": {"fc_rule": MD}})
    assert sc.law.fc == maugis_dugdale_pulloff(sc.data["contact"]["lambda"])


@pytest.mark.parametrize("value", ["md", "COS", 1, "maugis_dugdale"])
def test_bad_rule_is_one_line_naming_key_and_allowed(value, capsys):
    with pytest.raises(SceneError) as exc:
        load_scene("micro-star", [("contact.fc_rule", value)])
    msg = str(exc.value)
    assert msg.startswith("contact.fc_rule: ") and "\n" not in msg
    for rule in FC_RULES:
        assert repr(rule) in msg
    assert main(["info", "micro-star", "--set", f"contact.fc_rule={value}"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_rule_where_it_has_no_effect_is_refused():
    with pytest.raises(SceneError, match=r"^contact\.fc_rule: sets how fc follows"):
        load_scene({"contact": {"fc": -1.8, "fc_rule": MD}})
    with pytest.raises(SceneError, match=r"^contact\.fc_rule: not used by law 'jkr'"):
        load_scene({"contact": {"law": "jkr", "fc_rule": MD}})
    # an override of fc or of the law replaces the file's rule
    base = load_scene({"contact": {"lambda": 1.0, "fc_rule": MD}})
    assert base.with_overrides([("contact.fc", -1.7)]).law.fc == -1.7
    assert base.with_overrides([("contact.law", "jkr")]).law.fc == -1.5
    assert base.with_overrides([("contact.fc_rule", "cos")]).law.fc == fc_from_lambda(1.0)
