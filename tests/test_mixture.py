"""Chains of unlike beads ([beads], [striker]; mdgran.model.mixture): each pair's law, the start
from equilibrium, and runs of the reference backend against analytic results: the restitution of an
unlike pair, a striker's elastic collision, the modes of a dimer chain, a light intruder's
localized mode.  The expected values are computed here from the paper's formulas and the
homogeneous law (contact.ContactLaw), not from mdgran.model.mixture."""
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mdgran import run
from mdgran.model.chain import model_from_scene
from mdgran.model.contact import ContactLaw, fc_from_lambda
from mdgran.model.scene import SceneError, load_scene

from conftest import make_scene

LAM = 0.64


def pair_by_hand(s1, s2, k1, k2, a1, a2, lam=LAM):
    """``(A, L, law)`` of the pair (paper Eq. 4 and the module doc's scaling), own-units law."""
    R = 2 * s1 * s2 / (s1 + s2)
    K = 2 * k1 * k2 / (k1 + k2)
    w = math.sqrt(a1 * a2)
    L = (R * w * w / (K * K)) ** (1 / 3)
    return R * w, L, ContactLaw("schwarz", fc_from_lambda(lam * L, "cos"), "displacement")


ratio = st.floats(0.3, 3.0)


@settings(max_examples=60, deadline=None)
@given(s=st.lists(ratio, min_size=3, max_size=3), k=st.lists(ratio, min_size=3, max_size=3),
       a=st.lists(ratio, min_size=3, max_size=3), u=st.floats(-0.2, 3.0))
def test_each_contact_has_its_pairs_law(s, k, a, u):
    """Contact k of a free 3-bead chain has ``F = A f(delta / L)`` and ``V = A L V(delta / L)``
    of its pair, and its energy's derivative is its force (central difference)."""
    sc = make_scene(chain={"n": 3, "boundary": "free"},
                    beads={"diameter": s, "modulus": k, "adhesion": a})
    m = model_from_scene(sc)
    for c in range(2):
        A, L, law = pair_by_hand(s[c], s[c + 1], k[c], k[c + 1], a[c], a[c + 1])
        d = max(u * L, 0.9 * law.delta_off * L)
        assert m.delta_off[c] == pytest.approx(L * law.delta_off, rel=1e-12)
        assert m.loop_energy[c] == pytest.approx(A * L * law.loop_energy, rel=1e-12)
        assert m.law_force(np.array([d]), [c])[0] == pytest.approx(A * law.force(d / L),
                                                                   rel=1e-11, abs=1e-12)
        e = m.contact_law_energy(np.array([d]), [c])[0]
        assert e == pytest.approx(A * L * law.energy(d / L), rel=1e-10, abs=1e-12)
        h = 1e-6 * L
        dv = (m.contact_law_energy(np.array([d + h]), [c])[0]
              - m.contact_law_energy(np.array([d - h]), [c])[0]) / (2 * h)
        assert dv == pytest.approx(m.law_force(np.array([d]), [c])[0], rel=1e-5, abs=1e-7)


def test_hertz_pair_is_the_hertz_law_of_the_pair():
    """Hertz: ``F = (K_ij/K0) sqrt(R_ij/R0) delta^(3/2)`` (w cancels)."""
    sc = make_scene(chain={"n": 2, "boundary": "free"}, contact={"law": "hertz"},
                    beads={"diameter": [1.0, 0.5], "modulus": [1.0, 2.0], "adhesion": 7.0})
    m = model_from_scene(sc)
    R, K = 2 * 0.5 / 1.5, 2 * 2.0 / 3.0
    assert m.law_force(np.array([0.3]))[0] == pytest.approx(K * math.sqrt(R) * 0.3**1.5,
                                                            rel=1e-14)


def test_reference_beads_are_the_homogeneous_chain():
    """Ratios 1 everywhere make no mixture: the homogeneous chain, computed as before."""
    sc = load_scene("micro-star", [("beads.diameter", 1.0), ("beads.density", [1.0] * 20)])
    assert sc.mixture is None and model_from_scene(sc).mixed is False


