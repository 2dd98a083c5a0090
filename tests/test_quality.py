"""Unmarked mistrack detection (each test must flag planted errors and nothing else) and reports."""

import json
import warnings

import numpy as np
import pytest

from cassi_fit.mistracks import Reason, detect_mistracks, mistrack_report
from cassi_fit.quality import quality_report
from cassi_fit.txy import FRAME_STEP_US, PELLET_NAMES, PelletTrack

MEDIANS = np.array(
    [[15, 18], [9, -21], [-17, 1], [-28, 7.5], [-39, 14.5], [-53, 17], [-1, -8], [-44, -3]]
)


def _speech_like(n=1500, seed=0, jaw_noise=0.3):
    """Smooth motion (peak speeds near 250 mm/s), a rigid jaw rotating about a far pivot."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * FRAME_STEP_US * 1e-6
    pos = np.repeat(MEDIANS[None].astype(float), n, axis=0)
    for k in range(6):  # lips and tongue: 4-6 Hz, amplitude up to 7 mm
        f, amp = 4 + 0.4 * k, 7.0
        pos[:, k, 0] += amp * np.sin(2 * np.pi * f * t + k)
        pos[:, k, 1] += amp * np.cos(2 * np.pi * f * t + 2 * k)
    theta = np.deg2rad(6) * (1 - np.cos(2 * np.pi * 3 * t))  # 0..12 degrees
    pivot = np.array([-95.0, 25.0])
    c, s = np.cos(theta), np.sin(theta)
    for k in (6, 7):
        d = MEDIANS[k] - pivot
        pos[:, k, 0] = pivot[0] + c * d[0] + s * d[1]
        pos[:, k, 1] = pivot[1] - s * d[0] + c * d[1]
    pos += rng.normal(scale=0.1, size=pos.shape)
    pos[:, 6:] += rng.normal(scale=jaw_noise / 2, size=(n, 2, 2))
    return t, pos


def _track(t, pos, valid=None):
    valid = np.ones(pos.shape, bool) if valid is None else valid
    return PelletTrack(t, pos, valid)


def test_clean_speech_has_no_flags():
    t, pos = _speech_like()
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max() / np.diff(t)[0]
    assert 200 < speed < 450  # the test data really is fast
    assert not detect_mistracks(_track(t, pos)).any()
    valid = np.ones(pos.shape, bool)
    valid[:30] = False  # leading untracked rows, and gaps: one-sided windows
    valid[500:520:2, 4] = False
    valid[800:900, 1] = False
    assert not detect_mistracks(_track(t, pos, valid)).any()


def test_planted_errors_are_found_and_only_them():
    t, pos = _speech_like(seed=1)
    expected = np.zeros((len(t), 8), bool)
    pos[100, 2] += [6.0, -4.0]  # one-frame spike on T1
    expected[100, 2] = True
    pos[400:402, 0] += [0.0, 8.0]  # two-frame excursion on UL
    expected[400:402, 0] = True
    pos[700, 5] = [-300.0, 17.0]  # far out of range on T4
    expected[700, 5] = True
    pos[900, 7] += [3.0, 0.0]  # MNM 3 mm off for one frame: the acceleration test names it
    expected[900, 7] = True
    valid = np.ones(pos.shape, bool)
    valid[1000:1010, 3] = False  # marked dropouts are not mistracks
    flags = detect_mistracks(_track(t, pos, valid))
    assert flags.shape == (len(t), 8)
    np.testing.assert_array_equal(np.argwhere(flags), np.argwhere(expected))


def test_jaw_threshold_floor_of_two_mm():
    """A slow slide of MNM away from MNI (no jump: only the jaw distance sees it) is
    flagged once it passes 2 mm, on both jaw pellets (the distance cannot say which)."""
    t, pos = _speech_like(seed=2, jaw_noise=0.02)  # tiny noise: 5 robust SD is far below 2 mm
    slide = np.zeros(len(t))
    slide[300:400] = np.linspace(0.0, 1.0, 100)
    slide[400:450] = 1.0
    pos[:, 7, 0] += 1.5 * slide  # up to 1.5 mm: within the floor
    assert not detect_mistracks(_track(t, pos))[:, 6:].any()
    pos[:, 7, 0] += 1.5 * slide  # up to 3 mm
    report = mistrack_report(_track(t, pos))
    deviation = 3.0 * slide  # along x; the distance changes by about as much
    assert report.flags[deviation > 2.4][:, 6:].all()
    assert not report.flags[deviation < 1.6].any()
    assert report.has(Reason.JAW_DISTANCE)[450 - 1, 6] and report.has(Reason.DRIFT)[420, 7]


def test_report():
    t, pos = _speech_like(n=600, seed=3)
    valid = np.ones(pos.shape, bool)
    valid[:10] = False
    valid[20:30, 2, 0] = False  # x of T1 only
    pos[200, 3] += [0.0, 9.0]
    track = PelletTrack(t, pos, valid)
    report = quality_report(track)
    assert report.n_frames == 600 and report.first_valid_frame == 10
    assert report.first_jaw_frame == 10
    assert report.valid_fraction["T1"] == pytest.approx(580 / 600)
    assert report.valid_fraction["UL"] == pytest.approx(590 / 600)
    assert report.all_valid_fraction == pytest.approx(580 / 600)
    assert report.never_tracked == ()  # all eight tracked somewhere: of all eight, as ever
    assert report.n_mistracked == {p: int(p == "T2") for p in PELLET_NAMES}
    assert 40 < report.jaw_distance_median_mm < 46
    assert 0.15 < report.jaw_distance_sd_mm < 0.5
    assert report.duration_s == pytest.approx(599 * FRAME_STEP_US * 1e-6)
    json.dumps(report.to_dict())  # machine-readable as is


def test_all_valid_is_over_the_pellets_the_file_tracks():
    """An articulograph file with one jaw sensor and three tongue sensors never tracks MNM
    and T4: ``all_valid_fraction`` is the share of frames with the six it tracks (the
    first valid line's set), not 0 for want of sensors it never had, and the report names
    the two."""
    t, pos = _speech_like(n=600, seed=4)
    valid = np.ones(pos.shape, bool)
    valid[:, [PELLET_NAMES.index("T4"), PELLET_NAMES.index("MNM")]] = False
    valid[:12] = False  # leading untracked lines
    valid[100:130, PELLET_NAMES.index("UL"), 1] = False  # y of UL only
    report = quality_report(PelletTrack(t, pos, valid))
    assert report.all_valid_fraction == pytest.approx(558 / 600)
    assert report.never_tracked == ("T4", "MNM")
    assert report.first_valid_frame == 12
    assert report.valid_fraction["MNM"] == 0.0 and report.valid_fraction["UL"] == pytest.approx(558 / 600)
    assert json.loads(json.dumps(report.to_dict()))["never_tracked"] == ["T4", "MNM"]
    nothing = quality_report(PelletTrack(t, pos, np.zeros(pos.shape, bool)))
    assert nothing.all_valid_fraction == 0.0 and nothing.never_tracked == PELLET_NAMES


def test_report_without_a_second_jaw_pellet():
    t, pos = _speech_like(n=50)
    valid = np.ones(pos.shape, bool)
    valid[:, 7] = False  # one jaw sensor (most EMA corpora): a first valid line, no jaw pair
    report = quality_report(PelletTrack(t, pos, valid))
    assert report.first_valid_frame == 0 and report.first_jaw_frame is None
    assert report.jaw_distance_median_mm is None and report.jaw_distance_sd_mm is None
    assert report.valid_fraction["MNM"] == 0.0


def test_single_frame():
    t, pos = _speech_like(n=1)
    assert not detect_mistracks(_track(t, pos)).any()
    assert quality_report(_track(t, pos)).duration_s == 0.0


def test_running_median_matches_nanmedian():
    from numpy.lib.stride_tricks import sliding_window_view

    from cassi_fit.mistracks import MEDIAN_WINDOW, running_median

    rng = np.random.default_rng(4)
    x = rng.normal(size=(60, 8, 2))
    x[rng.random(x.shape) < 0.5] = np.nan
    x[:7] = np.nan
    pad = np.full((MEDIAN_WINDOW // 2, 8, 2), np.nan)
    windows = sliding_window_view(np.concatenate([pad, x, pad]), MEDIAN_WINDOW, axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows
        expected = np.nanmedian(windows, axis=-1)
    np.testing.assert_array_equal(running_median(x), expected)


def test_jaw_outlier_blamed_on_the_pellet_that_jumped():
    t, pos = _speech_like(seed=5)
    pos[600, 7] += [0.0, 8.0]  # MNM jumps: the jump test names it, so MNI stays clean
    flags = detect_mistracks(_track(t, pos))
    assert flags[600, 7] and not flags[600, 6]
    assert flags.sum() == 1
