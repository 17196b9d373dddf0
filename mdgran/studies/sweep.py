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

**Realizations.**  Past its predictability horizon a case is one realization of a chaotic
system, and statistics over the sweep depend on which.  ``[sweep]`` may ask for an ensemble::

    [sweep]
    realizations = 5              # K >= 1 (default 1: one case per grid point, as without it)
    perturbation = 1e-3           # eps > 0, at most 0.1 (default 1e-3)

Realization ``r`` (``0 .. K-1``) of a grid point runs it with the impulse velocity
``v0 * (1 + r * eps)``, ``v0`` the grid point's own ``impulse.velocity`` (from the grid, the
fixed keys or the scene file; an ``impulse.velocity_si`` converted to p q first): ``r = 0`` is the
unperturbed case, with exactly the overrides it has without realizations; ``r >= 1`` appends
the override ``("impulse.velocity", v0 * (1 + r * eps))`` (replacing the grid point's
``impulse.velocity`` or ``impulse.velocity_si`` override).  A relative change of ``1e-3`` is far
below any structure of the grid and far above round-off, so the realizations diverge only
where the dynamics amplifies it (the impulse energy changes by the factor ``(1 + r eps)^2``,
0.2% per realization at ``1e-3``).  Each realization is a case of its own (``NNNN.h5``,
``NNNN.json``); with ``K > 1`` every case's ``params`` gain ``"realization": r`` (its other
``params`` are the grid point's, unperturbed).  Realizations are the slowest axis: case
``r * G + g`` is realization ``r`` of grid point ``g`` (``G`` grid points), so cases
``0 .. G-1`` are the sweep without realizations, numbered as before: a folder run with ``K``
realizations can be run again with more (same ``eps``) and only the new cases run.  The
``[small]`` section may set ``realizations`` and ``perturbation`` too (they replace the
``[sweep]`` values there).

Every case writes ``DIR/cases/NNNN.h5`` (the run, atomically) and then ``DIR/cases/NNNN.json``
(its summary, atomically).  A case counts as done when its JSON exists, says it did not fail,
and its H5 exists, so a sweep that is killed or interrupted and started again redoes only the
unfinished and failed cases.  ``[sweep] scene`` names a built-in scene or a path from the sweep
file's folder; ``DIR/sweep.json`` records the scene's resolved text's SHA-256, and a case or a
resume on a scene changed since is refused (the cases would mix two scenes).  ``DIR/sweep.json`` lists the cases and their parameters; ``DIR/summary.json``
(rewritten at the end of every call) counts the complete cases and lists the others: those
whose ledger error exceeded their backend's declared bound (status ``ledger-exceeded: ...``)
and those that failed.

