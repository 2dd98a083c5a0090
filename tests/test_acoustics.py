"""``cassi acoustics`` and cassi_fit.acoustics on a synthetic recording whose sound is a
synthetic vowel with labels beside it, and acoustic calibration (cassi_fit.acoustic_fit):
the solver recovers a known vocal tract from its formants, starting from the norms, away
from it.

One module for both, every run at stride 1 on a recording cut to ``SECONDS``, and the
known-tract fit on ``acoustic_fit.MAX_FRAMES`` frames: the commands and the fit then
share their compiled kernels (the animation, the area functions, the formants, the
solver), compiled once instead of once per shape."""

import wave

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.signal import lfilter

from cassi_fit import acoustic_fit, cli, synth
from cassi_fit import area_function as af
from cassi_fit.acoustics import is_vowel
from cassi_fit.dataset import Dataset
from cassi_fit.deform import default_params, deform
from cassi_fit.face_model import load_model

pytestmark = pytest.mark.slow
RATE = 16000
# the jaw-wagging recording cut to its first 0.6 s (88 lines: the frame bucket of 128),
# labelled a vowel from a tenth to nine tenths of it: the vowel still gives the acoustic
# fit more frames than it takes (acoustic_fit.MAX_FRAMES), and the fit converges on them
# as on the whole recording's
SECONDS = 0.6


