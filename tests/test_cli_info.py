"""``cassi info`` in-process: a folder, a single file, --json, --list, and errors."""

import json
import shutil
from pathlib import Path

import pytest

from cassi_fit.cli import main

FIXTURES = Path(__file__).parent / "fixtures"


@pytest.fixture
def dataset(tmp_path):
    root = tmp_path / "data"
    (root / "S01").mkdir(parents=True)
    shutil.copyfile(FIXTURES / "sample.txy", root / "S01" / "TP005.TXY")
    shutil.copyfile(FIXTURES / "sample.txy", root / "S01" / "tp020_2.txy")
    shutil.copyfile(FIXTURES / "PAL.DAT", root / "S01" / "PAL.DAT")
    shutil.copyfile(FIXTURES / "Headmeasures.txt", root / "Headmeasures.txt")
    shutil.copyfile(FIXTURES / "sample.txy", root / "jw11_tp106.txy")
    return root


def test_info_folder_table(dataset, capsys):
    assert main(["info", str(dataset)]) == 0
    out = capsys.readouterr().out
    assert "2 subject(s), 3 recording(s)" in out
    assert "S01: 2 task(s); palate 9 points" in out and "head measures from file" in out
    assert "JW11: 1 task(s)" in out and "DEFAULTS" in out
    row = next(line for line in out.splitlines() if "tp020_2" in line).split()
    assert row == ["S01", "tp020_2", "7", "0.04", "3", "42.9", "42.61", "0.003", "0"]
    assert "all%:" not in out and "never tracked" not in out  # XRMB: all eight, as ever


def test_info_json(dataset, capsys):
    assert main(["info", str(dataset), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["kind"] == "dataset" and sorted(report["subjects"]) == ["JW11", "S01"]
    q = report["subjects"]["S01"]["tp005"]["quality"]
    assert q["n_frames"] == 7 and q["first_valid_frame"] == 3
    assert q["valid_fraction"]["T4"] == pytest.approx(3 / 7)


def test_info_single_file(dataset, capsys):
    assert main(["info", str(dataset / "S01" / "TP005.TXY")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("S01 tp005") and "first valid frame 3" in out
    assert "palate 9 points" in out and "T4        42.9" in out
    assert main(["info", str(dataset / "jw11_tp106.txy"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["subject"], report["task"], report["head_is_default"]) == ("JW11", "tp106", True)


def test_info_list_reads_no_file(dataset, capsys):
    (dataset / "S01" / "tp020_2.txy").write_text("garbage\n")
    assert main(["info", str(dataset), "--list"]) == 0
    assert "tp020_2" in capsys.readouterr().out


def test_info_errors_are_one_line(dataset, capsys):
    (dataset / "S01" / "tp020_2.txy").write_text(
        FIXTURES.joinpath("sample.txy").read_text() + "1 2\n"
    )
    assert main(["info", str(dataset)]) == 2  # the bad file is reported, the rest listed
    out = capsys.readouterr().out
    assert "tp020_2.txy:8: expected 17 fields" in out and "tp005" in out
    assert main(["info", str(dataset / "S01" / "tp020_2.txy")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cassi: error: ") and err.count("\n") == 1 and ":8:" in err
    assert main(["info", str(dataset / "nothing")]) == 2
    assert "no such file or folder" in capsys.readouterr().err
    empty = dataset / "empty"
    empty.mkdir()
    assert main(["info", str(empty)]) == 2
    assert "found no recordings: looked for pellet files" in capsys.readouterr().err


def _one_jaw_sensor_ema(path: Path) -> Path:
    """A MOCHA-TIMIT EST file (tests/ema_files.py), 20 frames: no sensor for T4 or MNM, tb
    dead (T2 never tracked), the lower lip lost on 2 frames."""
    import struct

    from ema_files import mocha_header, mocha_values

    body = b""
    for i in range(20):
        values = mocha_values(i)
        if i in (4, 5):
            values[3] = values[8] = float("nan")  # ll_x, ll_y
        body += struct.pack("<22f", 0.002 * i, 1.0, *values)
    path.write_bytes(mocha_header(20) + body)
    return path


def test_all_is_over_the_pellets_the_file_tracks(dataset, capsys):
    """An articulograph file lacking some of the eight pellets: ``all`` is the share of
    frames with the pellets it tracks (90 %, not 0), and says which it never tracks; the
    dataset table's ``all%`` is the same figure, with a line saying what it is."""
    ema = _one_jaw_sensor_ema(dataset / "fsew0_001.ema")
    assert main(["info", str(ema)]) == 0
    out = capsys.readouterr().out
    assert "  all       90.0 (of the 5 pellets tracked; never tracked: T2, T4, MNM)\n" in out
    assert main(["info", str(ema), "--json"]) == 0
    q = json.loads(capsys.readouterr().out)["quality"]
    assert q["all_valid_fraction"] == pytest.approx(0.9)
    assert q["never_tracked"] == ["T2", "T4", "MNM"]
    assert main(["info", str(dataset)]) == 0
    out = capsys.readouterr().out
    assert next(line for line in out.splitlines() if "001" in line).split()[:6] == [
        "FSEW0", "001", "20", "0.04", "0", "90.0"]
    row = next(line for line in out.splitlines() if "tp020_2" in line).split()
    assert row == ["S01", "tp020_2", "7", "0.04", "3", "42.9", "42.61", "0.003", "0"]
    assert ("  all%: of the pellets each file tracks; 1 of 4 recording(s) never track some "
            "(T2, T4, MNM)") in out