**Faults.**  Cases run in separate worker processes (``--workers``).  A case that fails for
any reason is recorded as failed, with a one-line reason (``failed: RuntimeError: ...``), in
its JSON and in ``summary.json``, and the sweep goes on: an exception of any kind in the case
(returned by the worker as a line of text: not every exception pickles), or its worker process
dying (killed, out of memory, a crash in compiled code): the worker is replaced and the case
runs again, and a case that killed its worker :data:`WORKER_DEATHS` (2) times is recorded
failed.  The same command run again redoes the failed cases (and the unfinished ones).
Ctrl-C or SIGTERM on the main process stops the sweep at once: queued cases are not started,
the workers are killed (what they were writing is removed), finished cases stay, the command
exits with the interrupted status (130; 143 for SIGTERM) and the same command resumes.  Workers
exit by themselves when the main process dies, even by SIGKILL (Linux's parent-death signal,
and a thread polling the parent's pid).

**Workers.**  Each worker process runs case after case until the sweep ends: it imports
mdgran, loads the compiled kernels and builds what a case shares with the next (the fast
backend's contact table) once, and every case is still a run of its own (its file and summary
are those of the case run alone).  With several workers each runs on a share of the cores the
sweep may use (:func:`worker_cores`: with ``--workers 2`` on two cores, one core each), so a
backend whose thread count defaults to the cores a process may use does not run two threads
per core.

**MPI.**  The same spec runs on MPI ranks through mpi4py's ``MPIPoolExecutor``
(``--executor mpi``; ``pip install 'mdgran[mpi]'``), rank 0 running the sweep and the other
ranks its cases::

    mpiexec -n 17 python -m mpi4py.futures "$(command -v mdgran)" sweep SWEEP --out DIR \\
        --executor mpi

(Without mpiexec, ``--executor mpi`` spawns ``--workers`` MPI processes itself.)  Each case is a
run of its own on its rank (``collective=False``: it writes its H5 whatever the rank), and a
LAMMPS case runs on ``MPI.COMM_SELF`` (on ``MPI_COMM_WORLD``, shared by the pool's ranks, it
would deadlock).  Plain ``mpiexec -n K mdgran sweep`` is refused on ranks other than 0.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import sys
import time as _time
from pathlib import Path

from ..model.scene import SceneError, builtin_scenes, load_scene, read_toml
from ..output.run_record import unreadable
from ..output.storage import OutputLock, OutputLocked, write_atomic
from ..signals import interrupting

SWEEP_DIR = Path(__file__).parents[1] / "sweeps"


def builtin_sweeps() -> dict:
    return {p.stem: p for p in sorted(SWEEP_DIR.glob("*.toml"))}


#: default relative change of impulse.velocity between successive realizations
PERTURBATION = 1e-3
#: the largest perturbation allowed: realizations are the same grid point, perturbed
MAX_PERTURBATION = 0.1


def _realization_keys(head: dict, small_t: dict, small: bool, realizations=None):
    """``(K, eps)`` from ``[sweep]`` (``[small]`` replacing them with ``small``; the
    ``realizations`` argument replacing K), checked: one-line SceneError naming the key."""
    keys = dict(head)
    if small:
        keys.update({k: v for k, v in small_t.items() if k in ("realizations", "perturbation")})
    sec = {k: ("small" if small and k in small_t else "sweep")
           for k in ("realizations", "perturbation")}
    k = keys.get("realizations", 1) if realizations is None else realizations
    where = f"{sec['realizations']}.realizations" if realizations is None else "realizations"
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise SceneError(where, f"must be an integer >= 1, not {k!r}"[:200])
    eps = keys.get("perturbation", PERTURBATION)
    if (isinstance(eps, bool) or not isinstance(eps, (int, float)) or not math.isfinite(eps)
            or not 0 < eps <= MAX_PERTURBATION):
        raise SceneError(f"{sec['perturbation']}.perturbation", "must be a number > 0 and <= "
                         f"{MAX_PERTURBATION:g} (relative change of impulse.velocity per "
                         f"realization), not {eps!r}"[:200])
    return k, float(eps)


def perturbed_velocity(v0: float, r: int, eps: float) -> float:
    """The impulse velocity of realization ``r``: ``v0 * (1 + r * eps)``."""
    return float(v0) * (1.0 + r * eps)


def load_sweep(spec: str, extra_overrides=(), small: bool = False,
               realizations: int | None = None) -> dict:
    """Read and check a sweep; returns ``{"name", "scene", "backend", "cases": [...]}`` where
    each case is ``{"index", "overrides": [[key, value], ...], "params": {key: value}}``.
    ``realizations`` replaces the file's ``[sweep] realizations`` (module doc: case ``r * G +
    g`` is realization ``r`` of grid point ``g``; with more than one, ``params`` hold
    ``"realization"``, and the returned dict ``realizations`` and ``perturbation``)."""
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
    scene = scene_beside(scene, path)
    backend = head.get("backend", "reference")
    fixed_t = dict(raw.get("fixed", {}))
    grid = dict(raw.get("grid", {}))
    n_real, eps = _realization_keys(head, raw.get("small", {}), small, realizations)
    if small:  # the CI-sized version: [small] replaces grid axes (lists) and fixed keys
        for k, v in raw.get("small", {}).items():
            if k in ("realizations", "perturbation"):
                continue
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
    out = {"name": path.stem, "scene": scene, "scene_sha256": scene_digest(scene),
           "backend": backend, "cases": cases,
           "description": head.get("description", ""), "axes": list(grid.keys()),
           "small": raw.get("small", {})}
    if n_real > 1:
        out["cases"] = _realization_cases(scene, cases, n_real, eps)
        out["realizations"], out["perturbation"] = n_real, eps
    return out


def scene_beside(scene: str, sweep_file: Path) -> str:
    """A sweep's ``[sweep] scene``: a built-in name as it is, a relative path from the sweep
    file's folder (not from where the command runs)."""
    if scene in builtin_scenes() or Path(scene).is_absolute():
        return scene
    return str(Path(sweep_file).parent / scene)


def scene_digest(scene: str) -> str:
    """SHA-256 of the sweep's scene resolved (its TOML text, every value the cases start
    from): a sweep records it, and a case or a resume of a scene changed since is refused."""
    return hashlib.sha256(load_scene(scene).to_toml().encode("utf-8")).hexdigest()


def _realization_cases(scene: str, grid_cases: list, n_real: int, eps: float) -> list:
    """The cases of ``n_real`` realizations of each grid case, realization the slowest axis."""
    vel = ("impulse.velocity", "impulse.velocity_si")
    base = [float(load_scene(scene, c["overrides"]).impulse.velocity)
            for c in grid_cases]
    cases = []
    for r in range(n_real):
        for c, v0 in zip(grid_cases, base):
            overrides = list(c["overrides"])
            if r:
                overrides = [o for o in overrides if o[0] not in vel]
                overrides.append(("impulse.velocity", perturbed_velocity(v0, r, eps)))
                try:
                    load_scene(scene, overrides)
                except SceneError as exc:
                    raise SceneError("sweep.perturbation", f"realization {r} of case "
                                     f"{c['index']:04d}: {exc}") from None
            cases.append({"index": len(cases), "overrides": overrides,
                          "params": {**c["params"], "realization": r}})
    return cases


def _atomic_json(path: Path, obj):
    """``obj`` as JSON (one space indent, numpy numbers as floats), written atomically."""
    write_atomic(path, json.dumps(obj, indent=1, default=float) + "\n")


def case_summary(result) -> dict:
    """What a sweep keeps of each case besides its H5 file (``result``: the case's
    :class:`~mdgran.simulation.RunResult`, its record in memory)."""
    import numpy as np

    tr = result.trajectory
    e_imp = tr.scene.impulse_energy or 1.0
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
    out.update(tr.measures.summary)  # the paper's measures (mdgran.analysis.run_summary)
    return out


def run_case(scene_spec: str, backend: str, case: dict, out_dir: str,
             comm_self: bool = False, progress_every: float | None = None,
             scene_sha256: str | None = None) -> dict:
    """Run one case (in a worker process); returns its summary.  The run is a run of its own
    (``collective=False``): on an MPI worker rank it writes its ``.h5`` whatever the rank.
    ``comm_self``: the case runs on an MPI worker rank, so a backend that takes a communicator
    (LAMMPS) gets ``MPI.COMM_SELF``, not ``MPI_COMM_WORLD`` (which the pool's ranks share: a
    LAMMPS instance on it would wait for every rank and deadlock).  ``progress_every``
    (seconds): keep ``cases/NNNN.progress`` holding the case's simulated time while it runs
    (:class:`mdgran.output.progress.ProgressFile`; the main process reads it for its progress
    lines).  ``scene_sha256``: the sweep's :func:`scene_digest`; a scene changed since the
    sweep started fails the case (it would run another scene than its sweep's)."""
    from ..simulation import run

    cases = Path(out_dir) / "cases"
    stem = f"{case['index']:04d}"
    if scene_sha256 is not None and scene_digest(scene_spec) != scene_sha256:
        raise SceneError("sweep.scene", f"{scene_spec} changed since the sweep started; "
                         "restore it, or run the sweep again in a new folder")
    scene = load_scene(scene_spec, [tuple(o) for o in case["overrides"]])
    options = {}
    if comm_self:
        from ..backends import get_backend
        from ..simulation import spec_of

        if "comm" in getattr(get_backend(spec_of(backend)[0]), "accepted_options", ()):
            from mpi4py import MPI

            options["comm"] = MPI.COMM_SELF
    reporters = []
    if progress_every:
        from ..output.progress import ProgressFile

        reporters.append(ProgressFile(cases / f"{stem}.progress",
                                      float(scene.run.duration), progress_every))
    res = run(scene, backend, out=cases / f"{stem}.h5", raise_errors=False, collective=False,
              reporters=reporters, **options)
    summary = {"index": case["index"], "params": case["params"], **case_summary(res)}
    _atomic_json(cases / f"{stem}.json", summary)
    return summary


def one_line(exc: BaseException, limit: int = 300) -> str:
    """``Type: message`` of an exception on one line, at most ``limit`` characters."""
    text = f"{type(exc).__name__}: {' '.join(str(exc).split()) or '(no message)'}"
    return text if len(text) <= limit else text[:limit - 3] + "..."


#: whether this worker has frozen its objects (:func:`_call_case`)
_frozen = False


def _call_case(fn, args):
    """Run a case in a worker and never raise: ``("ok", summary)`` or ``("error", reason)``
    (an exception object may not pickle back: SceneError's does not).

    After its first case a worker moves every object it holds to the garbage collector's
    permanent generation (``gc.freeze``): the modules, compiled kernels and caches every case
    uses, which each full collection would otherwise walk again (about 40 ms each, one in
    four cases: 7 % of a micro-star case's time)."""
    global _frozen
    try:
        return "ok", fn(*args)
    except KeyboardInterrupt:  # Ctrl-C reaching an MPI rank: the sweep stops, the case is not
        raise                  # failed (it runs again on the next call)
    except BaseException as exc:  # noqa: BLE001 - any failure is the case's, not the sweep's
        return "error", one_line(exc)
    finally:
        if not _frozen:
            import gc

            _frozen = True
            gc.collect()
            gc.freeze()


def _failed_case(case: dict, out: Path, reason: str) -> dict:
    """Record a case that failed without a summary of its own (an exception, a dead worker)."""
    summary = {"index": case["index"], "params": case["params"], "status": f"failed: {reason}",
               "error": reason}
    _atomic_json(out / "cases" / f"{case['index']:04d}.json", summary)
    return summary


# ---- worker processes ---------------------------------------------------------------------
def _die_with_parent(parent_pid: int):
    """Make this worker exit when the sweep's main process dies, however it dies (SIGKILL
    included): the kernel's parent-death signal on Linux, and a thread that polls the parent's
    pid everywhere (it also covers a parent that died before the signal was armed)."""
    import signal
    import threading

    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(1)

    def watch():
        while True:
            _time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="mdgran-parent-watch", daemon=True).start()


