"""Rendering and encoding in step (issue 23, part 3): the two-step frame loop (OpenGL in
this thread, each frame's midsagittal drawing and caption in a helper thread, an option)
gives the same frames, byte for byte, as drawing each frame whole (the default); errors
in the helper reach the caller; the video writer's thread hands ffmpeg every frame."""

import threading
from pathlib import Path

import numpy as np
import pytest

from cassi_fit import recording_video, synth, video
from cassi_fit.animate import animate
from cassi_fit.dataset import Recording
from cassi_fit.initialize import initialize
from cassi_fit.options import VIEWS
from cassi_fit.render import Renderer

pytestmark = pytest.mark.render


@pytest.fixture(scope="module")
def run():
    # the recording tests/test_animate.py animates: the same shapes, compiled once
    anatomy = synth.make_subject("JWT", np.random.default_rng(3))
    track, _ = synth.synth_recording(anatomy, synth.SENTENCE_TASK, seed=3, duration_s=1.0)
    recording = Recording(subject="JWT", task=synth.SENTENCE_TASK, track=track,
                          palate=anatomy.palate, pharynx=anatomy.pharynx, head=anatomy.head,
                          head_is_default=False, audio=None, path=Path("/data/JWT/tp040.txy"))
    state = initialize(recording)
    return recording, state, animate(state, recording)


@pytest.fixture(scope="module")
def renderer(run):
    recording, state, _ = run
    with Renderer(state.model, size=(200, 120), views=VIEWS,
                  traces=recording_video.subject_traces(recording, state.scale)) as r:
        yield r


def test_two_steps_give_the_same_frames_byte_for_byte(run, renderer):
    _, _, animation = run
    options = {"subject": "JWT", "task": "sentence", "markers": True, "progress": False,
               "indices": range(0, animation.n_frames, 9)}
    two = list(recording_video.animation_frames(animation, renderer, helper_thread=True, **options))
    one = list(recording_video.animation_frames(animation, renderer, **options))  # the default
    assert len(two) == len(one) == len(options["indices"]) > video.PIPELINE_DEPTH
    for a, b in zip(two, one, strict=True):
        assert a.dtype == np.uint8 and a.shape == b.shape
        assert a.tobytes() == b.tobytes()
    # the frames differ from each other (the caption's time at least): not one frame
    assert len({f.tobytes() for f in two}) == len(two)


def test_pipelined_frames_are_each_frames_own_bytes(run, renderer):
    """``Renderer.render_frames`` draws frame k + 1 into a second framebuffer before frame
    k is read back: each frame is still ``render``'s own, byte for byte; a loop stopped
    early, or failing on a bad frame, leaves the renderer drawing the right frames."""
    _, _, animation = run
    work = list(recording_video.frame_work(animation, section=True, markers=True,
                                           subject="JWT", task="sentence",
                                           indices=range(0, animation.n_frames, 7)))
    whole = [renderer.render(points, **kwargs) for points, kwargs in work]
    piped = list(renderer.render_frames(iter(work)))
    assert len(piped) == len(whole) >= 4
    assert all(a.tobytes() == b.tobytes() for a, b in zip(piped, whole, strict=True))
    stopped = renderer.render_frames(iter(work))
    next(stopped)
    stopped.close()  # frame 1 drawn, never read
    assert renderer.render(*work[2][:1], **work[2][1]).tobytes() == whole[2].tobytes()
    broken = [*work[:2], (np.zeros((3, 3)), {}), *work[2:]]
    with pytest.raises(Exception, match="vertices"):
        list(renderer.render_frames(iter(broken)))
    assert [f.tobytes() for f in renderer.render_frames(iter(work[3:]))] == [
        f.tobytes() for f in whole[3:]]


def test_an_error_in_the_helper_thread_reaches_the_caller(run, renderer, monkeypatch):
    _, _, animation = run
    calls = []

    def broken(*args, **kwargs):
        calls.append(threading.current_thread().name)
        raise ValueError("the 2D drawing failed")

    monkeypatch.setattr(renderer, "finish_frame", broken)
    with pytest.raises(ValueError, match="the 2D drawing failed"):
        list(recording_video.animation_frames(animation, renderer, progress=False, indices=range(8),
                                    helper_thread=True))
    assert calls and calls[0] != threading.main_thread().name
    assert not [t for t in threading.enumerate() if t.name == "cassi-finish-frames"]


def test_a_consumer_that_stops_early_stops_the_helper(run, renderer):
    _, _, animation = run
    frames = recording_video.animation_frames(animation, renderer, progress=False, helper_thread=True)
    next(frames)
    frames.close()
    assert not [t for t in threading.enumerate() if t.name == "cassi-finish-frames"]


