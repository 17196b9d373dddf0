"""Parametric studies: a grid of scene overrides, run in parallel, resumable.

A sweep file (TOML; built-in ones in ``mdgran/sweeps/``)::

    [sweep]
    scene = "micro-star"          # built-in name or path
    backend = "reference"
    description = "..."

    [fixed]                       # overrides applied to every case
    "run.duration" = 400.0

    [grid]                        # axes; the cases are their product, first axis slowest
    "impulse.velocity" = [2.0, 4.0, 8.0]
    "substrate.k1_si" = [4.6, 21.5]

    [small]                       # the CI-sized version (--small): shorter axes, other keys
    "impulse.velocity" = [4.0]
    "run.duration" = 50.0

Every case writes ``DIR/cases/NNNN.h5`` (the run, atomically) and then ``DIR/cases/NNNN.json``
(its summary, atomically).  A case counts as done when its JSON exists, so a sweep that is
killed and started again redoes only the unfinished cases.  ``DIR/sweep.json`` lists the
cases and their parameters; ``DIR/summary.json`` (rewritten at the end of every call) counts
the complete cases and lists the others: those whose ledger error exceeded their backend's
declared bound (status ``ledger-exceeded: ...``) and those that failed.  Cases run in
separate processes (``--workers``); the same spec runs on a cluster through mpi4py's
``MPIPoolExecutor`` (``--executor mpi``, launched as
``mpiexec -n 17 python -m mpi4py.futures -m mdgran sweep ... --executor mpi``).
"""
from __future__ import annotations

import itertools
import json
import os
import sys
import time as _time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from .scene import SceneError, load_scene, read_toml

SWEEP_DIR = Path(__file__).parent / "sweeps"


def builtin_sweeps() -> dict:
    return {p.stem: p for p in sorted(SWEEP_DIR.glob("*.toml"))}


def load_sweep(spec: str, extra_overrides=(), small: bool = False) -> dict:
    """Read and check a sweep; returns ``{"name", "scene", "backend", "cases": [...]}`` where
    each case is ``{"index", "overrides": [[key, value], ...], "params": {key: value}}``."""
    sweeps = builtin_sweeps()
    path = sweeps.get(spec, Path(spec))
    try:
        spec.encode("utf-8")
    except UnicodeEncodeError:
        raise SceneError("SWEEP", f"{spec!r}: the path is not valid UTF-8; rename the file") \
            from None
    if not path.is_file():
        raise SceneError("SWEEP", f"{spec!r} is neither a built-in sweep ("
                         + ", ".join(sweeps) + ") nor a readable .toml file")
    raw = read_toml(path, "SWEEP")
    for sec in raw:
        if sec not in ("sweep", "fixed", "grid", "small"):
            raise SceneError(sec, "unknown sweep section; allowed: sweep, fixed, grid, small")
        if not isinstance(raw[sec], dict):
            raise SceneError(sec, f"must be a table ([{sec}] with its keys below it), not "
                             f"{raw[sec]!r}"[:200])
    head = raw.get("sweep", {})
    scene = head.get("scene")
    if not isinstance(scene, str):
        raise SceneError("sweep.scene", "must name a scene")
    backend = head.get("backend", "reference")
    fixed_t = dict(raw.get("fixed", {}))
    grid = dict(raw.get("grid", {}))
    if small:  # the CI-sized version: [small] replaces grid axes (lists) and fixed keys
        for k, v in raw.get("small", {}).items():
            (grid if isinstance(v, list) else fixed_t)[k] = v
    fixed = list(fixed_t.items()) + list(extra_overrides)
    if not grid or not all(isinstance(v, list) and v for v in grid.values()):
        raise SceneError("grid", "must have at least one axis, each a non-empty list")
    cases = []
    for i, values in enumerate(itertools.product(*grid.values())):
        params = dict(zip(grid.keys(), values))
        overrides = fixed + list(params.items())
        load_scene(scene, overrides)  # validate every case up front
        cases.append({"index": i, "overrides": overrides, "params": params})
    return {"name": path.stem, "scene": scene, "backend": backend, "cases": cases,
            "description": head.get("description", ""), "axes": list(grid.keys()),
            "small": raw.get("small", {})}


