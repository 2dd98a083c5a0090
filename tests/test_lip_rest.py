"""An articulograph's lip sensors sit elsewhere on the lips than the X-ray microbeam pellets
the model's lip sites stand for: without a fitted calibration the lips are at rest where
the recording's first valid line has them (``SubjectState.lip_rest``), so sensors glued
nearer the lips' opening do not pull the model's lips through each other."""

import dataclasses

import numpy as np
import pytest
import zoo
from real_data import EMU_MO1, load_mo1, missing, real_data

from cassi_fit.pellets import LL, UL
from cassi_fit.pipeline import run_recording
from cassi_fit.txy import PelletTrack

STRIDE = 8  # every 8th line: enough frames to see the lips over the sentence


@pytest.fixture(scope="module")
def mview(tmp_path_factory):
    """One synthetic mview recording (one jaw sensor, three tongue sensors), read back."""
    return zoo.synthetic_mview(tmp_path_factory)


def _glued_nearer_the_opening(rec, up=-5.0, low=+15.0):
    """``rec`` with its upper-lip sensor ``up`` mm and its lower-lip sensor ``low`` mm
    higher on every line (the lips' motion unchanged): vermilion sensors, as mo1's."""
    track = rec.track
    pos = np.array(track.positions)
    pos[:, UL, 1] += up
    pos[:, LL, 1] += low
    return dataclasses.replace(rec, track=PelletTrack(track.times, pos, track.valid, track.path))


def _lips_crossing(run):
    return float(np.percentile(run.animation.penetration["lips_crossing"], 95))


def test_lip_sensors_glued_elsewhere_do_not_cross_the_model_lips(mview):
    assert mview.sensors is not None  # an articulograph recording
    moved = _glued_nearer_the_opening(mview)
    run = run_recording(moved, stride=STRIDE)
    state = run.state
    first = np.asarray(state.initial_params.upper_lip), np.asarray(state.initial_params.lower_lip)
    assert first[0][1] == pytest.approx(0.0, abs=1e-9)  # the lips at rest on the first line
    assert first[1][1] == pytest.approx(0.0, abs=1e-9)
    assert state.lip_rest is not None
    # the same sensors taken as X-ray microbeam pellets at the model's sites cross the lips
    as_pellets = run_recording(dataclasses.replace(moved, sensors=None), stride=STRIDE)
    assert as_pellets.state.lip_rest is None
    assert _lips_crossing(as_pellets) > 8.0
    assert _lips_crossing(run) < 1.0
    # the offsets are the sensors' heights above the sites: 20 mm more apart than glued
    unmoved = run_recording(mview, stride=STRIDE, stages=("initialize",)).state.lip_rest
    assert state.lip_rest[0] - unmoved[0] == pytest.approx(-5.0, abs=1e-6)
    assert state.lip_rest[1] - unmoved[1] == pytest.approx(15.0, abs=1e-6)
    assert any("lip sensors sit" in line for line in state.calibration_caveats)


def test_cassi_mode_keeps_the_papers_lip_sites(mview):
    state = run_recording(_glued_nearer_the_opening(mview), "cassi", stride=STRIDE,
                          stages=("initialize",)).state
    assert state.lip_rest is None


@pytest.mark.skipif(real_data(EMU_MO1) is None, reason=missing(EMU_MO1))
def test_the_real_ips_speakers_lips_no_longer_cross():
    # before: the lips crossed by 21 mm (95th percentile over the sentence); the lower-lip
    # sensor sits about 23 mm above the model's lower-lip site on the first line
    run = run_recording(load_mo1(), stride=STRIDE)
    assert run.state.lip_rest[1] > 15.0
    assert _lips_crossing(run) < 1.0
