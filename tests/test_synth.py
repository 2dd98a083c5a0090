"""The synthetic corpus: anatomy, rigid-jaw kinematics, measurement effects, files, CLI."""

import wave

import jax
import numpy as np
import pytest
import zoo

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
    assert -4.5 < tip[0] < -2 and -2 < tip[1] < 0  # behind the upper tip: overjet
    assert mni[0] > tip[0] and mni[1] < tip[1] - 1.5  # MNI in front of and below the tip
    behind, above = tip - a.condyle_rest
    assert 90 <= behind <= 100 and -30 <= above <= -20
    np.testing.assert_array_equal(a.chin_rest, [a.head.gnathion_x, a.head.gnathion_y])
    np.testing.assert_array_equal(a.pellets_rest[6:], [a.mni_rest, a.mnm_rest])
    assert a.upper_lip_thickness == a.head.upper_lip_thickness
    assert 120 < a.face_width == a.head.face_width < 155


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


def test_generator_constants_match_the_face_model():
    from cassi_fit.face_model import load_model

    model = load_model()
    v = np.asarray(model.vertices)[:, :2]
    mni, mnm = v[model.landmarks["MNI"]], v[model.landmarks["MNM"]]
    tip = v[model.landmarks["lower_incisor_tip"]]
    forward = (mni - mnm) / np.linalg.norm(mni - mnm)
    assert synth.MODEL_JAW_PELLET_DISTANCE == pytest.approx(np.linalg.norm(mni - mnm), abs=1e-3)
    assert synth.MODEL_TIP_TO_MNI_ALONG == pytest.approx((mni - tip) @ forward, abs=1e-3)


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


def test_pivot_is_the_fixed_point_and_moves_as_the_jaw_opens():
    _, truth = zoo.jaw_wagging(1)
    assert truth.pivot_defined.all()  # theta > 0 throughout this task
    with jax.enable_x64(True):
        image = jax.vmap(rigid.apply)(truth.theta, truth.translation, truth.pivot)
    np.testing.assert_allclose(np.asarray(image), truth.pivot, atol=1e-8)
    closed = truth.pivot[np.argmin(truth.theta)]
    opened = truth.pivot[np.argmax(truth.theta)]
    assert np.linalg.norm(opened - closed) > 10.0  # not a fixed hinge
    slide = np.linalg.norm(truth.condyle - zoo.subject(1).condyle_rest, axis=1)
    assert 8.0 < slide.max() < 25.0  # the condyle slides forward/down on wide opening


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
    "kwargs", [{"n_subjects": 0}, {"tasks": ["tp999"]}, {"noise_scale": -1.0}, {"tasks": []}]
)
def test_bad_arguments_raise_the_toolkit_error(tmp_path, kwargs):
    with pytest.raises(CassiError):
        synth.generate_corpus(tmp_path / "c", **kwargs)
    assert not (tmp_path / "c").exists()


def test_default_corpus_location_and_ensure(tmp_path, monkeypatch):
    monkeypatch.delenv("CASSI_SYNTH_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    assert synth.default_corpus_dir().parent == tmp_path / "cache" / "cassi_fit"
    monkeypatch.setenv("CASSI_SYNTH_DIR", str(tmp_path / "corpus"))
    assert synth.default_corpus_dir() == tmp_path / "corpus"
    monkeypatch.setattr(synth, "_DEFAULT_CORPUS_ARGS", {"n_subjects": 1, "seed": 0})
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
