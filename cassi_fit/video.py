"""Frames to video: MP4 (H.264, yuv420p) with the recording's audio aligned, or GIF.

Timing. A recording's data lines are ``PelletTrack.frame_step_s`` apart (XRMB: 6.866 ms,
about 145.6 Hz; EMA: 2 ms at 500 Hz, 5 ms at 200 Hz ...). An animation that shows every
``stride``-th line plays at ``fps = 1 / (stride * step)`` (``Animation.frame_step_s``),
stored exactly as the rational ``1000000 / (step_us * stride)`` (for XRMB, a non-integer
rate). Frame ``k`` of the video shows data line ``first + k * stride``, recording time
``t_0 + k * stride * step``, and it is on screen from video time ``k / fps``.

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
import re
import subprocess
import tempfile
import wave
from collections.abc import Iterable, Iterator, Sequence
from fractions import Fraction
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
from jaxtyping import Float, UInt8

from ._io import atomic_output_path, atomic_write, commit_output, register_input, remove_quietly
from .errors import CassiError, DataFormatError

if TYPE_CHECKING:
    from .animate import Animation
    from .labels import Labels
    from .render import Renderer

VIDEO_SUFFIXES = (".mp4", ".gif")
TRAIL_S = 0.1
"""Seconds of pellet trail behind each pellet in the midsagittal view (at least 2 of the
animation's frames back)."""


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


def trail_frames(animation: Animation) -> int:
    """How many frames back the midsagittal view's pellet trail reaches: ``TRAIL_S`` of
    the recording, at least 2 frames."""
    return max(2, round(TRAIL_S / animation.frame_step_s))


def _ffmpeg() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


# --------------------------------------------------------------------------- audio


def check_wav(path: str | os.PathLike) -> wave._wave_params:
    """The parameters of a readable integer-PCM ``.wav`` with sound in it; registers it as
    an input (no output may replace it). Otherwise one :class:`DataFormatError` naming the
    file: not a WAVE file, empty, float or compressed samples, a rate or channel count of
    0, no samples."""
    params, _ = _read_pcm(path)
    return params


def _read_pcm(path: str | os.PathLike) -> tuple[wave._wave_params, bytes]:
    """(parameters, sample bytes) of a PCM ``.wav``, checked as :func:`check_wav` says."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(path, None, "sound file not found (or not a regular file)")
    try:
        with wave.open(str(path), "rb") as src:
            params = src.getparams()
            data = src.readframes(params.nframes)
    except (wave.Error, EOFError, OSError) as exc:
        reason = str(exc) or "empty or truncated header"
        if "unknown format: 3" in reason:
            reason = "float samples; only integer PCM is read"
        raise DataFormatError(path, None, f"not a readable PCM .wav file ({reason})") from None
    register_input(path)
    if params.framerate <= 0 or params.nchannels <= 0 or params.sampwidth not in (1, 2, 3, 4):
        raise DataFormatError(
            path, None, f"bad .wav header: rate {params.framerate} Hz, "
            f"{params.nchannels} channels, {params.sampwidth}-byte samples",
        )  # fmt: skip
    if len(data) < params.sampwidth * params.nchannels:
        raise DataFormatError(path, None, "the .wav file holds no sound samples")
    return params, data


def slice_wav(
    source: str | os.PathLike, destination: str | os.PathLike, start_s: float, duration_s: float
) -> Path:
    """Write the samples of ``source`` in ``[start_s, start_s + duration_s)`` to ``destination``.

    Times in seconds on the recording's clock (sample 0 = time 0). Where the interval
    reaches outside the sound it is filled with silence, so the result is always exactly
    ``round(duration_s * rate)`` samples long and sample 0 of the result is recording time
    ``start_s`` (to within half a sample). Any PCM sample width and channel count.
    ``destination`` is written atomically.
    """
    params, data = _read_pcm(source)
    frame_bytes = params.sampwidth * params.nchannels
    n_have = len(data) // frame_bytes
    first = int(round(start_s * params.framerate))
    count = max(int(round(duration_s * params.framerate)), 1)
    silence = b"\x80" if params.sampwidth == 1 else b"\x00"  # 8-bit PCM is unsigned
    out = bytearray(silence * (count * frame_bytes))
    lo, hi = max(first, 0), min(first + count, n_have)
    if hi > lo:
        at = (lo - first) * frame_bytes
        out[at : at + (hi - lo) * frame_bytes] = data[lo * frame_bytes : hi * frame_bytes]

    def write(fh: IO[bytes]) -> None:
        with wave.open(fh, "wb") as dst:
            dst.setnchannels(params.nchannels)
            dst.setsampwidth(params.sampwidth)
            dst.setframerate(params.framerate)
            dst.writeframes(bytes(out))

    return atomic_write(destination, write, overwrite=True, binary=True, data_file=True)


# --------------------------------------------------------------------------- writers


class VideoWriter:
    """Stream RGB frames into an MP4 or GIF; use as a context manager.

    ``path``: ``.mp4`` or ``.gif``. ``fps``: frames per second (a ``Fraction`` keeps the
    XRMB rate exact; see :func:`frame_rate`). ``audio``: optional ``.wav`` (MP4 only)
    whose recording time ``audio_start`` seconds is put at video time 0; it is checked
    (:func:`check_wav`) before anything is written. Frames are ``uint8 (H, W, 3)``, all
    the same size. Nothing appears at ``path`` until the writer closes without error;
    on any error or interrupt (``KeyboardInterrupt`` included) the hidden temporary file
    is removed.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        fps: Fraction | float,
        *,
        audio: str | os.PathLike | None = None,
        audio_start: float = 0.0,
        overwrite: bool = False,
    ):
        self.path = Path(path)
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
        else:
            try:
                self._proc.stdin.write(frame.tobytes())
            except BrokenPipeError:
                raise VideoError(f"{self.path}: ffmpeg stopped: {self._stderr()}") from None
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
        self._proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=self._errfile)

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


