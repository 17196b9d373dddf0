"""Term budget: each force term's size, and the paper's neglect of the cubic wire term."""
import numpy as np
import pytest

from mdgran.budget import paper_wire_k3, term_budget
from mdgran.model.chain import model_from_scene
from mdgran.model.scene import load_scene
from mdgran.simulation import make_backend, run


def test_paper_wire_cubic_coefficient():
    # docs/physics.md section 3: K3_hat of the micro wire of Table II is about 1.9e-8
    assert paper_wire_k3(load_scene("micro-star")) == pytest.approx(1.9e-8, rel=0.01)


def test_budget_of_micro_star():
    sc = load_scene("micro-star", [("run.duration", 40.0)])
    tr = run(sc, "reference").trajectory
    b = term_budget(tr)
    assert b["contact"]["force_share"] == 1.0  # the contact law dominates
    assert 0 < b["damping"]["force_share"] < 0.1
    assert not b["substrate_cubic"]["on"] and b["substrate_cubic"]["force_share"] < 1e-4
    # the dissipated viscous energy is the run's own
    assert b["damping"]["max_energy"] == tr.ledger["dissipated_viscous"][-1]


def test_contact_states_start_open_with_a_gap():
    # collision-pair starts open (initial_gap > 0): the stored and the replayed states are the
    # backend's own frames' states
    sc = load_scene("collision-pair")
    truth = np.array([f.closed.copy() for f in make_backend(sc, "reference").frames()])
    tr = run(sc, "reference").trajectory
    st = tr.replayed_states()
    assert st.shape == truth.shape == tr.closed.shape and truth.any() and not truth.all()
    assert (st == truth).all() and (tr.closed == truth).all()


def test_switched_off_terms_are_not_evaluated():
    m = model_from_scene(load_scene("micro-star", [("substrate.k1", 0.0)]))
    assert m.substrate_force(None) is None  # never touches x
