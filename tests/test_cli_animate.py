"""`cassi animate`, `cassi export`, `cassi demo` end to end on a small synthetic corpus:
videos with the right frame count and sound, non-blank views, one-line errors."""

import math

import imageio.v3 as iio
import numpy as np
import pytest

from cassi_fit import cli, synth
from cassi_fit.dataset import Dataset
from cassi_fit.export import read_glb
from cassi_fit.video import count_frames, media_info

SIZE = "160x120"
STRIDE = 12

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    root = tmp_path_factory.mktemp("corpus")
    return synth.generate_corpus(
        root, n_subjects=1, tasks=[synth.JAW_WAGGING_TASK, synth.SENTENCE_TASK], audio=True
    )


@pytest.fixture(scope="module")
def sentence(corpus):
    dataset = Dataset(corpus)
    subject = dataset.subjects()[0]
    return subject, dataset.load(subject, synth.SENTENCE_TASK)


@pytest.fixture(scope="module")
def every_40th(sentence):
    """The sentence at every 40th line, improved mode, in this process: ``RecordingRun``."""
    from cassi_fit.pipeline import run_recording

    return run_recording(sentence[1], stride=40)


def _expected_frames(recording, stride):
    from cassi_fit.pellets import first_valid_line

    first, _ = first_valid_line(recording.track)
    return math.ceil((len(recording.track.times) - first) / stride)


def _run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_animate_dataset_subject_task_to_mp4_with_sound(corpus, sentence, tmp_path, capsys):
    subject, recording = sentence
    assert recording.audio is not None
    out = tmp_path / "talk.mp4"
    code, stdout, _ = _run(
        capsys,
        "animate",
        corpus,
        subject,
        synth.SENTENCE_TASK,
        "--stride",
        STRIDE,
        "--size",
        SIZE,
        "--out",
        out,
        "--markers",
        "--quiet",
    )
    assert code == 0 and str(out) in stdout
    assert count_frames(out) == _expected_frames(recording, STRIDE)
    info = media_info(out)
    assert info["video"] and info["audio"]
    frames = _expected_frames(recording, STRIDE)
    assert info["duration"] == pytest.approx(frames * STRIDE * 0.006866, abs=0.05)
    # no sound when asked, and --force to replace
    code, _, _ = _run(
        capsys,
        "animate",
        recording.path,
        "--stride",
        STRIDE,
        "--size",
        SIZE,
        "--out",
        out,
        "--no-audio",
        "--force",
        "--quiet",
    )
    assert code == 0 and not media_info(out)["audio"]


def test_animate_at_a_display_rate_in_two_drawing_processes(sentence, tmp_path, capsys):
    """Issue 30: ``--fps 10`` over every 11th line (13.2 lines/s): 10 frames a second of
    the lines' span, the sound as long as the picture; ``--jobs 2`` draws them in two
    processes; the report still counts every strided line. (Every 11th line keeps the
    frames in the size bucket of the file's other animations: no compilation of its own.)"""
    _, recording = sentence
    out = tmp_path / "f10.mp4"
    code, stdout, _ = _run(capsys, "animate", recording.path, "--stride", 11, "--fps", 10,
                           "--jobs", 2, "--size", SIZE, "--views", "front,midsagittal",
                           "--out", out, "--quiet")
    lines = _expected_frames(recording, 11)
    assert code == 0 and f"({lines} frames, stride 11" in stdout
    frames = count_frames(out)
    assert lines > frames == round(lines * 11 * 0.006866 * 10)
    info = media_info(out)
    assert info["audio"] and info["duration"] == pytest.approx(frames / 10, abs=0.05)


def test_animate_pellet_file_to_gif_and_png(sentence, tmp_path, capsys):
    _, recording = sentence
    gif = tmp_path / "front.gif"
    code, _, _ = _run(
        capsys,
        "animate",
        recording.path,
        "--views",
        "front,top",
        "--stride",
        40,
        "--size",
        SIZE,
        "--out",
        gif,
        "--quiet",
    )
    assert code == 0
    frames = iio.imread(gif)
    assert frames.shape[0] == _expected_frames(recording, 40)


def test_animate_to_png_draws_the_frame_asked_for(sentence, every_40th, tmp_path, capsys):
    """``--out X.png --frame 2``: the still is animation frame 2, all five views with the
    subject's traces and its caption, as the renderer draws it here (not frame 0)."""
    from cassi_fit.options import VIEWS
    from cassi_fit.recording_video import animation_frames, subject_traces
    from cassi_fit.render import Renderer

    _, recording = sentence
    png = tmp_path / "still.png"
    code, _, err = _run(capsys, "animate", recording.path, "--stride", 40, "--size", SIZE,
                        "--out", png, "--frame", 2)
    assert code == 0, err
    image = iio.imread(png)[..., :3].astype(int)
    state, animation = every_40th.state, every_40th.animation
    with Renderer(state.model, size=(160, 120), views=VIEWS, grid=True,
                  traces=subject_traces(recording, state.scale)) as renderer:
        frame0, frame2 = animation_frames(animation, renderer, subject=recording.subject,
                                          task=recording.task, progress=False, indices=[0, 2])
    assert image.shape == frame2.shape
    assert np.abs(image - frame2).mean() < 0.5  # the same picture
    assert np.abs(image - frame0).mean() > 2 * np.abs(image - frame2).mean() + 0.5


