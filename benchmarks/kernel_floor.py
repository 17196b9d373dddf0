"""The compiled floor of the fast kernel: a hand-written C loop doing the per-step
work of :func:`mdgran.backends.fast_kernel.verlet_pass` (``benchmarks/c_floor/floor.c``),
built with the system C compiler, beside the numba kernel on the same states.

* **Same work.**  The C reads the state the fast backend starts from (after its initial settle
  and ``init_acc``): constants, the real spline coefficients of
  :class:`mdgran.model.contact.ContactTable`, ``x, v, a``, the contact states (:func:`dump_state`).
  ``check`` runs both for ``CHECK_STEPS`` steps on a 20-bead chain with a gentle impulse in
  the middle (no event, no flag: the C does not locate events) and reports the largest
  difference of ``x, v, a`` and ``D_viscous`` (0: the same operations in the same order).
* **Timing** (``ns per bead-step``): chains of micro-star's law (Schwarz table) and of
  macro-hertz (``delta^1.5``) at N = 1e4, 1e5, 1e6, from the paper's initial state (every
  contact closed at ``delta = 0``, impulse on bead 1); each repeat advances about
  ``BEAD_STEPS`` bead-steps, single thread.  C: one process, ``REPEATS`` repeats each from the
  previous one's end.  numba: ``FastBackend`` with one frame per repeat (the kernel call's wall
  time ``stats["kernel_s"]``, and the process CPU time over it, ``cpu``).  The machine may be
  shared: the CPU times, the load averages before and after, and min and median are recorded.
* The C is built ``-O2`` (baseline x86-64: SSE2, no FMA), ``-O2 -march=native
  -ffp-contract=off`` (the instructions numba uses, which compiles for the host CPU without
  contracting to FMA: the bitwise floor) and ``-O2 -march=native`` (FMA contraction: not
  bitwise; for reference).

Usage (the numba kernel is the mdgran imported: the working tree, or a worktree of HEAD
with ``PYTHONPATH``)::

    python benchmarks/kernel_floor.py --threads 1 2   # results/kernel_floor.json (~6 min)
    python benchmarks/kernel_floor.py --mixed    # results/kernel_floor_mixed.json
    PYTHONPATH=../mdgran-before python benchmarks/kernel_floor.py --out /tmp/head.json
    python benchmarks/kernel_floor.py --quick    # smoke run
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "c_floor" / "floor.c"
OUT = HERE / "results" / "kernel_floor.json"
OUT_MIXED = HERE / "results" / "kernel_floor_mixed.json"  # --mixed
BEAD_STEPS = 2e7  # per timed repeat
REPEATS = 7
SIZES = (10_000, 100_000, 1_000_000)
LAWS = {"table": "micro-star", "hertz": "macro-hertz"}
#: --mixed: micro-star's homogeneous chain beside two of unlike beads (as
#: benchmarks/mixed_cost.py: a dimer of diameter ratio 0.6, N + 1 beads so that big beads
#: touch both walls; every second bead of density 0.3), C and numba alike
MIXED = {"table": ("micro-star", lambda n: [("chain.n", n)]),
         "dimer": ("micro-star", lambda n: [("chain.n", n + 1), ("beads.pattern", "dimer"),
                                            ("beads.ratio", 0.6)]),
         "density": ("micro-star", lambda n: [("beads.density",
                                               [1.0, 0.3] * (n // 2) + [1.0] * (n % 2))])}
CHECK_STEPS = 1000
DT = 0.0025
#: build name -> cc flags
BUILDS = {"O2": ["-O2"], "O2-native-nofma": ["-O2", "-march=native", "-ffp-contract=off"],
          "O2-native": ["-O2", "-march=native"]}


def build(flags: list, folder: Path) -> Path:
    """The C floor compiled with ``cc`` and ``flags`` into ``folder``."""
    exe = folder / ("floor" + "".join(flags).replace("=", "_"))
    subprocess.run(["cc", *flags, "-Wall", "-o", str(exe), str(SOURCE), "-lm"], check=True)
    return exe


def steps_for(n: int, bead_steps: float) -> int:
    return int(np.clip(bead_steps // n, 10, 400000))


def backend(name: str, n: int, steps: int, frames: int, overrides=(), **options):
    """A FastBackend on scene ``name`` with ``n`` beads, ``steps`` steps per frame and
    ``frames`` frames after the first, one thread, and its frame generator advanced past
    frame 0."""
    from mdgran.backends.fast import FastBackend
    from mdgran.model.scene import SceneError, load_scene

    scene = load_scene(name, [("chain.n", n), ("run.dt", DT),
                              ("run.output_interval", steps * DT),
                              ("run.duration", frames * steps * DT), *overrides])
    try:
        b = FastBackend(scene, **{"threads": 1, **options})
    except SceneError:  # a backend without the threads option: one thread
        b = FastBackend(scene, **options)
    gen = b.frames()
    next(gen)
    return b, gen


def dump_state(b, path: Path) -> None:
    """The backend's current state and constants in the C floor's input format: int64
    ``n, m, walls, damped, k1_on, hertz, rows``; float64 ``h, gap, c, k1, delta_off,
    delta_max, mean_force_below, base, scale, last, step, power``; the table ``[rows, 4]``;
    ``x, v, a`` ``[n]``; ``closed`` ``[m]`` uint8; for unlike beads (flags.mixed) a trailer:
    int64 ``kinds, coefficients``, ``Mix.kind`` ``[m]`` uint32, ``Mix.pair``, ``Mix.coef``."""
    from mdgran.backends import fast_kernel as fk
    p, f, t = b.params, b.flags, b.params.table
    if f.exact or f.k3_on or not f.locate:
        raise ValueError("the C floor has the table or Hertz law, no k3, located events")
    now = b._current()
    coef = np.ascontiguousarray(t.coef, dtype=np.float64).reshape(-1, 4)
    ints = np.array([len(now.x), len(b.closed), f.walls, f.damped, f.k1_on, f.hertz,
                     coef.shape[0]], dtype=np.int64)
    dbl = np.array([b.dt, p.gap, p.damping, p.k1, p.delta_off, p.delta_max,
                    p.mean_force_below, t.base, t.scale, t.last, t.step,
                    float(b.counters["power"])], dtype=np.float64)
    with open(path, "wb") as fh:
        for arr in (ints, dbl, coef, now.x, now.v, now.a, b.closed.astype(np.uint8)):
            fh.write(np.ascontiguousarray(arr).tobytes())
        if f.mixed:
            mix = p.mix
            for arr in (np.array([len(mix.pair) // fk.NPAIR, len(mix.coef)], dtype=np.int64),
                        mix.kind.astype(np.uint32), mix.pair, mix.coef):
                fh.write(np.ascontiguousarray(arr).tobytes())


def run_c(exe: Path, state: Path, steps: int, repeats: int, out: Path | None = None) -> dict:
    args = [str(exe), str(state), str(steps), str(repeats)] + ([str(out)] if out else [])
    res = subprocess.run(args, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"{exe.name}: {res.stderr.strip()}")
    return json.loads(res.stdout)


def read_c_state(path: Path, n: int):
    raw = np.fromfile(path, dtype=np.float64)
    return raw[:n], raw[n:2 * n], raw[2 * n:3 * n], raw[3 * n], raw[3 * n + 1]


def check(exe: Path, tmp: Path, cases=None) -> dict:
    """C against numba: CHECK_STEPS steps of 20-bead chains with a gentle impulse on bead 10
    (no events, no flags); the largest differences of the end states.  ``cases``: law ->
    scene name, or (scene name, overrides of N) as MIXED's."""
    out = {}
    for law, name in (cases or LAWS).items():
        name, over = (name, lambda n: []) if isinstance(name, str) else name
        b, gen = backend(name, 20, CHECK_STEPS, 1,
                         [("impulse.bead", 10), ("impulse.velocity", 0.05), *over(20)])
        n = len(b._current().x)
        dump_state(b, tmp / "check.bin")
        c = run_c(exe, tmp / "check.bin", CHECK_STEPS, 1, tmp / "check.out")
        frame = next(gen)
        x, v, a, d_visc, power = read_c_state(tmp / "check.out", n)
        now = b._current()
        out[law] = {"steps": CHECK_STEPS, "events": len(frame.events),
                    "flagged_c": c["flagged"], "kicks_c": c["kicks"],
                    "max_abs_x": float(np.abs(x - frame.x).max()),
                    "max_abs_v": float(np.abs(v - frame.v).max()),
                    "max_abs_a": float(np.abs(a - now.a).max()),
                    "d_viscous": [float(d_visc), float(frame.dissipated_viscous)],
                    "bitwise": bool(np.array_equal(x, frame.x) and np.array_equal(v, frame.v)
                                    and np.array_equal(a, now.a)
                                    and d_visc == frame.dissipated_viscous),
                    "max_abs_x_moved": float(np.abs(frame.x).max())}
        print(f"check {law}: {json.dumps(out[law])}", flush=True)
    return out


