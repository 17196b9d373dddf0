"""The driver: run a scene on a backend and hand each frame to the reporters.

Example::

    from mdgran.scene import load_scene
    from mdgran.simulation import run
    result = run(load_scene("micro-star", [("run.duration", 50.0)]), "reference")
    traj = result.trajectory          # arrays in memory
    print(result.max_ledger_error)    # max |total - E0| / E_imp over the frames
"""
from __future__ import annotations

from dataclasses import dataclass

from .backends import BACKENDS, get_backend
from .backends.base import IntegrationError
from .reporters import H5MDWriter, MemoryReporter, ProgressReporter
from .scene import SceneError


class BackendUnavailable(RuntimeError):
    """The backend cannot run here (for example LAMMPS is not installed): one line."""


@dataclass
class RunResult:
    trajectory: object
    stats: dict
    status: str
    max_ledger_error: float  # relative to the impulse energy (or to |E0| if no impulse)
    error: str | None = None


def mpi_rank() -> int:
    """This process's rank under mpiexec (MPICH's PMI_RANK, Open MPI's variable), else 0.
    Under ``mpiexec -n K mdgran run ... --backend lammps`` every rank runs the driver, LAMMPS
    splits the chain over the ranks, and only rank 0 writes output."""
    import os

    for var in ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK"):
        if var in os.environ:
            return int(os.environ[var])
    return 0


def make_backend(scene, backend: str, **options):
    if backend not in BACKENDS:
        raise SceneError("--backend", f"must be one of {', '.join(BACKENDS)}, not {backend!r}")
    try:
        return get_backend(backend)(scene, **options)
    except ImportError as exc:
        raise BackendUnavailable(f"backend {backend!r} is not available: {exc}") from None


def run(scene, backend: str = "reference", out=None, progress: bool = False, keep=True,
        reporters=(), raise_errors: bool = True, checkpoint_every: float | None = None,
        resume: bool = False, **options) -> RunResult:
    """Run ``scene`` on ``backend``; write ``out`` (H5MD) if given; return the result.

    A failure during the run (:class:`IntegrationError`) closes the output with every frame so
    far and ``status = "failed: ..."``; it is re-raised when ``raise_errors`` is true.  Ctrl-C
    removes the partial output and re-raises, unless ``checkpoint_every`` (seconds) is set:
    then ``OUT.partial`` stays, and ``resume=True`` continues from its last checkpoint (the
    in-memory trajectory then holds only the resumed frames; the file holds all).
    """
    b = make_backend(scene, backend, **options)
    model = b.model
    reps = list(reporters)
    mem = MemoryReporter() if keep else None
    if mem is not None:
        reps.append(mem)
    writer = None
    if mpi_rank() != 0:  # under mpiexec: rank 0 alone writes and reports
        out, progress = None, False
    if out is not None:
        try:
            writer = H5MDWriter(out, scene, b.name, stats_source=lambda: b.stats,
                                checkpoint_every=checkpoint_every,
                                state_source=b.checkpoint_state, resume=resume)
        except ValueError as exc:
            raise SceneError("--resume", str(exc)) from None
        reps.append(writer)
    start = writer.resume_state if writer is not None else None
    if progress:
        reps.append(ProgressReporter(float(scene.data["run"]["duration"]),
                                     label=f"{scene.name} [{b.name}]"))
    scale = scene.impulse_energy or 1.0
    e0 = writer.resume_e0 if start is not None else None
    max_err = writer.resume_max_error / scale if start is not None else 0.0
    status, err = "complete", None
    try:
        for frame in (b.frames(resume=start) if start is not None else b.frames()):
            led = model.ledger(frame.x, frame.v, frame.closed, frame.dissipated_viscous,
                               frame.dissipated_hysteresis)
            if e0 is None:
                e0 = led["total_energy"]
                if not scene.impulse_energy:
                    scale = max(abs(e0), 1.0)
            max_err = max(max_err, abs(led["total_energy"] - e0) / scale)
            for r in reps:
                r.report(frame, led)
    except IntegrationError as exc:
        status, err = f"failed: {exc}", str(exc)
    except BaseException:
        for r in reps:
            r.close("interrupted")
        raise
    for r in reps:
        r.close(status)
    b.stats["max_ledger_error_rel"] = max_err
    result = RunResult(
        trajectory=mem.trajectory(scene.to_toml(), b.name) if mem is not None else None,
        stats=b.stats, status=status, max_ledger_error=max_err, error=err)
    if err is not None and raise_errors:
        raise IntegrationError(err)
    return result
