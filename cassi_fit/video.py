"""Frames to video: MP4 (H.264, yuv420p) with the recording's audio aligned, or GIF.

Timing. A recording's data lines are ``PelletTrack.frame_step_s`` apart (XRMB: 6.866 ms,
about 145.6 Hz; EMA: 2 ms at 500 Hz, 5 ms at 200 Hz ...). An animation that shows every
``stride``-th line plays at ``fps = 1 / (stride * step)`` (``Animation.frame_step_s``),
stored exactly as the rational ``1000000 / (step_us * stride)`` (for XRMB, a non-integer
rate). Frame ``k`` of the video shows data line ``first + k * stride``, recording time
``t_0 + k * stride * step``, and it is on screen from video time ``k / fps``. That is the
native video (``--fps native``); by default a video has 60 frames a second, frame ``k``
recording time ``t_0 + k / 60`` showing the (strided) line nearest that time
(``recording_video.video_frames``).

Speech synchronization (the report's future work, section 5): the video's time ``tau``
corresponds to the recording's time ``t_0 + tau``, where ``t_0`` is the time of the first
rendered frame. Audio time 0 is taken to be pellet time 0 (the first line of the ``.txy``
file). :func:`slice_wav` cuts the samples ``[t_0, t_0 + m / fps)`` out of the ``.wav``
(padding with silence where the sound does not reach) so the sound stays aligned for any
stride; the cut is then muxed as AAC.

GIF stores frame durations in hundredths of a second, so a GIF's timing is rounded
(and it carries no sound); use MP4 when timing matters.

Every file is written to a temporary name in the destination folder and moved into place
at the end (``cassi_fit._io``); an input file is never replaced.
"""

from __future__ import annotations

import os
import queue
import re
import subprocess
import tempfile
import threading
from collections.abc import Iterable
from fractions import Fraction
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
from jaxtyping import UInt8

from ._io import atomic_output_path, atomic_write, commit_output, register_input, remove_quietly
from .errors import CassiError, DataFormatError
from .sound import WavInfo, read_wav

if TYPE_CHECKING:
    pass

VIDEO_SUFFIXES = (".mp4", ".gif")


class VideoError(CassiError):
    """ffmpeg failed to write or read a video."""


def frame_rate(frame_step_s: float) -> Fraction:
    """Exact frames per second for frames ``frame_step_s`` seconds apart
    (``Animation.frame_step_s``), to the microsecond: ``10^6 / round(step * 10^6)``
    (XRMB every 3rd line: ``10^6 / 20598``)."""
    step_us = round(float(frame_step_s) * 1e6)
    if not step_us >= 1:
        raise CassiError(f"frame step must be at least 1 us, got {frame_step_s!r} s")
    return Fraction(1_000_000, step_us)


def _ffmpeg() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


# --------------------------------------------------------------------------- audio


def check_wav(path: str | os.PathLike) -> WavInfo:
    """What a readable ``.wav`` with sound in it holds (:func:`cassi_fit.sound.read_wav`:
    integer PCM or float, plain or extensible headers); registers it as an input (no output
    may replace it). Otherwise one :class:`DataFormatError` naming the file: not a WAVE
    file, empty, compressed samples, a rate or channel count of 0, no samples."""
    info, _ = _read_sound(path, header_only=True)
    return info


def _read_sound(path: str | os.PathLike, *,
                header_only: bool = False) -> tuple[WavInfo, np.ndarray]:
    """:func:`cassi_fit.sound.read_wav` of a ``.wav`` that holds samples (else one error),
    registered as an input."""
    path = Path(path)
    info, data = read_wav(path, header_only=header_only)
    register_input(path)
    if info.held == 0:
        raise DataFormatError(path, None, "the .wav file holds no sound samples")
    return info, data