def test_animate_midsagittal_view_alone(sentence, tmp_path, capsys):
    """``--views midsagittal``: the 2D section with the subject's traces, no OpenGL view;
    given as a dataset folder holding this one recording (it stands for the recording)."""
    import shutil

    _, recording = sentence
    folder = shutil.copytree(recording.path.parent.parent, tmp_path / "one")
    for path in (folder / recording.path.parent.name).iterdir():  # the other task's files
        if path.name.lower().startswith(synth.JAW_WAGGING_TASK):
            path.unlink()
    png = tmp_path / "section.png"
    code, _, err = _run(capsys, "animate", folder, "--views", "midsagittal",
                        "--stride", 40, "--size", SIZE, "--out", png, "--frame", 2)
    assert code == 0, err
    assert f"a dataset of one recording: {recording.subject} {recording.task}" in err
    image = iio.imread(png)[:100]  # above the caption
    assert image.shape[1] == 160
    drawn = np.abs(image.astype(int) - image[2, 2]).sum(axis=2) > 60
    assert 0.02 < drawn.mean() < 0.6  # contours on the light cell background
    grey = (np.abs(image.astype(int) - 158).max(axis=2) < 8)  # the palate/pharynx traces
    assert grey.sum() > 20


def _tongue_volumes(stdout):
    """The frames' least and greatest tongue volume (mL) that ``cassi animate`` prints."""
    (line,) = [ln for ln in stdout.splitlines() if ln.startswith("tongue volume, mL:")]
    low, _, high = line.split(":")[1].split()[:3]
    return float(low), float(high)


def test_animate_in_cassi_mode(sentence, tmp_path, capsys):
    """``--mode cassi`` draws CASSI's flat tongue, a sheet of no volume, where the
    improved mode's tongue keeps an adult's volume; the two stills differ in the views."""
    _, recording = sentence
    stills, volumes = {}, {}
    for mode in ("cassi", "improved"):
        png = tmp_path / f"{mode}.png"
        code, text, err = _run(capsys, "animate", recording.path, "--mode", mode, "--stride", 40,
                               "--size", SIZE, "--out", png, "--frame", 2)
        assert code == 0, err
        stills[mode], volumes[mode] = iio.imread(png)[..., :3].astype(int), _tongue_volumes(text)
    assert max(map(abs, volumes["cassi"])) < 0.01, volumes
    assert 50.0 < volumes["improved"][0] <= volumes["improved"][1] < 120.0, volumes
    changed = np.abs(stills["cassi"] - stills["improved"]).sum(axis=2) > 30
    assert changed.mean() > 0.005


def test_every_view_is_non_blank(sentence, every_40th):
    from cassi_fit.options import VIEWS
    from cassi_fit.recording_video import subject_traces
    from cassi_fit.render import Renderer

    _, recording = sentence
    state, animation = every_40th.state, every_40th.animation
    renderer = Renderer(state.model, size=(160, 120), views=VIEWS,
                        traces=subject_traces(recording, state.scale))  # fmt: skip
    views = renderer.render_views(animation.vertices[1])
    assert set(views) == {"front", "side", "inside", "top", "midsagittal"}
    for name, image in views.items():
        background = np.median(image.reshape(-1, 3), axis=0)
        drawn = np.abs(image.astype(int) - background).sum(axis=2) > 30
        assert drawn.mean() > 0.05, name
    # issue 13: the top and midsagittal views change with the data (the frames where the
    # tongue blade T2 is lowest and highest)
    t2 = np.asarray(animation.pellets_measured)[:, 3, 1]
    low, high = (renderer.render_views(animation.vertices[k])
                 for k in (int(np.argmin(t2)), int(np.argmax(t2))))  # fmt: skip
    for name in ("top", "midsagittal"):
        changed = np.abs(low[name].astype(int) - high[name]).sum(axis=2) > 30
        assert changed.mean() > 0.01, name
    # in the top view, under the palate too (seen through it), not only where the tongue
    # sticks out: the palate's and teeth's footprint with the tongue moved out of the view
    away = np.asarray(animation.vertices[1]).copy()
    away[state.model.regions["tongue"], 0] += 1000.0
    cover = renderer.render_views(away)["top"].astype(int)
    footprint = np.abs(cover - cover[0, 0]).sum(axis=2) > 30
    changed = np.abs(low["top"].astype(int) - high["top"]).sum(axis=2) > 30
    assert (changed & footprint).sum() > 0.3 * footprint.sum()  # an opaque palate: 2 %


