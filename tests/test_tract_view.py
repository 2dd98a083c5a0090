"""The tract view beside the face (issue 29 part 4: ``cassi animate --views ...,tract``):
its panels agree with the acoustics, the renderer draws what it is given, and the command
line writes it.

One synthetic sentence with its sound (every 6th data line)."""

import numpy as np
import pytest

from cassi_fit import cli, synth
from cassi_fit.acoustics import PANEL_HZ, recording_acoustics, tract_panels
from cassi_fit.dataset import Dataset

pytestmark = pytest.mark.render


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from cassi_fit.pipeline import run_recording

    root = synth.generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=1,
                                 tasks=[synth.SENTENCE_TASK], audio=True)
    dataset = Dataset(root)
    recording = dataset.load(dataset.subjects()[0], synth.SENTENCE_TASK)
    return run_recording(recording, stride=6)


@pytest.fixture(scope="module")
def panels(run):
    return tract_panels(run)


def test_panels_are_the_acoustics_of_each_frame(run, panels):
    assert len(panels) == run.animation.n_frames
    acoustics = recording_acoustics(run)
    model = np.stack([p["model_hz"] for p in panels])
    np.testing.assert_allclose(model, acoustics.model[:, :3], rtol=1e-9)
    areas = np.stack([p["areas_mm2"] for p in panels])
    np.testing.assert_allclose(areas, acoustics.areas, rtol=1e-9)
    # the sound's formants only where the tracker trusts them, else NaN
    measured = np.stack([p["measured_hz"] for p in panels])
    reliable = acoustics.measured.reliable
    assert reliable.any() and (~reliable).any()
    assert np.isnan(measured[~reliable]).all()
    np.testing.assert_allclose(measured[reliable], acoustics.measured.frequency[reliable, :3])