def usable_cores() -> list:
    """The cores this process may run on (its affinity), sorted; ``[]`` where unknown."""
    return sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []


def worker_cores(slot: int, workers: int, cores: list) -> list:
    """The cores worker ``slot`` (0-based) of ``workers`` runs on, of the sweep's ``cores``:
    all of them for one worker; else a share of its own, ``len(cores) // workers`` or one
    more (contiguous), or, with more workers than cores, core ``slot mod len(cores)``.  A
    backend whose thread count defaults to the cores a process may use
    (``os.sched_getaffinity``) then runs each case on its worker's share, instead of every
    worker taking every core."""
    cores = sorted(cores)
    if workers <= 1 or len(cores) <= 1:
        return cores
    if workers >= len(cores):
        return [cores[slot % len(cores)]]
    return cores[slot * len(cores) // workers:(slot + 1) * len(cores) // workers]


def _worker_main(conn, parent_pid: int, fn, cores=None):
    """A worker process: run the cases the main process sends until it sends None, on
    ``cores`` (its share, :func:`worker_cores`) if given."""
    import signal

    _die_with_parent(parent_pid)
    if cores:
        try:
            os.sched_setaffinity(0, cores)
        except (AttributeError, OSError):  # not Linux, or refused: every core, as before
            pass
    # Ctrl-C in a terminal reaches the whole process group: the main process decides what
    # happens (it stops the workers), a worker does not die of it mid-file on its own
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    while True:
        try:
            args = conn.recv()
        except (EOFError, OSError):
            return
        if args is None:
            return
        conn.send(_call_case(fn, args))


class _Worker:
    def __init__(self, ctx, fn, cores=None):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, os.getpid(), fn, cores),
                                name="mdgran-sweep-worker", daemon=True)
        self.proc.start()
        child.close()
        self.case = None

    def stop(self, kill: bool):
        if kill:
            self.proc.kill()
        else:
            try:
                self.conn.send(None)
            except OSError:
                pass
        self.proc.join(timeout=None if kill else 10)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def _death(exitcode) -> str:
    import signal

    if exitcode is not None and exitcode < 0:
        try:
            return f"killed by signal {-exitcode} ({signal.Signals(-exitcode).name})"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with status {exitcode}"


