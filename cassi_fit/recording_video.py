"""A recording's video: an ``animate.Animation``'s frames drawn by a ``render.Renderer``
(captions with the time, data line, status, mistrack reasons and current label; the
midsagittal view's pellet trails), encoded by :mod:`cassi_fit.video` at the recording's
pace with its sound; :func:`write_recording_video`, the one place that sets up the renderer
for a ``pipeline.RecordingRun``; and ``cassi animate DATASET``'s corpus task."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from jaxtyping import Float, Integer, UInt8

from .errors import CassiError
from .options import DEFAULT_FPS as DEFAULT_FPS  # "native": one frame per data line
from .video import PIPELINE_DEPTH, _drain, _put, frame_rate, write_video

if TYPE_CHECKING:
    from .animate import Animation
    from .labels import Labels
    from .render import Renderer


TRAIL_S = 0.1
"""Seconds of pellet trail behind each pellet in the midsagittal view (at least 2 of the
animation's frames back)."""


def trail_frames(animation: Animation) -> int:
    """How many frames back the midsagittal view's pellet trail reaches: ``TRAIL_S`` of
    the recording, at least 2 frames."""
    return max(2, round(TRAIL_S / animation.frame_step_s))


class VideoFrames(NamedTuple):
    """Which animation frame each video frame draws: ``rate`` frames per second (exact),
    ``index (n,)`` the animation frame (a strided data line) of each video frame and
    ``times (n,)`` each video frame's recording time in seconds (its caption's time, its
    label's, the sound's at that frame)."""

    rate: Fraction
    index: Integer[np.ndarray, " n"]
    times: Float[np.ndarray, " n"]


def parse_fps(value: object) -> Fraction | None:
    """``--fps``: a positive number of frames per second (``"59.94"``, ``"30000/1001"``),
    or ``"native"``/None (one frame per data line); a ``CassiError`` otherwise."""
    if value is None or (isinstance(value, str) and value.strip().lower() == "native"):
        return None
    try:
        rate = Fraction(str(value).strip()).limit_denominator(10**6)
    except (ValueError, ZeroDivisionError):
        raise CassiError(f"--fps must be a number of frames per second or 'native', "
                         f"got {value!r}") from None
    if not 0 < rate <= 1000:
        raise CassiError(f"--fps {value}: must be above 0 and at most 1000")
    return rate


def video_frames(animation: Animation, fps: object = DEFAULT_FPS) -> VideoFrames:
    """The video's frames (:class:`VideoFrames`) at ``fps`` (see :func:`parse_fps`).

    ``"native"``/None: one video frame per animation frame at the rate of its nominal step
    (``frame_rate(animation.frame_step_s)``), as before. A number: video frame ``j`` is
    recording time ``t_0 + j / rate`` (``t_0`` the first animation frame's time) and draws
    the animation frame nearest in time (the earlier on a tie), found from the frames'
    own times, so irregular or dropped articulograph samples keep the picture on the
    sound's clock. ``rate`` is ``fps``, or the animation's own rate where that is lower
    (never more frames than data lines: ``--stride 10`` at 60 fps stays at the strided
    rate). Nothing is interpolated: a video frame shows the geometry, status and mistrack
    reasons of its data line, exactly as the native video shows that line. The video
    lasts from ``t_0`` to the end of the last animation frame (its time plus one step),
    rounded to whole frames; an MP4's sound is cut to the same length."""
    times = np.asarray(animation.times, np.float64)
    m = len(times)
    native = frame_rate(animation.frame_step_s)
    rate = parse_fps(fps)
    if rate is None:
        return VideoFrames(native, np.arange(m), times)
    if m > 1 and not np.all(np.diff(times) > 0):
        raise CassiError("the animation's frame times do not increase: cannot place them "
                         "on the video's clock")
    rate = min(rate, native)
    span = times[-1] - times[0] + animation.frame_step_s
    n = max(int(round(span * rate)), 1)
    at = times[0] + np.arange(n) / float(rate)
    if m == 1:
        return VideoFrames(rate, np.zeros(n, np.int64), at)
    after = np.clip(np.searchsorted(times, at), 1, m - 1)
    before = after - 1
    index = np.where(np.abs(times[after] - at) < np.abs(at - times[before]), after, before)
    return VideoFrames(rate, index.astype(np.int64), at)


def frame_caption(subject: str, task: str, time_s: float, line: int, status: str = "ok",
                  label: str = "") -> str:
    """The caption of one frame: subject, task, recording time, (1-based) data line, the
    frame's status unless "ok", and the current phone/word ``label`` (quoted) if any."""
    text = f"{subject} {task}   t = {time_s:7.3f} s   line {line + 1}"
    if status != "ok":
        text = f"{text}   [{status}]"
    return f'{text}   "{label}"' if label else text


def frame_work(
    animation: Animation,
    *,
    section: bool,
    subject: str = "",
    task: str = "",
    markers: bool = False,
    frames: VideoFrames | None = None,
    indices: Iterable[int] | None = None,
    labels: Labels | None = None,
    panels: Sequence[Any] | None = None,
) -> Iterator[tuple[np.ndarray, dict[str, Any]]]:
    """``(vertices (V, 3), Renderer.render keywords)`` of each video frame, in order: the
    video frames ``frames`` (:func:`video_frames`), or the animation frames ``indices``
    each at its own time (default: every animation frame, the native video). What
    :func:`animation_frames` draws, and what drawing workers are sent
    (``render.draw_in_workers``); see :func:`animation_frames` for the keywords.
    ``panels``: the tract view's panel of every animation frame
    (``acoustics.tract_panels``), handed to the renderer as ``tract``."""
    from .mistracks import mistrack_labels
    from .status import Status

    if frames is None:  # the animation frames themselves (the rate is not needed here)
        chosen = np.arange(animation.n_frames) if indices is None else np.fromiter(
            indices, np.int64)
        frames = VideoFrames(Fraction(0), chosen, np.asarray(animation.times, np.float64)[chosen])
    vertices = np.asarray(animation.vertices)
    measured = np.asarray(animation.pellets_measured)
    model_sites = np.asarray(animation.pellets_model)
    shown = np.isfinite(measured).all(axis=(0, 2))
    trail = trail_frames(animation) if section else 0
    current = (labels.at(frames.times) if labels is not None
               else np.full(len(frames.index), "", dtype=str))
    reasons = getattr(animation, "mistrack_reasons", None)  # the detector's, per pellet
    for j, k in enumerate(frames.index.tolist()):
        kwargs: dict[str, Any] = {}
        time_s = float(frames.times[j])
        if section:
            kwargs["trails"] = {"measured": measured[max(k - trail, 0) : k + 1, shown]}
            kwargs["time"] = time_s
        if markers:
            kwargs["markers"] = {
                "measured": _in_3d(measured[k][shown]),
                "model": _in_3d(model_sites[k][shown]),
            }
        status = Status(int(animation.frame_status[k])).label
        if reasons is not None and reasons[k].any():  # which pellet, and why
            status = f"{status} {mistrack_labels(reasons[k])}"
        if panels is not None:
            kwargs["tract"] = panels[k]
        kwargs["caption"] = frame_caption(
            subject, task, time_s, int(animation.frame_index[k]), status, str(current[j]),
        )
        yield vertices[k], kwargs


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
    helper_thread: bool = False,
    frames: VideoFrames | None = None,
    panels: Sequence[Any] | None = None,
) -> Iterator[UInt8[np.ndarray, "h w 3"]]:
    """Render the video frames ``frames`` (:func:`video_frames`; default: the animation
    frames ``indices``, each at its own time, default all) of an ``animate.Animation``
    with ``renderer`` (a ``render.Renderer``); yields ``uint8 (H, W, 3)`` images.
    ``markers``: draw the measured pellets and the model's pellet sites (never-tracked
    pellets left out); ``labels`` (``labels.Labels``): the label at each frame's time is
    captioned. A renderer with the ``midsagittal`` view gets, whatever ``markers`` says,
    the measured pellets with a trail of their last ``TRAIL_S`` seconds and the time.
    One step (the default) is ``renderer.render_frames``: frame k + 1's OpenGL views
    are drawn before frame k is read back and finished, so that llvmpipe's raster
    threads draw while this thread works. ``helper_thread``: draw each frame's OpenGL
    views in this thread and its 2D part (midsagittal view, caption) in a helper thread
    while the next frame's views are drawn (the same bytes); it pays only where a core
    is free: on 2 cores OpenGL's own threads and ffmpeg keep both busy and the helper
    thread was slower in ``benchmarks/bench_animation.py``.
    The progress bar goes to stderr."""
    import sys

    from tqdm import tqdm

    work = frame_work(animation, section="midsagittal" in getattr(renderer, "views", ()),
                      subject=subject, task=task, markers=markers, frames=frames,
                      indices=indices, labels=labels, panels=panels)
    if frames is not None:
        total = len(frames.index)
    else:
        total = animation.n_frames if indices is None else (
            len(indices) if hasattr(indices, "__len__") else None)
    work = tqdm(work, desc="rendering", unit="frame", file=sys.stderr, total=total,
                disable=not progress, leave=False)
    if not (helper_thread and hasattr(renderer, "render_gl")):  # one step
        if hasattr(renderer, "render_frames"):  # pipelined: the same bytes
            yield from renderer.render_frames(work)
            return
        for points, kwargs in work:
            yield renderer.render(points, **kwargs)
        return
    yield from _two_step(renderer, iter(work))


