"""mdgran.analysis.nulls and the channel / vectorized coincidence tests on synthetic data whose
answer is known (no simulation): Poisson re-clustering events, ``C_eff`` a smooth log-normal
process, independent of the events (uncoupled) or raised with the local re-clustering rate
(coupled)."""
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from mdgran import analysis as an
from mdgran.analysis import coincidence as co
from mdgran.analysis import nulls as nl
from mdgran.analysis.clusters import segment_means

K = 200  # shuffles per null in the seed loops
SEEDS = range(10)


def study(seed, coupling=0.0, n_cases=30):
    """A synthetic 'sweep': n_cases cases with event rates log-uniform in [0.03, 0.3]."""
    rng = np.random.default_rng(seed)
    rates = np.exp(rng.uniform(np.log(0.03), np.log(0.3), n_cases))
    return [nl.synthetic_case(rng, coupling, event_rate=r) for r in rates]


def pooled(cases, seed, n_shifts=2000):
    pc = [co.coincidence_case(c.time, c.c_eff, c.rate, 5.0, c.window) for c in cases]
    return co.pooled_coincidence_test(pc, n_shifts, seed)


def measures(cases, seed):
    """p-values (time-shift nulls) of every measure, and the Fig. 7 slope and its null."""
    obs = nl.observed_means(cases)
    fig7 = nl.fig7_slope(cases)
    fig7_null = nl.time_shift(cases, n_shuffles=K, rng=seed)
    seg = nl.segment_statistic(cases, obs)[0]
    seg_r = nl.segment_statistic(cases, obs, kind="r")[0]
    rho = nl.rate_damping_correlation(cases)
    return {
        "fig7": fig7, "fig7_null": nl.null_summary(fig7, fig7_null),
        "segment_slope": nl.null_summary(
            seg, nl.time_shift(cases, nl.segment_statistic, K, seed)),
        "segment_r": nl.null_summary(
            seg_r, nl.time_shift(cases, nl.segment_statistic, K, seed, kind="r")),
        "rho": nl.null_summary(rho, nl.rate_damping_null(cases, 5000, seed)),
        "coincidence": pooled(cases, seed),
    }


@pytest.fixture(scope="module")
def uncoupled():
    return [measures(study(s), s) for s in SEEDS]


@pytest.fixture(scope="module")
def coupled():
    return [measures(study(100 + s, coupling=1.0), s) for s in range(5)]


# ---- exactness of the vectorized pieces -----------------------------------------------------
def test_vectorized_segment_means_and_shift():
    case = nl.synthetic_case(3)
    ref = segment_means(case.time, case.c_eff, case.segments)
    many = nl.segment_means_many(case.time, nl.shifted_c_eff(case, [0, 17]), case.segments)
    assert np.allclose(many[0], ref, rtol=0, atol=1e-12)
    idx = nl._window_index(case)
    rolled = case.c_eff.copy()
    rolled[idx] = np.roll(case.c_eff[idx], 17)
    assert np.allclose(many[1], segment_means(case.time, rolled, case.segments), atol=1e-12)
    # averaged over every shift, each segment inside the window has the window's mean
    allm = nl.segment_means_many(case.time, nl.shifted_c_eff(case, np.arange(len(idx))),
                                 case.segments)
    assert np.allclose(allm.mean(axis=0)[:-1], case.c_eff[idx].mean(), atol=1e-12)


def test_fig7_slope_matches_linregress_and_statistic():
    cases = study(0)
    x, y, index = nl.fig7_points(cases)
    assert len(x) == len(cases) and np.all(index >= 0)
    for case, i, yy in zip(cases, index, y):
        m = segment_means(case.time, case.c_eff, case.segments)
        assert i == an.representative_segment(case.segments, m, case.t_min) and yy == m[i]
    slope = nl.fig7_slope(cases)
    assert slope == stats.linregress(x, y).slope
    assert nl.fig7_statistic(cases, nl.observed_means(cases))[0] == pytest.approx(slope, 1e-12)


def test_rate_damping_rho_is_spearman_of_shifted():
    case = nl.synthetic_case(5, coupling=0.5)
    idx = nl._window_index(case)
    rho = nl.rate_damping_rho(case)
    for k in (0, 1, 250):
        shifted = nl.shifted_c_eff(case, [k])[0]
        assert rho[k] == pytest.approx(stats.spearmanr(case.rate[idx], shifted[idx]).statistic,
                                       abs=1e-10)


def test_vectorized_coincidence_equals_loop():
    rng = np.random.default_rng(0)
    a, b = np.sort(rng.uniform(0, 100, 12)), np.sort(rng.uniform(0, 100, 4))
    loop = co.coincidence_test(a, b, 5.0, 0.0, 100.0, n_shifts=500, seed=3)
    vec = co.coincidence_shift_test(a, b, 5.0, 0.0, 100.0, n_shifts=500, seed=3)
    assert np.array_equal(loop["null"], vec["null"])
    assert vec["p_value"] == loop["p_value"] and vec["p_floor"] == 1 / 501


