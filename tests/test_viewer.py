"""The one-file viewer (issue 31): the frame encoding, the page's content, and the page in a
real headless Chromium (Playwright, Debian's chromium; ``make browser`` installs it).

One small synthetic recording (the sentence task with its sound, every data line), one page built once
for the module, opened once from its ``file://`` URL with every other request aborted. The
browser tests skip with one line only where no browser can be had here. Nothing waits for
time to pass: the tests wait for states (a frame shown), never for playback.
"""

import json
import re

import numpy as np
import pytest
from scipy import ndimage

from cassi_fit import cli, synth
from cassi_fit.dataset import Dataset
from cassi_fit.labels import Labels, write_lab
from cassi_fit.viewer import ViewerPage, decode_motion, encode_motion
from cassi_fit.viewer._browser import browser_missing, chromium, open_page
from cassi_fit.viewer._encode import TOLERANCE_MM

pytestmark = pytest.mark.render
BROWSER_MISSING = browser_missing()


# ------------------------------------------------------------------ the encoding
def _jaw_like_motion(n_frames=240, n_vertices=400, seed=1):
    """A rest mesh and frames whose lower half rotates about a pivot (a nonlinear motion:
    not exactly a low-rank linear one) and whose 'tongue' moves along two fixed shapes."""
    rng = np.random.default_rng(seed)
    rest = rng.normal(scale=30.0, size=(n_vertices, 3))
    t = np.linspace(0, 3, n_frames)
    theta = np.radians(8) * (1 + np.sin(2 * np.pi * 1.7 * t)) / 2
    frames = np.repeat(rest[None], n_frames, axis=0)
    jaw = rest[:, 1] < 0
    pivot = np.array([-60.0, 20.0])
    for f, th in enumerate(theta):
        c, s = np.cos(th), np.sin(th)
        xy = rest[jaw, :2] - pivot
        frames[f, jaw, :2] = pivot + xy @ np.array([[c, -s], [s, c]])
    tongue = np.flatnonzero(~jaw)[:50]
    shapes = rng.normal(size=(2, len(tongue), 3))
    weights = np.stack([np.sin(2 * np.pi * 0.9 * t), np.cos(2 * np.pi * 2.3 * t)], axis=1)
    frames[:, tongue] += 3.0 * np.einsum("fk,kvd->fvd", weights, shapes)
    return rest, frames


def test_every_frame_comes_back_within_the_tolerance():
    rest, frames = _jaw_like_motion()
    encoded = encode_motion(frames, rest)
    back = decode_motion(encoded, rest)
    assert back.shape == frames.shape  # every frame, none decimated
    error = np.abs(back - frames).max()
    assert error <= TOLERANCE_MM
    assert error == pytest.approx(encoded["max_error_mm"], rel=1e-6)
    # the still half (above the pivot, not the tongue) is not stored
    assert len(encoded["moving"]) < len(rest)
    # the components carry the motion: the mean frame alone is far off
    assert encoded["n_components"] >= 2
    mean_only = dict(encoded, coeff=np.zeros_like(encoded["coeff"]))
    assert np.abs(decode_motion(mean_only, rest) - frames).max() > 20 * TOLERANCE_MM
    assert encoded["basis"].dtype == np.int16 and encoded["coeff"].dtype == np.int16


def test_a_tighter_tolerance_takes_more_components_and_meets_it():
    rest, frames = _jaw_like_motion()
    loose = encode_motion(frames, rest, tolerance_mm=0.5)
    tight = encode_motion(frames, rest, tolerance_mm=0.005)
    assert tight["n_components"] > loose["n_components"]
    assert np.abs(decode_motion(tight, rest) - frames).max() <= 0.005


def test_a_still_face_and_bad_frames():
    rest, frames = _jaw_like_motion(n_frames=5)
    still = encode_motion(np.repeat(rest[None], 5, axis=0), rest)
    assert still["n_components"] == 0 and len(still["moving"]) == 0
    assert np.array_equal(decode_motion(still, rest), np.repeat(rest[None], 5, axis=0))
    frames[2, 3, 1] = np.nan
    with pytest.raises(Exception, match="not all finite"):
        encode_motion(frames, rest)


