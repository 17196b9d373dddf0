"""Side-by-side comparison of backends on one scene, with a verdict per criterion.

For each backend the scene is run twice: as given, and refined (the backend's
:meth:`~mdgran.backends.base.Backend.refinement`: 1/100 of the tolerance for the reference,
half the step for fixed-step backends).  The difference between the two, scaled by Richardson's
factor, is the backend's own error estimate ``e_B(t)`` (max over beads, units of p).

Predictability.  The micro chain amplifies small differences while its clusters form and
re-form.  The reference is run once more with the impulse changed by 1e-12 (relative; the
excitation, :func:`scaled_excitation`, for a scene driven by a pulse or a base motion): the
growth of that difference gives the amplification factor and a finite-time Lyapunov exponent.
A backend's predictability horizon is the first time its own error estimate exceeds
``PREDICTABLE`` (0.01 p, about 1 % of the equilibrium compression); past it, single events and
trajectories are no longer expected to match, and only statistics are compared.

Criteria (each with threshold and measured value in the report; exit status 3 when any fails):

* ``trajectory``: up to the horizon, ``max_i |x_B - x_ref|(t) <= 3 (e_B(t) + e_ref(t)) + floor``,
  each ``e`` at a frame the larger of its value there and at the next frame
  (:func:`next_frame_envelope`: the estimate vanishes at a frame just past an event).
* ``dissipation never decreases``: for each backend, D_viscous and D_hysteresis are
  non-decreasing (a sign error in damping or hysteresis breaks this first).
* ``ledger``: each backend's ledger closure over the whole run, ``max |E(t) - E0| / E_imp``,
  within the backend's declared bound (:meth:`~mdgran.backends.base.Backend.ledger_bound`, the
  same bound that sets the run's status: the criterion passes exactly when the nominal run's
  status is "complete"), with the refined run's error beside it.  (Whether it shrinks when
  dt halves is not judged: with step-quantized snaps, each event's error depends on where it
  falls in its step, so a short run's ledger error need not shrink; over micro-star's 58
  events it does, 2.4e-3 to 1.3e-3 to 2.4e-4.)
* ``dissipation``: viscous and hysteretic dissipation at the horizon agree within 3x the sum
  of the backends' error estimates of those quantities, plus the sum of their ledger errors
  (the split cannot be sharper than the bookkeeping), plus 1e-9 E_imp.
* ``events``: every contact goes through the same sequence of closes and opens up to the
  horizon, after dropping flicker: a contact that switches back within ``FLICKER_STEPS`` (10)
  steps of the fixed-step backend, as Hertz contacts resting at ``delta ~ 0`` do (no force jump
  either way; only the damping switches).  The number dropped is reported.  Sequences are
  compared per contact, not as one global order: two events on different contacts a few steps
  apart may swap order between backends without either being wrong (macro-hertz has such
  pairs).  A surplus event within (largest matched time offset + flicker window) of the
  horizon is an edge effect, not a disagreement; so is one where the other backend's contact
  passes within ``SAFETY`` times the summed error estimates of its switching point near that
  time (within the largest offset + flicker window + one frame): whether it switched is not
  decidable at the backends' accuracy (a grazing approach; the number excused is reported).
* ``cluster lifetimes`` and ``cluster sizes``: past the horizon individual events no longer
  match, so the clusters are compared as statistics.  Each backend runs an ensemble: its
  nominal and refined runs plus ``ensemble`` runs with the impulse (the excitation) changed by
  ``k x 1e-3`` (relative, ``k = 1..ensemble``): within any experimental uncertainty of an impulse, and
  large enough that the members decorrelate within the run (with micro-star's finite-time
  Lyapunov exponent 0.055, 1e-3 grows to order one by t ~ 125; 1e-6 perturbations stayed
  event-for-event identical to t = 100 and made the test vacuous).  The lifetimes (and sizes) of the clusters formed past the horizon, pooled over
  each ensemble, are compared with the two-sample Kolmogorov-Smirnov test; the criterion fails
  when ``p < 0.01``.  When fewer than 20 clusters form past the horizon in either ensemble
  (short runs), the whole run's clusters are compared instead, and below 20 the criterion is
  reported as not judged.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..backends import spec_stem
from ..backends.base import IntegrationError
from ..simulation import run

PREDICTABLE = 1e-2
SAFETY = 3.0
PERTURBATION = 1e-12
ENSEMBLE = 3
ENSEMBLE_STEP = 1e-3
KS_ALPHA = 0.01
MIN_CLUSTERS = 20
FLICKER_STEPS = 10


@dataclass
class Criterion:
    name: str
    passed: bool
    measured: float
    threshold: float
    detail: str = ""
    judged: bool = True


@dataclass
class BackendRuns:
    name: str
    nominal: object  # Run (mdgran.output.run_record)
    refined: object
    error: np.ndarray  # [F] own error estimate, max over beads
    factor: float
    wall_s: float
    ledger_error: float
    ledger_error_refined: float
    members: list = None  # the ensemble's trajectories (nominal and refined first)
    status: str = "complete"  # the nominal run's status
    ledger_bound: float = math.inf  # the nominal run's declared ledger bound (of E_imp)


def bead_difference(a, b) -> np.ndarray:
    """``max_i |x_i^a(t) - x_i^b(t)|`` at the common frame times."""
    m = min(len(a.time), len(b.time))
    return np.max(np.abs(a.x[:m] - b.x[:m]), axis=1)


def refinement_text(scene, overrides) -> str:
    """``tol/100``, ``dt/2``: what a refinement's overrides do, for progress labels."""
    parts = []
    for key, value in overrides:
        sec, _, name = key.partition(".")
        short = {"tolerance": "tol"}.get(name, name)
        try:
            ratio = float(scene.data[sec][name]) / float(value)
            parts.append(f"{short}/{ratio:.3g}" if ratio >= 1 else f"{short}x{1 / ratio:.3g}")
        except (KeyError, TypeError, ValueError, ZeroDivisionError):
            parts.append(f"{key}={value}")
    return ", ".join(parts)


