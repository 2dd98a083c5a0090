"""Video writing: frame counts, exact XRMB frame rates, audio presence and alignment."""

import subprocess
import wave
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from cassi_fit import _io
from cassi_fit.errors import CassiError, DataFormatError, OutputExistsError
from cassi_fit.recording_video import write_animation
from cassi_fit.txy import FRAME_STEP_US
from cassi_fit.video import (
    VideoWriter,
    _ffmpeg,
    count_frames,
    frame_rate,
    media_info,
    slice_wav,
    write_video,
)

RATE = 8000
FRAME_STEP_S = FRAME_STEP_US * 1e-6  # XRMB's line period, 6.866 ms


def _frames(n, size=(61, 81)):
    """Frames with odd sides (yuv420p needs padding) and distinct content."""
    return [np.full((*size, 3), (17 * i) % 256, np.uint8) for i in range(n)]


def _write_wav(path, samples, rate=RATE):
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(np.asarray(samples, "<i2").tobytes())
    return path


def _read_wav(path):
    with wave.open(str(path), "rb") as r:
        return np.frombuffer(r.readframes(r.getnframes()), "<i2"), r.getframerate()


def _decoded_audio(path, tmp_path):
    """The MP4's sound track as mono int16 samples at RATE, decoded by ffmpeg."""
    decoded = tmp_path / "decoded.wav"
    subprocess.run(
        [
            _ffmpeg(),
            "-loglevel",
            "error",
            "-i",
            str(path),
            "-ac",
            "1",
            "-ar",
            str(RATE),
            str(decoded),
        ],
        check=True,
    )
    return _read_wav(decoded)[0]


def test_frame_rate_is_exact_rational():
    """Frames ``frame_step_s`` apart (stride x line period): the exact rate, to the us."""
    assert frame_rate(FRAME_STEP_S) == Fraction(1_000_000, 6866)
    assert frame_rate(10 * FRAME_STEP_S) == Fraction(1_000_000, 68660)
    assert float(1 / frame_rate(4 * FRAME_STEP_S)) == pytest.approx(4 * FRAME_STEP_S)
    assert frame_rate(3 * 0.002) == Fraction(1_000_000, 6000)  # an articulograph at 500 Hz, stride 3
    with pytest.raises(CassiError):
        frame_rate(0)