# --------------------------------------------------------------------------- animations


def frame_caption(subject: str, task: str, time_s: float, line: int, status: str = "ok",
                  label: str = "") -> str:
    """The caption of one frame: subject, task, recording time, (1-based) data line, the
    frame's status unless "ok", and the current phone/word ``label`` (quoted) if any."""
    text = f"{subject} {task}   t = {time_s:7.3f} s   line {line + 1}"
    if status != "ok":
        text = f"{text}   [{status}]"
    return f'{text}   "{label}"' if label else text


def animation_frames(
    animation: Animation,
    renderer: Renderer,
    *,
    subject: str = "",
    task: str = "",
    markers: bool = False,
    progress: bool = True,
    indices: Iterable[int] | None = None,
    labels: Labels | None = None,
) -> Iterator[UInt8[np.ndarray, "h w 3"]]:
    """Render the frames ``indices`` (default all) of an ``animate.Animation`` with
    ``renderer`` (a ``render.Renderer``); yields ``uint8 (H, W, 3)`` images. ``markers``:
    draw the measured pellets and the model's pellet sites (never-tracked pellets left
    out); ``labels`` (``labels.Labels``): the label at each frame's time is captioned.
    A renderer with the ``midsagittal`` view gets, whatever ``markers`` says, the
    measured pellets with a trail of their last ``TRAIL_S`` seconds and the time.
    The progress bar goes to stderr."""
    import sys

    from tqdm import tqdm

    from .mistracks import mistrack_labels
    from .status import Status

    vertices = np.asarray(animation.vertices)
    measured = np.asarray(animation.pellets_measured)
    model_sites = np.asarray(animation.pellets_model)
    shown = np.isfinite(measured).all(axis=(0, 2))
    section = "midsagittal" in getattr(renderer, "views", ())
    trail = trail_frames(animation) if section else 0
    current = (labels.at(np.asarray(animation.times, np.float64)) if labels is not None
               else np.full(animation.n_frames, "", dtype=str))
    indices = range(animation.n_frames) if indices is None else indices
    reasons = getattr(animation, "mistrack_reasons", None)  # the detector's, per pellet
    for k in tqdm(
        indices, desc="rendering", unit="frame", file=sys.stderr, disable=not progress, leave=False
    ):
        kwargs = {}
        if section:
            kwargs["trails"] = {"measured": measured[max(k - trail, 0) : k + 1, shown]}
            kwargs["time"] = float(animation.times[k])
        if markers:
            kwargs["markers"] = {
                "measured": _in_3d(measured[k][shown]),
                "model": _in_3d(model_sites[k][shown]),
            }
        status = Status(int(animation.frame_status[k])).label
        if reasons is not None and reasons[k].any():  # which pellet, and why
            status = f"{status} {mistrack_labels(reasons[k])}"
        caption = frame_caption(
            subject, task, float(animation.times[k]), int(animation.frame_index[k]), status,
            str(current[k]),
        )
        yield renderer.render(vertices[k], caption=caption, **kwargs)


