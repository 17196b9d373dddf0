"""Progress output: labelled bars for runs, "run k of N" for a series of runs (``mdgran
compare``), and the files through which sweep workers report their case's simulated time.

Two kinds of stream:

* a terminal (``stream.isatty()``): one line per run, redrawn in place with ``\\r`` at most every
  0.2 s; each redraw is padded with spaces over what the previous one left, and cut to the
  terminal's width (a wrapped line cannot be redrawn).  The run's last draw, when it ends, shows
  100 % (or how far it got, with the status word: ``failed``, ``interrupted``) and ends the line.
* anything else (a CI log, a file): sparse, whole lines: one when a run starts (or, for a single
  ``mdgran run``, once it has taken ``delay`` seconds), one at most every ``interval`` (15 s) in
  between, and one when it ends.

Time left.  A run's own estimate is ``elapsed (1 - f) / f`` with ``f`` the fraction of its
simulated time done (from where it started, for a resumed run).  A series' estimate for all
its runs (:class:`RunSeries`) is rate-based: every finished run gives a wall time per unit of
simulated time for its backend and kind (``refined`` apart from the others, which cost about the
same); each pending run is charged its duration times that rate (a refined run not yet timed:
twice its backend's other runs); the running run its projection ``elapsed / f``.  Runs of a
backend not timed yet are named instead of guessed (``+ 5 lammps runs``).
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time as _time
from pathlib import Path

from .storage import write_atomic

TTY_INTERVAL = 0.2  # s between redraws on a terminal
LOG_INTERVAL = 15.0  # s between lines elsewhere
BAR = 20  # characters of a bar


def is_tty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def fmt_seconds(s) -> str:
    """``7s``, ``3m05s``, ``1h02m``; ``?`` for an unknown (NaN or infinite) time."""
    if s is None or not math.isfinite(s):
        return "?"
    s = max(0.0, s)
    if s < 60:
        return f"{s:.0f}s" if s >= 9.5 else f"{s:.1f}s".replace(".0s", "s")
    m = int(round(s)) // 60
    if m < 60:
        return f"{m}m{int(round(s)) % 60:02d}s"
    return f"{m // 60}h{m % 60:02d}m"


def bar(frac: float, width: int = BAR) -> str:
    k = int(width * min(1.0, max(0.0, frac)))
    return "[" + "#" * k + "-" * (width - k) + "]"


class Terminal:
    """Lines on ``stream``: on a terminal :meth:`draw` redraws the current line in place
    (padded over the previous draw, cut to the width), elsewhere it writes a whole line."""

    def __init__(self, stream=None, tty: bool | None = None, width: int | None = None):
        self.stream = stream or sys.stderr
        self.tty = is_tty(self.stream) if tty is None else tty
        self.width = width
        self._open = 0  # visible length of the line being redrawn (tty), 0: none

    def columns(self) -> int:
        if self.width:
            return self.width
        try:
            return os.get_terminal_size(self.stream.fileno()).columns
        except (AttributeError, ValueError, OSError):
            return shutil.get_terminal_size().columns

    def draw(self, text: str, final: bool = False):
        if not self.tty:
            self.stream.write(text + "\n")
        else:
            text = text[: max(20, self.columns() - 1)]
            pad = " " * max(0, self._open - len(text))
            self.stream.write("\r" + text + pad + ("\n" if final else ""))
            self._open = 0 if final else len(text)
        self.stream.flush()

    def say(self, text: str):
        """A line of its own (it ends a line being redrawn first)."""
        self.end()
        self.stream.write(text + "\n")
        self.stream.flush()

    def end(self):
        """End the line being redrawn (tty), leaving it as drawn."""
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = 0


def status_word(status: str) -> str:
    return str(status).split(":", 1)[0].strip() or "ended"


class CompileNotice:
    """While active (a context manager), one line on ``stream`` (stderr) when numba starts to
    compile, for a cache miss only (loading a compiled variant from numba's disk cache is no
    compilation): a first run of a scene's terms otherwise sits silent for 15-25 s before its
    first frame.  Uses numba's event API (``numba:compile`` events)."""

    def __init__(self, label: str = "", stream=None):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.said = False
        self._listener = None

    def __enter__(self):
        from numba.core import event

        notice = self

        class Listener(event.Listener):
            def on_start(self, ev):
                notice.compiling()

            def on_end(self, ev):
                pass

        self._listener = Listener()
        event.register("numba:compile", self._listener)
        return self

    def compiling(self):
        if not self.said:
            self.said = True
            prefix = f"{self.label}: " if self.label else ""
            print(f"{prefix}compiling the code for this scene's terms (numba; once, about "
                  "15-25 s, then cached on disk)", file=self.stream, flush=True)

    def __exit__(self, *exc):
        from numba.core import event

        event.unregister("numba:compile", self._listener)
        return False


