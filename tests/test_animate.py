"""The pipeline: initialization on the first valid line, p/d scaling, the jaw following the
MNI pellet, stride, gap repair and its flags."""

import dataclasses
import math
from pathlib import Path

import jax
import numpy as np
import pytest

from cassi_fit import synth
from cassi_fit.animate import animate
from cassi_fit.dataset import Recording
from cassi_fit.errors import CassiError, InvalidChoiceError, MissingDataError
from cassi_fit.frames import geometry
from cassi_fit.gaps import frame_status, repair
from cassi_fit.initialize import initialize
from cassi_fit.pellets import LL, MNI, MNM, UL, first_valid_line
from cassi_fit.status import Status
from cassi_fit.txy import PelletTrack

FRAME_OK, FRAME_HELD = Status.OK, Status.HELD
FRAME_INTERPOLATED, FRAME_MISTRACKED = Status.INTERPOLATED, Status.MISTRACKED


def make_recording(seconds=1.0, seed=3, *, head_is_default=False, **synth_options):
    anatomy = synth.make_subject("JWT", np.random.default_rng(seed))
    track, truth = synth.synth_recording(
        anatomy, synth.SENTENCE_TASK, seed=seed, duration_s=seconds, **synth_options
    )
    return Recording(
        subject="JWT",
        task=synth.SENTENCE_TASK,
        track=track,
        palate=anatomy.palate,
        pharynx=anatomy.pharynx,
        head=anatomy.head,
        head_is_default=head_is_default,
        audio=None,
        path=Path("/data/JWT/tp040.txy"),
    ), truth


def with_track(recording, positions, valid=None):
    valid = np.isfinite(positions) if valid is None else valid
    track = PelletTrack(recording.track.times, positions, valid, recording.track.path)
    return dataclasses.replace(recording, track=track)


@pytest.fixture(scope="module")
def model():
    from cassi_fit.face_model import load_model

    return load_model()


@pytest.fixture(scope="module")
def recording():
    return make_recording()[0]


@pytest.fixture(scope="module")
def state(recording, model):
    return initialize(recording, model)


@pytest.fixture(scope="module")
def animation(state, recording):
    return animate(state, recording)


# ------------------------------------------------------------------ pure numpy parts


def test_repair_hold_and_interpolate():
    x = np.arange(6.0)[:, None, None] * np.ones((6, 8, 2))
    bad = np.zeros((6, 8), bool)
    bad[2:4, 1] = True  # a gap in LL
    bad[0, 3] = True  # a leading gap in T2
    held = repair(np.where(bad[..., None], np.nan, x), bad, "hold")
    np.testing.assert_array_equal(held[:, 1, 0], [0, 1, 1, 1, 4, 5])
    np.testing.assert_array_equal(held[:, 3, 0], [1, 1, 2, 3, 4, 5])
    interp = repair(np.where(bad[..., None], np.nan, x), bad, "interpolate")
    np.testing.assert_allclose(interp[:, 1, 0], np.arange(6.0))
    np.testing.assert_array_equal(interp[:, 0], x[:, 0])  # untouched pellets unchanged
    with pytest.raises(InvalidChoiceError, match="gap policy"):
        repair(x, bad, "zero")


def test_frame_status_codes():
    untracked = np.zeros((4, 8), bool)
    mistracked = np.zeros((4, 8), bool)
    untracked[1, 2] = True
    mistracked[2, 0] = True
    untracked[3, 0] = mistracked[3, 1] = True
    np.testing.assert_array_equal(
        frame_status(untracked, mistracked, "hold"),
        [FRAME_OK, FRAME_HELD, FRAME_MISTRACKED, FRAME_MISTRACKED],
    )
    assert frame_status(untracked, mistracked, "interpolate")[1] == FRAME_INTERPOLATED
    assert [Status(int(x)).label for x in frame_status(untracked, mistracked, "hold")] == [
        "ok", "held", "mistracked", "mistracked"]


def test_first_valid_line_ignores_pellets_never_tracked(recording):
    positions = recording.track.positions.copy()
    positions[:, 5] = np.nan  # T4 never tracked, as in many real files
    first, tracked = first_valid_line(with_track(recording, positions).track, "x.txy")
    assert "T4" not in tracked and len(tracked) == 7
    positions[:, MNM] = np.nan  # one jaw sensor is enough for the rule
    assert "MNM" not in first_valid_line(with_track(recording, positions).track, "x.txy")[1]
    positions[:, MNI] = np.nan
    with pytest.raises(MissingDataError, match="x.txy.*MNI, MNM"):
        first_valid_line(with_track(recording, positions).track, "x.txy")


