"""The compiled scalar law (mdgran.model.contact_scalar): the fast kernel's forms (powers of t as
products) against the numpy law of mdgran.model.contact (the C library's ``pow``, lifted as ufuncs),
against the integral identities the kernel relies on, and the C++ fix's constants table."""
from pathlib import Path


import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mdgran.backends import fast_kernel as fk
from mdgran.backends.simd import branch_t8
from mdgran.model.contact import ContactLaw
from mdgran.model import contact_scalar
from mdgran.model.contact_scalar import (branch_t, hertz_energy, hertz_force,
                                         law_energy, law_force, schwarz_constants,
                                         schwarz_energy, schwarz_force, schwarz_mean_force)

LAWS = [ContactLaw("schwarz", fc) for fc in (-2.0, -1.85182, -1.5)] + [
    ContactLaw("schwarz", -1.65773, "force")]


def compressions(law):
    return np.concatenate([law.delta_min + np.logspace(-14, 0, 40), np.linspace(0.0, 60.0, 61)])


@pytest.mark.parametrize("law", LAWS, ids=lambda law: f"{law.fc}-{law.snap_off}")
def test_scalar_law_matches_numpy_law(law):
    """Force and energy of the scalar law equal ContactLaw's to round-off (the two evaluate
    the polynomials in t differently, so they may differ in the last bits only)."""
    k = schwarz_constants(law)
    for d in compressions(law):
        f, e = schwarz_force(d, k), schwarz_energy(d, k)
        assert f == pytest.approx(float(law.force(d)), rel=1e-13, abs=1e-13)
        assert e == pytest.approx(float(law.energy(d)), rel=1e-12, abs=1e-13)
        assert law_force(d, False, k) == f and law_energy(d, False, k) == e


@pytest.mark.parametrize("law", LAWS, ids=lambda law: f"{law.fc}-{law.snap_off}")
def test_branch_t_solves_the_branch_equation(law):
    """t^4 - 4 sigma t = delta on the stable branch t >= t_min; t_min below delta_min."""
    for d in compressions(law):
        t = branch_t(d, law.sigma, law.t_min, law.delta_min)
        assert t >= law.t_min
        assert t**4 - 4.0 * law.sigma * t == pytest.approx(d, rel=1e-13, abs=1e-13)
        assert float(law.t_of_delta(d)) == t  # contact.py inverts with this same function
    assert branch_t(law.delta_min - 1.0, law.sigma, law.t_min, law.delta_min) == law.t_min


OFFSETS = st.one_of(st.floats(-1.0, 0.2), st.floats(0.0, 80.0), st.floats(0.0, 1e-12))


@settings(max_examples=200, deadline=None)
@given(fc=st.floats(-2.0, -1.5), snap=st.sampled_from(["displacement", "force"]),
       offsets=st.lists(OFFSETS, min_size=8, max_size=8))
def test_branch_t8_is_branch_t_bit_for_bit(fc, snap, offsets):
    """The fast kernel's kicks invert eight compressions at once in vector instructions
    (branch_t8): each result is branch_t's, bit for bit, on any law between DMT and JKR and
    at any compression (below delta_min, at it, just above, far above)."""
    law = ContactLaw("schwarz", fc, snap)
    d = tuple(law.delta_min + o for o in offsets)
    eight = branch_t8(d, law.sigma, law.t_min, law.delta_min)
    assert list(eight) == [branch_t(x, law.sigma, law.t_min, law.delta_min) for x in d]


@settings(max_examples=100, deadline=None)
@given(fc=st.floats(-2.0, -1.5), start=st.integers(0, 3),
       rows=st.lists(st.tuples(OFFSETS, OFFSETS, st.booleans()), max_size=21))
def test_kick_inversions_are_branch_t_of_each_due_entry(fc, start, rows):
    """invert_kicks replaces column K_T1 of every kicked row and column K_T0 of the rows
    marked due by branch_t of what they held (eight at a time, the last group padded), and
    leaves every other entry as it was."""
    law = ContactLaw("schwarz", fc)
    kick = np.full((start + len(rows) + 2, 5), 7.0)
    for k, (t0, t1, due) in enumerate(rows, start):
        kick[k, fk.K_T0], kick[k, fk.K_T1] = law.delta_min + t0, law.delta_min + t1
        kick[k, fk.K_DUE] = float(due)
    want = kick.copy()
    for k, (_, _, due) in enumerate(rows, start):
        for col in (fk.K_T1, fk.K_T0) if due else (fk.K_T1,):
            want[k, col] = branch_t(kick[k, col], law.sigma, law.t_min, law.delta_min)
    fk.invert_kicks(schwarz_constants(law), kick, start, len(rows))
    assert kick.tobytes() == want.tobytes()


@pytest.mark.parametrize("law", LAWS[:3], ids=lambda law: str(law.fc))
def test_mean_force_is_the_energy_difference_quotient(law):
    """schwarz_mean_force(d0, d1) = (V(d1) - V(d0)) / (d1 - d0) (Gauss-Legendre, exact for the
    degree-9 polynomial), and f(d) as d1 -> d0."""
    k = schwarz_constants(law)
    lo = law.delta_min
    for d0, d1 in [(lo, lo + 0.05), (lo + 1e-9, lo + 0.1), (lo + 0.02, 0.3), (0.5, 2.0)]:
        expected = (float(law.energy(d1)) - float(law.energy(d0))) / (d1 - d0)
        assert schwarz_mean_force(d0, d1, k) == pytest.approx(expected, rel=1e-10)
        assert schwarz_mean_force(d1, d0, k) == pytest.approx(expected, rel=1e-10)
    d = lo + 0.01
    assert schwarz_mean_force(d, d, k) == pytest.approx(float(law.force(d)), rel=1e-14)


def test_hertz_scalar_law():
    law = ContactLaw("hertz")
    k = schwarz_constants(law)
    for d in (-1.0, 0.0, 1e-12, 0.3, 4.0, 80.0):
        assert hertz_force(d) == float(law.force(d))  # the same two operations
        assert hertz_energy(d) == float(law.energy(d))
        assert hertz_force(d) == pytest.approx(max(d, 0.0) ** 1.5, rel=1e-15)
        assert hertz_energy(d) == pytest.approx(0.4 * max(d, 0.0) ** 2.5, rel=1e-15)
        assert law_force(d, True, k) == hertz_force(d)
        assert law_energy(d, True, k) == hertz_energy(d)


def test_cxx_constants_header_is_generated_from_the_python_constants():
    """law_constants.h, which the C++ fix includes, is cxx_header()'s text (regenerate it
    with ``python -m mdgran.model.contact_scalar``), and it holds the values the Python side
    uses."""
    header = (Path(contact_scalar.__file__).parents[1] / "backends" / "lammps" / "fix"
              / contact_scalar.CXX_HEADER)
    text = header.read_text()
    assert text == contact_scalar.cxx_header()
    assert "NEWTON_STEPS = 7;" in text and "SING_BAND = 0.1;" in text
    assert np.sum(contact_scalar.GL_W) == pytest.approx(2.0, rel=1e-15)  # Gauss-Legendre
    assert np.allclose(np.polynomial.legendre.leggauss(5)[0], contact_scalar.GL_X, atol=1e-15)
