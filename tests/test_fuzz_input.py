"""Property-based bad input: hypothesis makes invalid scenes; every one must be rejected up
front with exit status 2, one line on stderr naming the key, no traceback, no output file."""
import io
import math
from contextlib import redirect_stderr

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mdgran.cli import main

VALID = {
    "chain": {"n": 4, "boundary": "fixed", "initial_gap": 0.0},
    "contact": {"law": "schwarz", "lambda": 0.64, "damping": 0.01, "snap_off": "displacement"},
    "substrate": {"k1": 0.01, "k3": 0.0},
    "impulse": {"bead": 1, "velocity": 1.0},
    "run": {"duration": 1.0, "output_interval": 0.5, "tolerance": 1e-8},
}

NUMERIC = [("chain", "initial_gap"), ("contact", "lambda"), ("contact", "damping"),
           ("substrate", "k1"), ("substrate", "k3"), ("impulse", "velocity"),
           ("run", "duration"), ("run", "output_interval"), ("run", "tolerance")]
POSITIVE = {("run", "duration"), ("run", "output_interval")}
NONNEG = {("chain", "initial_gap"), ("contact", "lambda"), ("contact", "damping"),
          ("substrate", "k1"), ("substrate", "k3")}
CHOICE = [("chain", "boundary"), ("contact", "law"), ("contact", "snap_off")]

wrong_type = st.one_of(st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=5),
                       st.booleans(),
                       st.lists(st.integers(), max_size=2))
not_finite = st.sampled_from([math.nan, math.inf, -math.inf])


@st.composite
def bad_scene(draw):
    """(scene dict, the key that must be named)."""
    scene = {s: dict(t) for s, t in VALID.items()}
    kind = draw(st.sampled_from(["type", "range", "nan", "unknown", "n", "bead", "choice",
                                 "section", "fc"]))
    if kind == "type":
        sec, key = draw(st.sampled_from(NUMERIC + [("chain", "n"), ("impulse", "bead")]))
        scene[sec][key] = draw(wrong_type)
    elif kind == "range":
        sec, key = draw(st.sampled_from(sorted(POSITIVE | NONNEG)))
        hi = 0.0 if (sec, key) in POSITIVE else -1e-300
        scene[sec][key] = draw(st.floats(max_value=hi, allow_nan=False, allow_infinity=False))
    elif kind == "nan":
        sec, key = draw(st.sampled_from(NUMERIC))
        scene[sec][key] = draw(not_finite)
    elif kind == "unknown":
        sec = draw(st.sampled_from(sorted(VALID)))
        key = draw(st.text("abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=8))
        if key in VALID[sec] or key in ("fc", "dt", "positions", "description") or \
                key.endswith("_si"):
            key = key + "_zz"
        scene[sec][key] = 1
    elif kind == "n":
        sec, key = "chain", "n"
        scene[sec][key] = draw(st.integers(max_value=0))
    elif kind == "bead":
        sec, key = "impulse", "bead"
        scene[sec][key] = draw(st.one_of(st.integers(max_value=0), st.integers(min_value=5)))
    elif kind == "choice":
        sec, key = draw(st.sampled_from(CHOICE))
        scene[sec][key] = draw(st.text("abcxyz", min_size=1, max_size=6))
    elif kind == "fc":
        sec, key = "contact", "fc"
        del scene["contact"]["lambda"]
        scene[sec][key] = draw(st.one_of(st.floats(max_value=-2.0001, min_value=-1e6),
                                         st.floats(min_value=-1.4999, max_value=1e6)))
    else:  # unknown section
        sec = draw(st.sampled_from(["chains", "Contact", "impulses", "runs"]))
        scene[sec] = {"x": 1}
        return scene, sec
    return scene, f"{sec}.{key}"


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, list):
        return "[" + ", ".join(str(x) for x in v) + "]"
    return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'


def to_toml(scene):
    out = []
    for sec, table in scene.items():
        out.append(f'["{sec}"]' if not sec.isidentifier() else f"[{sec}]")
        out += [f'"{k}" = {toml_value(v)}' for k, v in table.items()]
    return "\n".join(out) + "\n"


EXAMPLES = 300


@pytest.fixture(scope="module")
def fuzzed(tmp_path_factory):
    """Runs the property check once per module, whichever test asks first: hypothesis makes
    EXAMPLES bad scenes (shrinking any that is not rejected cleanly); returns how many it
    checked."""
    tmp = tmp_path_factory.mktemp("fuzz")
    seen = []

    @settings(max_examples=EXAMPLES, deadline=None)
    @given(case=bad_scene())
    def check(case):
        scene, key = case
        seen.append(key)
        path = tmp / "bad.toml"
        path.write_text(to_toml(scene))
        out = tmp / "out.h5"
        with redirect_stderr(io.StringIO()) as stderr:
            status = main(["run", str(path), "--out", str(out), "--quiet"])
        err = stderr.getvalue()
        assert status == 2, (scene, err)
        assert err.count("\n") == 1 and "Traceback" not in err
        assert key in err, (key, err)
        assert not out.exists() and not list(tmp.glob("out.h5*"))

    check()
    return len(seen)


def test_every_bad_scene_is_rejected_cleanly(fuzzed):
    assert fuzzed >= EXAMPLES


def test_fuzz_count_reported(fuzzed):
    """Passes alone too: the fixture runs the generation if no test has yet."""
    print(f"bad scenes generated and rejected: {fuzzed}")
    assert fuzzed >= EXAMPLES
