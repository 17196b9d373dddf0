"""Output that costs what moved (mdgran.rest_blocks): a long chain struck at one end.

The fast backend hands blocks of frames whose beads at rest it never copies
(``Frames.moved``), the ledger sums the beads that moved, and the writer writes only the
column blocks of a long series that differ from the fill value.  Checked against independent
values: the same chain's full ledger (every bead summed), a short twin chain the pulse never
crosses (its file's columns bitwise), the frames in memory, and an uninterrupted run (resume).
"""
import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import InterruptAt, make_scene

from mdgran.api import run
from mdgran.backends.fast import FastBackend
from mdgran.model.chain import initial_states, touching_contacts
from mdgran.rest_blocks import BLOCK, block_mask, column_runs, lazy_zeros
from mdgran.model.scene import POSITIONS_AUTO_BEADS, load_scene

OVER = [("run.duration", 20.0), ("run.output_interval", 1.0)]


def _series(path):
    with h5py.File(path, "r") as f:
        out = {k: f[f"particles/chain/{k}/value"][()] for k in ("displacement", "velocity")}
        out["closed"] = f["observables/contacts/closed/value"][()]
        out["chunks"] = {k: f[f"particles/chain/{k}/value"].id.get_num_chunks()
                         for k in ("displacement", "velocity")}
        out["chunks"]["closed"] = f["observables/contacts/closed/value"].id.get_num_chunks()
        out["energy"] = f["observables/total_energy/value"][()]
    return out


def test_long_chain_file_holds_every_value_and_costs_what_moved(tmp_path):
    """micro-star struck at bead 1, 3,000 and 30,000 beads to t = 20 (38 beads move): the
    long chain's file reads back bitwise the short chain's columns and zeros beyond them,
    and equals the frames in memory; its per-bead series hold one written chunk per frame
    (the blocks at rest are never written)."""
    short = run(load_scene("micro-star", OVER + [("chain.n", 3000)]), "fast",
                out=tmp_path / "short.h5", threads=1)
    long = run(load_scene("micro-star", OVER + [("chain.n", 30_000)]), "fast",
               out=tmp_path / "long.h5", threads=1)
    a, b = _series(tmp_path / "short.h5"), _series(tmp_path / "long.h5")
    frames = len(b["displacement"])
    for name in ("displacement", "velocity"):
        assert np.array_equal(a[name], b[name][:, :3000]), name
        assert not b[name][:, 3000:].view(np.uint64).any(), name  # +0.0, bitwise
    assert np.array_equal(a["closed"], b["closed"][:, :3001])
    assert b["closed"][:, 3001:].all()  # at rest: closed, as they started
    tr = long.trajectory
    assert np.array_equal(tr.x, b["displacement"]) and np.array_equal(tr.v, b["velocity"])
    assert np.array_equal(tr.closed, b["closed"].astype(bool))
    assert 30_000 > BLOCK and b["chunks"]["displacement"] == b["chunks"]["velocity"] == frames
    assert b["chunks"]["closed"] <= frames
    # the ledger of the moved beads: the short chain's, but for the contacts at rest
    # (each at its energy at delta = +0), to round-off
    scale = load_scene("micro-star").energy_scale
    assert np.max(np.abs(b["energy"] - b["energy"][0] - (a["energy"] - a["energy"][0]))) \
        <= 1e-12 * scale


@settings(max_examples=8, deadline=None)
@given(n=st.integers(40, 300), free=st.booleans(), gap=st.sampled_from([0.0, 0.002]),
       law=st.sampled_from(["schwarz", "dmt", "hertz"]), v0=st.sampled_from([3.0, 12.0, 40.0]),
       segment=st.integers(4, 32), block=st.integers(3, 64))
