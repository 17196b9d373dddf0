"""Contact laws against the independent check table of docs/physics.md section 2 and analytic
identities."""

import numpy as np
import pytest

from mdgran.model.contact import ContactLaw, fc_from_lambda, lambda_from_fc, table_error

# docs/physics.md section 2, check values: lambda, fc, delta_min, f_on, f_off, W, delta_eq,
# dF/ddelta at eq
CHECK = [
    (0.0, -2.00000, 0.0, -2.00000, -2.00000, 0.0, 1.58740, 1.88988),
    (0.30, -1.95193, -0.19067, -1.93591, -1.88784, 0.37039, 1.53888, 1.86295),
    (0.64, -1.85182, -0.40386, -1.80243, -1.65426, 0.73629, 1.44107, 1.81129),
    (1.50, -1.65773, -0.70570, -1.54364, -1.20136, 1.12313, 1.25384, 1.71463),
    (5.00, -1.51799, -0.88664, -1.35732, -0.87530, 1.26321, 1.11822, 1.64454),
    (None, -1.50000, -0.90856, -1.33333, -0.83333, 1.27494, 1.10064, 1.63541),
]


@pytest.mark.parametrize("row", CHECK)
def test_check_table(row):
    lam, fc, dmin, fon, foff, W, deq, keq = row
    law = ContactLaw("schwarz", -1.5 if lam is None else fc_from_lambda(lam))
    got = (law.fc, law.delta_min, law.f_on, law.f_off, law.loop_energy, law.delta_eq,
           law.stiffness_eq)
    np.testing.assert_allclose(got, (fc, dmin, fon, foff, W, deq, keq), atol=6e-6)


def test_lambda_roundtrip():
    for lam in (0.01, 0.64, 3.0):
        assert lambda_from_fc(fc_from_lambda(lam)) == pytest.approx(lam, rel=1e-12)


@pytest.mark.parametrize("fc", [-2.0, -1.85, -1.5])
def test_branch_inversion_to_machine_precision(fc):
    law = ContactLaw("schwarz", fc)
    d = np.concatenate([law.delta_min + np.logspace(-15, 0, 50), np.linspace(-0.5, 50, 200)])
    d = d[d >= law.delta_min]
    t = law.t_of_delta(d)
    assert np.all(t >= law.t_min)  # the stable branch, never the unstable one
    resid = t**4 - 4 * law.sigma * t - d
    assert np.max(np.abs(resid) / (1 + np.abs(d))) < 4e-15


def test_force_at_branch_ends_and_sign():
    law = ContactLaw("schwarz", fc_from_lambda(0.64))
    assert law.force(0.0) == pytest.approx(law.fc + law.s, abs=1e-14)  # f_on, tensile
    assert law.force(law.delta_min) == pytest.approx(law.fc + 4 * law.s, abs=1e-12)
    assert law.force(law.delta_eq) == pytest.approx(0.0, abs=1e-12)
    assert law.force(5.0) > 0 > law.force(0.5)  # repulsive in deep compression


@pytest.mark.parametrize("kind,fc", [("schwarz", -1.85182), ("schwarz", -1.5),
                                     ("schwarz", -2.0), ("hertz", 0.0)])
def test_energy_is_integral_of_force(kind, fc):
    law = ContactLaw(kind, fc)
    lo = law.delta_off + 2e-2 if kind == "schwarz" else 0.01  # away from the sqrt singularity
    d = np.linspace(lo, 4.0, 41)
    h = 1e-5
    dV = (law.energy(d + h) - law.energy(d - h)) / (2 * h)
    np.testing.assert_allclose(dV, law.force(d), atol=2e-9)
    assert law.energy(0.0) == pytest.approx(0.0, abs=1e-13)


def test_energy_matches_quadrature():
    from scipy.integrate import quad

    law = ContactLaw("schwarz", fc_from_lambda(0.64))
    for b in (law.delta_min, -0.2, 0.7, 3.0):
        ref, _ = quad(lambda s: float(law.force(s)), 0.0, b, epsabs=1e-13, epsrel=1e-12,
                      limit=200)
        assert law.energy(b) == pytest.approx(ref, abs=1e-12)


def test_hertz_exact():
    law = ContactLaw("hertz")
    assert law.force(2.0) == pytest.approx(2.0**1.5, rel=1e-15)
    assert law.force(-1.0) == 0.0
    assert law.energy(2.0) == pytest.approx(0.4 * 2.0**2.5, rel=1e-15)


def test_force_rule_opens_at_force_maximum():
    law = ContactLaw("schwarz", -1.5, "force")
    assert law.f_off == pytest.approx(law.fc, abs=1e-12)
    assert law.delta_off > ContactLaw("schwarz", -1.5).delta_off
    # less energy lost than with the displacement rule
    assert 0 < law.loop_energy < ContactLaw("schwarz", -1.5).loop_energy


def test_table_error_shrinks_with_size():
    """Linear interpolation of f(delta) converges at first order in the table spacing: the
    square-root singularity at delta_min dominates (f - f_off ~ sqrt(delta - delta_min))."""
    law = ContactLaw("schwarz", fc_from_lambda(0.64))
    e1, e2 = table_error(law, 500)["force_abs"], table_error(law, 1000)["force_abs"]
    assert 1.8 < e1 / e2 < 2.2
    assert table_error(law, 2001)["force_rel"] < 1e-5


def test_spline_table_is_fourth_order_through_snap_off():
    """The table is a cubic spline in w = sqrt(delta - delta_min): error ~ dw^4, so doubling
    the nodes divides it by ~16 (measured 12.3 and 13.9 from 101 to 201 to 401 nodes)."""
    from mdgran.model.contact import ContactTable

    law = ContactLaw("schwarz", fc_from_lambda(0.64))
    e1, e2 = ContactTable(law, 201).error(), ContactTable(law, 401).error()
    assert 11 < e1["force_abs"] / e2["force_abs"] < 18
    # the default table is at the round-off floor everywhere: through snap-off, at delta = 0
    # (where a tiny impulse resolves the stiffness) and deep in compression
    t = ContactTable(law)
    d = law.delta_off + np.array([1e-12, 1e-6, 1e-3, 0.5, 3.0, 50.0])
    d = np.append(d, [-1e-7, 0.0, 1e-7])
    np.testing.assert_allclose(t.force(d), law.force(d), atol=1e-11, rtol=0)
    np.testing.assert_allclose(t.energy(d), law.energy(d), atol=1e-9, rtol=0)


@pytest.mark.parametrize("law", [ContactLaw("schwarz", -2.0), ContactLaw("hertz")])
def test_spline_table_exact_where_force_is_cubic_in_w(law):
    """f(w) is a cubic polynomial for Hertz (w^3) and for Schwarz at fc = -2: the spline
    reproduces it to round-off even on a coarse table."""
    from mdgran.model.contact import ContactTable

    assert ContactTable(law, 101).error()["force_abs"] < 1e-10
