"""The synthetic corpus: anatomy, rigid-jaw kinematics, measurement effects, files, CLI."""

import wave

import jax
import numpy as np
import pytest
import zoo
from real_data import XRMB_JW11, missing, real_data

from cassi_fit import rigid, synth
from cassi_fit.cli import main
from cassi_fit.errors import CassiError, DataFormatError, MissingDataError, OutputExistsError

SPEECH_TASKS = ("tp011", "tp020", "tp040")
ALL_TASKS = tuple(synth.TASKS)
# One real speaker's 1st / median / 99th percentiles (mm), from the task description.
REAL = {
    "UL": ((12.6, 14.9, 20.2), (12.2, 17.8, 21.6)),
    "LL": ((2.5, 9.4, 15.4), (-32, -21.4, -11.7)),
    "T1": ((-32, -17, -7), (-13, 0.6, 14)),
    "T2": ((-40, -28, -19), (-4, 7.5, 19)),
    "T3": ((-50, -39, -29), (3, 14.5, 23)),
    "T4": ((-63, -53, -45), (9, 17.4, 25)),
    "MNI": ((-3.5, -1.2, 1.6), (-17, -8.2, -4)),
    "MNM": ((-46, -43.5, -40), (-9.6, -3.1, 0.5)),
}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return zoo.small_corpus(tmp_path_factory)


# ------------------------------------------------------------------ determinism, anatomy
def test_same_seed_same_recording_other_seed_differs():
    anatomy = zoo.subject(3)
    a_track, a_truth = synth.synth_recording(anatomy, "tp040", seed=7)
    b_track, b_truth = synth.synth_recording(anatomy, "tp040", seed=7)
    c_track, _ = synth.synth_recording(anatomy, "tp040", seed=8)
    np.testing.assert_array_equal(a_track.positions, b_track.positions)
    np.testing.assert_array_equal(a_truth.pellets_true, b_truth.pellets_true)
    np.testing.assert_array_equal(a_truth.mistracked, b_truth.mistracked)
    assert a_track.n_frames != c_track.n_frames or not np.array_equal(
        a_track.positions, c_track.positions, equal_nan=True
    )
    again = synth.make_subject("S04", np.random.default_rng([0, 1, 3]))
    np.testing.assert_array_equal(again.palate, anatomy.palate)
    assert again.head == anatomy.head


@pytest.mark.parametrize("index", range(15))
def test_anatomy_is_plausible(index):
    a = zoo.subject(index)
    assert a.name == f"S{index + 1:02d}"
    assert 9 <= len(a.palate) <= 52 and a.pharynx.shape == (2, 2)
    x, y = a.palate[:, 0], a.palate[:, 1]
    assert np.all(np.diff(x) < 0)  # front to back
    assert -5.5 < x[0] < -3 and -63 < x[-1] < -55
    assert y.min() > 4.0 and y.max() < 28.0
    assert 35.0 <= a.jaw_pellet_distance <= 45.0
    tip, mni = a.lower_incisor_tip_rest, a.mni_rest
    assert -4.5 < tip[0] < -1.5 and -2.5 < tip[1] < 0  # behind the upper tip: overjet
    assert abs(mni[0] - tip[0]) < 3.5 and mni[1] < tip[1] - 2.0  # MNI on the crown, below
    behind, above = tip - a.condyle_rest
    assert 90 <= behind <= 100 and -30 <= above <= -20
    np.testing.assert_array_equal(a.chin_rest, [a.head.gnathion_x, a.head.gnathion_y])
    np.testing.assert_array_equal(a.pellets_rest[6:], [a.mni_rest, a.mnm_rest])
    assert a.upper_lip_thickness == a.head.upper_lip_thickness
    assert 115 < a.face_width == a.head.face_width < 155
    assert a.jaw_kinematics == synth.DEFAULT_JAW_KINEMATICS_CYCLE[index % 3]


@pytest.mark.parametrize("index", range(4))
def test_lip_thickness_is_what_the_pellets_show(index):
    """Headmeasures' lip thickness (docs/FORMATS.md): the lip pellet ahead of the incisor
    tip at rest; the lower one along the jaw line MNM -> MNI."""
    a = zoo.subject(index)
    rest = a.pellets_rest
    assert rest[0, 0] == pytest.approx(a.upper_lip_thickness, abs=1e-3)  # um rounding
    forward = (a.mni_rest - a.mnm_rest) / np.linalg.norm(a.mni_rest - a.mnm_rest)
    ahead = (rest[1] - a.lower_incisor_tip_rest) @ forward
    assert ahead == pytest.approx(a.lower_lip_thickness, abs=1e-3)  # um rounding


