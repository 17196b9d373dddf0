"""Output for long chains: ``output.bead_stride`` (every k-th bead, or observables
and events only), ``output.compression`` (gzip, lzf) and chunks sized by bytes.

Each file is checked against the full, uncompressed file of the same run (several writers fed
the same frames, or the same deterministic reference run again): the stored beads and contacts
are the full file's columns ``0, k, 2k, ...`` bitwise, the observables and events are equal
bitwise, a compressed dataset reads back bitwise equal to the uncompressed one, and a resumed
decimated, compressed run writes the uninterrupted run's data.
"""
import h5py
import numpy as np
import pytest

from conftest import InterruptAt

from mdgran.model.chain import model_from_scene
from mdgran.cli import main
from mdgran.output.reporters import H5MD_BLOCK, H5MDWriter, buffer_frames, chunk_shape
from mdgran.output.run_record import LEDGER_NAMES, DecimatedRecord, read_h5
from mdgran.model.scene import SceneError, load_scene
from mdgran.simulation import run

T_END, T_STOP = 40.0, 30.0  # micro-star (20 beads, 21 contacts): 14 events by t = 40
STRIDE = 3  # beads 1, 4, ..., 19; contacts 1, 4, ..., 19 (of 1..21)


def _scene(**output):
    keys = [("run.duration", T_END), ("output.contacts", True), ("output.positions", True)]
    return load_scene("micro-star", keys + [(f"output.{k}", v) for k, v in output.items()])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """One reference run of micro-star to t = 40 written by four writers (full; stride 3;
    full gzip; full lzf), and a second run with bead_stride = 0."""
    d = tmp_path_factory.mktemp("decimation")
    sc = _scene()
    extra = {"stride": _scene(bead_stride=STRIDE), "gzip": _scene(compression="gzip"),
             "lzf": _scene(compression="lzf")}
    writers = [H5MDWriter(d / f"{name}.h5", s, "reference", model=model_from_scene(s))
               for name, s in extra.items()]
    run(sc, "reference", out=d / "full.h5", reporters=writers)
    zero = load_scene("micro-star", [("run.duration", T_END), ("output.bead_stride", 0)])
    run(zero, "reference", out=d / "zero.h5")
    return {name: d / f"{name}.h5" for name in ("full", "stride", "gzip", "lzf", "zero")}


def _datasets(path) -> dict:
    """Every dataset by every path (hard links too: chain/position is beads/position)."""
    out = {}

    def walk(group, prefix):
        for key, obj in group.items():
            if isinstance(obj, h5py.Dataset):
                out[prefix + key] = obj[()]
            else:
                walk(obj, f"{prefix}{key}/")

    with h5py.File(path, "r") as f:
        walk(f, "")
    return out


def _same_observables_and_events(a: dict, b: dict):
    stored = [n for n in LEDGER_NAMES if f"observables/{n}/value" in a]
    assert stored == [n for n in LEDGER_NAMES if f"observables/{n}/value" in b]
    assert "total_energy" in stored and "external_work" not in stored  # not driven
    names = [f"observables/{n}/{k}" for n in stored for k in ("step", "time", "value")]
    names += [f"events/{k}" for k in ("time", "contact", "kind")]
    for name in names:
        assert a[name].dtype == b[name].dtype and np.array_equal(a[name], b[name]), name
    assert len(a["events/time"]) == 14


def test_decimated_file_holds_every_kth_bead_bitwise(files):
    full, dec = _datasets(files["full"]), _datasets(files["stride"])
    ids = np.arange(1, 21, STRIDE)
    assert np.array_equal(dec["particles/chain/id"], ids)
    for name in ("displacement", "velocity", "position"):
        v = dec[f"particles/chain/{name}/value"]
        assert v.shape[1] == len(ids)
        assert np.array_equal(v, full[f"particles/chain/{name}/value"][:, ids - 1]), name
        for k in ("step", "time"):
            assert np.array_equal(dec[f"particles/chain/{name}/{k}"],
                                  full[f"particles/chain/{name}/{k}"])
    for name in ("closed", "compression", "force"):
        key = f"observables/contacts/{name}/value"
        assert np.array_equal(dec[key], full[key][:, ::STRIDE]), name
    _same_observables_and_events(dec, full)
    with h5py.File(files["stride"], "r") as f, h5py.File(files["full"], "r") as g:
        assert f["particles/chain"].attrs["bead_stride"] == STRIDE
        numbers = g["observables/contacts"].attrs["contact"]
        assert np.array_equal(f["observables/contacts"].attrs["contact"], numbers[::STRIDE])
        assert "id" not in g["particles/chain"]  # a full file is unchanged: every bead


def test_compressed_datasets_equal_uncompressed(files):
    full = _datasets(files["full"])
    for method in ("gzip", "lzf"):
        comp = _datasets(files[method])
        assert comp.keys() == full.keys()
        for name, value in full.items():
            assert comp[name].dtype == value.dtype and np.array_equal(comp[name], value), name
        with h5py.File(files[method], "r") as f:
            assert f["particles/chain/displacement/value"].compression == method
            assert f["observables/contacts/closed/value"].compression == method
            assert f["observables/total_energy/value"].compression is None


