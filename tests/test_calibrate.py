"""Calibration recovers the synthetic truth, its files round-trip, animation uses it."""

import dataclasses
import json
import warnings

import jax
import numpy as np
import pytest
import zoo

from cassi_fit import calibrate
from cassi_fit.animate import animate
from cassi_fit.cli import main as cli
from cassi_fit.dataset import Dataset
from cassi_fit.errors import CassiError, DataFormatError, MissingDataError
from cassi_fit.face_model import load_model
from cassi_fit.initialize import initialize
from cassi_fit.synth import load_anatomy

N_SUBJECTS = 3


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return zoo.small_corpus(tmp_path_factory, n_subjects=N_SUBJECTS)


@pytest.fixture(scope="module")
def separate(corpus):
    with jax.enable_x64(True):
        return calibrate.calibrate_dataset(corpus, method="separate")


def _recordings(corpus, subject):
    ds = Dataset(corpus)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return [ds.load(subject, t) for t in ds.tasks(subject)]


def _errors(corpus, cal):
    truth = load_anatomy(corpus, cal.subject)
    return {
        "upper": cal.upper_lip_thickness / truth.upper_lip_thickness - 1.0,
        "lower": cal.lower_lip_thickness / truth.lower_lip_thickness - 1.0,
        "face": cal.face_width / truth.face_width - 1.0,
    }


def test_separate_calibration_recovers_lip_thickness_and_face_width_within_5_percent(
    corpus, separate
):
    assert sorted(separate) == [f"S{i:02d}" for i in range(1, N_SUBJECTS + 1)]
    for cal in separate.values():
        errors = _errors(corpus, cal)
        assert all(abs(e) < 0.05 for e in errors.values()), (cal.subject, errors)
        assert cal.converged and cal.method == "separate"
        assert cal.residuals["lips_in_teeth"] < 0.05
        # the jaw shape has 3 unknowns for 4 coordinates: close, not exact. Its targets are
        # the skin over the bony Headmeasures points (conformation.skin_landmarks, issue
        # 14): the synthetic chins lie up to 10 mm ahead of the model's, which two scales
        # and a turn about the incisor tip reach only within 10 mm.
        assert cal.residuals["gonion"] < 6.0 and cal.residuals["gnathion"] < 10.0
        assert cal.bounds_hit == ()  # the synthetic jaws are adult jaws
        # separate: the scale is the paper's p / d (median over the recordings)
        sites = np.asarray(load_model().vertices)[[2185, 2262], :2]
        assert cal.scale > 0 and np.isfinite(cal.scale)
        assert np.linalg.norm(sites[0] - sites[1]) > 0


def test_joint_calibration_also_recovers_the_truth_and_fits_the_scale(corpus, separate):
    with jax.enable_x64(True):
        cal = calibrate.calibrate_subject(_recordings(corpus, "S02"), method="joint")
    errors = _errors(corpus, cal)
    assert all(abs(e) < 0.05 for e in errors.values()), errors
    assert cal.method == "joint" and cal.converged
    # jointly the scale answers to every recording's jaw pellet distance: near p / d
    assert cal.scale == pytest.approx(separate["S02"].scale, rel=0.02)


def test_the_lip_estimate_is_each_first_line_and_their_least_squares_compromise(separate):
    cal = separate["S01"]
    observed = np.array(cal.observed["upper_lip_thickness"], float)
    assert len(observed) == len(cal.recordings) == len(cal.first_lines) == 3
    assert cal.upper_lip_thickness == pytest.approx(observed.mean(), abs=0.01)
    assert cal.residuals["upper_lip"] == pytest.approx(observed.std(), abs=0.01)


def test_the_penalty_keeps_an_implausible_lip_out_of_the_teeth(corpus):
    recs = _recordings(corpus, "S03")[:1]
    rec = recs[0]
    positions = np.array(rec.track.positions)
    positions[:, 0, 0] = -4.0  # the UL pellet behind the incisor tip: the lip in the teeth
    track = dataclasses.replace(rec.track, positions=positions)
    bad = [dataclasses.replace(rec, track=track)]
    with jax.enable_x64(True):
        free = calibrate.calibrate_subject(bad, collisions=False)
        held = calibrate.calibrate_subject(bad, collisions=True)
    assert free.residuals["lips_in_teeth"] > 1.0
    assert held.residuals["lips_in_teeth"] < 0.2 * free.residuals["lips_in_teeth"]
    assert held.upper_lip_thickness > free.upper_lip_thickness