#: a case whose worker process died this many times is recorded as failed
WORKER_DEATHS = 2


class _Pool:
    """The sweep's worker processes, one case at a time each, in ``slots`` slots (each slot
    pinned to its share of ``cores``); a worker that dies is replaced in its slot."""

    def __init__(self, ctx, fn, slots: int, cores, out: Path):
        self.ctx, self.fn, self.slots, self.cores, self.out = ctx, fn, slots, cores, out
        self.workers: list = []

    def start(self):
        while len(self.workers) < self.slots:
            self.workers.append(self._new(len(self.workers)))

    def _new(self, slot: int) -> "_Worker":
        return _Worker(self.ctx, self.fn, worker_cores(slot, self.slots, self.cores))

    def busy(self) -> list:
        return [w for w in self.workers if w.case is not None]

    def assign(self, queue, args_of):
        """Hand the next cases of ``queue`` to the idle workers (one that died idle, killed
        from outside, is replaced first; one that dies just now is replaced next round)."""
        for i, w in enumerate(self.workers):
            if w.case is not None or not queue:
                continue
            if not w.proc.is_alive():
                w.stop(kill=True)
                self.workers[i] = w = self._new(i)
            try:
                w.conn.send(args_of(queue[0]))
            except OSError:
                continue
            w.case = queue.popleft()

    def finished(self, ready) -> list:
        """``(slot, case, message)`` of each busy worker that ``ready`` (of
        :func:`multiprocessing.connection.wait`) shows done: its message, None if it died."""
        out = []
        for i, w in enumerate(self.workers):
            if w.case is None or (w.conn not in ready and w.proc.sentinel not in ready):
                continue
            msg = None
            try:
                if w.conn.poll():
                    msg = w.conn.recv()
            except (EOFError, OSError):
                msg = None
            out.append((i, w.case, msg))
        return out

    def replace_dead(self, slot: int, case) -> str:
        """Replace the worker of ``slot``, which died running ``case``: its temporaries and
        the case's progress file go; returns how it died."""
        w = self.workers[slot]
        w.proc.join()
        why = _death(w.proc.exitcode)
        w.conn.close()
        for stale in (self.out / "cases").glob(f"*.tmp-{w.proc.pid}"):
            stale.unlink(missing_ok=True)
        (self.out / "cases" / f"{case['index']:04d}.progress").unlink(missing_ok=True)
        self.workers[slot] = self._new(slot)
        return why

    def stop(self, kill: bool):
        for w in self.workers:
            w.stop(kill=kill)


