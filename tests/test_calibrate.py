"""Calibration recovers the synthetic truth as docs/generated/calibration_recovery.md says,
its files round-trip, animation uses it.

The module's corpus is the first three subjects of the documented one (same seed, same
tasks, and a subject's data depend only on seed, subject and task), so the per-subject
numbers the docs quote must come out again here, to their printed precision; the bounds
(worst errors, residual ranges) are the documented, measured ones, not tolerances chosen to
pass. Re-run ``make experiments`` when the calibration changes, and these move with it.
"""

import dataclasses
import json
import re
import sys
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest
import zoo

from cassi_fit import calibrate, calibrate_residuals, calibration
from cassi_fit.animate import animate
from cassi_fit.calibration import CalibrationWarning
from cassi_fit.cli import main as cli
from cassi_fit.dataset import Dataset
from cassi_fit.deform import deform
from cassi_fit.errors import CassiError, DataFormatError, MissingDataError
from cassi_fit.face_model import load_model
from cassi_fit.initialize import initialize
from cassi_fit.pellets import MNI, MNM, first_valid_line
from cassi_fit.synth import load_anatomy

N_SUBJECTS = 3
ROOT = Path(__file__).resolve().parents[1]
RECOVERY = ROOT / "docs" / "generated" / "calibration_recovery.md"
sys.path.insert(0, str(ROOT / "experiments"))
import subject_rows as sf  # noqa: E402


def _doc_tables(path):
    """Every Markdown table of ``path``: a list of tables, each a list of {header: cell}."""
    tables, block = [], []
    for line in [*path.read_text(encoding="utf-8").splitlines(), ""]:
        if line.startswith("|"):
            block.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif block:
            tables.append([dict(zip(block[0], row, strict=True)) for row in block[2:]])
            block = []
    return tables


@pytest.fixture(scope="module")
def documented():
    """(per method summary row, per subject row) of the generated recovery tables."""
    summary, per_subject = _doc_tables(RECOVERY)
    return {r["method"]: r for r in summary}, {r["subject"]: r for r in per_subject}


def _half_unit(cell):
    """Half a unit of the last printed digit of ``cell``: a documented bound is the
    measured number rounded, so the measured number may exceed the print by this much."""
    return 0.5 * 10.0 ** -len(cell.split(".")[1]) if "." in cell else 0.5


def _bound(cell):
    """The largest value a printed upper bound ``cell`` stands for."""
    return float(cell) + _half_unit(cell)


def _span(cell):
    lo, hi = cell.split("-")
    return float(lo) - _half_unit(lo), _bound(hi)


def test_the_module_corpus_is_the_documented_one():
    # the comparison with the docs' per-subject numbers rests on this
    assert tuple(zoo.SMALL_CORPUS_TASKS) == sf.FULL.tasks and sf.SEED == 0
    assert N_SUBJECTS <= sf.FULL.n_subjects


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


def _errors(corpus, cal, model):
    """Signed lip errors (percent, and mm for the lower lip), the face width's difference
    from Headmeasures (percent) and the tip-offset difference (subject mm), from the truth
    in ``anatomy.json``, computed here independently of the experiment's code."""
    truth = load_anatomy(corpus, cal.subject)
    v = np.asarray(model.vertices)[:, :2]
    mni, mnm, tip = (v[model.landmarks[k]] for k in ("MNI", "MNM", "lower_incisor_tip"))
    p = np.linalg.norm(mni - mnm)
    forward = (truth.mni_rest - truth.mnm_rest) / truth.jaw_pellet_distance
    true_ahead = np.dot(truth.lower_incisor_tip_rest - truth.mni_rest, forward)
    model_ahead = np.dot(tip - mni, (mni - mnm) / p) * truth.jaw_pellet_distance / p
    return {
        "upper": 100 * (cal.upper_lip_thickness / truth.upper_lip_thickness - 1.0),
        "lower": 100 * (cal.lower_lip_thickness / truth.lower_lip_thickness - 1.0),
        "lower_mm": cal.lower_lip_thickness - truth.lower_lip_thickness,
        "offset_mm": true_ahead - model_ahead,
        "face": 100 * (cal.face_width / truth.head.face_width - 1.0),
        "scale": 100 * (cal.scale * truth.jaw_pellet_distance / p - 1.0),
    }


