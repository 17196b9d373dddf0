"""Where a sweep case's time goes: the CPU time of the paper's sweep cases (``paper-robustness``
on the fast backend, micro-star to t = 400) in a sweep worker's steady state, split by part,
for one or two source trees ("the 91-case sweep takes what its kernels take").

Each tree runs in a fresh process (``PYTHONPATH`` = the tree): one warm-up case (imports, the
compiled kernel's loading; its CPU time is ``first_case_ms``), then cases 40-59, each through
the sweep worker's own call (``mdgran.studies.sweep._call_case``, so what a worker does between
cases is in it).  Times are CPU times (``time.process_time``: less sensitive to other processes than
wall times), in ms per case:

* ``kernel``: the compiled stepping loop (``kernel_s``, made a CPU time by pointing the fast
  backend's clock at ``process_time``);
* ``frames_outside_kernel``: the rest of the backend's frame loop, which includes the driver's
  and the reporters' per-frame work (the backend's ``wall_time_s`` minus ``kernel_s``);
* ``backend_init``, ``writer_init``, ``writer_close`` (the buffered frames' appends, flush,
  rename), ``memory_record``, ``summary`` (:func:`mdgran.studies.sweep.case_summary`), ``scene``
  (load_scene), ``json`` (the summary file), ``check_resources``;
* ``other``: the case's total minus all of the above.

Usage::

    python benchmarks/sweep_case_profile.py                 # results/sweep_case_profile.json
    python benchmarks/sweep_case_profile.py --before ../mdgran-before   # and an older tree beside

Writes benchmarks/results/sweep_case_profile.json (``--out`` to change).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
AFTER = HERE.parent
CASES = range(40, 60)
OUT = HERE / "results" / "sweep_case_profile.json"

CHILD = r'''
import collections, functools, json, os, shutil, sys, tempfile, time, types
import mdgran.studies.sweep as S, mdgran.simulation as sim, mdgran.output.reporters as R
import mdgran.backends.fast as F
F._time = types.SimpleNamespace(perf_counter=time.process_time)  # kernel_s as CPU time
acc = collections.Counter()
def wrap(obj, name, label):
    f = getattr(obj, name)
    @functools.wraps(f)
    def g(*a, **k):
        t = time.process_time()
        try:
            return f(*a, **k)
        finally:
            acc[label] += time.process_time() - t
    setattr(obj, name, g)
for obj, name, label in ((S, "load_scene", "scene"), (sim, "check_resources", "check_resources"),
                         (sim, "make_backend", "backend_init"),
                         (R.H5MDWriter, "__init__", "writer_init"),
                         (R.H5MDWriter, "close", "writer_close"),
                         (R.MemoryReporter, "record", "memory_record"),
                         (S, "case_summary", "summary"), (S, "_atomic_json", "json")):
    wrap(obj, name, label)
sw = S.load_sweep("paper-robustness")
out = tempfile.mkdtemp(prefix="case_profile-")
os.makedirs(out + "/cases")
args = lambda i: (sw["scene"], "fast", sw["cases"][i], out, False, None)
t0 = time.process_time()
S._call_case(S.run_case, args(0))
first = time.process_time() - t0
acc.clear()
cases = [int(c) for c in sys.argv[1:]]
t0 = time.process_time()
for i in cases:
    S._call_case(S.run_case, args(i))
total = time.process_time() - t0
import h5py
kernel = backend = 0.0
for i in cases:
    with h5py.File(f"{out}/cases/{i:04d}.h5", "r") as f:
        st = json.loads(f["parameters"].attrs["backend_stats"])
    kernel += st["kernel_s"]
    backend += st["wall_time_s"]
shutil.rmtree(out)
n = len(cases)
row = {"case_total": total, "kernel": kernel, "frames_outside_kernel": backend - kernel,
       **{k: acc[k] for k in ("backend_init", "writer_init", "writer_close", "memory_record",
                              "summary", "scene", "json", "check_resources")}}
row["other"] = total - sum(v for k, v in row.items() if k != "case_total")
print(json.dumps({"first_case_ms": 1000 * first,
                  "per_case_ms": {k: 1000 * v / n for k, v in row.items()}}))
'''


def profile(tree: Path) -> dict:
    """The CPU split of ``tree``'s sweep cases (a fresh process)."""
    res = subprocess.run([sys.executable, "-c", CHILD, *map(str, CASES)], cwd="/tmp",
                         env=dict(os.environ, PYTHONPATH=str(tree)), capture_output=True,
                         text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="a copy of the old tree")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", type=Path, default=OUT, help="write the result JSON here")
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    trees = {"after": AFTER} if args.before is None else {"before": args.before, "after": AFTER}
    result = {"benchmark": "paper-robustness sweep case on the fast backend: CPU ms per case by "
                           "part, in a worker's steady state (cases 40-59)",
              "trees": {k: str(v) for k, v in trees.items()}, "note": args.note,
              "python": platform.python_version(), "cpus": os.cpu_count(),
              "load_at_start": list(os.getloadavg()), "runs": {k: [] for k in trees}}
    for _ in range(args.repeats):
        for k, tree in trees.items():
            row = profile(tree)
            result["runs"][k].append(row)
            print(f"{k:6s} first case {row['first_case_ms']:.0f} ms; per case "
                  + ", ".join(f"{name} {ms:.1f}" for name, ms in row["per_case_ms"].items()),
                  flush=True)
    result["load_at_end"] = list(os.getloadavg())
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
