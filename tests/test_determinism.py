"""Bitwise reproducibility against the recorded fingerprints (reference/fingerprints.json).

Runs where the installed versions (``constraints.txt``, what CI installs) and NumPy's CPU
dispatch are those of a recorded platform; elsewhere it is skipped with the difference as the
reason (results may then differ in the last bit, and chaotic runs more).
"""
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "reference"))
import fingerprints as fp  # noqa: E402

RECORDED = json.loads((ROOT / "reference" / "fingerprints.json").read_text())


PLATFORMS = RECORDED["platforms"]
KEYS = sorted({key for entry in PLATFORMS for key in entry["runs"]})


def test_constraints_pin_the_recorded_versions():
    """constraints.txt and every recorded platform speak of the same versions."""
    pins = dict(line.split(";")[0].strip().split("==")
                for line in (ROOT / "constraints.txt").read_text().splitlines()
                if "==" in line and not line.startswith("#"))
    for entry in PLATFORMS:
        for pkg, ver in entry["platform"]["packages"].items():
            assert pins.get(pkg) == ver, pkg


@pytest.mark.parametrize("key", KEYS)
def test_runs_are_bitwise_as_recorded(key):
    here = fp.platform_key()
    entry = fp.entry_for(PLATFORMS, here)
    if entry is None:
        pytest.skip(f"no recorded platform is this one: {here} vs "
                    f"{[e['platform'] for e in PLATFORMS]}")
    name, backend = key[:-1].split(" [")
    assert fp.fingerprint(name, fp.CASES[name], backend) == entry["runs"][key]


def test_fast_backend_does_not_depend_on_numpy_dispatch():
    """The fast backend's stepping is numba's code, not NumPy's SIMD kernels: its recorded
    runs are the same bits on every CPU dispatch recorded (the reference backend's are not:
    scipy's Runge-Kutta goes through NumPy's)."""
    assert len(PLATFORMS) >= 2
    fast = [{k: v for k, v in e["runs"].items() if k.endswith("[fast]")} for e in PLATFORMS]
    assert fast[0] and all(f == fast[0] for f in fast)