def slice_wav(
    source: str | os.PathLike, destination: str | os.PathLike, start_s: float, duration_s: float
) -> Path:
    """Write the samples of ``source`` in ``[start_s, start_s + duration_s)`` to ``destination``.

    Times in seconds on the recording's clock (sample 0 = time 0). Where the interval
    reaches outside the sound it is filled with silence, so the result is always exactly
    ``round(duration_s * rate)`` samples long and sample 0 of the result is recording time
    ``start_s`` (to within half a sample). The samples keep their type (24-bit PCM is
    written as 32-bit) and channels. ``destination`` is written atomically.
    """
    from scipy.io import wavfile

    info, data = _read_sound(source)
    first = int(round(start_s * info.framerate))
    count = max(int(round(duration_s * info.framerate)), 1)
    silence = 128 if data.dtype == np.uint8 else 0  # 8-bit PCM is unsigned
    out = np.full((count, data.shape[1]), silence, data.dtype)
    lo, hi = max(first, 0), min(first + count, info.held)
    if hi > lo:
        out[lo - first : hi - first] = data[lo:hi]

    def write(fh: IO[bytes]) -> None:
        wavfile.write(fh, info.framerate, out)

    return atomic_write(destination, write, overwrite=True, binary=True, data_file=True)


#: Frames in flight at most (each is an image in memory): waiting for the encoder, or drawn
#: ahead of the one being finished (``recording_video``).
PIPELINE_DEPTH = 3


def _put(q, item, stop) -> None:
    """``q.put(item)``, giving up when ``stop`` is set (the reader has left)."""
    import queue

    while stop is None or not stop.is_set():
        try:
            q.put(item, timeout=0.1)
            return
        except queue.Full:
            if stop is None:
                _drain(q)


def _drain(q) -> None:
    import queue

    while True:
        try:
            q.get_nowait()
        except queue.Empty:
            return



# --------------------------------------------------------------------------- writers