class ProgressReporter:
    """A labelled progress bar for one run (a reporter: ``report(frame, ledger)``,
    ``close(status)``).

    ``delay``: nothing is shown before the run has taken that long (a short run stays silent),
    0: a line at once (:meth:`start`).  ``interval``: seconds between draws (default 0.2 on a
    terminal, 15 elsewhere).  ``extra(final)``: text appended to every line (a series' time
    left); ``on_close(status, elapsed)`` is called before the last line is drawn.  Once shown,
    the run's last line says 100 % (or how far it got, and the status word)."""

    def __init__(self, t_end: float, label: str = "", delay: float = 2.0, stream=None,
                 interval: float | None = None, tty: bool | None = None, extra=None,
                 on_close=None, width: int | None = None):
        self.t_end = float(t_end)
        self.label = label
        self.delay = delay
        self.term = Terminal(stream, tty, width)
        self.stream = self.term.stream
        self.tty = self.term.tty
        self.interval = interval if interval is not None else (
            TTY_INTERVAL if self.tty else LOG_INTERVAL)
        self.extra = extra
        self.on_close = on_close
        self.start_time = _time.perf_counter()
        self.last = -math.inf
        self.shown = False
        self.closed = False
        self.t = None  # simulated time of the last frame
        self.t0 = None  # of the first (a resumed run starts past 0)
        self._fit, self._keep = 0, None  # how far a terminal line had to be shortened

    # ---- the numbers ------------------------------------------------------------------------
    def elapsed(self) -> float:
        return _time.perf_counter() - self.start_time

    def fraction(self) -> float:
        if self.t is None:
            return 0.0
        return min(1.0, self.t / self.t_end) if self.t_end > 0 else 1.0

    def projected_total(self) -> float:
        """This run's wall time projected from its progress so far (NaN before 2 %)."""
        if self.t is None or self.t0 is None or self.t_end <= self.t0:
            return math.nan
        f = (self.t - self.t0) / (self.t_end - self.t0)
        return self.elapsed() / f if f >= 0.02 else math.nan

    # ---- drawing ----------------------------------------------------------------------------
    def _text(self, status: str | None = None) -> str:
        el = self.elapsed()
        frac = self.fraction()
        if status is not None and status_word(status) in ("complete", "ledger-exceeded"):
            frac = 1.0
        t = self.t if self.t is not None else 0.0
        pct = "100%" if frac >= 1.0 else f"{int(100 * frac):3d}%"
        tpart = f"t = {t:.4g}/{self.t_end:.4g}"
        if status is None:
            left = f"left ~{fmt_seconds(self.projected_total() - el)}"
            when = ["starting"] if self.t is None else [f"{fmt_seconds(el)},", left]
        else:
            word = status_word(status)
            when = [f"done in {fmt_seconds(el)}" if word == "complete"
                    else f"{word} after {fmt_seconds(el)}"]
        more = self.extra(status is not None) if self.extra is not None else ""
        more_short = more.replace("all runs left", "all") if more else ""
        label = self.label

        def line(lab, width, tp, wh, mo):
            head = f"{lab}  " if lab else ""
            tail = "; " + mo if mo else ""
            return f"{head}{bar(frac, width)} {pct}  " + "  ".join(
                ([tp] if tp else []) + [" ".join(wh)]) + tail

        text = line(label, BAR, tpart, when, more)
        if not self.tty:
            return text
        # a terminal: the line must fit its width to be redrawn; give up, in this order, the
        # bar's length, t, the elapsed time, the long wording of the series' estimate, and
        # the end of the label (the role's details)
        # (the shape only ever gets shorter during a run: a line does not flicker between two)
        room = self.term.columns() - 1
        short_when = when[-1:]
        attempts = ((label, BAR, tpart, when, more), (label, 10, tpart, when, more),
                    (label, 10, "", when, more), (label, 10, "", short_when, more),
                    (label, 10, "", short_when, more_short))
        for k in range(self._fit, len(attempts)):
            text = line(*attempts[k])
            if len(text) <= room and self._keep is None:
                self._fit = k
                return text
        self._fit = len(attempts) - 1
        over = len(text) - room
        if label and len(label) > 18:
            keep = max(16, len(label) - over - 2)
            self._keep = keep if self._keep is None else min(self._keep, keep)
            text = line(label[: self._keep] + "..", 10, "", short_when, more_short)
        return text  # the terminal cuts what is still too long

    def _draw(self, status: str | None = None):
        self.term.draw(self._text(status), final=status is not None)
        self.last = _time.perf_counter()
        self.shown = True

    def start(self):
        """Draw the first line now (a run of a series: its role shows while it sets up)."""
        if self.delay <= 0 and not self.shown:
            self._draw()

    def report_block(self, block):
        """Show the time of the last frame of ``block`` (at most every ``interval``)."""
        self.t = float(block.time[-1])
        if self.t0 is None:
            self.t0 = float(block.time[0])
        now = _time.perf_counter()
        if now - self.start_time < self.delay:
            return
        if not self.shown or now - self.last >= self.interval:
            self._draw()

    def close(self, status):
        if self.closed:
            return
        self.closed = True
        if self.on_close is not None:
            self.on_close(status, self.elapsed())
        if self.shown:
            self._draw(status)


