"""Progress output: labelled bars for runs, "run k of N" for a series of runs (``mdgran
compare``), a sweep's line and the files through which its workers report their case's
simulated time.

The lines are ``tqdm`` bars (:class:`Line`): tqdm keeps the time, the estimate of the time
left, the throttling and, on a terminal (``stream.isatty()``), the redraw in place, padded over
the previous draw and cut to the terminal's width.  Anywhere else (a CI log, a file) the same
text is written as sparse whole lines, never carriage returns: one when a line starts (for a
single ``mdgran run``, once it has taken ``delay`` seconds), at most one every ``interval``
(15 s) in between, and one when it ends.  Times are tqdm's clock times, ``MM:SS`` or
``H:MM:SS`` (:func:`fmt_seconds`).

Time left.  A run's own estimate is tqdm's at its mean rate, ``elapsed (1 - f) / f`` with ``f``
the fraction of its simulated time done (from where it started, for a resumed run).  A
series' estimate for all its runs (:class:`RunSeries`) is rate-based: every finished run gives
a wall time per unit of simulated time for its backend and kind (``refined`` apart from the
others, which cost about the same); each pending run is charged its duration times that rate
(a refined run not yet timed: twice its backend's other runs); the running run its projection
``elapsed / f``.  Runs of a backend not timed yet are named instead of guessed
(``+ 5 lammps runs``).
"""
from __future__ import annotations

import json
import math
import os
import sys
import time as _time
from pathlib import Path

from tqdm import tqdm
from tqdm.utils import disp_len

from .storage import write_atomic

TTY_INTERVAL = 0.2  # s between redraws of a run's line on a terminal
LOG_INTERVAL = 15.0  # s between lines elsewhere
BAR, BAR_MIN = 20, 10  # characters of a bar; where a terminal is narrow


def is_tty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def fmt_seconds(s) -> str:
    """A duration in seconds as the bars show it (tqdm's ``MM:SS``, ``H:MM:SS``); ``?`` for an
    unknown (NaN or infinite) one."""
    if s is None or not math.isfinite(s):
        return "?"
    return tqdm.format_interval(max(0.0, s))


def status_word(status: str) -> str:
    return str(status).split(":", 1)[0].strip() or "ended"


def say(text: str, stream=None):
    """``text`` as a line of its own on ``stream`` (standard error); on a terminal a bar being
    redrawn there is cleared first and redrawn below it (``tqdm.write``)."""
    stream = stream if stream is not None else sys.stderr
    if is_tty(stream):
        tqdm.write(text, file=stream)
    else:
        print(text, file=stream, flush=True)


