"""The CASSI reproduction mode (docs/CASSI_MODE.md) and the measures of its artefacts."""

import dataclasses

import numpy as np
import pytest
import zoo

from cassi_fit import cli
from cassi_fit import evaluate as ev
from cassi_fit.dataset import Dataset
from cassi_fit.deform import tongue_midline
from cassi_fit.errors import CassiError, InvalidChoiceError
from cassi_fit.evaluate._measures import back_v_deg
from cassi_fit.initialize import initialize
from cassi_fit.pipeline import run_recording
from cassi_fit.run_spec import CASSI, IMPROVED, RunSpec, run_spec

STRIDE = 4  # as test_evaluate: one compilation per frame bucket


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return zoo.small_corpus(tmp_path_factory, n_subjects=4, tasks=("tp040",))


@pytest.fixture(scope="module")
def recording(corpus):
    return Dataset(corpus).load("S01", "tp040")


@pytest.fixture(scope="module")
def both(recording):
    """``{mode: (state, animation)}`` of S01's sentence in both modes."""
    return {m: run_recording(recording, m, stride=STRIDE)[2:4] for m in ("improved", "cassi")}


def test_modes_are_records_and_names():
    assert run_spec(None) == IMPROVED and run_spec("cassi") == CASSI
    assert (CASSI.tongue_shape, CASSI.tongue_anchor, CASSI.jaw_weights) == ("flat", "fixed", "cassi")
    assert (CASSI.calibration, CASSI.collisions, CASSI.lip_rounding) == ("cassi", "off", False)
    assert run_spec("cassi", stride=10).stride == 10
    assert isinstance(run_spec(CASSI), RunSpec)
    with pytest.raises(InvalidChoiceError, match="mode"):
        run_spec("parke")


def test_cassi_state_carries_the_papers_choices(both, recording):
    state, anim = both["cassi"]
    assert (state.mode, state.tongue_shape, state.tongue_anchor, state.lip_rounding) == (
        "cassi", "flat", "fixed", False)
    assert anim.collisions == "off" and anim.jaw_method == "closed-form"
    improved = both["improved"][0]
    assert (improved.tongue_shape, improved.tongue_anchor) == ("thick", "follow")
    # the paper's conformation: no lip thickness or face width from Headmeasures
    assert float(state.conformation.face_width) == 1.0
    assert float(state.conformation.upper_lip_thickness) == 0.0


def test_cassi_mode_refuses_a_fitted_calibration(recording):
    from cassi_fit.calibration import Calibration

    fields = {f.name: None for f in dataclasses.fields(Calibration)}
    fields.update(subject=recording.subject, params={}, lip_rest_offset=(0.0, 0.0))
    fake = Calibration(**fields)
    with pytest.raises(CassiError, match="cassi mode"):
        initialize(recording, calibration=fake, mode="cassi")


def test_cassi_tongue_has_zero_thickness_and_passes_through_the_pellets(both):
    state, anim = both["cassi"]
    idx, top = tongue_midline(state.model)
    v = np.asarray(anim.vertices)
    assert np.max(np.abs(v[:, idx, :2] - v[:, top, :2])) == 0.0  # a sheet: no thickness
    width = np.ptp(v[:, idx, 2], axis=1)
    assert np.all(width > 20.0)  # still as wide as a tongue
    measured, model = np.asarray(anim.pellets_measured), np.asarray(anim.pellets_model)
    np.testing.assert_allclose(model[:, 2:6], measured[:, 2:6], atol=1e-9)  # T1..T4
    thick = np.asarray(both["improved"][1].vertices)
    assert np.max(np.abs(thick[:, idx, :2] - thick[:, top, :2])) > 10.0


def test_cassi_back_anchors_stay_fixed(both):
    state, anim = both["cassi"]
    s = np.asarray(state.model.fields["tongue_s"])
    idx = np.asarray(state.model.regions["tongue"])
    behind = idx[s[idx] >= state.model.measures["tongue_anchor_s"]]
    assert behind.size > 0
    v = np.asarray(anim.vertices)[:, behind, :2]
    assert np.max(np.abs(v - v[:1])) < 1e-9  # anchored: the same place in every frame
    follow = np.asarray(both["improved"][1].vertices)[:, behind, :2]
    assert np.max(np.abs(follow - follow[:1])) > 1.0  # the improved back moves with T4


def test_back_v_measure_on_known_shapes():
    valley = np.array([[0.0, 0.0, 0], [-1.0, -1.0, 0], [-2.0, 0.0, 0]])
    assert float(back_v_deg(valley)) == pytest.approx(90.0)
    dome = np.array([[0.0, 0.0, 0], [-1.0, 1.0, 0], [-2.0, 0.0, 0]])
    assert float(back_v_deg(dome)) == pytest.approx(-90.0)
    straight = np.array([[0.0, 0.0, 0], [-1.0, 0.5, 0], [-2.0, 1.0, 0]])
    assert float(back_v_deg(straight)) == pytest.approx(0.0, abs=1e-9)


def test_rest_tongue_back_is_convex(both):
    state = both["improved"][0]
    from cassi_fit.evaluate._measures import _tongue_back

    rest = np.asarray(state.model.vertices)[_tongue_back(state.model)]
    assert float(back_v_deg(rest)) < 0.0


