"""mdgran: simulation of 1-D adhesive micro-granular chains (Schwarz contact, elastic substrate).

Everything inside the package is nondimensional (the units of :mod:`mdgran.units`):
force ``eta = pi R w``, length ``p``, time ``1/q``, bead mass 1.  SI input is converted once,
in :mod:`mdgran.units`.

The Python API (docs/python_api.md)::

    import mdgran
    mdgran.scenes()                                   # built-in scene names
    res = mdgran.run("micro-star", "fast", out="ms.h5", set={"run.duration": 50.0})
    rec = mdgran.read("ms.h5")                        # a Run: frames, states, scene, status

``import mdgran`` imports nothing heavy: the names below are loaded on first use (numpy, scipy
and h5py come with them), so that ``mdgran scenes`` starts fast.
"""
__version__ = "0.1.0"

#: public name -> (module, attribute), imported on first access (PEP 562)
_LAZY = {
    "run": ("api", "run"),
    "read": ("api", "read"),
    "scenes": ("api", "scenes"),
    "load_scene": ("scene", "load_scene"),
    "Scene": ("scene", "Scene"),
    "SceneError": ("scene", "SceneError"),
    "RunResult": ("simulation", "RunResult"),
    "BackendUnavailable": ("simulation", "BackendUnavailable"),
    "IntegrationError": ("backends.base", "IntegrationError"),
    "Run": ("run_record", "Run"),
    "Trajectory": ("run_record", "Run"),  # its former name (mdgran 0.1), kept for old code
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'mdgran' has no attribute {name!r}") from None
    import importlib

    value = getattr(importlib.import_module(f".{module}", __name__), attr)
    globals()[name] = value  # later look-ups do not come here
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