def run_plan(scene, backends, ensemble: int, refinements: dict) -> dict:
    """The runs of a comparison, in order: ``{key: (backend, kind, role, duration)}`` (see
    :class:`mdgran.output.progress.RunSeries`); ``refinements``: backend -> its refinement's
    overrides."""
    dur = float(scene.run.duration)
    plan = {}
    for b in backends:
        plan[(b, "nominal")] = (b, "nominal", f"{b} (as given)", dur)
        plan[(b, "refined")] = (b, "refined", f"{b} refined "
                                f"({refinement_text(scene, refinements[b])})", dur)
        for k in range(1, ensemble + 1):
            plan[(b, "ensemble", k)] = (b, "ensemble", f"{b} ensemble {k} of "
                                        f"{ensemble} (excitation +{100 * k * ENSEMBLE_STEP:g}%)",
                                        dur)
    ref = backends[0]
    plan[(ref, "perturbed")] = (ref, "perturbed", f"{ref} perturbed (excitation "
                                f"+{PERTURBATION:g}, predictability)", dur)
    return plan


def scaled_excitation(scene, factor: float):
    """``scene`` with its excitation scaled by ``factor``: the impulse velocity, the force
    pulse's amplitude and the base motion's samples, those it has (an ensemble member or the
    perturbed run of a scene driven by a pulse or a base motion alone differs from the
    nominal one by its drive: scaling a zero impulse would change nothing)."""
    over = [("impulse.velocity", float(scene.impulse.velocity) * factor)]
    if scene.pulse.amplitude:
        over.append(("pulse.amplitude", float(scene.pulse.amplitude) * factor))
    if scene.base.kind != "none":
        over.append(("base.values", [float(u) * factor for u in scene.base.values]))
    return scene.with_overrides(over)


def _run(series, key, scene, name, **kw):
    """One run of the comparison, with its labelled progress line when ``series`` is given."""
    if series is None:
        return run(scene, name, **kw)
    return series.run(key, run, scene, name, **kw)