class VideoWriter:
    """Stream RGB frames into an MP4 or GIF; use as a context manager.

    ``path``: ``.mp4`` or ``.gif``. ``fps``: frames per second (a ``Fraction`` keeps the
    XRMB rate exact; see :func:`frame_rate`). ``audio``: optional ``.wav`` (MP4 only)
    whose recording time ``audio_start`` seconds is put at video time 0; it is checked
    (:func:`check_wav`) before anything is written. Frames are ``uint8 (H, W, 3)``, all
    the same size. Nothing appears at ``path`` until the writer closes without error;
    on any error or interrupt (``KeyboardInterrupt`` included) the hidden temporary file
    is removed. ``writer_thread`` (MP4): frames go to ffmpeg from a writer thread fed by
    a bounded queue, so the caller draws the next frame while ffmpeg takes this one
    (False: the caller writes and waits, as before issue 23).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        fps: Fraction | float,
        *,
        audio: str | os.PathLike | None = None,
        audio_start: float = 0.0,
        overwrite: bool = False,
        writer_thread: bool = True,
    ):
        self.path = Path(path)
        self.writer_thread = bool(writer_thread)
        self.suffix = self.path.suffix.lower()
        if self.suffix not in VIDEO_SUFFIXES:
            raise CassiError(f"{self.path}: video must be one of {', '.join(VIDEO_SUFFIXES)}")
        if audio is not None and self.suffix != ".mp4":
            raise CassiError(f"{self.path}: audio can only be carried by an .mp4 video")
        self.fps = Fraction(fps).limit_denominator(10**7)
        if self.fps <= 0:
            raise CassiError(f"{self.path}: the frame rate must be positive, got {fps}")
        self.audio = None if audio is None else Path(audio)
        if self.audio is not None:
            check_wav(self.audio)  # before any file is made: a bad .wav leaves nothing
        self.audio_start = float(audio_start)
        self.tmp, self.final = atomic_output_path(self.path, overwrite=overwrite)
        self.count = 0
        self.size: tuple[int, int] | None = None
        self._proc: subprocess.Popen | None = None
        self._errfile: IO[bytes] | None = None
        self._gif: list[np.ndarray] | None = None
        self._frames: queue.Queue = queue.Queue(maxsize=PIPELINE_DEPTH)
        self._pipe: threading.Thread | None = None
        self._pipe_error: BaseException | None = None

    # -- frames
    def append(self, frame: UInt8[np.ndarray, "h w 3"]) -> None:
        """Add one frame; any error discards the temporary file."""
        try:
            self._append(frame)
        except BaseException:
            self._discard()
            raise

    def _append(self, frame) -> None:
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        if frame.ndim != 3 or frame.shape[2] != 3:
            raise CassiError(f"{self.path}: frames must be (H, W, 3) uint8, got {frame.shape}")
        if self.size is None:
            self.size = frame.shape[:2]
            self._open()
        elif frame.shape[:2] != self.size:
            raise CassiError(
                f"{self.path}: frame {self.count} is {frame.shape[:2]}, not {self.size}"
            )
        if self._gif is not None:
            self._gif.append(frame)
        elif self._pipe is None:  # no writer thread: the caller waits for ffmpeg
            try:
                self._proc.stdin.write(frame.tobytes())
            except BrokenPipeError:
                raise VideoError(f"{self.path}: ffmpeg stopped: {self._stderr()}") from None
        else:
            self._check_pipe()
            self._frames.put(frame.tobytes())  # waits while the queue is full
        self.count += 1

    def _open(self) -> None:
        if self.suffix == ".gif":
            self._gif = []
            return
        h, w = self.size
        cmd = [_ffmpeg(), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24"]
        cmd += ["-s", f"{w}x{h}", "-framerate", f"{self.fps.numerator}/{self.fps.denominator}"]
        cmd += ["-i", "pipe:0"]
        # yuv420p needs even sides: pad by one black row/column where needed.
        cmd += ["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-c:v", "libx264", "-pix_fmt", "yuv420p"]
        cmd += ["-preset", "veryfast", "-crf", "20", "-an", "-f", "mp4", str(self.tmp)]
        self._errfile = tempfile.TemporaryFile()
        # its own session: a Ctrl-C at the terminal reaches this process, which then stops
        # ffmpeg itself (_discard), rather than ffmpeg ending the file on its own first
        self._proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=self._errfile,
                                      start_new_session=True)
        if self.writer_thread:
            self._pipe = threading.Thread(target=self._feed, name="cassi-video-writer",
                                          daemon=True)
            self._pipe.start()

    def _feed(self) -> None:
        """The writer thread: frames from the queue into ffmpeg's input, so that the
        caller draws the next frame while ffmpeg takes this one; stops at ``None``. A
        failed write is kept for the caller (:meth:`_check_pipe`) and the rest dropped."""
        while True:
            data = self._frames.get()
            if data is None:
                return
            if self._pipe_error is None:
                try:
                    self._proc.stdin.write(data)
                except (BrokenPipeError, OSError, ValueError) as exc:
                    self._pipe_error = exc

    def _check_pipe(self) -> None:
        if self._pipe_error is not None:
            raise VideoError(f"{self.path}: ffmpeg stopped: {self._stderr()}") from None

    def _stop_pipe(self) -> None:
        """End the writer thread (after the frames queued so far; at once if ffmpeg is
        gone) and wait for it."""
        if self._pipe is None:
            return
        while True:
            try:
                self._frames.put(None, timeout=0.1)
                break
            except queue.Full:
                if self._proc.poll() is not None:  # nobody reads: drop what is queued
                    _drain(self._frames)
        self._pipe.join()
        self._pipe = None

    def _stderr(self) -> str:
        self._errfile.seek(0)
        text = self._errfile.read().decode(errors="replace").strip()
        return text.splitlines()[-1] if text else "unknown error"

    # -- finishing
    def close(self) -> Path:
        """Finish the file, mux the audio, move it into place; returns the final path.

        On any failure or interrupt the temporary file is removed and nothing appears.
        """
        try:
            self._finish()
        except BaseException:
            self._discard()
            raise
        return commit_output(self.tmp, self.final)

    def _finish(self) -> None:
        if self.count == 0:
            raise CassiError(f"{self.path}: no frames to write")
        if self._gif is not None:
            self._write_gif()
            return
        self._stop_pipe()
        self._check_pipe()
        self._proc.stdin.close()
        if self._proc.wait() != 0:
            raise VideoError(f"{self.path}: ffmpeg failed: {self._stderr()}")
        self._errfile.close()
        if self.audio is not None:
            self._mux_audio()

    def _write_gif(self) -> None:
        """Pillow directly (the bytes imageio's plugin would write): imageio re-runs an
        interrupted save in its ``close()``, so a Ctrl-C would first encode the GIF again."""
        from PIL import Image

        # GIF durations are in 1/100 s; Pillow rounds the milliseconds given here.
        duration_ms = float(1000 / self.fps)
        first, *rest = (Image.fromarray(frame) for frame in self._gif)
        options = {"save_all": True, "append_images": rest} if rest else {}
        first.save(self.tmp, format="GIF", duration=duration_ms, loop=0, **options)

    def _mux_audio(self) -> None:
        """Replace the silent temporary MP4 by one with the cut sound as AAC. The muxed
        file is a second hidden temporary next to the output (same file system, so the
        final ``os.replace`` stays atomic), removed if anything fails."""
        duration = self.count / float(self.fps)
        muxed, _ = atomic_output_path(self.final, overwrite=True)
        try:
            with tempfile.TemporaryDirectory() as folder:
                cut = slice_wav(self.audio, Path(folder) / "audio.wav", self.audio_start, duration)
                cmd = [_ffmpeg(), "-y", "-loglevel", "error", "-i", str(self.tmp), "-i", str(cut)]
                cmd += ["-map", "0:v:0", "-map", "1:a:0", "-c:v", "copy", "-c:a", "aac"]
                cmd += ["-b:a", "128k", "-movflags", "+faststart", "-f", "mp4", str(muxed)]
                done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode != 0:
                last = (done.stderr.strip().splitlines() or ["unknown error"])[-1]
                raise VideoError(f"{self.path}: could not add audio {self.audio}: {last}")
            os.replace(muxed, self.tmp)
        except BaseException:
            remove_quietly(muxed)
            raise

    def _discard(self) -> None:
        """Stop ffmpeg (without letting it finish the file) and remove the temporary."""
        try:
            if self._proc is not None and self._proc.poll() is None:
                self._proc.kill()
                self._proc.wait()
            self._stop_pipe()
        finally:
            remove_quietly(self.tmp)
            if self._errfile is not None:
                self._errfile.close()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close()
        else:
            self._discard()
        return False


def write_video(
    path: str | os.PathLike,
    frames: Iterable[UInt8[np.ndarray, "h w 3"]],
    fps: Fraction | float,
    *,
    audio: str | os.PathLike | None = None,
    audio_start: float = 0.0,
    overwrite: bool = False,
) -> Path:
    """Write an iterable of ``uint8 (H, W, 3)`` frames to ``path`` (.mp4 or .gif); see
    :class:`VideoWriter`. Returns the path written."""
    writer = VideoWriter(path, fps, audio=audio, audio_start=audio_start, overwrite=overwrite)
    with writer:
        for frame in frames:
            writer.append(frame)
    return writer.final


# --------------------------------------------------------------------------- reading back

_DURATION = re.compile(r"Duration:\s*(\d+):(\d+):([\d.]+)")
_FRAME_COUNT = re.compile(r"frame=\s*(\d+)")


def media_info(path: str | os.PathLike) -> dict[str, Any]:
    """What ffmpeg says about a media file: ``{"video": bool, "audio": bool, "duration": s,
    "streams": [stream lines]}`` (parsed from ``ffmpeg -i``; no ffprobe needed)."""
    done = subprocess.run(
        [_ffmpeg(), "-hide_banner", "-i", str(path)], capture_output=True, text=True
    )
    streams = [ln.strip() for ln in done.stderr.splitlines() if ln.strip().startswith("Stream #")]
    match = _DURATION.search(done.stderr)
    duration = None
    if match:
        h, m, s = match.groups()
        duration = int(h) * 3600 + int(m) * 60 + float(s)
    return {
        "video": any(": Video:" in s for s in streams),
        "audio": any(": Audio:" in s for s in streams),
        "duration": duration,
        "streams": streams,
    }


def count_frames(path: str | os.PathLike) -> int:
    """Number of video frames in ``path``, by decoding it (ffmpeg to the null muxer)."""
    cmd = [_ffmpeg(), "-hide_banner", "-nostats", "-i", str(path), "-map", "0:v:0"]
    cmd += ["-f", "null", "-progress", "pipe:1", "-"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise VideoError(f"{path}: ffmpeg could not read it")
    counts = _FRAME_COUNT.findall(done.stdout)
    if not counts:
        raise VideoError(f"{path}: no video frames found")
    return int(counts[-1])
