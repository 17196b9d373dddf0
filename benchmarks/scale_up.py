"""Scale-up of the fast backend: time per bead-step and peak memory for chains of 10^2..10^6.

Each chain is micro-star's physics (contact, damping, substrate, impulse on bead 1) with
``chain.n = N``; the backend advances a fixed number of steps per frame, and each frame is
one timed repeat (the kernel call only: frames, ledger and output are not in the time).
Reported per N: median ns per bead-step with min and max over the repeats; memory traced by
tracemalloc (numpy's allocations): resident after set-up, peak during set-up (the contact
table's construction) and peak while stepping; the process's peak RSS.

``--vs-reference``: micro-star to t = 400 on both backends at several accuracies (reference:
``run.tolerance``; fast: ``run.dt``), wall time against ledger error (max |E - E0| / E_imp).

Usage::

    python benchmarks/scale_up.py                   # writes benchmarks/results/scale_up.json
    python benchmarks/scale_up.py --sizes 100 1000 --repeats 3
    python benchmarks/scale_up.py --vs-reference    # adds the comparison (a few minutes)
"""
from __future__ import annotations

import argparse
import json
import platform
import resource
import time
import tracemalloc
from pathlib import Path

import numpy as np

from mdgran.backends.fast import FastBackend
from mdgran.model.scene import load_scene
from mdgran.simulation import run

OUT = Path(__file__).resolve().parent / "results" / "scale_up.json"
TARGET_NS = 20.0
BEAD_STEPS_PER_REPEAT = 2e7


def time_chain(n: int, repeats: int, locate: bool = True) -> dict:
    """Median time per bead-step of ``repeats`` frames of a fixed number of steps."""
    dt = 0.0025
    steps = int(np.clip(BEAD_STEPS_PER_REPEAT // n, 20, 400000))
    scene = load_scene("micro-star", [("chain.n", n), ("run.dt", dt),
                                      ("run.output_interval", steps * dt),
                                      ("run.duration", (repeats + 1) * steps * dt)])
    tracemalloc.start()
    backend = FastBackend(scene, locate_events=locate)
    frames = backend.frames()
    next(frames)  # t = 0
    next(frames)  # warm-up repeat
    resident, setup_peak = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    times = []
    for _ in range(repeats):
        k0 = backend.stats["kernel_s"]
        next(frames)
        times.append(backend.stats["kernel_s"] - k0)
    _, run_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    ns = np.array(times) / (n * steps) * 1e9
    return {"n": n, "steps_per_repeat": steps, "repeats": repeats,
            "ns_per_bead_step_median": float(np.median(ns)),
            "ns_per_bead_step_min": float(ns.min()), "ns_per_bead_step_max": float(ns.max()),
            "resident_MB": resident / 1e6, "setup_peak_MB": setup_peak / 1e6,
            "stepping_peak_MB": run_peak / 1e6,
            "events": backend.stats["events"], "event_substeps": backend.stats["event_substeps"]}


def vs_reference(duration: float = 400.0) -> dict:
    """Wall time and ledger error on micro-star to ``duration``, both backends."""
    out = {"scene": "micro-star", "duration": duration, "reference": [], "fast": []}
    for tol in (1e-6, 1e-8, 1e-10):
        sc = load_scene("micro-star", [("run.duration", duration), ("run.tolerance", tol)])
        t = time.perf_counter()
        r = run(sc, "reference")
        out["reference"].append({"tolerance": tol, "wall_s": time.perf_counter() - t,
                                 "ledger_error": r.max_ledger_error,
                                 "events": len(r.trajectory.ev_time)})
        print("reference", out["reference"][-1], flush=True)
    for dt in (0.0025, 0.001, 0.00025, 0.0001, 0.00005):
        sc = load_scene("micro-star", [("run.duration", duration), ("run.dt", dt)])
        t = time.perf_counter()
        r = run(sc, "fast")
        out["fast"].append({"dt": dt, "wall_s": time.perf_counter() - t,
                            "kernel_s": r.stats["kernel_s"], "ledger_error": r.max_ledger_error,
                            "events": len(r.trajectory.ev_time)})
        print("fast", out["fast"][-1], flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000, 100000, 1000000])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--vs-reference", action="store_true")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    time_chain(100, 1)  # compile (or load the cached compiled code) outside the measurements
    rows = []
    for n in args.sizes:
        row = time_chain(n, args.repeats)
        rows.append(row)
        print(f"N = {n:>8}: {row['ns_per_bead_step_median']:6.2f} ns/bead-step "
              f"[{row['ns_per_bead_step_min']:.2f}, {row['ns_per_bead_step_max']:.2f}], "
              f"resident {row['resident_MB']:.1f} MB, peak {row['setup_peak_MB']:.1f} MB (set-up), "
              f"{row['stepping_peak_MB']:.1f} MB (stepping)",
              flush=True)
    result = {"benchmark": "fast backend scale-up (micro-star physics, chain.n = N)",
              "target_ns_per_bead_step_at_1e6": TARGET_NS, "machine": platform.processor()
              or platform.machine(), "python": platform.python_version(), "rows": rows,
              "peak_rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    if len(rows) >= 2:  # memory per bead from the two largest chains
        a, b = rows[-2], rows[-1]
        result["resident_bytes_per_bead"] = (b["resident_MB"] - a["resident_MB"]) * 1e6 / (
            b["n"] - a["n"])
    big = [r for r in rows if r["n"] >= 1000000]
    if big:
        result["target_met"] = bool(big[-1]["ns_per_bead_step_median"] <= TARGET_NS)
    if args.vs_reference:
        result["vs_reference"] = vs_reference()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