def run_backend(scene, name, out_dir=None, progress=False, ensemble: int = ENSEMBLE,
                series=None, refinement=None) -> BackendRuns:
    """``name``'s nominal, refined and ensemble runs.  ``series`` (a
    :class:`~mdgran.output.progress.RunSeries` holding :func:`run_plan`'s keys) draws their labelled
    progress; without it, ``progress`` gives each run :func:`~mdgran.simulation.run`'s own
    bar.  ``refinement``: ``(overrides, factor)``, if already known."""
    from ..simulation import make_backend

    overrides, factor = refinement or make_backend(scene, name).refinement(scene)
    prog = progress and series is None
    t0 = _time.perf_counter()
    out = Path(out_dir) / f"{spec_stem(name)}.h5" if out_dir is not None else None
    res = _run(series, (name, "nominal"), scene, name, out=out, progress=prog)
    nominal = res.trajectory
    wall = _time.perf_counter() - t0
    res_refined = _run(series, (name, "refined"), scene.with_overrides(overrides), name,
                       progress=prog)
    refined = res_refined.trajectory
    members = [nominal, refined] + [
        _run(series, (name, "ensemble", k), scaled_excitation(scene, 1 + k * ENSEMBLE_STEP),
             name, progress=prog).trajectory for k in range(1, ensemble + 1)]
    return BackendRuns(name, nominal, refined, factor * bead_difference(nominal, refined),
                       factor, wall, res.max_ledger_error, res_refined.max_ledger_error,
                       members, res.status, res.ledger_bound)


def cluster_statistics(ref: BackendRuns, other: BackendRuns, t_horizon: float):
    """KS comparison of the ensembles' cluster lifetimes and sizes past ``t_horizon`` (see the
    module docstring); returns (criteria, info)."""
    from ..analysis.statistics import cluster_lives, ks_compare, pooled

    def lives(br, t_from):
        return pooled([cluster_lives(tr.measures.history, t_from) for tr in br.members])

    t_from, where = t_horizon, "past the horizon"
    a, b = lives(ref, t_from), lives(other, t_from)
    if min(len(a), len(b)) < MIN_CLUSTERS:
        t_from, where = -np.inf, "over the whole run (too few past the horizon)"
        a, b = lives(ref, t_from), lives(other, t_from)
    crit, info = [], {"where": where, "ensemble": [len(ref.members), len(other.members)]}
    for what, xa, xb in (("lifetimes", a.lifetime, b.lifetime), ("sizes", a.size, b.size)):
        ks = ks_compare(xa, xb)
        info[what] = {**ks, "mean": [float(np.mean(xa)) if len(xa) else None,
                                     float(np.mean(xb)) if len(xb) else None]}
        judged = min(len(xa), len(xb)) >= MIN_CLUSTERS
        detail = (f"{len(xa)} vs {len(xb)} clusters {where}, from {len(ref.members)} and "
                  f"{len(other.members)} runs; mean {info[what]['mean'][0]:.3g} vs "
                  f"{info[what]['mean'][1]:.3g}; KS D = {ks['statistic']:.3g}"
                  if judged else f"not judged: {len(xa)} vs {len(xb)} clusters {where}")
        crit.append(Criterion(f"cluster {what} {other.name} vs {ref.name} (KS p-value)",
                              (not judged) or ks["pvalue"] >= KS_ALPHA,
                              ks["pvalue"] if judged else float("nan"), KS_ALPHA, detail,
                              judged))
    info["lives"] = {ref.name: a, other.name: b}
    return crit, info


def predictability(scene, ref: BackendRuns, series=None) -> dict:
    """Growth of a 1e-12 impulse perturbation in the reference."""
    pert = _run(series, (ref.name, "perturbed"), scaled_excitation(scene, 1 + PERTURBATION),
                ref.name).trajectory
    d = bead_difference(ref.nominal, pert)
    t = ref.nominal.time[: len(d)]
    k1 = int(np.searchsorted(t, min(1.0, t[-1])))
    kmax = int(np.argmax(d))
    amp = float(d[kmax] / d[k1]) if d[k1] > 0 else float("inf")
    ftle = float(math.log(amp) / (t[kmax] - t[k1])) if kmax > k1 and amp > 0 else 0.0
    return {"perturbation": PERTURBATION, "difference": d, "time": t,
            "amplification": amp, "ftle": ftle, "t_max_difference": float(t[kmax])}


