"""Fast backend: per-frame overhead on a small chain, start-up cost, and ns per bead-step, for
two source trees side by side (before = a pristine copy of HEAD, after = the working tree).

Every measurement runs in a fresh child process with ``PYTHONPATH`` set to one tree, and the
two trees alternate within each repeat (so a change of machine load hits both alike).  Per
tree and case the JSON holds every repeat, the median, min and max, and ``os.getloadavg()``
before and after each measurement (the machine is shared: read the timings with the loads).

* ``micro_star``: micro-star to t = 400 (4001 frames at the default output interval 0.1) at
  ``dt`` = 0.0025 and 0.01.  Times (s): ``kernel`` (the compiled stepping loop only,
  ``stats["kernel_s"]``), ``backend`` (iterating ``FastBackend.blocks()``, what the driver
  iterates, or in a tree without it ``frames()``, with nothing done per frame: kernel plus
  the backend's own per-frame work), ``run`` (:func:`mdgran.simulation.run`:
  backend, ledger, in-memory reporter), the same as CPU times (``backend_cpu``,
  ``backend_kernel_cpu``: the kernel calls of the ``backend`` measurement, ``run_cpu``; the
  process's, less sensitive to other processes than wall times), ``process`` (a whole
  ``python -c`` of imports and the run, measured from outside) with ``imports`` and ``setup`` (scene, table, compiled variant
  loaded) inside it.  Target: ``backend <= 1.5 kernel``
  (``backend_over_kernel``, and ``backend_over_kernel_cpu`` from the CPU times).
* ``ns_per_bead_step``: ``chain.n = N`` (1e4, 1e5, 1e6) of micro-star's law and of
  macro-hertz; each repeat advances a fixed number of bead-steps in one kernel call per frame
  (the kernel's wall time only, and the process's CPU time over the same call: ``cpu``, less
  sensitive to other processes on a busy machine), single thread.

Usage::

    git worktree add ../mdgran-before HEAD
    python benchmarks/fast_overhead.py --before ../mdgran-before   # results/fast_overhead.json
    python benchmarks/fast_overhead.py --before ../mdgran-before --quick   # smoke run (~1 min)
    python benchmarks/fast_overhead.py              # the working tree alone
    python benchmarks/fast_overhead.py --before ../mdgran-before --parts micro_star \
        --out /tmp/frames.json                     # the frame overhead alone
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
AFTER = HERE.parent
OUT = HERE / "results" / "fast_overhead.json"
BEAD_STEPS = 2e7  # per timed repeat of the ns-per-bead-step measurement

MICRO_STAR = r"""
import json, sys, time
t0 = time.perf_counter()
from mdgran.backends.fast import FastBackend
from mdgran.model.scene import load_scene
from mdgran.simulation import run
t1 = time.perf_counter()
dt, mode = float(sys.argv[1]), sys.argv[2]
scene = load_scene("micro-star", [("run.duration", 400.0)])
if mode == "process":  # one run as a user's process does it
    r = run(scene, "fast", dt=dt)
    print(json.dumps({"imports": t1 - t0, "run": time.perf_counter() - t1}))
    sys.exit()
run(scene, "fast", dt=dt)  # warm: compiled variants loaded, caches filled
out = {}
b = FastBackend(scene, dt=dt)
kernel, kernel_cpu = b.advance, [0.0]
def timed(*args):  # the kernel's CPU time (the process's: every thread)
    c = time.process_time()
    try:
        return kernel(*args)
    finally:
        kernel_cpu[0] += time.process_time() - c
b.advance = timed
w, c = time.perf_counter(), time.process_time()
frames = (sum(len(bl) for bl in b.blocks()) if hasattr(b, "blocks")  # what the driver takes
          else sum(1 for _ in b.frames()))
out["backend"] = time.perf_counter() - w
out["backend_cpu"] = time.process_time() - c
out["backend_kernel"] = b.stats["kernel_s"]
out["backend_kernel_cpu"] = kernel_cpu[0]
w, c = time.perf_counter(), time.process_time()
r = run(scene, "fast", dt=dt)
out["run"] = time.perf_counter() - w
out["run_cpu"] = time.process_time() - c
out["kernel"] = r.stats["kernel_s"]
out["frames"] = frames
print(json.dumps(out))
"""

PER_BEAD = r"""
import json, sys, time
import numpy as np
from mdgran.backends.fast import FastBackend
from mdgran.model.scene import load_scene
name, n, repeats, bead_steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
dt = 0.0025
steps = int(np.clip(bead_steps // n, 20, 400000))
scene = load_scene(name, [("chain.n", n), ("run.dt", dt), ("run.output_interval", steps * dt),
                          ("run.duration", (repeats + 1) * steps * dt)])
b = FastBackend(scene)
frames = b.frames()
next(frames)
next(frames)  # warm-up repeat
ns, cpu = [], []
for _ in range(repeats):
    k0, c0 = b.stats["kernel_s"], time.process_time()
    next(frames)
    cpu.append((time.process_time() - c0) / (n * steps) * 1e9)
    ns.append((b.stats["kernel_s"] - k0) / (n * steps) * 1e9)
print(json.dumps({"ns": ns, "cpu_ns": cpu, "steps": steps, "events": b.stats["events"]}))
"""


def child(tree: Path, code: str, *args) -> tuple[dict, float, list]:
    """Run ``code`` with ``tree`` first on the path; its JSON line, the process's wall time
    from outside, and the load averages before and after."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    load0 = os.getloadavg()
    t = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code, *map(str, args)], env=env, cwd="/tmp",
                         capture_output=True, text=True)
    wall = time.perf_counter() - t
    if res.returncode != 0:
        raise RuntimeError(f"{tree}: exit status {res.returncode}: "
                           f"{res.stderr.strip().splitlines()[-1:]}")
    return json.loads(res.stdout.strip().splitlines()[-1]), wall, [load0, os.getloadavg()]


