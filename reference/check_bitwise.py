"""Bitwise regression check of the fast (and reference) backend: run a fixed set of cases with
the mdgran on ``sys.path`` and write their H5MD files into a folder, then compare two such
folders dataset by dataset with ``numpy.array_equal`` (NaNs equal where both are NaN).

Usage::

    # before: a pristine copy of HEAD (git worktree add ../mdgran-before HEAD)
    PYTHONPATH=../mdgran-before python reference/check_bitwise.py generate /tmp/bits-before
    # after: the working tree
    python reference/check_bitwise.py generate /tmp/bits-after
    python reference/check_bitwise.py compare /tmp/bits-before /tmp/bits-after

``generate`` takes ``--only NAME`` (repeatable) to run some cases.  ``compare`` prints one
line per file (identical, or the first datasets that differ and by how much) and exits 1 if
any file differs or is missing from either folder (``--common``: datasets that only one of
two files has are listed, not counted).  File attributes (dates, wall times) are
not compared; every dataset is, including the stored scene text.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

#: name -> (scene, backend, overrides, backend options).  The fast backend in its three modes
#: (located events with the table, step-quantized events, the exact law instead of the table)
#: on the four built-in scenes and one hard scene; the reference backend on short runs; the
#: LAMMPS backend (the hook and the native plugin, whose homogeneous runs stay bitwise the same with unlike beads supported).
CASES = {
    "fast-micro-star": ("micro-star", "fast", {}, {}),
    "fast-macro-hertz": ("macro-hertz", "fast", {}, {}),
    "fast-dmt-chain": ("dmt-chain", "fast", {}, {}),
    "fast-collision-pair": ("collision-pair", "fast", {}, {}),
    "fast-hard-violent-50": ("hard/violent-50", "fast", {"run.duration": 100.0}, {}),
    "fast-hard-jkr-force": ("hard/jkr-force", "fast", {"run.duration": 100.0}, {}),
    "fast-quantized-micro-star": ("micro-star", "fast", {}, {"locate_events": False}),
    "fast-quantized-macro-hertz": ("macro-hertz", "fast", {}, {"locate_events": False}),
    "fast-quantized-dmt-chain": ("dmt-chain", "fast", {}, {"locate_events": False}),
    "fast-quantized-collision-pair": ("collision-pair", "fast", {}, {"locate_events": False}),
    "fast-exact-micro-star": ("micro-star", "fast", {}, {"contact_eval": "exact"}),
    "fast-exact-dmt-chain": ("dmt-chain", "fast", {}, {"contact_eval": "exact"}),
    "fast-exact-collision-pair": ("collision-pair", "fast", {}, {"contact_eval": "exact"}),
    "reference-micro-star": ("micro-star", "reference", {"run.duration": 40.0}, {}),
    "reference-macro-hertz": ("macro-hertz", "reference", {"run.duration": 40.0}, {}),
    "reference-dmt-chain": ("dmt-chain", "reference", {"run.duration": 40.0}, {}),
    "reference-collision-pair": ("collision-pair", "reference", {}, {}),
    # LAMMPS: the Python hook (step-quantized; table and exact law) and the native plugin
    # (quantized and located), with the cubic substrate on micro-star's chain once each
    "lammps-micro-star": ("micro-star", "lammps", {"run.duration": 100.0}, {}),
    "lammps-macro-hertz": ("macro-hertz", "lammps", {"run.duration": 100.0}, {}),
    "lammps-dmt-chain": ("dmt-chain", "lammps", {"run.duration": 100.0}, {}),
    "lammps-collision-pair": ("collision-pair", "lammps", {}, {}),
    "lammps-k3-micro-star": ("micro-star", "lammps",
                             {"run.duration": 40.0, "substrate.k3": 0.01}, {}),
    "lammps-exact-micro-star": ("micro-star", "lammps", {"run.duration": 20.0},
                                {"contact_eval": "exact"}),
    "lammps-native-quantized-micro-star": ("micro-star", "lammps", {"run.duration": 100.0},
                                           {"contact": "native", "events": "quantized"}),
    "lammps-native-micro-star": ("micro-star", "lammps", {"run.duration": 100.0},
                                 {"contact": "native"}),
    "lammps-native-macro-hertz": ("macro-hertz", "lammps", {"run.duration": 100.0},
                                  {"contact": "native"}),
    "lammps-native-dmt-chain": ("dmt-chain", "lammps", {"run.duration": 100.0},
                                {"contact": "native"}),
    "lammps-native-collision-pair": ("collision-pair", "lammps", {}, {"contact": "native"}),
    "lammps-native-k3-micro-star": ("micro-star", "lammps",
                                    {"run.duration": 40.0, "substrate.k3": 0.01},
                                    {"contact": "native"}),
    # unlike beads: the general mixed kernel and the variants that leave out what a
    # chain does not need; the density-only chains (one law, masses per bead), unit masses,
    # thermal starts and substrate damping, several segments and threads, quantized and exact
    "fast-mixed-dimer": ("mixed/dimer", "fast", {}, {}),
    "fast-mixed-intruder": ("mixed/intruder", "fast", {}, {}),
    "fast-mixed-tapered": ("mixed/tapered", "fast", {}, {}),
    "fast-mixed-striker": ("mixed/striker", "fast", {}, {}),
    "fast-mixed-density-free": ("micro-star", "fast", {
        "chain.boundary": "free", "beads.density": [1.0, 0.3] * 10,
        "thermal.temperature": 0.5, "substrate.damping": 0.01}, {}),
    "fast-mixed-dimer-thermal": ("mixed/dimer", "fast", {
        "thermal.temperature": 1.0, "substrate.damping": 0.02, "substrate.k3": 0.01}, {}),
    "fast-mixed-unit-mass": ("mixed/dimer", "fast", {"beads.mass": [1.0] * 21}, {}),
    "fast-mixed-dimer-long": ("mixed/dimer", "fast", {"chain.n": 5001, "run.duration": 20.0}, {}),
    "fast-mixed-dimer-threads": ("mixed/dimer", "fast", {
        "chain.n": 5001, "run.duration": 20.0, "run.threads": 2}, {}),
    "fast-mixed-density-long": ("micro-star", "fast", {
        "chain.n": 5001, "run.duration": 20.0, "beads.density": [1.0, 0.3] * 2500 + [1.0],
        "thermal.temperature": 0.5}, {}),
    "fast-mixed-pulse": ("driven/pulse", "fast", {
        "chain.n": 21, "beads.pattern": "dimer", "beads.ratio": 0.6}, {}),
    "fast-mixed-shaken": ("driven/shaken", "fast", {"beads.density": [1.0, 0.3] * 10}, {}),
    "fast-quantized-mixed-dimer": ("mixed/dimer", "fast", {}, {"locate_events": False}),
    "fast-quantized-mixed-intruder": ("mixed/intruder", "fast", {}, {"locate_events": False}),
    "fast-quantized-mixed-density-free": ("micro-star", "fast", {
        "chain.boundary": "free", "beads.density": [1.0, 0.3] * 10,
        "thermal.temperature": 0.5}, {"locate_events": False}),
    "fast-exact-mixed-dimer": ("mixed/dimer", "fast", {}, {"contact_eval": "exact"}),
    "fast-exact-mixed-intruder": ("mixed/intruder", "fast", {}, {"contact_eval": "exact"}),
    "fast-mixed-hertz-dimer": ("macro-hertz", "fast", {
        "chain.n": 21, "beads.pattern": "dimer", "beads.ratio": 0.6}, {}),
    "fast-mixed-hertz-density": ("macro-hertz", "fast", {"beads.density": [1.0, 0.3] * 10}, {}),
}


def scene_path(name: str) -> str:
    """A built-in scene name, or the path of a scene under the package's ``scenes/`` folder
    (``hard/...`` ones are not listed as built-in names)."""
    import mdgran

    path = Path(mdgran.__file__).parent / "scenes" / f"{name}.toml"
    return str(path) if "/" in name else name


def generate(folder: Path, only: list[str]) -> None:
    """Run every case (or those in ``only``) into ``folder/NAME.h5``."""
    import mdgran
    from mdgran.api import run

    folder.mkdir(parents=True, exist_ok=True)
    print(f"mdgran from {Path(mdgran.__file__).parent}", flush=True)
    for name, (scene, backend, overrides, options) in CASES.items():
        if only and name not in only:
            continue
        out = folder / f"{name}.h5"
        if out.exists():
            out.unlink()
        res = run(scene_path(scene), backend, out=str(out), set=overrides, keep=False,
                  **options)
        print(f"{name}: {res.status}", flush=True)


def datasets(path: Path) -> dict:
    """Every dataset of an HDF5 file, by its path, as a numpy array."""
    import h5py

    from mdgran.output.run_record import dataset_paths

    with h5py.File(path, "r") as f:
        return {key: f[key][()] for key in dataset_paths(f)}


def same(a, b) -> bool:
    """Bitwise equality of two dataset values (floats: NaN equals NaN)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind in "fc":
        return bool(np.array_equal(a, b, equal_nan=True))
    return bool(np.array_equal(a, b))


