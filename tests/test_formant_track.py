"""The formant tracker (cassi_fit.formant_track) on a synthetic vowel with known
resonances, and against the EMU bundle's own formant track (an independent tracker)."""

import base64
import json
from pathlib import Path

import numpy as np
import pytest
from real_data import EMU_MO1, missing, real_data
from scipy.signal import lfilter

from cassi_fit import formant_track as ft

ROOT = Path(__file__).resolve().parents[1]
EMU = real_data(EMU_MO1)
RATE = 16000.0
TRUE_F = (550.0, 1450.0, 2550.0)


def synthetic_vowel(f0_hz: float = 110.0):
    """0.3 s of silence, 0.6 s of a ``f0_hz`` pulse train (tilted -12 dB/octave) through five
    resonators (TRUE_F, then 3500 and 4500 Hz; bandwidths 80-200 Hz), 0.3 s of white noise at a tenth of the vowel's level."""
    rng = np.random.default_rng(0)
    n = int(0.6 * RATE)
    x = np.zeros(n)
    x[np.round(np.arange(0, n, RATE / f0_hz)).astype(int)] = 1.0
    x = lfilter([1.0], [1.0, -0.97], lfilter([1.0], [1.0, -0.97], x))  # a glottal pulse's tilt
    for f, b in zip(TRUE_F + (3500.0, 4500.0), (80.0, 100.0, 120.0, 150.0, 200.0), strict=True):
        r = np.exp(-np.pi * b / RATE)
        x = lfilter([1.0 - r], [1.0, -2 * r * np.cos(2 * np.pi * f / RATE), r * r], x)
    x = x / np.max(np.abs(x)) * 0.5
    noise = rng.normal(0, 0.05, int(0.3 * RATE))
    return np.concatenate([np.zeros(int(0.3 * RATE)), x, noise])


def test_synthetic_vowel_formants_and_reliability():
    times = np.array([0.15, 0.45, 0.6, 0.75, 1.05])
    track = ft.measure_formants(synthetic_vowel(), RATE, times)
    assert list(track.reason) == ["silence", "", "", "", "unvoiced"]
    assert track.share_reliable == pytest.approx(0.6)
    np.testing.assert_allclose(track.frequency[1:4], np.tile(TRUE_F, (3, 1)), rtol=0.04)


@pytest.mark.parametrize(("f0", "speaker"), [(110.0, "male"), (220.0, "female")])
def test_the_voice_says_the_speaker(f0, speaker):
    """The median F0 of the voiced frames (the silence and the noise left out) is the
    pulse train's, and the 160 Hz boundary gives the speaker."""
    heard = ft.median_f0(synthetic_vowel(f0), RATE)
    assert heard == pytest.approx(f0, rel=0.02)
    assert ft.voice_speaker(heard) == speaker
    assert ft.voice_speaker(ft.F0_BOUNDARY_HZ - 1) == "male"
    assert ft.voice_speaker(ft.F0_BOUNDARY_HZ) == "female"


@pytest.mark.parametrize(("f0", "hint"), [(110.0, False), (220.0, True)])
def test_the_default_line_names_a_high_voice(f0, hint):
    """``cassi acoustics``'s line: the default adult male norms always, and for a voice at
    220 Hz (above the 160 Hz boundary), not at 110 Hz, its F0 and the female norms' option."""
    from cassi_fit.acoustics import speaker_norms

    norms = speaker_norms(samples=synthetic_vowel(f0), rate_hz=RATE)
    line = norms.line()
    assert norms.speaker == "male" and norms.f0_hz == pytest.approx(f0, rel=0.02)
    assert line.startswith("speaker: adult male norms (larynx 30 mm below the hyoid, "
                           "formant ceiling 5000 Hz)")
    assert (f"the voice's median F0 is {f0:.0f} Hz, above 160 Hz: --speaker female (or auto) "
            "for the adult female norms" in line) is hint
    assert ("--speaker" in line) is hint and ("F0" in line) is hint