def subject_traces(recording: Any, scale: float) -> dict[str, Float[np.ndarray, "n 2"] | None]:
    """The midsagittal view's traces of a ``dataset.Recording``: its subject's palate
    (PAL.DAT) and pharyngeal wall (PHA.DAT) in the model frame, i.e. the pellet frame's
    mm times ``scale`` (``SubjectState.scale``); None where the file is absent."""
    out = {}
    for name in ("palate", "pharynx"):
        points = getattr(recording, name, None)
        out[name] = None if points is None else np.asarray(points, np.float64) * float(scale)
    return out


def _in_3d(points_2d: np.ndarray) -> np.ndarray:
    """Pellet (x, y) in the midsagittal plane as model points (x, y, 0)."""
    return np.concatenate([points_2d, np.zeros((len(points_2d), 1))], axis=1)


def write_animation(
    path: str | os.PathLike,
    animation: Animation,
    renderer: Renderer,
    *,
    subject: str = "",
    task: str = "",
    audio: str | os.PathLike | None = None,
    markers: bool = False,
    progress: bool = True,
    overwrite: bool = False,
    labels: Labels | None = None,
) -> Path:
    """Render ``animation`` to an MP4/GIF at the recording's pace
    (``frame_rate(animation.frame_step_s)``);
    an MP4 carries ``audio`` (a ``.wav`` on the recording's clock) aligned so that the
    first frame sounds at its own recording time; ``labels`` (``labels.Labels``, e.g.
    ``labels.labels_for(pellet_path)``) put the current phone/word in each caption.
    Returns the path written."""
    fps = frame_rate(animation.frame_step_s)
    start = float(animation.times[0])
    frames = animation_frames(
        animation, renderer, subject=subject, task=task, markers=markers, progress=progress,
        labels=labels,
    )
    return write_video(path, frames, fps, audio=audio, audio_start=start, overwrite=overwrite)


# ------------------------------------------------------------- a recording's video
def write_recording_video(
    path: str | os.PathLike,
    run: Any,
    *,
    renderer: Renderer | None = None,
    size: tuple[int, int] = (640, 480),
    views: Sequence[str] | None = None,
    markers: bool = False,
    audio: bool = True,
    labels: Labels | bool | None = True,
    accept_mismatch: bool = False,
    progress: bool = True,
    overwrite: bool = False,
) -> Path:
    """The video of a ``pipeline.RecordingRun``: the one place that sets up the renderer
    for a recording (the model, its ``views`` (default all of ``options.VIEWS``, in a
    grid) at ``size``, the subject's palate and pharynx traces in the midsagittal view)
    and writes :func:`write_animation`, with the recording's sound in an MP4 when
    ``audio`` and a ``.wav`` is there (a GIF has none; the sound is checked against the
    recording's length first, ``sound.check_sound``), the current label in the captions
    (``labels``: True for the labels beside the recording, ``labels.labels_for``, checked
    against its length; a ``Labels``; or None/False for none). ``accept_mismatch``: keep
    sound or labels whose length does not fit the recording (with a warning) instead of
    the error. ``renderer``: reuse an open ``render.Renderer`` of the same model (its
    traces are replaced). Returns the path written."""
    from .options import VIEWS
    from .render import Renderer
    from .sound import check_sound, recording_seconds

    recording, state = run.recording, run.state
    length_s = recording_seconds(recording.track.times)
    if labels is True:
        from .labels import labels_for

        labels = labels_for(recording.path, recording_s=length_s,
                            accept_mismatch=accept_mismatch) if recording.path else None
    labels = labels or None
    sound = recording.audio if audio and Path(path).suffix.lower() == ".mp4" else None
    if sound is not None:
        check_sound(sound, length_s, accept_mismatch=accept_mismatch)
    traces = subject_traces(recording, state.scale)
    own = renderer is None
    if own:
        views = tuple(views or VIEWS)
        renderer = Renderer(state.model, size=tuple(size), views=views, grid=len(views) > 1,
                            traces=traces)
    else:
        renderer.set_traces(traces)
    try:
        return write_animation(path, run.animation, renderer, subject=recording.subject,
                               task=recording.task, audio=sound, markers=markers,
                               progress=progress, overwrite=overwrite, labels=labels)
    finally:
        if own:
            renderer.close()


