"""Bitwise fingerprints of short runs (writes reference/fingerprints.json).

The project's bitwise claims (a resumed run equals an uninterrupted one, a refactor leaves
results unchanged) hold for one set of package versions on one kind of CPU: NumPy picks its
SIMD kernels at run time (AVX2 here, AVX-512 elsewhere) and those round differently in the
last bit, which a chaotic chain amplifies.  This script records, for four scenes on the
reference and fast backends, the SHA-256 of the displacement, velocity and event arrays,
together with the package versions (those of ``constraints.txt``) and NumPy's CPU dispatch.
The file holds one entry per platform it was run on (``platforms``: the pinned versions on
each kind of CPU dispatch met so far); running the script replaces this platform's entry and
drops the entries of other package versions.  ``tests/test_determinism.py`` compares against
the entry of its platform, and skips with the reason where there is none.

    python reference/fingerprints.py
"""
from __future__ import annotations

import hashlib
import json
import sys
from importlib.metadata import version
from pathlib import Path

import numpy as np

from mdgran.model.scene import load_scene
from mdgran.simulation import run

OUT = Path(__file__).with_name("fingerprints.json")
PACKAGES = ("numpy", "scipy", "numba", "llvmlite", "h5py")
CASES = {
    "micro-star": [("run.duration", 20.0)],
    "macro-hertz": [("run.duration", 20.0)],
    "collision-pair": [("run.duration", 5.0)],
    "hard/dmt": [("run.duration", 20.0)],
}
BACKENDS = ("reference", "fast")


def platform_key() -> dict:
    """Package versions and the CPU features NumPy dispatches to."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return {"packages": {p: version(p) for p in PACKAGES},
            "numpy_dispatch": sorted(k for k in __cpu_dispatch__ if __cpu_features__.get(k))}


def fingerprint(scene_name: str, overrides, backend: str) -> str:
    """SHA-256 over a run's displacements, velocities and events (time, contact, kind)."""
    tr = run(load_scene(scene_name, overrides), backend).trajectory
    h = hashlib.sha256()
    for arr in (tr.x, tr.v, tr.ev_time, tr.ev_contact, tr.ev_kind):
        h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()


def all_fingerprints() -> dict:
    return {f"{name} [{b}]": fingerprint(name, ov, b) for name, ov in CASES.items()
            for b in BACKENDS}


def entry_for(platforms: list, platform: dict) -> dict | None:
    """The recorded entry of ``platform`` (package versions and NumPy dispatch), or None."""
    return next((e for e in platforms if e["platform"] == platform), None)


def main() -> int:
    here = platform_key()
    old = json.loads(OUT.read_text())["platforms"] if OUT.exists() else []
    keep = [e for e in old if e["platform"]["packages"] == here["packages"]
            and e["platform"] != here]
    entries = keep + [{"platform": here, "runs": all_fingerprints()}]
    OUT.write_text(json.dumps({"platforms": entries}, indent=1) + "\n")
    print(f"wrote {OUT} ({len(entries)} platforms)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