def test_male_norms_asked_for_give_no_hint():
    """``--speaker male`` given (asked, not the default): the same norms, said as asked, and
    no hint to the female norms for a high voice; the command line's default is None."""
    import argparse

    from cassi_fit._cli._options import add_speaker_argument
    from cassi_fit.acoustics import speaker_norms

    asked = speaker_norms("male", synthetic_vowel(220.0), RATE)
    assert (asked.speaker, asked.source) == ("male", "given")
    assert asked.line().startswith("speaker: adult male norms, as asked (larynx 30 mm")
    assert "--speaker" not in asked.line() and not asked.voice_suggests_female
    parser = argparse.ArgumentParser()
    add_speaker_argument(parser, "the test")
    assert parser.parse_args([]).speaker is None
    assert parser.parse_args(["--speaker", "male"]).speaker == "male"


def test_no_voice_is_none_not_nan():
    """No sound, a sound too short for the pitch window, silence and noise: no F0 (None),
    no speaker, never NaN or an error."""
    noise = np.random.default_rng(1).normal(0, 0.1, int(RATE))
    for x in (np.zeros(0), np.zeros(100), np.zeros(int(RATE)), noise):
        assert ft.median_f0(x, RATE) is None
    assert ft.median_f0(synthetic_vowel(), 0.0) is None
    assert ft.voice_speaker(None) is None and ft.voice_speaker(float("nan")) is None


@pytest.fixture
def pitch_calls(monkeypatch):
    """The number of times Praat's pitch tracker (``Sound.to_pitch``) has run."""
    import parselmouth

    calls = []
    to_pitch = parselmouth.Sound.to_pitch

    def counted(self, *args, **kwargs):
        calls.append(1)
        return to_pitch(self, *args, **kwargs)

    monkeypatch.setattr(parselmouth.Sound, "to_pitch", counted)
    return calls


def test_a_given_pitch_track_gives_the_same_formants(pitch_calls):
    """``measure_formants(pitch=voice_pitch(...))`` reads the given track (the tracker
    not run again) and measures exactly what it measures on its own."""
    x, times = synthetic_vowel(220.0), np.linspace(0.05, 1.15, 23)
    own = ft.measure_formants(x, RATE, times)
    assert len(pitch_calls) == 1
    pitch = ft.voice_pitch(x, RATE)
    given = ft.measure_formants(x, RATE, times, pitch=pitch)
    assert len(pitch_calls) == 2  # voice_pitch's, none in measure_formants
    for field in ("frequency", "bandwidth", "reliable", "reason"):
        np.testing.assert_array_equal(getattr(given, field), getattr(own, field))
    assert ft.pitch_median_f0(pitch) == ft.median_f0(x, RATE)
    assert ft.voice_pitch(np.zeros(100), RATE) is None and ft.pitch_median_f0(None) is None


class _Labels:
    def at(self, times):
        return np.full(np.shape(times), "a")