def test_calibration_files_round_trip_and_bad_files_are_named(tmp_path, separate):
    cal = separate["S01"]
    path = calibrate.write_calibration(tmp_path / "S01.calibration.json", cal)
    back = calibrate.read_calibration(path)
    assert back == cal
    with pytest.raises(Exception, match="exists|input file"):
        calibrate.write_calibration(path, cal)
    assert calibrate.load_calibrations(tmp_path) == {"S01": cal}
    broken = tmp_path / "broken" / "S09.calibration.json"
    broken.parent.mkdir()
    broken.write_text('{"format": "cassi_fit calibration 1",\n "scale": }\n')
    with pytest.raises(DataFormatError, match=r"S09.calibration.json:2: invalid JSON"):
        calibrate.read_calibration(broken)
    data = json.loads(cal.to_json())
    data["params"]["jaw_shape_scale"] = [1.0]
    broken.write_text(json.dumps(data))
    with pytest.raises(DataFormatError, match="jaw_shape_scale"):
        calibrate.read_calibration(broken)
    data = json.loads(cal.to_json())
    data["scale"] = -1
    broken.write_text(json.dumps(data))
    with pytest.raises(DataFormatError, match="scale"):
        calibrate.read_calibration(broken)
    with pytest.raises(MissingDataError):
        calibrate.load_calibrations(tmp_path / "nowhere")


def test_animation_uses_the_calibration(corpus, separate):
    cal = separate["S01"]
    rec = _recordings(corpus, "S01")[0]
    with jax.enable_x64(True):
        state = initialize(rec, calibration=cal)
        anim = animate(state, rec, stride=20)
    assert state.scale == cal.scale
    v = np.asarray(load_model().vertices)
    model = state.model
    rest = np.asarray(
        __import__("cassi_fit.deform", fromlist=["deform"]).deform(model, state.conformation)
    )
    upper = rest[model.landmarks["UL"], 0] - rest[model.landmarks["upper_incisor_tip"], 0]
    assert upper / cal.scale == pytest.approx(cal.upper_lip_thickness, abs=1e-6)
    assert np.isfinite(np.asarray(anim.vertices)).all() and v.shape == rest.shape
    with pytest.raises(CassiError, match="of subject S01, not S02"):
        initialize(_recordings(corpus, "S02")[0], calibration=cal)
    with pytest.raises(CassiError, match="calibration"):
        initialize(rec, calibration="everything")


def test_cli_calibrate_writes_one_file_per_subject_and_animate_reads_them(
    corpus, tmp_path, capsys
):
    out = tmp_path / "cal"
    assert cli(["calibrate", str(corpus), "--out", str(out), "--subjects", "S01", "--quiet"]) == 0
    assert (out / "S01.calibration.json").is_file()
    assert (out / "calibration_summary.csv").read_text().startswith("subject,method,scale")
    assert "S01" in capsys.readouterr().out
    assert cli(["calibrate", str(corpus), "--out", str(out), "--subjects", "S01"]) == 2
    assert "exists" in capsys.readouterr().err
    png, depths = tmp_path / "s01.png", tmp_path / "depths.csv"
    args = ["animate", str(corpus), "S01", "tp040", "--calibration", str(out),
            "--collisions", "project", "--stride", "50", "--penetration", str(depths),
            "--out", str(png), "--size", "160x120"]
    assert cli(args) == 0 and png.is_file()
    assert "tongue_upper_front" in capsys.readouterr().out
    table = np.genfromtxt(depths, delimiter=",", names=True)
    assert len(table) > 5 and {"tongue_palate_mm", "lips_lower_teeth_after_mm"} <= set(
        table.dtype.names)
    after = [n for n in table.dtype.names if n.endswith("_after_mm")]
    assert max(float(table[n].max()) for n in after) < 0.01
    assert cli(args[:-4] + ["--cassi", "--out", str(png), "--force"]) == 2
    assert "exclude" in capsys.readouterr().err


def test_calibration_choice_reads_a_folder_or_a_file_and_excludes_cassi(tmp_path, separate):
    cal = separate["S01"]
    path = calibrate.write_calibration(calibrate.calibration_path(tmp_path, "S01"), cal)
    assert calibrate.calibration_choice(tmp_path, "s01") == cal
    assert calibrate.calibration_choice(path, "S02") == cal  # a file is taken as it is
    assert calibrate.calibration_choice(None, "S01") is None
    assert calibrate.calibration_choice(None, "S01", cassi=True) == "cassi"
    with pytest.raises(CassiError, match="exclude each other"):
        calibrate.calibration_choice(tmp_path, "S01", cassi=True)


def test_the_unknowns_are_named_and_flatten_in_their_documented_order():
    from jax.flatten_util import ravel_pytree

    x = calibrate.Unknowns(*map(np.float64, (1, 2, 3, 4, 5)), np.array([6.0, 7.0]))
    np.testing.assert_array_equal(ravel_pytree(x)[0], np.arange(1.0, 8.0))
    mask = calibrate.Unknowns.mask(("face_width", "log_jaw_scale"))
    np.testing.assert_array_equal(ravel_pytree(mask)[0], [0, 0, 0, 1, 0, 1, 1])
    assert calibrate.UNKNOWN_NAMES == tuple(f.name for f in dataclasses.fields(x))
    from cassi_fit.errors import InvalidChoiceError

    with pytest.raises(InvalidChoiceError, match="calibration method"):
        calibrate.calibrate_subject([object()], method="both")