def _vowel(seconds, f0_hz=120.0):
    """A pulse train at ``f0_hz`` through five resonators (F1 600 Hz), int16 samples."""
    x = np.zeros(int(seconds * RATE))
    x[:: int(RATE // f0_hz)] = 1.0
    x = lfilter([1.0], [1.0, -0.97], lfilter([1.0], [1.0, -0.97], x))
    for f, b in ((600, 80), (1200, 100), (2500, 120), (3500, 150), (4500, 200)):
        r = np.exp(-np.pi * b / RATE)
        x = lfilter([1.0 - r], [1.0, -2 * r * np.cos(2 * np.pi * f / RATE), r * r], x)
    return (x / np.max(np.abs(x)) * 20000).astype("<i2")


def _vowel_wav(path, seconds):
    pcm = _vowel(seconds)
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(RATE)
        w.writeframes(pcm.tobytes())


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    root = synth.generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=1,
                                 tasks=[synth.JAW_WAGGING_TASK], audio=False)
    dataset = Dataset(root)
    subject = dataset.subjects()[0]
    rec = dataset.load(subject, synth.JAW_WAGGING_TASK)
    # the pellet file and its truth cut to the lines before SECONDS (each a line a time)
    keep = int(np.sum(np.asarray(rec.track.times) < SECONDS))
    truth = rec.path.parent / f"{synth.JAW_WAGGING_TASK}.truth.csv"
    for path, header in ((rec.path, 0), (truth, 2)):
        lines = path.read_bytes().splitlines(keepends=True)
        path.write_bytes(b"".join(lines[: header + keep]))
    rec = dataset.load(subject, synth.JAW_WAGGING_TASK)
    assert len(rec.track.times) == keep
    seconds = float(rec.track.times[-1]) + 0.01
    _vowel_wav(rec.path.with_suffix(".wav"), seconds)
    a0, a1 = 0.1 * seconds, 0.9 * seconds
    rec.path.with_suffix(".lab").write_text(
        f"0 {a0:.3f} sil\n{a0:.3f} {a1:.3f} a\n{a1:.3f} {seconds - 0.005:.3f} sil\n")
    return rec.path


def test_is_vowel():
    assert is_vowel("a") and is_vowel("a:") and is_vowel("aU") and is_vowel("AA1")
    assert not is_vowel("s") and not is_vowel("sil") and not is_vowel("")


def test_cli_tables_figure_and_refusals(recording, tmp_path, capsys):
    out = tmp_path / "f.csv"
    png = tmp_path / "f.png"
    code = cli.main(["acoustics", str(recording), "--stride", "1", "--csv", str(out),
                     "--plot", str(png)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "% of the vowels' frames scored" in text
    header = out.read_text().splitlines()[0].split(",")
    assert {"time_s", "label", "scored", "F1_model_hz", "F1_measured_hz"} <= set(header)
    import csv

    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert {r["reason"] for r in rows if r["scored"] == "false"} >= {"silence"}
    assert "nan" not in out.read_text().lower()  # a formant Praat did not find: blank
    segments = out.with_suffix(".segments.csv").read_text().splitlines()
    assert len(segments) == 2 and segments[1].split(",")[2] == "a"
    # the synthetic vowel's resonances are measured (the model's are its own)
    f1 = float(segments[1].split(",")[segments[0].split(",").index("F1_measured_hz")])
    assert abs(f1 - 600) < 60
    assert png.stat().st_size > 10_000
    # the default norms said in one line; a 120 Hz voice: no hint to other norms
    assert [w for w in text.splitlines() if w.startswith("speaker:")] == [
        "speaker: adult male norms (larynx 30 mm below the hyoid, formant ceiling 5000 Hz)"]
    # asked for: the female norms, and a given ceiling wins over theirs
    code = cli.main(["acoustics", str(recording), "--stride", "1", "--speaker", "female",
                     "--ceiling", "5200"])
    text = capsys.readouterr().out
    assert code == 0, text
    line = [w for w in text.splitlines() if w.startswith("speaker:")]
    assert line == ["speaker: adult female norms, as asked (larynx 15 mm below the hyoid, "
                    "formant ceiling 5200 Hz as given)"]
    # an existing output is refused in one line; without a sound the formants cannot be measured
    assert cli.main(["acoustics", str(recording), "--stride", "1", "--csv", str(out)]) != 0
    assert "exists" in capsys.readouterr().err
    recording.with_suffix(".wav").rename(tmp_path / "moved.wav")
    try:
        assert cli.main(["acoustics", str(recording), "--stride", "1"]) != 0
        assert "no sound" in capsys.readouterr().err
    finally:
        (tmp_path / "moved.wav").rename(recording.with_suffix(".wav"))


def test_calibrate_acoustic_writes_the_tract_and_acoustics_reads_it(recording, tmp_path, capsys):
    dataset = recording.parent.parent  # DATASET/SUBJECT/TASK.TXY
    out = tmp_path / "cal"
    code = cli.main(["calibrate", str(dataset), "--acoustic", "--out", str(out),
                     "--accept-unconverged"])
    text = capsys.readouterr().out
    assert code == 0, text
    written = sorted(out.glob("*.acoustic.json"))
    assert len(written) == 1 and "one vowel quality" in text
    assert "speaker: adult male norms (larynx 30 mm" in text  # the prior's: the default
    assert "NOT CONVERGED" not in text  # as on the whole recording: the cut keeps the fit's
    code = cli.main(["acoustics", str(recording), "--stride", "1", "--calibration", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "no acoustic calibration" not in text
    # the speaker's line gives the fitted larynx in place of the norms'
    assert f"mm below the hyoid, fitted to the sound ({written[0].name}), formant ceiling" in text
    written[0].write_text("{}")
    assert cli.main(["acoustics", str(recording), "--stride", "1", "--calibration", str(out)]) != 0
    assert "not an acoustic calibration" in capsys.readouterr().err


@pytest.fixture(scope="module")
def opening():
    """``(geometry, frames, measured)``: the model from rest to an opened mouth in
    MAX_FRAMES frames (the shape of every fit here) and their F1-F3 with a longer larynx
    (40 mm) and a narrower pharynx (x0.6) than the norms."""
    model = load_model()
    geometry = af.tract_geometry(model)
    p0 = default_params(model)
    opened = eqx.tree_at(lambda p: (p.jaw_translation, p.tongue), p0,
                         (jnp.array([0.0, -10.0]),
                          p0.tongue + jnp.array([[0, -10], [0, -10], [-4, -12], [-6, -10]], float)))
    # in one compiled function (op by op, every parameter's interpolation compiles its own)
    w = np.linspace(0.0, 1.0, acoustic_fit.MAX_FRAMES)
    frames = eqx.filter_jit(lambda p0, opened: jax.vmap(lambda p: deform(model, p))(jax.tree.map(
        lambda a, b: a[None] + w.reshape((-1,) + (1,) * a.ndim) * (b - a)[None], p0, opened)))(
        p0, opened)
    truth = af.TractParams(jnp.asarray(40.0), jnp.asarray(1.0), jnp.asarray(0.6), jnp.asarray(1.0))
    return geometry, frames, np.asarray(acoustic_fit.tract_formants(geometry, frames, truth,
                                                                    1.0))[:, :3]


def test_fit_recovers_a_longer_larynx_and_narrower_pharynx(opening):
    geometry, frames, measured = opening
    fit = acoustic_fit.fit_tract(geometry, frames, measured, 1.0)
    # the norms start 10 mm and a factor 0.6 away: their formants are off by several %
    assert np.max(fit.before) > 0.04
    assert fit.converged
    # the prior keeps the scales near the norms: within 3 %, from up to 8 %
    assert np.max(fit.after) < 0.03 and np.all(fit.after < fit.before / 2)
    assert abs(float(fit.tract.larynx_drop_mm) - 40.0) < 4.0
    record = acoustic_fit.tract_record(fit.tract)
    again = acoustic_fit.tract_from_record(record)
    assert float(again.pharynx_scale) == record["pharynx_scale"]


def test_a_fit_stopped_away_from_its_minimum_is_not_converged(opening, monkeypatch):
    """The solver's own test (its steps are small) is not enough: with tolerances so wide
    that it stops at its first steps, the solver reports success, and the fit, whose
    Gauss-Newton step still predicts a gain, says it did not converge (the same compiled
    fit: the tolerances are arrays)."""
    geometry, frames, measured = opening
    seen = {}
    solve = acoustic_fit._solve

    def spy(*a):
        out = solve(*a)
        seen["successful"], seen["steps"] = bool(out[1]), int(out[2])
        return out

    monkeypatch.setattr(acoustic_fit, "_solve", spy)
    monkeypatch.setattr(acoustic_fit, "SOLVER_TOL", 30.0)
    fit = acoustic_fit.fit_tract(geometry, frames, measured, 1.0)
    assert seen["successful"] and seen["steps"] < 5  # the solver says it is done
    assert not fit.converged
    assert np.max(fit.after) > 0.01  # and it is not: the recovery's fit gets under 3 %


def test_the_default_norms_keep_the_voice_and_auto_follows_it(recording):
    """The recording's run heard with a 220 Hz voice: by default the adult male norms (the
    tract's larynx 30 mm below the hyoid, Praat's ceiling 5000 Hz: main's figures), the
    voice's F0 kept and the line's hint to the female norms; ``auto``: the female norms
    (15 mm, 5500 Hz); a given ceiling wins over the norms'; no voice: the male norms."""
    from cassi_fit.acoustics import recording_acoustics, speaker_norms
    from cassi_fit.dataset import load_recording
    from cassi_fit.pipeline import run_recording

    run = run_recording(load_recording(recording), stride=1)
    seconds = float(run.animation.times[-1]) + 0.01
    high = _vowel(seconds, 220.0) / 32768.0
    default = recording_acoustics(run, samples=high, rate_hz=RATE)
    assert (default.norms.speaker, default.norms.source) == ("male", "default")
    assert default.norms.f0_hz == pytest.approx(222.0, rel=0.02)
    assert float(default.tract.larynx_drop_mm) == af.GLOTTIS_BELOW_HYOID_MM == 30.0
    assert default.measured.ceiling_hz == 5000.0
    assert "above 160 Hz: --speaker female (or auto)" in default.norms.line()
    heard = recording_acoustics(run, samples=high, rate_hz=RATE, speaker="auto")
    assert (heard.norms.speaker, heard.norms.source) == ("female", "voice")
    assert float(heard.tract.larynx_drop_mm) == af.LARYNX_DROP_MM["female"] == 15.0
    assert heard.measured.ceiling_hz == 5500.0
    assert not np.allclose(heard.model[:, :3], default.model[:, :3])  # a shorter tract
    given = recording_acoustics(run, samples=high, rate_hz=RATE, speaker="auto", ceiling_hz=5200.0)
    assert float(given.tract.larynx_drop_mm) == 15.0 and given.measured.ceiling_hz == 5200.0
    silent = speaker_norms("auto", np.zeros(len(high)), RATE)
    assert (silent.speaker, silent.source, silent.f0_hz) == ("male", "no voiced frame", None)
    assert speaker_norms().source == "default" and speaker_norms().f0_hz is None
    assert "no sound" in speaker_norms("auto").line()
    with pytest.raises(ValueError, match="robot"):
        speaker_norms("robot")