class Line(tqdm):
    """A tqdm bar counting to ``total`` on ``stream`` (standard error), laid out by
    :meth:`layout`, drawn at most every ``interval`` seconds (default ``tty_interval`` on a
    terminal, 15 elsewhere) and when it closes.  On a terminal tqdm redraws it in place, cut
    to ``width - 1`` columns (default: the terminal's, read at every draw); where the line is
    too long, its ``{bar}`` of ``BAR`` characters is shortened (to ``BAR_MIN``), then its
    ``short`` layout used, then the end of its label (the role's details) cut, and tqdm cuts
    what is still too long.  Elsewhere (``tty``: say which) each draw is a whole line.
    ``shown``: drawn at least once."""

    monitor_interval = 0  # no tqdm thread redrawing a stalled bar

    def __init__(self, total: float, stream=None, tty: bool | None = None,
                 width: int | None = None, interval: float | None = None,
                 tty_interval: float = TTY_INTERVAL, **kwargs):
        self.stream = stream if stream is not None else sys.stderr
        self.tty = is_tty(self.stream) if tty is None else tty
        self.shown = False
        self._short, self._keep = False, None  # how far a terminal line was shortened
        if interval is None:
            interval = tty_interval if self.tty else LOG_INTERVAL
        super().__init__(total=total, file=self.stream, mininterval=interval, miniters=0,
                         smoothing=0, ncols=width - 1 if width else None,
                         dynamic_ncols=self.tty and not width, **kwargs)

    def layout(self, short: bool = False) -> tuple:
        """``(bar_format, its fields beyond tqdm's)`` of the next draw; ``short``: for a
        terminal too narrow for the whole line."""
        return "{desc}: {percentage:3.0f}%|{bar}|", {}

    @property
    def format_dict(self):
        """tqdm's fields and :meth:`layout`'s, fitted to a terminal's width."""
        d = super().format_dict
        room = d["ncols"] if self.tty and (d["ncols"] or 0) > 0 else None  # a log's lines
        d["ncols"] = room  # are whole; so are those of a pseudo-terminal without a size
        for short in (self._short, True):  # (a line only gets shorter: no flicker)
            fmt, fields = self.layout(short)
            d.update(fields)
            rest = disp_len(self.format_meter(**{**d, "bar_format": fmt.replace("{bar}", ""),
                                                 "ncols": None}))
            if room is None or rest + BAR_MIN <= room:
                break
        self._short = short
        if room is not None and (rest + BAR_MIN > room or self._keep) and len(self.desc) > 18:
            keep = max(16, len(self.desc) - max(0, rest + BAR_MIN - room) - 2)
            self._keep = min(keep, self._keep or keep)
            d["prefix"] = self.desc[:self._keep] + ".."
        width = BAR if room is None else max(BAR_MIN, min(BAR, room - rest))
        d["bar_format"] = fmt.replace("{bar}", f"{{bar:{width}}}")
        return d

    def display(self, msg=None, pos=None):
        """Draw the line (tqdm's), or ``msg``; elsewhere than a terminal, as a whole line."""
        self.shown = self.shown or msg != ""
        if self.tty:
            if self.nrows is not None and self.nrows < 1:  # a pseudo-terminal without a size:
                self.nrows = None  # tqdm would draw nothing, taking it for 0 rows
            return super().display(msg, pos)
        if msg == "":  # tqdm clearing the line: nothing to clear in a log
            return False
        self.fp.write((self.__str__() if msg is None else msg) + "\n")
        self.fp.flush()
        return True

    def clear(self, nolock=False):
        """Clear a terminal's line (tqdm's); nothing elsewhere."""
        if self.tty:
            super().clear(nolock)

    def close(self):
        """The last draw (tqdm's); elsewhere than a terminal a whole line, if any was shown."""
        if self.tty or self.disable:
            return super().close()
        self.leave = False  # the last line, whole: tqdm's would end with a second newline
        super().close()
        if self.shown:
            self.display()

    def elapsed(self) -> float:
        """Wall seconds since the line was made."""
        return self._time() - self.start_t

    def move_to(self, n: float):
        """Set the count to ``n`` (a run's simulated time, a sweep's cases done), drawn if
        ``interval`` has passed since the last draw (tqdm's ``update``)."""
        self.update(n - self.n)


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
            say(f"{prefix}compiling the code for this scene's terms (numba; once, about "
                "15-25 s, then cached on disk)", self.stream)

    def __exit__(self, *exc):
        from numba.core import event

        event.unregister("numba:compile", self._listener)
        return False