def test_the_spectrum_peaks_where_the_formants_are(panels):
    """The spectrum (the tube's gain on a 25 Hz grid) and the formants (Newton's method on
    the inverse gain) are computed apart: each F1 is a local peak of the drawn curve."""
    for p in panels[:: max(len(panels) // 8, 1)]:
        gain, f1 = p["gain_db"], p["model_hz"][0]
        assert np.all(np.isfinite(gain)) and len(gain) == len(PANEL_HZ)
        k = int(np.argmin(np.abs(PANEL_HZ - f1)))
        window = gain[max(k - 3, 0): k + 4]
        peak = max(k - 3, 0) + int(np.argmax(window))
        assert abs(PANEL_HZ[peak] - f1) <= 50.0
        assert gain[peak] > np.median(gain) + 6.0  # a resonance, not a flat stretch


def _cell(image):
    """The right half of a two-view image (the tract view's cell), without the caption."""
    h, w, _ = image.shape
    return image[: int(h * 0.9), w // 2:].astype(int)


def test_the_renderer_draws_the_panel_it_is_given(run, panels):
    from cassi_fit.render import Renderer

    vertices = np.asarray(run.animation.vertices)
    a, b = 0, int(np.argmax([abs(p["model_hz"][0] - panels[0]["model_hz"][0]) for p in panels]))
    with Renderer(run.state.model, size=(480, 240), views=("midsagittal", "tract")) as r:
        first = r.render(vertices[a], tract=panels[a])
        other = r.render(vertices[a], tract=panels[b])  # the same face, another tract
        none = r.render(vertices[a])
        again = r.render(vertices[a], tract=panels[a])
    assert np.array_equal(first, again)
    assert np.abs(_cell(first) - _cell(other)).sum(axis=2).astype(bool).mean() > 0.005
    assert np.abs(_cell(first) - _cell(none)).sum(axis=2).astype(bool).mean() > 0.02
    # the left half (midsagittal) does not depend on the tract panel
    assert np.array_equal(first[:, : first.shape[1] // 2 - 2], other[:, : other.shape[1] // 2 - 2])


def test_cassi_animate_writes_the_tract_view(run, tmp_path, capsys):
    out = tmp_path / "still.png"
    code = cli.main(["animate", str(run.recording.path), "--views", "midsagittal,tract",
                     "--size", "480x240", "--stride", "6", "--frame", "3", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    from PIL import Image

    image = np.asarray(Image.open(out).convert("RGB"))
    cell = _cell(image)
    assert (cell.std(axis=(0, 1)) > 10).all()  # plots drawn, not an empty cell
    assert cli.main(["animate", str(run.recording.path), "--views", "front,throat",
                     "--out", str(tmp_path / "x.png")]) == 2
    assert "tract" in capsys.readouterr().err  # the error lists the views, tract among them


def test_the_subjects_fitted_vocal_tract_is_drawn_when_the_calibration_holds_one(
        run, panels, tmp_path, capsys):
    """``--calibration FOLDER`` with ``SUBJECT.acoustic.json`` in it (``cassi calibrate
    --acoustic``): the tract view shows that tract (its areas and formants, and says so),
    not the adult norms; a folder without one says the norms are used."""
    import json

    from cassi_fit.acoustic_fit import (
        AcousticFit,
        acoustic_calibration_path,
        write_acoustic_calibration,
    )
    from cassi_fit.area_function import GLOTTIS_BELOW_HYOID_MM, TractParams

    subject = run.recording.subject
    # a longer tract (the glottis 12 mm lower), wider everywhere: other formants, areas
    fitted = TractParams(*(np.float64(v) for v in (GLOTTIS_BELOW_HYOID_MM + 12.0, 1.5, 1.2, 1.3)))
    folder = tmp_path / "cal"
    folder.mkdir()
    nothing = tract_panels(run, calibration=folder)
    # the default adult male norms, said as before the speaker's norms; with --speaker auto
    # the norms of the subject's voice (acoustics.speaker_norms), and why
    assert nothing[0]["tract"] == f"no acoustic calibration for {subject} in {folder}: the adult norms"
    norms = recording_acoustics(run, speaker="auto").norms
    why = f"the adult norms, {norms.speaker} ({norms.why})"
    assert norms.source == "voice" and f"median F0 {norms.f0_hz:.0f} Hz" in why
    assert tract_panels(run, calibration=folder, speaker="auto")[0]["tract"] == (
        f"no acoustic calibration for {subject} in {folder}: {why}")
    np.testing.assert_array_equal(nothing[0]["areas_mm2"], panels[0]["areas_mm2"])
    write_acoustic_calibration(acoustic_calibration_path(folder, subject), subject,
                               AcousticFit(fitted, True, 5, np.zeros(3), np.zeros(3)),
                               recordings=["x"], frames=10, qualities=["a"])
    assert json.loads(acoustic_calibration_path(folder, subject).read_text())["converged"]
    own = tract_panels(run, calibration=folder)
    assert own[0]["tract"] == f"vocal tract: fitted to the sound ({subject}.acoustic.json)"
    assert panels[0]["tract"] == "vocal tract: the adult norms"
    # what the view draws: the same, short (not the line's words cut up)
    assert own[0]["tract_label"] == f"fitted to the sound ({subject}.acoustic.json)"
    assert nothing[0]["tract_label"] == panels[0]["tract_label"] == "the adult norms"
    # the same frames through the fitted tract: what cassi acoustics computes with it
    expected = recording_acoustics(run, tract=fitted)
    np.testing.assert_allclose(np.stack([p["model_hz"] for p in own]), expected.model[:, :3],
                               rtol=1e-9)
    assert not np.allclose(np.stack([p["model_hz"] for p in own]),
                           np.stack([p["model_hz"] for p in panels]))
    # and the command line takes it from --calibration (a still: the view's cell differs)
    from PIL import Image

    stills = {}
    for name, extra in (("norms", []), ("fitted", ["--calibration", str(folder)])):
        out = tmp_path / f"{name}.png"
        code = cli.main(["animate", str(run.recording.path), "--views", "midsagittal,tract",
                         "--size", "480x240", "--stride", "6", "--frame", "3",
                         "--out", str(out), *extra])
        assert code == 0, capsys.readouterr().err
        stills[name] = _cell(np.asarray(Image.open(out).convert("RGB")))
    assert np.abs(stills["norms"] - stills["fitted"]).sum(axis=2).astype(bool).mean() > 0.005