def _run_processes(todo, args_of, fn, workers: int, out: Path, done, tick=None,
                   tick_every: float = 1.0):
    """Run ``todo`` on ``workers`` processes; ``done(case, summary)`` for each finished one.
    A case raising anything is recorded failed (reason on one line); a worker that dies is
    replaced and its case run again, and recorded failed when it killed its worker
    :data:`WORKER_DEATHS` times.  Any exception here (Ctrl-C, SIGTERM) kills the workers at
    once and propagates: finished cases stay, the others run on the next call.  ``tick(running
    case indices)`` is called at least every ``tick_every`` seconds (progress lines)."""
    import collections
    import multiprocessing
    from multiprocessing.connection import wait

    pool = _Pool(multiprocessing.get_context(), fn, min(workers, len(todo)), usable_cores(),
                 out)
    queue = collections.deque(todo)
    deaths: dict = {}
    try:
        pool.start()
        while queue or pool.busy():
            pool.assign(queue, args_of)
            busy = pool.busy()
            if not busy:  # every idle worker died before taking a case: replace them
                _time.sleep(0.05)
                continue
            ready = wait([w.conn for w in busy] + [w.proc.sentinel for w in busy],
                         timeout=tick_every if tick is not None else None)
            if tick is not None:
                tick([w.case["index"] for w in pool.busy()])
            for slot, case, msg in pool.finished(ready):
                if msg is not None:
                    pool.workers[slot].case = None
                    kind, value = msg
                    done(case, value if kind == "ok" else _failed_case(case, out, value))
                    continue
                why = pool.replace_dead(slot, case)  # and run the case again, first
                deaths[case["index"]] = deaths.get(case["index"], 0) + 1
                if deaths[case["index"]] >= WORKER_DEATHS:
                    done(case, _failed_case(case, out, f"its worker process died "
                                            f"{WORKER_DEATHS} times running it (last: {why})"))
                else:
                    queue.appendleft(case)
    except BaseException:
        pool.stop(kill=True)
        raise
    pool.stop(kill=False)


