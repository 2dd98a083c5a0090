"""An articulograph's tongue sensors are glued where the lab chose, not at the X-ray
microbeam pellet sites T1..T4 the model's tongue is driven at: the IPS Munich back sensor
``tb`` lies near the model's T4 site, yet its map reads it as T3. Outside CASSI mode each
tongue sensor is placed along the model's tongue by its distances from the one in front
(``SubjectState.tongue_sites``), and the tongue is driven through every sensor at that
point (``frames.tongue_drive``), instead of dragging the T3 site back onto a sensor that
lies behind it."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
import zoo
from real_data import EMU_MO1, load_mo1, missing, real_data

from cassi_fit.face_model import load_model
from cassi_fit.frames import tongue_drive, tongue_fill
from cassi_fit.pellets import MNM, T1, T3, T4
from cassi_fit.pipeline import run_recording
from cassi_fit.tongue import tongue_displacement
from cassi_fit.txy import PelletTrack

STRIDE = 8


def _site_s(model):
    s = np.asarray(model.fields["tongue_s"], float)
    return np.array([s[model.landmarks[k]] for k in ("T1", "T2", "T3", "T4")])


@pytest.mark.parametrize("tracked", [(1, 1, 1, 1), (1, 1, 1, 0), (1, 0, 1, 1), (0, 1, 1, 0),
                                     (1, 0, 0, 0)])
def test_sensors_at_the_sites_are_driven_as_xrmb_pellets(tracked):
    model = load_model()
    site_s = _site_s(model)
    w = tongue_drive(np.array(tracked, bool), site_s, site_s,
                     float(model.measures["tongue_anchor_s"]))
    np.testing.assert_allclose(w, tongue_fill(np.array(tracked, bool), site_s), atol=1e-12)


@pytest.mark.parametrize("anchor", ["follow", "fixed", "none"])
def test_the_tongue_passes_through_sensors_between_and_behind_the_sites(anchor):
    model = load_model()
    site_s, anchor_s = _site_s(model), float(model.measures["tongue_anchor_s"])
    sensor_s = np.array([site_s[0], 0.5 * (site_s[1] + site_s[2]) + 2.0, site_s[3] + 2.5, np.nan])
    tracked = np.array([1, 1, 1, 0], bool)
    w = tongue_drive(tracked, site_s, sensor_s, anchor_s, anchor)
    delta = np.random.default_rng(0).normal(size=(4, 2)) * 5.0
    field = np.asarray(tongue_displacement(jnp.asarray(sensor_s[:3]), jnp.asarray(site_s),
                                           jnp.asarray(w @ delta), anchor_s, anchor))
    np.testing.assert_allclose(field, delta[:3], atol=1e-4)


@pytest.fixture(scope="module")
def mview(tmp_path_factory):
    """One synthetic mview recording (the X-ray microbeam set of sensors), read back."""
    return zoo.synthetic_mview(tmp_path_factory, sensors=None)


def _back_sensor_read_as_t3(rec):
    """``rec`` as a lab with three tongue sensors and one jaw sensor records it, its back
    tongue sensor glued at XRMB's T4 site but read as T3 (as IPS Munich's ``tb``); the
    true T3 positions are returned beside it."""
    track = rec.track
    pos, valid = np.array(track.positions), np.array(track.valid)
    truth = pos[:, T3].copy()
    pos[:, T3], valid[:, T3] = pos[:, T4], valid[:, T4]
    for k in (T4, MNM):
        pos[:, k], valid[:, k] = np.nan, False
    roles = {**rec.sensors.roles, "T3": rec.sensors.roles["T4"], "T4": None, "MNM": None}
    return dataclasses.replace(
        rec, track=PelletTrack(track.times, pos, valid, track.path),
        sensors=dataclasses.replace(rec.sensors, roles=roles)), truth


def _t3_site_error(run, truth):
    """Median distance (mm) from the model's T3 site to the hidden true T3 sensor."""
    idx = run.animation.frame_index
    t3 = run.state.model.landmarks["T3"]
    model_t3 = np.asarray(run.animation.vertices)[:, t3, :2] / run.state.scale
    err = np.linalg.norm(model_t3 - truth[idx], axis=1)
    return float(np.nanmedian(err))


