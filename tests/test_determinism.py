"""Bitwise reproducibility against the recorded fingerprints (reference/fingerprints.json).

Runs only where the installed versions (``constraints.txt``, what CI installs) and NumPy's CPU
dispatch are those the fingerprints were recorded with; elsewhere it is skipped with the
difference as the reason (results may then differ in the last bit, and chaotic runs more).
"""
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "reference"))
import fingerprints as fp  # noqa: E402

RECORDED = json.loads((ROOT / "reference" / "fingerprints.json").read_text())


def test_constraints_pin_the_recorded_versions():
    """constraints.txt and the fingerprints speak of the same versions."""
    pins = dict(line.split(";")[0].strip().split("==")
                for line in (ROOT / "constraints.txt").read_text().splitlines()
                if "==" in line and not line.startswith("#"))
    for pkg, ver in RECORDED["platform"]["packages"].items():
        assert pins.get(pkg) == ver, pkg


@pytest.mark.parametrize("key", sorted(RECORDED["runs"]))
def test_runs_are_bitwise_as_recorded(key):
    here = fp.platform_key()
    if here != RECORDED["platform"]:
        pytest.skip(f"platform differs from the recorded one: {here} vs {RECORDED['platform']}")
    name, backend = key[:-1].split(" [")
    assert fp.fingerprint(name, fp.CASES[name], backend) == RECORDED["runs"][key]
