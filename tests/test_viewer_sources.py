"""The one-file viewer (issue 31) on the recordings its done-criteria name: a lab-like
articulograph file (Haskins mview ``.mat``: numbered sensors named by a sensor map, no
reference sensor, the sound inside the file) and, where it is beside the checkout, the real
JW11 recording. Each page opens offline in headless Chromium without an error, holds
every data line and the sound, and draws a different mouth at two times."""

from pathlib import Path

import pytest
from real_data import XRMB_JW11, missing, real_data

from cassi_fit import cli
from cassi_fit.dataset import load_recording
from cassi_fit.quality import quality_report
from cassi_fit.viewer._browser import browser_missing, chromium, open_page

pytestmark = pytest.mark.render
ROOT = Path(__file__).resolve().parents[1]
JW11 = None if real_data(XRMB_JW11) is None else real_data(XRMB_JW11) / "jw11_tp005.txy"
BROWSER_MISSING = browser_missing()


@pytest.fixture(scope="module")
def browser():
    if BROWSER_MISSING:
        pytest.skip(f"viewer browser tests: {BROWSER_MISSING}")
    with chromium() as b:
        yield b


@pytest.fixture(scope="module")
def mview(tmp_path_factory):
    root = tmp_path_factory.mktemp("lab")
    assert cli.main(["synth", str(root / "corpus"), "--format", "mview", "--lab-like",
                     "--subjects", "1", "--tasks", "tp106"]) == 0
    folder = root / "corpus" / "L01"
    return folder / "tp106.mat", folder / "truth_sensors.toml"


def _page(tmp_path, argv):
    out = tmp_path / "talk.html"
    assert cli.main(["view", *argv, "--out", str(out)]) == 0
    return out


def _check_page(browser, page, recording, labels=None):
    tab, errors = open_page(browser, page)
    try:
        # every data line a frame, from the first valid one (as every animation starts)
        lines = recording.track.n_frames - quality_report(recording.track).first_valid_frame
        assert tab.evaluate("cassiViewer.n") == lines
        assert "data:audio/wav;base64," in page.read_text()  # the sound travels with it
        pictures = []
        for frame in (lines // 4, lines // 2):
            tab.evaluate("f => cassiViewer.seekFrame(f)", frame)
            tab.wait_for_function(f"cassiViewer.frame === {frame}")
            pictures.append(tab.evaluate(
                "cassiViewer.scene.renderer.domElement.toDataURL('image/png')"))
        assert pictures[0] != pictures[1]  # the face moved between the two times
        tab.locator("#cassi-fwd").click()
        assert tab.evaluate("cassiViewer.frame") == lines // 2 + 1
        if labels is not None:  # the labels beside the file, each on the timeline
            assert tab.locator(".cassi-label").count() == len(labels.labels)
        assert errors == []  # nothing blocked, no console or page error
    finally:
        tab.close()


def test_a_lab_like_articulograph_file_with_its_sound_inside(browser, mview, tmp_path):
    path, sensor_map = mview
    page = _page(tmp_path, [str(path), "--sensor-map", str(sensor_map)])
    recording = load_recording(path, sensor_map=sensor_map)
    assert recording.sound is not None and recording.sound.kind == "mview AUDIO"
    _check_page(browser, page, recording)


@pytest.mark.skipif(JW11 is None, reason=missing(XRMB_JW11))
def test_the_real_jw11_recording(browser, tmp_path):
    page = _page(tmp_path, [str(JW11)])
    from cassi_fit.labels import recording_labels

    recording = load_recording(JW11)
    labels = recording_labels(recording)
    assert labels is not None and len(labels.labels) > 10
    _check_page(browser, page, recording, labels)