# ------------------------------------------------------------------ the page
@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """The synthetic sentence with its sound, and phone labels written beside it."""
    root = synth.generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=1,
                                 tasks=[synth.SENTENCE_TASK], audio=True)  # fmt: skip
    dataset = Dataset(root)
    recording = dataset.load(dataset.subjects()[0], synth.SENTENCE_TASK)
    write_lab(recording.path.with_suffix(".lab"), _labels(recording))
    return recording


def _labels(recording):
    """Four labels over the recording (made here: the synthetic corpus writes none)."""
    t = np.asarray(recording.track.times)
    edges = np.round(np.linspace(t[0], t[-1], 5), 4)
    return Labels(edges[:-1].copy(), edges[1:].copy(), ("aa", "bb", "cc", "dd"), "labels")


@pytest.fixture(scope="module")
def run(recording):
    """The run the page shows, in this process (its vertices for the toolkit's render)."""
    from cassi_fit.pipeline import run_recording

    return run_recording(recording, stride=1)


@pytest.fixture(scope="module")
def page(recording, run, tmp_path_factory):
    """``cassi view RECORDING --out talk.html``, after the run above (compiled once)."""
    path = tmp_path_factory.mktemp("page") / "talk.html"
    assert cli.main(["view", str(recording.path), "--out", str(path)]) == 0
    return path


def _data(html):
    blob = re.search(r'<script id="cassi-data" type="application/json">(.*?)</script>', html, re.S)
    return json.loads(blob.group(1))


def test_page_holds_every_data_line_the_sound_and_says_what_it_is(page, run, recording, capsys):
    path = page
    html = path.read_text()
    data = _data(html)
    assert data["meta"]["frames"] == run.animation.n_frames
    assert data["times"]["shape"] == [run.animation.n_frames]
    assert data["meta"]["stride"] == 1  # every data line a frame
    assert data["meta"]["max_error_mm"] <= TOLERANCE_MM
    assert "data:audio/wav;base64," in html
    header = re.search(r"<header>(.*?)</header>", html, re.S).group(1)
    for word in (recording.subject, recording.task, "jaw method", run.animation.jaw_method,
                 "calibration", "Hz"):  # fmt: skip
        assert word in header
    # nothing fetched: no script/link/img from elsewhere, no module script
    assert not re.search(r'(src|href)="(https?:)?//', html)
    assert 'type="module"' not in html
    assert str(path.parent) not in html  # no machine's path in the page
    # small enough to e-mail: at most 15 MB for 5 s (this recording is about 4 s)
    seconds = float(run.animation.times[-1] - run.animation.times[0])
    assert path.stat().st_size <= 15e6 * seconds / 5
    assert [t["name"] for t in data["labels"]] == ["labels"]  # the .lab beside it
    inline = ViewerPage(html, data["meta"])._repr_html_()  # what Jupyter shows
    assert inline.startswith("<iframe srcdoc=") and "&lt;script" in inline


def test_cli_refuses_a_wrong_suffix_and_an_existing_page(page, recording, capsys):
    assert cli.main(["view", str(recording.path), "--out", str(page.with_suffix(".png"))]) != 0
    assert ".html" in capsys.readouterr().err
    before = page.read_bytes()
    assert cli.main(["view", str(recording.path), "--out", str(page)]) != 0
    assert "exists" in capsys.readouterr().err
    assert page.read_bytes() == before


# ------------------------------------------------------------------ in the browser
@pytest.fixture(scope="module")
def browser():
    if BROWSER_MISSING:
        pytest.skip(f"viewer browser tests: {BROWSER_MISSING}")
    with chromium() as b:
        yield b


@pytest.fixture(scope="module")
def tab(browser, page):
    tab, errors = open_page(browser, page)
    yield tab, errors
    assert errors == []  # nothing blocked, no console or page error, over every test


def _canvas(tab):
    """The 3D view's pixels as drawn (its drawing buffer, kept), (H, W, 3) int."""
    import base64
    import io

    import imageio.v3 as iio

    url = tab.evaluate("cassiViewer.scene.renderer.domElement.toDataURL('image/png')")
    png = base64.b64decode(url.split(",", 1)[1])
    return iio.imread(io.BytesIO(png), extension=".png")[..., :3].astype(int)