def test_separate_calibration_reproduces_the_documented_recovery(corpus, separate, documented):
    summary, per_subject = documented
    worst = summary["separate"]
    model = load_model()
    assert sorted(separate) == [f"S{i:02d}" for i in range(1, N_SUBJECTS + 1)]
    for cal in separate.values():
        e, doc = _errors(corpus, cal, model), per_subject[cal.subject]
        # the per-subject numbers the docs print, to their printed precision (0.01)
        assert e["upper"] == pytest.approx(float(doc["upper error % (separate)"]), abs=0.006)
        assert e["lower"] == pytest.approx(float(doc["lower error % (separate)"]), abs=0.006)
        assert e["lower_mm"] == pytest.approx(float(doc["lower error mm (separate)"]), abs=0.006)
        assert e["offset_mm"] == pytest.approx(float(doc["tip offset difference mm"]), abs=0.006)
        # the documented explanation: the lower lip is off by the unobserved tip offset,
        # up to what the table says remains
        assert abs(e["lower_mm"] - e["offset_mm"]) <= _bound(worst["lower minus offset, worst mm"])
        assert abs(e["upper"]) <= _bound(worst["upper lip, worst abs error %"])
        # face width is set from Headmeasures, not fitted: the model reaches the setting
        assert abs(e["face"]) <= _bound(
            worst["face width (set from Headmeasures), worst abs difference %"])
        assert cal.converged and cal.method == "separate"
        assert cal.residuals["lips_in_teeth"] <= _bound(worst["lips in teeth, max mm"])
        # the jaw shape has 3 unknowns for 4 coordinates: within the documented ranges
        for point in ("gonion", "gnathion"):
            lo, hi = _span(worst[f"{point} residual mm"])
            assert lo <= cal.residuals[point] <= hi, (cal.subject, point)
        assert cal.bounds_hit == ()  # the synthetic jaws are adult jaws (issue 14 bounds)


LIMITS = ROOT / "docs" / "generated" / "calibration_limits.md"


def test_the_documented_limits_are_this_calibrations(corpus, separate):
    """docs/generated/calibration_limits.md (experiments/calibration_limits.py), rows
    S01-S03: the jaw stage as solved now, the lower lip's error and its reported range,
    to their printed precision; so a change to the calibration not followed by ``make
    experiments`` fails here."""
    tables = _doc_tables(LIMITS)  # the stall trace (table 2) only when a subject stalls
    jaw, lower = tables[0], tables[-1]
    jaw, lower = {r["subject"]: r for r in jaw}, {r["subject"]: r for r in lower}
    model = load_model()
    for cal in separate.values():
        row = jaw[cal.subject]
        assert row["now: converged"] == "true" and row["now: bounds hit"] == ""
        assert cal.params["jaw_shape_scale"][0] == pytest.approx(
            float(row["now: x scale"]), abs=_half_unit(row["now: x scale"]))
        row = lower[cal.subject]
        error = _errors(corpus, cal, model)["lower_mm"]
        assert error == pytest.approx(float(row["error mm"]), abs=0.006)
        low, high = cal.lower_lip_bias
        assert low == pytest.approx(float(row["range low mm"]), abs=0.006)
        assert high == pytest.approx(float(row["range high mm"]), abs=0.006)
        assert (low <= error <= high) == (row["error inside"] == "true")


def test_separate_scale_is_p_over_the_median_first_line_jaw_pellet_distance(corpus, separate):
    model = load_model()
    v = np.asarray(model.vertices)[:, :2]
    p = np.linalg.norm(v[model.landmarks["MNI"]] - v[model.landmarks["MNM"]])
    for subject, cal in separate.items():
        d = []
        for rec in _recordings(corpus, subject):
            xy = np.asarray(rec.track.positions)[first_valid_line(rec.track)[0]]
            d.append(np.linalg.norm(xy[MNI] - xy[MNM]))
        assert cal.scale == pytest.approx(p / np.median(d), rel=1e-9), subject