def _run_futures(pool, todo, args_of, fn, out: Path, done, tick=None, tick_every: float = 1.0):
    """The same over a ``concurrent.futures`` executor (mpi4py's ``MPIPoolExecutor``): a case
    raising anything is recorded failed; an interrupt cancels the queued cases.  ``tick(None)``
    is called at least every ``tick_every`` seconds (the executor does not say which cases
    run: the progress lines find them by their progress files)."""
    from concurrent.futures import FIRST_COMPLETED, wait

    try:
        futs = {pool.submit(_call_case, fn, args_of(c)): c for c in todo}
        pending = set(futs)
        while pending:
            finished, pending = wait(pending, timeout=tick_every if tick is not None else None,
                                     return_when=FIRST_COMPLETED)
            for fut in finished:
                case = futs[fut]
                try:
                    kind, value = fut.result()
                except Exception as exc:  # noqa: BLE001 - the executor's own failure
                    kind, value = "error", f"the executor failed on it: {one_line(exc)}"
                done(case, value if kind == "ok" else _failed_case(case, out, value))
            if tick is not None:
                tick(None)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def sweep_summary(results: list) -> dict:
    """Counts of a sweep's case summaries, and the cases that are not complete, split into
    ``ledger_exceeded`` (ledger error above the backend's bound) and ``failed``."""
    from ..simulation import LEDGER_EXCEEDED

    def brief(r):
        return {"index": r["index"], "params": r["params"], "status": r["status"]}

    bad = [r for r in results if r["status"] != "complete"]
    exceeded = [brief(r) for r in bad if r["status"].startswith(LEDGER_EXCEEDED)]
    return {"cases": len(results), "complete": len(results) - len(bad),
            "ledger_exceeded": exceeded,
            "failed": [brief(r) for r in bad if not r["status"].startswith(LEDGER_EXCEEDED)]}


def _finished(out_dir: Path, index: int) -> bool:
    """A case is finished when its JSON exists, says it did not fail, and its H5 exists and
    opens (:func:`~mdgran.output.run_record.unreadable`):
    a failed case is run again by a rerun (a case that failed for a reason of the moment, such
    as another sweep on the same folder, must not stay failed), and so is a case whose JSON
    says it ran but whose H5 is missing (as an older mdgran's MPI sweep left on its worker
    ranks)."""
    js = out_dir / "cases" / f"{index:04d}.json"
    if not js.exists():
        return False
    try:
        status = str(json.loads(js.read_text()).get("status", ""))
    except (ValueError, UnicodeDecodeError, AttributeError):
        return False
    h5 = out_dir / "cases" / f"{index:04d}.h5"
    return not status.startswith("failed") and h5.exists() and unreadable(h5) is None


def _extends(before, cases: list) -> bool:
    """Whether a folder's recorded cases ``before`` are ``cases`` or the first of them with
    fewer realizations (realization 0 recorded without its ``"realization"`` key when the
    folder had one realization)."""
    if not isinstance(before, list) or len(before) > len(cases):
        return False
    if before == cases:
        return True
    if len(before) == len(cases) or "realization" not in cases[0]["params"]:
        return False

    def plain(c):
        if not isinstance(c, dict) or not isinstance(c.get("params"), dict):
            return c
        params = {k: v for k, v in c["params"].items()
                  if not (k == "realization" and v == 0)}
        return {**c, "params": params}

    return [plain(c) for c in before] == [plain(c) for c in cases[:len(before)]]