def test_the_writer_thread_hands_ffmpeg_every_frame(tmp_path):
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8) for _ in range(23)]
    path = video.write_video(tmp_path / "v.mp4", iter(frames), 25)
    assert video.count_frames(path) == 23
    assert not [t for t in threading.enumerate() if t.name == "cassi-video-writer"]
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]


def test_worker_processes_draw_the_same_bytes_in_order(run, renderer):
    """Issue 30: frames drawn by two worker processes (each its own OpenGL context, the
    model sent as arrays) come back in order, byte for byte the serial loop's, at the
    60 fps schedule; a worker's error reaches the caller."""
    from cassi_fit.render import FramePool

    recording, state, animation = run
    schedule = recording_video.video_frames(animation, 60)
    assert len(schedule.index) < animation.n_frames  # 60 fps draws fewer frames than lines
    picked = recording_video.VideoFrames(schedule.rate, schedule.index[::5],
                                         schedule.times[::5])
    options = {"subject": "JWT", "task": "sentence", "markers": True, "frames": picked}
    serial = list(recording_video.animation_frames(animation, renderer, progress=False,
                                                   **options))
    setup = {"size": renderer.size, "views": renderer.views,
             "traces": recording_video.subject_traces(recording, state.scale)}
    with FramePool(state.model, jobs=2, **setup) as pool:
        assert pool.threads >= 1
        work = recording_video.frame_work(animation, section=True, **options)
        parallel = list(pool.draw(work))
        assert len(parallel) == len(serial) >= 4
        for a, b in zip(parallel, serial, strict=True):
            assert a.shape == b.shape and a.tobytes() == b.tobytes()
        assert len({f.tobytes() for f in parallel}) == len(parallel)  # not one frame
        with pytest.raises(Exception, match="vertices"):
            list(pool.draw([(np.zeros((3, 3)), {})]))
    # a pool started before the model is known (cassi animate --jobs N), its worker
    # ready: the batches are shared between this process and the worker, in order
    many = recording_video.VideoFrames(schedule.rate, schedule.index, schedule.times)
    options = {**options, "frames": many}
    serial = list(recording_video.animation_frames(animation, renderer, progress=False,
                                                   **options))
    with FramePool(jobs=2) as pool:
        assert pool.views == ()
        pool._starting.join()
        pool._warm[0].result(timeout=120)  # the worker has imported what drawing needs
        pool.set_model(state.model, **setup)
        assert pool.views == tuple(renderer.views)
        drawn = []
        real = pool._pool.submit
        pool._pool.submit = lambda *a: drawn.append(len(a[-1])) or real(*a)
        work = recording_video.frame_work(animation, section=True, **options)
        parallel = list(pool.draw(work))
        assert drawn and sum(drawn) < len(serial)  # some batches the worker's, some here
        assert [a.tobytes() for a in parallel] == [b.tobytes() for b in serial]


def test_the_egl_device_is_chosen_by_cassi_egl_device(monkeypatch):
    """Issue 30: ``CASSI_EGL_DEVICE`` picks the EGL device (a GPU first by default, Mesa's
    software device where there is none); one that does not exist is one line saying
    which devices there are."""
    from cassi_fit.render import _gl

    if _gl.probe_gl_platform("egl") is not None:
        pytest.skip("no EGL here")
    device = _gl.egl_device()
    assert device is not None and device["renderer"]
    assert device["file"] or "pipe" in device["renderer"].lower()  # a GPU, or llvmpipe
    monkeypatch.setenv("CASSI_EGL_DEVICE", "99")
    reason = _gl.probe_gl_platform("egl")
    assert reason is not None and "CASSI_EGL_DEVICE=99: no such EGL device" in reason
    monkeypatch.setenv("CASSI_EGL_DEVICE", "software")
    assert _gl.probe_gl_platform("egl") is None
    assert not _gl.egl_device()["file"]


def test_the_side_view_leaves_out_what_the_head_hides(run, renderer):
    """Palate, pharynx and the mouth's walls, within the head behind the cheeks, are not
    drawn from the side (issue 30 item 4); ``drawn`` counts a grid frame's draw calls and
    triangles, one call per piece whatever its views."""
    hidden = {"palate", "pharynx", "mouth_wall"}
    assert not [p for p in renderer.pieces if p.material in hidden and "side" in p.views]
    assert any(p.material == "palate" and "front" in p.views for p in renderer.pieces)
    calls, triangles = renderer.drawn()
    assert calls == len(renderer.pieces)
    faces = run[1].model.faces
    assert len(faces) < triangles < 4 * len(faces)