def test_joint_calibration_reproduces_the_documented_recovery(corpus, documented):
    summary, per_subject = documented
    with jax.enable_x64(True):
        cal = calibrate.calibrate_subject(_recordings(corpus, "S02"), method="joint")
    e, doc = _errors(corpus, cal, load_model()), per_subject["S02"]
    assert e["upper"] == pytest.approx(float(doc["upper error % (joint)"]), abs=0.006)
    assert e["lower"] == pytest.approx(float(doc["lower error % (joint)"]), abs=0.006)
    assert cal.method == "joint" and cal.converged
    # jointly the scale answers to every recording's jaw pellet distance
    assert abs(e["scale"]) <= _bound(summary["joint"]["scale p/d, worst abs error %"])


def test_the_lip_estimate_is_each_first_line_and_their_least_squares_compromise(separate):
    cal = separate["S01"]
    observed = np.array(cal.observed["upper_lip_thickness"], float)
    assert len(observed) == len(cal.recordings) == len(cal.first_lines) == 3
    assert cal.upper_lip_thickness == pytest.approx(observed.mean(), abs=0.01)
    assert cal.residuals["upper_lip"] == pytest.approx(observed.std(), abs=0.01)


def test_fewer_recordings_are_padded_to_the_solver_of_the_others(separate, corpus, monkeypatch):
    # one compiled solver serves a subject of 1 to RECORDING_BUCKET recordings: the padding
    # rows weigh nothing, and no summary carries them
    shapes, kernel = [], calibrate.stage_kernel

    def spy(model, data, *args):
        shapes.append(np.shape(data["pellets"]))
        return kernel(model, data, *args)

    monkeypatch.setattr(calibrate, "stage_kernel", spy)
    with jax.enable_x64(True):
        one = calibrate.calibrate_subject(_recordings(corpus, "S01")[:1])
    assert shapes and set(shapes) == {(calibrate.RECORDING_BUCKET, 8, 2)}
    assert len(one.observed["upper_lip_thickness"]) == len(one.first_lines) == 1
    assert one.residuals["upper_lip"] == pytest.approx(0.0, abs=1e-3)  # one line: met
    assert one.upper_lip_thickness == pytest.approx(one.observed["upper_lip_thickness"][0],
                                                    abs=1e-3)
    assert [calibrate.recording_bucket(r) for r in (1, 4, 5, 9)] == [4, 4, 8, 12]


def _lip_in_the_teeth(rec):
    positions = np.array(rec.track.positions)
    positions[:, 0, 0] = -4.0  # the UL pellet behind the incisor tip: the lip in the teeth
    return dataclasses.replace(rec, track=dataclasses.replace(rec.track, positions=positions))


def test_the_penalty_keeps_an_implausible_lip_out_of_the_teeth(corpus):
    # every recording of S03 (as the module's other calibrations: one compiled solver)
    bad = [_lip_in_the_teeth(rec) for rec in _recordings(corpus, "S03")]
    with jax.enable_x64(True):
        # the lip lands behind the incisor tip: flagged, penalised or not (never written)
        with pytest.warns(CalibrationWarning) as caught:
            free = calibrate.calibrate_subject(bad, collisions=False)
            held = calibrate.calibrate_subject(bad, collisions=True)
    said = [str(w.message) for w in caught]
    assert len(said) == 2 and all(s.startswith("S03: implausible calibration, "
                                               "upper_lip_thickness: -") for s in said)
    assert free.residuals["lips_in_teeth"] > 1.0
    assert held.residuals["lips_in_teeth"] < 0.2 * free.residuals["lips_in_teeth"]
    assert held.upper_lip_thickness > free.upper_lip_thickness


def test_one_jaw_sensor_cannot_give_the_scale_and_is_refused_in_one_line(corpus):
    rec = _recordings(corpus, "S01")[0]
    valid = np.array(rec.track.valid)
    valid[:, MNM] = False  # an articulograph's one jaw sensor: enough to animate, not to scale
    positions = np.where(valid, np.asarray(rec.track.positions), np.nan)
    one = dataclasses.replace(rec, track=dataclasses.replace(rec.track, valid=valid,
                                                             positions=positions))
    with pytest.raises(MissingDataError, match=r"calibration needs both jaw pellets .*MNM is "
                                               "never tracked"):
        calibrate.calibrate_subject([one])