def compare(before: Path, after: Path, common: bool = False) -> int:
    """Compare the files of two folders; returns the number of files that differ.  With
    ``common``, datasets found in only one of two files are listed but do not count (a writer
    that stores more than before)."""
    names = sorted({p.name for p in before.glob("*.h5")} | {p.name for p in after.glob("*.h5")})
    bad = 0
    for name in names:
        pa, pb = before / name, after / name
        if not (pa.exists() and pb.exists()):
            print(f"{name}: MISSING in {before if not pa.exists() else after}")
            bad += 1
            continue
        da, db = datasets(pa), datasets(pb)
        only = sorted(set(da) ^ set(db))
        both = sorted(set(da) & set(db))
        diffs = [] if common else list(only)
        diffs += [k for k in both if not same(da[k], db[k])]
        extra = f"; in one file only (not compared): {', '.join(only)}" if common and only else ""
        if not diffs:
            print(f"{name}: identical ({len(both)} datasets, "
                  f"{sum(np.asarray(da[k]).size for k in both)} values{extra})")
            continue
        bad += 1
        print(f"{name}: DIFFERS in {len(diffs)} datasets, e.g.")
        for k in diffs[:5]:
            if k in da and k in db and np.asarray(da[k]).shape == np.asarray(db[k]).shape \
                    and np.asarray(da[k]).dtype.kind == "f":
                err = float(np.nanmax(np.abs(np.asarray(da[k]) - np.asarray(db[k]))))
                print(f"  {k}: max |difference| {err:.3g}")
            else:
                print(f"  {k}: missing, or shape/dtype/value differ")
    print(f"{len(names) - bad} of {len(names)} files identical")
    return bad


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("generate", help="run the cases into a folder")
    g.add_argument("folder", type=Path)
    g.add_argument("--only", action="append", default=[], choices=sorted(CASES))
    c = sub.add_parser("compare", help="compare two folders of H5 files")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    c.add_argument("--common", action="store_true",
                   help="compare only the datasets both files have (list the others)")
    args = ap.parse_args(argv)
    if args.cmd == "generate":
        generate(args.folder, args.only)
        return 0
    return 1 if compare(args.before, args.after, args.common) else 0


if __name__ == "__main__":
    sys.exit(main())