def _atomic_json(path: Path, obj):
    tmp = path.with_name(f"{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(obj, indent=1, default=float) + "\n")
    os.replace(tmp, path)


def case_summary(scene, result) -> dict:
    """What a sweep keeps of each case besides its H5 file."""
    import numpy as np

    tr = result.trajectory
    e_imp = scene.impulse_energy or 1.0
    out = {
        "status": result.status,
        "wall_s": result.stats.get("wall_time_s"),
        "ledger_error": result.max_ledger_error,
        "ledger_bound": result.ledger_bound,
        "events": int(len(tr.ev_time)),
        "opens": int(np.sum(tr.ev_kind == 0)),
        "last_event_time": float(tr.ev_time[-1]) if len(tr.ev_time) else None,
        "kinetic_final_over_eimp": float(tr.ledger["kinetic_energy"][-1] / e_imp),
        "kinetic_max_over_eimp": float(tr.ledger["kinetic_energy"].max() / e_imp),
        "dissipated_viscous_over_eimp": float(tr.ledger["dissipated_viscous"][-1] / e_imp),
        "dissipated_hysteresis_over_eimp": float(tr.ledger["dissipated_hysteresis"][-1] / e_imp),
    }
    try:
        from .analysis import run_summary  # the paper's measures, where the analysis has them
    except ImportError:
        run_summary = None
    if run_summary is not None:
        out.update(run_summary(tr, scene))
    return out


def run_case(scene_spec: str, backend: str, case: dict, out_dir: str) -> dict:
    """Run one case (in a worker process); returns its summary."""
    from .simulation import run

    cases = Path(out_dir) / "cases"
    stem = f"{case['index']:04d}"
    scene = load_scene(scene_spec, [tuple(o) for o in case["overrides"]])
    res = run(scene, backend, out=cases / f"{stem}.h5", raise_errors=False)
    summary = {"index": case["index"], "params": case["params"], **case_summary(scene, res)}
    _atomic_json(cases / f"{stem}.json", summary)
    return summary


def sweep_summary(results: list) -> dict:
    """Counts of a sweep's case summaries, and the cases that are not complete, split into
    ``ledger_exceeded`` (ledger error above the backend's bound) and ``failed``."""
    from .simulation import LEDGER_EXCEEDED

    def brief(r):
        return {"index": r["index"], "params": r["params"], "status": r["status"]}

    bad = [r for r in results if r["status"] != "complete"]
    exceeded = [brief(r) for r in bad if r["status"].startswith(LEDGER_EXCEEDED)]
    return {"cases": len(results), "complete": len(results) - len(bad),
            "ledger_exceeded": exceeded,
            "failed": [brief(r) for r in bad if not r["status"].startswith(LEDGER_EXCEEDED)]}


def pending_cases(sweep: dict, out_dir: Path) -> list:
    return [c for c in sweep["cases"]
            if not (out_dir / "cases" / f"{c['index']:04d}.json").exists()]


def _executor(kind: str, workers: int):
    if kind == "process":
        return ProcessPoolExecutor(max_workers=workers)
    if kind == "mpi":
        try:
            from mpi4py.futures import MPIPoolExecutor
        except ImportError:
            raise SceneError("--executor", "'mpi' needs mpi4py (pip install mpi4py)") from None
        return MPIPoolExecutor()
    raise SceneError("--executor", f"must be 'process' or 'mpi', not {kind!r}")


def run_sweep(spec: str, out_dir, workers: int = 1, executor: str = "process",
              overrides=(), progress=True, stream=None, small: bool = False,
              backend: str | None = None) -> list:
    """Run every unfinished case of ``spec``; returns all case summaries (finished ones read
    back from disk), sorted by case index.  ``backend`` replaces the spec's backend; a folder
    holds one sweep on one backend, so resuming it on another is refused."""
    from .backends import BACKENDS

    stream = stream or sys.stderr
    sweep = load_sweep(spec, overrides, small)
    if backend is not None:
        if backend not in BACKENDS:
            raise SceneError("--backend", f"must be one of {', '.join(BACKENDS)}, not "
                             f"{backend!r}")
        sweep["backend"] = backend
    out = Path(out_dir)
    if (out / "sweep.json").exists():
        try:
            before = json.loads((out / "sweep.json").read_text(encoding="utf-8"))
            if not isinstance(before, dict):
                raise ValueError("not a JSON object")
        except (ValueError, UnicodeDecodeError, RecursionError) as exc:
            raise SceneError("--out", f"{out}/sweep.json is not a sweep's record ({exc}); use "
                             "a new folder or remove it") from None
        if before.get("backend") != sweep["backend"] or before.get("cases") != json.loads(
                json.dumps(sweep["cases"])):
            raise SceneError("--out", f"{out} holds another sweep (or the same on backend "
                             f"{before.get('backend')!r}); use a new folder")
    (out / "cases").mkdir(parents=True, exist_ok=True)
    for stale in (out / "cases").glob("*.tmp-*"):  # left by a killed sweep (one sweep per DIR)
        stale.unlink()
    _atomic_json(out / "sweep.json", {k: v for k, v in sweep.items() if k != "small"})
    todo = pending_cases(sweep, out)
    total, done0 = len(sweep["cases"]), len(sweep["cases"]) - len(todo)
    start = _time.perf_counter()
    if progress and done0:
        print(f"{sweep['name']}: {done0} of {total} cases already done, resuming", file=stream)
    if todo:
        with _executor(executor, workers) as pool:
            futs = [pool.submit(run_case, sweep["scene"], sweep["backend"], c, str(out))
                    for c in todo]
            for k, fut in enumerate(as_completed(futs), start=1):
                fut.result()
                if progress:
                    el = _time.perf_counter() - start
                    left = el / k * (len(todo) - k)
                    frac = (done0 + k) / total
                    bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
                    print(f"{sweep['name']} [{bar}] {done0 + k}/{total} cases  "
                          f"elapsed {el:.0f}s  left ~{left:.0f}s", file=stream, flush=True)
    results = [json.loads((out / "cases" / f"{c['index']:04d}.json").read_text())
               for c in sweep["cases"]]
    _atomic_json(out / "summary.json", sweep_summary(results))
    return results