def test_the_truth_does_not_know_the_face_model():
    """Issue 11: subject geometry is drawn from anthropometric norms, not from the model.
    The generator neither imports the face model nor reads its files."""
    import inspect
    import subprocess
    import sys

    source = inspect.getsource(synth)
    assert "face_model" not in source and "model.json" not in source
    assert "MODEL_" not in source
    code = "import sys, cassi_fit.synth; print(sorted(m for m in sys.modules if 'face' in m))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_subject_geometry_follows_its_anthropometric_norms():
    """Lip thickness and the MNI-to-incisor offset: mean and SD as NORMS says (400 draws)."""
    subjects = [synth.make_subject("X", np.random.default_rng([9, k])) for k in range(400)]
    for key, values in {
        "upper_lip_thickness": [a.upper_lip_thickness for a in subjects],
        "lower_lip_thickness": [a.lower_lip_thickness for a in subjects],
        "face_width": [a.face_width for a in subjects],
        "overjet": [-a.lower_incisor_tip_rest[0] for a in subjects],
    }.items():
        mean, sd = synth.NORMS[key]
        assert np.mean(values) == pytest.approx(mean, abs=3 * sd / np.sqrt(400)), key
        assert np.std(values) == pytest.approx(sd, rel=0.15), key
    depth = [np.linalg.norm(a.mni_rest - a.lower_incisor_tip_rest) for a in subjects]
    expected = np.hypot(synth.NORMS["mni_depth"][0], synth.NORMS["mni_labial"][0])
    assert np.median(depth) == pytest.approx(expected, abs=0.3)
    assert np.std(depth) > 0.5  # a spread, not one model-derived offset


def test_subjects_differ():
    distances = {round(zoo.subject(i).jaw_pellet_distance, 3) for i in range(15)}
    assert len(distances) == 15


# ------------------------------------------------------------------------ kinematics
@pytest.mark.parametrize("task", ["tp106", "tp040"])
def test_mandible_moves_exactly_rigidly(task):
    _, truth = zoo.recording(task, 2)
    a = zoo.subject(2)
    jaw = truth.pellets_true[:, 6:8]
    distance = np.linalg.norm(jaw[:, 0] - jaw[:, 1], axis=1)
    np.testing.assert_allclose(distance, a.jaw_pellet_distance, atol=1e-9)
    with jax.enable_x64(True):
        moved = jax.vmap(rigid.apply, in_axes=(0, 0, None))(
            truth.theta, truth.translation, np.stack([a.mni_rest, a.mnm_rest, a.condyle_rest])
        )
    moved = np.asarray(moved)
    np.testing.assert_allclose(moved[:, :2], jaw, atol=1e-9)
    np.testing.assert_allclose(moved[:, 2], truth.condyle, atol=1e-9)


@pytest.mark.parametrize("index", [0, 1, 2])  # physiological, fixed-condyle, thrust
def test_pivot_is_the_fixed_point(index):
    _, truth = zoo.jaw_wagging(index)
    assert truth.pivot_defined.all()  # theta > 0 throughout this task
    with jax.enable_x64(True):
        image = jax.vmap(rigid.apply)(truth.theta, truth.translation, truth.pivot)
    np.testing.assert_allclose(np.asarray(image), truth.pivot, atol=1e-8)


def _family_subject(family, index=0):
    name = synth.subject_names(index + 1)[index]
    return synth.make_subject(name, np.random.default_rng([0, 1, index]), jaw_kinematics=family)


def _wagging(anatomy, index=0):
    return synth.synth_recording(anatomy, "tp106", seed=[0, 2, index, 11], noise_mm=0.0,
                                 dropouts=False, mistracks=False)[1]  # fmt: skip


@pytest.mark.parametrize("index", range(4))
def test_fixed_condyle_rotates_about_a_fixed_centre(index):
    anatomy = _family_subject("fixed-condyle", index)
    truth = _wagging(anatomy, index)
    np.testing.assert_allclose(truth.condyle, np.broadcast_to(anatomy.condyle_rest,
                                                              truth.condyle.shape), atol=1e-9)
    np.testing.assert_allclose(truth.pivot, np.broadcast_to(anatomy.condyle_rest,
                                                            truth.pivot.shape), atol=1e-6)


@pytest.mark.parametrize("index", range(4))
def test_physiological_condyle_glides_on_a_curved_path_coupled_to_rotation(index):
    anatomy = _family_subject("physiological", index)
    truth = _wagging(anatomy, index)
    glide = truth.condyle - anatomy.condyle_rest
    distance = np.linalg.norm(glide, axis=1)
    deg = np.rad2deg(truth.theta)
    # Coupled: the glide is a function of the angle, growing with it (rotation first).
    order = np.argsort(deg)
    assert np.all(np.diff(distance[order]) >= -1e-9)
    assert distance[deg < 3.0].max() < 0.8 and distance.max() > 4.0
    # Forward and down, and curved: the heading flattens as the condyle glides on.
    assert np.all(glide[distance > 0.5, 0] > 0) and np.all(glide[distance > 0.5, 1] < 0)
    early = glide[np.argmin(np.abs(distance - 1.0))]
    late = glide[np.argmax(distance)]
    heading = np.rad2deg(np.arctan2(-early[1], early[0])), np.rad2deg(
        np.arctan2(-(late - early)[1], (late - early)[0]))
    assert heading[0] - heading[1] > 5.0, heading
    # The true rotation centre therefore moves as the jaw opens (not a hinge).
    assert np.ptp(truth.pivot, axis=0).max() > 5.0


