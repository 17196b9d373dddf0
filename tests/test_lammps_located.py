"""The native contact's located-events mode (``fix mdgran/chain ... events located``).

The fix integrates the chain itself (velocity Verlet), locates each snap event inside the step
and steps the event's window of beads again alone, split there, as the fast backend does:
second order in dt through events.  Checked against the reference backend (event-driven,
tolerance 1e-12): the error shrinks ~4x when dt halves, the events are the reference's, the
ledger closes to the fast backend's level; 1 and 2 MPI ranks agree bit for bit, windows across
the slab boundary included, and a window beyond the ghosts stops the run.  (The quantized mode against the hook, bitwise: tests/test_lammps_plugin.py.)
"""
import ctypes
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import run_on_one_and_two_ranks, spread_chain_input
from mdgran.backends.lammps import plugin as native_plugin
from mdgran.model.scene import SceneError, load_scene
from mdgran.simulation import make_backend, run

pytestmark = pytest.mark.lammps
MPIEXEC = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))


def located(scene, dt=None, **options):
    if dt is not None:
        options["dt"] = dt
    res = run(scene, "lammps", contact="native", events="located", **options)
    assert res.status == "complete"
    return res


def events(res):
    t = res.trajectory
    return list(zip(t.ev_contact.tolist(), t.ev_kind.tolist())), np.asarray(t.ev_time)


def test_options_and_order(plugin):
    sc = load_scene("micro-star", [("run.duration", 1.0)])
    b = make_backend(sc, "lammps", contact="native")
    assert b.event_mode == "located" and b.order == 2  # the native default
    assert b.refinement(sc)[1] == pytest.approx(4.0 / 3.0)
    assert make_backend(sc, "lammps:native:quantized").order == 1
    assert make_backend(sc, "lammps").order == 1  # the hook: quantized only
    for bad, words in ((dict(contact="hook", events="located"), "needs contact='native'"),
                       (dict(contact="native", events="exact"), "'located' or 'quantized'")):
        with pytest.raises(SceneError) as exc:
            make_backend(sc, "lammps", **bad)
        assert exc.value.key.endswith("events") and words in str(exc.value)


def contact_phase(res):
    """(contact duration, rebound speed) of collision-pair: from the close to the open event,
    and the pair's relative speed at the end (the beads have separated)."""
    (kinds, times) = events(res)
    assert [k for _, k in kinds] == [1, 0]  # close, then open
    v = res.trajectory.v[-1]
    return times[1] - times[0], abs(v[1] - v[0])


def test_collision_pair_second_order(plugin):
    """Contact duration and rebound speed against the reference: error / 4 when dt halves."""
    sc = load_scene("collision-pair", [("run.duration", 10.0)])
    ref = contact_phase(run(sc, "reference", tolerance=1e-12))
    dt0 = float(sc.data["run"]["dt"])
    errs = [np.abs(np.subtract(contact_phase(located(sc, dt0 / k)), ref)) for k in (1, 2, 4)]
    for coarse, fine in zip(errs, errs[1:]):
        ratio = coarse / fine
        assert np.all((3.3 < ratio) & (ratio < 4.7)), ratio  # measured 3.8-4.0
    assert np.all(errs[0] < 1e-3 * np.abs(ref))


def test_micro_star_second_order_and_events(plugin):
    """Positions against the reference over 20 time units (a snap-off at t = 0.034 and one at
    16.57): the error shrinks 4x per halving of dt (measured 1.12e-4, 2.80e-5, 6.99e-6), the
    events are the reference's, their times within the same second-order error."""
    sc = load_scene("micro-star", [("run.duration", 20.0)])
    ref = run(sc, "reference", tolerance=1e-12)
    ref_kinds, ref_times = events(ref)
    dt0 = float(sc.data["run"]["dt"])
    errs = []
    for k in (1, 2, 4):
        res = located(sc, dt0 / k)
        kinds, times = events(res)
        assert kinds == ref_kinds and len(kinds) == 2
        assert np.abs(times - ref_times).max() < 1e-5 / k**2  # measured 4.1e-6 / k^2
        errs.append(np.abs(res.trajectory.x - ref.trajectory.x).max())
    assert 3.5 < errs[0] / errs[1] < 4.5 and 3.5 < errs[1] / errs[2] < 4.5, errs