@pytest.mark.parametrize("overrides, key", [
    ([("beads.pattern", "dimer")], "beads.ratio"),
    ([("beads.diameter", [1.0, 2.0])], "beads.diameter"),
    ([("beads.ratio", 2.0)], "beads.ratio"),
    ([("beads.density", 0.0)], "beads.density"),
    ([("beads.density", [])], "beads.density"),
    ([("beads.pattern", "tapered"), ("beads.ratio", 2.0)], "beads.ratio"),
    ([("beads.pattern", "intruder"), ("beads.ratio", 0.5), ("beads.index", 21)], "beads.index"),
    ([("beads.pattern", "random"), ("beads.spread", 0.95)], "beads.spread"),
    ([("striker.diameter", 2.0)], "striker.diameter"),
    ([("chain.boundary", "free"), ("striker.diameter", 2.0), ("impulse.bead", 2)],
     "impulse.bead"),
    ([("striker.density", 2.0)], "striker.density"),
])
def test_bad_bead_input_names_the_key(overrides, key):
    with pytest.raises(SceneError) as err:
        load_scene("micro-star", overrides)
    assert err.value.key == key and "\n" not in str(err.value)


def test_patterns_lay_out_the_diameters():
    """Masses m_i = density_i d_i^3 of each pattern."""
    def masses(*overrides):
        return model_from_scene(load_scene("micro-star", [("chain.n", 5), *overrides])).masses

    assert masses(("beads.pattern", "dimer"), ("beads.ratio", 0.5)) == pytest.approx(
        [1, 0.125, 1, 0.125, 1])
    assert masses(("beads.pattern", "tapered"), ("beads.ratio", 0.9)) == pytest.approx(
        0.9 ** (3 * np.arange(5)))
    assert masses(("beads.pattern", "intruder"), ("beads.ratio", 0.5)) == pytest.approx(
        [1, 1, 0.125, 1, 1])
    r = masses(("beads.pattern", "random"), ("beads.spread", 0.2), ("beads.seed", 3))
    d = 1 + 0.2 * (2 * np.random.default_rng(3).random(5) - 1)
    assert r == pytest.approx(d**3)


# ---- against analytic results --------------------------------------------------------------
UNLIKE_PAIR = dict(s=[1.0, 0.6], rho=[1.0, 2.0], k=[1.0, 0.5], a=[1.0, 1.5], v0=3.0)


def unlike_pair_scene(dt=0.01):
    p = UNLIKE_PAIR
    return make_scene(chain={"n": 2, "boundary": "free"}, contact={"damping": 0.0},
                      substrate={"k1": 0.0}, impulse={"velocity": p["v0"]},
                      beads={"diameter": p["s"], "density": p["rho"], "modulus": p["k"],
                             "adhesion": p["a"]},
                      run={"duration": 20.0, "output_interval": 1.0, "tolerance": 1e-11,
                           "dt": dt})


def unlike_pair_after():
    """``(W_pair, v1, v2)``: the pair's loop energy and both velocities after it separates."""
    p = UNLIKE_PAIR
    A, L, law = pair_by_hand(*p["s"], *p["k"], *p["a"])
    m1, m2 = p["rho"][0] * p["s"][0] ** 3, p["rho"][1] * p["s"][1] ** 3
    w_pair = A * L * law.loop_energy
    v_rel = math.sqrt(p["v0"] ** 2 - 2 * w_pair * (m1 + m2) / (m1 * m2))
    v_cm = m1 * p["v0"] / (m1 + m2)
    return w_pair, v_cm - m2 / (m1 + m2) * v_rel, v_cm + m1 / (m1 + m2) * v_rel