class ProgressReporter(Line):
    """A labelled progress bar for one run (a reporter: ``report_block(block)``,
    ``close(status)``), counting its simulated time to ``t_end``.

    ``delay``: nothing is shown before the run has taken that long (a short run stays silent),
    0: a line at once.  ``interval``: seconds between draws (default 0.2 on a terminal, 15
    elsewhere).  ``extra(short)``: text added after the time left (a series' time left;
    ``short``: its short form, for a narrow terminal);
    ``on_close(status, elapsed)`` is called before the last line is drawn.  Once shown, the
    run's last line says 100 % (or how far it got, and the status word)."""

    def __init__(self, t_end: float, label: str = "", delay: float = 2.0, stream=None,
                 interval: float | None = None, tty: bool | None = None, extra=None,
                 on_close=None, width: int | None = None):
        self.extra, self.on_close = extra, on_close
        self.status = None  # the run's status, once closed
        self.started = False  # a frame seen
        super().__init__(float(t_end), stream, tty, width, interval, desc=label, delay=delay)

    def projected_total(self) -> float:
        """This run's wall time projected from its progress so far (NaN before 2 %)."""
        if not self.started or self.total <= self.initial:
            return math.nan
        f = (self.n - self.initial) / (self.total - self.initial)
        return self.elapsed() / f if f >= 0.02 else math.nan

    def layout(self, short: bool = False) -> tuple:
        """The line: label, percentage, bar, this run's time left (or ``starting``, or ``done
        in``/the status word and the time taken), ``extra()``, ``t`` and the time taken;
        ``short`` without ``t`` nor the time taken while running."""
        head = "{desc}: {percentage:3.0f}%|{bar}| "
        more = self.extra(short) if self.extra is not None else ""
        fields = {"more": f", {more}" if more else "", "t": "" if short else
                  "  t = {:.4g}/{:.4g}".format(self.n, self.total)}
        if self.status is not None:
            word = status_word(self.status)
            fields["end"] = "done in" if word == "complete" else f"{word} after"
            return head + "{end} {elapsed}{more}{t}", fields
        if not self.started:
            return head + "starting{more}", fields
        return head + "left ~{remaining}{more}" + ("" if short else "{t} in {elapsed}"), fields

    def report_block(self, block):
        """Show the time of the last frame of ``block`` (at most every ``interval``)."""
        if not self.started:  # a resumed run starts past 0: its rate counts from there
            self.started = True
            self.initial = float(block.time[0])
        self.move_to(min(float(block.time[-1]), self.total))

    def close(self, status=None):
        """End the line with the run's ``status`` (tqdm's own ``close()``: ``ended``)."""
        if self.status is not None or self.disable:
            return
        self.status = status if status is not None else "ended"
        if status_word(self.status) in ("complete", "ledger-exceeded"):
            self.n = self.total
        if self.on_close is not None:
            self.on_close(self.status, self.elapsed())
        super().close()


class RunSeries:
    """Progress of a planned series of runs: each run's line says ``run k of N`` and its role,
    and adds the time left for the whole series (see the module docstring).

    ``plan``: ``{key: (backend, kind, label, duration)}`` in the order the runs will go;
    ``kind`` ``"refined"`` marks the runs that cost more.  :meth:`run` runs one of them."""

    def __init__(self, plan: dict, stream=None, interval: float | None = None,
                 tty: bool | None = None, width: int | None = None):
        self.plan = dict(plan)
        self.keys = list(self.plan)
        self.stream = stream if stream is not None else sys.stderr
        self.tty, self.interval, self.width = tty, interval, width
        self.walls: dict = {}  # key -> wall seconds of the finished runs
        self.current = None  # (key, reporter)
        self.start_time = _time.perf_counter()

    def say(self, text: str):
        say(text, self.stream)

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

    def left(self, short: bool = False) -> str:
        """Time left for the series: the current run's and the pending runs' estimates
        (``all runs left ~...``; ``short``: ``all ~...``)."""
        total, unknown = 0.0, {}
        if self.current is not None:
            key, rep = self.current
            tot = rep.projected_total()
            if rep.status is not None:
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
        head = "all ~" if short else "all runs left ~"
        if not unknown:
            return head + fmt_seconds(total)
        if total <= 0:
            return head + "?"
        return head + fmt_seconds(total) + "".join(
            f" + {n} {b} run{'s' if n > 1 else ''}" for b, n in unknown.items())

    def reporter(self, key) -> ProgressReporter:
        """The line of run ``key``, drawn at once (its role shows while it sets up)."""
        k = self.keys.index(key) + 1
        backend, kind, label, duration = self.plan[key]
        self.current = None  # until its reporter exists (it draws at once)
        rep = ProgressReporter(duration, label=f"run {k} of {len(self.keys)}  {label}",
                               delay=0.0, stream=self.stream, interval=self.interval,
                               tty=self.tty, width=self.width, extra=self.left,
                               on_close=lambda status, el: self.walls.__setitem__(key, el))
        self.current = (key, rep)
        return rep

    def run(self, key, fn, *args, **kwargs):
        """``fn(*args, reporters=[its reporter], **kwargs)`` (:func:`mdgran.simulation.run`),
        the run's line ended however it ends."""
        rep = self.reporter(key)
        try:
            return fn(*args, reporters=[rep], **kwargs)
        except BaseException as exc:
            rep.close("interrupted" if isinstance(exc, KeyboardInterrupt) else "failed")
            raise
        finally:
            if rep.status is None:  # run() raised before its frames (bad input)
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