def test_micro_star_ledger_at_the_default_dt(plugin):
    """The whole micro-star run (t = 400) at its dt: ledger error <= 2e-5 of E_imp, the fast
    backend's level (the quantized mode: ~1e-3), within the declared bound."""
    res = located(load_scene("micro-star"))
    assert res.max_ledger_error <= 2e-5
    assert res.max_ledger_error <= res.ledger_bound
    quantized = run(load_scene("micro-star", [("run.duration", 100.0)]), "lammps",
                    contact="native", events="quantized")
    assert quantized.max_ledger_error > 10 * res.max_ledger_error  # located is the better one


def test_macro_hertz_against_reference(plugin):
    """Hertz (delta_off = 0, contacts resting at delta = 0 ahead of the pulse): the same 46
    events as the reference to t = 20, and second-order convergence."""
    sc = load_scene("macro-hertz", [("run.duration", 20.0)])
    ref = run(sc, "reference", tolerance=1e-12)
    dt0 = float(sc.data["run"]["dt"])
    a, b = located(sc), located(sc, dt0 / 2)
    assert events(a)[0] == events(ref)[0] == events(b)[0]
    ea = np.abs(a.trajectory.x - ref.trajectory.x).max()
    eb = np.abs(b.trajectory.x - ref.trajectory.x).max()
    assert 3.5 < ea / eb < 4.5 and ea < 2e-4  # measured 1.07e-4, ratio 3.99


SPREAD_FIXES = """fix contact all mdgran/chain law schwarz lambda 0.64 damping 0.013 k1 0.012 k3 0.002 &
    walls yes events located
fix_modify contact energy yes
fix line all setforce NULL 0.0 0.0"""


def spread(plugin):
    """conftest's 200-bead input with the located contact."""
    return spread_chain_input(plugin, SPREAD_FIXES, "ke pe f_contact[1] f_contact[2] f_contact[3]")


def test_one_and_two_ranks_agree(plugin, tmp_path):
    """200 beads over 2 ranks with a ghost cut-off of 6 (a few ghosts per rank), bead 100
    struck next to the slab boundary: its snap-offs are stepped in their event windows by the
    ranks holding them; the same positions, velocities, events and energies as on 1 rank."""
    script = tmp_path / "spread.in"
    script.write_text(spread(plugin))
    thermo, final, nghost = run_on_one_and_two_ranks(script, tmp_path)
    assert 0 < nghost < 10
    a, b = final["one"], final["two"]
    assert np.array_equal(a, b)  # positions and velocities bit for bit
    assert thermo["two"][4] == thermo["one"][4] >= 2  # events (a snap-off on each side)
    np.testing.assert_allclose(thermo["two"], thermo["one"], rtol=1e-12)
    # the ledger: E0 = 72 = ke + pe (contact + substrate, the fix's) + D_hyst + D_visc
    assert sum(thermo["one"][:4]) == pytest.approx(72.0, rel=2e-5)


