"""The synthetic EMA corpus (cassi_fit.ema.synthetic) read back through the toolkit: in
every format, head correction and the bite-plane frame recover the known head movement
and the 2D midsagittal positions within the files' rounding; without the head correction
they would not (so the test fails if the correction is removed)."""

import json
import warnings

import numpy as np
import pytest

from cassi_fit import cli
from cassi_fit._cli.synth import FORMATS as CLI_FORMATS
from cassi_fit.dataset import Dataset, DefaultHeadMeasuresWarning
from cassi_fit.ema.sensor_map import SensorMap
from cassi_fit.ema.synthetic import FORMATS, ROLE_NAMES, load_ema_truth, write_ema_corpus
from cassi_fit.pellets import PELLET_NAMES
from cassi_fit.synth import generate_corpus

TASK = "tp011"
# float32 files (EST binary, .pos) round positions of ~200 mm to ~1e-5 mm; Wave exports
# keep 4 decimals; the truth table 6.
TOLERANCE_MM = {"est": 1e-4, "est-ascii": 1e-5, "ag501": 1e-4, "wave": 3e-4, "mview": 1e-5,
                "emu": 1e-4}


@pytest.fixture(scope="module")
def corpora(tmp_path_factory):
    root = tmp_path_factory.mktemp("ema")
    xrmb = generate_corpus(root / "xrmb", n_subjects=1, tasks=TASK)  # measured 5 times
    return {fmt: write_ema_corpus(root / fmt, format=fmt, from_corpus=xrmb) for fmt in FORMATS}


def _load(folder, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return Dataset(folder, **kw).load("S01", TASK)


def test_cli_offers_the_same_formats():
    assert CLI_FORMATS == ("xrmb", *FORMATS)


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_positions_and_head_movement_recovered(corpora, fmt):
    rec = _load(corpora[fmt])
    truth = load_ema_truth(corpora[fmt], "S01", TASK)
    report = rec.sensors
    assert report.format == ("ag501" if fmt == "ag501" else fmt.split("-")[0])
    assert report.rate_hz == FORMATS[fmt][1] and rec.track.frame_step_s == pytest.approx(
        1 / FORMATS[fmt][1])
    np.testing.assert_allclose(rec.track.times, truth.times, atol=1e-6)
    for j, role in enumerate(PELLET_NAMES):
        want = truth.positions[ROLE_NAMES[role]]
        got = rec.track.positions[:, j]
        np.testing.assert_array_equal(np.isfinite(got).all(-1), np.isfinite(want).all(-1))
        both = np.isfinite(want).all(-1)
        np.testing.assert_allclose(got[both], want[both], atol=TOLERANCE_MM[fmt], rtol=0)
    lc = np.isfinite(truth.positions["LC"]).all(-1)  # a sensor is tracked as a whole
    np.testing.assert_array_equal(rec.track.extra_valid[:, 0].all(-1), lc)
    np.testing.assert_allclose(rec.track.extra("LC")[lc], truth.positions["LC"][lc],
                               atol=TOLERANCE_MM[fmt], rtol=0)
    # the head movement: toolkit = F (R_t p + t_t - o) must undo p = Rh_t (M q + o0) + th_t
    fits = report.head_fits
    undo = np.linalg.inv(truth.device_from_toolkit) @ np.swapaxes(truth.head_rotation, 1, 2)
    keep = fits.ok  # every frame but an EMU export's padded end (no reference tracked)
    assert keep.sum() == len(keep) - (40 if fmt == "emu" else 0)
    np.testing.assert_allclose((report.frame_rotation @ fits.rotation)[keep], undo[keep],
                               atol=2e-6)
    assert np.nanmax(report.head_rotation_deg) > 1.0  # there was movement to remove
    assert np.nanmax(report.head_residual_mm) < 10 * TOLERANCE_MM[fmt]
    assert report.midsagittal_distance_mm["LC"] == pytest.approx(25.0, abs=1e-3)
    assert report.midsagittal_distance_mm["LMA"] == pytest.approx(52.0, abs=1e-3)
    assert "bite plane" in report.frame_source and report.bite_plane.endswith("bite" + FORMATS[
        fmt][0])


def test_without_head_correction_the_positions_are_off(corpora):
    smap = SensorMap(references=())  # no references: nothing removes the head movement
    rec = _load(corpora["est"], sensor_map=smap)
    truth = load_ema_truth(corpora["est"], "S01", TASK)
    assert rec.sensors.head_correction.startswith("none")
    assert any("assumed not to have moved" in n for n in rec.sensors.notes)
    err = np.nanmax(np.abs(rec.track.positions[:, 0] - truth.positions["UL"]))
    assert err > 1.0


def test_mview_keeps_the_sound_aside_and_the_corpus_has_its_truth(corpora):
    rec = _load(corpora["mview"])
    assert any("AUDIO" in n for n in rec.sensors.notes)
    assert rec.audio is not None and rec.audio.name.lower() == f"{TASK}.wav"
    folder = corpora["mview"] / "S01"
    assert {"PAL.DAT", "PHA.DAT", "anatomy.json", f"{TASK}.truth.csv", "frame.json"} <= {
        p.name for p in folder.iterdir()}
    assert rec.palate is not None and not rec.head_is_default
    assert Dataset(corpora["mview"]).tasks("S01") == [TASK]  # bite.mat is not a task


def test_cassi_synth_and_info_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "pos"
    assert cli.main(["synth", str(out), "--format", "ag501", "--subjects", "1", "--tasks",
                     TASK, "--no-audio"]) == 0
    assert (out / "S01" / f"{TASK}.pos").is_file() and (out / "S01" / "sensors.toml").is_file()
    capsys.readouterr()
    assert cli.main(["info", str(out / "S01" / f"{TASK}.pos"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    truth = load_ema_truth(out, "S01", TASK)
    want = np.nanmedian(truth.positions["UL"], axis=0)
    np.testing.assert_allclose(report["median_mm"]["UL"], want, atol=0.01)
    assert report["sensors"]["roles"]["MNI"] == "LI" and report["format"] == "ag501"
    assert cli.main(["info", str(out / "S01" / f"{TASK}.pos")]) == 0
    text = capsys.readouterr().out
    assert "head correction: rigid, 4 references" in text and "occlusal frame: bite plane" in text
    assert cli.main(["synth", str(out), "--format", "ag501", "--subjects", "1", "--tasks",
                     TASK]) == 2  # an existing corpus is refused without --force