def spread(values) -> dict:
    v = np.asarray(values, dtype=float)
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max()),
            "all": [round(float(x), 4) for x in v]}


def time_numba(b, gen, n: int, steps: int, repeats: int) -> dict:
    """ns per bead-step of ``repeats`` frames of the backend (warm-up frame first)."""
    next(gen)  # warm-up
    ns, cpu = [], []
    for _ in range(repeats):
        k0, c0 = b.stats["kernel_s"], time.process_time()
        next(gen)
        cpu.append((time.process_time() - c0) / (n * steps) * 1e9)
        ns.append((b.stats["kernel_s"] - k0) / (n * steps) * 1e9)
    return {"wall": spread(ns), "cpu": spread(cpu), "events": b.stats["events"]}


def c_floor(exes: dict, b, n: int, steps: int, repeats: int, tmp: Path) -> dict:
    """ns per bead-step of each C build from the backend's current state."""
    dump_state(b, tmp / "state.bin")
    out = {}
    for key, exe in exes.items():
        r = run_c(exe, tmp / "state.bin", steps, repeats)
        out[key] = {"wall": spread(r["wall_ns"]), "cpu": spread(r["cpu_ns"]),
                    "flagged": r["flagged"], "kicks": r["kicks"]}
    (tmp / "state.bin").unlink()
    return out


