"""Pellet files: fixture reading, round trip, per-value markers, every bad-input error."""

from pathlib import Path

import numpy as np
import pytest

from cassi_fit.errors import DataFormatError, MissingDataError, OutputExistsError
from cassi_fit.pellets import first_valid_line
from cassi_fit.txy import (
    FRAME_STEP_US,
    PELLET_NAMES,
    UNTRACKED,
    PelletTrack,
    pad_untracked,
    read_txy,
    require_tracked,
    write_txy,
)

FIXTURES = Path(__file__).parent / "fixtures"
# a plausible rest posture in um (the reader checks the anatomy): UL LL T1..T4 MNI MNM
POSTURE = ["15000", "18000", "9000", "-21000", "-17000", "1000", "-28000", "8000", "-39000",
           "15000", "-53000", "17000", "-1000", "-8000", "-43000", "-3000"]
ROW = "\t".join(["0"] + POSTURE)


def _track(n=6, seed=0):
    rng = np.random.default_rng(seed)
    times = np.arange(n) * FRAME_STEP_US * 1e-6
    # random values around a plausible posture (the reader checks the anatomy)
    rest = np.array([[15, 18], [9, -21], [-17, 1], [-28, 8], [-39, 15], [-53, 17], [-1, -8],
                     [-43, -3]], dtype=float)
    positions = rest + rng.uniform(-1.5, 1.5, size=(n, 8, 2))
    valid = rng.random((n, 8, 2)) > 0.2
    return PelletTrack(times, positions, valid)


def _write(tmp_path, text, name="x.txy"):
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


def test_fixture_crlf_leading_untracked_and_per_value_marker():
    track = read_txy(FIXTURES / "sample.txy")
    assert track.n_frames == 7
    assert track.times[0] == 0.0
    np.testing.assert_allclose(np.diff(track.times), FRAME_STEP_US * 1e-6)
    assert not track.valid[:3].any() and np.isnan(track.positions[:3]).all()
    assert first_valid_line(track).index == 3
    np.testing.assert_array_equal(track.pellet("MNM")[3], [-43.5, -3.1])
    np.testing.assert_array_equal(track.pellet("ul")[3], [14.9, 17.8])
    # frame 5: only x of T4 is untracked
    t4 = PELLET_NAMES.index("T4")
    assert not track.valid[5, t4, 0] and track.valid[5, t4, 1]
    assert np.isnan(track.positions[5, t4, 0]) and track.positions[5, t4, 1] == 17.42
    assert track.valid[5].sum() == 15
    assert not track.frame_valid()[5] and track.frame_valid(("MNI", "MNM"))[5]
    assert track.path == FIXTURES / "sample.txy"


def test_round_trip_exact_at_um_resolution(tmp_path):
    track = _track()
    back = read_txy(write_txy(tmp_path / "a.txy", track))
    np.testing.assert_array_equal(back.valid, track.valid)
    expected = np.round(track.positions * 1e3) / 1e3
    np.testing.assert_array_equal(back.positions, expected)
    np.testing.assert_array_equal(back.times, np.round(track.times * 1e6) / 1e6)
    # and a second trip is the identity
    again = read_txy(write_txy(tmp_path / "b.txy", back))
    np.testing.assert_array_equal(again.positions, back.positions)


def test_writer_conventions(tmp_path):
    track = pad_untracked(_track(n=3), 0)
    raw = write_txy(tmp_path / "a.txy", track).read_bytes()
    lines = raw.split(b"\r\n")
    assert lines[-1] == b"" and all(b"\n" not in s for s in lines)
    assert all(len(s.split(b"\t")) == 17 for s in lines[:-1])
    assert str(UNTRACKED).encode() in raw


def test_pad_untracked_starts_at_zero():
    track = _track(n=4)
    shifted = PelletTrack(track.times + 3 * FRAME_STEP_US * 1e-6, track.positions, track.valid)
    padded = pad_untracked(shifted, 3)
    assert padded.n_frames == 7 and abs(padded.times[0]) < 1e-12
    assert not padded.valid[:3].any()
    with pytest.raises(ValueError):
        pad_untracked(track, 1)


