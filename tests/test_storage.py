"""mdgran.output.storage's atomic write: the whole new text in place of the old, no temporary
left."""
import os

import pytest

from mdgran.output.storage import temporary_path, write_atomic


def test_write_atomic_replaces_the_file_whole_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "report.json"
    path.write_text("old, longer than the new text\n")
    write_atomic(path, "new\n")
    assert path.read_text() == "new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.json"]


def test_the_temporary_is_beside_the_file_and_named_for_this_process(tmp_path):
    """NAME.tmp-PID: a sweep removes the *.tmp-* of its killed workers by that pattern."""
    assert temporary_path(tmp_path / "a.h5") == tmp_path / f"a.h5.tmp-{os.getpid()}"


def test_write_atomic_into_a_missing_folder_raises_and_writes_nothing(tmp_path):
    with pytest.raises(FileNotFoundError):
        write_atomic(tmp_path / "missing" / "report.md", "text")
    assert list(tmp_path.iterdir()) == []
