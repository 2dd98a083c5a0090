"""Labels: .lab (seconds and HTK units) and TextGrid round trips, tier choice, discovery,
every malformation naming file and line, and the per-segment jaw and lip summaries."""

from pathlib import Path

import numpy as np
import pytest

from cassi_fit.errors import DataFormatError, MissingDataError
from cassi_fit.labels import (
    LabelMismatchWarning,
    Labels,
    check_labels,
    label_path_for,
    labels_for,
    read_lab,
    read_labels,
    read_textgrid,
    segment_summary,
    write_lab,
    write_textgrid,
)
from cassi_fit.txy import PELLET_NAMES

LABELS = Labels([0.1, 0.25, 0.5], [0.25, 0.4, 0.9], ("p", "a", "t"), "phones")


def _same(a: Labels, b: Labels):
    assert a.labels == b.labels
    np.testing.assert_array_equal(a.starts, b.starts)
    np.testing.assert_array_equal(a.ends, b.ends)


@pytest.mark.parametrize("units", ["seconds", "htk"])
def test_lab_round_trip_and_unit_detection(tmp_path, units):
    path = write_lab(tmp_path / "x.lab", LABELS, units=units)
    text = path.read_text()
    assert ("2500000" in text) == (units == "htk")
    back = read_lab(path)  # units detected
    _same(back, Labels(LABELS.starts, LABELS.ends, LABELS.labels))
    assert back.path == path and back.tier == "labels"


def test_lab_units_rule_and_override(tmp_path):
    small = tmp_path / "small.lab"
    small.write_text("0 1 a\n1 2 b\n")  # integers below 1000: seconds
    assert read_lab(small).ends.tolist() == [1.0, 2.0]
    assert read_lab(small, units="htk").ends.tolist() == [1e-7, 2e-7]
    htk = tmp_path / "htk.lab"
    htk.write_text("0 2300000 sil score 1.0\n2300000 4100000 b\n")  # extra fields ignored
    lab = read_lab(htk)
    assert lab.ends.tolist() == [0.23, 0.41] and lab.labels == ("sil", "b")
    assert read_lab(htk, units="seconds").ends[0] == 2300000.0


def test_textgrid_round_trip_and_tier_choice(tmp_path):
    path = write_textgrid(tmp_path / "x.TextGrid", LABELS, duration=1.2)
    _same(read_textgrid(path), LABELS)
    assert read_textgrid(path).tier == "phones"
    # a second grid: "words" first, "Phones" second, a point tier: default is phones
    from praatio import textgrid
    from praatio.utilities.constants import Interval, Point

    grid = textgrid.Textgrid(0.0, 1.0)
    grid.addTier(textgrid.IntervalTier("words", [Interval(0.1, 0.9, "pat")], 0.0, 1.0))
    grid.addTier(textgrid.IntervalTier("Phones", [Interval(0.1, 0.3, "p"),
                                                  Interval(0.3, 0.9, "at")], 0.0, 1.0))
    grid.addTier(textgrid.PointTier("events", [Point(0.5, "x")], 0.0, 1.0))
    two = tmp_path / "two.TextGrid"
    grid.save(str(two), format="short_textgrid", includeBlankSpaces=True)
    assert read_textgrid(two).labels == ("p", "at")
    assert read_textgrid(two, tier="WORDS").labels == ("pat",)
    with pytest.raises(MissingDataError, match="no interval tier 'events'.*words, Phones"):
        read_textgrid(two, tier="events")


def test_at_and_segments():
    times = np.array([0.0, 0.1, 0.2499, 0.25, 0.45, 0.8999, 0.9, 5.0])
    assert LABELS.at(times).tolist() == ["", "p", "p", "a", "", "t", "", ""]
    assert [s.label for s in LABELS.segments()] == ["p", "a", "t"]
    assert LABELS.segments()[1].start == 0.25
    assert Labels([], [], ()).at(times).tolist() == [""] * 8