def test_pooled_coincidence_draws_as_study():
    """Same shifts and numbers as mdgran.studies.paper_study.pooled_coincidence's loop (copied
    here)."""
    cases = study(1)
    per = [p for p in (co.coincidence_case(c.time, c.c_eff, c.rate, 5.0, c.window)
                       for c in cases) if p is not None]
    rng = np.random.default_rng(7)

    def hits(shift):
        total = 0
        for (a, b, w, t0, t1), s in zip(per, shift):
            bb = t0 + (b - t0 + s * (t1 - t0)) % (t1 - t0)
            total += int(np.sum(np.min(np.abs(a[:, None] - bb[None, :]), axis=1) <= w))
        return total

    n_a = sum(len(p[0]) for p in per)
    null = np.array([hits(rng.uniform(size=len(per))) / n_a for _ in range(300)])
    r = co.pooled_coincidence_test(per, 300, 7)
    assert r["fraction"] == pytest.approx(hits(np.zeros(len(per))) / n_a, abs=1e-12)
    assert np.allclose(r["null"], null, atol=1e-12)
    assert r["p_value"] == (1 + np.sum(null >= r["fraction"])) / 301


def test_channel_damping_adds_up():
    t = np.arange(0.0, 200.0, 0.05)
    kin = 0.5 * np.exp(-0.02 * t) * np.sin(t) ** 2 + 0.01
    ledger = {"kinetic_energy": kin, "dissipated_viscous": 0.3 * (1 - np.exp(-0.02 * t)),
              "dissipated_hysteresis": 0.1 * np.floor(t / 20.0)}
    scene = SimpleNamespace(contact=SimpleNamespace(damping=0.5))  # a scene's [contact]
    traj = SimpleNamespace(time=t, ledger=ledger, n=3, scene=scene)
    ch = an.channel_damping(traj)
    scale = np.max(np.abs(ch["total"]))  # the spline solve is linear to ~1e-10 of the scale
    assert np.allclose(ch["viscous"] + ch["hysteresis"], ch["total"], rtol=0, atol=1e-8 * scale)
    assert np.array_equal(ch["total"], an.effective_damping(traj))


def test_null_summary():
    s = nl.null_summary(1.0, [0.5, 2.0, np.nan, -1.0, 1.0])
    assert s["K"] == 4 and s["p_value"] == 3 / 5 and s["p_floor"] == 1 / 5
    assert s["fraction_positive"] == 0.75


# ---- no coupling: the measures must not see one, and Fig. 7 is positive anyway --------------
def test_uncoupled_fig7_selection_artefact(uncoupled):
    """max_mean on uncoupled data: the slope is positive far more often than not, and so is its
    time-shift null (the slope is built in); the null covers the observed slope."""
    slopes = np.array([m["fig7"] for m in uncoupled])
    assert np.mean(slopes > 0) >= 0.7
    assert all(m["fig7_null"]["null_mean"] > 0 for m in uncoupled)
    positive = np.array([m["fig7_null"]["fraction_positive"] for m in uncoupled])
    assert np.all(positive >= 0.8) and np.mean(positive) >= 0.85
    assert np.mean([m["fig7_null"]["p_value"] < 0.05 for m in uncoupled]) <= 0.3


@pytest.mark.parametrize("key", ["segment_slope", "segment_r", "rho", "coincidence"])
def test_uncoupled_consistent_with_null(uncoupled, key):
    assert np.mean([m[key]["p_value"] < 0.05 for m in uncoupled]) <= 0.3


def test_uncoupled_swap_positive_random_late_not():
    """Another case's C_eff keeps the max selection, so its slope stays positive; a random late
    segment removes the selection, and on uncoupled data its slope is centred near 0."""
    cases = study(0)
    swap = nl.swap_cases(cases, n_shuffles=100, rng=0)
    late = nl.random_late_null(cases, n_shuffles=100, rng=0)
    assert np.all(np.isfinite(swap)) and np.mean(swap) > 0 and np.mean(swap > 0) > 0.9
    assert np.all(np.isfinite(late)) and abs(np.mean(late)) < np.std(late)


# ---- coupling: the selection-free measures and the coincidence see it ------------------------
@pytest.mark.parametrize("key", ["segment_slope", "segment_r", "rho", "coincidence"])
def test_coupled_detected(coupled, key):
    for m in coupled:
        assert m[key]["p_value"] < 0.01
    if key != "coincidence":
        assert all(m[key]["observed"] > m[key]["null_mean"] + 3 * m[key]["null_sd"]
                   for m in coupled)
    else:
        assert all(m[key]["fraction"] > m[key]["null_mean"] + 3 * m[key]["null_std"]
                   for m in coupled)
