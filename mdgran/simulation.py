"""The driver: run a scene on a backend and hand each frame to the reporters.

Example::

    from mdgran.model.scene import load_scene
    from mdgran.simulation import run
    result = run(load_scene("micro-star", [("run.duration", 50.0)]), "reference")
    traj = result.trajectory          # arrays in memory
    print(result.max_ledger_error)    # max |total - E0| / E_imp over the frames
    print(result.status)              # "complete", "ledger-exceeded: ...", "failed: ..."

A run ends "complete" only if it did not fail and its ledger error is within its backend's
declared bound (:meth:`~mdgran.backends.base.Backend.ledger_bound`); otherwise its status starts
with ``LEDGER_EXCEEDED`` and says both numbers.

The driver takes the backend's frames by blocks (:meth:`~mdgran.backends.base.Backend.blocks`:
the fast backend's kernel calls, a frame each for the others), computes each block's ledger
once (and its per-contact series, :meth:`~mdgran.backends.base.Frames.contact_series`, when an
H5MD writer stores them), and hands each block to every reporter:
``reporter.report_block(block)`` (a :class:`~mdgran.backends.base.Frames`; ``block.ledger()``
its ledger), or, for a reporter without it, ``reporter.report(frame, ledger)`` frame by frame;
``reporter.close(status)`` at the end.  The driver decides when a checkpoint is stored (between
blocks); the writer stores it, and reads back the one a resumed run goes on from
(:func:`mdgran.output.checkpoint.resume`).
"""
from __future__ import annotations

import math
import os
import time as _time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .backends import BadSpec, check_options, get_backend, parse_spec
from .backends.base import IntegrationError
from .output.checkpoint import CheckpointError
from .output.h5md_writer import H5MDWriter
from .output.memory_reporter import MemoryReporter
from .output.progress import CompileNotice, ProgressReporter
from .output.run_record import ledger_scale, relative_ledger_error
from .model.scene import SceneError
from .signals import FrameSections
from .output.storage import OutputLocked


#: prefix of the status of a run whose ledger error exceeds its backend's declared bound
LEDGER_EXCEEDED = "ledger-exceeded: "


class BackendUnavailable(RuntimeError):
    """The backend cannot run here (for example LAMMPS is not installed): one line."""


@dataclass(repr=False)
class RunResult:
    """What :func:`run` (and ``mdgran.run``) returns; all values nondimensional (docs/physics.md
    section 1: time ``1/q``, length ``p``, energy ``eta p``).

    Attributes:
        trajectory: the run's record in memory (:class:`~mdgran.output.run_record.Run`: frames,
            contact states, events, scene, status), or None for ``keep=False``.
        stats: the backend's counters (``steps``, ``events``, ``wall_time_s``, ...).
        status: ``"complete"``, ``"failed: ..."`` or ``"ledger-exceeded: ..."``.
        max_ledger_error: ``max |E(t) - E0| / E_imp`` over the frames (scale:
            :func:`~mdgran.output.run_record.ledger_scale`).
        error: the failure's one-line message, or None.
        ledger_bound: the backend's declared bound on ``max_ledger_error`` (same scale).
    """

    trajectory: object
    stats: dict
    status: str
    max_ledger_error: float  # relative to the impulse energy (or to |E0| if no impulse)
    error: str | None = None
    ledger_bound: float = math.inf  # the backend's declared bound, same scale

    def __repr__(self) -> str:
        tr = self.trajectory
        attrs = getattr(tr, "attrs", None) or {}
        status = self.status if len(self.status) <= 60 else self.status[:57] + "..."
        parts = ([f"scene={str(attrs['scene_name'])!r}"] if attrs.get("scene_name") else [])
        if tr is not None:
            parts += [f"backend={tr.backend!r}", f"status={status!r}",
                      f"frames={len(tr.time)}", f"n={tr.n}", f"events={len(tr.ev_time)}"]
        else:
            parts += [f"status={status!r}", f"events={self.stats.get('events', '?')}"]
        parts.append(f"ledger_error={self.max_ledger_error:.1e} (bound {self.ledger_bound:.1e})")
        return f"RunResult({', '.join(parts)})"