class RunSeries:
    """Progress of a planned series of runs: each run's line says ``run k of N`` and its role,
    and ends with the time left for the whole series (see the module docstring).

    ``plan``: ``{key: (backend, kind, label, duration)}`` in the order the runs will go;
    ``kind`` ``"refined"`` marks the runs that cost more.  :meth:`run` runs one of them."""

    def __init__(self, plan: dict, stream=None, interval: float | None = None,
                 tty: bool | None = None, width: int | None = None):
        self.plan = dict(plan)
        self.keys = list(self.plan)
        self.term = Terminal(stream, tty, width)
        self.interval, self.width = interval, width
        self.walls: dict = {}  # key -> wall seconds of the finished runs
        self.current = None  # (key, reporter)
        self.start_time = _time.perf_counter()

    def say(self, text: str):
        self.term.say(text)

    def _rate(self, backend: str, kind: str):
        """Wall seconds per simulated time unit of ``backend``'s runs of this cost class."""
        def rates(refined):
            out = [w / self.plan[k][3] for k, w in self.walls.items()
                   if self.plan[k][0] == backend and (self.plan[k][1] == "refined") == refined
                   and self.plan[k][3] > 0]
            if self.current is not None:
                ck, rep = self.current
                b, kd, _, dur = self.plan[ck]
                tot = rep.projected_total()
                if b == backend and (kd == "refined") == refined and dur > 0 and \
                        math.isfinite(tot):
                    out.append(tot / dur)
            return out

        same = rates(kind == "refined")
        if same:
            return sum(same) / len(same)
        other = rates(kind != "refined")
        if other:
            return sum(other) / len(other) * (2.0 if kind == "refined" else 0.5)
        return None

    def left(self) -> str:
        """Time left for the series: the current run's and the pending runs' estimates."""
        total, unknown = 0.0, {}
        if self.current is not None:
            key, rep = self.current
            tot = rep.projected_total()
            if rep.closed:
                tot = 0.0
            elif not math.isfinite(tot):
                r = self._rate(*self.plan[key][:2])
                tot = r * self.plan[key][3] if r is not None else math.nan
            if math.isfinite(tot):
                total += max(0.0, tot - rep.elapsed())
            else:
                unknown[self.plan[key][0]] = unknown.get(self.plan[key][0], 0) + 1
        started = set(self.walls) | ({self.current[0]} if self.current else set())
        for key in self.keys:
            if key in started:
                continue
            backend, kind, _, dur = self.plan[key]
            r = self._rate(backend, kind)
            if r is None:
                unknown[backend] = unknown.get(backend, 0) + 1
            else:
                total += r * dur
        if not unknown:
            return f"all runs left ~{fmt_seconds(total)}"
        if total <= 0:
            return "all runs left ~?"
        return f"all runs left ~{fmt_seconds(total)}" + "".join(
            f" + {n} {b} run{'s' if n > 1 else ''}" for b, n in unknown.items())

    def reporter(self, key) -> ProgressReporter:
        k = self.keys.index(key) + 1
        backend, kind, label, duration = self.plan[key]
        rep = ProgressReporter(duration, label=f"run {k} of {len(self.keys)}  {label}",
                               delay=0.0, stream=self.term.stream, interval=self.interval,
                               tty=self.term.tty, width=self.width,
                               extra=lambda final: self.left())
        rep.on_close = lambda status, el: self.walls.__setitem__(key, el)
        self.current = (key, rep)
        return rep

    def run(self, key, fn, *args, **kwargs):
        """``fn(*args, reporters=[its reporter], **kwargs)`` (:func:`mdgran.simulation.run`),
        the run's line ended however it ends."""
        rep = self.reporter(key)
        rep.start()
        try:
            return fn(*args, reporters=[rep], **kwargs)
        except BaseException as exc:
            rep.close("interrupted" if isinstance(exc, KeyboardInterrupt) else "failed")
            raise
        finally:
            if not rep.closed:  # run() raised before its frames (bad input)
                rep.close("failed")
            self.current = None

    def elapsed(self) -> float:
        return _time.perf_counter() - self.start_time


