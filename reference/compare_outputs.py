"""Compare two mdgran output folders (``mdgran compare``, ``mdgran report``, sweeps) file by file.

Usage::

    python reference/compare_outputs.py BEFORE AFTER [--json OUT.json]

What "identical" means per file type:

* ``.json``: the parsed values are equal, every number exactly (NaN equal to NaN), every key
  present on both sides, except the wall-clock timings (keys in :data:`TIMING_KEYS`);
* ``.md``: the lines are equal, except the cells of table columns whose header says
  ``wall time`` (timings);
* ``.txt``, ``.toml``, ``.csv``: the bytes are equal;
* ``.png``: the pixel arrays (matplotlib's image reader) are equal;
* ``.h5``: every dataset of BEFORE is in AFTER with the same dtype, shape and bytes; datasets only
  in AFTER are listed (new outputs), not counted as differences; ``/parameters`` attributes that
  differ are listed too, JSON-valued ones (``backend_stats``) compared as JSON without the
  timings.

JSON strings holding the folder's own path (``report.json``'s ``sweep.dir``) are compared with
it replaced.  Besides the identity check: where an H5 file of AFTER stores the contact states
(``/observables/contacts/closed``), they are checked against its events replayed
(:func:`mdgran.model.chain.replay_states`) and a frame where they differ is listed (``STATES``);
this does not change the exit status.

Exit status 0 when every file of BEFORE has an identical counterpart in AFTER, 1 otherwise.  The
script prints one line per file that differs and a summary count per type.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

TEXT = {".txt", ".toml", ".csv"}
#: JSON keys that hold wall-clock timings, which no two runs share
TIMING_KEYS = {"wall_s", "wall_time_s", "kernel_s"}


def same_json(a, b, where="") -> list:
    """Paths (``where``) at which two parsed JSON values differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{where}/{k}: missing in {'after' if k in a else 'before'}"
               for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b) - TIMING_KEYS):
            out += same_json(a[k], b[k], f"{where}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{where}: length {len(a)} vs {len(b)}"]
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            out += same_json(x, y, f"{where}[{i}]")
        return out
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return []
    return [] if (a == b and type(a) is type(b)) else [f"{where}: {a!r} vs {b!r}"]


def h5_datasets(path) -> dict:
    """Dataset name -> array, and ``@parameters`` -> the /parameters attributes."""
    import h5py

    from mdgran.output.run_record import dataset_paths

    out = {}
    with h5py.File(path, "r") as f:
        out.update((name, f[name][()]) for name in dataset_paths(f))
        if "parameters" in f:
            out["@parameters"] = {k: (v.decode() if isinstance(v, bytes) else v)
                                  for k, v in f["parameters"].attrs.items()}
    return out


def compare_h5(a, b) -> tuple[list, list]:
    """(differences, notes) between two H5 files: datasets of ``a`` missing or not bitwise equal
    in ``b``; notes: datasets only in ``b`` and differing /parameters attributes."""
    da, db = h5_datasets(a), h5_datasets(b)
    pa, pb = da.pop("@parameters", {}), db.pop("@parameters", {})
    diff, notes = [], []
    for name, x in da.items():
        y = db.get(name)
        if y is None:
            diff.append(f"{name}: missing in after")
        elif (np.asarray(x).dtype != np.asarray(y).dtype or np.shape(x) != np.shape(y)
              or np.asarray(x).tobytes() != np.asarray(y).tobytes()):
            diff.append(f"{name}: not bitwise equal")
    notes += [f"{name}: only in after" for name in sorted(set(db) - set(da))]
    for k in sorted(set(pa) | set(pb)):
        if str(pa.get(k)) == str(pb.get(k)):
            continue
        try:
            jd = same_json(json.loads(pa[k]), json.loads(pb[k]))
        except (KeyError, TypeError, ValueError):
            jd = ["differs"]
        if jd:
            notes.append(f"@parameters/{k}: {'; '.join(jd)}")
    return diff, notes


def markdown_without_timings(text: str) -> list:
    """The lines of a markdown text with the cells of ``wall time`` table columns blanked."""
    out, header = [], None
    for line in text.splitlines():
        if not line.startswith("|"):
            header = None
            out.append(line)
            continue
        cells = line.split("|")
        if header is None:
            header = ["wall time" in c for c in cells]
        elif len(cells) == len(header):
            cells = ["" if timing else c for c, timing in zip(cells, header)]
        out.append("|".join(cells))
    return out


