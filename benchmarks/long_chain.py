"""Cost of a pulse in a long chain at rest: what the beads it reaches cost, against the chain.

    python benchmarks/long_chain.py                                  # the matrix below
    python benchmarks/long_chain.py --sizes 1e3,1e6 --velocities 12 --durations 100

Each point is micro-star's impulse (``impulse.velocity`` = v0 on bead 1) into a chain of N
beads to t = T on ``--backend`` (``fast``: the fast backend, one thread; ``native``:
``lammps:native``, one rank; ``native-2``: the same on 2 MPI ranks, CPU time rank 0's),
frames every ``--interval`` time units (the
energy ledger of each frame is computed; no output file, nothing kept in memory), in a
process of its own.  Reported per point: wall and CPU time of the whole ``run()`` (the
contact table and the first compilation excluded: each process first runs a small chain of
the same variant), the bead-steps taken against N x steps, the beads the activity front holds
at the end (the pulse's reach), peak RSS, and ``os.getloadavg()`` before and after (2 cores:
a load below ~0.5 before a point means an idle machine).

For each (v0, T), ``ratio_to_shortest_uncrossed``: the 1e6-bead chain's CPU time over that of
the shortest chain of the matrix whose last bead the front never reached (target: at most 2).
v0 = 1000 runs with ``fast:delta_max=1000`` (its first contacts go beyond the default table).
Writes benchmarks/results/long_chain.json (``--out``): each point measured replaces the
file's row of the same backend, N, v0 and T, the others stay (a file of the latest measure
of every point).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "results" / "long_chain.json"


def worker(n, velocity, duration, interval, report, backend="fast"):
    import resource

    from mdgran.model.scene import load_scene
    from mdgran.simulation import run

    def scene(n, duration):
        return load_scene("micro-star", [
            ("chain.n", n), ("impulse.velocity", velocity), ("run.duration", duration),
            ("run.output_interval", interval), ("output.bead_stride", 0)])

    # v0 = 1000 compresses the first contacts beyond the default table (delta_max = 100 p)
    delta_max = 1000.0 if abs(velocity) > 500 else 100.0
    # (the LAMMPS backend's table ends at 100 p: v0 = 1000 stops there, an error row)
    spec, options = (("fast", {"threads": 1, "delta_max": delta_max}) if backend == "fast"
                     else ("lammps:native", {}))
    run(scene(100, interval), spec, keep=False, **options)  # compile or load the variant
    w0, c0 = time.perf_counter(), time.process_time()
    res = run(scene(n, duration), spec, keep=False, **options)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    st = res.stats
    from mdgran.simulation import mpi_rank

    if mpi_rank() != 0:
        return
    Path(report).write_text(json.dumps({
        "status": res.status, "wall_s": wall, "cpu_s": cpu, "kernel_s": st.get("kernel_s"),
        "bead_steps": st["bead_steps"], "all_bead_steps": n * st["steps"],
        "front": st["front"], "events": st["events"],
        "max_ledger_error": res.max_ledger_error,
        "peak_rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}))


def measure(n, velocity, duration, interval, timeout, backend="fast"):
    row = {"backend": backend, "n": n, "velocity": velocity, "duration": duration,
           "interval": interval, "loadavg_before": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "report.json"
        cmd = [sys.executable, __file__, "--worker", str(n), "--velocity", str(velocity),
               "--duration", str(duration), "--interval", str(interval), "--report", str(report),
               "--backend", backend]
        if backend == "native-2":
            mpiexec = shutil.which("mpiexec") or str(Path(sys.executable).with_name("mpiexec"))
            cmd = [mpiexec, "-n", "2", *cmd]
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                                 env={**os.environ, "OMP_NUM_THREADS": "1"})
        except subprocess.TimeoutExpired:
            return {**row, "error": f"not finished in {timeout} s"}
        if res.returncode or not report.exists():
            return {**row, "error": (res.stderr or res.stdout)[-600:]}
        row.update(json.loads(report.read_text()))
    row["loadavg_after"] = os.getloadavg()
    return row


def merged(path, rows) -> list:
    """The rows of the file at ``path`` (a row without a backend is the fast backend's), each
    replaced by the row of ``rows`` of the same point, then the new points."""
    def key(r):
        return (r.get("backend", "fast"), r["n"], r["velocity"], r["duration"])

    try:
        old = json.loads(Path(path).read_text())["rows"]
    except (OSError, ValueError, KeyError):
        old = []
    new = {key(r): r for r in rows}
    kept = [{"backend": "fast", **r} if key(r) not in new else new.pop(key(r)) for r in old]
    return kept + list(new.values())


def ratios(rows):
    """The largest chain's CPU time over the shortest chain's whose end the front never
    reached, per (v0, T)."""
    out = []
    for key in sorted({(r.get("backend", "fast"), r["velocity"], r["duration"])
                       for r in rows}):
        done = sorted((r for r in rows if (r.get("backend", "fast"), r["velocity"],
                                           r["duration"]) == key
                       and "error" not in r), key=lambda r: r["n"])
        uncrossed = [r for r in done if r["front"] is not None and r["front"][1] < r["n"]]
        if len(done) < 2 or not uncrossed or uncrossed[0] is done[-1]:
            continue
        short, big = uncrossed[0], done[-1]
        out.append({"backend": key[0], "velocity": key[1], "duration": key[2], "n": big["n"],
                    "shortest_uncrossed_n": short["n"],
                    "ratio_to_shortest_uncrossed": big["cpu_s"] / short["cpu_s"]})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e3,1e4,1e5,1e6")
    ap.add_argument("--velocities", type=float, nargs="+", default=[12.0, 100.0, 1000.0])
    ap.add_argument("--durations", type=float, nargs="+", default=[100.0, 1000.0])
    ap.add_argument("--interval", type=float, default=10.0, help="time between frames")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per point")
    ap.add_argument("--backend", default="fast", choices=("fast", "native", "native-2"))
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--velocity", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--duration", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--report", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        return worker(args.worker, args.velocity, args.duration, args.interval, args.report,
                      args.backend)
    rows = []
    for duration in args.durations:
        for velocity in args.velocities:
            for n in (int(float(s)) for s in args.sizes.split(",")):
                row = measure(n, velocity, duration, args.interval, args.timeout,
                              args.backend)
                rows.append(row)
                print(json.dumps({k: v for k, v in row.items()
                                  if not k.startswith("loadavg")}), flush=True)
    rows = merged(args.out, rows)
    result = {"benchmark": __doc__.splitlines()[0], "scene": "micro-star",
              "machine": platform.processor() or platform.machine(),
              "rows": rows, "ratios": ratios(rows)}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