def test_slice_wav_is_sample_aligned_and_padded(tmp_path):
    ramp = np.arange(RATE, dtype=np.int64) % 30000  # sample i has value i (mod 30000)
    src = _write_wav(tmp_path / "ramp.wav", ramp)
    out, rate = _read_wav(slice_wav(src, tmp_path / "cut.wav", 0.25, 0.5))
    assert rate == RATE and out.size == RATE // 2
    np.testing.assert_array_equal(out, ramp[RATE // 4 : RATE // 4 + RATE // 2])
    # reaching past the end: the missing part is silence, the length is still exact
    out, _ = _read_wav(slice_wav(src, tmp_path / "tail.wav", 0.75, 0.5))
    assert out.size == RATE // 2
    np.testing.assert_array_equal(out[: RATE // 4], ramp[3 * RATE // 4 :])
    assert not out[RATE // 4 :].any()


def test_slice_wav_rejects_a_non_wav(tmp_path):
    bad = tmp_path / "bad.wav"
    bad.write_bytes(b"not a wave file at all")
    with pytest.raises(DataFormatError, match="bad.wav"):
        slice_wav(bad, tmp_path / "x.wav", 0.0, 1.0)


def test_mp4_has_every_frame_and_the_xrmb_rate(tmp_path):
    fps = frame_rate(3 * FRAME_STEP_S)
    path = write_video(tmp_path / "clip.mp4", _frames(23), fps)
    assert count_frames(path) == 23
    info = media_info(path)
    assert info["video"] and not info["audio"]
    assert info["duration"] == pytest.approx(23 / float(fps), abs=0.02)
    assert "48.55 fps" in " ".join(info["streams"])  # 1e6 / (3 * 6866) = 48.548...


def test_mp4_carries_audio_aligned_to_the_first_frame(tmp_path):
    """A click at recording time 0.6 s, video starting at t_0 = 0.4 s: heard at 0.2 s."""
    samples = np.zeros(2 * RATE)
    click = int(0.6 * RATE)
    samples[click : click + 80] = 20000
    wav = _write_wav(tmp_path / "speech.wav", samples)
    fps = frame_rate(5 * FRAME_STEP_S)
    path = write_video(tmp_path / "talk.mp4", _frames(30), fps, audio=wav, audio_start=0.4)
    info = media_info(path)
    assert info["video"] and info["audio"]
    assert count_frames(path) == 30
    heard = _decoded_audio(path, tmp_path)
    onset = np.argmax(np.abs(heard) > 5000) / RATE
    assert onset == pytest.approx(0.2, abs=0.01)
    assert heard.size / RATE == pytest.approx(30 / float(fps), abs=0.05)


def test_gif_round_trip(tmp_path):
    import imageio.v3 as iio

    path = write_video(tmp_path / "clip.gif", _frames(7), frame_rate(2 * FRAME_STEP_S))
    frames = iio.imread(path)
    assert frames.shape == (7, 61, 81, 3)
    with pytest.raises(CassiError, match="audio"):
        VideoWriter(tmp_path / "x.gif", 10, audio=tmp_path / "a.wav")


def test_outputs_are_atomic_and_respect_inputs(tmp_path):
    path = write_video(tmp_path / "a.mp4", _frames(3), 10)
    with pytest.raises(OutputExistsError):
        write_video(path, _frames(3), 10)
    write_video(path, _frames(4), 10, overwrite=True)
    assert count_frames(path) == 4
    _io.register_input(tmp_path / "input.mp4")
    with pytest.raises(OutputExistsError):
        write_video(tmp_path / "input.mp4", _frames(2), 10, overwrite=True)
    # a failure half way leaves nothing behind
    with pytest.raises(CassiError):
        write_video(tmp_path / "broken.mp4", [_frames(1)[0], np.zeros((5, 5, 3), np.uint8)], 10)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mp4"]


def test_bad_suffix_and_empty_video(tmp_path):
    with pytest.raises(CassiError, match=".avi"):
        VideoWriter(tmp_path / "x.avi", 10)
    with pytest.raises(CassiError, match="no frames"):
        write_video(tmp_path / "empty.mp4", [], 10)
    assert not list(tmp_path.iterdir())


class _FlatRenderer:
    """Stands in for render.Renderer: a grey frame whose shade encodes the frame."""

    def __init__(self):
        self.captions = []

    def render(self, vertices, *, caption=None, markers=None):
        self.captions.append(caption)
        return np.full((40, 48, 3), int(vertices[0, 0]) % 256, np.uint8)


def _fake_animation(lines, stride, times=None, step=FRAME_STEP_S):
    """An animation of the data ``lines`` whose frame ``k`` is drawn (by _FlatRenderer)
    in the shade ``k % 256``, unless ``shade`` is given per frame."""
    from types import SimpleNamespace

    m = len(lines)
    return SimpleNamespace(
        times=lines * step if times is None else times,
        frame_index=lines,
        stride=stride,
        frame_step_s=stride * step,
        n_frames=m,
        vertices=np.arange(m)[:, None, None] * np.ones((m, 3, 3)),
        pellets_measured=np.zeros((m, 8, 2)),
        pellets_model=np.zeros((m, 8, 2)),
        frame_status=np.zeros(m, int),
    )


def _decoded_shades(path):
    """The mean grey level of each decoded frame of a video."""
    done = subprocess.run([_ffmpeg(), "-loglevel", "error", "-i", str(path), "-f", "rawvideo",
                           "-pix_fmt", "gray", "-"], capture_output=True, check=True)
    return np.frombuffer(done.stdout, np.uint8).reshape(-1, 40 * 48).mean(axis=1)


@pytest.mark.parametrize(("stride", "fps"), [(1, "native"), (7, "native"), (1, 60), (2, 60)])
def test_animation_sound_is_aligned_for_any_stride(tmp_path, stride, fps):
    """Lines from index 50 (t_0 = 0.343 s); a click at recording time 0.9 s must sound at
    video time 0.9 - t_0, whatever the stride and frame rate; at 60 fps, the picture too:
    the frames turn white at the line of the click, and the first white frame is on
    screen when the click sounds (to within a frame); every caption's time is its video
    frame's."""
    lines = np.arange(50, 250, stride)
    m = len(lines)
    animation = _fake_animation(lines, stride)
    click_line = int(np.ceil(0.9 / FRAME_STEP_S))
    animation.vertices[:] = np.where(lines >= click_line, 255, 0)[:, None, None]
    samples = np.zeros(2 * RATE)
    samples[int(0.9 * RATE) : int(0.9 * RATE) + 80] = 20000
    wav = _write_wav(tmp_path / "s.wav", samples)
    renderer = _FlatRenderer()
    path = write_animation(tmp_path / "a.mp4", animation, renderer, subject="S", task="t",
                           audio=wav, progress=False, fps=fps)
    span = m * stride * FRAME_STEP_S  # the lines' time, first to the end of the last
    frames = count_frames(path)
    assert frames == (m if fps == "native" else round(span * fps))
    assert "line 51" in renderer.captions[0] and "S t" in renderer.captions[0]
    heard = _decoded_audio(path, tmp_path)
    onset = np.argmax(np.abs(heard) > 5000) / RATE
    assert onset == pytest.approx(0.9 - 50 * FRAME_STEP_S, abs=0.01)
    # sound and picture last as long as each other: frames / fps = the sound's length
    assert len(heard) / RATE == pytest.approx(frames / float(video_rate(fps, stride)), abs=0.03)
    if fps != "native":
        white = int(np.argmax(_decoded_shades(path) > 128))
        assert white / fps == pytest.approx(onset, abs=1 / fps + stride * FRAME_STEP_S / 2)
        j = 37  # a caption's time is its video frame's: t_0 + j / 60
        assert f"t = {50 * FRAME_STEP_S + j / 60:7.3f} s" in renderer.captions[j]


def video_rate(fps, stride):
    return frame_rate(stride * FRAME_STEP_S) if fps == "native" else fps


def test_video_frames_pick_the_nearest_line_on_the_files_own_clock():
    """An articulograph file at 200 Hz whose clock drops samples (a 50 ms hole): at 60
    fps each video frame shows the line nearest its time, so the picture after the hole
    stays on the sound's clock; at the data's own rate or more, one frame per line."""
    from cassi_fit.recording_video import video_frames

    times = np.arange(400) * 0.005
    times[200:] += 0.05  # ten samples never written
    animation = _fake_animation(np.arange(400), 1, times=times, step=0.005)
    chosen = video_frames(animation, 60)
    assert chosen.rate == 60
    expected = np.array([np.argmin(np.abs(times - t)) for t in chosen.times])
    assert np.array_equal(chosen.index, expected)
    assert chosen.times[0] == 0 and np.allclose(np.diff(chosen.times), 1 / 60)
    assert len(chosen.index) == round((times[-1] + 0.005) * 60)
    late = chosen.times > 1.2  # after the hole: never a line more than half a line away
    assert np.all(np.abs(times[chosen.index[late]] - chosen.times[late]) <= 0.0025 + 1e-12)
    # a rate above the data's: one frame per line, at the data's rate (no repeated frames)
    regular = _fake_animation(np.arange(10, 100, 3), 3)
    for fps in (500, "native"):
        chosen = video_frames(regular, fps)
        assert np.array_equal(chosen.index, np.arange(30))
        assert chosen.rate == frame_rate(3 * FRAME_STEP_S)


# -- no lost, destroyed or partial files (issue 12) -------------------------------------------


def _wav_bytes(fmt=1, channels=1, rate=RATE, width=2, samples=b"\x00\x01" * 100):
    """A RIFF/WAVE file written by hand, so that broken headers can be made."""
    import struct

    block = channels * width
    fmt_chunk = struct.pack("<HHIIHH", fmt, channels, rate, rate * block, block, 8 * width)
    body = b"WAVE" + b"fmt " + struct.pack("<I", 16) + fmt_chunk
    body += b"data" + struct.pack("<I", len(samples)) + samples
    return b"RIFF" + struct.pack("<I", len(body)) + body


BAD_WAVS = {
    "garbage": b"this is not a sound file, just text\n" * 4,
    "empty": b"",
    "compressed": _wav_bytes(fmt=2, width=1, samples=b"\x00" * 400),  # ADPCM: not decoded
    "rate0": _wav_bytes(rate=0),
    "silent": _wav_bytes(samples=b""),
}


@pytest.mark.parametrize("kind", sorted(BAD_WAVS))
def test_a_bad_wav_is_one_error_and_leaves_no_file(tmp_path, kind):
    wav = tmp_path / f"{kind}.wav"
    wav.write_bytes(BAD_WAVS[kind])
    with pytest.raises(DataFormatError) as info:
        write_video(tmp_path / "out_X.mp4", _frames(3), 10, audio=wav)
    message = str(info.value)
    assert message.startswith(str(wav)) and "\n" not in message
    assert sorted(p.name for p in tmp_path.iterdir()) == [wav.name]
    assert wav.read_bytes() == BAD_WAVS[kind]


def test_a_float_sound_is_sliced_and_muxed_as_it_is(tmp_path):
    """A lab's 32-bit float ``.wav`` (as Audacity or a recording program writes it; the
    toolkit refused it before): sliced sample-aligned with its values unchanged, and heard
    in the video."""
    from scipy.io import wavfile

    t = np.arange(RATE) / RATE
    tone = (0.5 * np.sin(2 * np.pi * 440 * t)).astype("<f4")
    wav = tmp_path / "float.wav"
    wav.write_bytes(_wav_bytes(fmt=3, width=4, samples=tone.tobytes()))
    rate, out = wavfile.read(slice_wav(wav, tmp_path / "cut.wav", 0.25, 0.5))
    assert rate == RATE and out.dtype == np.float32
    np.testing.assert_array_equal(out, tone[RATE // 4 : 3 * RATE // 4])
    video = write_video(tmp_path / "talk.mp4", _frames(10), 10, audio=wav)
    heard = _decoded_audio(video, tmp_path).astype(float) / 32768
    assert heard.size / RATE == pytest.approx(1.0, abs=0.05)
    assert np.sqrt(np.mean(heard[RATE // 10 : -RATE // 10] ** 2)) == pytest.approx(0.5 / np.sqrt(2),
                                                                                  rel=0.1)


def test_the_audio_is_registered_as_an_input(tmp_path):
    wav = _write_wav(tmp_path / "speech.wav", np.zeros(RATE))
    before = wav.read_bytes()
    write_video(tmp_path / "talk.mp4", _frames(2), 10, audio=wav)
    assert _io.is_input(wav)
    with pytest.raises(OutputExistsError, match="input"):
        _io.atomic_write(wav, "not sound", overwrite=True)
    assert wav.read_bytes() == before


def _only(folder, *names):
    """The folder holds exactly ``names``: no partial or hidden file."""
    assert sorted(p.name for p in folder.iterdir()) == sorted(names)


def test_an_interrupt_while_encoding_a_gif_leaves_nothing(tmp_path, monkeypatch):
    from PIL import Image

    def interrupted(image, path, *args, **kwargs):
        open(path, "wb").write(b"GIF89a half")
        raise KeyboardInterrupt

    monkeypatch.setattr(Image.Image, "save", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_video(tmp_path / "clip.gif", _frames(4), 10)
    _only(tmp_path)


def test_an_interrupt_while_finishing_an_mp4_leaves_nothing(tmp_path, monkeypatch):
    wav = _write_wav(tmp_path / "s.wav", np.zeros(RATE))

    def interrupted(cmd, *args, **kwargs):  # the audio mux, the MP4's last step
        open(cmd[-1], "wb").write(b"half an mp4")
        raise KeyboardInterrupt

    monkeypatch.setattr(subprocess, "run", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_video(tmp_path / "talk.mp4", _frames(5), 10, audio=wav)
    _only(tmp_path, "s.wav")


def test_an_interrupt_between_frames_stops_ffmpeg_and_leaves_nothing(tmp_path):
    def frames():
        yield from _frames(3)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_video(tmp_path / "clip.mp4", frames(), 10)
    _only(tmp_path)


# A writer in a real process, interrupted while it is known to be writing: it writes until
# a partial file is on disk, prints that file's name, and then waits on its standard input,
# which the test never writes to. The test then sends the signal. No step depends on how
# fast the machine is: the child waits for the signal, the test waits for the child's line.
_INTERRUPTED_WRITER = """
import os, signal, sys
import numpy as np
from cassi_fit._signals import terminate_as_interrupt
from cassi_fit.video import VideoWriter

signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C's, even if SIGINT was ignored
rng = np.random.default_rng(0)
writer = VideoWriter(sys.argv[1], 25)


def noise():
    return rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)


def writing():
    print(writer.tmp, flush=True)  # the partial file is on disk: the test may signal now
    os.read(0, 1)  # wait for the signal (the test never writes here)
    sys.exit("stdin closed and no signal came")


try:
    with terminate_as_interrupt(), writer:
        if writer.suffix == ".gif":  # Pillow encodes at close(): wait after its first frame
            from PIL import ImageFile

            encode = ImageFile._save

            def encode_then_wait(image, fp, *args, **kwargs):
                encode(image, fp, *args, **kwargs)
                fp.flush()
                ImageFile._save = encode
                writing()

            ImageFile._save = encode_then_wait
            for _ in range(4):
                writer.append(noise())
        else:  # ffmpeg encodes as frames come: feed it until it has written to the file
            while writer.tmp.stat().st_size == 0:
                writer.append(noise())
            writing()
finally:
    if writer._proc is not None:
        print("ffmpeg returncode", writer._proc.returncode, file=sys.stderr)
"""


@pytest.mark.parametrize(
    ("name", "how"),
    [("clip.mp4", "ctrl-c"), ("clip.gif", "ctrl-c"), ("clip.mp4", "sigterm")],
)
def test_an_interrupted_writer_process_leaves_no_partial_file(tmp_path, name, how):
    """Ctrl-C (SIGINT to the process group, ffmpeg included, as a terminal sends it) or
    ``kill`` (SIGTERM to the writer alone, inside ``terminate_as_interrupt``) while a
    partial file is on disk: the process stops, the partial file is removed, and ffmpeg
    is not left running (nor allowed to finish the file it was given)."""
    import os
    import signal
    import sys

    out = tmp_path / "out"
    out.mkdir()
    with open(tmp_path / "stderr.txt", "w+") as err:
        child = subprocess.Popen(
            [sys.executable, "-c", _INTERRUPTED_WRITER, str(out / name)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err, text=True,
            start_new_session=True,  # its own process group: a Ctrl-C reaches it alone
        )  # fmt: skip
        try:
            partial = child.stdout.readline().strip()
            if not partial:  # it ended without reaching its wait
                child.wait()
                err.seek(0)
                pytest.fail(f"the writer ended before writing: {err.read()}")
            # while it waits, the partial file is the folder's only file, and not empty
            assert [p.name for p in out.iterdir()] == [Path(partial).name]
            assert Path(partial).name.startswith(".") and Path(partial).stat().st_size > 0
            if how == "ctrl-c":
                os.killpg(child.pid, signal.SIGINT)
            else:
                child.send_signal(signal.SIGTERM)
            child.communicate()
        finally:
            if child.poll() is None:
                os.killpg(child.pid, signal.SIGKILL)
                child.wait()
        err.seek(0)
        stderr = err.read()
    assert child.returncode != 0 and "KeyboardInterrupt" in stderr, stderr
    _only(out)
    with pytest.raises(ProcessLookupError):  # nothing of the group is left running
        os.killpg(child.pid, 0)
    if how == "sigterm":  # ffmpeg saw no signal: the writer stopped it (killed, not finished)
        assert int(stderr.split("ffmpeg returncode")[1].split()[0]) < 0, stderr


def test_videos_get_the_users_normal_mode(tmp_path):
    import os

    old = os.umask(0o022)
    try:
        wav = _write_wav(tmp_path / "s.wav", np.zeros(RATE))
        for path in (
            write_video(tmp_path / "a.mp4", _frames(3), 10),
            write_video(tmp_path / "b.mp4", _frames(3), 10, audio=wav),
            write_video(tmp_path / "c.gif", _frames(3), 10),
        ):
            assert path.stat().st_mode & 0o777 == 0o644, path
    finally:
        os.umask(old)
