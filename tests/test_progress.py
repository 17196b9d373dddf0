"""Progress output: every run's line ends at 100 % or at its status, a redrawn line
leaves nothing of the previous one, compare lines say their role and "run k of N", and a sweep
names its running cases with their simulated time while they run."""
import io
import re
from dataclasses import dataclass

import pytest

from mdgran.output.progress import CompileNotice, ProgressReporter, RunSeries, fmt_seconds, is_tty
from mdgran.model.scene import load_scene
from mdgran.simulation import run


class FakeTTY(io.StringIO):
    def isatty(self):
        return True


@dataclass
class Frames:
    """A block of one frame at ``t``, as the driver hands progress reporters."""
    t: float

    @property
    def time(self):
        return [self.t]


def screen(text: str) -> list:
    """What a terminal shows: ``\\r`` returns to column 0 and overwrites, ``\\n`` ends the
    line.  Also checks every draw: right after it, the visible line is exactly what was drawn
    (nothing left over from a longer line before it)."""
    lines = []
    for physical in text.split("\n"):
        cur: list = []
        for seg in physical.split("\r"):
            cur[: len(seg)] = list(seg)
            if seg:
                visible = "".join(cur).rstrip()
                assert visible == seg.rstrip(), f"leftovers: {visible!r} after drawing {seg!r}"
        lines.append("".join(cur).rstrip())
    return [ln for ln in lines if ln]


def test_screen_emulation_catches_leftovers():
    with pytest.raises(AssertionError, match="leftovers"):
        screen("\rleft ~10s0s\rleft ~0s")
    assert screen("\rabc   \rab    \n") == ["ab"]


def test_fmt_seconds():
    assert [fmt_seconds(s) for s in (0.04, 3.0, 42.4, 185, 3725)] == \
        ["00:00", "00:03", "00:42", "03:05", "1:02:05"]
    assert fmt_seconds(float("nan")) == "?"


def test_reporter_ends_at_100_percent_and_pads_over_longer_lines():
    """A line drawn just before the end (here: at 17 %) is not the last word: close() draws
    100 %; a shorter line after a longer one is padded over it."""
    out = FakeTTY()
    rep = ProgressReporter(400.0, label="micro-star [reference]", delay=0.0, stream=out,
                           interval=0.0, width=200)
    rep.report_block(Frames(0.0))
    rep.set_description_str("micro-star [reference] with a much longer label for one draw")
    rep.report_block(Frames(68.0))
    rep.set_description_str("micro-star [reference]")
    rep.report_block(Frames(69.0))
    rep.mininterval = 1e9  # no redraw between here and the end: the bar would stay at 17 %
    rep.report_block(Frames(400.0))
    rep.close("complete")
    shown = screen(out.getvalue())
    assert len(shown) == 1 and out.getvalue().endswith("\n")
    assert "100%" in shown[0] and "done in" in shown[0] and "t = 400/400" in shown[0]


@pytest.mark.parametrize("tty", [False, True])
def test_run_progress_ends_with_100_percent_or_the_status(tty, interrupt_at):
    sc = load_scene("micro-star", [("run.duration", 20.0)])
    out = FakeTTY() if tty else io.StringIO()
    rep = ProgressReporter(20.0, label="micro-star [reference]", delay=0.0, stream=out,
                           interval=0.01 if tty else 0.3, width=120)
    run(sc, "reference", reporters=[rep])
    lines = screen(out.getvalue())
    assert lines[-1].startswith("micro-star [reference]") and "100%" in lines[-1]
    assert "done in" in lines[-1]
    if tty:
        assert len(lines) == 1  # one line, redrawn in place
    else:  # sparse: a line at the start, one at the end, at most one per 0.3 s between
        assert lines[0].endswith("starting") and len(lines) <= 2 + rep.elapsed() / 0.3 + 1
    # an interrupted run: its line stops where it stopped, with the status word
    out2 = FakeTTY() if tty else io.StringIO()
    rep = ProgressReporter(20.0, label="micro-star [reference]", delay=0.0, stream=out2,
                           interval=0.0, width=120)
    with pytest.raises(KeyboardInterrupt):
        run(sc, "reference", reporters=[rep, interrupt_at(5.0)])
    last = screen(out2.getvalue())[-1]
    assert "interrupted after" in last and "100%" not in last
    assert re.search(r"\b(2[0-9])%", last)  # stopped at t ~ 5 of 20


