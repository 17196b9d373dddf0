"""Compare two folders of one sweep (``mdgran sweep ... --out DIR``) case by case: every dataset
of every case's H5 file bitwise (:func:`check_bitwise.same`: NaN equals NaN), every attribute
of every object in it, each case's JSON summary, and the folder's ``sweep.json`` and
``summary.json``.  What differs from run to run on any tree is left out: the timings in
``/parameters@backend_stats`` (``wall_time_s``, ``kernel_s``) and the summaries' ``wall_s``.

Usage::

    PYTHONPATH=../mdgran-before python -m mdgran sweep paper-robustness --backend fast --out /tmp/a
    PYTHONPATH=. python -m mdgran sweep paper-robustness --backend fast --out /tmp/b
    python reference/compare_sweeps.py /tmp/a /tmp/b

Prints one line per differing case (and a count) and exits 1 if anything differs or is
missing from either folder.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_bitwise import datasets, same  # noqa: E402

#: run-to-run timings: left out of the comparison
TIMINGS = ("wall_time_s", "kernel_s", "wall_s")


def attributes(path: Path) -> dict:
    """``{object path: {attribute: value}}`` of an HDF5 file (the root is ``"/"``), with the
    timings of ``backend_stats`` removed."""
    import h5py

    found = {}

    def visit(key, obj):
        attrs = {}
        for name, value in obj.attrs.items():
            if name == "backend_stats":
                value = {k: v for k, v in json.loads(value).items() if k not in TIMINGS}
            attrs[name] = value
        found[key] = attrs

    with h5py.File(path, "r") as f:
        visit("/", f)
        f.visititems(visit)
    return found


def same_attrs(a: dict, b: dict) -> list:
    """The ``object@attribute`` names whose values differ (or exist in one file only)."""
    out = []
    for key in sorted(set(a) | set(b)):
        ka, kb = a.get(key, {}), b.get(key, {})
        for name in sorted(set(ka) | set(kb)):
            if name not in ka or name not in kb:
                out.append(f"{key}@{name}")
            elif isinstance(ka[name], dict) or isinstance(kb[name], dict):
                if ka[name] != kb[name]:
                    out.append(f"{key}@{name}")
            elif not same(ka[name], kb[name]):
                out.append(f"{key}@{name}")
    return out


def summary(path: Path) -> dict:
    """A case's JSON summary without its timings."""
    return {k: v for k, v in json.loads(path.read_text()).items() if k not in TIMINGS}


def compare_case(a: Path, b: Path, stem: str) -> list:
    """What differs between case ``stem`` of folders ``a`` and ``b`` (empty: identical)."""
    diffs = []
    ha, hb = a / "cases" / f"{stem}.h5", b / "cases" / f"{stem}.h5"
    if ha.exists() != hb.exists():
        diffs.append("h5 missing in one folder")
    elif ha.exists():
        da, db = datasets(ha), datasets(hb)
        diffs += [f"dataset {k}" for k in sorted(set(da) ^ set(db))]
        diffs += [f"dataset {k}" for k in sorted(set(da) & set(db)) if not same(da[k], db[k])]
        diffs += [f"attribute {k}" for k in same_attrs(attributes(ha), attributes(hb))]
    ja, jb = a / "cases" / f"{stem}.json", b / "cases" / f"{stem}.json"
    if ja.exists() != jb.exists():
        diffs.append("json missing in one folder")
    elif ja.exists() and summary(ja) != summary(jb):
        sa, sb = summary(ja), summary(jb)
        diffs += [f"summary {k}" for k in sorted(set(sa) | set(sb)) if sa.get(k) != sb.get(k)]
    return diffs


def compare(a: Path, b: Path) -> int:
    """Compare two sweep folders; returns the number of differing cases and files."""
    stems = sorted({p.stem for p in (a / "cases").glob("*.json")}
                   | {p.stem for p in (b / "cases").glob("*.json")})
    bad_cases = 0
    for stem in stems:
        diffs = compare_case(a, b, stem)
        if diffs:
            bad_cases += 1
            print(f"case {stem}: DIFFERS: {', '.join(diffs[:6])}"
                  + (f" (+{len(diffs) - 6} more)" if len(diffs) > 6 else ""))
    bad_files = 0
    for name in ("sweep.json", "summary.json"):
        fa, fb = a / name, b / name
        if not (fa.exists() and fb.exists()) or json.loads(fa.read_text()) != \
                json.loads(fb.read_text()):
            bad_files += 1
            print(f"{name}: DIFFERS (or missing)")
    print(f"{len(stems) - bad_cases} of {len(stems)} cases identical (every dataset bitwise, "
          f"every attribute, the summary); sweep.json, summary.json: "
          f"{2 - bad_files} of 2 identical")
    return bad_cases + bad_files


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    args = ap.parse_args(argv)
    return 1 if compare(args.a, args.b) else 0


if __name__ == "__main__":
    sys.exit(main())