def test_a_jaw_beyond_its_bound_is_held_there_and_the_fit_converges(corpus, monkeypatch):
    """A stall at the bound, made on purpose (S09's on the default corpus of generator
    version 5): S01's Headmeasures gonion moved back to x = -110 mm asks for a jaw longer
    than JAW_SCALE_BOUND allows. The bounded jaw-shape stage then walks out along
    tanh's flat tail until its budget ends; the calibration holds the bound and solves the
    rest again, so it converges and reports the bound. Without that (stubbed), it does not."""
    recs = _recordings(corpus, "S01")
    head = dataclasses.replace(recs[0].head, gonion_x=-110.0)
    long = [dataclasses.replace(r, head=head) for r in recs]
    with jax.enable_x64(True):
        with pytest.warns(CalibrationWarning, match=r"S01: the jaw shape reached its "
                                                    r"anatomical bound \(jaw_scale_x 1.300"):
            cal = calibrate.calibrate_subject(long)
        monkeypatch.setattr(calibrate, "_pressing_on_a_bound", lambda y, g, free: 0 * free)
        with pytest.warns(CalibrationWarning) as caught:
            stalled = calibrate.calibrate_subject(long)
    assert cal.converged and cal.unconverged == () and cal.bounds_hit == ("jaw_scale_x",)
    assert cal.params["jaw_shape_scale"][0] == pytest.approx(calibrate.JAW_SCALE_BOUND, rel=1e-6)
    assert not stalled.converged and stalled.unconverged == ("jaw_shape",)
    # the same face either way: the stall was at the bound, only the verdict differs
    assert cal.params["jaw_shape_scale"] == pytest.approx(stalled.params["jaw_shape_scale"],
                                                          abs=1e-3)
    assert [str(w.message) for w in caught] == stalled.problems()
    assert len(stalled.problems()) == 2 and "not converge (stage jaw_shape)" in stalled.problems()[0]


def test_calibrating_an_impossible_chin_hits_the_bound_and_warns(corpus):
    """A Headmeasures gnathion 40 mm below the subject's asks for a jaw taller than
    JAW_SCALE_BOUND allows: the fit reaches the bound along y and says so (moved here from
    test_cassi_mode: with the module's three recordings it shares their compiled solver)."""
    recs = _recordings(corpus, "S01")
    head = dataclasses.replace(recs[0].head, gnathion_y=recs[0].head.gnathion_y - 40.0)
    odd = [dataclasses.replace(r, head=head, head_is_default=False) for r in recs]
    with jax.enable_x64(True):
        with pytest.warns(UserWarning, match="anatomical bound"):
            result = calibrate.calibrate_subject(odd, method="separate", collisions=False)
    assert "jaw_scale_y" in result.bounds_hit


def test_calibration_files_round_trip_and_bad_files_are_named(tmp_path, separate):
    cal = separate["S01"]
    path = calibration.write_calibration(tmp_path / "S01.calibration.json", cal)
    back = calibration.read_calibration(path)
    assert back == cal
    with pytest.raises(Exception, match="exists|input file"):
        calibration.write_calibration(path, cal)
    assert calibration.load_calibrations(tmp_path) == {"S01": cal}
    broken = tmp_path / "broken" / "S09.calibration.json"
    broken.parent.mkdir()
    broken.write_text('{"format": "cassi_fit calibration 1",\n "scale": }\n')
    with pytest.raises(DataFormatError, match=r"S09.calibration.json:2: invalid JSON"):
        calibration.read_calibration(broken)
    data = json.loads(cal.to_json())
    data["params"]["jaw_shape_scale"] = [1.0]
    broken.write_text(json.dumps(data))
    with pytest.raises(DataFormatError, match="jaw_shape_scale"):
        calibration.read_calibration(broken)
    data = json.loads(cal.to_json())
    data["scale"] = -1
    broken.write_text(json.dumps(data))
    with pytest.raises(DataFormatError, match="scale"):
        calibration.read_calibration(broken)
    with pytest.raises(MissingDataError):
        calibration.load_calibrations(tmp_path / "nowhere")


