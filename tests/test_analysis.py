"""mdgran.analysis against known answers on synthetic input, plus one short real run."""
import numpy as np
import pytest

from mdgran import analysis as an
from mdgran.analysis import clusters as cl
from mdgran.model.contact import ContactLaw, fc_from_lambda


# ---- effective damping -------------------------------------------------------------------------
def damped_oscillator(c, k=1.0, dt=0.05, duration=300.0):
    """Free decay of m x'' + c x' + k x = 0 (m = 1, x(0) = 1, v(0) = 0): t, T, E_d exactly."""
    t = np.arange(0.0, duration, dt)
    z = c / 2.0
    wd = np.sqrt(k - z * z)
    e = np.exp(-z * t)
    x = e * (np.cos(wd * t) + z / wd * np.sin(wd * t))
    v = -e * (k / wd) * np.sin(wd * t)
    kin = 0.5 * v * v
    return t, kin, 0.5 * k - kin - 0.5 * k * x * x


@pytest.mark.parametrize("c", [0.02, 0.1])
def test_c_eff_recovers_known_damping(c):
    t, kin, ed = damped_oscillator(c, duration=12.0 / c)  # energy decays to exp(-12)
    ce = an.c_eff(t, ed, kin, n_beads=1)
    inner = (t > 20.0) & (t < t[-1] - 20.0)  # away from the spline ends
    assert np.max(np.abs(ce[inner] / c - 1.0)) < 0.03


def test_c_eff_scales_with_bead_count():
    """N identical independent oscillators: the equivalent oscillator of mass N m needs N c."""
    t, kin, ed = damped_oscillator(0.05)
    ce = an.c_eff(t, 3 * ed, 3 * kin, n_beads=3)
    inner = (t > 20.0) & (t < t[-1] - 20.0)
    assert np.median(ce[inner]) == pytest.approx(0.15, rel=0.02)


def test_envelope_mean_of_fast_oscillation():
    t = np.arange(0.0, 100.0, 0.1)
    y = 2.0 * (1.0 + np.cos(3.0 * t)) * np.exp(-t / 50.0)  # mean 2 exp(-t/50)
    mid = (t > 5) & (t < 95)
    assert np.allclose(an.envelope_mean(t, y)[mid], 2.0 * np.exp(-t[mid] / 50.0), rtol=0.02)


def test_smoothing_spline_half_amplitude_at_smoothing_time():
    t = np.arange(0.0, 400.0, 0.1)
    for period, gain in [(10.0, 0.5), (20.0, 1 / 1.0625), (5.0, 1 / 17.0)]:
        y = np.sin(2 * np.pi * t / period)
        s = an.smoothing_spline(t, y, 10.0)(t)
        mid = slice(1000, 3000)
        assert np.std(s[mid]) / np.std(y[mid]) == pytest.approx(gain, rel=0.01)


@pytest.mark.parametrize("n", [5, 7, 4001])
@pytest.mark.parametrize("lam", [0.0, 1e-3, 3.7, 1e4])
def test_smoothing_spline_bitwise_scipys(n, lam):
    """mdgran's copy of scipy's make_smoothing_spline (its penalty matrix computed by
    columns together) gives scipy's spline bit for bit, on uniform and uneven samples."""
    from scipy.interpolate import make_smoothing_spline as scipys

    from mdgran.analysis.effective_damping import make_smoothing_spline

    rng = np.random.default_rng(n)
    y = np.cumsum(rng.standard_normal(n))
    for x in (np.linspace(0.0, 400.0, n), np.cumsum(rng.random(n) + 0.01)):
        ours, theirs = make_smoothing_spline(x, y, lam), scipys(x, y, lam=lam)
        assert ours.k == theirs.k == 3
        assert np.array_equal(ours.t, theirs.t) and np.array_equal(ours.c, theirs.c)
        assert np.array_equal(ours.derivative()(x), theirs.derivative()(x))
    with pytest.raises(ValueError, match="ascending"):
        make_smoothing_spline(y[::-1] * 0.0, y, lam)


