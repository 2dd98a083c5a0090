"""``cassi acoustics`` and cassi_fit.acoustics on a synthetic recording whose sound is a
synthetic vowel with labels beside it."""

import wave

import numpy as np
import pytest
from scipy.signal import lfilter

from cassi_fit import cli, synth
from cassi_fit.acoustics import is_vowel
from cassi_fit.dataset import Dataset

pytestmark = pytest.mark.slow
RATE = 16000


def _vowel_wav(path, seconds):
    x = np.zeros(int(seconds * RATE))
    x[:: RATE // 120] = 1.0
    x = lfilter([1.0], [1.0, -0.97], lfilter([1.0], [1.0, -0.97], x))
    for f, b in ((600, 80), (1200, 100), (2500, 120), (3500, 150), (4500, 200)):
        r = np.exp(-np.pi * b / RATE)
        x = lfilter([1.0 - r], [1.0, -2 * r * np.cos(2 * np.pi * f / RATE), r * r], x)
    pcm = (x / np.max(np.abs(x)) * 20000).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(RATE)
        w.writeframes(pcm.tobytes())


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    root = synth.generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=1,
                                 tasks=[synth.JAW_WAGGING_TASK], audio=False)
    dataset = Dataset(root)
    subject = dataset.subjects()[0]
    rec = dataset.load(subject, synth.JAW_WAGGING_TASK)
    seconds = float(rec.track.times[-1]) + 0.01
    _vowel_wav(rec.path.with_suffix(".wav"), seconds)
    rec.path.with_suffix(".lab").write_text(
        f"0 {seconds / 3:.3f} sil\n{seconds / 3:.3f} {2 * seconds / 3:.3f} a\n"
        f"{2 * seconds / 3:.3f} {seconds - 0.005:.3f} sil\n")
    return rec.path


def test_is_vowel():
    assert is_vowel("a") and is_vowel("a:") and is_vowel("aU") and is_vowel("AA1")
    assert not is_vowel("s") and not is_vowel("sil") and not is_vowel("")


def test_cli_tables_figure_and_refusals(recording, tmp_path, capsys):
    out = tmp_path / "f.csv"
    png = tmp_path / "f.png"
    code = cli.main(["acoustics", str(recording), "--stride", "8", "--csv", str(out),
                     "--plot", str(png)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "% of the vowels' frames scored" in text
    header = out.read_text().splitlines()[0].split(",")
    assert {"time_s", "label", "scored", "F1_model_hz", "F1_measured_hz"} <= set(header)
    segments = out.with_suffix(".segments.csv").read_text().splitlines()
    assert len(segments) == 2 and segments[1].split(",")[2] == "a"
    # the synthetic vowel's resonances are measured (the model's are its own)
    f1 = float(segments[1].split(",")[segments[0].split(",").index("F1_measured_hz")])
    assert abs(f1 - 600) < 60
    assert png.stat().st_size > 10_000
    # an existing output is refused in one line; without a sound the formants cannot be measured
    assert cli.main(["acoustics", str(recording), "--stride", "8", "--csv", str(out)]) != 0
    assert "exists" in capsys.readouterr().err
    recording.with_suffix(".wav").rename(tmp_path / "moved.wav")
    try:
        assert cli.main(["acoustics", str(recording), "--stride", "8"]) != 0
        assert "no sound" in capsys.readouterr().err
    finally:
        (tmp_path / "moved.wav").rename(recording.with_suffix(".wav"))


def test_calibrate_acoustic_writes_the_tract_and_acoustics_reads_it(recording, tmp_path, capsys):
    dataset = recording.parent.parent  # DATASET/SUBJECT/TASK.TXY
    out = tmp_path / "cal"
    code = cli.main(["calibrate", str(dataset), "--acoustic", "--out", str(out),
                     "--accept-unconverged"])
    text = capsys.readouterr().out
    assert code == 0, text
    written = sorted(out.glob("*.acoustic.json"))
    assert len(written) == 1 and "one vowel quality" in text
    code = cli.main(["acoustics", str(recording), "--stride", "8", "--calibration", str(out)])
    assert code == 0
    assert "no acoustic calibration" not in capsys.readouterr().out
    written[0].write_text("{}")
    assert cli.main(["acoustics", str(recording), "--stride", "8", "--calibration", str(out)]) != 0
    assert "not an acoustic calibration" in capsys.readouterr().err
