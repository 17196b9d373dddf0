"""Command line: ``mdgran scenes | info | run | compare | sweep | report`` (docs/cli.md).

Exit status: 0 success; 3 a comparison whose verdict fails; 2 bad input (one line on stderr naming the key and what is allowed,
no traceback, no output file); 1 a failure during a run (the output file is written first,
with every frame so far and its ``status`` attribute saying what failed), including a run
whose energy-ledger error exceeds its backend's declared bound (status ``ledger-exceeded: ...``,
one line on stderr; every frame is in the file) and a sweep with any case not complete.
Heavy imports are done inside the subcommands so that ``mdgran scenes`` starts fast.

``--out`` is checked before anything runs (:func:`~mdgran.output.storage.check_out_file`,
:func:`~mdgran.output.storage.check_out_dir`): a
file name for ``run`` (not empty, not a folder, not ending in ``/``: a trailing slash is refused,
not taken as a folder to put a file in; not the scene file itself; in a folder that exists or
can be created and is writable; short enough for the temporary ``NAME.tmp-PID`` and
``NAME.partial`` beside it), a folder for ``compare``, ``sweep`` and ``report`` (not an existing
file).  ``info --json`` prints values that are not finite (``contact_lambda`` of the JKR limit
is infinite) as ``null``: JSON has no Infinity or NaN.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys

from .output.storage import check_out_dir, check_out_file


class UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse prints usage + two lines)
        raise UsageError(message)


def _fail(message: str, status: int) -> int:
    print(f"mdgran: error: {message}", file=sys.stderr)
    return status


def _finite_or_none(obj):
    """``obj`` with every float that is not finite replaced by None (JSON null)."""
    import math

    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _load(args):
    from .model.scene import load_scene, parse_override

    overrides = [parse_override(s) for s in (args.set or [])]
    return load_scene(args.scene, overrides)


# ---- subcommands -----------------------------------------------------------------------
def cmd_scenes(args) -> int:
    from .model.scene import builtin_scenes, describe

    names = builtin_scenes()
    width = max(len(n) for n in names)
    for name in names:
        print(f"{name:<{width}}  {describe(name)}")
    return 0


def scene_info(scene) -> dict:
    """The derived values that ``mdgran info`` prints (nondimensional, plus SI scales)."""
    from .model.contact import lambda_from_fc, table_error

    law = scene.law
    info = {"scene": scene.name, **law.describe()}
    if law.kind == "schwarz":
        # the lambda that the law's fc stands for, under the scene's fc rule
        info["contact_lambda"] = lambda_from_fc(law.fc, law.fc_rule or "cos")
    info.update({
        "n": scene.chain.n, "boundary": scene.chain.boundary,
        "k1": scene.substrate.k1, "k3": scene.substrate.k3,
        "damping": scene.contact.damping, "impulse_velocity": scene.impulse.velocity,
        "impulse_energy": scene.impulse_energy,
    })
    if law.kind == "schwarz":
        info["table_error_2001"] = table_error(law, 2001)
    if scene.mixture is not None:  # unlike beads: the law above is the reference pair's
        info["mixture"] = scene.mixture.describe()
    sc = scene.scales
    if sc is not None:
        from .model.units import wire_tension

        info.update(sc.as_dict())
        info["k1_N_per_m"] = scene.substrate.k1 * sc.stiffness
        info["damping_Ns_per_m"] = scene.contact.damping * sc.damping
        info["impulse_velocity_m_per_s"] = scene.impulse.velocity * sc.velocity
        info["impulse_energy_J"] = scene.impulse_energy * sc.energy
        # paper Table II geometry: wire length L_s = 2.5 d
        info["wire_tension_N"] = wire_tension(info["k1_N_per_m"], 2.5 * sc.diameter)
    return info


def cmd_info(args) -> int:
    scene = _load(args)
    info = scene_info(scene)
    if args.json:
        print(json.dumps(_finite_or_none(info), indent=2, default=float, allow_nan=False))
        return 0
    for k, v in info.items():
        if isinstance(v, float):
            v = f"{v:.6g}"
        print(f"{k:<28} {v}")
    return 0


def exit_status(exc: KeyboardInterrupt) -> int:
    """128 + the signal's number: 130 for Ctrl-C (SIGINT), 143 for SIGTERM."""
    import signal

    return 128 + getattr(exc, "signum", signal.SIGINT)


