"""The old import paths of the modules that moved into their rooms' folders (mdgran._moved):
each gives the module at its new path, the same object, with a DeprecationWarning naming it;
``import mdgran`` imports none of them."""
import importlib
import subprocess
import sys
import warnings

import pytest

import mdgran
from mdgran._moved import MOVED

PACKAGE_DIR = mdgran.__path__[0]


def forget(old: str):
    """Drop the old name from ``sys.modules`` and the package, so that importing it runs the
    alias again (the module at its new name stays loaded)."""
    sys.modules.pop(old, None)
    mdgran.__dict__.pop(old.rsplit(".", 1)[1], None)


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_name_imports_the_moved_module_and_warns(old):
    new = MOVED[old]
    forget(old)
    with pytest.warns(DeprecationWarning, match=rf"{old} is now {new}\b") as record:
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    assert module.__name__ == new and module.__spec__.name == new
    # the warning names the line that imported the old name, not the import machinery
    assert record[0].filename == __file__
    assert module.__file__.startswith(PACKAGE_DIR)
    assert module.__file__.replace("\\", "/").endswith(new.split(".", 1)[1].replace(".", "/")
                                                       + ".py")


def test_from_import_attribute_and_identity_through_an_old_name():
    """``from mdgran.scene import Scene``, ``mdgran.scene.Scene`` and the class at its new path
    are one object."""
    from mdgran.model import scene as new_scene

    forget("mdgran.scene")
    with pytest.warns(DeprecationWarning, match="mdgran.model.scene"):
        from mdgran.scene import Scene
    assert Scene is new_scene.Scene and mdgran.scene is new_scene
    forget("mdgran.scene")
    with pytest.warns(DeprecationWarning, match="mdgran.model.scene"):
        assert mdgran.scene.Scene is new_scene.Scene


def test_a_name_that_did_not_move_is_not_aliased():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ModuleNotFoundError):
            importlib.import_module("mdgran.no_such_module")
        with pytest.raises(AttributeError):
            getattr(mdgran, "no_such_name")


def test_import_mdgran_imports_no_moved_module():
    """The alias is lazy: a fresh ``import mdgran`` loads the package and its alias table
    only."""
    code = ("import sys, mdgran; "
            "print(sorted(m for m in sys.modules if m.startswith('mdgran')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=PACKAGE_DIR + "/..").stdout
    assert out.strip() == "['mdgran', 'mdgran._moved']"