def pending_cases(sweep: dict, out_dir: Path) -> list:
    return [c for c in sweep["cases"] if not _finished(Path(out_dir), c["index"])]


def _mpi_executor(workers: int):
    try:
        from mpi4py.futures import MPIPoolExecutor
    except ImportError:
        raise SceneError("executor", "'mpi' needs mpi4py: pip install 'mdgran[mpi]'") \
            from None
    # under python -m mpi4py.futures the pool is the other ranks (max_workers is not used);
    # otherwise mpi4py spawns ``workers`` processes
    return MPIPoolExecutor(max_workers=workers)


def run_sweep(spec: str, out_dir, workers: int = 1, executor: str = "process",
              overrides=(), progress=True, stream=None, small: bool = False,
              backend: str | None = None, case_fn=None,
              progress_interval: float | None = None, realizations: int | None = None) -> list:
    """Run every unfinished case of ``spec``; returns all case summaries (finished ones read
    back from disk), sorted by case index.  ``backend`` replaces the spec's backend; a folder
    holds one sweep on one backend, so resuming it on another is refused.  ``realizations``
    replaces the file's ``[sweep] realizations`` (module doc); a folder holding the same sweep
    with fewer realizations (its cases a prefix of these) is extended: only the new cases run.

    A case that fails for any reason (an exception, its worker process dying twice) is
    recorded as failed, with a one-line reason, in its JSON and in ``summary.json``, and the
    sweep goes on.  Ctrl-C or SIGTERM stops the workers at once and raises
    :class:`KeyboardInterrupt` (:class:`mdgran.signals.Interrupted` for a signal): the finished cases
    stay, and the same call runs the rest.  ``case_fn`` replaces :func:`run_case` (same
    arguments; a module-level function, for tests).

    ``progress``: lines on ``stream`` (standard error): cases done, the running cases'
    simulated times (their workers keep ``cases/NNNN.progress`` files), elapsed and time left
    (:class:`mdgran.output.progress.SweepProgress`); on a terminal one line redrawn at most every
    ``progress_interval`` seconds (default 1), elsewhere a line per finished case and, between,
    one after ``progress_interval`` (default 15) seconds of silence."""
    from ..simulation import spec_of

    if executor not in ("process", "mpi"):
        raise SceneError("executor", f"must be 'process' or 'mpi', not {executor!r}")
    from ..simulation import mpi_rank

    if mpi_rank() != 0:  # plain mpiexec -n K mdgran sweep: every rank would run every case
        raise SceneError("executor", f"this is MPI rank {mpi_rank()}: run a sweep on MPI "
                         "ranks as mpiexec -n K python -m mpi4py.futures "
                         '"$(command -v mdgran)" sweep ... --executor mpi')
    stream = stream or sys.stderr
    sweep = load_sweep(spec, overrides, small, realizations)
    if backend is not None:
        spec_of(backend)  # a bad spec: SceneError on "backend", before anything runs
        sweep["backend"] = backend
    out = Path(out_dir)
    if (out / "sweep.json").exists():
        try:
            before = json.loads((out / "sweep.json").read_text(encoding="utf-8"))
            if not isinstance(before, dict):
                raise ValueError("not a JSON object")
        except (ValueError, UnicodeDecodeError, RecursionError) as exc:
            raise SceneError("out_dir", f"{out}/sweep.json is not a sweep's record ({exc}); use "
                             "a new folder or remove it") from None
        if before.get("backend") != sweep["backend"] or not _extends(
                before.get("cases"), json.loads(json.dumps(sweep["cases"]))):
            raise SceneError("out_dir", f"{out} holds another sweep (or the same on backend "
                             f"{before.get('backend')!r}); use a new folder")
        if before.get("scene_sha256", sweep["scene_sha256"]) != sweep["scene_sha256"]:
            raise SceneError("out_dir", f"the scene {sweep['scene']} changed since the sweep in "
                             f"{out} started (its cases would mix two scenes); restore it or "
                             "use a new folder")
    out.mkdir(parents=True, exist_ok=True)
    try:
        lock = OutputLock(out / "sweep")  # one sweep per folder at a time
    except OutputLocked as exc:
        raise SceneError("out_dir", f"{out}: another sweep is running in this folder "
                         f"({str(exc).split('(', 1)[1].split(')')[0]}); wait for it to end "
                         "or use another folder") from None
    try:
        return _run_cases(sweep, out, workers, executor, stream, progress, case_fn,
                          progress_interval)
    finally:
        lock.release()