def interrupted_line(exc: KeyboardInterrupt, out: str) -> str:
    """What an interrupted ``run`` kept, and how to go on."""
    from .output.checkpoint import has_checkpoint
    from .simulation import partial_path

    name = getattr(exc, "signum", None)
    name = "SIGINT" if name is None else str(exc)
    if getattr(exc, "finished", None) is not None:
        return (f"interrupted ({name}) as the run ended, after {out} was written whole "
                f"(status: {exc.finished})")
    partial = partial_path(out)
    if partial.exists() and has_checkpoint(partial):
        return (f"interrupted ({name}); {partial} holds a checkpoint: run the same command "
                "with --resume to continue")
    return (f"interrupted ({name}); nothing was kept under {out} (no checkpoint: "
            "--checkpoint 0, a backend that cannot checkpoint, or none written yet)")


def _events_in(path, default):
    """The number of events the finished file ``path`` holds (all of them, also those before
    a resume, which the backend's counter does not see); ``default`` if it cannot be read."""
    try:
        import h5py

        with h5py.File(path, "r") as f:
            return int(f["events/time"].shape[0])
    except Exception:  # noqa: BLE001 - the summary line falls back to the backend's count
        return default


def cmd_run(args) -> int:
    from .backends.base import IntegrationError
    from .simulation import LEDGER_EXCEEDED, run
    from .output.storage import StorageError

    check_out_file(args.out, args.scene)
    if not math.isfinite(args.checkpoint) or args.checkpoint < 0:
        raise UsageError(f"--checkpoint: must be a number of seconds >= 0 (0: no checkpoints), "
                         f"not {args.checkpoint}")
    scene = _load(args)
    small = int(scene.chain.n) <= 10_000  # keep frames in memory for the budget
    try:
        res = run(scene, args.backend, out=args.out, progress=not args.quiet,
                  **{k: v for k, v in (("contact", args.contact), ("events", args.events)) if v},
                  keep=small and not args.quiet,
                  raise_errors=False, resume=args.resume,
                  checkpoint_every=args.checkpoint if args.checkpoint > 0 else None)
    except IntegrationError as exc:  # pragma: no cover - run() reports via status
        return _fail(str(exc), 1)
    except StorageError as exc:
        return _fail(str(exc), 1)
    except KeyboardInterrupt as exc:
        return _fail(interrupted_line(exc, args.out), exit_status(exc))
    if res.error is not None:
        return _fail(f"run failed ({args.out} holds the frames so far): {res.error}", 1)
    from .simulation import mpi_rank

    if not args.quiet and mpi_rank() == 0:
        st = res.stats
        print(f"{scene.name} [{args.backend}] -> {args.out}: t = {scene.run.duration}, "
              f"{_events_in(args.out, st.get('events', '?'))} events, "
              f"wall {st.get('wall_time_s', float('nan')):.2f} s, "
              f"ledger error {res.max_ledger_error:.2e} of E_imp (bound {res.ledger_bound:.2e})")
        if st.get("bead_steps") is not None and st.get("steps"):
            full = scene.chain.n * st["steps"]
            front = st.get("front")
            reach = f", beads {front[0]}-{front[1]} in motion" if front else ""
            print(f"bead-steps taken: {st['bead_steps']:.3g} of {full:.3g} "
                  f"({st['bead_steps'] / full:.3g}; beads at rest are not stepped){reach}")
        if res.trajectory is not None:
            from .budget import format_budget, term_budget

            print("term budget (which force terms this scene needs):")
            print(format_budget(term_budget(res.trajectory)))
    if res.status.startswith(LEDGER_EXCEEDED):
        return _fail(f"{res.status}; {args.out} holds every frame and says so in "
                     "/parameters@status", 1)
    return 0