def video_output_path(out_dir: str | os.PathLike, item: Any, suffix: str = ".mp4") -> Path:
    """``out_dir/SUBJECT/TASK.mp4`` (or the given suffix) of a ``corpus.CorpusItem``."""
    return Path(out_dir) / item.subject / f"{item.task}{suffix}"


def animate_task(item: Any, out_dir: str, *, spec: Any, suffix: str = ".mp4",
                 size: tuple[int, int] = (640, 480), views: Sequence[str] | None = None,
                 audio: bool = True, markers: bool = False, labels: bool = True,
                 overwrite: bool = False) -> Any:
    """``cassi animate DATASET``'s task: run one recording (``pipeline.run_recording``
    with the ``run_spec.RunSpec`` ``spec`` and the worker's model) and write
    ``out_dir/SUBJECT/TASK.mp4`` (or ``.gif``) by :func:`write_recording_video`, the
    current label (``labels.labels_for``) in each frame's caption. Row: frames, stride,
    the video, the label file, the tongue's volume range."""
    from .corpus import TaskResult, load_item, worker_model
    from .labels import labels_for
    from .pipeline import run_recording
    from .sound import recording_seconds
    from .tongue import tongue_volumes

    run = run_recording(load_item(item, quiet=True), spec, model=worker_model())
    found = labels_for(run.recording.path, recording_s=recording_seconds(
        run.recording.track.times)) if labels else None
    path = write_recording_video(video_output_path(out_dir, item, suffix), run, size=size,
                                 views=views, markers=markers, audio=audio, labels=found,
                                 progress=False, overwrite=overwrite)
    volume = tongue_volumes(run.state.model, run.animation.vertices)
    row = {"frames": int(run.animation.n_frames), "stride": int(run.animation.stride),
           "video": str(Path(path).relative_to(Path(out_dir))),
           "label_file": found.path.name if found is not None and found.path else "",
           "tongue_volume_min_ml": round(float(volume.min()), 3),
           "tongue_volume_max_ml": round(float(volume.max()), 3)}
    return TaskResult(row, (str(path),))


def animate_corpus(dataset: Any, out_dir: str | os.PathLike, *, spec: Any = None,
                   subjects: Iterable[str] | None = None, tasks: Iterable[str] | None = None,
                   video_options: dict[str, Any] | None = None,
                   run_options: dict[str, Any] | None = None, **changes: Any) -> tuple:
    """``cassi animate DATASET --out DIR``: :func:`animate_task` on every recording (the
    run ``spec``, a ``run_spec.RunSpec`` or a preset's name, with ``changes``;
    ``video_options``: ``suffix``, ``size``, ``views``, ``audio``, ``markers``, ``labels``),
    then ``DIR/animate_corpus.csv`` (and ``.parquet``): one row per recording, failed ones
    with their error. ``run_options`` go to ``corpus.run_corpus``. Returns ``(run, the
    table files written)``."""
    from .corpus import (
        dataset_items,
        refuse_existing,
        replaces,
        require_items,
        run_corpus,
        write_table,
    )
    from .run_spec import run_spec

    spec = run_spec(spec, **changes)
    run_options = dict(run_options or {})
    table = Path(out_dir) / "animate_corpus.csv"
    refuse_existing([table], run_options)
    run_options.setdefault("desc", "animate")
    options = {**(video_options or {}), "spec": spec}
    items = require_items(dataset_items(dataset, subjects=subjects, tasks=tasks), dataset,
                          subjects, tasks)
    run = run_corpus(animate_task, items, out_dir, options=options, **run_options)
    return run, write_table(run.rows(), table, overwrite=replaces(run_options))
