"""NDI Wave exports (cassi_fit.ema.wave) on a hand-written TSV, and mview .mat files
(cassi_fit.ema.mview) on structs written with scipy.io.savemat as mview's documentation
describes them (NAME, SRATE, SIGNAL), with their refusals."""

from pathlib import Path

import numpy as np
import pytest

from cassi_fit.ema.detect import detect_format
from cassi_fit.ema.mview import read_mview
from cassi_fit.ema.wave import read_wave_tsv
from cassi_fit.errors import DataFormatError

FIXTURES = Path(__file__).parent / "fixtures" / "ema"


# ------------------------------------------------------------------------- NDI Wave
def test_wave_export_with_header_states_and_blank_columns():
    path = FIXTURES / "wave_export.tsv"
    assert detect_format(path) == "wave"
    raw = read_wave_tsv(path)
    assert raw.names == ("S1", "S2") and raw.rate_hz == 100.0 and raw.dims == 3
    np.testing.assert_allclose(raw.sensor("S1")[1], [10.75, -20.5, 30.125])
    assert np.isnan(raw.sensor("S2")[1]).all()  # State Missing
    np.testing.assert_allclose(raw.sensor("S2")[2], [-1.5, 2.5, -3.5])
    np.testing.assert_allclose(raw.orientation[0, 1], [0.5, 0.5, 0.5, 0.5])


def test_wave_export_without_header(tmp_path):
    rows = ["0.0\t3\t1\tOK\t1\t0\t0\t0\t1\t2\t3", "0.0025\t3\t2\tOK\t1\t0\t0\t0\t1.5\t2\t3"]
    path = tmp_path / "noheader.tsv"
    path.write_text("\n".join(rows) + "\n")
    raw = read_wave_tsv(path)
    assert raw.names == ("S3",) and raw.rate_hz == 400.0
    np.testing.assert_allclose(raw.sensor("S3")[1], [1.5, 2, 3])


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("\tTz\t \t", "\tTzz\t \t", 1), "no TZ column"),
    (lambda t: t.replace("10.75", "1O.75"), r"wave\.tsv:3: not a number: '1O.75'"),
    (lambda t: t.replace("0.020\t", "0.005\t"), r":4: time 0.005000 s does not increase"),
    (lambda t: t.replace("\t-3.5\r\n", "\r\n"), r":4: 21 fields, the header has 22"),
])
def test_wave_refusals_name_the_line(tmp_path, edit, message):
    path = tmp_path / "wave.tsv"
    text = (FIXTURES / "wave_export.tsv").read_bytes().decode()
    path.write_bytes(edit(text).encode())
    with pytest.raises(DataFormatError, match=message):
        read_wave_tsv(path)


# ------------------------------------------------------------------------- mview .mat
def _struct(entries):
    array = np.empty((1, len(entries)), dtype=[("NAME", object), ("SRATE", object),
                                               ("SIGNAL", object), ("SOURCE", object)])
    for j, (name, rate, signal) in enumerate(entries):
        array[0, j] = (name, float(rate), signal, "hand-made")
    return array


def _save(path, **variables):
    from scipy.io import savemat

    savemat(path, variables, format="5")
    return path


def test_mview_struct_with_audio_and_angles(tmp_path):
    n = 5
    tt = np.column_stack([np.arange(n), np.full(n, 2.0), np.full(n, 3.0), np.full(n, 45.0),
                          np.full(n, 10.0)])  # x y z, then two angles
    ul = np.column_stack([np.full(n, 9.0), np.full(n, 12.0), np.zeros(n)])
    ul[2, 1] = np.nan
    audio = np.sin(np.arange(2205) / 10.0)
    path = _save(tmp_path / "utt01.mat", utt01=_struct([("AUDIO", 22050, audio), ("TT", 100, tt),
                                                         ("UL", 100, ul)]))
    assert detect_format(path) == "mview"
    raw = read_mview(path)
    assert raw.names == ("TT", "UL") and raw.rate_hz == 100.0 and raw.dims == 3
    np.testing.assert_allclose(raw.sensor("TT")[:, 0], np.arange(n))
    np.testing.assert_allclose(raw.orientation[0, 0], [45.0, 10.0])
    assert np.isnan(raw.sensor("UL")[2, 1])
    assert any("AUDIO" in note and "sound" in note for note in raw.notes)
    np.testing.assert_allclose(raw.times, np.arange(n) / 100.0)


