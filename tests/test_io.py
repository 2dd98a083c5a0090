"""Atomic writing: never a half-written file, never an overwritten input."""

import re

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


def _mode(path):
    return path.stat().st_mode & 0o777


@pytest.fixture
def umask_022():
    import os

    old = os.umask(0o022)
    yield
    os.umask(old)


def test_outputs_get_the_users_normal_mode(tmp_path, umask_022):
    import os

    written = _io.atomic_write(tmp_path / "table.csv", "a,b\n")
    assert _mode(written) == 0o644
    tmp, final = _io.atomic_output_path(tmp_path / "mesh.ply")
    tmp.write_bytes(b"ply")
    assert _mode(_io.commit_output(tmp, final)) == 0o644
    os.umask(0o027)  # a stricter umask is respected, as open() would
    assert _mode(_io.atomic_write(tmp_path / "private.json", "{}")) == 0o640
    assert _io.default_mode() == 0o640


@pytest.mark.parametrize(
    "name",
    [
        "TP101.TXY",
        "tp005.txy",
        "PAL.DAT",
        "pha.dat",
        "jw11_pal.dat",
        "Headmeasures.txt",
        "TP101.WAV",
    ],
)
def test_recording_data_are_never_replaced_by_an_output(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"data")
    with pytest.raises(OutputExistsError, match=f"{name}: refusing to replace") as info:
        _io.atomic_write(path, "time,theta\n", overwrite=True)
    assert "\n" not in str(info.value)
    with pytest.raises(OutputExistsError, match="recording data"):
        _io.atomic_output_path(path, overwrite=True)
    with pytest.raises(OutputExistsError, match="recording data"):
        _io.check_outputs([path], overwrite=True)
    assert path.read_bytes() == b"data"
    assert [p.name for p in tmp_path.iterdir()] == [name]
    # the writer of that very kind (write_txy, write_outline, ...) may replace it
    _io.atomic_write(path, "new", overwrite=True, data_file=True)
    assert path.read_text() == "new"


def test_data_kind_by_name():
    assert _io.data_kind("x/TP101.TXY") == "a pellet file"
    assert _io.data_kind("PHA.DAT") == "a pharynx trace"
    assert _io.data_kind("headmeasures.TXT") == "a Headmeasures file"
    assert _io.data_kind("out.csv") is None and _io.data_kind("pal.dat.csv") is None


def test_check_outputs_refuses_one_path_twice(tmp_path):
    out, csv = tmp_path / "a.png", tmp_path / "sub" / ".." / "a.png"
    with pytest.raises(OutputExistsError, match="given twice") as info:
        _io.check_outputs([out, None, csv], overwrite=True)
    assert str(out) in str(info.value) and "\n" not in str(info.value)
    assert _io.check_outputs([out, None, tmp_path / "b.csv"]) == [out, tmp_path / "b.csv"]
    out.write_text("old")
    with pytest.raises(OutputExistsError, match="--force"):
        _io.check_outputs([out])
    assert list(tmp_path.iterdir()) == [out]  # checking writes nothing


def test_folders_and_paths_under_files_are_one_clear_line(tmp_path):
    (tmp_path / "plain").write_text("x")
    with pytest.raises(CassiError, match="is a folder"):
        _io.atomic_write(tmp_path, "x", overwrite=True)
    with pytest.raises(CassiError, match="a parent is a file"):
        _io.atomic_write(tmp_path / "plain" / "out.csv", "x")


def test_an_interrupt_leaves_no_temporary_file(tmp_path):
    def interrupted(fh):
        fh.write("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _io.atomic_write(tmp_path / "out.csv", interrupted)
    assert list(tmp_path.iterdir()) == []


def test_temporary_files_are_hidden_and_keep_the_suffix(tmp_path):
    tmp, final = _io.atomic_output_path(tmp_path / "clip.mp4")
    assert tmp.name.startswith(".clip.") and tmp.suffix == ".mp4" and tmp.exists()
    _io.remove_quietly(tmp)
    _io.remove_quietly(tmp)  # already gone: no error
    assert list(tmp_path.iterdir()) == []


def test_atomic_outputs_are_all_or_nothing(tmp_path):
    table, figure = tmp_path / "table.csv", tmp_path / "figure.png"
    with pytest.raises(KeyboardInterrupt):
        with _io.atomic_outputs() as group:
            group.write(table, "a,b\n1,2\n")
            group.path(figure).write_bytes(b"\x89PNG half")
            raise KeyboardInterrupt  # Ctrl-C before the last file is done
    assert list(tmp_path.iterdir()) == []
    with _io.atomic_outputs() as group:
        group.write(table, "a,b\n1,2\n")
        group.path(figure).write_bytes(b"\x89PNG")
        assert not table.exists()  # nothing appears before the end
    assert table.read_text() == "a,b\n1,2\n" and figure.read_bytes() == b"\x89PNG"
    with pytest.raises(OutputExistsError, match="file exists"):
        with _io.atomic_outputs() as group:
            group.write(table, "new")
    with pytest.raises(OutputExistsError, match="given twice"):
        with _io.atomic_outputs(overwrite=True) as group:
            group.write(table, "new")
            group.write(table, "again")
    assert table.read_text() == "a,b\n1,2\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure.png", "table.csv"]