def test_writers_refuse_to_overwrite(tmp_path):
    track = _track()
    p = write_txy(tmp_path / "a.txy", track)
    with pytest.raises(OutputExistsError):
        write_txy(p, track)
    write_txy(p, track, overwrite=True)
    read_txy(p)  # now an input: even overwrite=True must refuse
    with pytest.raises(OutputExistsError, match="input"):
        write_txy(p, track, overwrite=True)


def test_whitespace_lf_bom_and_blank_lines(tmp_path):
    body = "\n".join(f"{t}  " + "   ".join(POSTURE) for t in (0, 6866)) + "\n\n  \n"
    track = read_txy(_write(tmp_path, "\ufeff" + body))
    expected = np.array([int(v) for v in POSTURE]).reshape(8, 2) / 1e3
    assert track.n_frames == 2 and np.all(track.positions == expected)


@pytest.mark.parametrize(
    "text, line, match",
    [
        (ROW + "\r\n6866\t1\t2\r\n", 2, "expected 17 fields"),
        (
            ROW + "\n" + ROW.replace("0\t", "6866\t", 1).replace("1000", "1e3", 1),
            2,
            "not an integer",
        ),
        (ROW + "\n" + ROW.replace("1000", "12.5", 1), 2, "not an integer"),
        (ROW + "\n" + ROW, 2, "does not increase"),
        (
            "\n\n" + ROW + "\n" + "9\t" + ROW[2:] + "\n" + ROW.replace("0\t", "5\t", 1),
            5,
            "increase",
        ),
        (ROW.replace("1000", "9" * 30, 1), 1, "out of range"),
    ],
)
def test_bad_input_names_file_and_line(tmp_path, text, line, match):
    p = _write(tmp_path, text)
    with pytest.raises(DataFormatError, match=match) as info:
        read_txy(p)
    assert info.value.line == line and info.value.path == str(p)
    assert str(info.value).startswith(f"{p}:{line}: ")


@pytest.mark.parametrize("content", [b"", b"\r\n\r\n  \n", b"\xef\xbb\xbf"])
def test_empty_file(tmp_path, content):
    with pytest.raises(DataFormatError, match="empty"):
        read_txy(_write(tmp_path, content))


def test_binary_garbage_names_line(tmp_path):
    with pytest.raises(DataFormatError, match="UTF-8") as info:
        read_txy(_write(tmp_path, (ROW + "\n").encode() + b"\xff\xfe\n"))
    assert info.value.line == 2


def test_no_tracked_value_and_missing_file(tmp_path):
    all_untracked = "\n".join(f"{t}\t" + "\t".join([str(UNTRACKED)] * 16) for t in (0, 6866))
    p = _write(tmp_path, all_untracked)
    with pytest.raises(MissingDataError, match=str(p)):
        read_txy(p)
    with pytest.raises(MissingDataError, match="no such file"):
        read_txy(tmp_path / "nope.txy")
    with pytest.raises(DataFormatError, match="folder"):
        read_txy(tmp_path)


def test_first_valid_frame_and_require_tracked(tmp_path):
    track = _track()
    valid = track.valid.copy()
    valid[:, 6, :] = True
    valid[:, 7, 1] = False  # MNM y never tracked
    valid[4, 7, 1] = True
    t = PelletTrack(track.times, track.positions, valid, path=tmp_path / "j.txy")
    assert first_valid_line(t, pellets=("MNI", "MNM")).index == 4
    require_tracked(t, ("MNI", "MNM"))
    valid[4, 7, 1] = False
    t = PelletTrack(track.times, track.positions, valid, path=tmp_path / "j.txy")
    with pytest.raises(MissingDataError, match=r"j\.txy.*MNM"):
        require_tracked(t)
    with pytest.raises(MissingDataError, match=r"j\.txy"):
        first_valid_line(t, pellets=("MNI", "MNM"))


def test_track_contract():
    track = _track()
    assert np.array_equal(np.isnan(track.positions), ~track.valid)
    with pytest.raises(ValueError):
        PelletTrack(track.times[:-1], track.positions, track.valid)
    with pytest.raises(ValueError, match="unknown pellet"):
        track.pellet("T5")