def test_unlike_pair_restitution():
    """Two free unlike beads, bead 1 at v0: after the contact opens once, the relative kinetic
    energy is ``mu v0^2 / 2`` less the pair's own loop energy ``A L W(fc_pair)``, with the reduced
    mass ``mu``; momentum is conserved."""
    s, rho, k, a, v0 = (UNLIKE_PAIR[key] for key in ("s", "rho", "k", "a", "v0"))
    res = run(unlike_pair_scene(), "reference")
    tr = res.trajectory
    A, L, law = pair_by_hand(*s, *k, *a)
    m1, m2 = rho[0] * s[0] ** 3, rho[1] * s[1] ** 3
    mu = m1 * m2 / (m1 + m2)
    w_pair = A * L * law.loop_energy
    assert list(tr.ev_kind) == [0]  # one snap-off
    assert tr.ledger["dissipated_hysteresis"][-1] == pytest.approx(w_pair, rel=1e-10)
    v_rel = tr.v[-1, 1] - tr.v[-1, 0]
    assert v_rel == pytest.approx(math.sqrt(v0**2 - 2 * w_pair / mu), rel=1e-8)
    assert m1 * tr.v[-1, 0] + m2 * tr.v[-1, 1] == pytest.approx(m1 * v0, rel=1e-12)
    assert res.max_ledger_error < 1e-9


@pytest.mark.parametrize("d_striker, density", [(1.5, 1.0), (0.7, 2.5)])
def test_striker_on_free_hertz_pair_is_an_elastic_collision(d_striker, density):
    """A striker (bead 1, off the substrate) hits a free Hertz bead: velocities after are those
    of the 1-D elastic collision, ``v1 = (m1 - m2) v0 / (m1 + m2)``, ``v2 = 2 m1 v0 / (m1 +
    m2)``, with the striker's mass ``m1 = density d^3``."""
    v0 = 2.0
    sc = make_scene(chain={"n": 2, "boundary": "free"}, contact={"law": "hertz", "damping": 0.0},
                    substrate={"k1": 0.0}, impulse={"velocity": v0},
                    striker={"diameter": d_striker, "density": density},
                    run={"duration": 30.0, "output_interval": 1.0, "tolerance": 1e-11})
    tr = run(sc, "reference").trajectory
    m1, m2 = density * d_striker**3, 1.0
    assert tr.v[-1, 0] == pytest.approx((m1 - m2) / (m1 + m2) * v0, rel=1e-8, abs=1e-9)
    assert tr.v[-1, 1] == pytest.approx(2 * m1 / (m1 + m2) * v0, rel=1e-8)
    assert sc.impulse_energy == pytest.approx(0.5 * m1 * v0**2)
    assert tr.ledger["kinetic_energy"][-1] == pytest.approx(0.5 * m1 * v0**2, rel=1e-9)


def linear_modes(masses, k_contacts, k1):
    """Frequencies and mass-normalised shapes of a chain between walls with contact stiffnesses
    ``k_contacts`` [n + 1] and on-site ``k1``: numpy's eigenvalues of ``M^-1/2 K M^-1/2``."""
    n = len(masses)
    K = np.diag(k_contacts[:-1] + k_contacts[1:] + k1)
    K -= np.diag(k_contacts[1:-1], 1) + np.diag(k_contacts[1:-1], -1)
    s = 1 / np.sqrt(masses)
    w2, y = np.linalg.eigh(s[:, None] * K * s[None, :])
    return np.sqrt(w2), s[:, None] * y  # x = sum_j phi_j q_j, phi_j^T M phi_k = delta_jk