def _show(tab, frame, preset):
    tab.evaluate("([f, p]) => { cassiViewer.setPreset(p); cassiViewer.seekFrame(f); }",
                 [frame, preset])  # fmt: skip
    tab.wait_for_function(f"cassiViewer.frame === {frame}")


def _silhouette(image, background=(235, 235, 235)):
    mask = np.abs(image - np.array(background)).sum(axis=2) > 24
    return ndimage.binary_fill_holes(ndimage.binary_opening(mask, iterations=1))


def test_picture_agrees_with_the_toolkits_render(tab, run):
    from cassi_fit.render import Renderer

    tab, _ = tab
    frame = int(np.argmax(np.asarray(run.animation.params.jaw_theta)))  # mouth open
    shots = {}
    for preset in ("front", "side"):
        tab.evaluate("document.querySelectorAll('[data-pellets]').forEach(b => "
                     "{ if (b.checked) b.click(); })")  # the toolkit's views draw none
        _show(tab, frame, preset)
        shots[preset] = _canvas(tab)
    height, width = shots["side"].shape[:2]
    with Renderer(run.state.model, size=(width, height), views=("front", "side"),
                  grid=False) as renderer:  # fmt: skip
        ours = renderer.render_views(np.asarray(run.animation.vertices[frame]))

    def iou(a, b):
        return (a & b).sum() / (a | b).sum()

    for preset in ("front", "side"):
        page_mask, toolkit_mask = _silhouette(shots[preset]), _silhouette(ours[preset])
        assert page_mask.mean() > 0.1  # a head, not a blank canvas
        assert iou(page_mask, toolkit_mask) > 0.93, preset
    # the comparison tells views apart: the page's front is not the toolkit's side
    assert iou(_silhouette(shots["front"]), _silhouette(ours["side"])) < 0.85
    tab.evaluate("document.querySelectorAll('[data-pellets]').forEach(b => "
                 "{ if (!b.checked) b.click(); })")


def _mouth_box(run, width, height):
    """The lips' pixels (rows, cols slices) in the page's side preset, from the toolkit's
    camera fit (the same numbers the page uses)."""
    from cassi_fit.face_model import MATERIALS
    from cassi_fit.render import view_cameras

    cams = view_cameras(run.state.model, ("side",))
    v = cams["side"]
    pad = np.array(v["extent"]) + 2 * cams["margin_mm"]
    scale = min(width / pad[0], height / pad[1]) * (1 - 2 * cams["margin"])
    model = run.state.model
    lips = np.unique(np.asarray(model.faces)[np.asarray(model.face_material)
                                             == MATERIALS.index("lips")])  # fmt: skip
    p = np.asarray(model.vertices)[lips] - np.array(v["centre"])
    cols = width / 2 + scale * (p @ np.array(v["right"]))
    rows = height / 2 - scale * (p @ np.array(v["up"]))
    margin = 15
    return (slice(int(rows.min()) - margin, int(rows.max()) + margin),
            slice(int(cols.min()) - margin, int(cols.max()) + margin))  # fmt: skip


def test_scrubbing_to_two_times_changes_the_mouth(tab, run):
    tab, _ = tab
    theta = np.asarray(run.animation.params.jaw_theta)
    closed, opened = int(np.argmin(theta)), int(np.argmax(theta))
    scrub = tab.locator("#cassi-scrub")
    tab.evaluate("cassiViewer.setPreset('side')")
    pictures = []
    for frame in (closed, opened):
        scrub.fill(str(frame))  # the range input, as a user drags it
        tab.wait_for_function(f"cassiViewer.frame === {frame}")
        pictures.append(_canvas(tab))
    rows, cols = _mouth_box(run, pictures[0].shape[1], pictures[0].shape[0])
    changed = np.abs(pictures[0] - pictures[1]).sum(axis=2) > 30
    assert changed[rows, cols].mean() > 0.05  # the mouth moved
    forehead = changed[: rows.start - 40]
    assert forehead.mean() < 0.2 * changed[rows, cols].mean()  # and not the whole head