def test_thrust_translates_independently_of_rotation():
    anatomy = _family_subject("thrust", 2)
    truth = _wagging(anatomy, 2)
    glide = np.linalg.norm(truth.condyle - anatomy.condyle_rest, axis=1)
    assert glide.max() > 0.5
    steps = np.abs(np.diff(glide))
    assert steps.max() > 0.3 and np.mean(steps > 1e-9) < 0.05  # held levels that jump
    # Not a function of the angle: frames at nearly the same angle, glides far apart.
    deg = np.rad2deg(truth.theta)
    close = np.abs(deg[:, None] - deg[None, :]) < 0.05
    assert (np.abs(glide[:, None] - glide[None, :])[close]).max() > 0.5
    # With the jaw not turning at all, the motion is a pure translation: no pivot.
    n = 400
    protrusion = synth.thrust_protrusion_mm(anatomy, n, 4, np.random.default_rng(1))
    assert np.ptp(protrusion) > 0.3
    offset = synth.condyle_offset(anatomy, np.zeros(n), protrusion)
    t, pivot, defined, moved = synth._jaw_motion(anatomy, np.zeros(n), offset,
                                                 anatomy.pellets_rest[6:])  # fmt: skip
    assert not defined.any() and np.abs(t).max() > 0.3
    np.testing.assert_allclose(moved - anatomy.pellets_rest[6:], np.repeat(t[:, None], 2, 1))


def _mni_per_degree(truth):
    """(x, y) mm of true MNI displacement per degree of true opening (least squares)."""
    deg = np.rad2deg(truth.theta)
    mni = truth.pellets_true[:, 6] - truth.pellets_true[0, 6]
    design = np.stack([deg, np.ones_like(deg)], axis=1)
    return np.linalg.lstsq(design, mni, rcond=None)[0][0]


@pytest.mark.parametrize("index", range(3))
def test_speech_jaw_translates_with_and_apart_from_the_rotation(index):
    """The speech family's incisor goes nearly straight down as the jaw opens (the glide
    cancels a hinge's backward swing: JW11's MNI moves -0.09 mm forward per degree, a
    fixed condyle's -0.6), and its translation is not a function of the angle."""
    speech = _family_subject("speech", index)
    hinge = _family_subject("fixed-condyle", index)
    assert 0.6 <= speech.speech_slide_mm_per_deg <= 1.2
    record = dict(seed=[0, 2, index, 5], noise_mm=0.0, dropouts=False, mistracks=False)
    truth = synth.synth_recording(speech, "tp005", **record)[1]
    x_speech, y_speech = _mni_per_degree(truth)
    x_hinge, _ = _mni_per_degree(synth.synth_recording(hinge, "tp005", **record)[1])
    assert x_hinge < -0.5 and -0.35 < x_speech < 0.2, (x_hinge, x_speech)
    assert -2.4 < y_speech < -1.7, y_speech  # an effective radius beyond the condyle's
    # Its own protrusion on top of the coupled glide: frames at nearly the same angle sit
    # at condyle positions millimetres apart (a fixed-condyle or physiological jaw: 0).
    deg = np.rad2deg(truth.theta)
    close = np.abs(deg[:, None] - deg[None, :]) < 0.05
    apart = np.linalg.norm(truth.condyle[:, None] - truth.condyle[None, :], axis=-1)[close]
    assert 0.5 < apart.max() < 8.0, apart.max()
    # The motion is still rigid in the plane, so the pivot truth stays exact.
    jaw = truth.pellets_true[:, 6:8]
    np.testing.assert_allclose(np.linalg.norm(jaw[:, 0] - jaw[:, 1], axis=1),
                               speech.jaw_pellet_distance, atol=1e-9)