def test_dimer_chain_modes_acoustic_and_optical():
    """A dimer of masses 1 and 3 on identical springs ``k = f'(0)`` between walls: numpy's
    eigenfrequencies fill the acoustic and optical bands of the infinite dimer chain on the
    substrate, ``(2k + k1 - m1 w^2)(2k + k1 - m2 w^2) = 4 k^2 cos^2(q/2)``, none in the gap; and
    a small-impulse run follows each mode's linear motion ``q_j(t) = (phi_j^T M v0) sin(w_j t)
    / w_j``."""
    n, m_heavy, k1, v0 = 21, 3.0, 0.05, 1e-6
    sc = make_scene(chain={"n": n}, contact={"damping": 0.0}, substrate={"k1": k1},
                    impulse={"velocity": v0, "bead": 11},
                    beads={"density": [1.0, m_heavy] * 10 + [1.0]},
                    run={"duration": 60.0, "output_interval": 0.25, "tolerance": 1e-12})
    k = ContactLaw("schwarz", fc_from_lambda(LAM, "cos")).stiffness(0.0)
    masses = np.array([1.0, m_heavy] * 10 + [1.0])
    omega, phi = linear_modes(masses, np.full(n + 1, k), k1)
    # bands: each branch runs from its q = 0 value to its q = pi value
    b, c = 2 * k + k1, (2 * k + k1) ** 2 - 4 * k * k
    root = np.sqrt((b * (1 + m_heavy)) ** 2 - 4 * m_heavy * c)
    ac = (math.sqrt((b * (1 + m_heavy) - root) / (2 * m_heavy)), math.sqrt(b / m_heavy))
    op = (math.sqrt(b / 1.0), math.sqrt((b * (1 + m_heavy) + root) / (2 * m_heavy)))
    acoustic = omega[omega <= ac[1] * (1 + 1e-12)]
    optical = omega[omega >= op[0] * (1 - 1e-12)]
    assert len(acoustic) + len(optical) == n and len(acoustic) == 10 and len(optical) == 11
    assert acoustic.min() >= ac[0] and optical.max() <= op[1] * (1 + 1e-12)

    tr = run(sc, "reference").trajectory
    assert len(tr.ev_time) == 0
    q_sim = tr.x @ (masses[:, None] * phi)  # [frames, modes]
    amp = (phi.T @ (masses * tr.v[0])) / omega
    q_lin = np.sin(np.outer(tr.time, omega)) * amp
    excited = np.abs(amp) > 1e-3 * np.abs(amp).max()
    err = np.abs(q_sim - q_lin)[:, excited].max(axis=0) / np.abs(amp[excited])
    assert excited.sum() >= 10 and err.max() < 1e-4


def test_light_intruder_has_a_localized_mode_above_the_band():
    """A light intruder (mass m' = 0.3) in a chain of unit masses on springs ``k``: the mode
    above the band has Montroll and Potts's frequency ``w^2 = k (1 + u)^2 / u``, ``u = m' /
    (2 - m')`` its decay per bead; numpy's top eigenvalue has it, and the intruder of a run
    struck there oscillates at it (spectral peak)."""
    n, mi = 41, 0.3
    density = [1.0] * n
    density[20] = mi
    k = ContactLaw("schwarz", fc_from_lambda(LAM, "cos")).stiffness(0.0)
    u = mi / (2 - mi)
    w_loc = math.sqrt(k * (1 + u) ** 2 / u)
    omega, phi = linear_modes(np.array(density), np.full(n + 1, k), 0.0)
    assert omega[-1] == pytest.approx(w_loc, rel=1e-9)
    assert omega[-2] < 2 * math.sqrt(k)  # the rest stay in the band
    shape = np.abs(phi[:, -1])
    assert shape[22] / shape[21] == pytest.approx(u, rel=1e-6)  # decays by u per bead

    sc = make_scene(chain={"n": n}, contact={"damping": 0.0}, substrate={"k1": 0.0},
                    impulse={"velocity": 1e-6, "bead": 21}, beads={"density": density},
                    run={"duration": 200.0, "output_interval": 0.05, "tolerance": 1e-12})
    tr = run(sc, "reference").trajectory
    x = tr.x[:, 20] * np.hanning(len(tr.time))
    spec = np.abs(np.fft.rfft(x, 16 * len(x)))
    freqs = 2 * np.pi * np.fft.rfftfreq(16 * len(x), tr.time[1] - tr.time[0])
    assert freqs[np.argmax(spec)] == pytest.approx(w_loc, rel=2e-3)