def clear_previous(out: Path, backends):
    """Remove what an earlier comparison left in ``out`` and this one will not write again: its
    report, figures and the runs of other backends (``NAME.h5`` of a backend spec), so that
    a folder never shows a report or a run of another comparison beside this one's."""
    from ..backends import BACKENDS

    mine = {f"{spec_stem(b)}.h5" for b in backends}
    for path in out.glob("*.h5"):
        stem = path.stem.split("-")[0]
        if stem in BACKENDS and path.name not in mine:
            path.unlink(missing_ok=True)
    for name in ("report.json", "report.md"):
        (out / name).unlink(missing_ok=True)
    for fig in (out / "figures").glob("*.png") if (out / "figures").is_dir() else ():
        fig.unlink(missing_ok=True)


def failed_comparison(scene, backends, runs, name: str, error: str, out_dir):
    """A backend's run failed: write a report that says which and why, with the runs done so
    far (``report.json``, ``report.md``; the failed run's file holds its frames so far), then
    raise :class:`IntegrationError` naming it (exit status 1)."""
    report = {"scene": scene.name, "backends": list(backends), "passed": False,
              "failed": {"backend": name, "error": error},
              "runs": {r.name: {"wall_s": r.wall_s, "status": r.status,
                                "ledger_error": r.ledger_error,
                                "ledger_bound": r.ledger_bound} for r in runs}}
    where = ""
    if out_dir is not None:
        from .compare_report import write_failure

        write_failure(Path(out_dir), scene, report)
        where = f"; report in {Path(out_dir) / 'report.md'}"
    raise IntegrationError(f"compare {scene.name}: backend {name} failed: {error}{where}")


def horizon(time, *errors) -> float:
    """First time any error estimate exceeds PREDICTABLE (the run's end if never)."""
    e = np.max(np.vstack([err[: len(time)] for err in errors]), axis=0)
    above = np.flatnonzero(e > PREDICTABLE)
    return float(time[above[0]]) if above.size else float(time[-1])


def drop_flicker(times, contacts, kinds, tau):
    """Remove pairs of events of one contact that switch it back within ``tau``; returns the
    kept indices."""
    keep = np.ones(len(times), dtype=bool)
    last = {}
    for i, (t, c) in enumerate(zip(times, contacts)):
        j = last.get(int(c))
        if j is not None and keep[j] and t - times[j] < tau:
            keep[i] = keep[j] = False
            last.pop(int(c))
        else:
            last[int(c)] = i
    return np.flatnonzero(keep)


def event_sequence(tr, t_max, tau=0.0):
    idx = drop_flicker(tr.ev_time, tr.ev_contact, tr.ev_kind, tau) if tau > 0 else \
        np.arange(len(tr.ev_time))
    idx = idx[tr.ev_time[idx] <= t_max]
    dropped = int(len(tr.ev_time) - len(drop_flicker(tr.ev_time, tr.ev_contact, tr.ev_kind,
                                                          tau))) if tau > 0 else 0
    return (tr.ev_time[idx], list(zip(tr.ev_contact[idx].tolist(), tr.ev_kind[idx].tolist())),
            dropped)