def test_xrmb_measurement_is_band_limited_and_follows_the_jaw():
    """The xrmb family's noise has no power a 10 ms Gaussian removes (JW11: 0.007 mm of
    the jaw pellet distance; realistic: 0.17 mm), and the molar pellet's out-of-plane
    error follows the opening (slope of the distance against the angle)."""
    from scipy.ndimage import gaussian_filter1d

    anatomy = _family_subject("speech", 1)
    out = {}
    for family in ("xrmb", "realistic"):
        track, truth = synth.synth_recording(anatomy, "tp005", seed=[3, 1], dropouts=False,
                                             mistracks=False, noise_family=family)
        lead = int(np.argmax(track.valid.any(axis=(1, 2))))
        pos = track.positions[lead:]
        distance = np.linalg.norm(pos[:, 6] - pos[:, 7], axis=1)
        dev = distance - distance.mean()
        out[family] = (np.std(dev - gaussian_filter1d(dev, 0.010 / synth.FRAME_STEP_S)),
                       np.corrcoef(dev[1:], dev[:-1])[0, 1], np.std(dev),
                       np.polyfit(np.rad2deg(truth.theta[lead:]), distance, 1)[0])
    hp, lag1, sd, slope = out["xrmb"]
    assert hp < 0.02 and lag1 > 0.98, out
    assert out["realistic"][0] > 0.1 and out["realistic"][1] < 0.8, out
    assert 0.15 < sd < 0.45, out  # JW11: 0.30 mm
    # MNM (behind MNI) moved forward by lateral * sin(yaw) shortens the distance
    expected = -anatomy.mnm_lateral_mm * np.deg2rad(anatomy.jaw_yaw_per_deg)  # mm/deg
    assert abs(expected) > 0.05 and slope == pytest.approx(expected, abs=0.03), out
    # noise scale 0 is ideal data, the out-of-plane error included
    track, truth = synth.synth_recording(anatomy, "tp005", seed=[3, 1], noise_mm=0.0,
                                         dropouts=False, mistracks=False, noise_family="xrmb")
    lead = int(np.argmax(track.valid.any(axis=(1, 2))))
    np.testing.assert_allclose(track.positions[lead:], truth.pellets_true[lead:], atol=6e-4)


def test_the_family_changes_nothing_but_the_jaw_motion():
    a = _family_subject("thrust", 3)
    b = _family_subject("fixed-condyle", 3)
    np.testing.assert_array_equal(a.pellets_rest, b.pellets_rest)
    assert a.head == b.head
    ta, tb = _wagging(a, 3), _wagging(b, 3)
    np.testing.assert_array_equal(ta.theta, tb.theta)
    assert not np.allclose(ta.translation, tb.translation)
    with pytest.raises(CassiError, match="jaw kinematics"):
        _family_subject("hinge")


def test_jaw_angles_speech_versus_wagging():
    speech_peaks = [np.rad2deg(zoo.recording("tp040", i)[1].theta.max()) for i in range(4)]
    wag_peaks = [np.rad2deg(zoo.jaw_wagging(i)[1].theta.max()) for i in range(4)]
    assert all(5.0 <= p <= 15.0 for p in speech_peaks), speech_peaks
    assert all(18.0 <= p <= 27.0 for p in wag_peaks), wag_peaks
    _, truth = zoo.sentence(0)
    assert np.all(truth.theta >= 0.0)


@pytest.mark.slow
def test_pellet_ranges_match_a_real_speaker():
    truths = [zoo.recording(t, i)[1] for i in range(15) for t in SPEECH_TASKS]
    pellets = np.concatenate([t.pellets_true for t in truths])
    for k, name in enumerate(synth.PELLETS):
        for axis in range(2):
            lo, mid, hi = np.percentile(pellets[:, k, axis], [1, 50, 99])
            real_lo, real_mid, real_hi = REAL[name][axis]
            where = f"{name} {'xy'[axis]}: ours {lo:.1f}/{mid:.1f}/{hi:.1f}"
            assert abs(mid - real_mid) < 2.5, where
            assert abs(lo - real_lo) < 6.5 and abs(hi - real_hi) < 6.5, where
            assert lo < real_mid < hi, where


@pytest.mark.parametrize("task", ALL_TASKS)
def test_tongue_stays_below_the_palate_and_speeds_are_bounded(task):
    _, truth = zoo.recording(task, 4)
    palate = zoo.subject(4).palate
    tongue = truth.pellets_true[:, 2:6]
    ceiling = np.interp(tongue[..., 0], palate[::-1, 0], palate[::-1, 1])
    assert np.all(tongue[..., 1] < ceiling)
    contact = (ceiling - tongue[..., 1] < 1.5).any(axis=1)
    if task != "tp101":  # a swallow presses the tongue to the palate on purpose
        assert contact.mean() < 0.35  # contact is brief
    speed = np.linalg.norm(np.diff(truth.pellets_true, axis=0), axis=2) / synth.FRAME_STEP_S
    assert speed.max() < 300.0


