"""Hostile inputs of issue 12: mistracks on the first line, wrong units and geometry,
bad times. Each test fails without its check."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from cassi_fit.errors import DataFormatError, MissingDataError
from cassi_fit.pellets import MistrackedFirstLineWarning, first_valid_line
from cassi_fit.txy import FRAME_STEP_US, PelletTrack, first_valid_frame, read_txy, write_txy
from cassi_fit.quality import quality_report

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
        assert first_valid_frame(track) == 1
    with pytest.warns(MistrackedFirstLineWarning):
        assert first_valid_frame(track, ("MNI", "MNM")) == 1


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
