"""mdgran: simulation of 1-D adhesive micro-granular chains (Schwarz contact, elastic substrate).

Everything inside the package is nondimensional (the units of :mod:`mdgran.model.units`):
force ``eta = pi R w``, length ``p``, time ``1/q``, bead mass 1.  SI input is converted once,
in :mod:`mdgran.model.units`.

The Python API (docs/python_api.md)::

    import mdgran
    mdgran.scenes()                                   # built-in scene names
    res = mdgran.run("micro-star", "fast", out="ms.h5", set={"run.duration": 50.0})
    rec = mdgran.read("ms.h5")                        # a Run: frames, states, scene, status

``import mdgran`` imports nothing heavy: the names below are loaded on first use (numpy, scipy
and h5py come with them), so that ``mdgran scenes`` starts fast.

The modules sit in folders by role (docs/developers.md): ``model/``, ``backends/``,
``output/``, ``studies/``, ``crosscheck/``, ``analysis/``.  A module's name from before
(``mdgran.scene``) still imports it, with a DeprecationWarning naming its new path
(:mod:`mdgran._moved`).
"""
from . import _moved

__version__ = "0.1.0"
_moved.install()

#: public name -> (module, attribute), imported on first access (PEP 562)
_LAZY = {
    "run": ("api", "run"),
    "read": ("api", "read"),
    "scenes": ("api", "scenes"),
    "load_scene": ("model.scene", "load_scene"),
    "Scene": ("model.scene", "Scene"),
    "SceneError": ("model.scene", "SceneError"),
    "RunResult": ("simulation", "RunResult"),
    "BackendUnavailable": ("simulation", "BackendUnavailable"),
    "IntegrationError": ("backends.base", "IntegrationError"),
    "Run": ("output.run_record", "Run"),
    "Trajectory": ("output.run_record", "Run"),  # its former name (mdgran 0.1), kept for old code
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    import importlib

    if f"{__name__}.{name}" in _moved.MOVED:  # a moved module's old name: it warns
        return importlib.import_module(f"{__name__}.{name}")
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'mdgran' has no attribute {name!r}") from None

    value = getattr(importlib.import_module(f".{module}", __name__), attr)
    globals()[name] = value  # later look-ups do not come here
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