def test_swallow_touches_the_palate_and_protrusion_pushes_t1_forward():
    palate = zoo.subject(0).palate
    _, swallow = zoo.recording("tp101", 0)
    t = swallow.pellets_true[:, 2:6]
    gap = np.interp(t[..., 0], palate[::-1, 0], palate[::-1, 1]) - t[..., 1]
    assert gap.min() < 1.5
    _, protrusion = zoo.recording("tp104", 0)
    _, sentence = zoo.sentence(0)
    assert protrusion.pellets_true[:, 2, 0].max() > sentence.pellets_true[:, 2, 0].max() + 10.0
    assert protrusion.pellets_true[:, 2, 0].max() > -2.0


# ----------------------------------------------------------------------- measurement
def test_leading_rows_time_axis_and_validity():
    track, truth = zoo.sentence(5)
    assert track.times[0] == 0.0
    np.testing.assert_allclose(np.diff(track.times), 6866e-6, atol=1e-12)
    lead = int(np.argmax(track.valid.any(axis=(1, 2))))
    assert 4 <= lead <= 10 and not track.valid[:lead].any()
    np.testing.assert_array_equal(track.valid, ~truth.dropped)
    assert np.isnan(track.positions[~track.valid]).all()
    assert np.isfinite(track.positions[track.valid]).all()
    assert truth.dropped[lead:].any()  # a few dropouts after the leading rows
    np.testing.assert_array_equal(truth.times, track.times)


def test_noise_size_and_mistracks_are_as_recorded():
    track, truth = zoo.jaw_wagging(6)
    error = np.linalg.norm(track.positions - truth.pellets_true, axis=2)  # (n, 8), NaN dropped
    tracked = track.valid.all(axis=2)
    assert truth.mistracked.any()
    assert np.all(error[truth.mistracked & tracked] > 2.5)
    assert np.nanmax(np.where(truth.mistracked, np.nan, error)) < 2.5
    jaw_ok = tracked[:, 6] & tracked[:, 7] & ~truth.mistracked[:, 6:].any(axis=1)
    distance = np.linalg.norm(track.positions[jaw_ok, 6] - track.positions[jaw_ok, 7], axis=1)
    assert 0.2 < distance.std() < 0.4  # about 0.3 mm, as in real files


@pytest.mark.parametrize("family", ["white", "drift", "realistic"])
@pytest.mark.parametrize("sd", [0.1, 0.25, 0.5])
def test_noise_families_have_the_stated_sd(family, sd):
    track, truth = synth.synth_recording(zoo.subject(0), "tp040", seed=[5, 1], noise_mm=sd,
                                         dropouts=False, mistracks=False, noise_family=family)
    lead = int(np.argmax(track.valid.any(axis=(1, 2))))
    noise = track.positions[lead:] - truth.pellets_true[lead:]  # (n, 8, 2)
    assert noise.std() == pytest.approx(sd, rel=0.12 if family == "white" else 0.3)
    lag1 = np.mean([np.corrcoef(noise[1:, k, a], noise[:-1, k, a])[0, 1]
                    for k in range(8) for a in range(2)])  # fmt: skip
    # white: independent frames; drift: a slow wander (0.4 s >> 6.9 ms); realistic: half
    expected = {"white": (-0.1, 0.1), "drift": (0.99, 1.0), "realistic": (0.3, 0.65)}[family]
    assert expected[0] < lag1 <= expected[1], lag1


def test_noise_scales_and_clean_recordings_have_no_corruption():
    track, truth = zoo.recording("tp040", 0, noise_mm=0.0, clean=True)
    lead = int(np.argmax(track.valid.any(axis=(1, 2))))
    assert track.valid[lead:].all() and not truth.mistracked.any()
    np.testing.assert_allclose(track.positions[lead:], truth.pellets_true[lead:], atol=5e-4)
    loud, _ = zoo.recording("tp040", 0, noise_mm=1.0, clean=True)
    spread = np.nanstd(loud.positions[lead:] - truth.pellets_true[lead:])
    assert 0.8 < spread < 1.2