def busy_processes(threshold: float = 20.0) -> list:
    """Other processes above ``threshold`` % CPU (``ps``), as (pid, %cpu, command)."""
    res = subprocess.run(["ps", "-eo", "pid,pcpu,comm", "--no-headers"], capture_output=True,
                         text=True)
    rows = [line.split(None, 2) for line in res.stdout.splitlines()]
    return [(int(p), float(c), cmd) for p, c, cmd in rows
            if float(c) > threshold and int(p) != os.getpid()]


def measure(exes: dict, sizes, repeats: int, bead_steps: float, tmp: Path,
            threads=(1,), cases=None) -> dict:
    """Per law and N: the C builds (one thread) and the numba kernel on each thread count
    of ``threads`` (wall time of the kernel calls; ``cpu`` is the process's, all threads).
    ``cases`` as :func:`check`'s."""
    out = {}
    for law, name in (cases or LAWS).items():
        name, over = (name, lambda n: []) if isinstance(name, str) else name
        for n in sizes:
            steps = steps_for(n, bead_steps)
            load0, busy0 = os.getloadavg(), busy_processes()
            b, gen = backend(name, n, steps, repeats + 2, over(n))
            c = c_floor(exes, b, n, steps, repeats, tmp)
            del b, gen
            nb = {}
            for t in threads:
                b, gen = backend(name, n, steps, repeats + 2, over(n), threads=t)
                nb[str(t)] = time_numba(b, gen, n, steps, repeats)
                nb[str(t)]["threads_used"] = b.stats.get("threads", 1)
                del b, gen
            row = {"scene": name, "n": n, "steps_per_repeat": steps, "c": c, "numba": nb,
                   "loads": [load0, os.getloadavg()], "busy_at_start": busy0}
            out[f"{law} N={n}"] = row
            print(f"{law:5s} N={n:>7d}: C " + ", ".join(
                f"{k} {v['wall']['min']:.2f}/{v['wall']['median']:.2f}" for k, v in c.items())
                + " ns; numba " + ", ".join(
                    f"{t} thread(s) {v['wall']['min']:.2f}/{v['wall']['median']:.2f}"
                    for t, v in nb.items())
                + f" ns (wall min/median), load {load0[0]:.2f}, busy {busy0}", flush=True)
    return out


def mdgran_source() -> dict:
    """Which mdgran the numba kernel came from: its folder, git commit and whether
    mdgran/backends/fast_kernel.py differs from that commit."""
    import mdgran

    root = Path(mdgran.__file__).resolve().parent.parent

    def git(*a):
        return subprocess.run(["git", "-C", str(root), *a], capture_output=True,
                              text=True).stdout.strip()

    return {"path": str(root), "commit": git("rev-parse", "HEAD"),
            "fast_kernel_modified": bool(git("status", "--short",
                                             "mdgran/backends/fast_kernel.py"))}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, 3 repeats")
    ap.add_argument("--out", type=Path, default=None,
                    help="default results/kernel_floor.json, with --mixed kernel_floor_mixed.json")
    ap.add_argument("--threads", type=int, nargs="+", default=[1],
                    help="thread counts of the numba kernel (run.threads), e.g. 1 2")
    ap.add_argument("--sizes", type=int, nargs="+", default=None)
    ap.add_argument("--mixed", action="store_true",
                    help="micro-star beside a dimer and a two-density chain (MIXED)")
    args = ap.parse_args(argv)
    cases = MIXED if args.mixed else LAWS
    if args.out is None:
        args.out = OUT_MIXED if args.mixed else OUT
    sizes, repeats, bead_steps = ((10_000, 100_000), 3, 5e6) if args.quick else \
        (SIZES, REPEATS, BEAD_STEPS)
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        exes = {k: build(f, tmp) for k, f in BUILDS.items()}
        cc = subprocess.run(["cc", "--version"], capture_output=True, text=True).stdout
        result = {"benchmark": "kernel_floor", "quick": args.quick,
                  "machine": platform.machine(), "cpus": os.cpu_count(),
                  "cc": cc.splitlines()[0], "builds": {k: " ".join(v) for k, v in BUILDS.items()},
                  "python": sys.version.split()[0], "mdgran": mdgran_source(),
                  "load_at_start": os.getloadavg(),
                  "cases": {k: v if isinstance(v, str) else v[0] for k, v in cases.items()},
                  "check": check(exes["O2"], tmp, cases),
                  "busy_at_start": busy_processes(),
                  "ns_per_bead_step": measure(exes, args.sizes or sizes, repeats, bead_steps,
                                              tmp, args.threads, cases),
                  "load_at_end": os.getloadavg()}
    args.out.parent.mkdir(exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