def test_animation_uses_the_calibration(corpus, separate):
    cal = separate["S01"]
    rec = _recordings(corpus, "S01")[0]
    with jax.enable_x64(True):
        state = initialize(rec, calibration=cal)
        anim = animate(state, rec, stride=20)
    assert state.scale == cal.scale
    model = state.model
    rest = np.asarray(deform(model, state.conformation))
    at = {k: rest[model.landmarks[k]] for k in
          ("UL", "LL", "upper_incisor_tip", "lower_incisor_tip", "MNI", "MNM")}
    # the rest face the animation starts from has the calibrated measures (subject mm)
    upper = at["UL"][0] - at["upper_incisor_tip"][0]
    forward = (at["MNI"][:2] - at["MNM"][:2]) / np.linalg.norm(at["MNI"][:2] - at["MNM"][:2])
    lower = np.dot(at["LL"][:2] - at["lower_incisor_tip"][:2], forward)
    width = rest[model.landmarks["zygion_left"], 2] - rest[model.landmarks["zygion_right"], 2]
    assert upper / cal.scale == pytest.approx(cal.upper_lip_thickness, abs=1e-6)
    assert lower / cal.scale == pytest.approx(cal.lower_lip_thickness, abs=1e-6)
    assert width / cal.scale == pytest.approx(cal.face_width, abs=1e-6)
    # and the default conformation does not: the calibration is what changed it
    plain_rest = np.asarray(deform(model, initialize(rec).conformation))
    assert np.abs(plain_rest - rest).max() > 0.1
    assert np.isfinite(np.asarray(anim.vertices)).all()
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
    printed = capsys.readouterr().out
    assert "tongue_upper_front" in printed
    # the tongue keeps its volume through the collision projection (docs/TONGUE.md)
    low, high = re.search(r"tongue volume.*; ([-+.\d]+) % \.\. ([-+.\d]+) %", printed).groups()
    assert -3.0 < float(low) <= float(high) < 3.0
    table = np.genfromtxt(depths, delimiter=",", names=True)
    assert len(table) > 5 and {"tongue_palate_mm", "lips_lower_teeth_after_mm"} <= set(
        table.dtype.names)
    after = [n for n in table.dtype.names if n.endswith("_after_mm")]
    assert max(float(table[n].max()) for n in after) < 0.01
    assert cli(args[:-4] + ["--cassi", "--out", str(png), "--force"]) == 2
    assert "exclude" in capsys.readouterr().err


def test_the_run_spec_resolves_a_folder_or_a_file_and_excludes_cassi(tmp_path, separate):
    from cassi_fit.run_spec import run_spec

    cal = separate["S01"]
    path = calibration.write_calibration(calibration.calibration_path(tmp_path, "S01"), cal)
    assert run_spec(calibration=tmp_path).calibration_for("s01") == cal
    assert run_spec(calibration=path).calibration_for("S01") == cal
    assert run_spec(calibration={"s01": cal}).calibration_for("S01") == cal
    # one line naming the file (or the folder and what it holds)
    with pytest.raises(CassiError, match=r"S01.calibration.json: the calibration is of "
                       r"subject S01, not S02"):
        run_spec(calibration=path).calibration_for("S02")
    with pytest.raises(MissingDataError, match=r"no calibration of subject S02 .*it has S01"):
        run_spec(calibration=tmp_path).calibration_for("s02")
    with pytest.raises(MissingDataError, match=r"no calibration of subject S02 among those "
                       r"given \(S01\)"):
        run_spec(calibration={"S01": cal}).calibration_for("S02")
    assert run_spec().calibration_for("S01") is None
    assert run_spec("cassi").calibration_for("S01") == "cassi"
    with pytest.raises(CassiError, match="exclude each other"):
        run_spec("cassi", calibration=tmp_path)


def test_the_unknowns_are_named_and_flatten_in_their_documented_order():
    from jax.flatten_util import ravel_pytree

    x = calibrate_residuals.Unknowns(*map(np.float64, (1, 2, 3, 4, 5)), np.array([6.0, 7.0]))
    np.testing.assert_array_equal(ravel_pytree(x)[0], np.arange(1.0, 8.0))
    mask = calibrate_residuals.Unknowns.mask(("face_width", "log_jaw_scale"))
    np.testing.assert_array_equal(ravel_pytree(mask)[0], [0, 0, 0, 1, 0, 1, 1])
    assert calibrate_residuals.UNKNOWN_NAMES == tuple(f.name for f in dataclasses.fields(x))
    from cassi_fit.errors import InvalidChoiceError

    with pytest.raises(InvalidChoiceError, match="calibration method"):
        calibrate.calibrate_subject([object()], method="both")