def test_interior_extrema_as_scipys_argrelextrema():
    """The envelopes' extrema are scipy.signal.argrelextrema's (order 1), ties, plateaus, NaNs,
    short series and ends included."""
    from scipy.signal import argrelextrema

    from mdgran.analysis.effective_damping import interior_extrema

    rng = np.random.default_rng(3)
    series = [rng.integers(0, 4, 60).astype(float), rng.standard_normal(200),
              np.array([1.0, 2.0, 2.0, 1.0, 3.0, np.nan, 0.0, 5.0, 1.0]), np.array([2.0, 1.0]),
              np.array([1.0]), np.array([0.0, 1.0, 0.0])]
    for y in series:
        for comparator in (np.greater, np.less):
            assert np.array_equal(interior_extrema(y, comparator), argrelextrema(y, comparator)[0])


# ---- clusters ----------------------------------------------------------------------------------
# n = 4 beads, fixed walls, contacts 1..5 (contact k joins bead k-1 and bead k), all closed at 0.
EV_TIME = np.array([1.0, 2.0, 3.0, 5.0, 5.0])
EV_CONTACT = np.array([3, 1, 4, 3, 5])
EV_KIND = np.array([0, 0, 0, 1, 0])
C = cl.Cluster


def test_clusters_of_one_state():
    assert cl.clusters_of(np.ones(5, bool), 4) == [C(1, 4, True, True)]
    closed = np.array([0, 1, 0, 1, 1], bool)  # contacts 1 and 3 open
    assert cl.clusters_of(closed, 4) == [C(1, 2, False, False), C(3, 4, False, True)]
    assert cl.clusters_of(closed, 4, min_size=3) == []
    free = np.array([1, 0, 1], bool)  # free chain of 4: contacts 2, 3, 4
    assert cl.clusters_of(free, 4) == [C(1, 2, False, False), C(3, 4, False, False)]


def test_cluster_history_hand_made():
    h = cl.cluster_history(EV_TIME, EV_CONTACT, EV_KIND, n=4)
    assert h.initial == [C(1, 4, True, True)]
    assert list(h.times) == [1.0, 2.0, 3.0, 5.0]  # the two events at t = 5 handled together
    assert list(h.count) == [2, 2, 3, 2]
    assert list(h.new) == [2, 1, 2, 2]
    assert list(h.cumulative) == [2, 3, 5, 7]
    assert h.clusters[-1] == [C(1, 3, False, False), C(4, 4, False, False)]
    assert list(h.cumulative_at([0.5, 1.0, 4.0, 9.0])) == [0, 2, 5, 7]
    # wall attachment not part of the identity: leaving the wall at t = 2 forms nothing new
    h2 = cl.cluster_history(EV_TIME, EV_CONTACT, EV_KIND, n=4, attach=False)
    assert list(h2.new) == [2, 0, 2, 1]


def test_contact_states_rebuilt_from_events():
    s = cl.contact_states([0.0, 1.0, 2.5, 6.0], EV_TIME, EV_CONTACT, EV_KIND, n=4)
    assert s.tolist() == [[1, 1, 1, 1, 1], [1, 1, 0, 1, 1], [0, 1, 0, 1, 1], [0, 1, 1, 0, 0]]


def test_segments_and_rates():
    h = cl.cluster_history(EV_TIME, EV_CONTACT, EV_KIND, n=4)
    s = cl.segments(h, 0.0, 10.0, merge_within=0.5)
    assert list(s.start) == [0, 1, 2, 3, 5] and list(s.end) == [1, 2, 3, 5, 10]
    assert list(s.cumulative) == [0, 2, 3, 5, 7]
    assert np.allclose(s.rate[:-1], [2, 1, 2, 1]) and np.isnan(s.rate[-1])
    merged = cl.segments(h, 0.0, 10.0, merge_within=1.5)  # events at 1, 2, 3 -> one event
    assert list(merged.start) == [0, 1, 5] and list(merged.cumulative) == [0, 5, 7]
    t = np.linspace(0, 10, 1001)
    means = cl.segment_means(t, t, s)  # C(t) = t: mean is the midpoint
    assert np.allclose(means, [0.5, 1.5, 2.5, 4.0, 7.5])
    assert cl.representative_segment(s, means) == 3  # the last segment has no rate
    assert cl.representative_segment(s, [1, 9, 2, 3, 99]) == 1


