"""Hostile inputs of issue 12: mistracks on the first line, wrong units and geometry,
bad times. Each test fails without its check."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cassi_fit.errors import DataFormatError, MissingDataError
from cassi_fit.pellets import MistrackedFirstLineWarning, first_valid_line
from cassi_fit.quality import quality_report
from cassi_fit.txy import FRAME_STEP_US, PelletTrack, TimeGapWarning, read_txy

pytestmark = pytest.mark.filterwarnings("ignore::cassi_fit.dataset.DefaultHeadMeasuresWarning")

# A plausible rest posture (mm, pellet frame): UL, LL, T1..T4, MNI, MNM.
REST = np.array([[15.0, 18.0], [9.0, -21.0], [-17.0, 0.6], [-28.0, 7.5], [-39.0, 14.5],
                 [-53.0, 17.4], [-1.2, -8.2], [-43.5, -3.1]])


def make_track(n: int = 200, seed: int = 0, path=None) -> PelletTrack:
    """``n`` frames of small smooth movement around REST (a jaw that rotates slightly)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * FRAME_STEP_US * 1e-6
    wobble = 0.8 * np.sin(2 * np.pi * 2.0 * t)[:, None, None]
    pos = REST[None] + wobble * np.array([0.2, 1.0]) + rng.normal(0, 0.05, (n, 8, 2))
    return PelletTrack(times=t, positions=pos, valid=np.ones((n, 8, 2), bool), path=path)


def with_first_line_spike(track: PelletTrack, frame: int = 0, mm: float = 30.0) -> PelletTrack:
    pos = track.positions.copy()
    pos[frame, 6, 1] -= mm  # MNI 30 mm down on one line: a mistrack
    return PelletTrack(track.times, pos, track.valid, track.path)


# ---------------------------------------------------------------- 1. mistracks everywhere
def test_first_valid_line_skips_a_mistracked_first_line_and_says_so():
    track = with_first_line_spike(make_track())
    with pytest.warns(MistrackedFirstLineWarning, match="data line 2"):
        first = first_valid_line(track, "f.txy")
    assert first.index == 1
    with pytest.warns(MistrackedFirstLineWarning):
        assert first_valid_line(track).index == 1
    with pytest.warns(MistrackedFirstLineWarning):
        assert first_valid_line(track, pellets=("MNI", "MNM")).index == 1


def test_clean_first_line_is_unchanged_and_silent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert first_valid_line(make_track()).index == 0


def test_quality_report_shows_the_moved_reference():
    report = quality_report(with_first_line_spike(make_track(), frame=3))
    assert report.first_complete_frame == 0
    assert report.first_valid_frame == 0  # the spike is on line 4, not the first
    report = quality_report(with_first_line_spike(make_track(), frame=0))
    assert (report.first_complete_frame, report.first_valid_frame) == (0, 1)
    assert report.first_jaw_frame == 1


def test_no_clean_line_is_missing_data():
    track = make_track(5)
    pos = track.positions.copy()
    pos[:, 6] += 200.0  # MNI far outside the plausible box on every line
    with pytest.raises(MissingDataError, match="mistracked"):
        first_valid_line(PelletTrack(track.times, pos, track.valid))


# ---------------------------------------------------------------- 2. units and geometry
def _written(tmp_path, track: PelletTrack, name="t.txy", times_us=None):
    """The track as a pellet file, written by hand (no range limits, any times)."""
    path = tmp_path / name
    times_us = np.round(track.times * 1e6) if times_us is None else np.asarray(times_us)
    um = np.round(track.positions.reshape(track.n_frames, 16) * 1e3)
    rows = np.concatenate([times_us[:, None], um], axis=1).astype(np.int64)
    path.write_text("".join("\t".join(map(str, r)) + "\r\n" for r in rows.tolist()))
    return path


def scaled(track: PelletTrack, factor: float) -> PelletTrack:
    return PelletTrack(track.times, track.positions * factor, track.valid)


def test_plausible_track_reads(tmp_path):
    assert read_txy(_written(tmp_path, make_track())).n_frames == 200