def compare_events(ta, sa, tb, sb, t_horizon, tau, undecidable=None) -> dict:
    """Compare two event lists (times, [(contact, kind)]) contact by contact.

    For each contact the common prefix of kinds is matched (its time offsets measured); what is
    left over on either side is a disagreement unless it lies within ``max offset + tau`` of
    ``t_horizon`` (an event that one backend has just before the horizon and the other just
    after), or ``undecidable(t, contact, kind, side, slack)`` says the other backend came within
    its error of that switch.  Returns matched count, max offset, number of contacts differing,
    the number excused as undecidable and the first disagreement (text) or None.
    """
    per_a, per_b = {}, {}
    for t, (c, k) in zip(ta, sa):
        per_a.setdefault(c, []).append((float(t), k))
    for t, (c, k) in zip(tb, sb):
        per_b.setdefault(c, []).append((float(t), k))
    matched, offsets, leftovers = 0, [0.0], []
    for c in sorted(set(per_a) | set(per_b)):
        a, b = per_a.get(c, []), per_b.get(c, [])
        i = 0
        while i < min(len(a), len(b)) and a[i][1] == b[i][1]:
            offsets.append(abs(a[i][0] - b[i][0]))
            i += 1
        matched += i
        rest = [(t, c, k, "first") for t, k in a[i:]] + [(t, c, k, "second") for t, k in b[i:]]
        if rest:
            leftovers.append(min(rest))
    slack = max(offsets) + tau
    real = sorted(r for r in leftovers if r[0] < t_horizon - slack)
    excused = [r for r in real if undecidable is not None and undecidable(*r, slack)]
    real = [r for r in real if r not in excused]
    first = None
    if real:
        t, c, k, side = real[0]
        first = (f"contact {c} {'close' if k == 1 else 'open'} at t = {t:.4g} in the {side} "
                 f"backend has no counterpart")
    return {"matched": matched, "max_offset": max(offsets), "contacts_differing": len(real),
            "undecidable": len(excused), "disagreement": first}


def grazing_test(scene, ref: "BackendRuns", other: "BackendRuns"):
    """``undecidable(t, contact, kind, side, slack)`` for :func:`compare_events`: True when the
    backend without the event (``side`` names the one with it) has that contact within ``SAFETY``
    times the summed error estimates of its switching point (``delta = 0`` for a close,
    ``delta_off`` for an open) in some frame within ``slack`` plus one frame of ``t``."""
    from ..model.chain import model_from_scene

    model = model_from_scene(scene)
    column = {int(c): k for k, c in enumerate(model.contact_numbers)}
    offs = np.broadcast_to(model.delta_off, (model.n_contacts,))
    frame = float(scene.run.output_interval)

    def undecidable(t, contact, kind, side, slack) -> bool:
        tr = other.nominal if side == "first" else ref.nominal
        near = np.flatnonzero(np.abs(tr.time - t) <= slack + frame)
        near = near[near < min(len(ref.error), len(other.error))]
        if near.size == 0:
            return False
        j = column[int(contact)]
        delta = np.array([model.compressions(x)[j] for x in tr.x[near]])
        distance = np.abs(delta - (0.0 if kind == 1 else offs[j]))
        err = SAFETY * (ref.error[near] + other.error[near])
        return bool(np.any(distance <= err))

    return undecidable


def next_frame_envelope(error: np.ndarray) -> np.ndarray:
    """``max(e(t_i), e(t_i+1))`` for each frame i (the last frame's own ``e``): the own error
    estimate a trajectory is judged with.  Where an event falls in the second half of a step,
    the nominal run and the refined one (half the step) both end the frame with the same
    sub-step, from the event to the frame: their difference, the estimate, vanishes there
    while that sub-step's own error does not (collision-pair at t = 0.17, just past its
    collision at 1/6: estimate 1.5e-16, difference to the reference 8.7e-9).  The error only
    grows from there, and the next frame's estimate holds it (2.5e-7)."""
    out = np.array(error, dtype=float)
    out[:-1] = np.maximum(out[:-1], out[1:])
    return out