def test_smoothed_cumulative_appendix_a():
    h = cl.cluster_history(EV_TIME, EV_CONTACT, EV_KIND, n=4)
    t = np.linspace(0, 40, 4001)
    s = cl.segments(h, 0.0, 40.0, merge_within=0.5)
    smooth, rate = cl.smoothed_cumulative(t, s, smoothing_time=1.0)
    assert abs(smooth[0]) < 0.1  # pinned to the origin
    assert np.allclose(smooth[t > 10], 7.0, atol=0.05)  # flat over the last segment
    assert np.allclose(rate[t > 10], 0.0, atol=0.05)
    assert np.sum(rate[:-1] * np.diff(t)) == pytest.approx(smooth[-1] - smooth[0], abs=0.05)
    none = cl.segments(cl.cluster_history([], [], [], n=4), 0.0, 40.0)
    assert np.all(cl.smoothed_cumulative(t, none)[1] == 0.0)


# ---- modes -------------------------------------------------------------------------------------
def test_modes_of_linear_chain_with_walls():
    n, k, k1 = 7, 1.8, 0.0121
    om, shapes = an.modes(np.full(n + 1, k), k1, left_wall=True, right_wall=True)
    j = np.arange(1, n + 1)
    assert np.allclose(om, np.sqrt(k1 + 4 * k * np.sin(j * np.pi / (2 * (n + 1))) ** 2))
    first = shapes[:, 0] * np.sign(shapes[0, 0])  # in-phase mode: sin(i pi / (n + 1))
    assert np.allclose(first, np.sin(np.arange(1, n + 1) * np.pi / (n + 1))
                       / np.linalg.norm(np.sin(np.arange(1, n + 1) * np.pi / (n + 1))))


def test_modes_of_free_cluster():
    b, k, k1 = 5, 1.8, 0.0121
    om, _ = an.modes(np.full(b - 1, k), k1)
    j = np.arange(b)
    assert np.allclose(om, np.sqrt(k1 + 4 * k * np.sin(j * np.pi / (2 * b)) ** 2))
    assert om[0] == pytest.approx(np.sqrt(k1))  # rigid motion on the substrate


def test_equilibrium_modes_use_law_stiffness():
    law = ContactLaw("schwarz", fc_from_lambda(0.64))
    # the check values of docs/physics.md section 2
    assert law.stiffness_eq == pytest.approx(1.81129, abs=1e-4)
    om, _ = an.equilibrium_modes(law, 4, 0.0121, left_wall=True)
    ref, _ = an.modes(np.full(4, law.stiffness_eq), 0.0121, left_wall=True)
    assert np.allclose(om, ref)