def test_stride_zero_keeps_observables_and_events(files):
    zero, full = _datasets(files["zero"]), _datasets(files["full"])
    assert not any(k.startswith(("particles/chain/displacement", "particles/chain/position",
                                 "observables/contacts")) for k in zero)
    assert len(zero["particles/chain/id"]) == 0
    _same_observables_and_events(zero, full)  # a second, deterministic run: equal bitwise


def test_read_decimated_records(files):
    full = read_h5(files["full"])
    for name in ("stride", "zero"):
        rec = read_h5(files[name])
        assert rec.decimated and rec.n == 20 and rec.frames == full.frames
        assert np.array_equal(rec.time, full.time)
        assert np.array_equal(rec.x_stored, full.x[:, rec.bead_ids - 1])
        assert np.array_equal(rec.v_stored, full.v[:, rec.bead_ids - 1])
        # every contact's state, replayed from the events, is the full file's stored one
        assert np.array_equal(rec.closed, full.closed)
        # analyses of the observables and events work; C_eff is the full record's
        assert np.array_equal(rec.measures.c_eff, full.measures.c_eff)
        with pytest.raises(DecimatedRecord) as exc:
            rec.measures.characteristic_period  # the pulse speed needs every bead
        text = str(exc.value)
        assert "\n" not in text and "output.bead_stride" in text and str(files[name]) in text
    from mdgran.budget import term_budget

    with pytest.raises(DecimatedRecord, match="output.bead_stride = 3"):
        term_budget(read_h5(files["stride"]))


def test_resumed_decimated_compressed_run_equals_uninterrupted(files, tmp_path):
    """A checkpoint holds everything written up to a frame, decimated and compressed too."""
    sc = _scene(bead_stride=STRIDE, compression="lzf")
    sc = load_scene(sc.data, [("run.output_interval", 0.4)])  # 101 frames: cheap checkpoints
    run(sc, "reference", out=tmp_path / "whole.h5")
    out = tmp_path / "r.h5"
    with pytest.raises(KeyboardInterrupt):
        run(sc, "reference", out=out, checkpoint_every=0.0, reporters=[InterruptAt(T_STOP)])
    assert not out.exists() and (tmp_path / "r.h5.partial").exists()
    run(sc, "reference", out=out, checkpoint_every=0.0, resume=True)
    resumed, whole = _datasets(out), _datasets(tmp_path / "whole.h5")
    assert len(whole["particles/chain/id"]) == 7 and len(whole["events/time"]) == 14
    series = [k for k in whole if k.startswith(("particles/chain", "observables", "events"))]
    for name in series:
        assert np.array_equal(resumed[name], whole[name]), name


def test_chunks_and_buffer_by_bytes():
    # a long series (more than BLOCK = 4096 values a frame): one frame by 4096 columns, the
    # grain at which blocks at rest are left out (mdgran.rest_blocks)
    assert chunk_shape((10**6,), 8) == chunk_shape((4097,), 1) == (1, 4096)
    assert chunk_shape((10**6, 3), 8) == (1, 87381, 3)
    assert chunk_shape((20,), 8) == (1024, 20)  # small frames: 1024 of them per chunk
    assert chunk_shape((1000,), 8) == (262, 1000)
    # a 1e6-bead frame (x, v and 1 byte per contact = 17 MB): 3 frames in 64 MiB
    assert buffer_frames(16e6 + 1e6 + 1) == 3
    assert buffer_frames(200.0) == H5MD_BLOCK == 8192 and buffer_frames(1e12) == 1


@pytest.mark.parametrize("key,value", [("output.bead_stride", "-1"),
                                       ("output.bead_stride", "2.5"),
                                       ("output.compression", "zip")])
def test_bad_output_keys_exit_2(tmp_path, capsys, key, value):
    out = tmp_path / "bad.h5"
    assert main(["run", "micro-star", "--out", str(out), "--set", f"{key}={value}"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and key in err and not out.exists()


def test_contacts_need_a_stride():
    with pytest.raises(SceneError, match="output.contacts"):
        load_scene("micro-star", [("output.contacts", True), ("output.bead_stride", 0)])


def test_long_chain_file_holds_its_contact_numbers(tmp_path):
    """The contact numbers of 10001 contacts (80 kB) exceed HDF5 1.6's 64 kB attribute limit:
    before, any chain above ~8100 beads could not be written at all."""
    sc = load_scene("micro-star", [("chain.n", 10_000), ("output.positions", False)])
    w = H5MDWriter(tmp_path / "long.h5", sc, "reference", model=model_from_scene(sc))
    w.close("complete")
    with h5py.File(tmp_path / "long.h5", "r") as f:
        assert np.array_equal(f["observables/contacts"].attrs["contact"], np.arange(1, 10_002))
        # a long series: one frame by 4096 columns (mdgran.rest_blocks)
        assert f["particles/chain/displacement/value"].chunks == (1, 4096)
