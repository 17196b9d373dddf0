"""Old import paths of the modules that moved into their rooms' folders (docs/developers.md).

``import mdgran.scene``, ``from mdgran.scene import Scene`` and ``mdgran.scene`` still work:
each gives the module at its new path (:mod:`mdgran.model.scene`), the same module object, and
warns once with a :class:`DeprecationWarning` that names the new path.  :data:`MOVED` is the
one table of old and new names; :class:`MovedFinder`, on ``sys.meta_path`` from ``import
mdgran`` on, answers the old names only, and imports a moved module only when its old name is
imported.
"""
import os
import sys
import warnings
from importlib import import_module
from importlib.machinery import ModuleSpec

#: old dotted name -> the module's dotted name now
MOVED = {
    # the model
    "mdgran.units": "mdgran.model.units",
    "mdgran.contact_scalar": "mdgran.model.contact_scalar",
    "mdgran.contact": "mdgran.model.contact",
    "mdgran.mixture": "mdgran.model.mixture",
    "mdgran.drive": "mdgran.model.drive",
    "mdgran.scene_records": "mdgran.model.scene_records",
    "mdgran.scene": "mdgran.model.scene",
    "mdgran.chain": "mdgran.model.chain",
    # the output
    "mdgran.storage": "mdgran.output.storage",
    "mdgran.checkpoint": "mdgran.output.checkpoint",
    "mdgran.measures": "mdgran.output.measures",
    "mdgran.run_record": "mdgran.output.run_record",
    "mdgran.trajectory": "mdgran.output.trajectory",
    "mdgran.progress": "mdgran.output.progress",
    "mdgran.run_environment": "mdgran.output.run_environment",
    "mdgran.h5md_layout": "mdgran.output.h5md_layout",
    "mdgran.h5md_append": "mdgran.output.h5md_append",
    "mdgran.h5md_writer": "mdgran.output.h5md_writer",
    "mdgran.memory_reporter": "mdgran.output.memory_reporter",
    "mdgran.reporters": "mdgran.output.reporters",
    # the studies
    "mdgran.sweep": "mdgran.studies.sweep",
    "mdgran.controls": "mdgran.studies.controls",
    "mdgran.paper_figures": "mdgran.studies.paper_figures",
    "mdgran.study": "mdgran.studies.paper_study",
    "mdgran.long_chain": "mdgran.studies.long_chain",
    # the cross-checks
    "mdgran.compare_report": "mdgran.crosscheck.compare_report",
    "mdgran.compare": "mdgran.crosscheck.compare",
}

#: files whose frames stand between an ``import`` statement and :class:`MovedFinder`
_MACHINERY = (__file__, os.path.join(os.path.dirname(__file__), "__init__.py"),
              import_module.__code__.co_filename)


def _importer_stacklevel() -> int:
    """The ``stacklevel`` that makes a warning name the line of the importing code: frames of
    this module, ``importlib.import_module`` and ``mdgran.__getattr__`` are counted and skipped
    (``warnings.warn`` itself skips, without counting, the frozen importlib frames)."""
    frame, level = sys._getframe(1), 1
    while frame is not None:
        name = frame.f_code.co_filename
        internal = "importlib" in name and "_bootstrap" in name
        if not internal and name not in _MACHINERY:
            return level
        frame, level = frame.f_back, level + (not internal)
    return 1


class _AliasLoader:
    """Loads an old name as the module at its new name (imported, if it is not yet)."""

    def __init__(self, new: str):
        self.new = new
        self.spec = None

    def create_module(self, spec):
        """The moved module itself; the import system then records it under the old name."""
        module = import_module(self.new)
        self.spec = module.__spec__
        return module

    def exec_module(self, module):
        """Nothing to run: give the module back the spec of its new name, which the import
        system replaced by the old name's."""
        module.__spec__ = self.spec


class MovedFinder:
    """A meta path finder for the old names of :data:`MOVED` (and nothing else)."""

    @staticmethod
    def find_spec(fullname, path=None, target=None):
        """A spec loading ``fullname``'s new module, with a DeprecationWarning; None for any
        name that did not move."""
        new = MOVED.get(fullname)
        if new is None:
            return None
        warnings.warn(f"{fullname} is now {new}; import it from there ({fullname} will be "
                      "removed in a future version)", DeprecationWarning,
                      stacklevel=_importer_stacklevel())
        return ModuleSpec(fullname, _AliasLoader(new))


def install():
    """Put :class:`MovedFinder` first on ``sys.meta_path`` (once), so that an old name is never
    found as a stale file of an older install."""
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())