def test_diameter_dimer_starts_from_its_equilibrium():
    """Between walls the pairs' forces at delta = 0 differ, so the chain starts from its static
    equilibrium: zero net force on every bead by each pair's own law, and with no impulse it
    stays at rest (no event, displacements within 1e-9 p)."""
    sc = load_scene("micro-star", [("beads.pattern", "dimer"), ("beads.ratio", 0.7),
                                   ("chain.n", 21), ("impulse.velocity", 0.0),
                                   ("run.duration", 20.0), ("run.tolerance", 1e-11)])
    m = model_from_scene(sc)
    x = m.equilibrium
    delta = m.compressions(x)
    s = [1.0, 0.7] * 10 + [1.0]
    s = [s[0]] + s + [s[-1]]  # walls: mirror beads
    f = np.array([A * law.force(d / L) for d, (A, L, law) in
                  zip(delta, (pair_by_hand(s[i], s[i + 1], 1, 1, 1, 1) for i in range(22)))])
    net = f[:-1] - f[1:] - m.k1 * x
    assert np.abs(x).max() > 0.1 and np.abs(net).max() < 1e-13
    tr = run(sc, "reference").trajectory
    assert len(tr.ev_time) == 0 and np.abs(tr.x - x).max() < 1e-9


@settings(max_examples=12, deadline=None)
@given(s=st.lists(st.floats(0.6, 1.6), min_size=6, max_size=6),
       rho=st.lists(st.floats(0.3, 3.0), min_size=6, max_size=6),
       v0=st.floats(0.5, 6.0))
def test_random_free_mixtures_conserve_momentum_and_close_the_ledger(s, rho, v0):
    """Free chains of random unlike beads with no substrate: total momentum stays ``m_1 v0``
    and the energy ledger closes within the reference's bound, whatever the events."""
    sc = make_scene(chain={"n": 6, "boundary": "free"}, substrate={"k1": 0.0},
                    impulse={"velocity": v0}, beads={"diameter": s, "density": rho},
                    run={"duration": 30.0, "output_interval": 1.0, "tolerance": 1e-10})
    res = run(sc, "reference")
    m = np.array(rho) * np.array(s) ** 3
    p = res.trajectory.v @ m
    assert np.abs(p - m[0] * v0).max() < 1e-9 * (1 + m[0] * v0)
    assert res.status == "complete" and res.max_ledger_error <= res.ledger_bound


# ---- the fast backend --------------------------------------------------------------------------
def test_fast_unlike_pair_is_second_order_to_the_analytic_restitution():
    """The fast backend on the unlike pair: the velocities after the snap-off approach the
    analytic ones at second order in dt (located events), one snap-off each time."""
    w_pair, v1, v2 = unlike_pair_after()
    errs = []
    for dt in (0.02, 0.01, 0.005):
        tr = run(unlike_pair_scene(dt), "fast").trajectory
        assert list(tr.ev_kind) == [0]
        assert tr.ledger["dissipated_hysteresis"][-1] == pytest.approx(w_pair, rel=1e-3)
        errs.append(max(abs(tr.v[-1, 0] - v1), abs(tr.v[-1, 1] - v2)))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert errs[-1] < 1e-4 and np.all(orders > 1.8), (errs, orders)


@pytest.mark.parametrize("d_striker, density", [(1.5, 1.0), (0.7, 2.5)])
def test_fast_striker_on_free_hertz_pair(d_striker, density):
    """The elastic collision of a striker on a free Hertz bead, on the fast backend (dt 1e-3)."""
    v0, m1 = 2.0, density * d_striker**3
    sc = make_scene(chain={"n": 2, "boundary": "free"}, contact={"law": "hertz", "damping": 0.0},
                    substrate={"k1": 0.0}, impulse={"velocity": v0},
                    striker={"diameter": d_striker, "density": density},
                    run={"duration": 30.0, "output_interval": 1.0, "dt": 1e-3})
    tr = run(sc, "fast").trajectory
    assert tr.v[-1, 0] == pytest.approx((m1 - 1) / (m1 + 1) * v0, abs=1e-5)
    assert tr.v[-1, 1] == pytest.approx(2 * m1 / (m1 + 1) * v0, abs=1e-5)