def judge(scene, ref: BackendRuns, other: BackendRuns, pred: dict) -> tuple[list, dict]:
    scale = scene.energy_scale or 1.0
    t = ref.nominal.time
    th = horizon(t, ref.error, other.error)
    k = int(np.searchsorted(t, th, side="right"))
    crit = []
    # trajectory
    d = bead_difference(ref.nominal, other.nominal)
    allowed = SAFETY * (next_frame_envelope(ref.error[: len(d)])
                        + next_frame_envelope(other.error[: len(d)])) + 1e-12 * max(
        1.0, float(np.abs(ref.nominal.x).max()))
    ratio = d[:k] / allowed[:k]
    worst = int(np.argmax(ratio))
    crit.append(Criterion(f"trajectory {other.name} vs {ref.name}", bool(ratio.max() <= 1.0),
                          float(d[worst]), float(allowed[worst]),
                          f"worst at t = {t[worst]:.4g} (horizon {th:.4g})"))
    # ledger closure of each backend within its declared bound: the run's status
    for b in (ref, other):
        crit.append(Criterion(f"ledger {b.name}", b.status == "complete", b.ledger_error,
                              b.ledger_bound, f"status {b.status}; refined run: "
                              f"{b.ledger_error_refined:.3g}"))

    # dissipation only grows (a damping or hysteresis sign error breaks this first)
    for b in (ref, other):
        worst = min(float(np.min(np.diff(b.nominal.ledger[q]))) if len(b.nominal.time) > 1
                    else 0.0 for q in ("dissipated_viscous", "dissipated_hysteresis"))
        crit.append(Criterion(f"dissipation never decreases ({b.name})", worst >= -1e-12 * scale,
                              -worst / scale, 1e-12, "largest decrease of D_viscous or "
                              "D_hysteresis between frames, relative to E_imp"))
    # dissipation split at the horizon
    kk = min(k, len(other.nominal.time), len(ref.nominal.time)) - 1
    for q in ("dissipated_viscous", "dissipated_hysteresis"):
        a, b = ref.nominal.ledger[q][kk], other.nominal.ledger[q][kk]
        ea = ref.factor * abs(a - ref.refined.ledger[q][kk])
        eb = other.factor * abs(b - other.refined.ledger[q][kk])
        # plus each backend's energy bookkeeping error: the split cannot be sharper than that
        thr = SAFETY * (ea + eb) + (ref.ledger_error + other.ledger_error) * scale \
            + 1e-9 * scale
        crit.append(Criterion(f"{q} at horizon", bool(abs(a - b) <= thr),
                              float(abs(a - b) / scale), float(thr / scale), f"{ref.name} {a:.6g}, {other.name} {b:.6g} "
                              f"(units eta p; measured and threshold relative to E_imp)"))
    # events
    tau = FLICKER_STEPS * float(scene.run.dt)
    ta, sa, drop_a = event_sequence(ref.nominal, th, tau)
    tb, sb, drop_b = event_sequence(other.nominal, th, tau)
    ev = compare_events(ta, sa, tb, sb, th, tau, grazing_test(scene, ref, other))
    offset = ev["max_offset"]
    crit.append(Criterion(f"events {other.name} vs {ref.name}", ev["disagreement"] is None,
                          float(ev["contacts_differing"]), 0.0,
                          f"{len(sa)} vs {len(sb)} events up to the horizon, {ev['matched']} "
                          f"matched contact by contact; max time offset {offset:.3g}; "
                          f"flicker dropped over the run: {drop_a} and {drop_b}; "
                          f"undecidable within the error estimates: {ev['undecidable']}"
                          + ("" if ev["disagreement"] is None else
                             f"; first disagreement: {ev['disagreement']}")))
    whole_a = list(zip(ref.nominal.ev_contact.tolist(), ref.nominal.ev_kind.tolist()))
    whole_b = list(zip(other.nominal.ev_contact.tolist(), other.nominal.ev_kind.tolist()))
    info = {"horizon": th, "max_event_time_offset": offset, "events_compared": ev["matched"],
            "events_whole_run": [len(whole_a), len(whole_b)],
            "whole_run_sequence_identical": whole_a == whole_b}
    return crit, info