# ------------------------------------------------------------------ initialization


def test_initialization_uses_the_first_valid_line(recording, model):
    positions = recording.track.positions.copy()
    n_lead = int(np.argmax(np.isfinite(positions).all(axis=(1, 2))))
    positions[n_lead : n_lead + 3, 2, 0] = np.nan  # T1 x untracked on the next three lines
    rec = with_track(recording, positions)
    state = initialize(rec, model)
    assert state.first_frame == n_lead + 3
    from cassi_fit.deform import model_pellets

    sites = np.asarray(model_pellets(model, model.vertices))
    p = np.linalg.norm(sites[MNI] - sites[MNM])
    d = np.linalg.norm(positions[n_lead + 3, MNI] - positions[n_lead + 3, MNM])
    assert state.scale == pytest.approx(p / d, rel=1e-12)
    np.testing.assert_allclose(state.reference_jaw, state.scale * positions[n_lead + 3, [MNI, MNM]])


def test_initial_pose_puts_the_model_on_the_first_frame(state, recording):
    verts, sites = geometry(state, jax.tree.map(lambda x: x[None], state.initial_params))
    scaled = state.scale * recording.track.positions[state.first_frame]
    assert np.all(np.isfinite(np.asarray(verts)))
    np.testing.assert_allclose(sites[0, MNI], scaled[MNI], atol=0.1)
    # jaw line direction matches (closed form, Eqs 1-3)
    model_line = np.asarray(sites[0, MNI] - sites[0, MNM])
    data_line = scaled[MNI] - scaled[MNM]
    cos = model_line @ data_line / np.linalg.norm(model_line) / np.linalg.norm(data_line)
    assert cos == pytest.approx(1.0, abs=1e-6)


def test_jaw_pellets_never_tracked_name_the_file(recording, model):
    positions = recording.track.positions.copy()
    positions[:, [MNI, MNM]] = np.nan  # one jaw sensor would do; none cannot
    with pytest.raises(MissingDataError, match="tp040.txy"):
        initialize(with_track(recording, positions), model)


# ------------------------------------------------------------------ animation


def test_model_mni_follows_the_scaled_pellet_in_every_frame(animation, recording, state):
    """Acceptance: closed-form jaw, CASSI weights -> the MNI site within 0.1 mm."""
    measured = np.asarray(animation.pellets_measured)
    model_sites = np.asarray(animation.pellets_model)
    assert animation.n_frames == len(recording.track.times) - state.first_frame
    good = ~animation.repaired[:, MNI]
    assert good.mean() > 0.8
    error = np.linalg.norm(model_sites[:, MNI] - measured[:, MNI], axis=1)
    assert error.max() < 0.1, error.max()
    # against the raw file too, not only the repaired copy
    raw = state.scale * recording.track.positions[animation.frame_index]
    assert np.nanmax(np.linalg.norm(model_sites[good, MNI] - raw[good, MNI], axis=1)) < 0.1


def test_lips_and_tongue_follow_their_pellets(animation):
    measured = np.asarray(animation.pellets_measured)
    model_sites = np.asarray(animation.pellets_model)
    error = np.linalg.norm(model_sites - measured, axis=2)  # (m, 8)
    for pellet in (UL, LL, 2, 3, 4, 5):
        assert np.median(error[:, pellet]) < 0.5, (pellet, np.median(error[:, pellet]))


def test_animation_is_finite_and_repairs_are_flagged(recording, model):
    rec, truth = make_recording(seconds=1.0, seed=11)
    positions = rec.track.positions.copy()
    state = initialize(rec, model)
    hole = slice(state.first_frame + 20, state.first_frame + 30)
    positions[hole, LL] = np.nan
    rec = with_track(rec, positions)
    held = animate(state, rec, gap_policy="hold")
    interp = animate(state, rec, gap_policy="interpolate")
    for anim in (held, interp):
        assert np.all(np.isfinite(np.asarray(anim.vertices)))
        assert np.all(np.isfinite(anim.pellets_measured))
        assert anim.repaired[20:30, LL].all()
        assert set(np.unique(anim.frame_status[20:30])) <= {
            FRAME_HELD,
            FRAME_INTERPOLATED,
            FRAME_MISTRACKED,
        }
    np.testing.assert_array_equal(
        held.pellets_measured[20:30, LL], held.pellets_measured[[19] * 10, LL]
    )
    assert np.all(
        interp.frame_status[20:30][interp.frame_status[20:30] != FRAME_MISTRACKED]
        == FRAME_INTERPOLATED
    )
    # the synthetic mistracks are caught and flagged, not animated
    flagged = truth.mistracked[held.frame_index]
    if flagged.any():
        assert held.repaired[flagged].mean() > 0.5


