"""Atomic writing: never a half-written file, never an overwritten input."""

import pytest

from cassi_fit import _io
from cassi_fit.errors import CassiError, OutputExistsError


def test_atomic_write_creates_and_refuses_to_overwrite(tmp_path):
    path = tmp_path / "sub" / "out.txt"
    _io.atomic_write(path, "hello")
    assert path.read_text() == "hello"
    with pytest.raises(OutputExistsError):
        _io.atomic_write(path, "again")
    _io.atomic_write(path, "again", overwrite=True)
    assert path.read_text() == "again"
    assert [p.name for p in path.parent.iterdir()] == ["out.txt"]  # no temp files left


def test_inputs_are_never_overwritten(tmp_path):
    path = tmp_path / "input.txy"
    path.write_text("data")
    _io.register_input(path)
    with pytest.raises(OutputExistsError) as info:
        _io.atomic_write(path, "x", overwrite=True)
    assert isinstance(info.value, CassiError)
    assert "input" in str(info.value)
    with pytest.raises(OutputExistsError):
        _io.atomic_output_path(path, overwrite=True)
    assert path.read_text() == "data"


def test_failed_write_leaves_nothing(tmp_path):
    path = tmp_path / "out.bin"

    def explode(fh):
        fh.write(b"partial")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        _io.atomic_write(path, explode, binary=True)
    assert list(tmp_path.iterdir()) == []


def test_output_path_then_commit(tmp_path):
    tmp, final = _io.atomic_output_path(tmp_path / "video.mp4")
    assert tmp.suffix == ".mp4" and tmp.parent == final.parent
    tmp.write_bytes(b"abc")
    _io.commit_output(tmp, final)
    assert final.read_bytes() == b"abc" and not tmp.exists()
