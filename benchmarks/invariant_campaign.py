"""Randomized invariant campaign: many short random scenes on the reference and fast backends,
every frame checked against the state invariant (benchmarks/invariants.py).

    python benchmarks/invariant_campaign.py [--scenes 3000] [--seed 1] [--long 4]
        [--backends reference,fast] [--workers 1] [--records FILE.jsonl]
        [--out benchmarks/results/invariant_campaign.json]

Per run: no closed contact below its switching point and no open contact past contact, at
1e-9 p, on every frame; ledger error within the backend's declared bound
(:meth:`mdgran.backends.base.Backend.ledger_bound`, the bound that sets a run's status);
``D_hysteresis = opens * V(delta_off)``; and the reference's and fast backend's event
sequences ``(contact, kind)`` compared in time order up to the first difference.

Where the answer is known it is checked exactly: a scene with an initial gap and no substrate
has its first event at ``t = gap / |v0|`` (the ``frame_event`` family puts that time on a
frame time on purpose), and two free beads with no damping close once and separate iff
``v0^2 / 4 > V(delta_off)`` (2 events, else 1; see ``pair_events_expected``).

Scene families (overrides of the built-in ``collision-pair`` scene, or ``micro-star``):

* ``frame_event``: an initial gap, no substrate; ``output_interval = (gap / v0) / m`` so a
  frame time falls on the first closing; ``gap``, ``v0``, ``m`` dyadic (exact) half the time;
* ``general``: any law (schwarz, lambda in [0.05, 5]; jkr; dmt; hertz), either snap-off rule,
  n <= 6, fixed or free, gap 0 or not, |v0| log-uniform in [1e-6, 200], substrate on or off,
  tolerance 1e-10..1e-6;
* ``near_threshold``: two free beads at ``v0 = 2 sqrt(V(delta_off)) (1 +- eps)``: the bound
  pair grazes its snap-off point on every swing (or barely escapes);
* ``long_snapoff`` (``--long``): micro-star-like chains of 20 beads over 50-100 time units,
  displacement rule, many snap-offs near the square-root singularity.

To check old code, put its checkout first on PYTHONPATH (the invariants are this checkout's,
benchmarks/invariants.py beside this script): ``PYTHONPATH=/tmp/old python benchmarks/...``.
Progress goes to stderr; the JSON has counts, and every violating scene's overrides so that it
can be rerun with ``mdgran run collision-pair --set KEY=VALUE ...``.
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

import mdgran
from mdgran.model.contact import law_from_contact_table
from mdgran.model.scene import load_scene
from mdgran.simulation import LEDGER_EXCEEDED

from invariants import check_run, matched_events  # benchmarks/invariants.py

RESULTS = Path(__file__).parent / "results"
#: fast backend step: at most this / (1 + |v0|)^0.5 (stiffer contacts at larger impulses)
FAST_DT_MAX = 0.01
FAMILY_WEIGHTS = {"frame_event": 0.4, "general": 0.45, "near_threshold": 0.15}
LAMBDA_RANGE = (0.05, 5.0)
#: frames at most in a frame_event scene (its interval can be tiny)
MAX_FRAMES = 400
#: a colliding pair 5 % above the escape threshold separates within PAIR_ESCAPE (1 + v0^-1/2)
#: time units of closing (slow collisions last longer: Hertz, ~ v0^-1/5)
PAIR_ESCAPE = 4.0


# ---- scene generator ------------------------------------------------------------------------
def log_uniform(rng, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def random_contact(rng, laws=("schwarz", "jkr", "dmt", "hertz")) -> list:
    """Overrides for a random contact law and snap-off rule."""
    law = str(rng.choice(laws))
    ov = [("contact.law", law), ("contact.snap_off", str(rng.choice(["displacement", "force"])))]
    if law == "schwarz":
        ov.append(("contact.lambda", log_uniform(rng, *LAMBDA_RANGE)))
    return ov


def fast_dt(rng, interval: float, v0: float) -> float:
    """A step that divides ``interval`` and is at most ``FAST_DT_MAX / sqrt(1 + |v0|)``."""
    k = max(1, math.ceil(interval * math.sqrt(1.0 + abs(v0)) / FAST_DT_MAX))
    return interval / (k * int(rng.choice([1, 2])))


def dyadic_gap_speed(rng) -> tuple:
    """(gap, v0, t_e) dyadic rationals with ``gap / v0 == t_e`` exactly in floating point."""
    while True:
        v0 = int(rng.integers(1, 32)) / 2.0 ** int(rng.integers(-3, 5))
        t_e = int(rng.integers(1, 16)) / 2.0 ** int(rng.integers(-1, 8))
        gap = v0 * t_e
        if 0.005 <= gap <= 2.0 and t_e <= 20.0 and gap / v0 == t_e:
            return gap, v0, t_e


def frame_event_scene(rng) -> list:
    """An initial gap, no substrate: the first closing is at ``t_e = gap / |v0|``, and a frame
    time is ``t_e`` (``output_interval = t_e / m``; exactly so for dyadic values)."""
    exact = bool(rng.random() < 0.5)
    if exact:
        gap, v0, t_e = dyadic_gap_speed(rng)
        m = int(rng.choice([1, 2, 4, 8, 16]))
    else:
        gap = float(rng.uniform(0.005, 1.0))
        v0 = log_uniform(rng, gap / 20.0, 200.0)
        t_e = gap / v0
        m = int(rng.integers(1, 13))
    interval = t_e / m
    n_frames = min(MAX_FRAMES, m + int(float(rng.uniform(2.0, 6.0)) / interval))
    free = bool(rng.random() < 0.6)
    n = 2 if free and rng.random() < 0.6 else int(rng.integers(2 if free else 1, 7))
    sign = -1.0 if (not free and rng.random() < 0.2) else 1.0
    ov = [("chain.n", n), ("chain.boundary", "free" if free else "fixed"),
          ("chain.initial_gap", gap), ("impulse.bead", 1), ("impulse.velocity", sign * v0),
          ("substrate.k1", 0.0), ("substrate.k3", 0.0),
          ("contact.damping", 0.0 if rng.random() < 0.6 else float(rng.uniform(0.001, 0.1))),
          ("run.output_interval", interval), ("run.duration", max(n_frames * interval, t_e)),
          ("run.tolerance", log_uniform(rng, 1e-10, 1e-6))]
    return random_contact(rng) + ov + [("run.dt", fast_dt(rng, interval, v0))]


def general_scene(rng) -> list:
    """Anything goes (short, small chains)."""
    free = bool(rng.random() < 0.3)
    n = int(rng.integers(2 if free else 1, 7))
    v0 = log_uniform(rng, 1e-6, 200.0) * (1.0 if rng.random() < 0.8 else -1.0)
    interval = float(rng.choice([0.01, 0.02, 0.05, 0.1, 0.125, 0.2, 0.25, 0.5]))
    gap = 0.0 if rng.random() < 0.7 else log_uniform(rng, 1e-3, 1.0)
    ov = [("chain.n", n), ("chain.boundary", "free" if free else "fixed"),
          ("chain.initial_gap", gap), ("impulse.bead", int(rng.integers(1, n + 1))),
          ("impulse.velocity", v0),
          ("contact.damping", 0.0 if rng.random() < 0.3 else log_uniform(rng, 1e-3, 0.5)),
          ("substrate.k1", 0.0 if rng.random() < 0.3 else log_uniform(rng, 1e-3, 1.0)),
          ("substrate.k3", 0.0 if rng.random() < 0.7 else log_uniform(rng, 1e-5, 1e-2)),
          ("run.output_interval", interval), ("run.duration", float(rng.uniform(2.0, 6.0))),
          ("run.tolerance", log_uniform(rng, 1e-10, 1e-6))]
    return random_contact(rng) + ov + [("run.dt", fast_dt(rng, interval, v0))]


def near_threshold_scene(rng) -> list:
    """Two free beads whose relative kinetic energy ``v0^2 / 4`` is within ``eps`` of the
    energy ``V(delta_off)`` lost at snap-off."""
    contact = random_contact(rng, laws=("schwarz", "jkr"))
    law = law_from_contact_table(dict(contact_table(contact)))
    eps = log_uniform(rng, 1e-9, 1e-2) * (1.0 if rng.random() < 0.5 else -1.0)
    v0 = 2.0 * math.sqrt(law.loop_energy) * (1.0 + eps)
    interval = float(rng.choice([0.01, 0.05, 0.1, 0.25]))
    gap = float(rng.uniform(0.01, 0.5))
    ov = [("chain.n", 2), ("chain.boundary", "free"), ("chain.initial_gap", gap),
          ("impulse.bead", 1), ("impulse.velocity", v0), ("contact.damping", 0.0),
          ("substrate.k1", 0.0), ("substrate.k3", 0.0), ("run.output_interval", interval),
          ("run.duration", float(rng.uniform(5.0, 20.0))),
          ("run.tolerance", log_uniform(rng, 1e-10, 1e-6))]
    return contact + ov + [("run.dt", fast_dt(rng, interval, v0))]


def long_snapoff_scene(rng) -> list:
    """micro-star-like: 20 beads, displacement rule, 50-100 time units (base micro-star)."""
    law = str(rng.choice(["schwarz", "schwarz", "jkr"]))
    ov = [("contact.law", law), ("contact.snap_off", "displacement"),
          ("impulse.velocity", float(rng.choice([8.0, 12.0, 20.0]))),
          ("run.duration", float(rng.uniform(50.0, 100.0))), ("run.output_interval", 0.1),
          ("run.tolerance", float(rng.choice([1e-8, 1e-9]))), ("run.dt", 0.0025)]
    if law == "schwarz":
        ov.append(("contact.lambda", float(rng.choice([0.3, 0.64, 1.5, 5.0]))))
    return ov


def contact_table(overrides) -> dict:
    """The ``[contact]`` entries of a list of overrides, as a table."""
    return {k.split(".")[1]: v for k, v in overrides if k.startswith("contact.")}


GENERATORS = {"frame_event": frame_event_scene, "general": general_scene,
              "near_threshold": near_threshold_scene, "long_snapoff": long_snapoff_scene}
BASE = {"long_snapoff": "micro-star"}


def generate(n: int, seed: int, n_long: int = 0) -> list:
    """``n`` random scenes plus ``n_long`` long ones: ``[(family, base, overrides)]``."""
    rng = np.random.default_rng(seed)
    fams = list(FAMILY_WEIGHTS)
    p = np.array([FAMILY_WEIGHTS[f] for f in fams])
    out = []
    for _ in range(n):
        fam = str(rng.choice(fams, p=p / p.sum()))
        out.append((fam, BASE.get(fam, "collision-pair"), GENERATORS[fam](rng)))
    for _ in range(n_long):
        out.append(("long_snapoff", "micro-star", long_snapoff_scene(rng)))
    return out


# ---- expectations and bounds ----------------------------------------------------------------
def first_event_expected(scene):
    """``(time, contact)`` of the first event when known in closed form, else None: with an
    initial gap and no substrate, bead ``b`` (the struck one) flies freely and meets its
    neighbour (or the wall) at ``t = gap / |v0|``."""
    d = scene.data
    gap, v0 = float(d["chain"]["initial_gap"]), float(d["impulse"]["velocity"])
    if gap <= 0.0 or d["substrate"]["k1"] or d["substrate"]["k3"] or v0 == 0.0:
        return None
    if gap / abs(v0) > float(d["run"]["duration"]) * (1.0 - 1e-9):
        return None  # not reached in the run
    bead, n = int(d["impulse"]["bead"]), int(d["chain"]["n"])
    walls = d["chain"]["boundary"] == "fixed"
    contact = bead + 1 if v0 > 0 else bead  # contact i joins bead i-1 and bead i
    if (contact == n + 1 or contact == 1) and not walls:
        return None  # a free end: it flies away
    return gap / abs(v0), contact


def pair_events_expected(scene):
    """Event count of two free undamped beads without substrate (the struck one moving
    towards the other), or None: 1 (close) when ``v0^2 / 4 < V(delta_off)`` (bound for
    ever), 2 (close, open) when it is 5 % above and the run lasts long enough past the
    closing (``PAIR_ESCAPE``).  None otherwise (near the threshold the answer may go either
    way)."""
    d = scene.data
    if (d["chain"]["n"] != 2 or d["chain"]["boundary"] != "free" or d["contact"]["damping"]
            or d["substrate"]["k1"] or d["substrate"]["k3"] or d["chain"]["initial_gap"] <= 0):
        return None
    v0 = float(d["impulse"]["velocity"]) * (1 if d["impulse"]["bead"] == 1 else -1)
    t_e = float(d["chain"]["initial_gap"]) / v0 if v0 > 0 else math.inf
    if t_e > float(d["run"]["duration"]) * (1.0 + 1e-9):
        return 0
    if t_e >= float(d["run"]["duration"]) * (1.0 - 1e-9):
        return None  # closing at the last frame time: reported there or not, both are right
    ratio = v0 * v0 / 4.0 / max(float(scene.law.loop_energy), 1e-300)
    if ratio < 1.0 - 1e-3:
        return 1
    if ratio > 1.05 and float(d["run"]["duration"]) - t_e >= PAIR_ESCAPE * (1 + v0**-0.5):
        return 2
    return None


# ---- one scene ------------------------------------------------------------------------------
def run_record(res, scene) -> dict:
    """A JSON-ready summary of one backend's :class:`RunCheck`."""
    bound = res.ledger_bound
    ok_h, expected_h, err_h = res.hysteresis
    return {"frames": res.frames, "status": res.status, "events": len(res.events),
            "opens": res.opens, "violations": res.counts,
            "examples": [list(v) for v in res.violations],
            "first_violation_time": res.first_violation_time,
            "ledger_error": res.ledger_error, "ledger_bound": bound,
            "ledger_ok": bool(res.ledger_error <= bound),
            "hysteresis_ok": bool(ok_h), "hysteresis_rel_error": float(err_h),
            "wall_s": round(res.wall_s, 4)}