class SweepProgress(Line):
    """The main process's progress line of a sweep of ``todo`` cases to run (of ``total``,
    ``done0`` done before): cases done, elapsed, time left, and the running cases' simulated
    times (read from their :class:`ProgressFile`).

    It counts the cases done in this call plus the running cases' fractions, so the time left
    (tqdm's, at the mean rate) assumes cases cost alike and the workers stay busy.  On a
    terminal the line is redrawn in place at most every ``interval`` (default 1 s) and when a
    case ends; elsewhere a line when it starts, when a case ends and, between, at most every
    ``interval`` (default 15 s) of silence; closed, the cases done and the time taken."""

    SHOW = 4  # running cases named on a line

    def __init__(self, name: str, total: int, done0: int, todo: int, cases_dir, stream=None,
                 interval: float | None = None, tty: bool | None = None,
                 width: int | None = None):
        self.name, self.cases_total, self.done0 = name, total, done0
        self.cases = Path(cases_dir)
        self.count = 0
        self.finished: set = set()
        self.running_text = ""
        super().__init__(todo, stream, tty, width, interval, tty_interval=1.0)

    def layout(self, short: bool = False) -> tuple:
        """Cases done, elapsed, time left and the running cases; closed, the time taken."""
        head = "sweep {name}: {done}/{cases_total} cases done"
        tail = (" in {elapsed}" if self.disable
                else ", elapsed {elapsed}, left ~{remaining}{running}")
        return head + tail, {"name": self.name, "done": self.done0 + self.count,
                             "cases_total": self.cases_total, "running": self.running_text}

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

    def _look(self, running):
        """Read the running cases' progress: their text, and the count of cases done with
        their fractions."""
        run = self._running(running)
        fracs = [min(1.0, d["t"] / d["t_end"]) for _, d in run
                 if d and d.get("t_end", 0) > 0 and "t" in d]

        def state(i, d):
            if not d or "t" not in d:
                return f"case {i:04d} starting"
            if d.get("ended"):
                word = "" if d["ended"] == "complete" else f"{d['ended']}, "
                return f"case {i:04d} {word}summarising"
            return f"case {i:04d} at t = {d['t']:.4g}/{d['t_end']:.4g}"

        named = [state(i, d) for i, d in run[: self.SHOW]]
        more = f", +{len(run) - self.SHOW} more" if len(run) > self.SHOW else ""
        self.running_text = f"; {len(run)} running: {', '.join(named)}{more}" if run else ""
        return self.count + sum(fracs)

    def case_done(self, case: dict, summary: dict, running=None):
        """A case is recorded: the line now (after the last case, the closing one)."""
        self.count += 1
        self.finished.add(case["index"])
        st = str(summary.get("status", ""))
        if st.startswith("failed"):
            say(f"sweep {self.name}: case {case['index']:04d} {st}", self.stream)
        self.n = self._look(running)
        if self.count < self.total:
            self.refresh()
            self.last_print_n, self.last_print_t = self.n, self._time()  # the next tick waits

    def tick(self, running=None):
        """The line, if ``interval`` has passed since the last."""
        self.move_to(self._look(running))