@pytest.mark.parametrize(
    ("factor", "hint"), [(1e-3, "millimetres"), (50.0, "scaled"), (0.1, "units")]
)
def test_wrong_units_are_refused_naming_the_file(tmp_path, factor, hint):
    path = _written(tmp_path, scaled(make_track(), factor))
    with pytest.raises(DataFormatError, match=f"t.txy: median jaw pellet distance.*{hint}"):
        read_txy(path)
    assert read_txy(path, check=False).n_frames == 200  # the expert's way round


def test_swapped_x_and_y_are_refused(tmp_path):
    track = make_track()
    path = _written(tmp_path, PelletTrack(track.times, track.positions[..., ::-1], track.valid))
    with pytest.raises(DataFormatError, match="MNM in front of.*swapped"):
        read_txy(path)


def test_mirrored_front_to_back_is_refused(tmp_path):
    track = make_track()
    pos = track.positions * np.array([-1.0, 1.0])
    with pytest.raises(DataFormatError, match="in front of"):
        read_txy(_written(tmp_path, PelletTrack(track.times, pos, track.valid)))


def test_lips_upside_down_are_refused(tmp_path):
    track = make_track()
    pos = track.positions.copy()
    pos[:, [0, 1]] = pos[:, [1, 0]]
    with pytest.raises(DataFormatError, match="UL below lower lip"):
        read_txy(_written(tmp_path, PelletTrack(track.times, pos, track.valid)))


# ---------------------------------------------------------------- 3. time
def _times(n=200):
    return np.arange(n) * FRAME_STEP_US


@pytest.mark.parametrize(
    ("times", "line", "match"),
    [
        (_times() - 10_000_000, 1, "negative"),
        (np.r_[_times()[:-1], 9e15], 200, "beyond 10800 s"),
        (np.r_[_times()[:50], _times()[49], _times()[51:]], 51, "does not increase"),
        (np.r_[_times()[:50], _times()[60], _times()[51:]], 52, "does not increase"),
    ],
)
def test_bad_times_name_the_file_and_line(tmp_path, times, line, match):
    path = _written(tmp_path, make_track(), times_us=times)
    with pytest.raises(DataFormatError, match=f"t.txy:{line}: .*{match}"):
        read_txy(path)


def test_microsecond_frame_spacing_is_refused(tmp_path):
    path = _written(tmp_path, make_track(), times_us=np.arange(200))
    with pytest.raises(DataFormatError, match="frame spacing 1 us.*microseconds"):
        read_txy(path)


def test_a_one_hour_gap_is_refused_and_a_long_gap_warns(tmp_path):
    hour = np.r_[_times()[:100], _times()[100:] + 3_600_000_000]
    with pytest.raises(DataFormatError, match="t.txy:101: 3600 s gap"):
        read_txy(_written(tmp_path, make_track(), times_us=hour))
    gap = np.r_[_times()[:100], _times()[100:] + 5_000_000]
    with pytest.warns(TimeGapWarning, match=r"t.txy:101: 5.0 s gap"):
        read_txy(_written(tmp_path, make_track(), "t.txy", times_us=gap))


@pytest.mark.parametrize("bad", ["nan", "unsorted", "repeated"])
def test_pellet_track_refuses_bad_times(bad):
    track = make_track(10)
    times = track.times.copy()
    if bad == "nan":
        times[3] = np.nan
    elif bad == "unsorted":
        times[[3, 4]] = times[[4, 3]]
    else:
        times[4] = times[3]
    with pytest.raises(DataFormatError, match="pellet track"):
        PelletTrack(times, track.positions, track.valid)


def test_a_long_recording_is_not_refused():
    n = 200_000  # 23 minutes at 145.6 Hz: the smooth-pivot benchmark's size
    times = np.arange(n) * FRAME_STEP_US * 1e-6
    assert PelletTrack(times, np.zeros((n, 8, 2)), np.ones((n, 8, 2), bool)).n_frames == n


# ---------------------------------------------------------------- 4. non-regular files
@pytest.mark.parametrize("reader", ["txy", "palate", "headmeasures"])
def test_a_fifo_is_refused_without_blocking(tmp_path, reader):
    import os

    from cassi_fit.headmeasures import read_headmeasures
    from cassi_fit.outlines import read_outline

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    read = {"txy": read_txy, "palate": read_outline, "headmeasures": read_headmeasures}[reader]
    with pytest.raises(DataFormatError, match="pipe: not a regular file"):
        read(fifo)  # without the check, opening blocks forever (pytest-timeout-free: hangs)