def _two_step(renderer: Any, frames: Iterator[tuple]) -> Iterator[np.ndarray]:
    """Each frame's OpenGL views in this thread (the context's), its 2D drawing
    (midsagittal view, caption: ``renderer.finish_frame``) in a helper thread while the
    next frame's OpenGL views are drawn; the finished frames in order. Any error or
    interrupt stops the helper before it passes on."""
    import queue
    import threading

    todo: queue.Queue = queue.Queue(maxsize=PIPELINE_DEPTH)
    done: queue.Queue = queue.Queue(maxsize=PIPELINE_DEPTH)
    stop = threading.Event()

    def finish() -> None:
        while not stop.is_set():
            job = todo.get()
            if job is None:
                return
            image, points, kwargs = job
            try:
                result = (renderer.finish_frame(image, points, **kwargs), None)
            except BaseException as exc:  # noqa: BLE001 -- passed to the main thread
                result = (None, exc)
            _put(done, result, stop)
            if result[1] is not None:
                return

    def take() -> np.ndarray:
        image, error = done.get()
        if error is not None:
            raise error
        return image

    helper = threading.Thread(target=finish, name="cassi-finish-frames", daemon=True)
    helper.start()
    pending = 0
    try:
        for points, kwargs in frames:
            image, checked = renderer.render_gl(points, markers=kwargs.get("markers"))
            if pending == PIPELINE_DEPTH:  # the helper is that far behind: wait for it
                yield take()
                pending -= 1
            todo.put((image, checked, kwargs))
            pending += 1
        for _ in range(pending):
            yield take()
        pending = 0
    finally:
        stop.set()
        _drain(done)
        _put(todo, None, None)
        helper.join()


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
    renderer: Renderer | None,
    *,
    subject: str = "",
    task: str = "",
    audio: str | os.PathLike | None = None,
    markers: bool = False,
    progress: bool = True,
    overwrite: bool = False,
    labels: Labels | None = None,
    fps: object = DEFAULT_FPS,
    workers: Any = None,
    panels: Sequence[Any] | None = None,
) -> Path:
    """Render ``animation`` to an MP4/GIF at ``fps`` (default :data:`DEFAULT_FPS`;
    ``"native"``: one frame per animation frame, ``frame_rate(animation.frame_step_s)``;
    :func:`video_frames`); an MP4 carries ``audio`` (a ``.wav`` on the recording's clock)
    aligned so that the first frame sounds at its own recording time; ``labels``
    (``labels.Labels``, e.g. ``labels.labels_for(pellet_path)``) put the current
    phone/word in each caption. ``workers``: a ``render.FramePool`` drawing the frames in
    worker processes instead of ``renderer`` (the same bytes). ``panels``: the tract
    view's panel of every animation frame (``acoustics.tract_panels``). Returns the path
    written."""
    schedule = video_frames(animation, fps)
    start = float(schedule.times[0])
    if workers is None:
        frames = animation_frames(
            animation, renderer, subject=subject, task=task, markers=markers,
            progress=progress, labels=labels, frames=schedule, panels=panels,
        )
    else:
        import sys

        from tqdm import tqdm

        work = frame_work(animation, section="midsagittal" in workers.views, subject=subject,
                          task=task, markers=markers, frames=schedule, labels=labels,
                          panels=panels)
        frames = tqdm(workers.draw(work), desc="rendering", unit="frame", file=sys.stderr,
                      total=len(schedule.index), disable=not progress, leave=False)
    return write_video(path, frames, schedule.rate, audio=audio, audio_start=start,
                       overwrite=overwrite)


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
    fps: object = DEFAULT_FPS,
    jobs: int = 1,
    panels: Sequence[Any] | None = None,
    pool: Any = None,
) -> Path:
    """The video of a ``pipeline.RecordingRun``: the one place that sets up the renderer
    for a recording (the model, its ``views`` (default all of ``options.VIEWS``, in a
    grid) at ``size``, the subject's palate and pharynx traces in the midsagittal view)
    and writes :func:`write_animation` at ``fps`` (:func:`video_frames`), with the recording's sound in an MP4 when
    ``audio`` and it has one (``Recording.sound``: a ``.wav`` beside its file or the sound
    inside it; a GIF has none; checked against the recording's length first,
    ``sound.check_sound``), the current label in the captions (``labels``: True for the
    recording's labels, beside its file or inside it, ``labels.recording_labels``,
    checked against its length; a ``Labels``; or None/False for none). ``accept_mismatch``: keep
    sound or labels whose length does not fit the recording (with a warning) instead of
    the error. ``renderer``: reuse an open ``render.Renderer`` of the same model (its
    traces are replaced). ``jobs``: frames drawn by that many processes, this one and
    ``jobs - 1`` workers (``render.FramePool``, each its own OpenGL context; the same
    bytes); ``pool``: such a pool started already (its workers' start-up done while the
    recording was fitted), given this model and drawing the frames. ``panels``: with
    the ``tract`` view among ``views``, the panel of every animation frame (``acoustics.tract_panels(run)``; without them its cell says there is
    no tract). Returns the path written."""
    from .options import VIEWS
    from .render import FramePool
    from .sound import Sound, check_sound

    recording, state = run.recording, run.state
    length_s = recording.track.length_s
    if labels is True:  # beside the file or inside it (labels.recording_labels)
        from .labels import recording_labels

        labels = recording_labels(recording, recording_s=length_s,
                                  accept_mismatch=accept_mismatch)
    labels = labels or None
    # the sound beside the file or inside it (mview AUDIO, EMU media): dataset.Recording.sound
    sound = getattr(recording, "sound", None) or (
        None if getattr(recording, "audio", None) is None else Sound.from_file(recording.audio))
    sound = sound if audio and Path(path).suffix.lower() == ".mp4" else None
    if sound is not None:
        check_sound(sound, length_s, accept_mismatch=accept_mismatch)
    traces = subject_traces(recording, state.scale)
    options = {"subject": recording.subject, "task": recording.task,
               "markers": markers, "progress": progress, "overwrite": overwrite,
               "labels": labels, "fps": fps, "panels": panels}
    views = tuple(views or VIEWS)
    setup = {"size": tuple(size), "views": views, "grid": len(views) > 1, "traces": traces}
    # the sound as a .wav for the encoder (a temporary one for a sound held in memory)
    with sound.wav_file() if sound is not None else contextlib.nullcontext() as wav:
        options["audio"] = wav
        if renderer is None and pool is not None:
            pool.set_model(state.model, **setup)
            return write_animation(path, run.animation, None, workers=pool, **options)
        if renderer is None and int(jobs) > 1:
            with FramePool(state.model, jobs=int(jobs), **setup) as pool:
                return write_animation(path, run.animation, None, workers=pool, **options)
        return _draw_with(renderer, state, setup, traces, path, run.animation, options)


