"""The fast backend's event windows piece by piece, against the kernel's own full step and
conservation laws: a window's first step (:func:`~mdgran.backends.fast_kernel.window_start`)
against :func:`~mdgran.backends.fast_kernel.window_pass`, and a window whose only event ends
the step.  (Whole runs through windows: tests/test_fast.py.)"""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mdgran.backends import fast_kernel as fk
from mdgran.backends.fast import FastBackend
from mdgran.model.scene import load_scene

from conftest import make_scene


#: scenes whose event windows take each branch of the window's first step: walls, a free end,
#: unlike beads, substrate damping, a pulsed bead, the JKR band
WINDOW_SCENES = {
    "micro-star": [("chain.n", 12)],
    "mixed/tapered": [],
    "driven/pulse": [("chain.n", 12), ("substrate.damping", 0.3)],
    "hard/jkr-displacement": [("chain.n", 12), ("chain.boundary", "free"),
                              ("substrate.damping", 0.3)],
}


def _window_backend(name, cache={}):
    if name not in cache:
        cache[name] = FastBackend(load_scene(name, WINDOW_SCENES[name]))
    return cache[name]


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(sorted(WINDOW_SCENES)), seed=st.integers(0, 2**32 - 1),
       where=st.floats(0.0, 1.0), width=st.integers(0, 5), frac=st.floats(0.01, 1.0),
       t0=st.floats(0.0, 20.0))
def test_window_start_is_window_pass_without_its_forces(name, seed, where, width, frac, t0):
    """An event window's first step (the whole step, cut by its event in the usual case) is
    taken by window_start, which computes no force: its positions, end damping power, edges
    in the mean-force band and status are window_pass's, bit for bit, for compressions drawn
    near snap-off, in the bulk and beyond the force table, any contact states and window."""
    b = _window_backend(name)
    flags, params, walls = b.flags, b.params, b.flags.walls
    n, m = b.model.n, b.model.n_contacts
    lo = int(where * (n - 1))
    hi = min(lo + width, n - 1)
    rng = np.random.default_rng(seed)
    band = params.mean_force_below
    d = np.where(rng.random(m) < 0.6, rng.uniform(band - 0.15, band + 0.05, m),
                 rng.uniform(-0.5, 3.0, m))
    d[rng.random(m) < 0.05] = rng.uniform(90.0, 110.0)  # around the table's end
    x = np.zeros(n)
    for j in range(m):  # positions with those compressions
        left, right = fk.beads_of(walls, j)
        if 0 <= left and right < n:
            x[right] = x[left] - params.gap - d[j]
    cur = fk.Beads(x, rng.normal(0.0, 2.0, n), rng.normal(0.0, 5.0, n))
    closed = rng.random(m) < 0.7
    h = frac * b.dt
    x_start = np.full(n, np.nan)
    start = fk.window_start(flags, params, cur, x_start, closed, h, t0, lo, hi)
    nxt = fk.Beads(np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan))
    memo = np.zeros((m, 2))
    p1, _, _, band_edges, status, bad = fk.window_pass(flags, params, cur, nxt, closed, h, t0,
                                                       lo, hi, memo)
    assert np.float64(start[0]).tobytes() == np.float64(p1).tobytes()
    assert start[1:] == (band_edges, status, bad)
    assert x_start.tobytes() == nxt.x.tobytes()


def _snap_off_at_step_end(b, eps):
    """A free chain of 6 beads, contact 2 (beads 2, 3) closed and stretched to delta_off +
    eps, the others open, its beads moving apart so that it reaches delta_off at the step's
    end (velocity chosen from its parabola); returns (old state, kernel state)."""
    params, h = b.params, b.dt
    ks = fk.new_state(6, 5, 1 << 10)
    ks.closed[2] = True
    d0 = params.delta_off + eps
    x = np.array([-3.0, -2.0, 0.0, -d0, 2.0 - d0, 3.0 - d0])
    old = fk.Beads(x, np.zeros(6), np.zeros(6))
    fk.init_acc(fk.Flags(*b.flags), params, old, ks)
    q = old.a[2] - old.a[3]
    r = (params.delta_off - d0 - 0.5 * h * h * q) / h
    old.v[2], old.v[3] = 0.5 * r, -0.5 * r
    return old, ks


@pytest.mark.parametrize("eps", [1e-4, 3e-4, 1e-3, 3e-3, 1e-2])
def test_window_whose_event_ends_the_step_is_stepped_whole(eps):
    """An event window whose only event falls at the step's end (a snap-off exactly there,
    to rounding) keeps its whole first step: it is stepped again with its forces, the
    contact opens at t0 + dt, and the momentum of the window and its neighbours (a free
    chain, no substrate, no damping: internal forces only) is what it was, to round-off."""
    b = FastBackend(make_scene(
        chain={"n": 6, "boundary": "free"}, substrate={"k1": 0.0}, contact={"damping": 0.0},
        impulse={"velocity": 0.0}, run={"duration": 1.0, "output_interval": 0.5,
                                        "dt": 0.0025}))
    flags, params, h = fk.Flags(*b.flags), b.params, b.dt
    old, ks = _snap_off_at_step_end(b, eps)
    x_new = old.x + h * old.v + 0.5 * h * h * old.a
    s = fk.first_root(False, params, 2, old, x_new, ks.closed, h)
    if not s >= h * (1.0 - 1e-9):
        pytest.skip(f"rounding put the root at {s!r}, not at the step's end")
    new = fk.Beads(x_new, old.v.copy(), old.a.copy())
    log = ks.lanes.log
    lane = fk.Lane(ks.closed, ks.lanes.counters[0],
                   fk.EventLog(log.time[0], log.contact[0], log.kind[0], log.loss[0]),
                   ks.lanes.switching[0], ks.lanes.chatter[0], ks.seg.branch, ks.local)
    grow = fk.resolve_window(flags, params, old, new, lane, 2, 3, 1.0, h)[0]
    c = lane.counters[0]
    assert grow == 0 and c["status"] == fk.OK and c["events"] == 1
    assert lane.log.contact[0] == 2 and lane.log.time[0] == 1.0 + h and not ks.closed[2]
    p0, p1 = old.v[1:5].sum(), new.v[1:5].sum()
    assert abs(p1 - p0) <= 1e-13 * np.abs(old.v).sum(), (p0, p1)
    assert np.abs(new.v[2:4] - old.v[2:4]).max() < 0.5 * np.abs(old.v[2:4]).max()