def _run_cases(sweep: dict, out: Path, workers: int, executor: str, stream, progress: bool,
               case_fn, progress_interval) -> list:
    """:func:`run_sweep`'s cases in ``out``, which it holds the lock of."""
    pool = _mpi_executor(workers) if executor == "mpi" and pending_cases(sweep, out) else None
    _prepare_sweep_folder(sweep, out)
    todo = pending_cases(sweep, out)
    total, done0 = len(sweep["cases"]), len(sweep["cases"]) - len(todo)
    if progress and done0:
        print(f"sweep {sweep['name']}: {done0} of {total} cases already done, resuming",
              file=stream, flush=True)
    status = None
    if progress and todo:  # its line starts at once
        from ..output.progress import SweepProgress

        status = SweepProgress(sweep["name"], total, done0, len(todo), out / "cases", stream,
                               progress_interval)
    if todo:
        _run_pending(sweep, out, todo, workers, pool, executor == "mpi", case_fn or run_case,
                     status)
    elif pool is not None:
        pool.shutdown()
    return _collect_results(sweep, out)


def _prepare_sweep_folder(sweep: dict, out: Path):
    """``out/cases`` exists without what a killed sweep left (its temporary and progress
    files; one sweep per folder), and ``out/sweep.json`` describes ``sweep``."""
    (out / "cases").mkdir(parents=True, exist_ok=True)
    for pattern in ("*.tmp-*", "*.progress"):
        for stale in (out / "cases").glob(pattern):
            stale.unlink()
    _atomic_json(out / "sweep.json", {k: v for k, v in sweep.items() if k != "small"})


def _run_pending(sweep: dict, out: Path, todo: list, workers: int, pool, mpi: bool, fn,
                 status):
    """Runs the ``todo`` cases with ``fn`` on the MPI ``pool`` (``mpi``) or on ``workers``
    processes, reporting to ``status`` (a :class:`mdgran.output.progress.SweepProgress`, or None);
    then removes the progress files and, with the processes stopped, their partial files."""
    # workers rewrite their case's progress file at most this often (the main process reads it)
    every = max(0.1, min(2.0, status.mininterval / 2)) if status is not None else None

    def args_of(c):
        return (sweep["scene"], sweep["backend"], c, str(out), mpi, every,
                sweep["scene_sha256"])

    running = [None]  # the running cases' indices, where the executor says

    def done(case, summary):
        (out / "cases" / f"{case['index']:04d}.progress").unlink(missing_ok=True)
        if status is not None:
            status.case_done(case, summary, running[0])

    def tick(indices):
        running[0] = indices
        status.tick(indices)

    tick_every = min(1.0, status.mininterval) if status is not None else 1.0
    ticker = tick if status is not None else None
    try:
        with interrupting():
            if mpi:
                _run_futures(pool, todo, args_of, fn, out, done, ticker, tick_every)
            else:
                _run_processes(todo, args_of, fn, workers, out, done, ticker, tick_every)
    finally:
        if status is not None:
            status.close()
        _remove_run_files(out / "cases", partial=not mpi)


def _remove_run_files(cases: Path, partial: bool):
    """Removes the cases' progress files from ``cases`` and, with ``partial`` (the worker
    processes are stopped), the temporary files they were writing."""
    for stale in cases.glob("*.progress"):
        stale.unlink(missing_ok=True)
    if partial:
        for stale in cases.glob("*.tmp-*"):
            stale.unlink(missing_ok=True)


def _collect_results(sweep: dict, out: Path) -> list:
    """Every case's record from ``out/cases`` in the sweep's order (a case run before
    realizations were asked for takes the sweep's parameters); writes ``summary.json``."""
    results = []
    for c in sweep["cases"]:
        rec = json.loads((out / "cases" / f"{c['index']:04d}.json").read_text())
        if "realization" in c["params"]:  # a case run before realizations were asked for
            rec["params"] = c["params"]
        results.append(rec)
    _atomic_json(out / "summary.json", sweep_summary(results))
    return results