def test_narrow_terminal_lines_fit_and_keep_their_role():
    out = FakeTTY()
    series = RunSeries({("reference", "nominal"): ("reference", "nominal",
                                                     "reference ensemble 3 of 3 (excitation +0.3%)",
                                                     10.0)}, stream=out, interval=0.0,
                       width=72)
    rep = series.reporter(("reference", "nominal"))
    for t in (0.0, 1.0, 5.0, 10.0):
        rep.report_block(Frames(t))
    rep.close("complete")
    lines = screen(out.getvalue())
    assert len(lines) == 1 and len(lines[0]) <= 71
    assert lines[0].startswith("run 1 of 1  reference ens") and "100%" in lines[0]
    assert is_tty(io.StringIO()) is False


@pytest.mark.parametrize("tty", [False, True])
def test_compare_lines_are_labelled_and_counted(tty, monkeypatch):
    from mdgran.crosscheck.compare import compare

    monkeypatch.setenv("COLUMNS", "200")
    out = FakeTTY() if tty else io.StringIO()
    sc = load_scene("micro-star", [("run.duration", 10.0)])
    compare(sc, ("reference", "fast"), progress=True, ensemble=0, stream=out,
            progress_interval=0.02 if tty else 1.0)
    lines = screen(out.getvalue())
    roles = ["reference (as given)", "reference refined (tol/100)", "fast (as given)",
             "fast refined (dt/2)", "reference perturbed"]
    assert lines[0].startswith("compare micro-star: 5 runs")
    assert lines[-1].startswith("compare micro-star: 5 runs done")
    for k, role in enumerate(roles, 1):
        mine = [ln for ln in lines if ln.startswith(f"run {k} of 5  {role}")]
        assert mine, (role, lines)
        assert "100%" in mine[-1] and "done in" in mine[-1] and "all runs left" in mine[-1]
        assert len(mine) == (1 if tty else len(mine))
    last_run = [ln for ln in lines if ln.startswith("run 5 of 5")][-1]
    assert "all runs left ~00:00" in last_run


def test_sweep_names_running_cases_while_they_run(tmp_path):
    from mdgran.studies.sweep import run_sweep

    spec = tmp_path / "slow.toml"
    spec.write_text('[sweep]\nscene = "micro-star"\nbackend = "reference"\n\n[fixed]\n'
                    '"run.duration" = 200.0\n\n[grid]\n"impulse.velocity" = [1.0, 2.0]\n')
    out = io.StringIO()
    res = run_sweep(str(spec), tmp_path / "sw", workers=2, stream=out, progress_interval=0.3)
    assert [r["status"] for r in res] == ["complete", "complete"]
    lines = out.getvalue().splitlines()
    # a case at its time, wherever it stands in the list (the other may be summarising); the
    # cases run ~1 s each (t = 40 took 0.5 s, so ticks 0.3 s apart could miss them running)
    running = [ln for ln in lines if re.search(r"running: .*case 000[01] at t = [0-9.]+/200", ln)]
    assert running, lines
    assert re.match(r"sweep slow: 0/2 cases done, elapsed \S+, left ~\S+; [12] running",
                    running[0])
    assert lines[-1].startswith("sweep slow: 2/2 cases done in ")
    assert not list((tmp_path / "sw" / "cases").glob("*.progress"))


CACHED_MODULE = """
from numba import njit

@njit(cache=True)
def twice(x):
    return 2 * x
"""

NOTICE_CHILD = """
import io, sys
sys.path.insert(0, sys.argv[1])
from mdgran.output.progress import CompileNotice
import cached_twice
out = io.StringIO()
with CompileNotice("scene [fast]", stream=out):
    cached_twice.twice(3)
print(repr(out.getvalue()))
"""


def test_compile_notice_speaks_once_when_numba_compiles_and_not_on_a_cache_load(tmp_path):
    """The line a first run shows while numba compiles: once for nested compilations, not for
    functions compiled already, not once the notice is closed, and not when the compiled code
    comes from numba's disk cache (a second process)."""
    import os
    import subprocess
    import sys

    from numba import njit

    @njit
    def inner(x):
        return x + 1

    @njit
    def outer(x):
        return inner(x) * 2

    out = io.StringIO()
    with CompileNotice("scene [fast]", stream=out):
        outer(1), outer(2)
    assert out.getvalue().count("compiling") == 1 and out.getvalue().startswith("scene [fast]: ")
    again = io.StringIO()
    with CompileNotice(stream=again):
        outer(3)
    assert again.getvalue() == ""

    @njit
    def later(x):
        return x
    later(1)  # after the notice closed: no listener left to speak
    assert again.getvalue() == "" and out.getvalue().count("compiling") == 1

    (tmp_path / "cached_twice.py").write_text(CACHED_MODULE)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    said = [subprocess.run([sys.executable, "-c", NOTICE_CHILD, str(tmp_path)], env=env,
                           capture_output=True, text=True, check=True).stdout.strip()
            for _ in range(2)]
    assert "compiling" in said[0] and said[1] == "''"