def ledger_status(error: float, bound: float) -> str:
    """The status of a run whose ledger error exceeds its bound (both relative to E_imp)."""
    return (f"{LEDGER_EXCEEDED}ledger error {error:.3g} of E_imp exceeds the backend's bound "
            f"{bound:.3g}")


def partial_path(out) -> Path:
    """The checkpoint file of a run writing ``out``: ``OUT.partial`` beside it."""
    out = Path(out)
    return out.with_name(f"{out.name}.partial")


def mpi_rank() -> int:
    """This process's rank under mpiexec (MPICH's PMI_RANK, Open MPI's variable), else 0.
    Under ``mpiexec -n K mdgran run ... --backend lammps`` every rank runs the driver, LAMMPS
    splits the chain over the ranks, and only rank 0 writes output."""
    import os

    for var in ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK"):
        if var in os.environ:
            return int(os.environ[var])
    return 0


def available_memory() -> float | None:
    """Bytes of memory available to a new allocation (``MemAvailable`` of /proc/meminfo, else
    the free physical pages), or None where neither is known."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None


def resource_estimate(scene, keep: bool = True) -> dict:
    """Lower bounds, in bytes, of the memory and the output-file size of a run of ``scene``:
    ``8 n`` bytes per stored array of ``n`` beads; the backend's state (10 such arrays), the
    H5MD writer's buffer (:func:`~mdgran.output.h5md_layout.buffer_frames` frames of x and v and
    their copies at a flush, plus 3 arrays of positions, plus 1 byte per contact for its state, 17
    with ``output.contacts``; of the stored beads, ``output.bead_stride``),
    the frames kept
    in memory (``keep``: x and v, and the copies made for the trajectory, plus the frame's
    time and ledger, 64 bytes); on disk x, v (and positions, and the per-contact series), the
    six observables and the step and time they share (positions: a time of their own), the
    series of more than :data:`~mdgran.rest_blocks.BLOCK` beads counted at one block a frame
    (the writer leaves out the blocks at rest)."""
    from .output.h5md_layout import buffer_frames, stored_bead_count
    from .rest_blocks import BLOCK

    n = int(scene.chain.n)
    ns = stored_bead_count(n, int(scene.output.bead_stride))  # stored beads
    r = scene.run
    frames = int(float(r.duration) / float(r.output_interval) + 1e-9) + 1
    pos = 3 if scene.output.positions else 0
    detail = bool(scene.output.contacts)
    con = (17.0 if detail else 1.0) / 8.0  # per contact: 2 f8 + 1 i1, or the i1 state alone
    block = min(frames, buffer_frames(8.0 * ns * (2 + pos + con)))
    memory = 8.0 * n * 10 + 8.0 * ns * block * (4 + pos + con) + (
        frames * (4 * 8.0 * n + 64.0) if keep else 0)
    written = min(ns, BLOCK)  # a long series: at least one column block a frame (rest_blocks)
    disk = frames * (8.0 * (written * (2 + con) + ns * pos) + 16.0 * (1 + (pos > 0)) + 6 * 8.0)
    return {"n": n, "frames": frames, "memory": memory, "disk": disk}


def check_resources(scene, out=None, keep: bool = True):
    """Refuse up front (:class:`SceneError`, exit status 2) a run whose frames cannot fit: the
    :func:`resource_estimate` lower bound above the available memory, or the output file above
    the free space of the file system that will hold ``out``."""
    import shutil
    from pathlib import Path

    est = resource_estimate(scene, keep)
    what = (f"{est['n']} beads x {est['frames']} frames (run.duration / run.output_interval)")
    gib = 2.0**30
    avail = available_memory()
    if avail is not None and est["memory"] > avail:
        raise SceneError("chain.n, run.output_interval",
                         f"{what} need at least {est['memory'] / gib:.3g} GiB of memory, "
                         f"{avail / gib:.3g} GiB are available; make chain.n smaller or "
                         "run.output_interval larger")
    if out is not None:
        where = Path(out).absolute().parent
        while not where.exists() and where != where.parent:
            where = where.parent
        try:
            free = float(shutil.disk_usage(where).free)
        except OSError:
            return
        if est["disk"] > free:
            raise SceneError("chain.n, run.output_interval",
                             f"{what} need at least {est['disk'] / gib:.3g} GiB on disk, "
                             f"{free / gib:.3g} GiB are free at {where} (out); make chain.n "
                             "smaller or run.output_interval larger")


def make_backend(scene, backend: str, **options):
    """The backend named by the spec ``backend`` (``"lammps:native"``: name and options, see
    :mod:`mdgran.backends`), constructed for ``scene`` with the spec's options and ``options``
    (an option given both ways must agree).  The options a run was made with, if any, are kept
    in ``stats["options"]`` (stored with the run)."""
    name, spec_options = spec_of(backend)
    for key, value in spec_options.items():
        if key in options and options[key] != value:
            raise SceneError("backend", f"{backend!r} sets {key} = {value!r}, but "
                             f"{key} = {options[key]!r} was given too")
    options = check_options(name, {**spec_options, **options})
    try:
        b = get_backend(name)(scene, **options)
    except ImportError as exc:
        raise BackendUnavailable(f"backend {backend!r} is not available: {exc}") from None
    kept = {k: v for k, v in options.items() if isinstance(v, (str, int, float, bool))}
    if kept:
        b.stats["options"] = kept
    return b


def spec_of(backend: str) -> tuple[str, dict]:
    """``(name, options)`` of a backend spec; a bad one is a :class:`SceneError` on key
    ``backend`` (one line saying what is allowed)."""
    try:
        return parse_spec(backend)
    except BadSpec as exc:
        raise SceneError("backend", str(exc)) from None


def worst(so_far: float, errors: np.ndarray) -> float:
    """The largest of ``so_far`` and ``errors``; NaN once any is NaN (a NaN error is not
    within any bound)."""
    e = float(errors.max())
    return so_far if so_far != so_far or e <= so_far else e


def report(reporter, block) -> None:
    """Hand the frames of ``block`` (:class:`~mdgran.backends.base.Frames`) to ``reporter``:
    whole if it has ``report_block(block)``, else frame by frame, ``report(frame, ledger)``
    (each frame's ledger a dict, as :meth:`~mdgran.model.chain.ChainModel.ledger` gives it)."""
    whole = getattr(reporter, "report_block", None)
    if whole is not None:
        whole(block)
        return
    for k in range(len(block)):
        reporter.report(block.frame(k), block.ledger_row(k))


class CheckpointClock:
    """When a run stores a checkpoint: at the first block that ends ``every`` seconds of wall
    time or more after the last one (None: never).  The driver decides and hands the writer
    the backend's state (:meth:`~mdgran.output.h5md_writer.H5MDWriter.checkpoint`)."""

    def __init__(self, every: float | None):
        self.every = every
        self.restart()

    def restart(self):
        self.last = _time.perf_counter()

    def due(self) -> bool:
        return self.every is not None and _time.perf_counter() - self.last >= self.every


def run(scene, backend: str = "reference", out=None, progress: bool = False, keep=True,
        reporters=(), raise_errors: bool = True, checkpoint_every: float | None = None,
        resume: bool = False, collective: bool = True, **options) -> RunResult:
    """Run ``scene`` on ``backend``; write ``out`` (H5MD) if given; return the result.

    A failure during the run (:class:`IntegrationError`) closes the output with every frame so
    far and ``status = "failed: ..."``; it is re-raised when ``raise_errors`` is true.  A run
    whose ledger error ``max |E - E0| / E_imp`` over the frames exceeds the backend's declared
    bound (``result.ledger_bound``) ends with ``status = "ledger-exceeded: ..."`` (not raised:
    its frames are what the backend computed; the status says they are not to be trusted).  Ctrl-C
    removes the partial output and re-raises, unless ``checkpoint_every`` (seconds) is set:
    then ``OUT.partial`` stays, and ``resume=True`` continues from its last checkpoint (the
    in-memory trajectory then holds only the resumed frames; the file holds all).  A run whose
    frames cannot fit in memory or on disk is refused first (:func:`check_resources`).  The run
    works on its own copy of ``scene``, checked again (:meth:`~mdgran.model.scene.Scene.own_copy`).

    ``collective`` (default True): under ``mpiexec`` every rank runs this same call (LAMMPS
    splits the chain over them), so rank 0 alone writes ``out`` and shows progress.  False: this
    process runs a run of its own (a sweep case on an MPI worker rank) and writes its own ``out``
    whatever its rank.
    """
    _check_checkpoint_every(checkpoint_every)
    scene = scene.own_copy()  # the run's own: a later change to the caller's is not its
    writes = not collective or mpi_rank() == 0
    check_resources(scene, out if writes else None, keep)
    b = make_backend(scene, backend, **options)
    # a collective run under mpiexec: rank 0 alone writes and shows progress
    reps, mem, writer = _reporters(scene, b, reporters, keep, out if writes else None,
                                   progress and writes, checkpoint_every, resume)
    resumed = writer.resumed if writer is not None else None
    watch = LedgerWatch(scene.energy_scale, resumed)
    detail = any(isinstance(r, H5MDWriter) and r.contacts for r in reps)  # contact series
    clock = CheckpointClock(writer.checkpoint_every if writer is not None else None)
    status, err = "complete", None
    # a signal while a frame goes to the reporters is held until all have it, so that a
    # checkpoint (the backend's state at its last frame) matches the frames written; one
    # while the files are closed waits until they are whole
    notice = CompileNotice(f"{scene.name} [{b.name}]") if progress else nullcontext()
    with notice, FrameSections() as sections:
        try:
            for block in b.blocks(resume=resumed.state) if resumed else b.blocks():
                sections.inside = True
                _hand_on(block, reps, watch, detail)
                _checkpoint_if_due(clock, writer, b)
                sections.leave()
        except IntegrationError as exc:
            status, err = f"failed: {exc}", str(exc)
        except BaseException:
            sections.inside = True  # a second signal waits for the checkpoint and the close
            _interrupted(reps, writer if clock.every is not None else None, b)
            raise
        sections.inside = True
        bound = b.ledger_bound(watch.scale, watch.term_max)
        status = watch.status(status, bound)
        b.stats["max_ledger_error_rel"] = watch.max_err
        b.stats["ledger_bound_rel"] = bound
        for r in reps:
            r.close(status)
        _leave_finished(sections, status)
    result = RunResult(
        trajectory=mem.record(scene, b.name) if mem is not None else None, stats=b.stats,
        status=status, max_ledger_error=watch.max_err, error=err, ledger_bound=bound)
    if err is not None and raise_errors:
        raise IntegrationError(err)
    return result


def _leave_finished(sections, status: str) -> None:
    """Deliver a signal that arrived while the run's files were closed; the
    :class:`KeyboardInterrupt` it raises carries ``finished = status`` (the files are whole)."""
    try:
        sections.leave()
    except KeyboardInterrupt as exc:
        exc.finished = status
        raise


def _hand_on(block, reps, watch, detail: bool) -> None:
    """One block to the reporters: its ledger into ``watch`` and, when a writer stores them
    (``detail``), its per-contact series, each computed once for the block, then the block
    to every reporter in turn."""
    watch.update(block.ledger())  # {term: [F]}
    if detail:
        block.contact_series()  # {name: [F, n_contacts]}
    for r in reps:
        report(r, block)


def _checkpoint_if_due(clock, writer, backend) -> None:
    """The backend's state at its last frame to the writer, when ``clock`` says a checkpoint
    is due (between blocks: every frame before it has been written)."""
    if clock.due():
        writer.checkpoint(backend.checkpoint_state())
        clock.restart()


def _reporters(scene, backend, reporters, keep, out, progress, checkpoint_every, resume):
    """``(reporters, memory, writer)``: the caller's reporters, then a
    :class:`MemoryReporter` (``keep``; else None), the H5MD writer (``out``; else None) and
    a progress line (``progress``), in the order they see each block."""
    reps = list(reporters)
    mem = MemoryReporter() if keep else None
    writer = (_open_writer(out, scene, backend, checkpoint_every, resume)
              if out is not None else None)
    reps += [r for r in (mem, writer) if r is not None]
    if progress:
        reps.append(ProgressReporter(float(scene.run.duration),
                                     label=f"{scene.name} [{backend.name}]"))
    return reps, mem, writer


def _check_checkpoint_every(every):
    if every is not None and (isinstance(every, bool) or not isinstance(every, (int, float))
                              or not 0 <= every < math.inf):
        raise SceneError("checkpoint_every", "must be a number of seconds >= 0, or None (no "
                         f"checkpoints), not {every!r}")


def _open_writer(out, scene, backend, checkpoint_every, resume) -> H5MDWriter:
    """The run's H5MD writer (checkpoints only where the backend can make them; a resume of
    a backend that cannot is refused by the writer); a refusal is a SceneError."""
    if not backend.can_checkpoint and not (resume and partial_path(out).exists()):
        checkpoint_every = None
    try:
        return H5MDWriter(out, scene, backend.name, backend=backend, model=backend.model,
                          stats_source=lambda: backend.stats,
                          checkpoint_every=checkpoint_every, resume=resume)
    except CheckpointError as exc:
        raise SceneError("resume", str(exc)) from None
    except OutputLocked as exc:
        raise SceneError("out", str(exc)) from None


def _interrupted(reps, writer, backend):
    """An interrupted run: a checkpoint at the last frame ``writer`` (None: no checkpoints)
    holds, then every reporter closed as interrupted."""
    try:
        if writer is not None:
            writer.checkpoint(backend.checkpoint_state())
    finally:
        for r in reps:
            r.close("interrupted")


class LedgerWatch:
    """The run's ledger error as frames come: ``max_err = max |E - E0| / scale`` (NaN once
    any error is NaN) with ``scale`` from the scene's energy scale and ``E0`` (the first
    frame's total energy; a resumed run's from its checkpoint), and ``term_max``, the largest
    ``|ledger term|`` (the round-off floor's scale)."""

    def __init__(self, energy_scale: float, resumed=None):
        self.energy_scale = energy_scale
        self.e0 = resumed.e0 if resumed is not None else None
        self.scale = ledger_scale(energy_scale, 0.0 if self.e0 is None else self.e0)
        self.max_err = resumed.max_error / self.scale if resumed is not None else 0.0
        self.term_max = resumed.term_max if resumed is not None else 0.0

    def status(self, status: str, bound: float) -> str:
        """``status`` of a complete run whose error exceeds ``bound`` becomes
        ``ledger-exceeded: ...`` (a NaN error is not within any bound); any other stays."""
        if status == "complete" and not self.max_err <= bound:
            return ledger_status(self.max_err, bound)
        return status

    def update(self, led: dict):
        """Take in a block's ledger ``{term: [F]}``."""
        if self.e0 is None:
            self.e0 = float(led["total_energy"][0])
            self.scale = ledger_scale(self.energy_scale, self.e0)
        errors = np.abs(relative_ledger_error(led["total_energy"], self.e0, self.scale))
        self.max_err = worst(self.max_err, errors)
        self.term_max = max(self.term_max, max(float(np.abs(c).max()) for c in led.values()))