def expectations(scene, runs: dict) -> dict:
    """Known answers held against each backend's events: first event, pair event count."""
    out = {}
    first = first_event_expected(scene)
    pair = pair_events_expected(scene)
    for name, res in runs.items():
        if res.status != "complete":
            continue
        if first is not None:
            ev = sorted(res.events)
            ok = (bool(ev) and ev[0][1] == first[1]
                  and abs(ev[0][0] - first[0]) <= 1e-9 * (1 + first[0]))
            out[f"{name}_first_event_ok"] = bool(ok)
        if pair is not None:
            out[f"{name}_pair_events_ok"] = bool(len(res.events) == pair)
    return out


def check_scene(family: str, base: str, overrides: list, backends: list) -> dict:
    """Run one scene on every backend; the record of what was found."""
    scene = load_scene(base, overrides)
    rec = {"family": family, "base": base, "overrides": [list(o) for o in overrides]}
    runs = {b: check_run(scene, b) for b in backends}
    rec["runs"] = {b: run_record(r, scene) for b, r in runs.items()}
    if set(runs) >= {"reference", "fast"}:
        a, b = runs["reference"].events, runs["fast"].events
        rec["events_matched"] = matched_events(a, b)
        rec["events_identical"] = bool(rec["events_matched"] == len(a) == len(b))
    rec.update(expectations(scene, runs))
    return rec


