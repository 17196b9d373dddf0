"""mdgran's Python API: ``mdgran.run``, ``mdgran.read``, ``mdgran.scenes`` (see docs/python_api.md).

Example::

    import mdgran

    res = mdgran.run("micro-star", "reference", out="ms.h5", set={"run.duration": 50.0})
    print(res)                        # RunResult(scene='micro-star', backend='reference', ...)
    rec = mdgran.read("ms.h5")        # the same Run record, read back from the H5MD file

Everything is nondimensional (docs/physics.md section 1): length ``p``, force ``eta = pi R w``,
time ``1/q``, bead mass 1, energy ``eta p``.  Errors name this module's parameters (``scene``,
``backend``, ``out``, ``set``, ...), not the command line's flags: bad input raises
:class:`~mdgran.model.scene.SceneError` (a ``ValueError``) or ``TypeError`` before anything runs.
The heavy modules (numpy, scipy, h5py) are imported when a function is called, not when
``mdgran`` is imported.
"""
from __future__ import annotations

import os
from collections.abc import Mapping

#: keyword arguments of :func:`run` besides the backend's own options
RUN_KEYWORDS = ("set", "progress", "keep", "reporters", "raise_errors", "checkpoint_every",
                "resume", "collective")

def scenes() -> list:
    """Names of the built-in scenes (``mdgran scenes`` prints them with a description)."""
    from .model.scene import builtin_scenes

    return list(builtin_scenes())


def read(path):
    """The :class:`~mdgran.output.run_record.Run` stored in an mdgran H5MD file ``path`` (written by
    ``mdgran.run(..., out=path)`` or ``mdgran run --out path``): frames, contact states,
    ledger, events, the stored scene and status."""
    from .output.run_record import read_h5

    return read_h5(os.fspath(path))


def _overrides(given) -> list:
    """``set=`` as ``(key, value)`` pairs.  Accepted: None; a mapping ``{"run.duration": 50}``
    or nested ``{"run": {"duration": 50}}``; an iterable of ``(key, value)`` pairs or of
    ``"KEY=VALUE"`` strings (the command line's ``--set`` syntax)."""
    from .model.scene import SceneError, parse_override

    if given is None:
        return []
    if isinstance(given, (str, bytes)):
        raise SceneError("set", "must be a mapping such as {'run.duration': 50.0} or a list of "
                         f"(key, value) pairs, not a string ({given!r}); use set=[{given!r}]")
    pairs = []
    if isinstance(given, Mapping):
        for key, value in given.items():
            if isinstance(value, Mapping):  # nested: {"run": {"duration": 50}}
                pairs += [(f"{key}.{k}", v) for k, v in value.items()]
            else:
                pairs.append((key, value))
    else:
        try:
            items = list(given)
        except TypeError:
            raise SceneError("set", "must be a mapping or a list of (key, value) pairs, not "
                             f"{type(given).__name__}") from None
        for item in items:
            if isinstance(item, str):
                pairs.append(parse_override(item))
            elif isinstance(item, (tuple, list)) and len(item) == 2:
                pairs.append(tuple(item))
            else:
                raise SceneError("set", "items must be (key, value) pairs or 'KEY=VALUE' "
                                 f"strings, not {item!r}")
    for key, _ in pairs:
        if not isinstance(key, str):
            raise SceneError("set", f"keys are strings SECTION.NAME, not {key!r}")
    return pairs


def as_scene(scene, overrides=()):
    """A resolved :class:`~mdgran.model.scene.Scene` from a built-in name, a path to a TOML file, a
    nested mapping with the TOML's keys, or a Scene, with ``(key, value)`` overrides (what
    :func:`~mdgran.model.scene.load_scene` takes)."""
    from .model.scene import load_scene

    return load_scene(scene, overrides)


