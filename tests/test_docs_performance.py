"""The manual's performance page (docs/make_performance.py, run by docs/conf.py at every build)
prints the numbers of benchmarks/results/*.json and names the file each comes from; a file
that is not there is skipped with a line saying so, and the rest of the page is still written.
"""
import importlib.util
import json
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"


def load_script():
    spec = importlib.util.spec_from_file_location("make_performance",
                                                  ROOT / "docs" / "make_performance.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_numbers_come_from_the_files_and_a_missing_file_is_skipped(tmp_path):
    mp = load_script()
    present = [name for name in mp.SOURCES if (RESULTS / name).is_file()]
    assert present, "no benchmark result the page reads is in benchmarks/results"
    kept, dropped = present[0], [name for name in mp.SOURCES if name != present[0]]
    shutil.copy(RESULTS / kept, tmp_path / kept)
    page = mp.page(tmp_path)
    for name in dropped:
        assert f"`benchmarks/results/{name}` is not in this checkout" in page
    assert f"*Source: `benchmarks/results/{kept}`" in page
    # every section still has its heading
    assert page.count("\n## ") == len(mp.SOURCES)


def test_work_precision_table_holds_the_files_numbers(tmp_path):
    mp = load_script()
    data = {"target_ledger_error": 1e-6, "results": [{
        "scene": "micro-star", "duration": 400.0,
        "summary": {"fast": {"order_in": "run.dt", "order_trajectory": 2.0001,
                             "order_ledger": 1.98932, "wall_s_at_ledger_1e-6": 0.4517,
                             "extrapolated": False}}}]}
    (tmp_path / "work_precision.json").write_text(json.dumps(data))
    page = mp.page(tmp_path)
    assert "| fast | run.dt | 2.00 | 1.99 | 0.452 | no |" in page
    write = tmp_path / "out" / "performance.md"
    mp.write_page(tmp_path, write)
    assert write.read_text() == page


def test_active_paired_table_holds_the_files_numbers(tmp_path):
    mp = load_script()
    spread = {"median": 1.2345, "ci95": [1.18, 1.29], "q1": 1.2, "q3": 1.3, "min": 1.1,
              "max": 1.4, "count": 12}
    data = {"steps_per_block": 800, "temperatures": {"moving": 1e-6, "active": 2.0},
            "rows": [{"n": 1000000, "threads": 1, "pairs": 12,
                      "active_over_moving_loop": spread,
                      "active_over_moving_cpu": {**spread, "median": 1.25},
                      "ns_per_bead_step_moving_median": 8.5,
                      "ns_per_bead_step_active_median": 10.5},
                     {"n": 100000, "threads": 2, "error": "not finished in 1200 s"}]}
    (tmp_path / "active_paired.json").write_text(json.dumps(data))
    page = mp.page(tmp_path)
    assert ("| 1 000 000 | 1 | 12 | 1.23 [1.18-1.29] (1.20-1.30; 1.10-1.40) | "
            "1.25 [1.18-1.29] (1.20-1.30; 1.10-1.40) | 8.50 | 10.5 |") in page
    assert "| 100 000 | 2 | failed |" in page
    assert "*Source: `benchmarks/results/active_paired.json`, key `rows[]`.*" in page


def test_active_chains_ratio_table_holds_the_files_ratios(tmp_path):
    mp = load_script()
    rows = [{"n": 1000000, "backend": b, "temperature": t, "ns_per_bead_step_median": ns}
            for b, t, ns in (("fast-1", 1e-6, 8.5), ("fast-1", 2.0, 10.5),
                             ("native-2", 1e-6, 11.2), ("native-2", 2.0, 13.5))]
    rows.append({"n": 1000, "backend": "fast-1", "temperature": 2.0,
                 "error": "not finished in 900 s"})
    ratios = [{"backend": "fast-1", "n": 1000000, "active_over_quiet": 1.2345,
               "ci95": [1.19, 1.281], "rounds": [1.2, 1.25]},
              {"backend": "native-2", "n": 1000000, "active_over_quiet": 1.175,
               "rounds": [1.16, 1.18]},
              {"backend": "fast", "n": 1000000, "temperature": 2.0,
               "two_over_one_speed": 1.8, "rounds": [1.8]}]
    (tmp_path / "active_chains.json").write_text(json.dumps(
        {"dt": 0.0025, "cores": 2, "rows": rows, "ratios": ratios}))
    page = mp.page(tmp_path)
    assert "| fast-1 | 1 000 000 | 1.23 | 1.19-1.28 | 1.20, 1.25 |" in page
    assert "| native-2 | 1 000 000 | 1.18 | - | 1.16, 1.18 |" in page
    assert "| fast | 1 000 000 |" not in page  # speed-ups are not active/moving ratios
    assert "| fast-1 | 2 | failed | 10.5 |" in page  # a failed point says so
    assert ("*Source: `benchmarks/results/active_chains.json`, "
            "key `ratios[].active_over_quiet`.*") in page
