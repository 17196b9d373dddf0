"""Scales against the paper's Table I and Table II."""
import pytest

from mdgran.model.units import contact_modulus, scales_from_material, wire_tension, work_of_adhesion


def test_work_of_adhesion():
    assert work_of_adhesion() == pytest.approx(0.146, rel=2e-3)


@pytest.mark.parametrize("d,stiff,damp", [(2.5e-6, 1776, 7.53e-6), (2.5e-3, 177584, 2.38)])
def test_table_one(d, stiff, damp):
    s = scales_from_material({"diameter": d})
    assert s.stiffness == pytest.approx(stiff, rel=3e-4)
    assert s.damping == pytest.approx(damp, rel=2e-3)


def test_normalized_coefficients():
    s = scales_from_material({"diameter": 2.5e-6})
    assert 21.5 / s.stiffness == pytest.approx(0.012107, rel=1e-4)
    assert 1e-7 / s.damping == pytest.approx(0.013285, rel=1e-4)


def test_maugis_parameter_and_modulus_convention():
    s = scales_from_material({"diameter": 2.5e-6})
    assert s.maugis_lambda == pytest.approx(0.64, abs=0.005)
    assert s.K == pytest.approx(176.8e9, rel=1e-3)
    assert contact_modulus(338e9, 0.21, "text") == pytest.approx(235.7e9, rel=1e-3)
    text = scales_from_material({"diameter": 2.5e-6, "modulus": "text"})
    assert text.stiffness != pytest.approx(1776, rel=1e-2)  # the text formula misses Table I


def test_table_two_wire_tension():
    assert wire_tension(21.5, 6.25e-6) == pytest.approx(67.2e-6, rel=1e-3)
    assert wire_tension(2150, 6.25e-3) == pytest.approx(6.72, rel=1e-3)
