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
    with pytest.raises(DataFormatError, match="x.wav: not a readable .wav"):
        check_sound(bad, RECORDING_S)
    with pytest.raises(DataFormatError, match="not found"):
        check_sound(tmp_path / "missing.wav", RECORDING_S)


# ---------------------------------------------------------------- what labs' .wav files hold

RATE = 16000
#: WAVE_FORMAT_EXTENSIBLE's sub-format GUIDs' tail (after the 2-byte format code)
_GUID_TAIL = b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71"


def _riff(fmt_code: int, channels: int, bits: int, data: bytes, *, extensible: bool = False,
          claimed: int | None = None) -> bytes:
    """A RIFF/WAVE file written by hand: plain or ``WAVE_FORMAT_EXTENSIBLE`` (``fmt_code``
    then its sub-format: 1 PCM, 3 float), the data chunk claiming ``claimed`` bytes."""
    import struct

    block = channels * bits // 8
    head = struct.pack("<HIIHH", channels, RATE, RATE * block, block, bits)
    if extensible:
        fmt = struct.pack("<H", 0xFFFE) + head + struct.pack("<HHI", 22, bits, 0)
        fmt += struct.pack("<H", fmt_code) + _GUID_TAIL
    else:
        fmt = struct.pack("<H", fmt_code) + head
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt
    body += b"data" + struct.pack("<I", len(data) if claimed is None else claimed) + data
    return b"RIFF" + struct.pack("<I", len(body)) + body