def _stub_run(monkeypatch, tmp_path, samples):
    """A run whose model part is stubbed (the tract's formants are not what is tested):
    the recording's sound ``samples`` (a .wav) and 23 animation frames."""
    import types
    import wave

    from cassi_fit import acoustics
    from cassi_fit import area_function as af
    from cassi_fit.sound import Sound

    m = 23
    monkeypatch.setattr(af, "tract_geometry", lambda model: None)
    monkeypatch.setattr(acoustics, "model_formants", lambda geometry, vertices, tract, scale: (
        np.full((m, 4), 500.0), np.full((m, 4), 80.0), np.ones((m, 5)), np.ones((m, 5))))
    monkeypatch.setattr(acoustics, "_spectra", lambda areas, lengths, hz: np.zeros((m, len(hz))))
    wav = tmp_path / "x.wav"
    with wave.open(str(wav), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(int(RATE))
        w.writeframes((samples * 32767).astype("<i2").tobytes())
    sound = Sound.from_file(wav)
    return types.SimpleNamespace(
        recording=types.SimpleNamespace(subject="S01", task="t", sound=sound),
        animation=types.SimpleNamespace(times=np.linspace(0.05, 1.15, m),
                                        vertices=np.zeros((m, 1, 3))),
        state=types.SimpleNamespace(model=None, scale=1.0))


@pytest.mark.parametrize("speaker", ["male", "auto"])
def test_praats_pitch_tracker_runs_once_per_recording(monkeypatch, tmp_path, pitch_calls, speaker):
    """``recording_acoustics`` and the tract view hear the voice (the norms, chosen before
    the formants: ``auto`` sets the ceiling from the F0) and measure the formants' voicing
    from one pitch analysis, and measure what the separate analyses measure."""
    from cassi_fit.acoustics import recording_acoustics, tract_panels
    run = _stub_run(monkeypatch, tmp_path, synthetic_vowel(220.0))
    x, rate = run.recording.sound.samples()
    result = recording_acoustics(run, samples=x, rate_hz=rate, labels=_Labels(), speaker=speaker)
    assert len(pitch_calls) == 1
    panels = tract_panels(run, speaker=speaker)
    assert len(pitch_calls) == 2
    f0 = ft.median_f0(x, rate)
    assert result.norms.f0_hz == f0 and f0 == pytest.approx(220.0, rel=0.02)
    ceiling = ft.CEILING_HZ["female" if speaker == "auto" else "male"]
    apart = ft.measure_formants(x, rate, run.animation.times, ceiling_hz=ceiling)
    assert result.measured.ceiling_hz == ceiling and result.measured.reliable.any()
    for field in ("frequency", "bandwidth", "reliable", "reason"):
        np.testing.assert_array_equal(getattr(result.measured, field), getattr(apart, field))
    np.testing.assert_array_equal(
        np.stack([p["measured_hz"] for p in panels]),
        np.where(apart.reliable[:, None], apart.frequency, np.nan))


def test_bad_input_is_one_clear_error(tmp_path):
    with pytest.raises(ValueError, match="samples"):
        ft.measure_formants(np.zeros(0), RATE, np.array([0.1]))
    bad = tmp_path / "x.wav"
    bad.write_bytes(b"not a wave")
    from cassi_fit.errors import DataFormatError

    with pytest.raises(DataFormatError, match="x.wav"):
        ft.measure_wav(bad, np.array([0.1]))


@pytest.mark.skipif(EMU is None, reason=missing(EMU_MO1))
def test_praat_agrees_with_the_emu_bundles_own_formant_track():
    """Praat's Burg against the bundle's ``fms`` track (EMU's own tracker, computed by its
    makers): on the vowels' reliable frames, the median relative difference is under 3 % for
    F2 and F3; Praat's F1 runs higher (median about 10 %), under 15 % asserted."""
    from cassi_fit.dataset import load_recording
    from cassi_fit.ema.ssff import parse_ssff
    from cassi_fit.labels import recording_labels

    bundle = next(EMU.glob("*_bndl.json"))
    recording = load_recording(bundle)  # the sound and the Segment level inside the bundle
    fms = next(f for f in json.loads(bundle.read_text())["ssffFiles"]
               if f["fileExtension"] == "fms")
    fms = parse_ssff(base64.b64decode(fms["data"]), where=f"{bundle}: fms")
    t, fm = fms.times, fms.columns["fm"]
    with recording.sound.wav_file() as wav:
        track = ft.measure_wav(wav, t)
    segments = recording_labels(recording)
    assert segments is not None and segments.tier == "Segment"
    vowels = {"O", "U", "i:", "e:", "6", "aU", "u:", "E", "a:", "@"}
    label = np.full(t.shape, "", dtype=object)
    for start, end, lab in zip(segments.starts, segments.ends, segments.labels, strict=True):
        label[(t >= start) & (t < end)] = lab
    scored = np.isin(label, list(vowels)) & track.reliable & np.all(fm[:, :3] > 0, axis=1)
    assert scored.sum() > 50
    diff = np.median(np.abs(track.frequency[scored] / fm[scored, :3] - 1), axis=0)
    assert diff[0] < 0.15 and diff[1] < 0.03 and diff[2] < 0.03