def busy_processes() -> list:
    """``[pid, %cpu, command]`` of the processes using more than 10 % of a core (``ps``,
    averaged over each one's life), other than this one: the machine's other work."""
    try:
        out = subprocess.run(["ps", "-eo", "pid=,pcpu=,comm="], capture_output=True,
                             text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    rows = [line.split(None, 2) for line in out.splitlines()]
    return [[int(r[0]), float(r[1]), r[2]] for r in rows
            if len(r) == 3 and int(r[0]) != os.getpid() and float(r[1]) > 10.0]


def spread(values) -> dict:
    v = np.asarray(values, dtype=float)
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max()),
            "all": [float(x) for x in v]}


def micro_star(trees: dict, dts, repeats: int) -> dict:
    out = {}
    for dt in dts:
        timed = ("kernel", "backend", "backend_kernel", "run", "backend_cpu",
                 "backend_kernel_cpu", "run_cpu")
        raw = {k: {**{key: [] for key in timed}, "process": [], "imports": [],
                   "setup_and_run": [], "loads": []} for k in trees}
        for _ in range(repeats):
            for k, tree in trees.items():
                r, _, loads = child(tree, MICRO_STAR, dt, "frames")
                for key in timed:
                    raw[k][key].append(r[key])
                p, wall, loads2 = child(tree, MICRO_STAR, dt, "process")
                raw[k]["process"].append(wall)
                raw[k]["imports"].append(p["imports"])
                raw[k]["setup_and_run"].append(p["run"])
                raw[k]["loads"] += [loads, loads2]
        case = {}
        for k in trees:
            row = {key: spread(v) for key, v in raw[k].items() if key != "loads"}
            row["loads"] = raw[k]["loads"]
            row["backend_over_kernel"] = row["backend"]["median"] / row["backend_kernel"]["median"]
            row["run_over_kernel"] = row["run"]["median"] / row["kernel"]["median"]
            row["backend_over_kernel_cpu"] = (row["backend_cpu"]["median"]
                                              / row["backend_kernel_cpu"]["median"])
            row["run_cpu_over_kernel_cpu"] = (row["run_cpu"]["median"]
                                              / row["backend_kernel_cpu"]["median"])
            case[k] = row
            print(f"micro-star dt = {dt}: {k:6s} kernel {row['kernel']['median']:.3f} s, "
                  f"backend {row['backend']['median']:.3f} s "
                  f"({row['backend_over_kernel']:.2f}x its kernel; CPU time "
                  f"{row['backend_over_kernel_cpu']:.2f}x), run "
                  f"{row['run']['median']:.3f} s ({row['run_over_kernel']:.2f}x; CPU "
                  f"{row['run_cpu_over_kernel_cpu']:.2f}x), process {row['process']['median']:.2f} s "
                  f"(imports {row['imports']['median']:.2f} s)", flush=True)
        out[f"dt={dt}"] = case
    return out


def per_bead(trees: dict, sizes, repeats: int, bead_steps: float) -> dict:
    out = {}
    for name in ("micro-star", "macro-hertz"):
        for n in sizes:
            case = {}
            for k, tree in trees.items():
                r, _, loads = child(tree, PER_BEAD, name, n, repeats, bead_steps)
                case[k] = {**spread(r["ns"]), "cpu": spread(r["cpu_ns"]),
                           "steps_per_repeat": r["steps"], "events": r["events"],
                           "loads": loads}
            print(f"{name} N = {n:>8}: " + ", ".join(
                f"{k} {case[k]['median']:.2f} ns [{case[k]['min']:.2f}, {case[k]['max']:.2f}] "
                f"(cpu {case[k]['cpu']['median']:.2f})" for k in trees), flush=True)
            out[f"{name} N={n}"] = case
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="a copy of the old tree (git worktree of HEAD)")
    ap.add_argument("--quick", action="store_true", help="smoke run: few repeats, N <= 1e5")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--note", default="", help="stored with the results (what the trees are)")
    ap.add_argument("--parts", default="micro_star,ns_per_bead_step",
                    help="comma-separated: micro_star, ns_per_bead_step (default both)")
    args = ap.parse_args(argv)
    trees = {"after": AFTER} if args.before is None else {"before": args.before, "after": AFTER}
    repeats = args.repeats or (2 if args.quick else 5)
    sizes = [10000, 100000] if args.quick else [10000, 100000, 1000000]
    bead_steps = 2e6 if args.quick else BEAD_STEPS
    parts = set(args.parts.split(","))
    if not parts or not parts <= {"micro_star", "ns_per_bead_step"}:
        ap.error(f"--parts: micro_star and/or ns_per_bead_step, not {args.parts!r}")
    for tree in trees.values():  # compile / load every variant used, outside the timings
        child(tree, MICRO_STAR, 0.01, "process")
        for name in ("micro-star", "macro-hertz") if "ns_per_bead_step" in parts else ():
            child(tree, PER_BEAD, name, 100, 1, 1e4)
    result = {"benchmark": "fast backend: frame overhead, start-up, ns per bead-step",
              "trees": {k: str(v) for k, v in trees.items()}, "note": args.note,
              "quick": args.quick, "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
              "python": platform.python_version(), "load_at_start": os.getloadavg(),
              "busy_at_start": busy_processes()}
    if "micro_star" in parts:
        result["micro_star"] = micro_star(trees, (0.0025, 0.01), repeats)
    if "ns_per_bead_step" in parts:
        result["ns_per_bead_step"] = per_bead(trees, sizes, repeats, bead_steps)
    result["load_at_end"] = os.getloadavg()
    result["busy_at_end"] = busy_processes()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