def test_a_back_sensor_behind_the_t3_site_drives_the_tongue_where_it_sits(mview):
    assert mview.sensors is not None  # an articulograph recording
    rec, truth = _back_sensor_read_as_t3(mview)
    run = run_recording(rec, stride=STRIDE)
    sites, site_s = run.state.tongue_sites, _site_s(run.state.model)
    assert sites[0] == pytest.approx(site_s[0]) and sites[3] is None
    # the back sensor is found near the T4 site, not at the T3 site its role names
    assert abs(sites[2] - site_s[3]) < abs(sites[2] - site_s[2])
    assert sites[2] > site_s[2] + 8.0
    assert any("tongue sensors" in line and "median distances" in line
               for line in run.state.calibration_caveats)
    # the model's T3 site, between the sensors, lands near the hidden true T3; read as
    # X-ray microbeam pellets (T3's site dragged onto the back sensor) it is a site away
    as_pellets = run_recording(dataclasses.replace(rec, sensors=None), stride=STRIDE)
    assert as_pellets.state.tongue_sites is None
    assert _t3_site_error(as_pellets, truth) > 9.0
    assert _t3_site_error(run, truth) < 4.0


def test_the_model_point_beside_each_tongue_sensor_is_where_it_sits(mview):
    """The model's point shown and compared beside the back sensor (``pellets_model``,
    the overlay's and the viewer's) is the tongue where that sensor sits, not the T3 site
    its role names, which lies a site in front of it."""
    rec, _ = _back_sensor_read_as_t3(mview)
    run = run_recording(rec, stride=STRIDE)
    anim = run.animation
    measured = np.asarray(anim.pellets_measured)[:, T3]
    beside = np.linalg.norm(np.asarray(anim.pellets_model)[:, T3] - measured, axis=1)
    t3_site = np.asarray(anim.vertices)[:, run.state.model.landmarks["T3"], :2]
    site_gap = np.linalg.norm(t3_site - measured, axis=1)
    assert np.nanmedian(beside) < 2.0 and np.nanmedian(site_gap) > 8.0
    # the tip sensor, taken at its own site, keeps the site
    np.testing.assert_allclose(
        np.asarray(anim.pellets_model)[:, T1],
        np.asarray(anim.vertices)[:, run.state.model.landmarks["T1"], :2], atol=1e-4)


def test_cassi_mode_keeps_the_papers_tongue_sites(mview):
    rec, _ = _back_sensor_read_as_t3(mview)
    state = run_recording(rec, "cassi", stride=STRIDE, stages=("initialize",)).state
    assert state.tongue_sites is None and state.tongue_note is None


def test_one_tongue_sensor_says_its_place_cannot_be_measured(mview):
    track = mview.track
    pos, valid = np.array(track.positions), np.array(track.valid)
    for k in range(T1 + 1, T4 + 1):
        pos[:, k], valid[:, k] = np.nan, False
    rec = dataclasses.replace(mview, track=PelletTrack(track.times, pos, valid, track.path))
    state = run_recording(rec, stride=STRIDE, stages=("initialize",)).state
    assert state.tongue_sites[1:] == (None, None, None)
    assert "cannot be measured" in state.tongue_note


@pytest.mark.skipif(real_data(EMU_MO1) is None, reason=missing(EMU_MO1))
def test_the_real_ips_speakers_back_sensor_no_longer_shuts_the_pharynx():
    # before: tb drove the T3 site, about 14 mm in front of where it lies; the tongue went
    # through the (template's) pharyngeal wall by 14.3 mm at the 95th percentile
    run = run_recording(load_mo1(), stride=STRIDE)
    site_s = _site_s(run.state.model)
    assert run.state.tongue_sites[2] > site_s[2] + 8.0  # tb: near T4, not at T3
    assert abs(run.state.tongue_sites[2] - site_s[3]) < 4.0
    assert np.percentile(np.asarray(run.animation.penetration["tongue_pharynx"]), 95) < 8.0