# ------------------------------------------------------------------------------ files
def test_files_round_trip_through_the_readers(corpus):
    from cassi_fit.dataset import Dataset
    from cassi_fit.headmeasures import read_headmeasures
    from cassi_fit.outlines import read_outline
    from cassi_fit.txy import read_txy

    assert (corpus / "S01" / "TP106.TXY").is_file() and (corpus / "S02" / "tp106.txy").is_file()
    dataset = Dataset(corpus)
    assert [s.upper() for s in dataset.subjects()] == ["S01", "S02"]
    heads = read_headmeasures(corpus / "Headmeasures.txt")
    for index, name in enumerate(["S01", "S02"]):
        anatomy = synth.load_anatomy(corpus, name)
        np.testing.assert_array_equal(anatomy.palate, zoo.subject(index).palate)
        assert anatomy.head == zoo.subject(index).head == heads[name]
        np.testing.assert_allclose(read_outline(dataset.load(name, "tp106").path.parent
                                                / ("PAL.DAT" if index == 0 else "pal.dat")),
                                   anatomy.palate, atol=1e-12)  # fmt: skip
        assert {t.lower() for t in dataset.tasks(name)} == set(zoo.SMALL_CORPUS_TASKS)
        for task in zoo.SMALL_CORPUS_TASKS:
            track, truth = zoo.recording(task, index)
            read = read_txy(dataset.pellet_path(name, task))
            np.testing.assert_array_equal(read.valid, track.valid)
            np.testing.assert_allclose(read.positions, track.positions, atol=1e-9)
            np.testing.assert_allclose(read.times, track.times, atol=1e-12)
            loaded = synth.load_truth(corpus, name, task)
            np.testing.assert_allclose(loaded.pellets_true, truth.pellets_true, atol=1e-6)
            np.testing.assert_allclose(loaded.theta, truth.theta, atol=1e-11)
            np.testing.assert_allclose(loaded.translation, truth.translation, atol=1e-6)
            np.testing.assert_allclose(loaded.pivot, truth.pivot, atol=1e-6)
            np.testing.assert_array_equal(loaded.pivot_defined, truth.pivot_defined)
            np.testing.assert_array_equal(loaded.dropped, truth.dropped)
            np.testing.assert_array_equal(loaded.mistracked, truth.mistracked)


def test_audio_is_aligned_and_follows_the_speech(corpus):
    from cassi_fit.dataset import Dataset

    recording = Dataset(corpus).load("S02", "tp040")
    assert recording.audio is not None and recording.audio.name == "tp040.wav"
    with wave.open(str(recording.audio), "rb") as w:
        assert (w.getnchannels(), w.getsampwidth(), w.getframerate()) == (1, 2, 16000)
        samples = np.frombuffer(w.readframes(w.getnframes()), "<i2").astype(float)
    duration = recording.track.n_frames * 6866e-6
    assert abs(samples.size / 16000 - duration) <= 1 / 16000
    lead = int(np.argmax(recording.track.valid.any(axis=(1, 2))))
    silent = samples[: int(lead * 6866e-6 * 16000)]
    assert np.sqrt(np.mean(silent**2)) < 0.02 * np.sqrt(np.mean(samples**2))
    assert not (corpus / "S02" / "tp106.wav").exists()  # no audio for jaw wagging


def test_truth_and_anatomy_errors(corpus, tmp_path):
    with pytest.raises(MissingDataError):
        synth.load_truth(corpus, "S01", "tp999")
    with pytest.raises(MissingDataError):
        synth.load_anatomy(corpus, "S09")
    bad = tmp_path / "S01"
    bad.mkdir()
    good = (corpus / "S01" / "tp106.truth.csv").read_text().splitlines()
    (bad / "tp106.truth.csv").write_text("\n".join(good[:5] + ["1,2,3"]) + "\n")
    with pytest.raises(MissingDataError, match="not a complete synthetic corpus"):
        synth.load_truth(tmp_path, "s01", "TP106")  # no README.txt: an unfinished corpus
    (tmp_path / "README.txt").write_text((corpus / "README.txt").read_text())
    with pytest.raises(DataFormatError, match=r"tp106.truth.csv:6:"):
        synth.load_truth(tmp_path, "s01", "TP106")
    (bad / "anatomy.json").write_text("{}")
    with pytest.raises(DataFormatError, match="anatomy.json"):
        synth.load_anatomy(tmp_path, "S01")


def test_generation_is_byte_identical_and_refuses_to_overwrite(tmp_path):
    first = synth.generate_corpus(tmp_path / "a", n_subjects=1, tasks=["tp020"], seed=3)
    second = synth.generate_corpus(tmp_path / "b", n_subjects=1, tasks="tp020", seed=3)
    names = sorted(p.relative_to(first) for p in first.rglob("*") if p.is_file())
    assert names == sorted(p.relative_to(second) for p in second.rglob("*") if p.is_file())
    for name in names:
        assert (first / name).read_bytes() == (second / name).read_bytes(), name
    before = (first / "S01" / "TP020.TXY").read_bytes()
    with pytest.raises(OutputExistsError):
        synth.generate_corpus(first, n_subjects=1, tasks=["tp020"], seed=4)
    assert (first / "S01" / "TP020.TXY").read_bytes() == before
    synth.generate_corpus(first, n_subjects=1, tasks=["tp020"], seed=4, overwrite=True)
    assert (first / "S01" / "TP020.TXY").read_bytes() != before
    assert "seed: 4" in (first / "README.txt").read_text()


