"""An articulograph recording without a palate trace: the palate from its tongue sensors'
upper envelope (``palate.envelope_palate``). A tongue sensor never passes above the palate
and the tongue reaches it in closures: the default centreline's heights are scaled by the
least factor that leaves every tongue sensor on or below it. XRMB's ``PAL.DAT`` and CASSI
mode keep theirs."""

import dataclasses
import warnings

import numpy as np
import pytest
import zoo
from real_data import EMU_MO1, XRMB_JW11, load_mo1, missing, real_data

from cassi_fit.area_function import tract_geometry
from cassi_fit.dataset import load_recording
from cassi_fit.palate import DEFAULT_OUTLINE, N_HARD, envelope_factor
from cassi_fit.pellets import T1, T4
from cassi_fit.pipeline import run_recording


def _height(outline, x):
    return np.interp(-np.asarray(x), -outline[:, 0], outline[:, 1])


def test_the_factor_is_the_lowest_palate_no_point_passes_above():
    rng = np.random.default_rng(0)
    truth = DEFAULT_OUTLINE * np.array([1.0, 0.8])
    x = rng.uniform(-58.0, -6.0, 300)
    below = np.stack([x, _height(truth, x) - rng.uniform(0.5, 15.0, 300)], -1)
    touching = np.array([[-30.0, _height(truth, -30.0)]])
    ignored = np.array([[5.0, 40.0], [-75.0, 40.0], [np.nan, 90.0]])  # ahead, behind, NaN
    points = np.concatenate([below, touching, ignored])
    factor, k = envelope_factor(points)
    assert factor == pytest.approx(0.8, abs=1e-12) and k == len(below)
    # a sensor above the default palate raises it: none may pass above
    factor, _ = envelope_factor(np.array([[-30.0, _height(DEFAULT_OUTLINE, -30.0) + 2.0]]))
    assert factor > 1.0
    assert envelope_factor(ignored) is None


def _tongue_points(rec, scale):
    pos = scale * np.asarray(rec.track.positions, float)[:, T1:T4 + 1]
    ok = np.asarray(rec.track.valid)[:, T1:T4 + 1].all(-1)
    return pos[ok]


def _midline(state):
    """The model's hard-palate midline (N_HARD, 2) model mm, front to back."""
    return np.asarray(tract_geometry(state.model).palate)[:N_HARD]


def _highest_above_palate(state, points):
    """The tongue sensors' greatest height above the model's hard-palate midline (mm)."""
    pal = _midline(state)
    under = (points[:, 0] <= pal[0, 0]) & (points[:, 0] >= pal[-1, 0])
    return float(np.max(points[under, 1] - _height(pal, points[under, 0])))


@pytest.fixture(scope="module")
def mview(tmp_path_factory):
    """One synthetic mview recording (one jaw sensor, three tongue sensors), read back: an
    articulograph recording without a palate trace."""
    return zoo.synthetic_mview(tmp_path_factory)


def test_the_palate_rests_on_the_tongue_sensors_upper_envelope(mview):
    assert mview.sensors is not None and mview.palate is not None  # the synthetic truth
    rec = dataclasses.replace(mview, palate=None)  # a lab without a palate trace
    state = run_recording(rec, stages=("initialize",)).state
    points = _tongue_points(rec, state.scale)
    # the highest sensor touches the palate's midline, none passes above it (the hard
    # palate's rows stand at the teeth's stations: the midline between rows is a chord)
    assert abs(_highest_above_palate(state, points)) < 0.3
    assert any("palate estimated from the tongue sensors' upper envelope: no palate trace"
               in line for line in state.calibration_caveats)
    # nearer the speaker's palate than the default (the synthetic tongue stays about 1 mm
    # below it): within 1.6 mm of it everywhere, where the default is 3.3 mm off at the back
    truth = state.scale * mview.palate
    off = lambda pal: np.abs(_midline(pal)[:, 1] - _height(truth, _midline(pal)[:, 0]))  # noqa: E731
    default = run_recording(rec, "cassi", stages=("initialize",)).state
    assert default.palate_note is None  # CASSI mode: the paper's default palate
    assert off(state).max() < 0.6 * off(default).max()
    assert np.median(off(state)) <= np.median(off(default))


def test_a_mistracked_spike_does_not_lift_the_palate(mview):
    rec = dataclasses.replace(mview, palate=None)
    clean = run_recording(rec, stages=("initialize",)).state
    positions = np.array(rec.track.positions, np.float64)
    positions[200, T1 + 1, 1] += 25.0  # one line's T2 flies 25 mm up, into the skull
    spiked = dataclasses.replace(rec, track=dataclasses.replace(rec.track, positions=positions))
    state = run_recording(spiked, stages=("initialize",)).state
    assert state.palate_note == clean.palate_note
    np.testing.assert_array_equal(_midline(state), _midline(clean))


@pytest.mark.skipif(real_data(EMU_MO1) is None, reason=missing(EMU_MO1))
def test_the_real_ips_speakers_palate_comes_down_to_his_tongue():
    # before: the default palate, 6.5 mm above the highest tongue sensor (tm at rest), 7.8
    # mm above the tip sensor even in /d n l/ closures
    rec = load_mo1()
    state = run_recording(rec, stages=("initialize",)).state
    assert abs(_highest_above_palate(state, _tongue_points(rec, state.scale))) < 0.3
    assert "x0.72" in state.palate_note and "tm touches it" in state.palate_note


@pytest.mark.skipif(real_data(XRMB_JW11) is None, reason=missing(XRMB_JW11))
def test_a_palate_trace_is_kept():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load_recording(next(real_data(XRMB_JW11).glob("*.txy")))
    state = run_recording(rec, stages=("initialize",)).state
    assert rec.palate is not None and state.palate_note is None
    pal = np.asarray(tract_geometry(state.model).palate)[:N_HARD]
    trace = state.scale * np.asarray(rec.palate, float)
    assert np.median(np.abs(pal[:, 1] - _height(trace, pal[:, 0]))) < 0.5


def test_cassi_acoustics_says_the_palate_was_estimated(mview, tmp_path, capsys, monkeypatch):
    import shutil
    import wave

    from cassi_fit import acoustics, cli
    from cassi_fit.errors import CassiError

    folder = tmp_path / "corpus"
    shutil.copytree(mview.path.parent.parent, folder)
    (folder / mview.path.parent.name / "PAL.DAT").unlink()  # a lab without a palate trace
    path = folder / mview.path.parent.name / mview.path.name
    # without a sound nothing can be measured: said before the model is run
    assert cli.main(["acoustics", str(path)]) != 0
    out, err = capsys.readouterr()
    assert "no sound" in err and "calibration:" not in out
    seconds = float(mview.track.times[-1]) + 0.05
    with wave.open(str(path.with_suffix(".wav")), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(16000)
        t = np.arange(int(seconds * 16000)) / 16000
        w.writeframes((3000 * np.sin(2 * np.pi * 150 * t)).astype("<i2").tobytes())
    # the dataset folder of this one recording stands for it, said in one line; the
    # model's formants (tested in test_acoustics) are not computed here
    def measured_elsewhere(*args, **kwargs):
        raise CassiError("formants not computed in this test")

    monkeypatch.setattr(acoustics, "recording_acoustics", measured_elsewhere)
    assert cli.main(["acoustics", str(folder), "--stride", "4"]) == 2
    out, err = capsys.readouterr()
    assert "formants not computed in this test" in err
    assert f"{folder}: a dataset of one recording: S01 tp040" in err
    assert "calibration: palate estimated from the tongue sensors' upper envelope" in out
