"""The sound checked against the pellets' length (issue 24 part 2): files written here."""

import wave

import numpy as np
import pytest

from cassi_fit.errors import DataFormatError
from cassi_fit.sound import SoundMismatchWarning, check_sound
from cassi_fit.txy import PelletTrack

RECORDING_S = 730 * 6866e-6  # JW11 task 5: 730 frames of 6866 us (5.012 s)


def _wav(path, n_samples: int, rate: int):
    with wave.open(str(path), "wb") as dst:
        dst.setnchannels(1)
        dst.setsampwidth(2)
        dst.setframerate(rate)
        dst.writeframes(np.zeros(n_samples, np.int16).tobytes())
    return path


def _track(times):
    n = len(times)
    return PelletTrack(np.asarray(times, float), np.zeros((n, 8, 2)), np.ones((n, 8, 2), bool))


def test_a_recordings_length_is_time_zero_to_the_end_of_the_last_frame():
    assert _track(np.arange(730) * 6866e-6).length_s == pytest.approx(RECORDING_S, abs=1e-9)
    # an articulograph's own line period (AG501: 4 ms), not XRMB's
    assert _track(0.5 + np.arange(250) * 0.004).length_s == pytest.approx(1.5, abs=1e-9)
    assert _track([]).length_s == 0.0


def test_sound_that_fits(tmp_path):
    check = check_sound(_wav(tmp_path / "ok.wav", 80411, 16000), RECORDING_S)  # 5.03 s
    assert (check.status, check.message, check.rate_hz) == ("ok", None, 16000)
    assert check.sound_s == pytest.approx(80411 / 16000)


@pytest.mark.parametrize("header_hz, sound_s, likely", [
    (44100, 1.82, 16000),  # 16 kHz samples, a 44.1 kHz header: 1.8 s of sound
    (8000, 10.02, 16000),  # an 8 kHz header: 10 s of sound
])
def test_a_wrong_rate_in_the_header_is_one_error(tmp_path, header_hz, sound_s, likely):
    path = _wav(tmp_path / "rate.wav", 80192, header_hz)  # 5.012 s of samples at 16 kHz
    with pytest.raises(DataFormatError, match=rf"rate.wav: {sound_s:.3g} s of sound \(80192 "
                       rf"samples at {header_hz} Hz\) for 5.01 s of pellets: the header's rate is "
                       rf"likely wrong: the samples fill the recording at {likely} Hz"):
        check_sound(path, RECORDING_S)
    with pytest.warns(SoundMismatchWarning, match=f"{likely} Hz"):
        check = check_sound(path, RECORDING_S, accept_mismatch=True)
    assert (check.status, check.likely_rate_hz) == ("rate", likely)


@pytest.mark.parametrize("n_samples, cause", [
    (40096, "the file is cut"),  # cut in half (also an 8 kHz rate: both named)
    (1600, "the file looks cut"),  # 0.1 s of sound
])
def test_far_too_little_sound_is_an_error(tmp_path, n_samples, cause):
    path = _wav(tmp_path / "cut.wav", n_samples, 16000)
    with pytest.raises(DataFormatError, match=cause):
        check_sound(path, RECORDING_S)


def test_somewhat_short_or_long_sound_warns(tmp_path):
    with pytest.warns(SoundMismatchWarning, match=r"4 s of sound .*silent after 4 s"):
        assert check_sound(_wav(tmp_path / "s.wav", 64000, 16000), RECORDING_S).status == "shorter"
    with pytest.warns(SoundMismatchWarning, match="keeps the first 5.01 s"):
        assert check_sound(_wav(tmp_path / "l.wav", 104000, 16000), RECORDING_S).status == "longer"


def test_not_a_wav_is_one_error(tmp_path):
    bad = tmp_path / "x.wav"
    bad.write_bytes(b"RIFF0000WAVEjunk")
    with pytest.raises(DataFormatError, match="x.wav: not a readable PCM .wav"):
        check_sound(bad, RECORDING_S)
    with pytest.raises(DataFormatError, match="not found"):
        check_sound(tmp_path / "missing.wav", RECORDING_S)