# ---------------------------------------------------------------- 2b. outlines, head
PALATE = np.array([[-4.1, 4.0], [-9.9, 10.0], [-15.5, 14.0], [-22.0, 18.1], [-29.0, 21.5],
                   [-36.0, 24.0], [-43.1, 26.0], [-51.0, 26.8], [-60.0, 27.0]])


def _outline_file(tmp_path, points_mm, name="PAL.DAT"):
    path = tmp_path / name
    um = np.round(np.asarray(points_mm) * 1e3).astype(int)
    path.write_text("".join(f" {x:7d} {y:7d}\r\n" for x, y in um.tolist()))
    return path


def _zigzag():
    z = PALATE.copy()
    z[4, 0] = -5.0  # the fifth point jumps back to the front
    return z


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (PALATE[::-1], "PAL.DAT: the palate runs -55.9 mm.*reversed"),
        (PALATE[[0, 3, 1, 2, 4, 5, 6, 7, 8]], r"PAL.DAT:3: point 3 is .* in front"),
        (_zigzag(), r"PAL.DAT:5: point 5 is 17.0 mm in front"),
        (PALATE * 99, "PAL.DAT: .*scaled"),
        (PALATE / 1000, "PAL.DAT: .*millimetres"),
        (PALATE + [70.0, 0.0], r"PAL.DAT:1: point \(65.9, 4.0\) mm is outside"),
        (PALATE - [0.0, 40.0], r"PAL.DAT:1: .*is outside.*above"),
    ],
    ids=["reversed", "shuffled", "zigzag", "x100", "mm", "in-front", "below"],
)
def test_implausible_palates_are_refused(tmp_path, points, match):
    from cassi_fit.outlines import read_outline

    path = _outline_file(tmp_path, points)
    with pytest.raises(DataFormatError, match=match):
        read_outline(path)
    assert read_outline(path, check=False).shape == (9, 2)


def test_plausible_palate_and_pharynx_read(tmp_path):
    from cassi_fit.outlines import read_outline

    assert read_outline(_outline_file(tmp_path, PALATE)).shape == (9, 2)
    pha = _outline_file(tmp_path, [[-74.0, 18.0], [-70.0, -30.0]], "PHA.DAT")
    assert read_outline(pha, kind="pharynx").shape == (2, 2)
    front = _outline_file(tmp_path, [[10.0, 18.0], [12.0, -30.0]], "x_pha.dat")
    with pytest.raises(DataFormatError, match="x_pha.dat:1: .*behind the mouth"):
        read_outline(front, kind="pharynx")


HEADER = ("subject\tgonion_x\tgonion_y\tgnathion_x\tgnathion_y\tface_width\tjaw_width\t"
          "mouth_width\tupper_lip_thickness\tlower_lip_thickness\tnose_protrusion\n")
GOOD_ROW = ["-85", "-35", "0", "-43", "135", "100", "50", "15", "11.5", "20"]


@pytest.mark.parametrize(
    ("column", "value", "match"),
    [
        (4, "9999", "face_width: implausible value 9999 mm"),
        (4, "13.5", "face_width: .*centimetres"),
        (6, "0.05", "mouth_width: .*metres"),
        (0, "40", "gonion_x: .*in front of the face"),
        (2, "-90", "gnathion_x: implausible"),
    ],
)
def test_implausible_head_measures_name_file_line_and_value(tmp_path, column, value, match):
    from cassi_fit.headmeasures import read_headmeasures

    row = list(GOOD_ROW)
    row[column] = value
    path = tmp_path / "Headmeasures.txt"
    path.write_text(HEADER + "S01\t" + "\t".join(GOOD_ROW) + "\nS02\t" + "\t".join(row) + "\n")
    with pytest.raises(DataFormatError, match=f"Headmeasures.txt:3: S02 {match}"):
        read_headmeasures(path)
    assert set(read_headmeasures(path, check=False)) == {"S01", "S02"}