@pytest.mark.parametrize(
    "kwargs",
    [{"n_subjects": 0}, {"tasks": ["tp999"]}, {"noise_scale": -1.0}, {"tasks": []},
     {"noise_scale": 1e6}, {"noise_scale": float("nan")}, {"seed": -1}, {"seed": 1.5},
     {"jaw_kinematics": "hinge"}, {"jaw_kinematics": ""}, {"noise_family": "pink"}],
)  # fmt: skip
def test_bad_arguments_raise_the_toolkit_error(tmp_path, kwargs):
    with pytest.raises(CassiError):
        synth.generate_corpus(tmp_path / "c", n_subjects=kwargs.pop("n_subjects", 1), **kwargs)
    assert list(tmp_path.iterdir()) == []  # refused before anything is written


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def test_an_interrupted_generation_leaves_nothing_that_looks_complete(tmp_path, monkeypatch):
    import cassi_fit.headmeasures

    out = tmp_path / "corpus"
    monkeypatch.setattr(cassi_fit.headmeasures, "write_headmeasures", _interrupt)
    with pytest.raises(KeyboardInterrupt):
        synth.generate_corpus(out, n_subjects=2, tasks=["tp106"])
    assert list(tmp_path.iterdir()) == []  # no corpus, no hidden temporary folder
    monkeypatch.undo()
    synth.generate_corpus(out, n_subjects=1, tasks=["tp106"], seed=1)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    monkeypatch.setattr(cassi_fit.headmeasures, "write_headmeasures", _interrupt)
    with pytest.raises(KeyboardInterrupt):
        synth.generate_corpus(out, n_subjects=1, tasks=["tp106"], seed=2, overwrite=True)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before  # untouched
    assert [p.name for p in tmp_path.iterdir()] == ["corpus"]
    assert synth.corpus_status(out) == "complete"
    # A README without its last line (moved half-way) is refused by the readers.
    readme = out / "README.txt"
    readme.write_text(readme.read_text().replace(synth.COMPLETE_LINE, ""))
    assert synth.corpus_status(out) == "incomplete"
    with pytest.raises(MissingDataError, match="not a complete synthetic corpus"):
        synth.load_anatomy(out, "S01")


def test_corpus_families_are_as_asked_and_recorded(tmp_path):
    out = synth.generate_corpus(tmp_path / "m", n_subjects=4, tasks=["tp020"], audio=False)
    families = [synth.load_anatomy(out, n).jaw_kinematics for n in ("S01", "S02", "S03", "S04")]
    assert families == ["physiological", "fixed-condyle", "thrust", "physiological"]
    assert "S02 fixed-condyle" in (out / "README.txt").read_text()
    out = synth.generate_corpus(tmp_path / "t", n_subjects=2, tasks=["tp020"], audio=False,
                                jaw_kinematics="thrust,fixed-condyle", noise_family="white")
    assert [synth.load_anatomy(out, n).jaw_kinematics for n in ("S01", "S02")] == [
        "thrust", "fixed-condyle"]
    assert "noise_family: white" in (out / "README.txt").read_text()


def test_default_corpus_location_and_ensure(tmp_path, monkeypatch):
    monkeypatch.delenv("CASSI_SYNTH_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    assert synth.default_corpus_dir().parent == tmp_path / "cache" / "cassi_fit"
    monkeypatch.setenv("CASSI_SYNTH_DIR", str(tmp_path / "corpus"))
    assert synth.default_corpus_dir() == tmp_path / "corpus"
    from cassi_fit.synth import _corpus  # the stage module that reads the default's arguments

    monkeypatch.setattr(_corpus, "_DEFAULT_CORPUS_ARGS", {"n_subjects": 1, "seed": 0})
    root = synth.ensure_default_corpus()
    assert root == tmp_path / "corpus" and (root / "S01" / "TP106.TXY").is_file()
    stamp = (root / "README.txt").stat().st_mtime_ns
    assert synth.ensure_default_corpus() == root  # present: not regenerated
    assert (root / "README.txt").stat().st_mtime_ns == stamp
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp left


# -------------------------------------------------------------------------------- CLI
def test_cassi_synth_in_process(tmp_path, capsys):
    out = tmp_path / "corpus"
    args = ["synth", str(out), "--subjects", "1", "--tasks", "tp106,TP040", "--seed", "2"]
    assert main([*args, "--no-audio"]) == 0
    assert (out / "S01" / "TP040.TXY").is_file() and not (out / "S01" / "TP040.WAV").exists()
    assert "seed: 2" in (out / "README.txt").read_text()
    assert main(args) == 2  # exists
    assert "file exists" in capsys.readouterr().err
    assert main([*args, "--force", "--noise-scale", "0.5"]) == 0
    assert (out / "S01" / "TP040.WAV").is_file()
    assert main(["synth", str(tmp_path / "x"), "--tasks", "tp999"]) == 2
    assert "unknown task" in capsys.readouterr().err
    assert main(["synth", str(tmp_path / "x"), "--tasks", "list"]) == 0
    assert "tp106" in capsys.readouterr().out
    for bad in (["--noise-scale", "1e6"], ["--jaw-kinematics", "hinge"], ["--seed", "-3"],
                ["--noise-family", "pink"]):  # fmt: skip
        assert main(["synth", str(tmp_path / "y"), "--subjects", "1", *bad]) == 2, bad
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "y").exists()
    args = ["synth", str(tmp_path / "z"), "--subjects", "1", "--tasks", "tp020", "--no-audio"]
    assert main([*args, "--jaw-kinematics", "fixed-condyle", "--noise-family", "drift"]) == 0
    assert synth.load_anatomy(tmp_path / "z", "S01").jaw_kinematics == "fixed-condyle"