def cmd_compare(args) -> int:
    from .crosscheck.compare import compare

    check_out_dir(args.out)
    scene = _load(args)
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    if len(backends) < 2:
        raise UsageError("--backends: give at least two, e.g. reference,lammps")
    if args.ensemble < 0:
        raise UsageError(f"--ensemble: must be 0 or more, not {args.ensemble}")
    report = compare(scene, backends, out_dir=args.out, progress=not args.quiet,
                     ensemble=args.ensemble)
    n_pass = sum(c["passed"] for c in report["criteria"])
    print(f"{scene.name}: {'PASS' if report['passed'] else 'FAIL'} ({n_pass} of "
          f"{len(report['criteria'])} criteria); report in {args.out}/report.md")
    for c in report["criteria"]:
        if not c["passed"]:
            print(f"  FAIL {c['name']}: measured {c['measured']:.3g}, threshold "
                  f"{c['threshold']:.3g} ({c['detail']})")
    return 0 if report["passed"] else 3


def cmd_sweep(args) -> int:
    from .model.scene import parse_override
    from .studies.sweep import run_sweep, sweep_summary

    if args.workers < 1:
        raise UsageError(f"--workers: must be an integer >= 1, not {args.workers}")
    check_out_dir(args.out)
    overrides = [parse_override(s) for s in (args.set or [])]
    res = run_sweep(args.sweep, args.out, workers=args.workers, executor=args.executor,
                    overrides=overrides, progress=not args.quiet, small=args.small,
                    backend=args.backend)
    summ = sweep_summary(res)
    bad = summ["ledger_exceeded"] + summ["failed"]
    print(f"{args.sweep}: {summ['complete']} of {summ['cases']} cases complete in {args.out}"
          + (f"; {len(summ['ledger_exceeded'])} exceeded their ledger bound, "
             f"{len(summ['failed'])} failed" if bad else ""))
    for r in bad:
        print(f"  case {r['index']:04d} {r['params']}: {r['status']}")
    return 1 if bad else 0


def cmd_report(args) -> int:
    from pathlib import Path

    from .studies.paper_study import make_report

    if args.workers < 1:
        raise UsageError(f"--workers: must be an integer >= 1, not {args.workers}")
    check_out_dir(args.dir, "DIR")
    if args.sweep_dir is not None and not (Path(args.sweep_dir) / "sweep.json").exists():
        raise UsageError(f"--sweep-dir: {args.sweep_dir} holds no sweep.json (a folder written "
                         "by mdgran sweep)")
    from .studies.paper_study import BEYOND, BEYOND_STUDIES

    known = (*BEYOND, *BEYOND_STUDIES)
    beyond = [b.strip() for b in (args.beyond or "").split(",") if b.strip()]
    if args.beyond == "all":
        beyond = list(known)
    bad = [b for b in beyond if b not in known]
    if bad:
        raise UsageError(f"--beyond: {bad[0]!r} is not one of {', '.join(known)} (or all)")
    make_report(args.dir, small=args.small, workers=args.workers, backend=args.backend,
                sweep_dir=args.sweep_dir, progress=not args.quiet, beyond=beyond)
    print(f"report in {args.dir}/report.md")
    return 0