def test_fixtures_and_defaults_are_plausible():
    from pathlib import Path

    from cassi_fit.headmeasures import DEFAULT_HEAD_MEASURES, head_problem, read_headmeasures
    from cassi_fit.outlines import read_outline

    fixtures = Path(__file__).parent / "fixtures"
    assert head_problem(DEFAULT_HEAD_MEASURES) is None
    assert len(read_headmeasures(fixtures / "Headmeasures.txt")) == 2
    assert read_outline(fixtures / "PAL.DAT").shape == (9, 2)
    assert read_outline(fixtures / "PHA.DAT", kind="pharynx").shape == (2, 2)
    assert read_txy(fixtures / "sample.txy").n_frames == 7


def test_synthetic_corpus_passes_every_check(tmp_path):
    from cassi_fit.dataset import Dataset
    from cassi_fit.synth import generate_corpus

    root = generate_corpus(tmp_path / "corpus", n_subjects=4, seed=7, audio=False)
    ds = Dataset(root)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no gap, no moved first line either
        loaded = [ds.load(s, t) for s in ds.subjects() for t in ds.tasks(s)]
    assert len(loaded) == len(ds) > 0


# ---------------------------------------------------------------- 4. commands
def _subject_folder(tmp_path, name="t001.txy"):
    folder = tmp_path / "S01"
    folder.mkdir(exist_ok=True)
    return _written(folder, make_track(), name)