def test_setting_the_sounds_time_moves_the_frame(tab, run):
    tab, _ = tab
    tab.wait_for_function("document.getElementById('cassi-audio').readyState >= 1")
    times = np.asarray(run.animation.times)
    for frame in (len(times) // 3, 2 * len(times) // 3):
        t = float(times[frame])
        tab.evaluate(f"document.getElementById('cassi-audio').currentTime = {t}")
        tab.wait_for_function(f"cassiViewer.frame === {frame}")  # a state, not a delay
        assert tab.evaluate("Number(document.getElementById('cassi-scrub').value)") == frame


TOGGLES = [("#cassi-skin", "see-through"), ("#cassi-skin", "hidden"),
           ("[data-part=teeth]", None), ("[data-part=tongue]", None),
           ("[data-part=palate]", None), ("[data-part=pharynx]", None),
           ("[data-pellets=measured]", None), ("[data-pellets=model]", None)]  # fmt: skip


def test_each_toggle_changes_what_is_drawn(tab, run):
    tab, _ = tab
    frame = int(np.argmax(np.asarray(run.animation.params.jaw_theta)))
    for selector, value in TOGGLES:
        # the inner parts in the inside view (skin cut open), the skin in the side view
        _show(tab, frame, "side" if value else "inside")
        before = _canvas(tab)
        control = tab.locator(selector)
        if value:
            control.select_option(value)
        else:
            control.click()
        after = _canvas(tab)
        changed = (np.abs(before - after).sum(axis=2) > 30).sum()
        assert changed > 50, selector
        if not value:
            control.click()  # back on


def test_clicking_a_label_moves_the_scrubber_to_its_start(tab, run):
    tab, _ = tab
    times = np.asarray(run.animation.times)
    labels = _labels(run.recording)
    tab.locator(".cassi-label", has_text="cc").click()
    tab.wait_for_function("cassiViewer.time >= %r" % (float(labels.starts[2]) - 1e-9))
    frame = tab.evaluate("Number(document.getElementById('cassi-scrub').value)")
    assert times[frame] >= labels.starts[2] - 1e-9
    assert times[frame - 1] < labels.starts[2]  # its start, not later
    assert "cc" in tab.locator("#cassi-clock").inner_text()


def test_without_webgl_the_page_says_so(browser, page):
    from cassi_fit.viewer._browser import CHROMIUM_ARGS, chromium_path

    other = browser.browser_type.launch(executable_path=chromium_path(), headless=True,
                                        args=[*CHROMIUM_ARGS, "--disable-3d-apis"])
    try:
        tab, errors = open_page(other, page)
        note = tab.locator("#cassi-nogl")
        assert note.is_visible() and "cannot be drawn" in note.inner_text()
        assert tab.evaluate("cassiViewer.n") > 0  # the rest of the page works
        tab.locator("#cassi-fwd").click()
        assert tab.evaluate("cassiViewer.frame") == 1
        assert errors == []
    finally:
        other.close()


def test_stepping_and_slowing_down(tab, run):
    tab, _ = tab
    tab.evaluate("cassiViewer.seekFrame(10)")
    tab.locator("#cassi-fwd").click()
    assert tab.evaluate("cassiViewer.frame") == 11  # one data line on (stride 1)
    tab.locator("#cassi-back").click()
    tab.locator("#cassi-back").click()
    assert tab.evaluate("cassiViewer.frame") == 9
    for speed in ("0.5", "0.25", "1"):
        tab.locator("#cassi-speed").select_option(speed)
        assert tab.evaluate("document.getElementById('cassi-audio').playbackRate") == float(speed)
    tab.locator("[data-preset=top]").click()
    assert tab.evaluate("cassiViewer.preset") == "top"
    assert tab.locator("#cassi-skin").input_value() == "hidden"


def test_play_and_pause(tab):
    tab, _ = tab
    tab.evaluate("cassiViewer.seekFrame(0)")
    tab.locator("#cassi-play").click()
    assert tab.evaluate("cassiViewer.playing") is True
    assert tab.locator("#cassi-play").inner_text() == "pause"
    tab.locator("#cassi-play").click()
    assert tab.evaluate("cassiViewer.playing") is False
    assert tab.evaluate("document.getElementById('cassi-audio').paused") is True
