"""An articulograph recording without a fitted calibration, with the run's ``lip_closure``
(off by default): the model's lips touch where its two lip sensors are nearest
(``lips.lips_touching``), their opening at a line the sensors' distance there less that
closing distance, instead of the first valid line being taken as the model's lips at rest
(which leaves the IPS speaker mo1's lips 7.3 mm apart in the speaker's bilabial closures). XRMB
recordings and CASSI mode keep the paper's lip sites."""

import dataclasses
import warnings

import numpy as np
import pytest
import zoo
from real_data import EMU_MO1, XRMB_JW11, load_mo1, missing, real_data

from cassi_fit.area_function import lip_opening, tract_geometry
from cassi_fit.dataset import load_recording
from cassi_fit.labels import Labels
from cassi_fit.lips import CLOSED_PERCENTILE, bilabial_lines, closing_distance
from cassi_fit.pellets import LL, MNI, UL
from cassi_fit.pipeline import run_recording


@pytest.fixture(scope="module")
def mview(tmp_path_factory):
    """One synthetic mview recording (one jaw sensor, three tongue sensors), read back."""
    return zoo.synthetic_mview(tmp_path_factory)


def _apart(rec) -> np.ndarray:
    """The upper-lip sensor's height above the lower-lip sensor per line (mm)."""
    p = np.asarray(rec.track.positions, np.float64)
    return p[:, UL, 1] - p[:, LL, 1]


def _jaw_hanging_lips_sealed(rec, drop=6.0, settle_s=0.3):
    """``rec`` with its jaw sensor ``drop`` mm lower on the first line, back where it was
    after ``settle_s`` (linearly), the lip sensors unchanged: a speaker who starts with
    the jaw hanging and the lips sealed (as mo1 before the first /m/), so that the first
    line's lips are not where the model's lips rest for that jaw."""
    track = rec.track
    pos = np.array(track.positions, np.float64)
    pos[:, MNI, 1] -= drop * np.clip(1.0 - (track.times - track.times[0]) / settle_s, 0, 1)
    return dataclasses.replace(rec, track=dataclasses.replace(track, positions=pos))


def _model_opening(run) -> np.ndarray:
    """The model's lip opening per frame (mm): the upper lip's lowest midsagittal point
    above the lower lip's highest (as ``experiments/acoustic_tract_diagnosis.py``)."""
    return lip_opening(tract_geometry(run.state.model), run.animation.vertices)


def test_the_closing_distance_is_a_low_percentile_of_the_tracked_lines(mview):
    d = _apart(mview)
    distance, when, (up, low) = closing_distance(mview.track)
    ok = np.isfinite(d)  # the synthetic lips are never mistracked
    assert distance == pytest.approx(np.percentile(d[ok], CLOSED_PERCENTILE))
    assert d[np.argmin(np.abs(mview.track.times - when))] <= distance
    assert 0 < up < low  # the lower lip, carried by the jaw, moves more
    valid = np.array(mview.track.valid)
    valid[:, UL] = False  # no upper-lip sensor: no closing distance
    assert closing_distance(dataclasses.replace(mview.track, valid=valid)) is None


def test_bilabial_labels_are_counted():
    tier = Labels(np.array([0.0, 0.1, 0.2]), np.array([0.1, 0.2, 0.3]), ("a", "m", "P"))
    times = np.arange(0.0, 0.3, 0.01)
    assert bilabial_lines((tier,), times) == 20
    assert bilabial_lines((), times) is None


def test_the_model_lips_touch_where_the_sensors_are_nearest(mview):
    rec = _jaw_hanging_lips_sealed(mview)
    run = run_recording(rec, stride=2, lip_closure=True)
    distance = closing_distance(rec.track)[0]
    d = _apart(rec)[run.animation.frame_index]
    opening = _model_opening(run)
    # the model's opening is the sensors' distance less the closing distance (scale 1:
    # one jaw sensor), the lips pressed together below it
    expected = np.maximum(run.state.scale * (d - distance), 0.0)
    assert np.median(np.abs(opening - expected)) < 0.3
    assert abs(np.median(opening[d <= distance])) < 0.5
    assert "the lips taken to touch where their sensors are nearest" in run.state.lip_note
    assert run.state.lip_note in run.state.calibration_caveats


@pytest.mark.skipif(real_data(EMU_MO1) is None, reason=missing(EMU_MO1))
def test_the_real_ips_speakers_lips_touch_in_the_speakers_bilabial_closures():
    # before: the model's lips 7.3 mm apart (median) in mo1's /p b m/, least 5.0 mm (7.0 at
    # this stride). Every 4th line (800 -> 200 frames, 17 of them in /p b m/): the frame
    # bucket of the synthetic run above (stride 2), so the two share their compiled
    # geometry; every line's run compiles its own for 1024 frames and takes four times as long
    rec = load_mo1()
    run = run_recording(rec, stride=4, lip_closure=True)
    labels = next(t for t in rec.labels if t.tier == "Segment")
    t = run.animation.times
    bilabial = np.zeros(t.shape, bool)
    for start, end, name in zip(labels.starts, labels.ends, labels.labels, strict=True):
        bilabial |= (name in ("p", "b", "m")) & (t >= start) & (t < end)
    assert np.median(_model_opening(run)[bilabial]) < 2.5
    assert "72 lines labelled /p b m/" in run.state.lip_note


def test_cassi_mode_keeps_the_papers_lip_sites(mview):
    state = run_recording(mview, "cassi", stages=("initialize",), lip_closure=True).state
    assert state.lip_note is None and state.lip_rest is None
    # off by default: the lips at rest on the first valid line
    state = run_recording(mview, stages=("initialize",)).state
    assert state.lip_note is None and state.lip_rest is not None


@pytest.mark.skipif(real_data(XRMB_JW11) is None, reason=missing(XRMB_JW11))
def test_xrmb_keeps_the_papers_lip_sites():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load_recording(next(real_data(XRMB_JW11).glob("*.txy")))
    state = run_recording(rec, stages=("initialize",), lip_closure=True).state
    assert state.lip_note is None and state.lip_rest is None


def test_the_command_line_turns_it_on():
    import argparse

    from cassi_fit._cli._options import add_model_arguments, spec_from_args

    parser = argparse.ArgumentParser()
    add_model_arguments(parser)
    assert spec_from_args(parser.parse_args(["--lip-closure"])).lip_closure
    assert not spec_from_args(parser.parse_args([])).lip_closure