@pytest.mark.parametrize("text, line, words", [
    ("0.0 0.1 a\n0.1 x0.2 b\n", 2, "is not a number"),
    ("0.0 0.1 a\n\n0.3 0.2 b\n", 3, "before start"),
    ("0.0 0.5 a\n0.4 0.6 b\n", 2, "overlaps"),
    ("0.5 0.6 a\n0.1 0.2 b\n", 2, "not sorted"),
    ("0.0 0.1\n", 1, "expected 'start end label'"),
    ("0.0 nan a\n", 1, "non-finite"),
])
def test_malformed_lab_names_file_and_line(tmp_path, text, line, words):
    path = tmp_path / "bad.lab"
    path.write_text(text)
    with pytest.raises(DataFormatError, match=words) as info:
        read_labels(path)
    assert info.value.path == str(path) and info.value.line == line
    assert str(info.value).startswith(f"{path}:{line}: ")


def _grid_text(tmp_path) -> str:
    return write_textgrid(tmp_path / "good.TextGrid", LABELS).read_text()


def _line_of(text: str, needle: str) -> int:
    return next(k for k, s in enumerate(text.splitlines(), 1) if needle in s)


def test_malformed_textgrid_names_file_and_line(tmp_path):
    text = _grid_text(tmp_path)
    overlap = tmp_path / "overlap.TextGrid"
    overlap.write_text(text.replace("xmin = 0.25", "xmin = 0.2", 1))
    with pytest.raises(DataFormatError, match="overlaps") as info:
        read_textgrid(overlap)
    assert info.value.line == _line_of(overlap.read_text(), "xmin = 0.2 ")
    comma = tmp_path / "comma.TextGrid"
    comma.write_text(text.replace("xmax = 0.4", "xmax = 0,4", 1))
    with pytest.raises(DataFormatError, match="expected a number, got '0,4'") as info:
        read_textgrid(comma)
    assert info.value.line == _line_of(text, "xmax = 0.4")
    # a reversed blank interval, in the short format: praatio alone would drop it unchecked
    from praatio import textgrid

    textgrid.openTextgrid(str(tmp_path / "good.TextGrid"), False).save(
        str(tmp_path / "short.TextGrid"), format="short_textgrid", includeBlankSpaces=True)
    short = (tmp_path / "short.TextGrid").read_text()
    assert "\n0.4\n0.5\n\"\"\n" in short
    reversed_blank = tmp_path / "reversed.TextGrid"
    reversed_blank.write_text(short.replace("\n0.4\n0.5\n", "\n0.4\n0.3\n"))
    with pytest.raises(DataFormatError, match="before its start") as info:
        read_textgrid(reversed_blank)
    lines = reversed_blank.read_text().splitlines()  # the interval's start line, 1-based
    assert info.value.line == next(k for k in range(1, len(lines))
                                   if lines[k - 1:k + 1] == ["0.4", "0.3"])
    garbage = tmp_path / "garbage.TextGrid"
    garbage.write_text("this is not a TextGrid\n")
    with pytest.raises(DataFormatError, match="not a readable TextGrid") as info:
        read_textgrid(garbage)
    assert info.value.path == str(garbage)


def test_labels_record_refuses_bad_intervals():
    with pytest.raises(DataFormatError, match="overlaps"):
        Labels([0.0, 0.1], [0.2, 0.3], ("a", "b"))
    with pytest.raises(ValueError, match="2 starts"):
        Labels([0.0, 0.1], [0.2, 0.3], ("a",))


def test_write_lab_refuses_labels_it_cannot_hold(tmp_path):
    with pytest.raises(DataFormatError, match="white space"):
        write_lab(tmp_path / "x.lab", Labels([0.0], [1.0], ("two words",)))


def test_discovery_beside_pellet_file_any_case(tmp_path):
    pellet = tmp_path / "TP005.TXY"
    pellet.write_text("")
    assert label_path_for(pellet) is None and labels_for(pellet) is None
    write_lab(tmp_path / "tp005.lab", LABELS)
    assert labels_for(pellet).labels == LABELS.labels
    grid = write_textgrid(tmp_path / "Tp005.textgrid", Labels([0.0], [1.0], ("x",), "words"))
    assert label_path_for(pellet) == grid  # a TextGrid is preferred
    assert labels_for(pellet).labels == ("x",)
    assert label_path_for(tmp_path / "tp006.txy") is None


def _pellets(times, aperture):
    """Pellets (n, 8, 2) with UL straight above LL at ``aperture`` mm."""
    p = np.zeros((len(times), len(PELLET_NAMES), 2))
    p[:, PELLET_NAMES.index("UL"), 1] = aperture
    return p