def test_export_glb_and_obj(corpus, sentence, tmp_path, capsys):
    subject, recording = sentence
    glb = tmp_path / "talk.glb"
    code, _, _ = _run(
        capsys,
        "export",
        corpus,
        subject,
        synth.SENTENCE_TASK,
        "--out",
        glb,
        "--stride",
        STRIDE,
        "--max-keyframes",
        20,
    )
    assert code == 0
    doc, _ = read_glb(glb)
    assert len(doc["meshes"][0]["primitives"][0]["targets"]) == 19
    obj = tmp_path / "frame.obj"
    code, _, _ = _run(
        capsys, "export", recording.path, "--out", obj, "--frame", 3, "--stride", STRIDE
    )
    assert code == 0
    # the mesh of animation frame 3: every vertex where the animation puts it
    import trimesh

    from cassi_fit.pipeline import run_recording

    run = run_recording(recording, stride=STRIDE)
    mesh = trimesh.load(obj, process=False)
    expected = np.asarray(run.animation.vertices[3])
    assert mesh.vertices.shape == expected.shape
    assert len(mesh.faces) == len(run.state.model.faces)
    np.testing.assert_allclose(mesh.vertices, expected, atol=1e-5)
    assert np.abs(expected - np.asarray(run.animation.vertices[0])).max() > 0.5  # not frame 0


def test_demo_writes_everything_and_reruns(corpus, tmp_path, capsys, monkeypatch):
    """The demo writes every output; a rerun replaces its own outputs: one run over a
    folder that already holds a stale file under each name the demo writes (as an earlier
    run leaves it), so the run must replace every one of them."""
    monkeypatch.setenv("CASSI_SYNTH_DIR", str(corpus))  # the small corpus stands in
    out = tmp_path / "demo"
    out.mkdir()
    subject = Dataset(corpus).subjects()[0]
    stale = {f"{subject}.calibration.json", f"{subject}_{synth.SENTENCE_TASK}.glb",
             f"{subject}_{synth.JAW_WAGGING_TASK}_jaw.png",
             f"{subject}_{synth.SENTENCE_TASK}_cassi_vs_calibrated.png"}
    for task in (synth.JAW_WAGGING_TASK, synth.SENTENCE_TASK):
        stale.add(f"{subject}_{task}.mp4")
        stale |= {f"{subject}_{task}_{view}.png"
                  for view in ("front", "side", "inside", "top", "midsagittal", "grid")}
    for name in stale:
        (out / name).write_bytes(b"stale output of an earlier run")
    code, stdout, _ = _run(
        capsys, "demo", "--out", out, "--size", SIZE, "--stride", 20, "--quiet"
    )
    assert code == 0 and str(out.resolve()) in stdout
    names = {p.name for p in out.iterdir()}
    assert stale <= names
    for name in stale:  # every one replaced, and listed
        assert (out / name).read_bytes() != b"stale output of an earlier run", name
        assert name in stdout, name
    for task in (synth.JAW_WAGGING_TASK, synth.SENTENCE_TASK):
        assert f"{subject}_{task}.mp4" in names
        for view in ("front", "side", "inside", "top"):
            assert f"{subject}_{task}_{view}.png" in names
    assert f"{subject}_{synth.SENTENCE_TASK}.glb" in names
    assert f"{subject}_{synth.JAW_WAGGING_TASK}_jaw.png" in names
    assert media_info(out / f"{subject}_{synth.SENTENCE_TASK}.mp4")["audio"]
    assert not any(n.startswith(".") for n in names)  # no temporary files left


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["animate", "/no/such/file.txy"], "no such recording file"),
        (["animate", "{txy}", "--size", "big"], "--size"),
        (["animate", "{txy}", "--views", "front,back"], "back"),
        (["animate", "{txy}", "--out", "x.avi"], ".avi"),
        (["animate", "{txy}", "--stride", "0"], "stride"),
        (["animate", "{txy}", "--fps", "fast"], "--fps"),
        (["animate", "{txy}", "--fps", "0"], "--fps"),
        (["animate", "a", "b"], "DATASET SUBJECT TASK"),
        (["animate", "{root}", "NOBODY", "tp040"], "NOBODY"),
        (["acoustics", "{root}"], "recordings: name one as DATASET SUBJECT TASK"),
        # a folder with a still or a video for --out is read as one recording
        (["animate", "{root}", "--out", "x.png"], "recordings: name one as DATASET SUBJECT"),
        (["animate", "{root}"], "give --out DIR"),
        (["export", "{txy}", "--out", "x.stl"], ".stl"),
        (["animate", "{txy}", "--out", "{existing}"], "exists"),
        (["animate", "{txy}", "--mode", "cassi", "--collisions", "project"], "collision"),
        (["animate", "{txy}", "--cassi", "--mode", "improved"], "disagree"),
    ],
)
def test_errors_are_one_line(argv, fragment, corpus, sentence, tmp_path, capsys):
    existing = tmp_path / "old.mp4"
    existing.write_bytes(b"")
    words = [a.format(txy=sentence[1].path, root=corpus, existing=existing) for a in argv]
    code, _, err = _run(capsys, *words)
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("cassi: error:") and fragment in lines[0], err


def test_damaged_pellet_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.txy"
    bad.write_text("0\t1\t2\n")
    code, _, err = _run(capsys, "animate", bad, "--out", tmp_path / "x.mp4")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "bad.txy" in lines[0]