# ---- wavelet -----------------------------------------------------------------------------------
def test_wavelet_peak_at_sinusoid_frequency():
    dt, w, amp = 0.05, 1.3, 0.7
    t = np.arange(0.0, 300.0, dt)
    omegas = np.geomspace(0.3, 6.0, 300)
    spec = np.abs(an.morlet_cwt(amp * np.cos(w * t), dt, omegas))
    mid = slice(len(t) // 4, 3 * len(t) // 4)
    ridge = an.peak_frequency(omegas, spec[:, mid])
    assert np.allclose(ridge, w, rtol=0.01)
    assert np.max(spec[:, mid], axis=0) == pytest.approx(np.full(len(ridge), amp), rel=0.01)


# ---- coincidence -------------------------------------------------------------------------------
def test_coincidence_on_synthetic_peaks():
    assert an.coincidence_fraction([10, 50], [12, 200], 5.0) == 0.5
    rng = np.random.default_rng(1)
    b = np.sort(rng.uniform(0, 1000, 8))
    a = b + rng.uniform(-2, 2, 8)  # aligned
    res = an.coincidence_test(a, b, 5.0, 0.0, 1000.0, n_shifts=1000, seed=2)
    assert res["fraction"] == 1.0 and res["p_value"] < 0.01 and res["null_mean"] < 0.3
    unrelated = np.sort(rng.uniform(0, 1000, 8))
    res = an.coincidence_test(unrelated, b, 5.0, 0.0, 1000.0, n_shifts=1000, seed=2)
    assert res["p_value"] > 0.05


# ---- the primary pulse -------------------------------------------------------------------------
def test_pulse_speed_and_width_of_a_gaussian_pulse():
    """A pulse v_i(t) = exp(-(t - (i - 1)/c)**2 / (2 s**2)) running down 21 beads at c = 1.4:
    speed c and full width at half maximum 2 sqrt(2 ln 2) s, both exactly."""
    from types import SimpleNamespace

    c, s, n = 1.4, 0.45, 21
    t = np.arange(0.0, 25.0, 1e-3)
    v = np.exp(-(t[:, None] - np.arange(n) / c) ** 2 / (2 * s * s))
    tr = SimpleNamespace(v=v, time=t, n=n)
    assert an.primary_pulse_speed(tr) == pytest.approx(c, rel=1e-3)
    assert an.pulse_duration(tr) == pytest.approx(2 * np.sqrt(2 * np.log(2)) * s, abs=2e-3)


# ---- a short real run --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def micro_run():
    from mdgran.model.scene import load_scene
    from mdgran.simulation import run

    scene = load_scene("micro-star", [("run.duration", 60.0)])
    return scene, run(scene, "reference").trajectory


def test_real_micro_run(micro_run):
    scene, tr = micro_run
    summary = an.run_summary(tr)
    assert summary["clusters_formed"] > 10  # re-clustering happens
    assert summary["c_eff_mean"] > 0 and summary["c_eff_max_segment"] > 1.0
    assert summary["c_eff_max_segment_rate"] > 0
    assert 25.0 < summary["characteristic_period"] < 35.0  # 2 * 21 / 1.40
    assert 0.9 < an.pulse_duration(tr) < 1.3  # docs/analysis.md: "about 1.1"
    assert 0 < summary["kinetic_remaining"] < 1
    cbar = an.effective_damping(tr)
    assert np.all(np.isfinite(cbar))
    assert set(an.smoothing_effect(tr, (5.0, 20.0))) == {5.0, 20.0}

    # maps agree with the cluster history
    kmap = an.kinetic_energy_map(tr)
    assert kmap.shape == tr.x.shape and np.allclose(kmap.max(axis=1), 1.0)
    assert an.relative_velocity_map(tr).shape == (len(tr.time), tr.n + 1)
    labels = an.cluster_labels(tr)
    hist = cl.trajectory_history(tr)
    assert np.array_equal(labels[:, -1] + 1, hist.count_at(tr.time))

    # modes of a cluster about its mean state over the last 5 time units: where its contacts
    # stayed compressed (positive stiffness), frequencies are real and above sqrt(k1)
    from mdgran.model.chain import model_from_scene

    law = model_from_scene(scene).law
    checked = 0
    for c in cl.clusters_of(an.states_map(tr)[-1], tr.n):
        om, _, comp = an.cluster_modes_in_run(tr, c, 55.0, 60.0)
        assert len(om) == c.last - c.first + 1
        assert len(comp) == len(om) - 1 + c.left_wall + c.right_wall
        if len(comp) and np.all(comp > law.delta_force_max):
            assert np.all(om >= np.sqrt(scene.data["substrate"]["k1"]) * 0.999)
            checked += 1
            big = c
    assert checked >= 1

    t, omegas, amp = an.wavelet_spectrum(tr, (big.first + big.last) // 2, t0=20.0)
    assert amp.shape == (len(omegas), len(t)) and np.all(np.isfinite(amp))


def test_cluster_lives_from_hand_made_events():
    """3 beads between walls (contacts 1..4), all closed: one wall-to-wall cluster.  Contact 2
    opens at t = 1 (clusters [1]+left wall, [2-3]+right wall), closes at t = 3 (the whole chain
    again, re-formed), contact 3 opens at t = 4.  Clusters alive at the end are censored; the
    initial cluster has no birth time."""
    from mdgran.analysis import cluster_history
    from mdgran.analysis.statistics import cluster_lives, ks_compare

    h = cluster_history([1.0, 3.0, 4.0], [2, 2, 3], [0, 1, 0], 3, True)
    lv = cluster_lives(h)
    assert sorted(zip(lv.born, lv.lifetime, lv.size)) == [(1.0, 2.0, 1), (1.0, 2.0, 2),
                                                          (3.0, 1.0, 3)]
    late = cluster_lives(h, t_from=2.0)
    assert list(late.size) == [3]
    rng = np.random.default_rng(1)
    same = ks_compare(rng.exponential(1.0, 400), rng.exponential(1.0, 400))
    other = ks_compare(rng.exponential(1.0, 400), rng.exponential(2.0, 400))
    assert same["pvalue"] > 0.01 > other["pvalue"]
