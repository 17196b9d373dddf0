"""The package's rooms and which may import which (docs/developers.md): every module belongs
to one room, and imports only from its own room and the rooms below it, so that the model
never depends on a backend, a backend never on the output, the output never on the study, and
nothing but the command line on the command line."""
import ast
from pathlib import Path

import pytest

import mdgran

PACKAGE = Path(mdgran.__file__).parent

#: rooms from the bottom up; a module may import from its own room and those listed before it.
#: A room is a folder of the package (every module below ``model/`` is in the model) or, for
#: the base, the driver, the API and the command line, a few modules at the package's top.
ROOMS = {
    # the package's namespace (__init__: its version, and public names that load their
    # modules only when used; _moved: the old names of moved modules) and helpers every room
    # may use
    "base": ["__init__", "_moved", "signals", "rest_blocks"],
    "model": ["model"],
    "analysis": ["analysis"],
    "backends": ["backends"],
    "output": ["output"],
    "driver": ["simulation", "budget"],
    "studies": ["studies"],
    "crosscheck": ["crosscheck"],
    "front": ["api"],
    "cli": ["cli", "__main__"],
}
ORDER = list(ROOMS)


def room_of(module: str) -> str:
    """The room of ``mdgran.<module>``: that of its first component after the package (its
    folder, or itself at the top); an old name of a moved module (``scene``) is in no room."""
    top = module.split(".")[0]
    for room, members in ROOMS.items():
        if top in members:
            return room
    raise AssertionError(f"mdgran.{module} is in no room: add it to ROOMS and "
                         "docs/developers.md")


def imports_of(path: Path, root: Path = PACKAGE) -> set:
    """The mdgran modules ``path`` (a module of the package in ``root``) imports, relative or
    absolute, as dotted names below the package (``from . import analysis`` is ``analysis``;
    ``from . import __version__`` is ``__init__``)."""
    rel = path.relative_to(root).with_suffix("")
    package = list(rel.parts[:-1])
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[:len(package) - (node.level - 1)]
            if node.module:
                out.add(".".join(base + [node.module]) or "__init__")
            else:
                for alias in node.names:
                    sub = ".".join(base + [alias.name])
                    out.add(sub if (root / f"{sub.replace('.', '/')}.py").exists()
                            or (root / sub.replace(".", "/")).is_dir() else
                            ".".join(base) or "__init__")
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("mdgran."):
            out.add(node.module[len("mdgran."):])
        elif isinstance(node, ast.Import):
            out.update(a.name[len("mdgran."):] for a in node.names
                       if a.name.startswith("mdgran."))
    return out


def upward_imports(root: Path) -> list:
    """Each import in the package at ``root`` of a room above the importing module's."""
    bad = []
    for path in (p for p in root.rglob("*.py") if "__pycache__" not in p.parts):
        name = ".".join(path.relative_to(root).with_suffix("").parts)
        mine = ORDER.index(room_of(name))
        for target in imports_of(path, root):
            if ORDER.index(room_of(target)) > mine:
                bad.append(f"{name} ({room_of(name)}) imports {target} ({room_of(target)})")
    return bad


def test_every_module_imports_only_its_room_and_the_rooms_below():
    assert len(list(PACKAGE.rglob("*.py"))) > 40
    bad = upward_imports(PACKAGE)
    assert not bad, "\n".join(bad)


def test_the_rule_catches_an_upward_import(tmp_path):
    """A model module that imports the driver (inside a function, too) is found."""
    (tmp_path / "simulation.py").write_text("def run():\n    pass\n")
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "units.py").write_text("X = 1\n")
    (tmp_path / "model" / "chain.py").write_text("from .units import X\n\n\ndef f():\n"
                                                 "    from ..simulation import run\n"
                                                 "    return run\n")
    assert upward_imports(tmp_path) == ["model.chain (model) imports simulation (driver)"]


def test_a_module_in_no_room_fails(tmp_path):
    """A new module at the top, or a moved module's old name, is in no room: the check says so."""
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "chain.py").write_text("from ..scene import Scene\n")
    with pytest.raises(AssertionError, match="mdgran.scene is in no room"):
        upward_imports(tmp_path)