def _no_work(monkeypatch):
    """Any animation work fails the test: refusals must come before it."""
    import cassi_fit._cli.animate as cli_animate

    def forbidden(*args, **kwargs):
        raise AssertionError("the command started working before checking its outputs")

    monkeypatch.setattr(cli_animate, "run_args", forbidden)
    import cassi_fit._cli.export as cli_export

    monkeypatch.setattr(cli_export, "run_args", forbidden)


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--out", "{d}/a.png", "--penetration", "{d}/a.png"], "given twice as an output"),
        (["--out", "{d}/a.png", "--penetration", "{d}/PAL.DAT", "--force"],
         "PAL.DAT: refusing to"),
        (["--out", "{d}/link.png", "--force"], "refusing to overwrite an input file"),
    ],
    ids=["penetration-is-out", "penetration-is-palate", "out-links-to-input"],
)
def test_animate_refuses_colliding_outputs_before_work(tmp_path, monkeypatch, capsys, extra,
                                                        match):
    from cassi_fit import cli

    _no_work(monkeypatch)
    pellets = _subject_folder(tmp_path)
    palate = _outline_file(pellets.parent, PALATE)
    (pellets.parent / "link.png").symlink_to(pellets)
    before = {p: p.read_bytes() for p in (pellets, palate)}
    args = [a.format(d=pellets.parent) for a in extra]
    assert cli.main(["animate", str(pellets), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and match in err
    assert {p: p.read_bytes() for p in before} == before


def test_export_refuses_an_input_before_work(tmp_path, monkeypatch, capsys):
    from cassi_fit import cli

    _no_work(monkeypatch)
    pellets = _subject_folder(tmp_path)
    (pellets.parent / "link.glb").symlink_to(pellets)
    assert cli.main(["export", str(pellets), "--out", str(pellets.parent / "link.glb"),
                     "--force"]) == 2
    assert "refusing to overwrite an input file" in capsys.readouterr().err


def test_calibrate_without_recordings_fails_in_one_line(tmp_path, capsys):
    from cassi_fit import cli
    from cassi_fit.calibrate import calibrate_dataset

    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingDataError, match="no recordings"):
        calibrate_dataset(tmp_path / "empty")
    assert cli.main(["calibrate", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no recordings" in err
    assert not (tmp_path / "o").exists()


def test_names_differing_in_case_are_an_error_naming_both(tmp_path):
    from cassi_fit.dataset import Dataset

    _subject_folder(tmp_path, "TP101.TXY")
    _subject_folder(tmp_path, "tp101.txy")
    with pytest.raises(DataFormatError, match="S01: TP101.TXY and tp101.txy differ only in case"):
        Dataset(tmp_path)


def test_info_on_a_fifo_says_so(tmp_path, capsys):
    import os

    from cassi_fit import cli

    fifo = tmp_path / "S01" / "t001.txy"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    assert cli.main(["info", str(fifo)]) == 2
    assert "t001.txy: not a regular file" in capsys.readouterr().err


def test_info_reports_implausible_files_and_exits_non_zero(tmp_path, capsys):
    from cassi_fit import cli

    _subject_folder(tmp_path, "t001.txy")
    _written(tmp_path / "S01", scaled(make_track(), 1e-3), "t002.txy")
    assert cli.main(["info", str(tmp_path)]) == 2
    out = capsys.readouterr().out
    assert "t001" in out and "error:" not in out.split("t001")[1].split("\n")[0]
    assert "t002  error:" in out and "millimetres" in out


def _small_result():
    import cassi_fit.evaluate as ev

    settings = {"stride": 1, "jaw": "closed-form", "collisions": "off"}
    recs = [ev.RecordingRow.not_evaluated("S01", "tp040", "S01/tp040: bad",
                                          calibration="cassi", **settings)]
    subjects = [ev.SubjectRow.of_recordings("S01", recs, **settings)]
    return ev.EvaluationResult(recs, subjects, {**settings, "calibration": "cassi"})


def _interrupt_on_call(monkeypatch, target, attribute, n):
    """``target.attribute`` raises KeyboardInterrupt on its ``n``-th call (1-based)."""
    real = getattr(target, attribute)
    calls = []

    def fake(*args, **kwargs):
        calls.append(1)
        if len(calls) == n:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(target, attribute, fake)


def test_evaluate_tables_are_all_or_nothing(tmp_path, monkeypatch):
    import os

    from cassi_fit.evaluate import write_table

    _interrupt_on_call(monkeypatch, os, "fsync", 2)  # after the first file is complete
    with pytest.raises(KeyboardInterrupt):
        write_table(_small_result(), tmp_path)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    assert len(write_table(_small_result(), tmp_path)) == 3


def test_evaluate_report_is_all_or_nothing(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from cassi_fit.evaluate._report import write_report

    _interrupt_on_call(monkeypatch, Figure, "savefig", 1)  # the tables are done by then
    with pytest.raises(KeyboardInterrupt):
        write_report(_small_result(), tmp_path)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    names = sorted(p.name for p in write_report(_small_result(), tmp_path))
    assert names == sorted(p.name for p in tmp_path.iterdir()) and len(names) == 4


# ---------------------------------------------------------------- properties


def _posture(scale: float, angle_deg: float, shift) -> PelletTrack:
    """make_track's speaker resized, tilted and moved as real speakers differ."""
    track = make_track(40)
    a = np.deg2rad(angle_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    pos = track.positions @ rot.T * scale + np.asarray(shift)
    return PelletTrack(track.times, pos, track.valid)


speakers = dict(scale=st.floats(0.75, 1.3), angle_deg=st.floats(-12, 12),
                shift=st.tuples(st.floats(-4, 4), st.floats(-4, 4)))


@settings(max_examples=40, deadline=None)
@given(**speakers)
def test_property_every_plausible_speaker_passes(scale, angle_deg, shift):
    from cassi_fit.pellets import plausibility_problem

    assert plausibility_problem(_posture(scale, angle_deg, shift)) is None


@settings(max_examples=40, deadline=None)
@given(**speakers, error=st.sampled_from(["mm", "x10", "x50", "swap", "mirror"]))
def test_property_unit_and_axis_errors_never_pass(scale, angle_deg, shift, error):
    from cassi_fit.pellets import plausibility_problem

    track = _posture(scale, angle_deg, shift)
    pos = {"mm": track.positions / 1000, "x10": track.positions * 10,
           "x50": track.positions * 50, "swap": track.positions[..., ::-1],
           "mirror": track.positions * [-1.0, 1.0]}[error]
    assert plausibility_problem(PelletTrack(track.times, pos, track.valid)) is not None


def test_info_says_when_mistracks_moved_the_first_line(tmp_path, capsys):
    from cassi_fit import cli

    (tmp_path / "S01").mkdir()
    path = _written(tmp_path / "S01", with_first_line_spike(make_track()), "t001.txy")
    assert cli.main(["info", str(path)]) == 0
    assert "first valid frame 1 (moved from 0: mistracked)" in capsys.readouterr().out