def states_replay(path) -> list:
    """Differences between the contact states stored in ``path`` and its events replayed."""
    from mdgran.output.run_record import read_h5

    run = read_h5(path)
    if run._closed is None:
        return []
    bad = int(np.sum(np.any(run.closed != run.replayed_states(), axis=1)))
    return [f"stored contact states differ from the events replayed at {bad} frames"] if bad \
        else []


def without_root(value, root: Path):
    """``value`` (parsed JSON) with the folder's own path in its strings replaced by ``DIR``."""
    if isinstance(value, dict):
        return {k: without_root(v, root) for k, v in value.items()}
    if isinstance(value, list):
        return [without_root(v, root) for v in value]
    return value.replace(str(root), "DIR") if isinstance(value, str) else value


def compare_file(a: Path, b: Path, roots=None) -> tuple[list, list]:
    """(differences, notes) of one file of BEFORE against AFTER; ``roots``: the two folders
    (their paths in JSON strings are no difference)."""
    ext = a.suffix
    if ext == ".md":
        la = markdown_without_timings(a.read_text())
        lb = markdown_without_timings(b.read_text())
        bad = [i + 1 for i, (x, y) in enumerate(zip(la, lb)) if x != y]
        if len(la) != len(lb):
            bad.append(f"{len(la)} vs {len(lb)} lines")
        return ([f"lines {bad[:8]} differ"] if bad else []), []
    if ext == ".json":
        ja, jb = json.loads(a.read_text()), json.loads(b.read_text())
        if roots is not None:
            ja, jb = without_root(ja, roots[0]), without_root(jb, roots[1])
        return same_json(ja, jb), []
    if ext in TEXT:
        return ([] if a.read_bytes() == b.read_bytes() else ["bytes differ"]), []
    if ext == ".png":
        from matplotlib.image import imread

        x, y = imread(a), imread(b)
        if x.shape != y.shape:
            return [f"image shape {x.shape} vs {y.shape}"], []
        n = int(np.sum(np.any(x != y, axis=-1))) if x.ndim == 3 else int(np.sum(x != y))
        return ([f"{n} pixels differ"] if n else []), []
    if ext == ".h5":
        return compare_h5(a, b)
    return [], [f"not compared ({ext or 'no extension'})"]


def compare_dirs(before, after) -> dict:
    before, after = Path(before), Path(after)
    summary, report = {}, {"differ": {}, "notes": {}, "missing": [], "states": {}}
    for a in sorted(p for p in before.rglob("*") if p.is_file()):
        rel = a.relative_to(before)
        b = after / rel
        kind = a.suffix or "(none)"
        s = summary.setdefault(kind, {"identical": 0, "differ": 0})
        if not b.exists():
            report["missing"].append(str(rel))
            s["differ"] += 1
            continue
        diff, notes = compare_file(a, b, (before, after))
        if a.suffix == ".h5":
            bad = states_replay(b)
            if bad:
                report["states"][str(rel)] = bad
        s["differ" if diff else "identical"] += 1
        if diff:
            report["differ"][str(rel)] = diff
        if notes:
            report["notes"][str(rel)] = notes
    report["only_in_after"] = sorted(
        str(p.relative_to(after)) for p in after.rglob("*")
        if p.is_file() and not (before / p.relative_to(after)).exists())
    report["summary"] = summary
    return report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--json", help="write the full comparison here")
    args = ap.parse_args(argv)
    rep = compare_dirs(args.before, args.after)
    for rel, diff in rep["differ"].items():
        print(f"DIFFERS {rel}: {'; '.join(diff[:5])}{' ...' if len(diff) > 5 else ''}")
    for rel in rep["missing"]:
        print(f"MISSING {rel}")
    for rel, notes in rep["notes"].items():
        print(f"note    {rel}: {'; '.join(notes)}")
    for rel in rep["only_in_after"]:
        print(f"new     {rel}")
    for rel, bad in rep["states"].items():
        print(f"STATES  {rel} (after): {'; '.join(bad)}")
    for kind, s in sorted(rep["summary"].items()):
        print(f"{kind:>7}: {s['identical']} identical, {s['differ']} differ")
    if args.json:
        Path(args.json).write_text(json.dumps(rep, indent=1))
    return 0 if not rep["differ"] and not rep["missing"] else 1


if __name__ == "__main__":
    sys.exit(main())
