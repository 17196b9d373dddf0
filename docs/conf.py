"""Sphinx configuration of mdgran's manual.

Build (what CI runs, from the repository's root)::

    python -m sphinx -W --keep-going -n -b html docs docs/_build/html

The pages are Markdown (myst-parser); the API reference comes from the docstrings (autodoc,
autosummary, napoleon); the gallery's scripts (``docs/gallery/plot_*.py``) run at every build
(sphinx-gallery), and the performance page is written from ``benchmarks/results/*.json`` by
``docs/make_performance.py`` before the build reads it.
"""
from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))  # the mdgran of this checkout, installed or not
sys.path.insert(0, str(DOCS))

os.environ.setdefault("MPLBACKEND", "Agg")
# MDAnalysis (the gallery reads a run with it) warns on import that netCDF4, for AMBER files,
# is missing; the manual writes none
logging.getLogger("MDAnalysis.coordinates.AMBER").setLevel(logging.ERROR)

import make_performance  # noqa: E402

import mdgran  # noqa: E402

make_performance.write_page(ROOT / "benchmarks" / "results", DOCS / "generated" / "performance.md")

project = "mdgran"
author = "the mdgran authors"
copyright = "the mdgran authors, GPL-2.0-or-later"
release = version = mdgran.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "examples", "gallery", "**/README.md", "auto_examples/*.ipynb",
                    "auto_examples/*.py", "auto_examples/*.zip", "auto_examples/*.md5",
                    "auto_examples/*.json"]

myst_enable_extensions = ["colon_fence", "deflist"]  # formulas as text: no MathJax to fetch
myst_heading_anchors = 3

# --- API reference -----------------------------------------------------------------------------
autosummary_generate = False  # the API pages are written by hand (docs/api/*.md)
autodoc_typehints = "none"  # the docstrings say what each parameter is and its units
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": False}
napoleon_numpy_docstring = False
python_use_unqualified_type_names = True
add_module_names = False  # "run(scene, ...)" under its module's heading, not "mdgran.api.run"

napoleon_use_ivar = True  # a class's "Attributes:" as fields, not as a second description
# names the docstrings refer to that are described in prose (their class's or module's
# docstring) rather than as entries of their own, and one private helper
nitpick_ignore = [
    ("py:attr", "mdgran.backends.base.Frames.moved"),  # Frames's docstring
    ("py:attr", "Run.x_stored"), ("py:attr", "Run.bead_ids"), ("py:attr", "scene_toml"),
    ("py:class", "x_stored"),  # Run's "Attributes:"
    ("py:attr", "Scene.sources"),  # Scene's docstring
    ("py:meth", "force"),  # ContactTable's methods mirror ContactLaw's
    ("py:data", "LEDGER_NAMES"),  # run_record's ledger terms, listed in Run's docstring
    ("py:func", "_derive_beads"), ("py:func", "run_segments"),  # private; a compiled kernel
    ("py:class", "tqdm.std.tqdm"),  # progress.Line's base class, a library's (no intersphinx)
    ("py:class", "collections.abc.Sequence"),  # base.Events's base class, the standard
    # library's (no intersphinx)
]  # a class's "Attributes:" as fields, not as a second description

# ``mdgran.run`` and friends are documented where they are defined (``mdgran.api.run``); a
# reference to the package-level name resolves to that place.
PUBLIC = {f"mdgran.{name}": f"mdgran.{module}.{attr}"
          for name, (module, attr) in mdgran._LAZY.items()}
MOVED = mdgran._moved.MOVED


def defined_at(target: str, module: str | None) -> str | None:
    """Where the object that ``target`` names (from inside ``module``) is defined, as
    ``module.qualname``: ``SceneError`` written in :mod:`mdgran.simulation`, which imports it,
    is ``mdgran.model.scene.SceneError``.  None if it names nothing importable."""
    import importlib

    if target in PUBLIC:
        return PUBLIC[target]
    for base in ([module] if module else []) + [""]:
        path = f"{base}.{target}" if base else target
        parts = path.split(".")
        for cut in range(len(parts) - 1, 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            owner = getattr(obj, "__module__", None)
            name = getattr(obj, "__qualname__", None)
            if owner and name and f"{owner}.{name}" != path:
                return f"{owner}.{name}"
            break
    return None


def moved_name(target: str) -> str | None:
    """``target`` with a moved module's old name (``mdgran.chain.ChainModel``) replaced by the
    module's new one (``mdgran.model.chain.ChainModel``; the table of :mod:`mdgran._moved`);
    None if it names no moved module."""
    for old, new in MOVED.items():
        if target == old or target.startswith(old + "."):
            return new + target[len(old):]
    return None


def resolve_where_defined(app, env, node, contnode):
    """``missing-reference`` handler: a Python name that is imported or re-exported where
    the reference is written, or named by a moved module's old path, resolves to where it is
    defined and documented."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    moved = moved_name(target)
    canonical = defined_at(moved or target, node.get("py:module")) or moved
    if canonical is None:
        return None
    domain = env.get_domain("py")
    return domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], canonical,
                               node, contnode)


def napoleon_for_callables(app):
    """Napoleon reads Google-style sections of functions and classes only: mdgran's ``#:``
    comments of constants start with prose followed by a colon ("key -> value: ..."), which
    napoleon would take for a type."""
    from sphinx.ext.napoleon import _process_docstring

    listeners = app.events.listeners["autodoc-process-docstring"]
    for listener in list(listeners):
        if listener.handler is _process_docstring:
            app.disconnect(listener.id)

    def process(app, what, name, obj, options, lines):
        if what not in ("data", "attribute", "property"):
            _process_docstring(app, what, name, obj, options, lines)

    app.connect("autodoc-process-docstring", process)


def setup(app):
    app.connect("missing-reference", resolve_where_defined)
    app.connect("builder-inited", napoleon_for_callables)


# --- gallery -----------------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": "gallery",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "show_memory": False,
    "min_reported_time": 1,
}

# --- HTML ----------------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"mdgran {release}"
html_static_path = []
html_show_sourcelink = False