@pytest.mark.parametrize("stride", [3, 10])
def test_stride(state, recording, stride, animation):
    anim = animate(state, recording, stride=stride)
    n = len(recording.track.times)
    assert anim.n_frames == math.ceil((n - state.first_frame) / stride)
    np.testing.assert_array_equal(anim.frame_index, np.arange(state.first_frame, n, stride))
    np.testing.assert_allclose(anim.times, recording.track.times[anim.frame_index])
    np.testing.assert_allclose(anim.vertices, animation.vertices[::stride], atol=1e-9)
    assert anim.stride == stride


def _jaw_pivots(sites):
    """The fixed point of the jaw's motion from frame 0 to each frame, from the model's
    jaw sites ``sites (m, 8, 2)`` by hand (Eqs 1-7: the turn of the MNI-MNM line, then
    ``(I - R) p = t``); NaN where the turn is under 1 degree (no pivot to speak of)."""
    line = sites[:, MNI] - sites[:, MNM]
    angle = np.arctan2(line[:, 1], line[:, 0])
    theta = angle[0] - angle  # opening > 0; p' = R p + t, R = [[c, s], [-s, c]]
    c, s = np.cos(theta), np.sin(theta)
    rotation = np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)
    shift = sites[:, MNI] - np.einsum("kij,j->ki", rotation, sites[0, MNI])
    pivots = np.full((len(theta), 2), np.nan)
    for k in np.flatnonzero(np.abs(theta) > np.radians(1.0)):
        pivots[k] = np.linalg.solve(np.eye(2) - rotation[k], shift[k])
    return pivots


@pytest.mark.slow
def test_the_fixed_pivot_fit_turns_the_jaw_about_one_point(state, recording, animation):
    """The closed form gives every frame its own pivot (the pellet noise scatters it by
    mm); the fixed-pivot fit turns the model's jaw about one point in every frame, and
    still fits the jaw pellets."""
    fit = animate(state, recording, jaw="fixed-pivot", stride=5)
    assert fit.jaw_method == "fixed-pivot" and animation.jaw_method == "closed-form"
    fixed = _jaw_pivots(np.asarray(fit.pellets_model))
    closed = _jaw_pivots(np.asarray(animation.pellets_model)[::5])
    assert np.isfinite(fixed[:, 0]).sum() >= 5 and np.isfinite(closed[:, 0]).sum() >= 5
    assert np.nanstd(fixed, axis=0).max() < 1e-6
    assert np.nanstd(closed, axis=0).max() > 1.0
    jaw = [MNI, MNM]
    error = np.linalg.norm(np.asarray(fit.pellets_model)[:, jaw] - fit.pellets_measured[:, jaw],
                           axis=2)
    assert np.sqrt(np.mean(error**2)) < 0.5  # the pellet noise is about 0.25 mm


def test_bad_jaw_choices_and_strides_are_refused(state, recording):
    with pytest.raises(InvalidChoiceError, match="jaw method"):
        animate(state, recording, jaw="magic")
    with pytest.raises(CassiError, match="stride"):
        animate(state, recording, stride=0)


@pytest.mark.slow
def test_parke_weights_and_fixed_tongue_anchors(recording, model, animation):
    """Parke's weights move the lower teeth 90 % of the jaw's motion (CASSI's: 100 %);
    with fixed anchors the tongue behind them moves with the jaw only, whatever the
    tongue pellets do."""
    import equinox as eqx
    import jax.numpy as jnp

    from cassi_fit.deform import deform

    parke = initialize(recording, model, jaw_weights="parke", tongue_anchor="fixed")
    anim = animate(parke, recording, stride=5)

    def teeth_share(frames):  # least squares: model MNI displacement / measured one
        m = np.asarray(frames.pellets_model)[:, MNI]
        x = frames.pellets_measured[:, MNI]
        dm, dx = (m - m[0]).ravel(), (x - x[0]).ravel()
        return dm @ dx / (dx @ dx)

    assert teeth_share(anim) == pytest.approx(0.9, abs=0.01)
    assert teeth_share(animation) == pytest.approx(1.0, abs=0.01)

    tongue = np.asarray(model.regions["tongue"])
    behind = tongue[np.asarray(model.fields["tongue_s"])[tongue] >= model.measures["tongue_anchor_s"]]
    assert len(behind) > 20

    # the same frames with the tongue pellets at rest: the vertices behind the anchors
    # stay where they are (with following anchors they would move by up to about 12 mm)
    still = eqx.tree_at(lambda p: p.tongue, anim.params, jnp.zeros_like(anim.params.tongue))
    style = {"tongue_anchor": "fixed", "jaw_weights": "parke", "tongue_shape": parke.tongue_shape}
    rest = jax.jit(jax.vmap(lambda p: deform(parke.model, p, **style)))(still)
    moved = np.abs(np.asarray(anim.vertices)[:, behind, :2] - np.asarray(rest)[:, behind, :2])
    assert moved.max() < 1e-9
    assert np.abs(np.asarray(anim.vertices)[:, behind, :2] - np.asarray(anim.vertices)[0, behind, :2]).max() > 1.0  # they do move (with the jaw)