# ---- parser ----------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    p = _Parser(prog="mdgran", description="Adhesive micro-granular chain simulations.")
    p.add_argument("--version", action="version", version=f"mdgran {__version__}")
    sub = p.add_subparsers(dest="command", parser_class=_Parser)
    sub.required = True

    s = sub.add_parser("scenes", help="list built-in scenes")
    s.set_defaults(func=cmd_scenes)

    def scene_args(sp):
        sp.add_argument("scene", help="built-in scene name or path to a TOML file")
        sp.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="override a scene key, e.g. contact.lambda=1.5 (repeatable)")

    s = sub.add_parser("info", help="derived scales and contact-law values")
    scene_args(s)
    s.add_argument("--json", action="store_true", help="one JSON object")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("run", help="run a scene on one backend, write H5MD")
    scene_args(s)
    s.add_argument("--backend", default="reference",
                   help="reference | lammps | fast, optionally with options: lammps:native, "
                   "fast:quantized, fast:dt=0.005 (see docs/backends.md)")
    s.add_argument("--contact", choices=("hook", "native"), default=None,
                   help="lammps: the contact as the Python hook (default) or the native C++ "
                   "plugin (same as --backend lammps:native)")
    s.add_argument("--events", choices=("located", "quantized"), default=None,
                   help="lammps native contact: snap events located inside the step (second "
                   "order) or switched at step ends (first order, plain MD)")
    s.add_argument("--out", required=True, help="output file (.h5; not a folder: a name "
                   "ending in / is refused)")
    s.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    s.add_argument("--checkpoint", type=float, default=60.0, metavar="SECONDS",
                   help="checkpoint every SECONDS of wall time into OUT.partial (0: off; "
                        "default 60); a killed run resumes with --resume")
    s.add_argument("--resume", action="store_true",
                   help="continue from OUT.partial's last checkpoint if there is one")
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("compare", help="run backends side by side, write a report (exit 3 if "
                       "any criterion fails)")
    scene_args(s)
    s.add_argument("--out", required=True, help="report folder")
    s.add_argument("--backends", default="reference,lammps,lammps:native",
                   help="comma-separated backend specs, the first is the reference (default "
                   "reference,lammps,lammps:native: the reference, the LAMMPS hook and the "
                   "native contact with located events; see docs/backends.md)")
    s.add_argument("--ensemble", type=int, default=3,
                   help="extra runs per backend with the impulse changed by k x 1e-3, for the "
                   "cluster statistics past the horizon (default 3)")
    s.add_argument("--quiet", action="store_true", help="no progress bars")
    s.set_defaults(func=cmd_compare)

    s = sub.add_parser("sweep", help="parametric study, parallel and resumable")
    s.add_argument("sweep", help="built-in sweep name or path to a sweep TOML file")
    s.add_argument("--out", required=True, help="results folder (resumes what is there)")
    s.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="parallel processes (default: all cores)")
    s.add_argument("--executor", default="process", help="process (default) | mpi")
    s.add_argument("--small", action="store_true", help="the sweep's small (CI) version")
    s.add_argument("--backend", default=None,
                   help="backend of every case (default: the sweep file's, usually reference)")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scene key in every case")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=cmd_sweep)

    s = sub.add_parser("report", help="the paper's study: runs what DIR lacks, then every "
                       "figure and report.md")
    s.add_argument("dir", help="report folder (runs/, sweep/, figures/ are reused if there)")
    s.add_argument("--small", action="store_true", help="the sweep's small (CI) version")
    s.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="parallel processes for the sweep (default: all cores)")
    s.add_argument("--backend", default="reference", help="backend of the runs")
    s.add_argument("--sweep-dir", default=None,
                   help="use this finished mdgran sweep folder instead of DIR/sweep")
    s.add_argument("--beyond", default=None, metavar="SWEEPS",
                   help="also run and analyse these studies beyond the paper: comma-separated "
                   "from chain-100, chain-1000, lambda-range, long-chain (the primary pulse "
                   "in chains of up to 1e5 beads, fast backend), or all")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=cmd_report)
    return p


#: library parameter -> the command-line flag or argument that sets it (errors name what the
#: user typed)
FLAGS = {"scene": "SCENE", "out": "--out", "out_dir": "--out", "resume": "--resume",
         "backend": "--backend", "checkpoint_every": "--checkpoint", "contact": "--contact",
         "events": "--events", "executor": "--executor", "workers": "--workers"}
#: how the library's messages point at a parameter in their text -> the flag
FLAG_TEXT = {"(resume=True)": "(--resume)", "(out)": "(--out)"}


def flag_message(exc) -> str:
    """A SceneError's line with the library's parameter names replaced by the flags: its key,
    and the parameters its text points at (:data:`FLAG_TEXT`)."""
    flag = FLAGS.get(getattr(exc, "key", None))
    text = str(exc)
    if flag is not None:
        text = flag + text[len(exc.key):]
    for name, shown in FLAG_TEXT.items():
        text = text.replace(name, shown)
    return text


def main(argv=None) -> int:
    from .backends.base import IntegrationError
    from .model.scene import SceneError
    from .simulation import BackendUnavailable

    from .signals import terminate_as_interrupt

    terminate_as_interrupt()  # SIGTERM (a scheduler's time limit) ends a run like Ctrl-C
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except UsageError as exc:
        return _fail(str(exc), 2)
    except SceneError as exc:
        return _fail(flag_message(exc), 2)
    except BackendUnavailable as exc:
        return _fail(str(exc), 2)
    except IntegrationError as exc:  # a run failed (mdgran compare: after its report)
        return _fail(str(exc), 1)
    except KeyboardInterrupt as exc:
        return _fail(f"interrupted ({exc or 'SIGINT'})", exit_status(exc))
    except BrokenPipeError:  # output piped into head & co.
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
