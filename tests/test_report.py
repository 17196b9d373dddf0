"""The study report: the fit behind Fig. 7, the pooled coincidence test, and the whole
``mdgran report`` on a small sweep."""
import json

import numpy as np
import pytest

from mdgran.studies.paper_figures import fit_slope


def test_fit_slope_recovers_a_known_line_and_its_interval():
    rng = np.random.default_rng(7)
    x = rng.uniform(-1, 1, 91)
    y = 40 + 10 * x + rng.normal(0, 12, 91)
    f = fit_slope(x, y)
    # analytic standard error of the slope: sigma / sqrt(sum (x - mean)^2)
    se = 12 / np.sqrt(np.sum((x - x.mean()) ** 2))
    lo, hi = f["slope_ci95"]
    assert lo < 10 < hi
    assert (hi - lo) / 2 == pytest.approx(1.99 * se, rel=0.25)
    flat = fit_slope(x, 40 + rng.normal(0, 12, 91))
    assert flat["slope_ci95"][0] < 0 < flat["slope_ci95"][1]


def test_report_small(tmp_path):
    from mdgran.cli import main

    out = tmp_path / "rep"
    from mdgran.studies.paper_study import make_report

    nb = make_report(out, small=True, workers=2, duration=150.0, progress=False,
                     beyond=("lambda-range", "long-chain"))
    text = (out / "report.md").read_text()
    for f in ("fig2", "fig3", "fig4", "fig5", "fig6", "figB1", "figB2", "figB3", "fig7"):
        assert (out / "figures" / f"{f}.png").stat().st_size > 10_000, f
        assert f"figures/{f}.png" in text
    assert "## Beyond the paper" in text and (out / "figures" / "beyond-lambda-range.png").exists()
    data = json.loads((out / "report.json").read_text())
    assert data["beyond"]["lambda-range"]["cases"] == 2
    # the primary pulse in long chains: 100, 1000 and 3000 beads to t = 20 (the pulse reaches
    # ~60 beads: the three chains' beads move alike, bitwise), a figure and a section
    lc = data["long_chain"]
    assert "## The primary pulse in long chains" in text
    assert (out / "figures" / "beyond-long-chain.png").stat().st_size > 10_000
    assert lc["converged_peak_v"] == {"100": 0.0, "1000": 0.0, "3000": 0.0}
    assert all(r["status"] == "complete" and 0 < r["reach"] < 100 for r in lc["runs"])
    assert not lc["not_complete"]
    assert data["sweep"]["cases"] == 4 and data["sweep"]["max_ledger_error"] < 1e-8
    # during re-clustering micro-star's kinetic energy is below macro-hertz's (the paper's
    # Fig. 2c; measured 0.12 vs 0.205 of T(0) at 3 T_c, running mean over one T_c)
    d = nb["decay"]
    at = "3"
    assert d["micro"]["T_over_T0_at_multiples_of_T_c"][at] < \
        0.8 * d["macro"]["T_over_T0_at_multiples_of_T_c"][at]
    # a second call reuses the runs and the sweep (only redraws), through the command line
    before = (out / "runs" / "micro-star.h5").stat().st_mtime_ns
    assert main(["report", str(out), "--small", "--quiet"]) == 0
    assert (out / "runs" / "micro-star.h5").stat().st_mtime_ns == before


def test_paper_details_reproduce_the_printed_table_and_the_pull_off_check_values():
    """Table II's stress column is T_s / (pi L_s^2 / 4) (the printed 2.19 and 0.219 MPa), the
    stress in the wire T_s / A_s is 85.6 and 8.56 MPa; the COS relation overstates the exact
    Maugis-Dugdale pull-off by 10.8% at lambda = 0.64 (-1.852 against -1.672)."""
    from mdgran.studies.paper_study import paper_details

    pd = paper_details()
    micro, macro = pd["table_II"]
    assert micro["T_s_over_pi_L_s2_4_MPa"] == pytest.approx(micro["printed_MPa"], rel=2e-3)
    assert macro["T_s_over_pi_L_s2_4_MPa"] == pytest.approx(macro["printed_MPa"], rel=2e-3)
    assert micro["T_s_over_A_s_MPa"] == pytest.approx(85.6, rel=1e-3)
    assert macro["T_s_over_A_s_MPa"] == pytest.approx(8.56, rel=1e-3)
    assert micro["K_1_from_2_T_s_over_L_s"] == pytest.approx(21.5, rel=1e-3)
    row = {p["lambda"]: p for p in pd["pull_off"]}[0.64]
    assert row["cos"] == pytest.approx(-1.852, abs=1e-3)
    assert row["maugis_dugdale"] == pytest.approx(-1.672, abs=1e-3)
    assert row["cos_over_md_minus_1"] == pytest.approx(0.108, abs=1e-3)
