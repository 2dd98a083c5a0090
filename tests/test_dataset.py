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
    with pytest.raises(MissingDataError, match="no such dataset folder"):
        Dataset(tmp_path / "nowhere")
    with pytest.raises(MissingDataError):
        load_recording(tmp_path / "nowhere.txy")
    (folder_layout / "S01" / "Pal.dat").write_text("  1  2\n")
    with pytest.raises(DataFormatError, match="at least 2"):
        ds.load("S01", "tp005")


def test_empty_root(tmp_path):
    ds = Dataset(tmp_path)
    assert ds.subjects() == [] and len(ds) == 0


# ----------------------------------------------------- special files, nothing found (issue 24)
@pytest.mark.filterwarnings("ignore::cassi_fit.dataset.DefaultHeadMeasuresWarning")
def test_special_files_are_skipped_with_a_warning_and_never_opened(folder_layout):
    """A FIFO named like a pellet file, a palate or a Headmeasures file, a socket and a
    broken link: discovery names them in one SpecialFileWarning per folder and never
    opens them (opening a FIFO for reading would block for ever); loading one is a
    DataFormatError naming it."""
    from special_files import FifoGuard, make_fifo, make_socket

    from cassi_fit.dataset import SpecialFileWarning

    s01 = folder_layout / "S01"
    fifos = [make_fifo(s01 / "TP999.TXY"), make_fifo(folder_layout / "jw11" / "PAL.DAT"),
             make_fifo(folder_layout / "jw11" / "tp106.wav")]
    make_socket(s01 / "tp998.txy")
    (s01 / "tp997.txy").symlink_to(s01 / "absent.txy")
    with FifoGuard(*fifos) as guard, pytest.warns(SpecialFileWarning) as caught:
        ds = Dataset(folder_layout)
        assert ds.tasks("S01") == ["tp005", "tp020", "tp020_2"]
        with pytest.raises(MissingDataError, match=r"TP999\.TXY is a named pipe \(FIFO\), "
                           "skipped"):
            ds.load("S01", "tp999")
        rec = ds.load("jw11", "tp106")  # its palate and sound are FIFOs: absent, not read
        assert rec.palate is None and rec.audio is None
        for path in (fifos[0], s01 / "tp998.txy", s01 / "tp997.txy"):
            with pytest.raises(DataFormatError, match="not a regular file but a (named pipe|socket|broken link)") as info:
                load_recording(path)
            assert info.value.path == str(path)
    assert guard.opened == []
    messages = [str(w.message) for w in caught if w.category is SpecialFileWarning]
    assert len(messages) == 2 and all("\n" not in m for m in messages)
    s01_message = next(m for m in messages if m.startswith(f"{s01}:"))
    assert "skipped 3 special file(s), never opened" in s01_message
    for what in ("TP999.TXY (a named pipe (FIFO))", "tp998.txy (a socket)",
                 "tp997.txy (a broken link)"):
        assert what in s01_message
    assert sorted(p.name for p, _ in ds.skipped) == ["PAL.DAT", "TP999.TXY", "tp106.wav",
                                                     "tp997.txy", "tp998.txy"]


@pytest.mark.filterwarnings("ignore::cassi_fit.dataset.DefaultHeadMeasuresWarning")
def test_load_recording_warns_of_special_files_beside_it(tmp_path):
    from special_files import FifoGuard, make_fifo

    from cassi_fit.dataset import SpecialFileWarning

    pellets = _copy("sample.txy", tmp_path / "S01" / "tp005.txy")
    fifo = make_fifo(tmp_path / "S01" / "PHA.DAT")
    with FifoGuard(fifo) as guard, pytest.warns(SpecialFileWarning, match=r"PHA\.DAT \(a "
                                                "named pipe"):
        assert load_recording(pellets).pharynx is None
    assert guard.opened == []


def test_a_root_that_is_no_folder_is_one_line(tmp_path):
    from special_files import make_fifo

    (tmp_path / "tp005.txy").write_text("0" + "\t1000000" * 16 + "\n")
    for path, why in ((tmp_path / "tp005.txy", "is a file, not a dataset folder"),
                      (make_fifo(tmp_path / "pipe"), r"is a named pipe \(FIFO\), not a "
                       "dataset folder"),
                      (tmp_path / "absent", "no such dataset folder")):
        with pytest.raises(MissingDataError, match=f"^{path}: {why}") as info:
            Dataset(path)
        assert "\n" not in str(info.value)


def test_check_selection_names_the_folder_and_what_was_looked_for(folder_layout, tmp_path):

    empty = Dataset(tmp_path)
    with pytest.raises(MissingDataError, match=f"^{tmp_path}: found no recordings: looked "
                       r"for pellet files \(\.txy\) or articulograph recordings"):
        empty.check_selection()
    with pytest.raises(MissingDataError, match=f"^{tmp_path}: no subject 'S01' "
                       r"\(subjects: none\); found no recordings"):
        empty.tasks("S01")
    ds = Dataset(folder_layout)
    ds.check_selection()
    ds.check_selection(["s01"], ["TP005", "tp020"])
    ds.check_selection(None, ["tp106"])  # one subject has it
    cases = [
        (["S09"], None, r"no subject 'S09' \(subjects: JW11, S01\)"),
        ([], None, "no subject chosen"),
        (None, ["tp999"], r"no task tp999 for any subject \(tasks: tp005, tp020, tp020_2, "
         r"tp106\)"),
        (["S01"], ["tp005", "tp106"], r"no task tp106 for subject\(s\) S01 \(tasks: tp005, "
         r"tp020, tp020_2\)"),
        (None, [], "no task chosen"),
    ]
    for subjects, tasks, match in cases:
        with pytest.raises(MissingDataError, match=f"^{folder_layout}: {match}") as info:
            ds.check_selection(subjects, tasks)
        assert "\n" not in str(info.value)
    from special_files import make_fifo

    make_fifo(folder_layout / "S01" / "tp999.txy")
    with pytest.warns(UserWarning), pytest.raises(MissingDataError,
                                                  match=r"tp999\.txy is a named pipe"):
        Dataset(folder_layout).check_selection(["S01"], ["tp999"])