def _check_job(job):
    return check_scene(*job)


# ---- the summary ----------------------------------------------------------------------------
def bad_kinds(rec: dict, backend: str) -> list:
    """The kinds of problem one scene shows on one backend."""
    r = rec["runs"][backend]
    kinds = list(r["violations"])
    if not r["ledger_ok"]:
        kinds.append("ledger")
    if not r["hysteresis_ok"]:
        kinds.append("hysteresis")
    if r["status"].startswith("failed"):
        kinds.append("failed")
    elif not r["status"].startswith(("complete", LEDGER_EXCEEDED)):  # that one is "ledger"
        kinds.append("error")
    for key in ("first_event_ok", "pair_events_ok"):
        if rec.get(f"{backend}_{key}") is False:
            kinds.append(key.replace("_ok", "_wrong"))
    return kinds


def summarize(records: list, backends: list, args, wall: float) -> dict:
    out = {"mdgran_path": str(Path(mdgran.__file__).parent), "seed": args.seed,
           "scenes": len(records), "wall_s": round(wall, 1),
           "families": {f: sum(r["family"] == f for r in records)
                        for f in sorted({r["family"] for r in records})},
           "state_tol_p": 1e-9,
           "bounds": {"ledger": "each backend's declared bound (Backend.ledger_bound)",
                      "hysteresis_rtol": 1e-6}}
    for b in backends:
        runs = [r["runs"][b] for r in records]
        kinds: dict = {}
        scenes_by_kind: dict = {}
        examples = []
        for rec in records:
            ks = bad_kinds(rec, b)
            for k in ks:
                scenes_by_kind[k] = scenes_by_kind.get(k, 0) + 1
            for k, c in rec["runs"][b]["violations"].items():
                kinds[k] = kinds.get(k, 0) + c
            if ks and len(examples) < args.examples:
                examples.append({"family": rec["family"], "base": rec["base"], "problems": ks,
                                 "overrides": rec["overrides"], "run": rec["runs"][b]})
        led = np.array([r["ledger_error"] for r in runs if r["frames"] > 0])
        ratio = np.array([r["ledger_error"] / r["ledger_bound"] for r in runs if r["frames"]])
        out[b] = {"runs": len(runs), "frames_checked": int(sum(r["frames"] for r in runs)),
                  "events": int(sum(r["events"] for r in runs)),
                  "violations_by_kind": kinds, "scenes_with_problem": scenes_by_kind,
                  "scenes_with_state_violation": sum(bool(r["violations"]) for r in runs),
                  "ledger_error_max": float(led.max()) if led.size else None,
                  "ledger_error_over_bound_quantiles": {
                      q: float(np.quantile(ratio, float(q))) for q in ("0.5", "0.9", "0.99", "1")}
                  if ratio.size else None,
                  "wall_s": round(sum(r["wall_s"] for r in runs), 1), "examples": examples}
    if {"reference", "fast"} <= set(backends):
        both = [r for r in records if "events_matched" in r]
        strict = [r for r in both if r.get("reference_pair_events_ok") is not None]
        out["event_comparison"] = {
            "scenes": len(both),
            "identical": sum(r["events_identical"] for r in both),
            "diverged": sum(not r["events_identical"] for r in both),
            "two_bead_count_mismatch": [
                {"overrides": r["overrides"], "reference": r["runs"]["reference"]["events"],
                 "fast": r["runs"]["fast"]["events"]}
                for r in strict if r["runs"]["reference"]["events"] != r["runs"]["fast"]["events"]
            ][:args.examples]}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=3000, help="random short scenes")
    ap.add_argument("--long", type=int, default=4, help="long micro-star-like scenes")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--backends", default="reference,fast")
    ap.add_argument("--examples", type=int, default=30, help="violating scenes kept per backend")
    ap.add_argument("--out", type=Path, default=RESULTS / "invariant_campaign.json")
    ap.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    ap.add_argument("--records", type=Path, default=None,
                    help="also write every scene's record (JSON lines) here")
    ap.add_argument("--summarize", type=Path, default=None,
                    help="no runs: rebuild the summary from a --records file")
    args = ap.parse_args(argv)
    backends = args.backends.split(",")
    if args.summarize:
        records = [json.loads(line) for line in args.summarize.open()]
        return write_summary(summarize(records, backends, args, 0.0), args.out, backends)
    scenes = generate(args.scenes, args.seed, args.long)
    print(f"mdgran from {Path(mdgran.__file__).parent}; {len(scenes)} scenes", file=sys.stderr)
    records, wall0 = [], time.perf_counter()
    rec_fh = args.records.open("w") if args.records else None
    jobs = [(fam, base, ov, backends) for fam, base, ov in scenes]
    pool = multiprocessing.Pool(args.workers) if args.workers > 1 else None
    results = pool.imap(_check_job, jobs) if pool else map(_check_job, jobs)
    for i, rec in enumerate(results):
        fam = rec["family"]
        records.append(rec)
        if rec_fh:
            rec_fh.write(json.dumps(rec) + "\n")
            rec_fh.flush()
        probs = {b: bad_kinds(rec, b) for b in backends}
        if any(probs.values()) or (i + 1) % 50 == 0:
            print(f"[{i + 1}/{len(scenes)} {time.perf_counter() - wall0:.0f}s] {fam}: "
                  + "; ".join(f"{b} {p}" for b, p in probs.items() if p), file=sys.stderr)
    if pool:
        pool.close()
    write_summary(summarize(records, backends, args, time.perf_counter() - wall0), args.out,
                  backends)


def write_summary(summary: dict, out: Path, backends: list):
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps({b: {k: summary[b][k] for k in ("runs", "frames_checked",
                                                     "violations_by_kind", "scenes_with_problem")}
                      for b in backends}, indent=1))


if __name__ == "__main__":
    main()