def _draw_with(renderer, state, setup, traces, path, animation, options) -> Path:
    """:func:`write_animation` with ``renderer`` (its traces replaced), or with one opened
    here for ``state.model`` as ``setup`` says and closed after."""
    from .render import Renderer

    own = renderer is None
    if own:
        renderer = Renderer(state.model, **setup)
    else:
        renderer.set_traces(traces)
    try:
        return write_animation(path, animation, renderer, **options)
    finally:
        if own:
            renderer.close()


def video_output_path(out_dir: str | os.PathLike, item: Any, suffix: str = ".mp4") -> Path:
    """``out_dir/SUBJECT/TASK.mp4`` (or the given suffix) of a ``corpus.CorpusItem``."""
    return Path(out_dir) / item.subject / f"{item.task}{suffix}"


def animate_task(item: Any, out_dir: str, *, spec: Any, suffix: str = ".mp4",
                 size: tuple[int, int] = (640, 480), views: Sequence[str] | None = None,
                 audio: bool = True, markers: bool = False, labels: bool = True,
                 overwrite: bool = False, fps: object = DEFAULT_FPS,
                 tract_panels: Callable[[Any], Sequence[Any]] | None = None) -> Any:
    """``cassi animate DATASET``'s task: run one recording (``pipeline.run_recording``
    with the ``run_spec.RunSpec`` ``spec`` and the worker's model) and write
    ``out_dir/SUBJECT/TASK.mp4`` (or ``.gif``) by :func:`write_recording_video`, the
    current label (``labels.labels_for``) in each frame's caption, at ``fps``
    (:func:`video_frames`); ``tract_panels`` (``acoustics.tract_panels``, a module-level
    function a worker can be sent) makes the tract view's panels of the run. Row: frames
    (the animation's: every strided data line),
    stride, the video, the label file, the tongue's volume range."""
    from .corpus import TaskResult, load_item, worker_model
    from .labels import recording_labels
    from .pipeline import run_recording
    from .tongue import tongue_volumes

    run = run_recording(load_item(item, quiet=True), spec, model=worker_model())
    found = recording_labels(run.recording) if labels else None
    path = write_recording_video(video_output_path(out_dir, item, suffix), run, size=size,
                                 views=views, markers=markers, audio=audio, labels=found,
                                 progress=False, overwrite=overwrite, fps=fps,
                                 panels=None if tract_panels is None else tract_panels(run))
    volume = tongue_volumes(run.state.model, run.animation.vertices)
    row = {"frames": int(run.animation.n_frames), "stride": int(run.animation.stride),
           "video": str(Path(path).relative_to(Path(out_dir))),
           "label_file": found.path.name if found is not None and found.path else "",
           "tongue_volume_min_ml": round(float(volume.min()), 3),
           "tongue_volume_max_ml": round(float(volume.max()), 3)}
    return TaskResult(row, (str(path),))


def animate_corpus(dataset: Any, out_dir: str | os.PathLike, *,
                   subjects: Iterable[str] | None = None, tasks: Iterable[str] | None = None,
                   run_options: Mapping[str, Any] | None = None, spec: Any = None,
                   video_options: Mapping[str, Any] | None = None, **changes: Any) -> Any:
    """``cassi animate DATASET --out DIR``: :func:`animate_task` on every recording (the
    run ``spec``, a ``run_spec.RunSpec`` or a preset's name, with ``changes``;
    ``video_options``: ``suffix``, ``size``, ``views``, ``audio``, ``markers``, ``labels``,
    ``fps``),
    then ``DIR/animate_corpus.csv`` (and ``.parquet``): one row per recording, failed ones
    with their error. ``run_options`` go to ``corpus.run_corpus``. Returns ``(run, the
    table files written, None)`` as a ``corpus.CorpusResult``."""
    from .corpus import (
        CorpusResult,
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
    return CorpusResult(run, write_table(run.rows(), table, overwrite=replaces(run_options)))
