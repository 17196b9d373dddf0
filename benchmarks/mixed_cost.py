"""Cost per bead-step of the fast backend on a chain of unlike beads against the homogeneous one.

    python benchmarks/mixed_cost.py [--sizes 1e4,1e5,1e6] [--repeats 5] [--rounds 2]
                                    [--trees TREE1,TREE2] [--out FILE]

Cases (micro-star's physics, N + 1 beads so that a dimer touches both walls with large beads):

* ``homogeneous`` micro-star as it is (one law, unit masses: the kernel without ``Mix``);
* ``dimer``       ``beads.pattern = "dimer"``, ratio 0.6: two masses, three law classes (the
                  wall pairs and the unlike pair), each contact's law scaled (``flags.mixed``);
* ``density``     every second bead of density 0.3: unit diameters (one law class) but the
                  mixed kernel all the same (masses per bead).

Each (case, N) runs in a process of its own: set-up and one warm-up frame are not timed, then
``--repeats`` frames of the same number of steps are (the kernel's wall time per frame,
``stats["kernel_s"]``, over N x steps; and the process's CPU time per frame, ``cpu_*``, which
a loaded machine's descheduling does not count; a located event steps its window of beads
again, so the events and event sub-steps of the last run are recorded beside it).  The cases alternate, ``--rounds`` times, so that a
change in the machine's load reaches every case alike; medians and spreads (max - min) over
every timed frame of a case.  Load averages and the busy processes (ps) at the start are
recorded: the 2 cores may be shared.  Writes benchmarks/results/mixed_cost.json.

``--trees``: source trees of mdgran to compare (each case runs with ``PYTHONPATH`` set to each
in turn, alternating, in the same rounds); each row names its tree, and its ratio is to the
homogeneous chain of the same tree.  Each row also lists the kernel variant's flags.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
CASES = {"homogeneous": [], "dimer": [("beads.pattern", "dimer"), ("beads.ratio", 0.6)],
         "density": "density"}

CHILD = r"""
import json, sys, time
import numpy as np
from mdgran.backends.fast import FastBackend
from mdgran.model.scene import load_scene
n, repeats, bead_steps = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
overrides = json.loads(sys.argv[4])
threads = int(sys.argv[5])
if overrides == "density":
    overrides = [["beads.density", [1.0, 0.3] * (n // 2) + [1.0] * (n % 2)]]
dt = 0.0025
steps = int(np.clip(bead_steps // n, 20, 400000))
scene = load_scene("micro-star", [("chain.n", n), ("run.dt", dt),
                                  ("run.output_interval", steps * dt),
                                  ("run.duration", (repeats + 1) * steps * dt),
                                  ("run.threads", threads)]
                   + [tuple(o) for o in overrides])
b = FastBackend(scene)
frames = b.frames()
next(frames)
next(frames)  # warm-up frame
ns, cpu = [], []
for _ in range(repeats):
    k0 = b.stats["kernel_s"]
    c0 = time.process_time()
    next(frames)
    cpu.append((time.process_time() - c0) / (n * steps) * 1e9)
    ns.append((b.stats["kernel_s"] - k0) / (n * steps) * 1e9)
print(json.dumps({"ns": ns, "cpu": cpu, "steps": steps, "events": b.stats["events"],
                  "substeps": b.stats["event_substeps"], "mixed": bool(b.flags.mixed),
                  "flags": [k for k, v in b.flags._asdict().items() if v]}))
"""


def run_case(n: int, case: str, repeats: int, bead_steps: float, tree: str = "",
             threads: int = 1) -> dict:
    env = dict(os.environ, PYTHONPATH=tree) if tree else None
    # in the tree's folder: `python -c` looks in the working folder before PYTHONPATH
    res = subprocess.run([sys.executable, "-c", CHILD, str(n), str(repeats), str(bead_steps),
                          json.dumps(CASES[case]), str(threads)], capture_output=True,
                         text=True, env=env, cwd=tree or None)
    if res.returncode != 0:
        raise RuntimeError(f"{case} at N = {n} failed: {res.stderr.strip().splitlines()[-1:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def busy() -> list:
    out = subprocess.run(["ps", "-eo", "pcpu=,comm="], capture_output=True, text=True).stdout
    rows = [line.split(None, 1) for line in out.splitlines()]
    return [r for r in rows if len(r) == 2 and float(r[0]) > 10.0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e4,1e5,1e6")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--bead-steps", type=float, default=2e8)
    ap.add_argument("--out", default=str(HERE / "results" / "mixed_cost.json"))
    ap.add_argument("--trees", default="", help="comma-separated mdgran source trees to "
                    "compare (PYTHONPATH of each run); default: this interpreter's")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--threads", type=int, default=1, help="run.threads (default 1)")
    args = ap.parse_args(argv)
    trees = args.trees.split(",") if args.trees else [""]
    cases = args.cases.split(",")
    result = {"benchmark": __doc__.splitlines()[0], "machine": platform.machine(),
              "cpu_count": os.cpu_count(), "loadavg_before": os.getloadavg(),
              "busy_processes_before": busy(), "rows": []}
    result["trees"] = trees
    result["threads"] = args.threads
    for n in (int(float(s)) + 1 for s in args.sizes.split(",")):
        keys = [(tree, case) for case in cases for tree in trees]
        times = {key: [] for key in keys}
        cpu = {key: [] for key in keys}
        events = {}
        for _ in range(args.rounds):
            for tree, case in keys:
                out = run_case(n, case, args.repeats, args.bead_steps, tree, args.threads)
                times[tree, case] += out["ns"]
                cpu[tree, case] += out["cpu"]
                events[tree, case] = {k: out[k] for k in ("steps", "events", "substeps",
                                                          "flags")}
        for (tree, case), ns in times.items():
            base = float(np.median(times[tree, "homogeneous"]))
            v = np.asarray(ns)
            row = {"n": n, "case": case, **({"tree": tree} if tree else {}),
                   "ns_per_bead_step_median": float(np.median(v)),
                   "ns_per_bead_step_spread": float(v.max() - v.min()), "all": v.tolist(),
                   "ratio_to_homogeneous": float(np.median(v)) / base,
                   "loadavg": os.getloadavg(), **events[tree, case]}
            c = np.asarray(cpu[tree, case])
            row.update(cpu_ns_median=float(np.median(c)), cpu_ns_spread=float(c.max() - c.min()),
                       cpu_ratio=float(np.median(c)) / float(np.median(cpu[tree, "homogeneous"])),
                       cpu_all=c.tolist())
            result["rows"].append(row)
            print(json.dumps({k: row[k] for k in row if k not in ("all", "cpu_all")}),
                  flush=True)
    result["loadavg_after"] = os.getloadavg()
    Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