@pytest.mark.parametrize("name", ["mixed/dimer", "mixed/intruder", "mixed/striker"])
def test_fast_follows_the_reference_on_mixed_scenes(name):
    """fast (dt 0.0025, and half that) and reference (tol 1e-10) on the built-in mixed scenes to
    t = 10: the same events, and the fast run's difference from the reference within 4x its
    own error estimate (its difference from the half-step run, times 4/3 for second order)."""
    sc = load_scene(name, [("run.duration", 10.0), ("run.tolerance", 1e-10)])
    ref = run(sc, "reference").trajectory
    fast = run(sc, "fast", set={"run.dt": 0.0025}).trajectory
    fine = run(sc, "fast", set={"run.dt": 0.00125}).trajectory
    assert list(zip(fast.ev_contact, fast.ev_kind)) == list(zip(ref.ev_contact, ref.ev_kind))
    own = 4.0 / 3.0 * np.abs(fast.x - fine.x).max()
    assert 0 < np.abs(fast.x - ref.x).max() < 4.0 * own


# ---- analysis of unlike beads --------------------------------------------------------------
@settings(max_examples=30, deadline=None)
@given(k=st.lists(st.floats(0.1, 3.0), min_size=5, max_size=5),
       m=st.lists(st.floats(0.2, 5.0), min_size=4, max_size=4), k1=st.floats(0.0, 0.5))
def test_cluster_modes_with_masses_solve_the_generalized_problem(k, m, k1):
    """``modes(..., masses)`` against scipy's generalized eigensolver ``K u = w^2 M u``."""
    from scipy.linalg import eigh

    from mdgran.analysis.modes import modes, stiffness_matrix

    om, shapes = modes(k, k1, True, True, None, m)
    w2, u = eigh(stiffness_matrix(k, k1, True, True), np.diag(m))
    assert om**2 == pytest.approx(w2, rel=1e-10, abs=1e-12)
    u = u / np.linalg.norm(u, axis=0)
    assert np.abs(np.abs(np.sum(shapes * u, axis=0)) - 1.0).max() < 1e-8


def test_modes_of_a_dimer_cluster_in_a_run_match_its_spectrum():
    """A small-impulse run of the density dimer: the whole chain is one cluster, and
    ``cluster_modes_in_run`` gives numpy's frequencies of the dimer (masses 1 and 3)."""
    from mdgran.analysis.clusters import Cluster
    from mdgran.analysis.modes import cluster_modes_in_run

    n, k1 = 21, 0.05
    masses = np.array([1.0, 3.0] * 10 + [1.0])
    sc = make_scene(chain={"n": n}, contact={"damping": 0.0}, substrate={"k1": k1},
                    impulse={"velocity": 1e-6, "bead": 11}, beads={"density": list(masses)},
                    run={"duration": 5.0, "output_interval": 0.25})
    tr = run(sc, "reference").trajectory
    k = ContactLaw("schwarz", fc_from_lambda(LAM, "cos")).stiffness(0.0)
    expected, _ = linear_modes(masses, np.full(n + 1, k), k1)
    cl = Cluster(first=1, last=n, left_wall=True, right_wall=True)
    om, _, _ = cluster_modes_in_run(tr, cl, 0.0, 5.0)
    assert om == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("name", ["mixed/dimer", "mixed/intruder"])
def test_compare_passes_reference_against_fast_on_mixed_scenes(name, tmp_path):
    """``mdgran compare`` of reference and fast on the dimer and intruder scenes to t = 60:
    trajectories within the error estimates to the horizon, events matched (or undecidable
    at the backends' accuracy), ledgers within bounds, cluster statistics past the horizon."""
    from mdgran.crosscheck.compare import compare

    rep = compare(load_scene(name, [("run.duration", 60.0)]), ("reference", "fast"),
                  out_dir=tmp_path)
    failed = [c for c in rep["criteria"] if not c["passed"]]
    assert not failed, failed