def test_without_headmeasures_the_lips_come_from_the_first_line(model):
    """No Headmeasures for the subject: no jaw shape, face or nose change (the model's
    own), and the upper lip's thickness is the first valid line's (the UL pellet's
    distance ahead of the incisor tip, scaled): the model's UL site at rest is there.
    With Headmeasures, the same recording takes its shape from them."""
    from cassi_fit.deform import default_params

    own = default_params(model)
    for default in (True, False):
        rec, _ = make_recording(seconds=0.6, seed=5, head_is_default=default)
        state = initialize(rec, model)
        first = state.scale * rec.track.positions[state.first_frame]
        shape = {name: np.asarray(getattr(state.conformation, name)) for name in
                 ("jaw_shape_theta", "jaw_shape_translation", "face_width", "mouth_width",
                  "nose_tip")}  # fmt: skip
        unchanged = [np.array_equal(v, np.asarray(getattr(own, k))) for k, v in shape.items()]
        ul_x = float(state.rest_pellets[UL, 0])
        if default:
            assert all(unchanged), shape
            assert ul_x == pytest.approx(first[UL, 0], abs=1e-9)
        else:
            assert not any(unchanged), shape
            assert abs(ul_x - first[UL, 0]) > 0.1


def test_a_bad_choice_raises_one_error_type_everywhere(state, recording, model):
    """The same bad tongue anchor: the model layer (deform, tongue) and the pipeline
    (initialize) raise the same type, and so does a bad collision mode in animate."""
    from cassi_fit.deform import default_params, deform
    from cassi_fit.tongue import tongue_displacement

    calls = [
        # traced, not run op by op: the choice is refused while the model is traced (the
        # same Python, raising the same error), before dozens of small kernels compile
        lambda: jax.jit(lambda p: deform(model, p, tongue_anchor="glued"))(default_params(model)),
        lambda: tongue_displacement(np.zeros(3), np.arange(4.0), np.zeros((4, 2)), 9.0, "glued"),
        lambda: initialize(recording, model, tongue_anchor="glued"),
        lambda: deform(model, default_params(model), jaw_weights="mine"),
        lambda: initialize(recording, model, jaw_weights="mine"),
        lambda: animate(state, recording, collisions="sometimes"),
    ]
    for call in calls:
        with pytest.raises(InvalidChoiceError) as info:
            call()
        assert isinstance(info.value, CassiError) and isinstance(info.value, ValueError)


def test_a_second_recording_of_the_same_shape_compiles_nothing(model):
    """eqx.filter_jit on the model's hashable topology: after one recording, another one
    of the same subject whose frames fall in the same bucket compiles nothing new (a
    fresh load of the model included), for initialization and animation alike."""
    from jax import monitoring

    from cassi_fit.face_model import load_model
    from cassi_fit.frames import frame_bucket

    # as long as the module's recording (its frame bucket, 256, compiled there: this test
    # then compiles only what it checks is not compiled again)
    first, _ = make_recording(seconds=1.0, seed=21)
    t = first.track  # the same subject, other values and 7 lines fewer, same frame bucket
    second = dataclasses.replace(first, track=PelletTrack(
        t.times[:-7], t.positions[:-7] + 0.05, t.valid[:-7], t.path))
    n1 = len(first.track.times) - first_valid_line(first.track).index
    n2 = len(second.track.times) - first_valid_line(second.track).index
    assert n1 != n2 and frame_bucket(n1) == frame_bucket(n2)

    compiles = []

    def listener(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration)

    animate(initialize(first, model), first)
    monitoring.register_event_duration_secs_listener(listener)
    try:
        jax.jit(lambda x: x * 3.0 + 1.0)(np.ones(n1 + 1234))  # the listener does count
        assert len(compiles) >= 1
        compiles.clear()
        state = initialize(second, load_model())  # another model object, same content
        anim = animate(state, second)
    finally:
        monitoring.unregister_event_duration_listener(listener)
    assert anim.n_frames == n2
    assert len(compiles) == 0, f"{len(compiles)} new compilation(s)"