# ---- sweep workers: the simulated time of a running case, through a file -------------------
class ProgressFile:
    """A reporter that keeps ``path`` (a sweep's ``cases/NNNN.progress``) holding the run's
    simulated time as JSON ``{"t", "t_end", "wall", "pid"}``, rewritten atomically at most
    every ``every`` seconds (and at the first frame), and with ``"ended"`` (the status word)
    when the run ends; the sweep removes it when the case is recorded.  A file works
    on every executor (worker processes, MPI ranks): the sweep's folder is shared already."""

    def __init__(self, path, t_end: float, every: float = 2.0):
        self.path = Path(path)
        self.t_end = float(t_end)
        self.every = every
        self.start = _time.perf_counter()
        self.last = -math.inf
        self.t = 0.0
        self.ended = None

    def _write(self, **more):
        try:
            write_atomic(self.path, json.dumps({"t": self.t, "t_end": self.t_end, "wall":
                                                _time.perf_counter() - self.start,
                                                "pid": os.getpid(), **more}))
        except OSError:  # progress is not worth failing a case over
            pass

    def report_block(self, block):
        self.t = float(block.time[-1])
        now = _time.perf_counter()
        if now - self.last >= self.every:
            self.last = now
            self._write()

    def close(self, status):
        """The run's frames are done: the file says so (the case still writes its summary);
        the sweep's main process removes it once the case is recorded."""
        self._write(ended=status_word(status))


