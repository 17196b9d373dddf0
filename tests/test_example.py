"""docs/examples/small_study.py runs end to end: exit 0, its figure, finite numbers, and the
reference and fast backends agreeing on the early motion within the tolerance it states."""
import json
import math
import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "examples" / "small_study.py"


def test_small_study_example(tmp_path):
    out = tmp_path / "study"
    p = subprocess.run([sys.executable, str(SCRIPT), str(out), "--duration", "60"],
                       capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]

    png = out / "small_study.png"
    assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "reference.h5").is_file() and (out / "fast.h5").is_file()

    # the printed table: "measure  reference  fast", every number finite
    lines = p.stdout.splitlines()
    head = next(i for i, line in enumerate(lines) if line.split() == ["measure", "reference",
                                                                        "fast"])
    rows = {}
    for line in lines[head + 1:]:
        parts = line.split()
        if len(parts) != 3:
            break
        rows[parts[0]] = (float(parts[1]), float(parts[2]))
    assert {"pulse_speed", "T_c", "c_eff_mean", "clusters_formed", "ledger_error"} <= set(rows)
    assert all(math.isfinite(v) for pair in rows.values() for v in pair), rows

    # early-time agreement, as printed, within the stated tolerance
    m = re.search(r"early_max_dx (\S+) p over t <= T_c = (\S+) \(tolerance (\S+) p\): agree",
                  p.stdout)
    assert m, p.stdout
    dx, window, tol = map(float, m.groups())
    assert dx <= tol == 0.01 and window > 20.0
    ref, fast = rows["pulse_speed"]
    assert abs(ref - fast) <= 1e-3 * ref  # the primary pulse: an early-time quantity

    summary = json.loads((out / "summary.json").read_text())
    assert summary["agree"] is True and abs(summary["early_max_dx"] - dx) <= 1e-3 * dx
    assert summary["measures"]["reference"]["ledger_error"] <= 1e-6