def test_segment_summary_peaks_and_statuses():
    times = np.arange(0.0, 1.0, 0.01)
    theta = np.deg2rad(10.0 * np.sin(np.pi * times))  # peak 10 deg at t = 0.5
    aperture = 5.0 + 20.0 * np.abs(times - 0.3)  # minimum 5 mm at t = 0.3
    pellets = _pellets(times, aperture)
    pellets[times >= 0.795, PELLET_NAMES.index("LL")] = np.nan  # lips untracked from 0.8 s
    # bounds between frames (frames every 10 ms), so each segment's frames are certain
    labels = Labels([0.195, 0.395, 0.6051, 0.795], [0.395, 0.595, 0.6089, 0.955],
                    ("a", "b", "c", "d"))
    a, b, c, d = segment_summary(times, theta, pellets, labels)
    assert a["frames"] == 20 and a["status"] == "ok"
    assert a["lip_aperture_min_mm"] == pytest.approx(5.0)
    assert a["lip_aperture_min_time_s"] == pytest.approx(0.3)
    assert a["lip_aperture_max_mm"] == pytest.approx(7.0)  # at t = 0.2
    assert b["jaw_peak_opening_deg"] == pytest.approx(10.0)
    assert b["jaw_peak_time_s"] == pytest.approx(0.5)
    assert b["jaw_min_opening_deg"] == pytest.approx(10.0 * np.sin(np.pi * 0.4))
    assert c["frames"] == 0 and c["status"] == "no-frames"
    assert c["jaw_peak_opening_deg"] is None
    assert d["frames"] == 16 and d["status"] == "lips-untracked"
    assert d["lip_aperture_min_mm"] is None
    assert d["jaw_peak_opening_deg"] == pytest.approx(10.0 * np.sin(np.pi * 0.8))
    usable = times < 0.395
    rows = segment_summary(times, theta, pellets, labels, usable=usable)
    assert rows[1]["status"] == "jaw-untracked" and rows[1]["lip_aperture_min_mm"] > 0


def test_read_labels_refuses_other_suffixes(tmp_path):
    with pytest.raises(DataFormatError, match=".lab or .TextGrid"):
        read_labels(Path(tmp_path / "x.txt"))


def test_video_captions_carry_the_current_label():
    from types import SimpleNamespace

    from cassi_fit.recording_video import animation_frames, frame_caption

    n = 4
    animation = SimpleNamespace(
        vertices=np.zeros((n, 3, 3)), pellets_measured=np.zeros((n, 8, 2)),
        pellets_model=np.zeros((n, 8, 2)), frame_status=np.zeros(n, int),
        times=np.array([0.1, 0.2, 0.3, 0.4]), frame_index=np.arange(n), n_frames=n)
    captions = []

    class Recorder:
        def render(self, vertices, caption="", **kwargs):
            captions.append(caption)
            return np.zeros((2, 2, 3), np.uint8)

    labels = Labels([0.15, 0.3], [0.25, 0.5], ("pa", "ta"))
    list(animation_frames(animation, Recorder(), subject="S01", task="tp040",
                          progress=False, labels=labels))
    assert captions == [frame_caption("S01", "tp040", t, k, "ok", lab)
                        for k, (t, lab) in enumerate(zip(animation.times,
                                                         ("", "pa", "ta", "ta"), strict=True))]
    assert captions[1].endswith('"pa"') and '"' not in captions[0]


# ------------------------------------------- labels against the recording (issue 24)
JW11_LIKE = [(0.0, 0.752, "sil"), (0.752, 0.92, "s"), (0.92, 1.234, "a"), (1.234, 4.9, "s"),
             (4.9, 5.019, "a")]  # as the real JW11 task 5's labels: the last ends 5.019 s


@pytest.fixture
def five_seconds(tmp_path):
    """A 730-frame (5.01 s) pellet file, as JW11 task 5."""
    import zoo

    from cassi_fit.txy import PelletTrack, write_txy

    track, _ = zoo.recording("tp069", clean=True)  # the paragraph: longer than 730 frames
    k = slice(0, 730)
    short = PelletTrack(track.times[k], track.positions[k], track.valid[k])
    return write_txy(tmp_path / "tp005.txy", short)


def _lab(folder, rows, fmt) -> Path:
    path = folder / "tp005.lab"
    path.write_text("".join(f"{fmt(a)} {fmt(b)} {lab}\n" for a, b, lab in rows))
    return path


