"""The built wheel holds the whole package: every file of the source tree's ``mdgran/``.

The wheel is built from a copy of the tracked sources (a stale ``build/`` of the checkout cannot
leak into it) without build isolation and with the native plugin's compile skipped (``CXX`` set
to ``false``: setup.py then warns and goes on), which keeps the build to a few seconds.
"""
import os
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

import mdgran
from mdgran.backends.lammps import backend as lammps_backend
from mdgran.backends.lammps import plugin as native_plugin
from mdgran.model.scene import SCENE_DIR
from mdgran.studies.sweep import SWEEP_DIR

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(mdgran.__file__).resolve().parent
#: what the build makes in the package folder, never a source file
BUILD_PRODUCTS = {native_plugin.PLUGIN, native_plugin.INFO}
#: the files the build reads besides the package
PROJECT_FILES = ("pyproject.toml", "setup.py", "README.md", "LICENSE")
#: seconds: the wheel without the plugin's compile takes ~3 s on an idle machine
BUILD_BUDGET = 60.0


def _is_source(path: Path) -> bool:
    """A file of the package's sources: not a cache, a hidden temporary or a build product."""
    return ("__pycache__" not in path.parts and not path.name.startswith(".")
            and path.suffix != ".pyc" and path.name not in BUILD_PRODUCTS)


def source_files(package: Path) -> set[str]:
    """Paths (``mdgran/...``, POSIX) of the package's source files in the tree."""
    return {path.relative_to(package.parent).as_posix() for path in package.rglob("*")
            if path.is_file() and _is_source(path.relative_to(package.parent))}


@pytest.fixture(scope="module")
def wheel_names(tmp_path_factory):
    """The names in a wheel built from a copy of the sources, and the build's seconds."""
    if shutil.which("false") is None:
        pytest.skip("no 'false' command to stand in for the C++ compiler")
    src = tmp_path_factory.mktemp("src")
    for name in PROJECT_FILES:
        shutil.copy2(ROOT / name, src / name)
    for rel in source_files(PACKAGE):
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(PACKAGE.parent / rel, src / rel)
    dist = tmp_path_factory.mktemp("dist")
    env = {**os.environ, "CXX": shutil.which("false")}
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps",
                           "--no-build-isolation", "-w", str(dist), str(src)],
                          capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - start
    assert proc.returncode == 0, proc.stderr[-3000:]
    (wheel,) = dist.glob("mdgran-*.whl")
    with zipfile.ZipFile(wheel) as zf:
        return set(zf.namelist()), seconds


def test_wheel_holds_every_source_file_of_the_package(wheel_names):
    """Scenes, sweeps, the LAMMPS input, the plugin's C++ sources, the modules: a file added to
    the tree but not matched by pyproject's package-data is missing here; nothing else is in."""
    names, seconds = wheel_names
    packaged = {n for n in names if n.startswith("mdgran/")}
    expected = source_files(PACKAGE)
    assert expected - packaged == set(), "in the tree, not in the wheel"
    assert packaged - expected == set(), "in the wheel, not in the tree"
    assert seconds < BUILD_BUDGET


READ_BY_THE_PACKAGE = [SCENE_DIR / "micro-star.toml", SCENE_DIR / "driven" / "pulse.toml",
                       SWEEP_DIR / "chain-100.toml", lammps_backend.INPUT,
                       native_plugin.SOURCE_DIR / native_plugin.SOURCES[0]]


@pytest.mark.parametrize("path", READ_BY_THE_PACKAGE,
                         ids=["scene", "driven-scene", "sweep", "lammps-input", "plugin-source"])
def test_the_files_the_package_reads_are_in_the_wheel(wheel_names, path):
    """Each data file is found next to the module that reads it, so an installed wheel has it."""
    names, _ = wheel_names
    rel = path.resolve().relative_to(PACKAGE.parent).as_posix()
    assert rel in names