def _check_out(out, scene) -> str:
    """``out`` as a path, refused up front (:func:`~mdgran.output.storage.check_out_file`) where the
    run could not write it at its end."""
    from .model.scene import SceneError
    from .output.storage import check_out_file

    if not isinstance(out, (str, os.PathLike)):
        raise SceneError("out", f"must be a path to an .h5 file or None, not "
                         f"{type(out).__name__}")
    out = os.fspath(out)
    check_out_file(out, os.fspath(scene) if isinstance(scene, (str, os.PathLike)) else None)
    return out


def run(scene, backend: str = "reference", out=None, *, set=None, progress: bool = False,
        keep: bool = True, reporters=(), raise_errors: bool = True,
        checkpoint_every: float | None = None, resume: bool = False, collective: bool = True,
        **options):
    """Run a scene on a backend; write ``out`` (H5MD) if given; return a
    :class:`~mdgran.simulation.RunResult`.

    * ``scene``: a built-in scene name (:func:`scenes`), a path to a TOML file, a nested
      mapping with the TOML's keys (``{"chain": {"n": 10}, "run": {"duration": 20.0}}``,
      missing keys take their defaults) or a :class:`~mdgran.model.scene.Scene`.
    * ``backend``: ``"reference"`` (event-driven DOP853, the accuracy oracle), ``"fast"``
      (compiled velocity Verlet at ``run.dt``) or ``"lammps"``.
    * ``out``: path of the H5MD file to write (atomically, at the end), or None.
    * ``set``: overrides of scene keys, ``{"run.duration": 50.0, "impulse.velocity": 5}``
      (what ``--set`` does on the command line); also nested or as (key, value) pairs.
    * ``progress``: a progress bar on stderr for runs longer than 2 s.
    * ``keep`` (default True): keep the run in memory as ``result.trajectory`` (a
      :class:`~mdgran.output.run_record.Run`).
    * ``raise_errors`` (default True): a run that fails (blow-up, stalled step) raises
      :class:`~mdgran.backends.base.IntegrationError` after writing its frames; False returns
      the result with ``status = "failed: ..."``.
    * ``checkpoint_every`` (seconds), ``resume``, ``collective``, ``reporters``: as in
      :func:`mdgran.simulation.run`.
    * ``**options``: the backend's own options, e.g. ``tolerance=`` (reference), ``dt=`` or
      ``locate_events=`` (fast), ``contact="native"`` (lammps); or in ``backend`` itself, e.g. ``"lammps:native"`` (see
      :mod:`mdgran.backends`).  Any other keyword raises
      ``TypeError`` naming it, before anything runs.

    A run whose energy-ledger error exceeds the backend's declared bound is returned with
    ``status = "ledger-exceeded: ..."`` (not raised): check ``result.status == "complete"``.
    """
    from .backends import get_backend
    from .simulation import BackendUnavailable, spec_of
    from .simulation import run as simulate

    name, _ = spec_of(backend)  # "lammps:native": a backend and its options (mdgran.backends)
    try:
        accepted = tuple(get_backend(name).accepted_options)
    except ImportError as exc:
        raise BackendUnavailable(f"backend {backend!r} is not available: {exc}") from None
    unknown = [k for k in options if k not in accepted]
    if unknown:
        from .model.scene import SCHEMA

        names = ", ".join(repr(k) for k in unknown)
        keys = [f"{sec}.{k}" for k in unknown for sec in SCHEMA if k in SCHEMA[sec]]
        hint = (f"; scene keys go in set=, e.g. set={{{keys[0]!r}: ...}}" if keys else "")
        raise TypeError(f"run() got unexpected keyword argument{'s' if len(unknown) > 1 else ''}"
                        f" {names}; backend {backend!r} takes "
                        f"{', '.join(accepted) or 'no options'}, and run() takes "
                        f"{', '.join(RUN_KEYWORDS)}{hint}")
    sc = as_scene(scene, _overrides(set))
    if out is not None:
        out = _check_out(out, scene)
    result = simulate(sc, backend, out=out, progress=progress, keep=keep, reporters=reporters,
                      raise_errors=raise_errors, checkpoint_every=checkpoint_every,
                      resume=resume, collective=collective, **options)
    if result.trajectory is not None:
        result.trajectory.attrs.setdefault("scene_name", sc.name)
    return result