def test_the_default_subjects_jaws_have_adult_proportions():
    """Gonial angle (condyle-gonion-gnathion) and mandibular body (gonion-gnathion) of the
    default corpus's 15 subjects within Jarabak & Fizzell's adult norms (130 +- 7 degrees,
    Go-Me 71 +- 5 mm) +- 2.5 SD; generator version 5 drew 101-110 degrees and 87-97 mm,
    which asked the calibration for jaws at its bound (docs/SYNTHETIC.md, "Anatomy")."""
    for i in range(15):
        s = synth.make_subject(f"S{i + 1:02d}", np.random.default_rng([0, 1, i]))
        go = np.array([s.head.gonion_x, s.head.gonion_y])
        gn = np.array([s.head.gnathion_x, s.head.gnathion_y])
        a, b = s.condyle_rest - go, gn - go
        angle = np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))
        assert 130.0 - 17.5 <= angle <= 130.0 + 17.5, (s.name, angle)
        assert 71.0 - 12.5 <= np.linalg.norm(b) <= 71.0 + 12.5, (s.name, np.linalg.norm(b))
        assert 50.0 <= np.linalg.norm(a) <= 60.0  # the ramus height drawn


# ------------------------------------------- what the synthetic writers did not write
def test_foreign_data_of_a_synthetic_corpus(tmp_path_factory, tmp_path):
    """A corpus the synthetic writer wrote holds no foreign data; anything a user adds
    to it (a real recording, labels, another subject's head measures, a README of their
    own, a FIFO) is listed, and refuse_foreign_data names the folder and the first."""
    import os
    import shutil

    import zoo

    from cassi_fit.errors import OutputExistsError
    from cassi_fit.synth import foreign_data, refuse_foreign_data

    corpus = zoo.small_corpus(tmp_path_factory)
    assert foreign_data(corpus) == []
    assert foreign_data(tmp_path / "absent") == [] and foreign_data(tmp_path) == []
    refuse_foreign_data(corpus)  # nothing to say
    copy = tmp_path / "corpus"
    shutil.copytree(corpus, copy)
    headmeasures = (copy / "Headmeasures.txt").read_text()
    added = {
        "S01/TP999.TXY": (copy / "S01" / "TP106.TXY").read_text(),  # no truth sidecar
        "S01/TP106.lab": "0 0.5 a\n",
        "JW11/tp005.txy": "0" + "\t1000000" * 16 + "\n",
        "JW11/PAL.DAT": " -4000 4433\n",
        "jw11_pha.dat": " -90663 16444\n -90629 -24627\n",
        "S02/tp040.truth.csv": "time_s\n0\n",  # a sidecar that is not the generator's
    }
    for rel, text in added.items():
        (copy / rel).parent.mkdir(exist_ok=True)
        (copy / rel).write_text(text)
    os.mkfifo(copy / "S02" / "tp777.txy")
    expected = {copy / rel for rel in added} | {copy / "S02" / "tp777.txy"}
    # S02's tp040.txy and .wav lose their synthetic sidecar with it
    expected |= {p for p in (copy / "S02").iterdir() if p.name.lower() in ("tp040.txy",
                                                                             "tp040.wav")}
    assert set(foreign_data(copy)) == expected
    (copy / "Headmeasures.txt").write_text(headmeasures + "JW11 " + " 1" * 10 + "\n")
    (copy / "README.txt").write_text("JW11 from the XRMB database\n")
    found = foreign_data(copy)
    assert {copy / "Headmeasures.txt", copy / "README.txt"} <= set(found)
    with pytest.raises(OutputExistsError, match="did not write") as info:
        refuse_foreign_data(copy)
    message = str(info.value)
    assert message.startswith(f"{copy}: holds data cassi synth did not write ({found[0]} and")
    assert "\n" not in message


def test_the_real_recording_is_foreign_data():

    from cassi_fit.synth import foreign_data

    jw11 = real_data(XRMB_JW11)
    if jw11 is None:
        pytest.skip(missing(XRMB_JW11))
    names = {p.name for p in foreign_data(jw11)}
    assert {"jw11_tp005.txy", "jw11_pal.dat", "jw11_pha.dat", "jw11_tp005.wav",
            "jw11_tp005.lab"} <= names