def test_mview_refusals(tmp_path):
    a = np.zeros((4, 3))
    two = _save(tmp_path / "two.mat", first=_struct([("TT", 100, a)]),
                second=_struct([("UL", 100, a)]))
    with pytest.raises(DataFormatError, match="2 mview struct variables"):
        read_mview(two)
    assert read_mview(two, variable="second").names == ("UL",)
    rates = _save(tmp_path / "rates.mat", d=_struct([("TT", 100, a), ("UL", 200, a)]))
    with pytest.raises(DataFormatError, match="UL: 4 samples at 200 Hz, but TT"):
        read_mview(rates)
    cols = _save(tmp_path / "cols.mat", d=_struct([("TT", 100, a), ("UL", 100, a[:, :2])]))
    with pytest.raises(DataFormatError, match="UL: 2 columns, others have 3"):
        read_mview(cols)
    none = _save(tmp_path / "none.mat", x=np.zeros(3))
    with pytest.raises(DataFormatError, match="none with NAME, SRATE, SIGNAL"):
        read_mview(none)
    hdf = tmp_path / "v73.mat"
    hdf.write_bytes(b"MATLAB 7.3 MAT-file, Platform: GLNXA64" + b"\0" * 200)
    with pytest.raises(DataFormatError, match="v7.3"):
        read_mview(hdf)
    junk = tmp_path / "junk.mat"
    junk.write_bytes(b"MATLAB 5.0 MAT-file" + b"\xff" * 50)
    with pytest.raises(DataFormatError, match="junk.mat"):
        read_mview(junk)


# ------------------------------------------------------ lab-like mview: labels inside
def test_lab_like_mview_files_carry_phones_and_words_in_step_with_the_lips(tmp_path):
    """Haskins' files carry WORDS/PHONES beside AUDIO; the lab-like mview files do too
    (issue 28 part 5), on the recording's own clock: the lips are closer during the
    task's b's than during its a's (tp011: "aba ada aga ...")."""
    from cassi_fit import cli
    from cassi_fit.dataset import load_recording
    from cassi_fit.labels import recording_labels
    from cassi_fit.pellets import LL, UL

    assert cli.main(["synth", str(tmp_path / "c"), "--format", "mview", "--lab-like",
                     "--subjects", "1", "--tasks", "tp011,tp106"]) == 0
    folder = tmp_path / "c" / "L01"
    rec = load_recording(folder / "tp011.mat", sensor_map=folder / "truth_sensors.toml")
    assert {t.tier for t in rec.labels} == {"phones", "words"}
    words = next(t for t in rec.labels if t.tier == "words")
    assert words.labels == ("aba", "ada", "aga", "ibi", "idi", "igi", "ufu", "usu")
    phones = recording_labels(rec)  # what every output uses: the phones
    assert phones.tier == "phones" and len(phones) == 24
    times = rec.track.times
    gap = np.where(rec.track.valid[:, UL].all(-1) & rec.track.valid[:, LL].all(-1),
                   rec.track.positions[:, UL, 1] - rec.track.positions[:, LL, 1], np.nan)

    def mean_gap(symbol):
        inside = np.zeros(times.shape, bool)
        for seg in phones.segments():
            if seg.label == symbol:
                inside |= (times >= seg.start) & (times < seg.end)
        return np.nanmean(gap[inside])

    assert mean_gap("b") < mean_gap("a") - 3.0
    jaw = load_recording(folder / "tp106.mat", sensor_map=folder / "truth_sensors.toml")
    assert jaw.labels == () or not any(len(t) for t in jaw.labels)  # no text, no labels
