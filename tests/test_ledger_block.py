"""The ledger of a block of states (ChainModel.ledger_block, what the fast backend hands the
driver with its frames) is bitwise the ledger of each state alone (ChainModel.ledger, what
every other backend's frames get): random states on every law, boundary and substrate, chain
lengths around numpy's and BLAS's summation blocks, and a fast run frame by frame."""
import numpy as np
import pytest

from mdgran.backends.fast import FastBackend
from mdgran.model.chain import model_from_scene, row_dots
from mdgran.model.scene import load_scene

SCENES = [
    ("micro-star", []),  # Schwarz, displacement snap-off, walls, k1, damping
    ("macro-hertz", []),  # Hertz
    ("dmt-chain", []),
    ("collision-pair", []),  # free chain with an initial gap
    ("hard/jkr-force", [("substrate.k3", 0.05)]),  # force rule, cubic substrate
]


def random_block(model, frames, rng):
    """``frames`` random states of ``model``: compressions of order 1 (p), some contacts
    open, dissipated energies of order 10."""
    x = rng.standard_normal((frames, model.n)) * rng.choice([1e-3, 0.3, 2.0], (frames, 1))
    v = rng.standard_normal((frames, model.n)) * 5.0
    closed = rng.random((frames, model.n_contacts)) < 0.7
    return x, v, closed, 10.0 * rng.random(frames), 10.0 * rng.random(frames)


@pytest.mark.parametrize("name, overrides", SCENES)
@pytest.mark.parametrize("n", [1, 2, 20, 129, 1000])
def test_block_ledger_is_the_ledger_of_each_state(name, overrides, n):
    if name == "collision-pair" and n == 1:
        pytest.skip("a free chain needs two beads")
    model = model_from_scene(load_scene(name, [*overrides, ("chain.n", n)]))
    rng = np.random.default_rng(n)
    x, v, closed, dv, dh = random_block(model, 40, rng)
    block = model.ledger_block(x, v, closed, dv, dh)
    for k in range(len(x)):
        one = model.ledger(x[k], v[k], closed[k], float(dv[k]), float(dh[k]))
        assert list(block) == list(one)
        assert [float(c[k]).hex() for c in block.values()] == [float(b).hex()
                                                               for b in one.values()]


def test_row_dots_is_np_dot_of_each_row():
    rng = np.random.default_rng(3)
    for n in (1, 7, 33, 100, 4097):
        a = rng.standard_normal((25, n)) * 10.0 ** rng.integers(-6, 6, (25, 1))
        assert np.array_equal(row_dots(a), np.array([np.dot(r, r) for r in a]))


def test_fast_frames_carry_their_ledgers():
    """Every frame of a fast run (events included) hands the driver the ledger that
    ChainModel.ledger computes from the frame itself, from its block's."""
    b = FastBackend(load_scene("micro-star", [("run.duration", 60.0)]))
    frames = list(b.frames())
    assert len(frames) == 601 and b.stats["events"] > 0
    for f in frames:
        one = b.model.ledger(f.x, f.v, f.closed, f.dissipated_viscous, f.dissipated_hysteresis)
        got = f.ledger(b.model)
        assert [float(a).hex() for a in got.values()] == [float(b).hex() for b in one.values()]
    assert {len(f.block) for f in frames} == {1, 600}  # t = 0 alone, then one kernel call


@pytest.mark.parametrize("name, overrides", SCENES)
def test_contacts_at_rest_take_the_law_once(name, overrides):
    """The ledger evaluates the law once for the contacts at delta = +0 and -0 (a long chain
    at rest) and elementwise for the others: bitwise the law applied to every contact."""
    model = model_from_scene(load_scene(name, overrides))
    rng = np.random.default_rng(7)
    delta = rng.normal(0.0, 0.3, (30, 200))
    delta[:, ::3], delta[:, 1::7] = 0.0, -0.0
    closed = rng.random(delta.shape) < 0.8
    every = np.where(closed, model.contact_law_energy(delta), 0.0)
    assert every.tobytes() == model.closed_contact_energies(delta, closed).tobytes()


@pytest.mark.parametrize("name, overrides", [
    ("mixed/dimer", []),
    ("micro-star", [("chain.boundary", "free"), ("beads.density", [1.0, 0.3] * 2498)])])
def test_a_mixture_longer_than_a_ledger_block(name, overrides):
    """Unlike beads on more contacts than one ledger block (4096): each block's contacts take
    their own pair laws (the whole chain's scales were broadcast against one block and the
    ledger raised).  The block ledger is each state's, and its contact energy is the sum of
    the pair laws' energies taken contact by contact."""
    from mdgran.model.chain import LEDGER_BLOCK

    model = model_from_scene(load_scene(name, [("chain.n", LEDGER_BLOCK + 900), *overrides]))
    assert model.n_contacts > LEDGER_BLOCK
    x, v, closed, dv, dh = random_block(model, 3, np.random.default_rng(7))
    block = model.ledger_block(x, v, closed, dv, dh)
    for k in range(len(x)):
        one = model.ledger(x[k], v[k], closed[k], float(dv[k]), float(dh[k]))
        assert all(block[t][k] == one[t] for t in one)
        delta = model.compressions(x[k])
        each = sum(float(model.contact_law_energy(delta[j:j + 1], [j])[0])
                   for j in np.flatnonzero(closed[k]))
        assert block["contact_energy"][k] == pytest.approx(each, rel=1e-12)
