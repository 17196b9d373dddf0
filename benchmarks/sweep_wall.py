"""The paper's 91-case sweep (``paper-robustness``: 13 impulses x 7 substrate stiffnesses of
micro-star to t = 400) on the fast backend: wall time of the whole sweep beside the sum of its
cases' kernel times, for two source trees side by side (before = a pristine copy of HEAD,
after = the working tree).  Issue 18: "the 91-case sweep takes what its kernels take".

Each repeat runs ``python -m mdgran sweep paper-robustness --backend fast --workers W --quiet``
in a fresh folder, with ``PYTHONPATH`` set to one tree, the two trees alternating within each
repeat (a change of machine load hits both alike).  Per tree and repeat the JSON holds:

* ``wall_s``: the sweep command's wall time, measured from outside (process start, imports,
  every case, the summary);
* ``cpu_s``: its CPU time (user + system, the sweep process and its workers; less sensitive
  to other processes than the wall time);
* ``kernel_sum_s``: the sum over the cases of ``kernel_s`` (the compiled stepping loop's wall
  time, from each case's ``/parameters`` attribute ``backend_stats``), and
  ``backend_sum_s`` (the backends' ``wall_time_s``: from the first frame asked to the last
  handed over, so the driver's and reporters' work between frames included);
* ``wall_over_kernels`` = ``wall_s * W / kernel_sum_s`` (1 would be a sweep that takes what
  its kernels take on W workers) and ``cpu_over_kernels`` = ``cpu_s / kernel_sum_s``;
* the cases' statuses, and the machine's state: load averages before and after, the number
  of cores, and the processes using more than 10 % of a core (``ps``) just before, other
  than this one.  Timings of a busy machine say little: read them with these.

``--quick``: the sweep's small grid (v0 = 2, 16; K1 = 4.6, 21.5: 4 cases) at the full length
t = 400, one repeat.

``--workers 1 2`` runs each repeat with one worker and with two (each tree, alternating).  With
two trees, the two folders of each (repeat, workers) are compared case by case before they are
removed (``reference/compare_sweeps.py``: every dataset bitwise, every attribute, every summary
but the timings): ``identity`` in the JSON counts the identical and the differing cases.

Usage::

    git worktree add ../mdgran-before HEAD
    python benchmarks/sweep_wall.py --before ../mdgran-before        # results/sweep_wall.json
    python benchmarks/sweep_wall.py --before ../mdgran-before --quick
    python benchmarks/sweep_wall.py --workers 2                     # the working tree alone
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
AFTER = HERE.parent
OUT = HERE / "results" / "sweep_wall.json"
SWEEP = "paper-robustness"
BUSY_CPU_PERCENT = 10.0


def busy_processes() -> list:
    """``[pid, %cpu, command line]`` of the processes using more than BUSY_CPU_PERCENT of a
    core (``ps``: averaged over each one's life), other than this one; [] where ps is
    missing."""
    try:
        out = subprocess.run(["ps", "-eo", "pid=,pcpu=,args="], capture_output=True,
                             text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    busy = []
    for line in out.splitlines():
        parts = line.split(None, 2)
        if len(parts) == 3 and int(parts[0]) != os.getpid() and float(parts[1]) > \
                BUSY_CPU_PERCENT:
            busy.append([int(parts[0]), float(parts[1]), parts[2][:120]])
    return busy


def children_cpu() -> float:
    """User + system CPU seconds of this process's waited-for children (and theirs)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def case_stats(out: Path) -> dict:
    """Sums over the cases in ``out/cases``: kernel and backend wall times (from each file's
    ``backend_stats``), counts of cases and of their statuses."""
    import h5py

    kernel = backend = 0.0
    statuses: dict = {}
    files = sorted((out / "cases").glob("*.h5"))
    for path in files:
        with h5py.File(path, "r") as f:
            attrs = f["parameters"].attrs
            stats = json.loads(attrs["backend_stats"])
            status = attrs["status"]
        status = status.decode() if isinstance(status, bytes) else str(status)
        kernel += float(stats["kernel_s"])
        backend += float(stats["wall_time_s"])
        key = status.split(":")[0]
        statuses[key] = statuses.get(key, 0) + 1
    summaries = len(list((out / "cases").glob("*.json")))
    return {"cases": len(files), "summaries": summaries, "statuses": statuses,
            "kernel_sum_s": kernel, "backend_sum_s": backend}


def one_sweep(tree: Path, workers: int, quick: bool, out: Path) -> dict:
    """Run the sweep once with ``tree`` first on the path, into the fresh folder ``out``; its
    timings."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, "-m", "mdgran", "sweep", SWEEP, "--backend", "fast",
           "--workers", str(workers), "--out", str(out), "--quiet"]
    if quick:
        cmd += ["--small", "--set", "run.duration=400"]
    machine = {"load_before": list(os.getloadavg()), "busy_before": busy_processes()}
    cpu0, t0 = children_cpu(), time.perf_counter()
    res = subprocess.run(cmd, env=env, cwd=out.parent, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, children_cpu() - cpu0
    machine["load_after"] = list(os.getloadavg())
    if res.returncode != 0:
        raise RuntimeError(f"{tree}: {' '.join(cmd)} failed: "
                           f"{res.stderr.strip().splitlines()[-3:]}")
    row = {"wall_s": wall, "cpu_s": cpu, **case_stats(out), **machine}
    row["wall_over_kernels"] = wall * workers / row["kernel_sum_s"]
    row["cpu_over_kernels"] = cpu / row["kernel_sum_s"]
    return row


def identity(a: Path, b: Path) -> dict:
    """Case-by-case comparison of two folders of the sweep (reference/compare_sweeps.py)."""
    sys.path.insert(0, str(AFTER / "reference"))
    from compare_sweeps import compare_case

    stems = sorted({p.stem for p in (a / "cases").glob("*.json")}
                   | {p.stem for p in (b / "cases").glob("*.json")})
    differing = {s: d for s in stems if (d := compare_case(a, b, s))}
    return {"cases": len(stems), "identical": len(stems) - len(differing),
            "differing": {s: d[:5] for s, d in differing.items()}}


def summarize(rows: list) -> dict:
    """Medians over the repeats of the timings and ratios."""
    keys = ("wall_s", "cpu_s", "kernel_sum_s", "backend_sum_s", "wall_over_kernels",
            "cpu_over_kernels")
    return {k: float(np.median([r[k] for r in rows])) for k in keys}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="a copy of the old tree (git worktree of HEAD)")
    ap.add_argument("--quick", action="store_true",
                    help="the small grid (4 cases) at t = 400, one repeat")
    ap.add_argument("--repeats", type=int, default=None, help="default 1 (quick) or 2")
    ap.add_argument("--workers", type=int, nargs="+", default=[1],
                    help="sweep worker processes, one or more counts (default 1: wall time = "
                    "the cases' sum)")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--note", default="", help="stored with the results (what the trees are)")
    args = ap.parse_args(argv)
    trees = {"after": AFTER} if args.before is None else {"before": args.before, "after": AFTER}
    repeats = args.repeats or (1 if args.quick else 2)
    result = {"benchmark": f"{SWEEP} sweep on the fast backend: wall time and its kernels' "
                           "time",
              "trees": {k: str(v) for k, v in trees.items()}, "note": args.note,
              "quick": args.quick, "workers": args.workers, "repeats": repeats,
              "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
              "cpus_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
              else os.cpu_count(), "python": platform.python_version(),
              "load_at_start": list(os.getloadavg()), "busy_at_start": busy_processes(),
              "runs": {f"{k} W={w}": [] for w in args.workers for k in trees},
              "identity": []}
    for tree in trees.values():  # compile / load the kernel's variants outside the timings
        subprocess.run([sys.executable, "-c", "from mdgran.model.scene import load_scene;"
                        "from mdgran.simulation import run;"
                        "run(load_scene('micro-star', [('run.duration', 1.0)]), 'fast')"],
                       env=dict(os.environ, PYTHONPATH=str(tree)), check=True, cwd="/tmp")
    for rep in range(repeats):
        for workers in args.workers:
            with tempfile.TemporaryDirectory(prefix="sweep_wall-") as tmp:
                for k, tree in trees.items():
                    row = one_sweep(tree, workers, args.quick, Path(tmp) / k)
                    result["runs"][f"{k} W={workers}"].append(row)
                    print(f"{k:6s} W={workers}: {row['cases']} cases, wall {row['wall_s']:.1f} s "
                          f"(cpu {row['cpu_s']:.1f} s), kernels {row['kernel_sum_s']:.2f} s, "
                          f"backends {row['backend_sum_s']:.2f} s: wall x workers / kernels "
                          f"{row['wall_over_kernels']:.2f}, cpu / kernels "
                          f"{row['cpu_over_kernels']:.2f}; load {row['load_before'][0]:.2f} -> "
                          f"{row['load_after'][0]:.2f}, {len(row['busy_before'])} busy "
                          "processes", flush=True)
                if len(trees) == 2:
                    same = identity(Path(tmp) / "before", Path(tmp) / "after")
                    result["identity"].append({"repeat": rep, "workers": workers, **same})
                    print(f"identity W={workers}: {same['identical']} of {same['cases']} cases "
                          "identical", flush=True)
    result["median"] = {k: summarize(v) for k, v in result["runs"].items()}
    result["load_at_end"] = list(os.getloadavg())
    result["busy_at_end"] = busy_processes()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