def test_fast_with_one_law_per_pair_needs_the_exact_law():
    """Random diameters with contact.lambda give every pair its own law: more than the fast
    backend tabulates is refused (the key, what to do), and the exact law runs it, close to the
    reference."""
    sc = load_scene("micro-star", [("chain.n", 300), ("chain.boundary", "free"),
                                   ("beads.pattern", "random"),
                                   ("beads.spread", 0.2), ("run.duration", 2.0),
                                   ("run.tolerance", 1e-10)])
    assert len(sc.mixture.laws) > 255
    with pytest.raises(SceneError) as err:
        run(sc, "fast")
    assert err.value.key == "beads" and "contact_eval=exact" in str(err.value)
    fast = run(sc, "fast:contact_eval=exact").trajectory
    ref = run(sc, "reference").trajectory
    assert list(zip(fast.ev_contact, fast.ev_kind)) == list(zip(ref.ev_contact, ref.ev_kind))
    assert np.abs(fast.x - ref.x).max() < 1e-5 * np.abs(ref.x).max()  # dt 0.0025, order 2


def test_walled_mixture_whose_contacts_open_at_touch():
    """Contacts that switch at delta = 0 (Hertz, DMT) between walls: a Hertz mixture starts at
    x = 0, where every force is 0 (it crashed: the equilibrium search found its start off the
    closed branch); a DMT mixture, whose unlike pairs pull unequally at touch, is refused
    naming the key."""
    hertz = load_scene("macro-hertz", [("beads.pattern", "dimer"), ("beads.ratio", 0.6)])
    x, v, closed = model_from_scene(hertz).initial_state(1, 0.5)
    assert np.all(x == 0.0) and v[0] == 0.5 and closed.all()
    dmt = load_scene("micro-star", [("contact.law", "dmt"), ("beads.pattern", "dimer"),
                                    ("beads.ratio", 0.6)])
    with pytest.raises(SceneError) as exc:
        model_from_scene(dmt).initial_state(1, 0.5)
    assert exc.value.key == "beads"


@pytest.mark.parametrize("name, overrides, kinds", [
    ("mixed/dimer", [], 3),  # the wall pair (either end), the unlike pair with each left bead
    ("mixed/tapered", [], None),  # every contact its own
    ("mixed/striker", [], 2),  # the striker on bead 2; the chain
    ("micro-star", [("beads.density", [1.0, 0.3] * 10)], 2)])
def test_fast_contact_kinds_hold_each_contacts_constants(name, overrides, kinds):
    """The fast kernel's contact kinds (one row of constants per distinct contact, with its
    left bead): row kind[j] gives back contact j's A, L, opening threshold and law class and
    its left bead's mass and substrate factor from the mixture itself."""
    from mdgran.backends import fast_kernel as fk
    from mdgran.backends.fast import FastBackend
    sc = load_scene(name, overrides)
    mix = model_from_scene(sc).mixture
    kmix = FastBackend(sc).params.mix
    row = kmix.pair.reshape(-1, fk.NPAIR)[kmix.kind]
    m = len(mix.force_scale)
    assert len(kmix.pair) == fk.NPAIR * (kinds or m)
    left = np.arange(m) - (1 if model_from_scene(sc).walls else 0)
    inner = left >= 0
    for field, expected in [("force_scale", mix.force_scale), ("length", mix.length_scale),
                            ("delta_off", mix.delta_off)]:
        assert np.array_equal(row[:, fk.PAIR_FIELDS.index(field)], expected)
    assert np.array_equal(kmix.pair_class[kmix.kind], mix.law_index)
    assert np.array_equal(row[inner, fk.P_INV_MASS], 1.0 / mix.mass[left[inner]])
    assert np.array_equal(row[inner, fk.P_ON_SITE], mix.substrate[left[inner]])
