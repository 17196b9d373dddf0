"""Term budget: each force term's size, and the paper's neglect of the cubic wire term."""
import pytest

from mdgran.budget import contact_states, paper_wire_k3, term_budget
from mdgran.chain import model_from_scene
from mdgran.scene import load_scene
from mdgran.simulation import run


def test_paper_wire_cubic_coefficient():
    # physics.md section 3: K3_hat of the micro wire of Table II is about 1.9e-8
    assert paper_wire_k3(load_scene("micro-star")) == pytest.approx(1.9e-8, rel=0.01)


def test_budget_of_micro_star():
    sc = load_scene("micro-star", [("run.duration", 40.0)])
    tr = run(sc, "reference").trajectory
    b = term_budget(tr, sc)
    assert b["contact"]["force_share"] == 1.0  # the contact law dominates
    assert 0 < b["damping"]["force_share"] < 0.1
    assert not b["substrate_cubic"]["on"] and b["substrate_cubic"]["force_share"] < 1e-4
    # the dissipated viscous energy is the run's own
    assert b["damping"]["max_energy"] == tr.ledger["dissipated_viscous"][-1]


def test_contact_states_replay_events():
    sc = load_scene("micro-star", [("run.duration", 40.0)])
    tr = run(sc, "reference").trajectory
    m = model_from_scene(sc)
    st = contact_states(tr, m.n_contacts, m.contact_numbers)
    # the number of open contacts at the end is opens - closes
    assert (~st[-1]).sum() == (tr.ev_kind == 0).sum() - (tr.ev_kind == 1).sum()


def test_switched_off_terms_are_not_evaluated():
    m = model_from_scene(load_scene("micro-star", [("substrate.k1", 0.0)]))
    assert m.substrate_force(None) is None  # never touches x
