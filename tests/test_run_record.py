"""The run record (mdgran.output.run_record.Run): stored contact states against the events replayed,
a file written without states (an older mdgran's) read back the same, the scene read from the
file, one ledger-error scale, and the cached measures computed once each."""
import importlib

import h5py
import numpy as np
import pytest

from mdgran import analysis as an
from mdgran.model.chain import contact_numbers, replay_states
from mdgran.output.run_record import Run, ledger_scale, read_h5
from mdgran.model.scene import builtin_scenes, load_scene
from mdgran.simulation import run


@pytest.fixture(scope="module")
def macro(tmp_path_factory):
    """macro-hertz to t = 30 on the reference, written to a file (Hertz contacts close and open
    often: 120-odd events on most contacts)."""
    path = tmp_path_factory.mktemp("record") / "macro.h5"
    res = run(load_scene("macro-hertz", [("run.duration", 30.0)]), "reference", out=path)
    return res, path


def test_stored_states_are_the_events_replayed(macro):
    res, path = macro
    mem, back = res.trajectory, read_h5(path)
    assert isinstance(mem, Run) and isinstance(back, Run)
    kinds = set(mem.ev_kind.tolist())
    assert len(mem.ev_time) > 50 and kinds == {0, 1} and len(set(mem.ev_contact)) > 5
    # the states the backend stepped with (kept in memory, and stored in the file) ...
    np.testing.assert_array_equal(back.closed, mem.closed)
    # ... are the initial states with every event up to each frame applied
    np.testing.assert_array_equal(back.replayed_states(), back.closed)
    # every state changes only at frames that follow an event of that contact
    changed = np.argwhere(np.diff(back.closed.astype(np.int8), axis=0) != 0)
    for f, col in changed[:20]:
        c = back.contact_numbers[col]
        t0, t1 = back.time[f], back.time[f + 1]
        assert np.any((back.ev_contact == c) & (back.ev_time > t0) & (back.ev_time <= t1))


def test_file_without_states_is_read_by_replaying_its_events(macro, tmp_path):
    """An older mdgran stored no /observables/contacts without output.contacts: read_h5
    rebuilds the states from the events, equal to the ones stored."""
    res, path = macro
    old = tmp_path / "old.h5"
    with h5py.File(path, "r") as src, h5py.File(old, "w") as dst:
        for name in src:
            src.copy(src[name], dst, name)
        for k, v in src.attrs.items():
            dst.attrs[k] = v
        del dst["observables/contacts"]
    back = read_h5(old)
    np.testing.assert_array_equal(back.closed, res.trajectory.closed)
    np.testing.assert_array_equal(back.x, res.trajectory.x)
    assert back.scene.data == res.trajectory.scene.data  # the stored scene, parsed
    assert back.max_ledger_error == res.max_ledger_error  # one scale: E_imp


def test_replay_at_equal_times_and_free_chain_numbering():
    # free chain of 4 beads: contacts 2, 3, 4; two events on contact 3 at one instant: the
    # later in the list wins; a frame at an event's time includes it
    assert contact_numbers(4, walls=False).tolist() == [2, 3, 4]
    assert contact_numbers(4, walls=True).tolist() == [1, 2, 3, 4, 5]
    st = replay_states(np.ones(3, bool), [1.0, 2.0, 2.0, 3.0], [3, 3, 3, 2], [0, 1, 0, 0],
                       [0.0, 1.0, 2.0, 2.5, 3.0], walls=False)
    expect = [[1, 1, 1], [1, 0, 1], [1, 0, 1], [1, 0, 1], [0, 0, 1]]
    np.testing.assert_array_equal(st, np.array(expect, bool))


def test_scene_from_the_file_and_the_ledger_scale(tmp_path):
    """A scene without a material (jkr-chain) stores the default [material] table, which alone
    does not resolve: the record still parses it (once).  The ledger error's scale is E_imp,
    or max(|E0|, 1) without an impulse."""
    path = tmp_path / "jkr.h5"
    res = run(load_scene("jkr-chain", [("run.duration", 5.0)]), "reference", out=path)
    back = read_h5(path)
    assert back.scene is back.scene and back.scene.data["contact"]["law"] == "jkr"
    assert back.scene.data == res.trajectory.scene.data
    assert back.ledger_scale() == back.scene.impulse_energy == 72.0
    assert np.max(np.abs(back.ledger_error())) == res.max_ledger_error
    assert ledger_scale(0.0, -3.0) == 3.0 and ledger_scale(0.0, 0.25) == 1.0


def test_measures_are_computed_once(macro, monkeypatch):
    """Every measure the report asks for, asked twice: C_eff's smoothing runs once for the
    total and once per channel, the clusters are followed through the events once, and the
    values are those of the pure functions."""
    res, path = macro
    tr = read_h5(path)
    calls = {"c_eff": 0, "cluster_history": 0}
    cl = importlib.import_module("mdgran.analysis.clusters")
    ed = importlib.import_module("mdgran.analysis.effective_damping")  # the package's name
    # effective_damping is the function

    def counted(mod, name):
        orig = getattr(mod, name)

        def wrapper(*a, **k):
            calls[name] += 1
            return orig(*a, **k)
        monkeypatch.setattr(mod, name, wrapper)

    counted(ed, "c_eff")
    counted(cl, "cluster_history")
    m = tr.measures
    for _ in range(2):
        summary, co, case, ch = m.summary, m.coincidence, m.null_case, m.channels
        _ = (m.c_eff, m.reclustering, m.history, m.rate, m.characteristic_period)
    assert tr.measures is m
    assert calls == {"c_eff": 3, "cluster_history": 1}
    assert sorted(m.computed) == sorted(set(m.computed))  # each once
    monkeypatch.undo()
    fresh = read_h5(path)
    assert summary == an.run_summary(fresh)
    ref = an.run_coincidence(fresh)
    assert co["p_value"] == ref["p_value"] and np.array_equal(co["rate_peaks"], ref["rate_peaks"])
    assert np.array_equal(case.c_eff, an.case_of_run(fresh).c_eff)
    assert np.array_equal(ch["viscous"], an.channel_damping(fresh)["viscous"])


@pytest.mark.parametrize("name", sorted(builtin_scenes()))
def test_the_record_measures_the_ledger_as_the_run_does(name):
    """Every built-in scene, 1 time unit on the reference: the run record's ledger error
    (read back from the record alone) is the run's, in the same energy scale: the struck
    bead's m v0^2 / 2 (mixed/striker's striker is 8x a chain bead) plus the excitations'."""
    scene = load_scene(name, [("run.duration", 1.0), ("run.output_interval", 0.5)])
    res = run(scene, "reference")
    assert res.trajectory.ledger_scale() == pytest.approx(scene.energy_scale, rel=1e-12)
    assert res.trajectory.max_ledger_error == pytest.approx(res.max_ledger_error, rel=1e-9,
                                                            abs=1e-300)