@pytest.mark.parametrize("fmt, cause", [
    (lambda s: str(round(s * 1000)), "milliseconds read as HTK"),  # integers >= 1000: htk
    (lambda s: f"{s * 1000:.1f}", "milliseconds read as seconds"),
    (lambda s: str(round(s * 16000)), "samples at 16000 Hz read as HTK"),
    (lambda s: f"{s * 16000:.1f}", "samples at 16000 Hz read as seconds"),
])
def test_labels_in_the_wrong_unit_are_one_error_naming_the_cause(five_seconds, fmt, cause):
    path = _lab(five_seconds.parent, JW11_LIKE, fmt)
    with pytest.raises(DataFormatError, match=rf"{path.name}: 5 labels span .* the recording "
                       rf"5\.012 s .*likely .*{cause}"):
        labels_for(five_seconds)
    with pytest.warns(LabelMismatchWarning, match=cause):
        labels = labels_for(five_seconds, accept_mismatch=True)  # kept as they are
    assert len(labels) == 5


def test_labels_that_fit_pass_silently(five_seconds):
    import warnings

    _lab(five_seconds.parent, JW11_LIKE, lambda s: f"{s:g}")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(labels_for(five_seconds)) == 5  # 5.019 s against 5.012 s: fits
    check = check_labels(labels_for(five_seconds), 5.012)
    assert check.status == "ok" and check.message is None


def test_labels_past_the_end_warn_with_the_numbers(five_seconds):
    rows = [*JW11_LIKE, (5.019, 6.0, "s"), (6.0, 7.5, "a")]
    _lab(five_seconds.parent, rows, lambda s: f"{s:g}")
    with pytest.warns(LabelMismatchWarning, match=r"7 labels span 0-7\.5 s, the recording "
                      r"5\.012 s \(2 start after its end\)"):
        labels = labels_for(five_seconds)
    assert len(labels) == 7
    with pytest.warns(LabelMismatchWarning):
        check = check_labels(labels, 5.012)
    assert (check.status, check.n_past_end) == ("past-end", 2)


def test_a_partial_labelling_is_not_a_mismatch():
    check = check_labels(Labels([1.0, 1.2], [1.2, 1.5], ("p", "a")), 5.0)
    assert check.status == "ok"


# ------------------------------------------------------------- ESPS/xwaves label files
ESPS_HEADER = ("signal fsew0_001\ntype 0\ncolor 121\ncomment hand-made\n"
               "font -misc-*-bold-*-*-*-15-*-*-*-*-*-*-*\nseparator ;\nnfields 1\n#\n")


def test_an_esps_label_file_is_read_as_the_intervals_it_ends(tmp_path):
    """Festival's and the CSTR corpora's ``.lab`` (CMU ARCTIC's too): a header ended by
    ``#``, then ``end colour label``: each label ends its interval, which starts where the
    one before ended; a line without a label is blank silence, not a segment."""
    from cassi_fit.labels import read_lab

    path = tmp_path / "fsew0_001.lab"
    path.write_text(ESPS_HEADER + "    0.2500  125 sil\n    0.2800  125 breath\n"
                    "    0.3500  125\n    0.4200  125 dh\n    0.5000  125 i\n"
                    "    1000  125 ii\n")  # a whole number of seconds stays seconds
    labels = read_lab(path)
    np.testing.assert_allclose(labels.starts, [0.0, 0.25, 0.35, 0.42, 0.5])
    np.testing.assert_allclose(labels.ends, [0.25, 0.28, 0.42, 0.5, 1000.0])
    assert labels.labels == ("sil", "breath", "dh", "i", "ii")
    assert labels.at(np.array([0.3, 0.4])).tolist() == ["", "dh"]


@pytest.mark.parametrize("body, line, problem", [
    ("0.25 125 sil\n0.1x 125 a\n", 10, "not a number"),
    ("0.25 125 sil\n0.10 125 a\n", 10, "before"),  # times must not go back
    ("0.25 125 sil\n0.30\n", 10, "expected 'end colour label'"),
])
def test_a_bad_esps_line_is_one_error_naming_it(tmp_path, body, line, problem):
    from cassi_fit.labels import read_lab

    path = tmp_path / "bad.lab"
    path.write_text(ESPS_HEADER + body)
    with pytest.raises(DataFormatError, match=rf"bad.lab:{line}: .*{problem}") as err:
        read_lab(path)
    assert "\n" not in str(err.value)