def test_v_shape_in_cassi_mode_not_in_the_improved_mode(corpus):
    """On the synthetic corpus (4 subjects, one sentence each): the V is sharper in the
    CASSI mode for every recording, beyond the threshold for some, and for none in the
    improved mode; the tongue goes through the palate in every CASSI recording."""
    cassi = ev.evaluate_dataset(corpus, mode="cassi", progress=False, stride=STRIDE)
    improved = ev.evaluate_dataset(corpus, progress=False, stride=STRIDE)
    v_cassi = np.array([r.measures["tongue_back_v_deg"] for r in cassi.recordings])
    v_improved = np.array([r.measures["tongue_back_v_deg"] for r in improved.recordings])
    assert np.all(v_cassi > v_improved)
    assert np.sum(v_cassi > ev.TONGUE_V_DEG) >= 2
    assert np.sum(v_improved > ev.TONGUE_V_DEG) == 0
    flagged = [r for r in cassi.recordings if "tongue's back in a V" in r.problems["not_counted"]]
    assert len(flagged) == np.sum(v_cassi > ev.TONGUE_V_DEG)
    palate = np.array([r.measures["tongue_palate_mm"] for r in cassi.recordings])
    assert np.all(palate > ev.TONGUE_PALATE_MM)
    assert {r.calibration for r in cassi.recordings} == {"cassi mode"}
    # the V is reported, never counted: ratings follow from the counted problems only
    for row in cassi.recordings:
        assert all("V" not in p for c in ev.COMPONENTS for p in row.problems[c])


def test_cli_evaluate_mode_cassi(corpus, tmp_path, capsys):
    out = tmp_path / "eval"
    code = cli.main(["evaluate", str(corpus), "--out", str(out), "--mode", "cassi", "--quiet",
                     "--stride", str(STRIDE), "--subjects", "S01"])
    text, err = capsys.readouterr()
    assert code == 0, err
    assert "Calibration: cassi mode" in text
    assert "tongue_back_v_deg" in (out / "evaluation_recordings.csv").read_text()
    code = cli.main(["evaluate", str(corpus), "--out", str(tmp_path / "e2"), "--mode",
                     "improved", "--cassi", "--quiet"])
    _, err = capsys.readouterr()
    assert code == 2 and "disagree" in err


# ------------------------------------------------------------------ bone and skin landmarks
def _jaw_chin_lips(model):
    """Vertices the jaw shape, the jaw or the lips move (the regions part 2 is about)."""
    f = model.fields
    moved = (np.asarray(f["jaw_shape"]) > 0) | (np.asarray(model.jaw_weights["cassi"]) > 0)
    return moved | (np.asarray(f["upper_lip"]) > 0) | (np.asarray(f["lower_lip"]) > 0)


def _conformed(model, head):
    from types import SimpleNamespace

    from cassi_fit.conformation import default_conformation
    from cassi_fit.deform import deform, model_pellets

    first = np.asarray(model_pellets(model, model.vertices), np.float64)
    recording = SimpleNamespace(head=head, head_is_default=False)
    return np.asarray(deform(model, default_conformation(model, recording, first, 1.0)))


def test_default_headmeasures_leave_the_face_unchanged():
    from cassi_fit.face_model import load_model
    from cassi_fit.headmeasures import DEFAULT_HEAD_MEASURES

    model = load_model()
    rest, region = np.asarray(model.vertices), _jaw_chin_lips(model)
    assert region.sum() > 100
    moved = np.abs(_conformed(model, DEFAULT_HEAD_MEASURES) - rest)[region]
    assert moved.max() < 0.01
    # the old defaults (a bony chin read as the skin, a thin lower lip) moved the face
    old = dataclasses.replace(DEFAULT_HEAD_MEASURES, gnathion_x=0.0, gnathion_y=-43.0,
                              lower_lip_thickness=11.5)
    assert np.abs(_conformed(model, old) - rest)[region].max() > 3.0


def test_bone_points_map_to_the_models_skin_landmarks():
    from cassi_fit.conformation import skin_landmarks, skin_normal
    from cassi_fit.face_model import load_model
    from cassi_fit.headmeasures import BONE_FIELDS, DEFAULT_HEAD_MEASURES, SOFT_TISSUE_FIELDS

    model = load_model()
    skin = skin_landmarks(model, DEFAULT_HEAD_MEASURES)
    v = np.asarray(model.vertices)
    expected = v[[model.landmarks["gonion"], model.landmarks["gnathion"]], :2]
    np.testing.assert_allclose(skin, expected, atol=0.005)
    assert skin_normal(model, "gnathion")[1] < -0.5  # the chin's skin faces down
    assert set(BONE_FIELDS).isdisjoint(SOFT_TISSUE_FIELDS)
    assert len(BONE_FIELDS) + len(SOFT_TISSUE_FIELDS) == 10


def test_jaw_shape_unknowns_are_bounded_and_flagged():
    import jax.numpy as jnp

    from cassi_fit.calibrate import bounds_hit
    from cassi_fit.calibrate_residuals import Unknowns, bounded_jaw
    from cassi_fit.calibration import JAW_SCALE_BOUND, JAW_TURN_BOUND_RAD

    x = Unknowns.zeros()
    assert bounds_hit(x) == ()
    import equinox as eqx

    near = eqx.tree_at(lambda u: u.log_jaw_scale, x, jnp.array([0.01, -0.01]))
    theta, log_scale = bounded_jaw(near)
    np.testing.assert_allclose(np.asarray(log_scale), [0.01, -0.01], rtol=5e-3)  # ~identity
    far = eqx.tree_at(lambda u: (u.log_jaw_scale, u.jaw_theta), x,
                      (jnp.array([5.0, 0.0]), jnp.asarray(-3.0)))
    theta, log_scale = bounded_jaw(far)
    assert float(np.exp(log_scale[0])) <= JAW_SCALE_BOUND and abs(float(theta)) <= JAW_TURN_BOUND_RAD
    assert bounds_hit(far) == ("jaw_scale_x", "jaw_turn")