def compare(scene, backends=("reference", "lammps"), out_dir=None, progress=False,
            ensemble: int = ENSEMBLE, stream=None, progress_interval: float | None = None
            ) -> dict:
    """Run ``backends`` (the first is the reference) on ``scene`` and judge them; writes
    ``report.json``, ``report.md`` and figures into ``out_dir`` when given.

    ``progress``: a line per run on ``stream`` (standard error) with its role, ``run k of N``
    and the time left for all runs (:class:`mdgran.output.progress.RunSeries`); on a terminal it is
    redrawn in place, elsewhere a line when each run starts and ends and one every
    ``progress_interval`` seconds (default 15) in between."""
    from ..simulation import make_backend

    backends = tuple(backends)
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    series = None
    refinements = {b: make_backend(scene, b).refinement(scene) for b in backends}
    if progress:
        series = _run_series(scene, backends, ensemble, refinements, stream, progress_interval)
    if out_dir is not None:
        clear_previous(Path(out_dir), backends)
    runs = _run_backends(scene, backends, out_dir, progress, ensemble, series, refinements)
    ref = runs[0]
    pred = predictability(scene, ref, series)
    if series is not None:
        from ..output.progress import fmt_seconds

        series.say(f"compare {scene.name}: {len(series.keys)} runs done in "
                   f"{fmt_seconds(series.elapsed())}; judging"
                   + (" and writing the report" if out_dir is not None else ""))
    criteria, pairs = _judge_pairs(scene, ref, runs[1:], pred)
    report = _report_numbers(scene, backends, runs, pred, criteria, pairs)
    if out_dir is not None:
        from .compare_report import write_report

        write_report(Path(out_dir), scene, runs, pred, report, pairs)
    return report


def _run_series(scene, backends: tuple, ensemble: int, refinements: dict, stream,
                progress_interval):
    """The progress of every run :func:`compare` makes (:func:`run_plan`), started with a
    line saying what they are."""
    from ..output.progress import RunSeries

    plan = run_plan(scene, backends, ensemble, {b: r[0] for b, r in refinements.items()})
    series = RunSeries(plan, stream=stream, interval=progress_interval)
    series.say(f"compare {scene.name}: {len(plan)} runs to t = "
               f"{float(scene.run.duration):g} ({', '.join(backends)}: as "
               f"given, refined{f', {ensemble} ensemble members' if ensemble else ''}; "
               f"{backends[0]} perturbed by {PERTURBATION:g})")
    return series


def _run_backends(scene, backends: tuple, out_dir, progress, ensemble: int, series,
                  refinements: dict) -> list:
    """Each backend's runs (:func:`run_backend`) in order; a backend whose integration
    fails ends the comparison (:func:`failed_comparison`)."""
    runs = []
    for b in backends:
        try:
            runs.append(run_backend(scene, b, out_dir, progress, ensemble, series,
                                    refinements[b]))
        except IntegrationError as exc:
            failed_comparison(scene, backends, runs, b, str(exc), out_dir)
    return runs


def _judge_pairs(scene, ref, others: list, pred: dict):
    """``(criteria, pairs)``: every criterion judging each of ``others`` against the
    reference run ``ref`` (:func:`judge`, then :func:`cluster_statistics` to its horizon),
    and what was measured per pair, by the other backend's name."""
    criteria, pairs = [], {}
    for other in others:
        crit, info = judge(scene, ref, other, pred)
        crit_s, info["clusters"] = cluster_statistics(ref, other, info["horizon"])
        criteria += crit + crit_s
        pairs[other.name] = info
    return criteria, pairs


def _report_numbers(scene, backends: tuple, runs: list, pred: dict, criteria: list,
                    pairs: dict) -> dict:
    """The comparison's ``report.json``: verdict, criteria, predictability, the pairs
    (without the cluster lives), each run's cost and errors, and the thresholds."""
    return {
        "scene": scene.name,
        "backends": list(backends),
        "passed": all(c.passed for c in criteria),
        "criteria": [asdict(c) for c in criteria],
        "predictability": {k: v for k, v in pred.items() if k not in ("difference", "time")},
        "pairs": {name: {**info, "clusters": {k: v for k, v in info["clusters"].items()
                                               if k != "lives"}}
                  for name, info in pairs.items()},
        "runs": {r.name: {"wall_s": r.wall_s, "status": r.status, "ledger_error": r.ledger_error,
                          "ledger_bound": r.ledger_bound,
                          "ledger_error_refined": r.ledger_error_refined,
                          "events": int(len(r.nominal.ev_time)),
                          "max_own_error": float(r.error.max())} for r in runs},
        "thresholds": {"predictable_p": PREDICTABLE, "safety": SAFETY},
    }