# ------------------------------------------------ special files and foreign data (issue 24)
def _special_nodes(tmp_path):
    """``(path, what special_kind says)`` of paths that exist but are no regular file: a
    FIFO, a socket, a link to a character device (/dev/null: no root needed), a link to a
    FIFO, a broken link, a link to itself."""
    import os
    import socket

    os.mkfifo(tmp_path / "pipe.csv")
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(tmp_path / "sock.csv"))
    sock.close()
    (tmp_path / "null.csv").symlink_to(os.devnull)
    (tmp_path / "to_pipe.csv").symlink_to(tmp_path / "pipe.csv")
    (tmp_path / "broken.csv").symlink_to(tmp_path / "absent")
    (tmp_path / "loop.csv").symlink_to(tmp_path / "loop.csv")
    return [(tmp_path / "pipe.csv", "a named pipe (FIFO)"), (tmp_path / "sock.csv", "a socket"),
            (tmp_path / "null.csv", "a character device"),
            (tmp_path / "to_pipe.csv", "a named pipe (FIFO)"),
            (tmp_path / "broken.csv", "a broken link"), (tmp_path / "loop.csv", "a link that loops")]


def _node(path):
    import os

    return os.lstat(path).st_mode, os.readlink(path) if os.path.islink(path) else None


def test_special_files_are_never_replaced_even_with_force(tmp_path):
    """`--force` onto a FIFO or a device replaced the node with a regular file (as root,
    onto the disk's device node): every writer refuses any path that is not a regular
    file, with one line naming it and what it is, and leaves the node as it was."""
    for path, kind in _special_nodes(tmp_path):
        assert _io.special_kind(path) == kind
        before = _node(path)
        for write in (lambda p: _io.atomic_write(p, "x", overwrite=True),
                      lambda p: _io.atomic_write(p, "x"),
                      lambda p: _io.atomic_output_path(p, overwrite=True),
                      lambda p: _io.check_outputs([p], overwrite=True)):
            with pytest.raises(OutputExistsError, match="not a regular file") as info:
                write(path)
            message = str(info.value)
            assert message.startswith(f"{path}: is {kind}, not a regular file")
            assert "\n" not in message
        with pytest.raises(OutputExistsError, match="not a regular file"):
            with _io.atomic_outputs(overwrite=True) as group:
                group.write(path, "x")
        assert _node(path) == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def test_special_kind_of_ordinary_paths(tmp_path):
    (tmp_path / "file.csv").write_text("x")
    (tmp_path / "link.csv").symlink_to(tmp_path / "file.csv")
    assert [_io.special_kind(tmp_path / n) for n in ("file.csv", "link.csv", "absent")] == [
        None, None, None]
    assert _io.special_kind(tmp_path) is None  # a folder: check_output's own message
    _io.atomic_write(tmp_path / "link.csv", "y", overwrite=True)  # a link to a file is fine


def test_an_output_folder_that_is_not_a_folder(tmp_path):
    (tmp_path / "file").write_text("x")
    assert _io.check_output_folder(tmp_path) == tmp_path
    assert _io.check_output_folder(tmp_path / "new" / "deeper") == tmp_path / "new" / "deeper"
    for path, kind in _special_nodes(tmp_path):
        with pytest.raises(CassiError, match=f"^{re.escape(str(path))}: is {re.escape(kind)}, not a "
                           "folder") as info:
            _io.check_output_folder(path)
        assert "\n" not in str(info.value)
    with pytest.raises(CassiError, match="is a file, not a folder"):
        _io.check_output_folder(tmp_path / "file")
    with pytest.raises(CassiError, match="a parent is a file"):
        _io.check_output_folder(tmp_path / "file" / "out")