def test_moved_frames_keep_their_promise_and_ledger(n, free, gap, law, v0, segment, block):
    """Any chain struck at bead 1 (fixed or free, with or without a gap, three laws), its pass
    cut into segments so that the activity front skips the beads at rest, the ledger summed
    by blocks of 3-64 beads: outside each
    block's ``moved`` beads every x and v is +0.0 and every contact that touches none of them
    is in its initial state, and the ledger summed over the moved beads is bitwise the ledger
    summed over every bead (sums by blocks: a block of zeros changes no sum)."""
    from mdgran.model import chain
    from mdgran.backends import fast_kernel as fk

    scene = make_scene(chain={"n": n, "boundary": "free" if free else "fixed",
                              "initial_gap": gap},
                       contact={"law": law}, impulse={"velocity": v0},
                       run={"duration": 6.0, "output_interval": 0.5, "dt": 0.0025})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fk, "SEGMENT", segment)
        mp.setattr(chain, "LEDGER_BLOCK", block)
        backend = FastBackend(scene, threads=1)
        model = backend.model
        rest_states = initial_states(n, model.walls, model.gap)
        seen = 0
        for block in backend.blocks():
            if block.moved is None:
                continue
            seen += 1
            lo, hi = block.moved
            c0, c1 = touching_contacts(n, model.walls, lo, hi)
            for arr in (block.x, block.v):
                assert not arr[:, :lo].view(np.uint64).any()
                assert not arr[:, hi:].view(np.uint64).any()
            assert (block.closed[:, :c0] == rest_states[:c0]).all()
            assert (block.closed[:, c1:] == rest_states[c1:]).all()
            full = model.ledger_block(block.x, block.v, block.closed,
                                      block.dissipated_viscous, block.dissipated_hysteresis)
            part = block.ledger()
            for term, value in full.items():
                assert np.array_equal(part[term], value), term
    assert seen


def test_resumed_long_chain_equals_uninterrupted(tmp_path):
    """A long chain's checkpoint hashes and keeps only the blocks that moved: an interrupted
    run of 6,000 beads resumed from it writes the uninterrupted run's file, bitwise."""
    sc = load_scene("micro-star", OVER + [("chain.n", 6000)])
    run(sc, "fast", out=tmp_path / "whole.h5", threads=1)
    out = tmp_path / "r.h5"
    with pytest.raises(KeyboardInterrupt):
        run(sc, "fast", out=out, checkpoint_every=0.0, reporters=[InterruptAt(12.0)], threads=1)
    with h5py.File(tmp_path / "r.h5.partial", "r") as f:
        assert '"data_digest": "blocks"' in f["checkpoint"].attrs["meta"]
    run(sc, "fast", out=out, checkpoint_every=0.0, resume=True, threads=1)
    a, b = _series(out), _series(tmp_path / "whole.h5")
    for name in ("displacement", "velocity", "closed", "energy"):
        assert np.array_equal(a[name], b[name]), name


def test_positions_default_with_the_stored_beads():
    def positions(*keys):
        return load_scene("micro-star", list(keys)).data["output"]["positions"]

    assert positions() is True
    assert positions(("chain.n", POSITIONS_AUTO_BEADS)) is True
    assert positions(("chain.n", POSITIONS_AUTO_BEADS + 1)) is False
    assert positions(("chain.n", 10 * POSITIONS_AUTO_BEADS), ("output.bead_stride", 10)) is True
    assert positions(("chain.n", 10**6), ("output.positions", True)) is True


@given(st.lists(st.integers(0, 99), max_size=20), st.integers(1, 7))
def test_blocks_and_runs_cover_exactly_what_differs(cols, width):
    rows = np.zeros((2, 100))
    rows[1, cols] = 1.0
    rows[0, 50] = -0.0  # differs from the fill 0.0 bitwise
    mask = block_mask(rows, width, 0.0)
    want = sorted({c // width for c in cols} | {50 // width})
    assert np.flatnonzero(mask.any(axis=0)).tolist() == want
    covered = np.zeros(100, dtype=bool)
    for c0, c1 in column_runs(mask.any(axis=0), width, 100):
        covered[c0:c1] = True
    assert covered[cols].all() and covered[50]
    assert covered.sum() <= len(want) * width


def test_lazy_zeros_are_zeros():
    for shape in ((3, 10), (4, 1 << 18)):
        z = lazy_zeros(shape)
        assert z.shape == shape and z.flags.writeable and not z.any()
        z[1, 2] = 5.0
        assert z.sum() == 5.0