def _signal(channels: int = 1) -> np.ndarray:
    """0.25 s of a 220 Hz tone at half scale; a second channel is another signal (a lab's
    trigger or second microphone), which must not be read as the sound."""
    t = np.arange(RATE // 4) / RATE
    x = 0.5 * np.sin(2 * np.pi * 220 * t)
    return np.stack([x, 0.9 * np.sign(np.sin(2 * np.pi * 5 * t))][:channels], 1)


def _pcm(x: np.ndarray, bits: int) -> bytes:
    if bits == 8:
        return (np.round(x * 127) + 128).astype(np.uint8).tobytes()
    q = np.round(x * (2 ** (bits - 1) - 1)).astype("<i8")
    return b"".join(int(v).to_bytes(bits // 8, "little", signed=True) for v in q.reshape(-1))


ENCODINGS = {  # name: (file bytes, the quantisation step)
    "8-bit PCM": (lambda x: _riff(1, x.shape[1], 8, _pcm(x, 8)), 1 / 127),
    "16-bit PCM": (lambda x: _riff(1, x.shape[1], 16, _pcm(x, 16)), 2.0**-15),
    "24-bit PCM": (lambda x: _riff(1, x.shape[1], 24, _pcm(x, 24)), 2.0**-23),
    "24-bit PCM, extensible header": (
        lambda x: _riff(1, x.shape[1], 24, _pcm(x, 24), extensible=True), 2.0**-23),
    "32-bit float": (lambda x: _riff(3, x.shape[1], 32, x.astype("<f4").tobytes()), 1e-7),
    "32-bit float, extensible header": (
        lambda x: _riff(3, x.shape[1], 32, x.astype("<f4").tobytes(), extensible=True), 1e-7),
    "64-bit float": (lambda x: _riff(3, x.shape[1], 64, x.astype("<f8").tobytes()), 1e-12),
}


@pytest.mark.parametrize("channels", [1, 2])
@pytest.mark.parametrize("encoding", sorted(ENCODINGS))
def test_every_encoding_a_lab_writes_is_the_same_sound(tmp_path, encoding, channels):
    """A lab's sound as its software wrote it (24-bit and float samples, the extensible
    header most tools write for them; the standard library's ``wave`` reads none of the
    float or extensible ones, and the formants were measured from 8-, 16- and 32-bit PCM
    only): the first channel, checked against the recording and read as it was made."""
    from cassi_fit.sound import Sound

    make, step = ENCODINGS[encoding]
    x = _signal(channels)
    path = tmp_path / "s.wav"
    path.write_bytes(make(x))
    check = check_sound(path, x.shape[0] / RATE)
    assert (check.status, check.rate_hz, check.n_samples) == ("ok", RATE, x.shape[0])
    samples, rate = Sound.from_file(path).samples()
    assert rate == RATE and samples.shape == (x.shape[0],)
    np.testing.assert_allclose(samples, x[:, 0], atol=1.01 * step)
    held = Sound("rec.mat: AUDIO", "mview AUDIO", data=path.read_bytes())  # a sound inside a file
    np.testing.assert_array_equal(held.samples()[0], samples)
    assert f"{channels} channel(s)" in held.describe()


@pytest.mark.parametrize("encoding", ["24-bit PCM, extensible header", "32-bit float"])
def test_a_cut_file_is_found_whatever_its_encoding(tmp_path, encoding):
    x = _signal()
    whole = ENCODINGS[encoding][0](x)
    path = tmp_path / "cut.wav"
    path.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(DataFormatError, match=r"cut.wav: the header claims 4000 samples .*the "
                       r"file is cut") as err:
        check_sound(path, x.shape[0] / RATE)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("code, name", [(2, "ADPCM"), (7, "mu-law"), (0x55, "MP3")])
def test_a_compressed_wav_is_one_error_naming_the_file(tmp_path, code, name):
    """Compressed ``.wav`` (a phone's ADPCM, telephone mu-law, MP3 in a WAVE header) is not
    decoded: one line naming the file, not a sound of noise."""
    from cassi_fit.sound import Sound

    path = tmp_path / f"{name}.wav"
    path.write_bytes(_riff(code, 1, 8, bytes(400)))
    for read in (lambda: check_sound(path, 0.05), lambda: Sound.from_file(path).samples()):
        with pytest.raises(DataFormatError, match=rf"{name}.wav: not a readable .wav") as err:
            read()
        assert "\n" not in str(err.value)


def test_the_acoustics_check_the_sound_against_the_recording(tmp_path):
    """``cassi acoustics`` checks the sound as every output does: 1 s of sound for 5 s of
    pellets is one error naming the file (the formants of four fifths of the frames would
    be silently missing), ``accept_mismatch`` keeps it with a warning."""
    import types

    from cassi_fit.acoustics import recording_sound
    from cassi_fit.sound import Sound

    wav = _wav(tmp_path / "cut.wav", 16000, 16000)
    recording = types.SimpleNamespace(subject="S01", task="t", sound=Sound.from_file(wav),
                                      track=types.SimpleNamespace(length_s=5.0))
    with pytest.raises(DataFormatError, match=r"cut.wav: 1 s of sound .* for 5 s of pellets"):
        recording_sound(recording)
    with pytest.warns(SoundMismatchWarning):
        samples, rate = recording_sound(recording, accept_mismatch=True)
    assert samples.shape == (16000,) and rate == 16000.0


def test_the_share_scored_says_why_the_other_vowel_frames_are_not():
    import types

    from cassi_fit.acoustics import Acoustics

    result = types.SimpleNamespace(
        vowel=np.array([1, 1, 1, 1, 1, 0], bool), scored=np.array([1, 0, 0, 0, 0, 0], bool),
        share_scored=0.2, measured=types.SimpleNamespace(
            reliable=np.array([1, 0, 0, 1, 0, 0], bool),
            reason=np.array(["", "unvoiced", "silence", "", "unvoiced", "silence"])))
    assert Acoustics.scored_line(result) == (
        "20 % of the vowels' frames scored (5 vowel frames; not scored: 2 unvoiced, "
        "1 no model formant, 1 silence)")
    result.scored = result.vowel.copy()
    result.share_scored = 1.0
    assert Acoustics.scored_line(result) == "100 % of the vowels' frames scored"