def read_progress(path) -> dict | None:
    """A :class:`ProgressFile`'s content, or None (missing, or being replaced)."""
    try:
        d = json.loads(Path(path).read_text())
        return d if isinstance(d, dict) else None
    except (OSError, ValueError, UnicodeDecodeError):
        return None


class SweepProgress:
    """The main process's progress lines of a sweep: cases done, the running cases' simulated
    times (read from their :class:`ProgressFile`), elapsed, time left.

    Time left: ``elapsed / d * (cases to run - d)``, ``d`` the cases done in this call plus the
    running cases' fractions (it assumes cases cost alike and the workers stay busy).  On a
    terminal one status line is redrawn in place (at most every ``interval``, default 1 s);
    elsewhere a line when a case ends and, between, at most every ``interval`` (default 15 s)
    of silence."""

    SHOW = 4  # running cases named on a line

    def __init__(self, name: str, total: int, done0: int, todo: int, cases_dir, stream=None,
                 interval: float | None = None, tty: bool | None = None,
                 width: int | None = None):
        self.name, self.total, self.done0, self.todo = name, total, done0, todo
        self.cases = Path(cases_dir)
        self.term = Terminal(stream, tty, width)
        self.interval = interval if interval is not None else (
            1.0 if self.term.tty else LOG_INTERVAL)
        self.start = _time.perf_counter()
        self.last = self.start
        self.count = 0
        self.finished: set = set()

    def _running(self, running):
        """``[(index, progress dict or None)]`` of the running cases: those given, else the
        cases with a progress file (an executor that does not say which run)."""
        if running is None:
            running = []
            for p in sorted(self.cases.glob("*.progress")):
                try:
                    running.append(int(p.stem))
                except ValueError:
                    continue
        return [(i, read_progress(self.cases / f"{i:04d}.progress"))
                for i in sorted(running) if i not in self.finished]

    def text(self, running=None, final: bool = False) -> str:
        el = _time.perf_counter() - self.start
        done = self.done0 + self.count
        head = f"sweep {self.name}: {done}/{self.total} cases done"
        if final:
            return head + f" in {fmt_seconds(el)}"
        run = self._running(running)
        fracs = [min(1.0, d["t"] / d["t_end"]) for _, d in run
                 if d and d.get("t_end", 0) > 0 and "t" in d]
        eff = self.count + sum(fracs)
        left = el / eff * (self.todo - eff) if eff >= 0.05 else math.nan
        head += f", elapsed {fmt_seconds(el)}, left ~{fmt_seconds(left)}"
        if run:
            def state(i, d):
                if not d or "t" not in d:
                    return f"case {i:04d} starting"
                if d.get("ended"):
                    word = "" if d["ended"] == "complete" else f"{d['ended']}, "
                    return f"case {i:04d} {word}summarising"
                return f"case {i:04d} at t = {d['t']:.4g}/{d['t_end']:.4g}"

            named = [state(i, d) for i, d in run[: self.SHOW]]
            more = f", +{len(run) - self.SHOW} more" if len(run) > self.SHOW else ""
            head += f"; {len(run)} running: {', '.join(named)}{more}"
        return head

    def case_done(self, case: dict, summary: dict, running=None):
        self.count += 1
        self.finished.add(case["index"])
        st = str(summary.get("status", ""))
        if st.startswith("failed"):
            self.term.say(f"sweep {self.name}: case {case['index']:04d} {st}")
        if self.term.tty:
            self.term.draw(self.text(running))
        else:
            self.term.draw(self.text(running) if self.count < self.todo else self.text(
                final=True))
        self.last = _time.perf_counter()

    def tick(self, running=None):
        now = _time.perf_counter()
        if now - self.last >= self.interval:
            self.term.draw(self.text(running))
            self.last = now

    def finish(self):
        if self.term.tty and self.count:
            self.term.draw(self.text(final=True), final=True)
        self.term.end()
