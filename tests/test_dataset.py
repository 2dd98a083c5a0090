"""Dataset discovery on both layouts, case-insensitively; recordings with subject data."""

import shutil
import warnings
from pathlib import Path

import pytest

from cassi_fit.dataset import Dataset, DefaultHeadMeasuresWarning, load_recording
from cassi_fit.errors import DataFormatError, MissingDataError

FIXTURES = Path(__file__).parent / "fixtures"


def _copy(src, dst):
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(FIXTURES / src, dst)
    return dst


@pytest.fixture
def folder_layout(tmp_path):
    root = tmp_path / "xrmb"
    _copy("sample.txy", root / "S01" / "TP005.TXY")
    _copy("sample.txy", root / "S01" / "tp020_2.txy")
    _copy("sample.txy", root / "S01" / "tp020.txy")
    _copy("PAL.DAT", root / "S01" / "Pal.dat")
    _copy("PHA.DAT", root / "S01" / "PHA.DAT")
    (root / "S01" / "tp005.WAV").write_bytes(b"RIFF")
    _copy("sample.txy", root / "jw11" / "tp106.txy")
    _copy("Headmeasures.txt", root / "headmeasures.TXT")
    return root


@pytest.fixture
def flat_layout(tmp_path):
    root = tmp_path / "flat"
    _copy("sample.txy", root / "jw11_tp005.txy")
    _copy("sample.txy", root / "JW11_TP020_2.TXY")
    _copy("sample.txy", root / "s02_tp001.txy")
    _copy("PAL.DAT", root / "jw11_pal.dat")
    _copy("PHA.DAT", root / "JW11_PHA.DAT")
    _copy("Headmeasures.txt", root / "Headmeasures.txt")
    (root / "jw11_tp005.wav").write_bytes(b"RIFF")
    return root


def test_folder_layout(folder_layout):
    ds = Dataset(folder_layout)
    assert ds.subjects() == ["JW11", "S01"]
    assert ds.tasks("s01") == ["tp005", "tp020", "tp020_2"]
    assert ds.pellet_path("S01", "TP005").name == "TP005.TXY"
    rec = ds.load("s01", "tp005")
    assert (rec.subject, rec.task) == ("S01", "tp005")
    assert rec.track.n_frames == 7 and rec.palate.shape == (9, 2) and rec.pharynx.shape == (2, 2)
    assert rec.audio is not None and rec.audio.name == "tp005.WAV"
    assert not rec.head_is_default and rec.head.gonion_x == -84.5
    assert ds.load("S01", "tp020_2").audio is None


def test_flat_layout(flat_layout):
    ds = Dataset(flat_layout)
    assert ds.subjects() == ["JW11", "S02"]
    assert ds.tasks("jw11") == ["tp005", "tp020_2"]
    with pytest.warns(DefaultHeadMeasuresWarning, match="JW11"):  # not in Headmeasures.txt
        rec = ds.load("JW11", "tp005")
    assert rec.palate.shape == (9, 2) and rec.pharynx.shape == (2, 2)
    assert rec.audio.name == "jw11_tp005.wav"
    s02 = ds.load("S02", "tp001")  # in Headmeasures.txt, but no palate of its own
    assert s02.palate is None and s02.pharynx is None and not s02.head_is_default


def test_default_head_measures_warn_once(folder_layout):
    ds = Dataset(folder_layout)
    with pytest.warns(DefaultHeadMeasuresWarning, match="JW11"):
        rec = ds.load("JW11", "tp106")
    assert rec.head_is_default and rec.palate is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert ds.load("JW11", "tp106").head_is_default


def test_load_recording_both_layouts(folder_layout, flat_layout):
    rec = load_recording(folder_layout / "S01" / "TP005.TXY")
    assert (rec.subject, rec.task) == ("S01", "tp005")
    assert rec.palate is not None and rec.audio is not None and not rec.head_is_default
    rec = load_recording(folder_layout / "S01" / "tp020_2.txy")
    assert rec.task == "tp020_2"
    with pytest.warns(DefaultHeadMeasuresWarning):
        rec = load_recording(flat_layout / "JW11_TP020_2.TXY")
    assert (rec.subject, rec.task) == ("JW11", "tp020_2") and rec.pharynx is not None


def test_subject_folder_as_root(folder_layout):
    ds = Dataset(folder_layout / "S01")
    assert ds.subjects() == ["S01"] and len(ds) == 3
    rec = ds.load("S01", "tp005")  # Headmeasures.txt one folder up
    assert rec.palate is not None and not rec.head_is_default


def test_errors(folder_layout, tmp_path):
    ds = Dataset(folder_layout)
    with pytest.raises(MissingDataError, match="no subject"):
        ds.tasks("JW99")
    with pytest.raises(MissingDataError, match="no task"):
        ds.load("S01", "tp999")
    with pytest.raises(MissingDataError, match="not a folder"):
        Dataset(tmp_path / "nowhere")
    with pytest.raises(MissingDataError):
        load_recording(tmp_path / "nowhere.txy")
    (folder_layout / "S01" / "Pal.dat").write_text("  1  2\n")
    with pytest.raises(DataFormatError, match="at least 2"):
        ds.load("S01", "tp005")


def test_empty_root(tmp_path):
    ds = Dataset(tmp_path)
    assert ds.subjects() == [] and len(ds) == 0
