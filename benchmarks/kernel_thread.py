"""The fast backend's next kernel call on a thread of its own ("output off the
critical path"): wall time of whole runs (``mdgran.simulation.run`` with an H5MD file) with
the thread and with every call in line, alternating in one process after a warm-up run each.

The thread is used when the kernel runs on one thread and the process may use two cores or
more; "in line" is forced by making ``mdgran.backends.fast.usable_threads`` return 1 (the
kernel is the same single-thread variant in both).  Cases: micro-star to t = 400 at dt =
0.0025 and 0.01 (4001 frames), a 1000-bead chain to t = 100 (1001 frames of 1000 beads), and
a 1e5-bead chain (``run.threads = 1``) to t = 2 (21 frames of 1e5 beads, 8 MB of x, v and
positions each).  Per case: every repeat's wall time (s) on each side, the medians, min and
max, their ratio, and the kernel's own time; the load averages before and after, and the
processes using more than 10 % of a core at the start (``ps``).

Usage::

    python benchmarks/kernel_thread.py                  # results/kernel_thread.json
    python benchmarks/kernel_thread.py --repeats 3 --out /tmp/k.json
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "results" / "kernel_thread.json"

CASES = {
    "micro-star dt=0.0025": ("micro-star", [("run.duration", 400.0), ("run.dt", 0.0025)]),
    "micro-star dt=0.01": ("micro-star", [("run.duration", 400.0), ("run.dt", 0.01)]),
    "1000 beads": ("micro-star", [("chain.n", 1000), ("run.duration", 100.0)]),
    "1e5 beads, threads=1": ("micro-star", [("chain.n", 100000), ("run.duration", 2.0),
                                            ("run.threads", 1)]),
}


def busy() -> list:
    out = subprocess.run(["ps", "-eo", "pid=,pcpu=,args="], capture_output=True, text=True)
    rows = [line.split(None, 2) for line in out.stdout.splitlines()]
    return [r for r in rows if len(r) == 3 and float(r[1]) > 10 and int(r[0]) != os.getpid()
            and "ps -eo" not in r[2]]


def one(scene, inline: bool, where: Path) -> tuple:
    """Wall time of a run with an output file, and its kernel's time."""
    import mdgran.backends.fast as fast
    from mdgran.simulation import run

    real = fast.usable_threads
    if inline:
        fast.usable_threads = lambda threads: 1
    try:
        out = where / f"r-{time.perf_counter_ns()}.h5"
        t = time.perf_counter()
        res = run(scene, "fast", out=out, keep=False)
        wall = time.perf_counter() - t
        out.unlink()
    finally:
        fast.usable_threads = real
    assert res.status == "complete", res.status
    return wall, res.stats["kernel_s"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    from mdgran.model.scene import load_scene

    result = {"benchmark": "fast backend: next kernel call on a thread vs in line",
              "cpus": os.cpu_count(), "cpus_usable": len(os.sched_getaffinity(0)),
              "load_at_start": os.getloadavg(), "busy_at_start": busy(), "cases": {}}
    with tempfile.TemporaryDirectory() as d:
        for name, (spec, overrides) in CASES.items():
            scene = load_scene(spec, overrides)
            one(scene, False, Path(d))  # warm-up: compiled variant loaded, tables built
            one(scene, True, Path(d))
            walls = {"thread": [], "inline": []}
            kernels = {"thread": [], "inline": []}
            for _ in range(args.repeats):
                for side in ("thread", "inline"):
                    w, k = one(scene, side == "inline", Path(d))
                    walls[side].append(w)
                    kernels[side].append(k)
            med = {s: float(np.median(v)) for s, v in walls.items()}
            result["cases"][name] = {
                "wall_s": walls, "kernel_s": kernels,
                "median_s": med, "min_s": {s: min(v) for s, v in walls.items()},
                "max_s": {s: max(v) for s, v in walls.items()},
                "inline_over_thread": med["inline"] / med["thread"]}
            print(f"{name}: thread {med['thread']:.3f} s ({min(walls['thread']):.3f}-"
                  f"{max(walls['thread']):.3f}), in line {med['inline']:.3f} s "
                  f"({min(walls['inline']):.3f}-{max(walls['inline']):.3f}): "
                  f"{med['inline'] / med['thread']:.2f}x; kernel "
                  f"{np.median(kernels['thread']):.3f} s", flush=True)
    result["load_at_end"] = os.getloadavg()
    result["busy_at_end"] = busy()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
