"""Cost of one event window of the fast backend: ns per :func:`resolve_window` on the windows
of one step of an active chain, without the rest of the step.

The state is micro-star's physics with ``chain.n = N`` (1e5 by default), ``thermal.temperature
= 2`` and ``thermal.seed = 1`` at t = 4 (run there by the fast backend, then its accelerations
computed again by ``init_acc``). The windows are those the kernel would step from it: the beads
of the contacts with a root in the step of ``dt`` (beads along their parabolas), joined within
two beads (the kernel's :func:`~mdgran.backends.fast_kernel.find_windows`). Each timed repeat
steps every window through its events from the same state (each window's contact states are put
back after it), in a compiled loop, ``--reps`` times; reported: ns per window of each of
``--trials`` repeats, their median and min, the windows and the events per window. A single
thread; the time of one window does not depend on N (its beads and contacts alone), only the
number of windows does. On a machine whose speed drifts, compare two trees in alternating runs
(``PYTHONPATH=<other tree> python benchmarks/event_window.py --out ...``).

Writes benchmarks/results/event_window.json (``--out``).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "results" / "event_window.json"


def active_state(n: int):
    """(backend, state, flags, kernel state) of the active chain at t = 4."""
    from mdgran.backends import fast_kernel as fk
    from mdgran.backends.fast import FastBackend
    from mdgran.model.scene import load_scene
    from mdgran.simulation import run

    scene = load_scene("micro-star", [
        ("chain.n", n), ("thermal.temperature", 2.0), ("thermal.seed", 1),
        ("run.duration", 4.0), ("run.output_interval", 4.0), ("output.bead_stride", 1)])
    tr = run(scene, "fast", threads=1).trajectory
    backend = FastBackend(scene)
    flags = fk.Flags(*backend.flags)
    ks = fk.new_state(backend.model.n, backend.model.n_contacts, 1 << 16)
    ks.closed[:] = tr.closed[-1]
    old = fk.Beads(tr.x[-1].copy(), tr.v[-1].copy(), np.zeros(backend.model.n))
    fk.init_acc(flags, backend.params, old, ks)
    return backend, old, flags, ks


def windows_of(walls, params, old, x_new, h, ks):
    """The windows the kernel would step (:func:`~mdgran.backends.fast_kernel.find_windows`,
    every contact of every segment scanned: each marked as having flagged more contacts than
    it lists), as (first bead, last bead) rows."""
    from mdgran.backends import fast_kernel as fk

    seg, counters = ks.seg, ks.counters[0]
    seg.ints[:, fk.I_FLAGGED] = seg.flag.shape[1] + 1
    counters["seg_first"], counters["seg_last"] = 0, seg.count - 1
    count = fk.find_windows(walls, params, old, x_new, h, ks)
    return ks.windows[:count, [fk.W_LO, fk.W_HI]].copy()


def step_windows_loop():
    """The timed loop: every window stepped through its events from the same state."""
    from numba import njit

    from mdgran.backends import fast_kernel as fk

    @njit(_nrt=False)
    def step_windows(flags, params, old, new, lane, saved, windows, t0, dt, reps):
        c = lane.counters[0]
        events = 0
        for _ in range(reps):
            for k in range(windows.shape[0]):
                c.status, c.events, c.substeps = 0, 0, 0
                fk.resolve_window(flags, params, old, new, lane, windows[k, 0], windows[k, 1],
                                  t0, dt)
                events += c.events
                for j in range(max(windows[k, 0] - 2, 0),
                               min(windows[k, 1] + 2, saved.shape[0])):
                    lane.closed[j] = saved[j]
        return events

    return step_windows


def measure(n: int, reps: int, trials: int) -> dict:
    from mdgran.backends import fast_kernel as fk

    backend, old, flags, ks = active_state(n)
    h, params = backend.dt, backend.params
    new = fk.Beads(old.x + h * old.v + 0.5 * h * h * old.a, old.v.copy(), old.a.copy())
    step_windows = step_windows_loop()
    windows = windows_of(flags.walls, params, old, new.x, h, ks)
    log = ks.lanes.log
    lane = fk.Lane(ks.closed, ks.lanes.counters[0],
                   fk.EventLog(log.time[0], log.contact[0], log.kind[0], log.loss[0]),
                   ks.lanes.switching[0], ks.lanes.chatter[0], ks.seg.branch, ks.local)
    saved = ks.closed.copy()
    step_windows(flags, params, old, new, lane, saved, windows[:2], 4.0, h, 1)  # compile
    ns, events = [], 0
    load0 = os.getloadavg()
    for _ in range(trials):
        t = time.perf_counter()
        events = step_windows(flags, params, old, new, lane, saved, windows, 4.0, h, reps)
        ns.append((time.perf_counter() - t) / (reps * len(windows)) * 1e9)
        print(f"{ns[-1]:.0f} ns a window", flush=True)
    return {"n": n, "windows": len(windows), "events_per_window": events / (reps * len(windows)),
            "reps": reps, "ns_per_window": ns, "ns_per_window_median": float(np.median(ns)),
            "ns_per_window_min": min(ns), "loads": [load0, os.getloadavg()]}


def main(argv=None) -> None:
    import mdgran

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=float, default=1e5, help="beads of the chain")
    ap.add_argument("--reps", type=int, default=1000, help="passes over the windows a trial")
    ap.add_argument("--trials", type=int, default=7)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    result = {"benchmark": __doc__.split("\n\n")[0].replace("\n", " "),
              "mdgran": str(Path(mdgran.__file__).parent), "machine": platform.machine(),
              "cpus": os.cpu_count(), **measure(int(args.n), args.reps, args.trials)}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"median {result['ns_per_window_median']:.0f} ns a window over "
          f"{result['windows']} windows; wrote {args.out}")


if __name__ == "__main__":
    main()
