"""Two compiled fast-kernel variants in one process, both loaded from numba's disk cache.

numba names a compiled function by its qualified name, argument types and a counter of the
process that compiled it.  The variants' closures (``run_segments``, ``one_segment``) once had
the same name in every variant, so two variants compiled by two processes whose counters
agreed (each loading the shared functions from the cache, then compiling its own closures)
had the same symbols; a third process loading both linked the second variant to the first
one's pass: a dimer chain ran with the homogeneous chain's physics, and the homogeneous chain
after a dimer crashed (segmentation fault).  The run here reproduces that history in a cache
folder of its own and checks that each chain's result is the one it has alone.  The folder
starts as a copy of what the suite has cached by then, without the two variants: loading the
shared functions takes seconds where compiling them took a minute.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

N = 2101  # more contacts than fast_kernel.SEGMENT: the pass runs through run_segments

CHILD = r"""
import json, sys
import numpy as np
from mdgran import run
from mdgran.model.scene import load_scene
N = int(sys.argv[1])
CASES = {"warm": ("collision-pair", []),
         "homogeneous": ("micro-star", [("chain.n", N)]),
         "dimer": ("micro-star", [("chain.n", N), ("beads.pattern", "dimer"),
                                  ("beads.ratio", 0.6)])}
out = {}
for case in sys.argv[2:]:
    name, over = CASES[case]
    sc = load_scene(name, over + [("run.duration", 2.0), ("run.output_interval", 1.0),
                                  ("run.threads", 1)])
    x = run(sc, "fast").trajectory.x[-1]
    out[case] = [float(np.abs(x).sum()), float(x[len(x) // 2])]
from mdgran.backends import fast_kernel
out["segment_pass_compiled"] = len(fast_kernel.segment_pass.overloads)
print(json.dumps(out))
"""


def _run(cache, *cases):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    res = subprocess.run([sys.executable, "-c", CHILD, str(N), *cases], env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, f"{cases}: exit {res.returncode}: {res.stderr[-400:]}"
    return json.loads(res.stdout.strip().splitlines()[-1])


def _variant_tag(case):
    """The name tag of the fast kernel's variant for one of CHILD's cases (no compiling)."""
    from mdgran.backends.fast import FastBackend
    from mdgran.model.scene import load_scene

    over = {"homogeneous": [], "dimer": [("beads.pattern", "dimer"), ("beads.ratio", 0.6)]}
    scene = load_scene("micro-star", [("chain.n", N), ("run.threads", 1), *over[case]])
    return "".join("1" if f else "0" for f in FastBackend(scene).flags)


def _seed(cache, fresh_tags):
    """Copy what numba has cached for the package into ``cache`` (laid out as for
    NUMBA_CACHE_DIR), all but the compiled variants tagged ``fresh_tags``: the shared
    functions the suite has compiled by now are then loaded, not compiled again (~60 s).
    The ``warm`` run compiles what is missing."""
    import mdgran
    from numba.core.caching import _CacheLocator

    for folder in Path(mdgran.__file__).parent.rglob("__pycache__"):
        files = [f for f in folder.iterdir() if f.suffix in (".nbi", ".nbc")
                 and not any(f"_{tag}" in f.name for tag in fresh_tags)]
        if files:
            target = cache / _CacheLocator.get_suitable_cache_subpath(folder.parent / "x.py")
            target.mkdir(parents=True, exist_ok=True)
            for f in files:
                shutil.copyfile(f, target / f.name)


def test_variants_from_the_cache_keep_their_own_physics(tmp_path):
    cache = tmp_path / "numba-cache"
    _seed(cache, [_variant_tag("homogeneous"), _variant_tag("dimer")])
    _run(cache, "warm")  # the shared functions compiled: the next two compile alike
    homogeneous, dimer = _run(cache, "homogeneous"), _run(cache, "dimer")
    # a variant compiles its pass once, whether a chain has one segment or several (a
    # literal 0 for the one segment's index once made it compile the pass twice, ~7 s more)
    assert homogeneous.pop("segment_pass_compiled") == dimer.pop("segment_pass_compiled") == 1
    alone = {**homogeneous, **dimer}
    assert alone["homogeneous"] != alone["dimer"]
    for order in [("homogeneous", "dimer"), ("dimer", "homogeneous")]:
        again = _run(cache, *order)
        assert again.pop("segment_pass_compiled") == 0  # both from the cache
        assert again == {k: alone[k] for k in order}, order