def test_located_refuses_a_second_integrator(plugin, tmp_path):
    """With events located the fix moves the atoms: a fix nve (or spring/self) beside it is
    refused in one line naming the fix to remove."""
    script = tmp_path / "twice.in"
    script.write_text(spread(plugin).replace(
        "fix line all", "fix move mobile nve\nfix line all"))
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    out = subprocess.run([lmp, "-var", "tag", "x", "-in", str(script)], cwd=tmp_path,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode != 0
    assert "integrates the chain itself: unfix move" in out.stdout + out.stderr


def _lmp(tmp_path, script, tag="x", timeout=60):
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    return subprocess.run([lmp, "-var", "tag", tag, "-in", str(script)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("bad,key", [("k1 -5", "k1"), ("damping -1", "damping"),
                                     ("gap -0.5", "gap"), ("lambda -0.5", "lambda")])
def test_the_fix_refuses_negative_coefficients(plugin, tmp_path, bad, key):
    """k1 -5 or damping -1 ran (exit 0, a ledger of 6.3e10 for E0 = 72): the fix refuses a
    negative one in one line naming it (LAMMPS itself refuses nan and inf)."""
    script = tmp_path / "bad.in"
    script.write_text(spread(plugin).replace("walls yes events located",
                                             f"walls yes events located {bad}"))
    out = _lmp(tmp_path, script)
    assert out.returncode != 0
    assert f"{key} must be a finite number >= 0" in out.stdout + out.stderr


def test_a_restart_block_of_another_drive_is_refused(plugin, tmp_path):
    """A restart block written without a pulse was read by a fix with one: 7 values out of a
    block of 5 (bytes past its end). The block carries its mark and count; the mismatch is
    refused in one line."""
    small = spread(plugin).replace("201.5", "41.5").replace(
        "id 1 202", "id 1 42").replace("id 100", "id 2")
    head, setup = small.split("pair_style none\n")
    head += "pair_style none\n"
    setup = setup.split("velocity")[0]
    (tmp_path / "a.in").write_text(head + setup + "timestep 0.0025\nrun 10\n"
                                   "write_restart plain.restart\n")
    driven = setup.replace("walls yes events located", "walls yes events located "
                           "pulse 5 1.0 0.5 0.0")
    (tmp_path / "b.in").write_text("read_restart plain.restart\nplugin load " + str(plugin) +
                                   "\ncomm_modify vel yes cutoff 6.0\npair_style none\n" +
                                   driven + "timestep 0.0025\nrun 10\n")
    assert _lmp(tmp_path, tmp_path / "a.in").returncode == 0
    out = _lmp(tmp_path, tmp_path / "b.in")
    assert out.returncode != 0
    assert "restart file's block holds 5 values, this fix needs 7" in out.stdout + out.stderr


def test_restart_and_split_runs_continue_bitwise(plugin, tmp_path):
    """A located run continued from a restart file, and one run in two pieces, are the
    uninterrupted run bit for bit (the stored accelerations and damping power carry over)."""
    small = spread(plugin).replace("201.5", "41.5").replace(
        "id 1 202", "id 1 42").replace("id 100", "id 2")  # 40 beads, bead 1 struck
    head, setup = small.split("pair_style none\n")
    head += "pair_style none\n"
    setup = setup.split("velocity")[0]  # groups, fixes
    tail = ("thermo_style custom step f_contact[1] f_contact[2]\n"
            "thermo_modify norm no format float %.17g\n")
    velocity = "velocity struck set 12.0 0.0 0.0 units box\ntimestep 0.0025\n"
    dump = "write_dump all custom final.{} id x vx modify sort id format float %.17g\n"
    (tmp_path / "a.in").write_text(head + setup + velocity + tail + "run 1000\n"
                                   "write_restart half.restart\nrun 1000\n" + dump.format("a"))
    (tmp_path / "b.in").write_text("read_restart half.restart\nplugin load " + str(plugin) +
                                   "\ncomm_modify vel yes cutoff 6.0\npair_style none\n" + setup +
                                   "timestep 0.0025\n" + tail + "run 1000\n" + dump.format("b"))
    (tmp_path / "c.in").write_text(head + setup + velocity + tail + "run 2000\n" +
                                   dump.format("c"))
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    for name in "abc":
        out = subprocess.run([lmp, "-var", "tag", name, "-in", f"{name}.in"], cwd=tmp_path,
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    a, b, c = (np.loadtxt(tmp_path / f"final.{k}", skiprows=9) for k in "abc")
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert np.abs(a[1:-1, 1] - np.arange(1, 41)).max() > 0.1  # the chain has moved


THERMAL_WORKER = """
import sys
import numpy as np
from mpi4py import MPI
from mdgran.model.scene import load_scene
from mdgran.simulation import run
sc = load_scene("micro-star", [("chain.n", 21), ("run.duration", 8.0), ("run.output_interval", 1.0),
                               ("thermal.temperature", 2.0), ("thermal.seed", 1),
                               ("impulse.bead", 10), ("impulse.velocity", 40.0)])
extra = sys.argv[2:]  # LAMMPS commands after the input (a smaller ghost cut-off)
tr = run(sc, "lammps", contact="native", events="located", extra_commands=extra).trajectory
out = dict(x=tr.x, v=tr.v, ev_time=tr.ev_time, ev_contact=tr.ev_contact, ev_kind=tr.ev_kind,
           d_visc=tr.ledger["dissipated_viscous"], d_hyst=tr.ledger["dissipated_hysteresis"],
           ranks=MPI.COMM_WORLD.Get_size())
if MPI.COMM_WORLD.Get_rank() == 0:
    np.savez(sys.argv[1], **out)
"""


def run_thermal(tmp_path, ranks, *extra):
    script = tmp_path / "thermal.py"
    script.write_text(THERMAL_WORKER)
    out = tmp_path / f"thermal{ranks}.npz"
    return out, subprocess.run([MPIEXEC, "-n", str(ranks), sys.executable, str(script), str(out),
                                *extra], capture_output=True, text=True, timeout=600)


def test_windows_across_the_rank_boundary(plugin, tmp_path):
    """A thermal chain (micro-star, 21 beads at T = 2, bead 10 struck at 40, to t = 8): 28
    events along the chain, 3 of them at contacts 9-11, whose event windows have beads or
    closed-edge neighbours on both sides of the slab boundary of 2 ranks (between tags 11 and
    12, contact 10), so that both ranks step them from their ghosts.  Positions, velocities
    and events are the 1-rank run's bit for bit; D_viscous and D_hysteresis, summed per rank,
    to round-off."""
    (one, r1), (two, r2) = run_thermal(tmp_path, 1), run_thermal(tmp_path, 2)
    for res in (r1, r2):
        assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    a, b = np.load(one), np.load(two)
    assert int(a["ranks"]) == 1 and int(b["ranks"]) == 2
    for key in ("x", "v", "ev_time", "ev_contact", "ev_kind"):
        assert np.array_equal(a[key], b[key]), key
    for key in ("d_visc", "d_hyst"):
        np.testing.assert_allclose(b[key], a[key], rtol=1e-12, err_msg=key)
    at_boundary = np.isin(a["ev_contact"], [9, 10, 11])
    assert len(a["ev_time"]) >= 20 and at_boundary.sum() >= 3, a["ev_contact"]


def test_windows_beyond_the_ghosts_are_refused(plugin, tmp_path):
    """With the ghost cut-off of the quantized mode (2.5 spacings: a window's beads and the 3
    beyond them are not all ghosts) the run stops with one line saying what to raise."""
    _, res = run_thermal(tmp_path, 2, "comm_modify cutoff 320.0 vel yes")
    assert res.returncode != 0
    assert "beyond those rank" in res.stdout + res.stderr
    assert "raise comm_modify cutoff" in res.stdout + res.stderr


def test_active_chain_is_the_fast_backends(plugin):
    """A thermal chain (200 beads at T = 2 to t = 2, 70 events, several per step at times):
    the fix steps each event's window as the fast backend does, so the two runs have the same
    events and agree to round-off growth (measured 1.2e-10 p in position and velocity; the
    fix works in absolute positions, the fast backend in displacements)."""
    sc = load_scene("micro-star", [("chain.n", 200), ("run.duration", 2.0),
                                   ("run.output_interval", 0.5), ("thermal.temperature", 2.0),
                                   ("thermal.seed", 1)])
    fast, native = run(sc, "fast"), located(sc)
    (kinds, times), (fast_kinds, fast_times) = events(native), events(fast)
    assert kinds == fast_kinds and len(kinds) >= 60
    assert np.abs(times - fast_times).max() < 1e-10
    a, b = native.trajectory, fast.trajectory
    assert np.abs(a.x - b.x).max() < 1e-9 and np.abs(a.v - b.v).max() < 1e-9


def test_forces_reach_every_output_and_every_fix_that_may_read_them(plugin, tmp_path):
    """A located step puts its accelerations into LAMMPS's force array only when something
    reads it at the end of the step: output (here a dump every 7 steps, thermo), the run's last
    step, another fix after the forces.  The dumped forces, with the contact fix alone, are
    those of the same run with a fix print (end_of_step: then every step writes them), bit for
    bit, on 1 rank and on 2 (events in windows on both sides of the rank boundary), and so is
    the motion."""
    alone = spread(plugin).replace("fix line all setforce NULL 0.0 0.0", "").replace(
        "thermo 1200\n", "thermo 1200\ndump d all custom 7 f.${tag} id fx\n"
        "dump_modify d sort id format float %.17g\n")
    printed = alone.replace("fix_modify contact energy yes",
                            'fix_modify contact energy yes\nfix p all print 100000 "-"')
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    dumps, finals = {}, {}
    for ranks in (1, 2):
        for name, text in (("alone", alone), ("printed", printed)):
            tag = f"{name}{ranks}"
            (tmp_path / f"{tag}.in").write_text(text)
            cmd = [lmp] if ranks == 1 else [MPIEXEC, "-n", "2", lmp]
            out = subprocess.run([*cmd, "-var", "tag", tag, "-in", f"{tag}.in"], cwd=tmp_path,
                                 capture_output=True, text=True, timeout=120)
            assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
            dumps[tag] = (tmp_path / f"f.{tag}").read_text()
            finals[tag] = (tmp_path / f"final.{tag}").read_text()
    ref = dumps["printed1"]
    fx = np.array([float(ln.split()[1]) for ln in ref.splitlines()
                   if len(ln.split()) == 2 and ln.split()[0].isdigit()])
    assert ref.count("ITEM: TIMESTEP") == 1200 // 7 + 1 and np.abs(fx).max() > 1.0
    for tag in dumps:
        assert dumps[tag] == ref, tag
        assert finals[tag] == finals["printed1"], tag


def test_dumped_forces_are_the_law_at_the_dumped_positions(plugin, tmp_path):
    """Every step's dumped f (every step written: a dump each step) is the acceleration of
    each bead from the contact law at the dumped positions and contact states, f(delta_left)
    - f(delta_right) - k1 u - k3 u^3 (no damping, mass 1): ContactLaw's own force, also at
    the beads that an event window stepped again (their x, v and f are the window's).  A
    thermal chain (T = 2 along x): measured within 4.2e-14, contact states changing at 79 of
    1200 steps (f of the windows' beads left as the pass's: 1.8 off)."""
    from mdgran.model.contact import ContactLaw, fc_from_lambda

    text = spread(plugin).replace("fix line all setforce NULL 0.0 0.0", "").replace(
        "damping 0.013 ", "").replace(
        "velocity struck set 12.0 0.0 0.0 units box",
        "velocity mobile create 2.0 7 dist gaussian\nvelocity mobile set NULL 0.0 0.0 units box"
    ).replace("thermo 1200\n", "thermo 1200\ndump d all custom 1 f.dump id x fx f_contact\n"
        "dump_modify d sort id format float %.17g\n")
    (tmp_path / "f.in").write_text(text)
    out = _lmp(tmp_path, tmp_path / "f.in", timeout=120)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    law, k1, k3 = ContactLaw("schwarz", fc_from_lambda(0.64)), 0.012, 0.002
    blocks = (tmp_path / "f.dump").read_text().split("ITEM: TIMESTEP")[1:]
    assert len(blocks) == 1201
    worst = 0.0
    for block in blocks:
        rows = np.array([ln.split() for ln in block.splitlines()[9:]], dtype=float)
        u = rows[:, 1] - (rows[:, 0] - 1.0)  # tag t sits at x = t - 1 at the start
        u[[0, -1]] = 0.0  # the walls
        delta = u[:-1] - u[1:]
        force = np.where(rows[:-1, 3] != 0.0, law.force(np.maximum(delta, law.delta_off)), 0.0)
        a = force[:-1] - force[1:] - (k1 * u[1:-1] + k3 * u[1:-1] ** 3)
        worst = max(worst, np.abs(rows[1:-1, 2] - a).max())
    assert worst < 1e-12, worst
    assert np.abs(rows[1:-1, 2]).max() > 1.0  # forces really were there
    # events: steps where some contact's state changed (windows stepped those beads again)
    states = [np.array([ln.split()[3] for ln in b.splitlines()[9:]], dtype=float)
              for b in blocks]
    stepped_again = sum(np.any(p != q) for p, q in zip(states, states[1:]))
    assert stepped_again > 20, stepped_again


def test_event_table_in_one_call_is_the_global_array(plugin):
    """The plugin's ``mdgran_chain_events`` (the backend reads the fix's events so, one call a
    frame) copies the event table as LAMMPS's library interface gives it one value at a time
    (time, contact, kind, step), stops at its end, and gives -1 for an ID that is not a fix
    mdgran/chain; rows it released read 0 (and -1 from it), the count and the later rows
    stay."""
    sc = load_scene("micro-star", [("chain.n", 200), ("thermal.temperature", 2.0),
                                   ("thermal.seed", 1)])
    b = make_backend(sc, "lammps", contact="native", events="located")
    b._start()
    lmp = b.lmp
    try:
        lmp.command("run 400")
        n = int(lmp.extract_fix("contact", 0, 1, 2))
        table = [[lmp.extract_fix("contact", 0, 2, r, c) for c in range(4)] for r in range(n)]
        read = native_plugin.event_reader(b.plugin)
        rows = np.full((n + 1, 4), np.nan)
        out = rows.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        assert n >= 10 and read(lmp.lmp, b"contact", 0, n + 1, out, 0) == n
        assert rows[:n].tolist() == table and np.isnan(rows[n]).all()
        assert read(lmp.lmp, b"no-such-fix", 0, 1, out, 0) == -1
        assert read(lmp.lmp, b"contact", 0, n - 3, out, 1) == n - 3
        assert read(lmp.lmp, b"contact", n - 3, 3, out, 0) == 3 and rows[:3].tolist() == table[-3:]
        assert read(lmp.lmp, b"contact", n - 4, 1, out, 0) == -1
        assert int(lmp.extract_fix("contact", 0, 1, 2)) == n
        assert [lmp.extract_fix("contact", 0, 2, n - 4, c) for c in range(4)] == [0.0] * 4
        assert [lmp.extract_fix("contact", 0, 2, n - 1, c) for c in range(4)] == table[-1]
    finally:
        lmp.close()


def front_input(plugin, n):
    """conftest's input with n beads between the walls, bead 1 (tag 2) struck, 4000 steps."""
    return spread(plugin).replace("201.5", f"{n + 1}.5").replace(
        "id 1 202", f"id 1 {n + 2}").replace("id 100", "id 2").replace(
        "thermo 1200\nrun 1200", "thermo 4000\nrun 4000")


def test_front_long_and_short_chains_agree(plugin, tmp_path):
    """The fix steps only the activity front (the atoms not at rest and their neighbours),
    which is exact: a chain struck at bead 1 (4000 steps; the disturbance reaches ~25 beads)
    moves the first 2,000 beads of a chain of 20,000 as it moves a chain of 2,000, and the
    first 40 as a chain of 40 does, bit for bit, on 1 rank and on 2, with the same events.  On
    2 ranks the disturbance crosses the slab boundary of the chain of 40 (after tag 21): the
    second rank learns of it through its ghosts."""
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    final, thermo = {}, {}
    for ranks in (1, 2):
        for n in (40, 2000, 20000):
            name = f"{ranks}_{n}"
            (tmp_path / f"{name}.in").write_text(front_input(plugin, n))
            cmd = [lmp] if ranks == 1 else [MPIEXEC, "-n", "2", lmp]
            out = subprocess.run([*cmd, "-var", "tag", name, "-in", f"{name}.in"], cwd=tmp_path,
                                 capture_output=True, text=True, timeout=300)
            assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
            rows = [ln.split() for ln in out.stdout.splitlines() if ln.strip().startswith("4000 ")]
            thermo[ranks, n] = [float(v) for v in rows[-1][1:]]
            final[ranks, n] = np.loadtxt(tmp_path / f"final.{name}", skiprows=9)
    ref = final[1, 40]
    moved = ref[np.abs(ref[:, 2]) > 0.0, 0]
    assert 22 < moved.max() < 38  # past the slab boundary of 2 ranks, short of the chain's end
    for key, rows in final.items():
        assert np.array_equal(rows[:41], ref[:41]), key  # tag, x, vx (tag 42: the wall of 40)
        assert np.array_equal(rows[:2001], final[1, min(key[1], 2000)][:2001]), key
        assert not np.any(rows[41:, 2]) and np.array_equal(rows[41:, 1], rows[41:, 0] - 1)
        # D_hysteresis, D_viscous, events: the same where the ranks share the work alike (on 2
        # ranks the chain of 40 splits its sums between them: round-off, as LAMMPS's ke)
        if key[0] == 1 or key[1] >= 2000:
            assert thermo[key][2:] == thermo[key[0], 2000][2:], key
        np.testing.assert_allclose(thermo[key], thermo[1, 40], rtol=1e-12, err_msg=str(key))


def test_a_command_between_runs_reaches_the_kept_front(plugin, tmp_path):
    """A run that goes on from the step the last one ended keeps the activity front; an atom
    that a command between the runs set moving far outside it (tag 150; the pulse from bead 1
    reaches ~15 beads) is stepped all the same: it moves on and pushes its neighbour.  (With
    ``run ... pre no`` LAMMPS assumes that nothing changed between the runs, as mdgran's
    frames do.)"""
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    text = front_input(plugin, 200).replace(
        "thermo 4000\nrun 4000", "thermo 600\nrun 600\nset atom 150 vx 1.0\nrun 600")
    (tmp_path / "set.in").write_text(text)
    out = subprocess.run([lmp, "-var", "tag", "set", "-in", "set.in"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    final = np.loadtxt(tmp_path / "final.set", skiprows=9)  # id, x, vx (lattice x = id - 1)
    assert final[149, 0] == 150 and final[149, 1] - 149.0 > 1.0  # v t = 1.5
    assert final[150, 1] - 150.0 > 0.1 and np.all(final[100:140, 2] == 0.0)


HULL_WORKER = """
import sys
import numpy as np
from mpi4py import MPI
from mdgran.model.scene import load_scene
from mdgran.simulation import make_backend
sc = load_scene("micro-star", [("chain.n", 400), ("impulse.bead", 200), ("run.duration", 4.0)])
b = make_backend(sc, "lammps:native")
rows = [(bl.x[0], bl.v[0], bl.closed[0], bl.moved, bl.events) for bl in b.blocks()]
out = dict(x=np.array([r[0] for r in rows]), v=np.array([r[1] for r in rows]),
           closed=np.array([r[2] for r in rows]), moved=np.array([r[3] for r in rows]),
           events=np.array([(e.time, e.contact, e.kind) for r in rows for e in r[4]]),
           bead_steps=b.stats["bead_steps"], steps=b.stats["steps"])
if sys.argv[2] == "full":  # every bead gathered: what the hull's frames must be
    full = list(make_backend(sc, "lammps:native").frames())
    out.update(full_x=np.array([f.x for f in full]), full_v=np.array([f.v for f in full]),
               full_closed=np.array([f.closed for f in full]))
if MPI.COMM_WORLD.Get_rank() == 0:
    np.savez(sys.argv[1], **out)
"""


def test_frames_gather_the_moved_hull_alone(plugin, tmp_path):
    """A chain of 400 beads struck at bead 200, the slab boundary of 2 ranks: each frame
    gathers only the beads of the fix's moved hull (a few dozen beads at t = 4) and their
    contacts, bitwise the frames gathered whole, on 1 rank and on 2."""
    script = tmp_path / "hull.py"
    script.write_text(HULL_WORKER)
    runs = {}
    for ranks, mode in ((1, "full"), (2, "hull")):
        out = tmp_path / f"hull{ranks}.npz"
        res = subprocess.run([MPIEXEC, "-n", str(ranks), sys.executable, str(script), str(out),
                              mode], capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
        runs[ranks] = np.load(out)
    one, two = runs[1], runs[2]
    for key in ("x", "v", "closed"):
        assert np.array_equal(one[key].view(np.uint8), one[f"full_{key}"].view(np.uint8)), key
        assert np.array_equal(two[key].view(np.uint8), one[key].view(np.uint8)), key
    assert np.array_equal(one["events"], two["events"]) and len(one["events"]) >= 1
    assert np.array_equal(one["moved"], two["moved"])
    lo, hi = one["moved"][-1]
    assert lo < 199 < hi and 10 < hi - lo < 80, (lo, hi)  # around the struck bead, not the chain
    moving = np.flatnonzero(np.any(one["v"] != 0.0, axis=0))
    assert lo <= moving.min() and moving.max() < hi
    # the run's bead-steps count the front's atoms, not the chain's
    for res in (one, two):
        steps = int(res["steps"])
        assert 10 * steps < int(res["bead_steps"]) < 0.2 * 400 * steps


def test_joined_windows_are_the_fast_backends(plugin):
    """A hot chain at a coarse step (2,000 beads at T = 50, dt = 0.02, to t = 2: 1,545 events,
    many per step): event windows that must widen reach a window already stepped and are
    joined with it (the step's windows then stepped again), twice here.  The fix does as the
    fast backend does: the same events, times, positions and velocities to round-off growth
    (measured 1.6e-10 in event times, 3.2e-10 p in position, 9.3e-10 in velocity)."""
    sc = load_scene("micro-star", [("chain.n", 2000), ("run.duration", 2.0),
                                   ("run.output_interval", 0.5), ("thermal.temperature", 50.0),
                                   ("thermal.seed", 1), ("run.dt", 0.02)])
    native, fast = located(sc), run(sc, "fast")
    assert native.stats["event_windows_joined"] >= 1
    (kinds, times), (fast_kinds, fast_times) = events(native), events(fast)
    assert kinds == fast_kinds and len(kinds) > 1000
    assert np.abs(times - fast_times).max() < 1e-8
    a, b = native.trajectory, fast.trajectory
    assert np.abs(a.x - b.x).max() < 1e-8 and np.abs(a.v - b.v).max() < 1e-8
