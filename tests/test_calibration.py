"""The calibration record and its file (cassi_fit.calibration): validated like any input.

Every case is a hand-written JSON file: one plausible calibration (``GOOD``) and, for each
hostile case of issue 24 and a few more, that file with one entry broken. Each must end
in one line naming the file, the line of the entry and the entry; files a text editor
writes in other encodings read the same; a file that records a failed fit warns. No
calibration is run here (tests/test_calibrate.py runs them).
"""

from __future__ import annotations

import codecs
import copy
import json
import math
import os
import re
import warnings
from types import SimpleNamespace

import pytest

from cassi_fit import calibration
from cassi_fit.calibration import (
    Calibration,
    CalibrationWarning,
    calibration_path,
    load_calibrations,
    read_calibration,
    write_calibration,
)
from cassi_fit.cli import main as cli
from cassi_fit.errors import CassiError, DataFormatError, MissingDataError

#: A plausible calibration file, written out by hand (subject mm unless "model"); its
#: face and mouth width agree with its params (params x the model's own / scale).
GOOD = {
    "subject": "S01",
    "method": "separate",
    "scale": 1.05,
    "upper_lip_thickness": 14.2,
    "lower_lip_thickness": 17.7,
    "face_width": 131.5565 * 1.02 / 1.05,
    "mouth_width": 48.913 * 0.98 / 1.05,
    "nose_protrusion": 20.5,
    "gonion": [-86.0, -36.0],
    "gnathion": [-4.5, -50.0],
    "params": {
        "upper_lip_thickness": -0.3,
        "lower_lip_thickness": 2.1,
        "face_width": 1.02,
        "mouth_width": 0.98,
        "nose_tip": [1.5, 0.0],
        "jaw_shape_theta": 0.02,
        "jaw_shape_translation": [0.1, -0.05],
        "jaw_shape_scale": [1.1, 1.05],
    },
    "lip_rest_offset": [1.2, -0.8],
    "residuals": {"upper_lip": 0.1, "lower_lip": 0.2, "gonion": 2.0, "gnathion": 3.5},
    "observed": {"upper_lip_thickness": [14.1, 14.3, None],
                 "lower_lip_thickness": [17.6, 17.8, 17.7]},
    "recordings": ["tp106", "tp040", "tp020_2"],
    "first_lines": [12, 9, 30],
    "head_is_default": False,
    "collisions": True,
    "converged": True,
    "format": "cassi_fit calibration 2",
    "bounds_hit": [],
    "unconverged": [],
    "lower_lip_bias": [-0.8, 1.8],
}


def _write(tmp_path, data, name="S01.calibration.json", encoding="utf-8", bom=b""):
    path = tmp_path / name
    path.write_bytes(bom + json.dumps(data, indent=1).encode(encoding))
    return path


def _changed(change):
    data = copy.deepcopy(GOOD)
    change(data)
    return data


def _line_of(path, needle):
    """1-based line of the first line of ``path`` (UTF-8) containing ``needle``."""
    for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if needle in line:
            return i
    raise AssertionError(needle)


def test_a_plausible_file_reads_and_round_trips(tmp_path):
    cal = read_calibration(_write(tmp_path, GOOD))
    assert isinstance(cal, Calibration)
    assert cal.scale == 1.05 and cal.params["jaw_shape_scale"] == [1.1, 1.05]
    assert cal.recordings == ("tp106", "tp040", "tp020_2") and cal.first_lines == (12, 9, 30)
    assert cal.problems() == []
    again = write_calibration(tmp_path / "again" / "S01.calibration.json", cal)
    assert read_calibration(again) == cal
    assert json.loads(again.read_text(encoding="utf-8")) == json.loads(cal.to_json())


# (change to GOOD, the entry the message names, the key whose line it gives (None: no
# line), what it says)
HOSTILE = {
    "missing parameter": (lambda d: d["params"].pop("jaw_shape_scale"), "params", '"params"',
                          "missing parameter jaw_shape_scale"),
    "missing entry": (lambda d: d.pop("lip_rest_offset"), "", None, "missing lip_rest_offset"),
    "scale as a string": (lambda d: d.update(scale="1.05"), "scale", '"scale"',
                          r'expected a number, got a string \("1.05"\)'),
    "scale of 1000": (lambda d: d.update(scale=1000), "scale", '"scale"',
                      "1000 is outside the plausible range 0.5 to 2"),
    "scale true": (lambda d: d.update(scale=True), "scale", '"scale"',
                   "expected a number, got true/false"),
    "face width of 1e6 mm": (lambda d: d.update(face_width=1e6), "face_width", '"face_width"',
                             r"1e\+06 is outside the plausible range 100 to 175 \(mm\)"),
    "mouth width of -3": (lambda d: d.update(mouth_width=-3), "mouth_width", '"mouth_width"',
                          "-3 is outside the plausible range 30 to 80"),
    "drawn face width of 1000": (lambda d: d["params"].update(face_width=1000),
                                 "params.face_width", '"face_width": 1000',
                                 "1000 is outside the plausible range"),
    "drawn mouth width of -3": (lambda d: d["params"].update(mouth_width=-3),
                                "params.mouth_width", '"mouth_width": -3',
                                "-3 is outside the plausible range"),
    "jaw beyond its bound": (lambda d: d["params"].update(jaw_shape_scale=[1.1, 1.55]),
                             "params.jaw_shape_scale.1", "1.55",
                             "1.55 is outside the plausible range 0.7692 to 1.3"),
    "jaw scale of one number": (lambda d: d["params"].update(jaw_shape_scale=[1.0]),
                                "params.jaw_shape_scale", '"jaw_shape_scale"',
                                "expected a list of 2 numbers"),
    "not a number": (lambda d: d.update(upper_lip_thickness=float("nan")),
                     "upper_lip_thickness", '"upper_lip_thickness"', "not a finite number"),
    "a flag as a word": (lambda d: d.update(converged="yes"), "converged", '"converged"',
                         'expected true or false, got "yes"'),
    "a misspelt entry": (lambda d: d.update(sclae=1.0), "sclae", '"sclae"',
                         "unknown field \\(did you mean 'scale'\\?\\)"),
    "an unknown parameter": (lambda d: d["params"].update(jaw_shape_sclae=1.0),
                             "params.jaw_shape_sclae", '"jaw_shape_sclae"', "unknown field"),
    "an unknown bound": (lambda d: d.update(bounds_hit=["jaw_wider"]), "bounds_hit",
                         '"bounds_hit"', "unknown name 'jaw_wider'"),
    "a method of its own": (lambda d: d.update(method="both"), "method", '"method"',
                            "expected one of separate, joint"),
    "a subject that is a path": (lambda d: d.update(subject="../S01"), "subject", '"subject"',
                                 "expected a subject name"),
    "line numbers from 0": (lambda d: d.update(first_lines=[0, 9, 30]), "first_lines",
                            '"first_lines"', "line numbers"),
    "lines for other recordings": (lambda d: d.update(first_lines=[12]), "first_lines",
                                   '"first_lines"', "1 line numbers for 3 recordings"),
    "converged yet unconverged": (lambda d: d.update(unconverged=["lips"]), "converged",
                                  '"converged"', "disagrees with unconverged"),
    "face width edited alone": (lambda d: d.update(face_width=140.0), "face_width",
                                '"face_width"', "disagrees with params.face_width"),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_each_hostile_file_gets_one_line_naming_file_line_and_entry(tmp_path, case):
    change, entry, key, said = HOSTILE[case]
    path = _write(tmp_path, _changed(change))
    with pytest.raises(DataFormatError) as info:
        read_calibration(path)
    message = str(info.value)
    assert "\n" not in message
    line = f":{_line_of(path, key)}" if key else ""
    prefix = f"{re.escape(str(path))}{line}: " + (f"{re.escape(entry)}: " if entry else "")
    assert re.match(prefix, message) and re.search(said, message), message
    assert info.value.path == str(path)


def test_other_formats_and_other_documents_are_refused(tmp_path):
    with pytest.raises(DataFormatError, match=r"S01.calibration.json: not a calibration file"):
        read_calibration(_write(tmp_path, [1, 2, 3]))
    other = _changed(lambda d: d.update(format="cassi_fit calibration 9"))
    with pytest.raises(DataFormatError, match='found "cassi_fit calibration 9"'):
        read_calibration(_write(tmp_path, other))
    broken = tmp_path / "S02.calibration.json"
    broken.write_text('{"format": "cassi_fit calibration 2",\n "scale": }\n', encoding="utf-8")
    with pytest.raises(DataFormatError, match=r"S02.calibration.json:2: invalid JSON"):
        read_calibration(broken)
    with pytest.raises(MissingDataError, match="calibration file not found"):
        read_calibration(tmp_path / "S03.calibration.json")


def test_a_file_of_the_first_format_reads_with_the_later_entries_defaulted(tmp_path):
    old = {k: v for k, v in GOOD.items() if k in ("subject", "method", "scale", "params",
                                                  "upper_lip_thickness", "face_width",
                                                  "lower_lip_thickness")}
    old["format"] = "cassi_fit calibration 1"
    cal = read_calibration(_write(tmp_path, old))
    assert cal.converged and cal.unconverged == () and cal.lower_lip_bias == ()
    assert math.isnan(cal.mouth_width) and cal.lip_rest_offset == (0.0, 0.0)
    # format 2 requires them
    newer = {**old, "format": "cassi_fit calibration 2"}
    with pytest.raises(DataFormatError, match="missing mouth_width, nose_protrusion"):
        read_calibration(_write(tmp_path, newer))


@pytest.mark.parametrize("encoding, bom", [
    ("utf-8", codecs.BOM_UTF8), ("utf-16-le", codecs.BOM_UTF16_LE),
    ("utf-16-be", codecs.BOM_UTF16_BE)])
def test_any_encoding_a_text_editor_writes_reads_the_same(tmp_path, encoding, bom):
    plain = read_calibration(_write(tmp_path, GOOD))
    other = tmp_path / "other"
    other.mkdir()
    assert read_calibration(_write(other, GOOD, encoding=encoding, bom=bom)) == plain


def test_text_that_is_not_utf8_or_marked_utf16_gets_one_line(tmp_path):
    no_mark = _write(tmp_path, GOOD, encoding="utf-16-le")
    with pytest.raises(DataFormatError, match=r"S01.calibration.json:1: a NUL character: "
                                              r"UTF-16 without a byte-order mark"):
        read_calibration(no_mark)
    latin = tmp_path / "S02.calibration.json"
    text = json.dumps(_changed(lambda d: d.update(subject="S\u00d6")), indent=1,
                      ensure_ascii=False)
    latin.write_bytes(text.encode("latin-1"))
    line = text.splitlines().index(' "subject": "S\u00d6",') + 1
    with pytest.raises(DataFormatError, match=rf"S02.calibration.json:{line}: not a text file in "
                                              r"UTF-8.*byte 0xd6"):
        read_calibration(latin)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_a_fifo_named_like_a_calibration_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "S01.calibration.json"
    os.mkfifo(fifo)
    with pytest.raises(DataFormatError, match="not a regular file \\(a pipe, device or socket"):
        read_calibration(fifo)


def test_the_lines_of_the_entries_are_found_in_nested_json():
    text = '{\n "a": [\n  1,\n  [2,\n   3]\n ],\n "b": {"c":\n  "x\\"y"}, "d": 4\n}'
    lines = calibration._key_lines(text)
    assert lines[("a",)] == 2 and lines[("a", 0)] == 3 and lines[("a", 1)] == 4
    assert lines[("a", 1, 1)] == 5 and lines[("b",)] == 7 and lines[("b", "c")] == 7
    assert lines[("d",)] == 8


def _failed():
    return _changed(lambda d: d.update(converged=False, unconverged=["jaw_shape"],
                                       bounds_hit=["jaw_scale_x"],
                                       params={**GOOD["params"], "jaw_shape_scale": [1.3, 1.1]}))


def test_a_file_that_records_a_failed_fit_warns_naming_the_file(tmp_path):
    path = _write(tmp_path, _failed(), name="S09.calibration.json")
    with pytest.warns(CalibrationWarning) as caught:
        cal = read_calibration(path)
    said = [str(w.message) for w in caught]
    assert len(said) == 2 and all(s.startswith(f"{path}: S01: ") for s in said)
    assert "did not converge (stage jaw_shape)" in said[0]
    assert "anatomical bound (jaw_scale_x 1.300; bounds 0.769..1.300" in said[1]
    assert cal.problems() == [s.removeprefix(f"{path}: ") for s in said]
    with warnings.catch_warnings():
        warnings.simplefilter("error", CalibrationWarning)
        assert read_calibration(path, warn=False) == cal
        assert read_calibration(_write(tmp_path, GOOD)).problems() == []


def test_an_implausible_calibration_is_a_problem_and_is_not_written(tmp_path):
    from dataclasses import replace

    bad = replace(calibration.validate(GOOD), upper_lip_thickness=-4.0)
    assert bad.problems() == ["S01: implausible calibration, upper_lip_thickness: -4 is "
                              "outside the plausible range 2 to 35 (mm)"]
    target = tmp_path / "S01.calibration.json"
    with pytest.raises(CassiError, match=r"S01.calibration.json: not written, the calibration "
                                         "of S01 is implausible: upper_lip_thickness: -4"):
        write_calibration(target, bad)
    assert not target.exists()


def test_caveats_give_the_lower_lips_possible_bias_with_its_size(tmp_path):
    cal = read_calibration(_write(tmp_path, GOOD))
    (lower,) = cal.caveats()
    # 17.7 mm estimated, possibly 1.8 mm too thick (10 %) or 0.8 mm too thin (5 %)
    assert lower == ("S01: lower lip thickness 17.7 mm: no pellet sees the lower incisor tip, "
                     "so it may be up to 1.8 mm (10 %) too thick or 0.8 mm (5 %) too thin "
                     "(95 % range of the dental norms)")
    (tmp_path / "d").mkdir()
    default_head = read_calibration(_write(tmp_path / "d", _changed(
        lambda d: d.update(head_is_default=True, lower_lip_bias=[0.5, 2.0]))))
    assert "0.0 mm (0 %) too thin" in default_head.caveats()[0]
    assert "no Headmeasures" in default_head.caveats()[1]


def test_a_folder_with_two_calibrations_of_one_subject_is_refused(tmp_path):
    _write(tmp_path, GOOD)
    _write(tmp_path, GOOD, name="copy.calibration.json")
    with pytest.raises(DataFormatError, match="copy.calibration.json: a second calibration of "
                                              "subject S01"):
        load_calibrations(tmp_path)
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingDataError, match="no \\*.calibration.json"):
        load_calibrations(tmp_path / "empty")


def test_calibration_path_names_the_subject_in_capitals(tmp_path):
    assert calibration_path(tmp_path, "s01").name == "S01.calibration.json"


def test_the_documented_schema_is_the_codes():
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "experiments"))
    import calibration_limits

    documented = (root / "docs" / "generated" / "calibration_schema.md").read_text(
        encoding="utf-8")
    assert calibration_limits.schema_markdown() == documented


# ---- the command line: cassi calibrate's exit status -------------------------------------


def _fake_corpus_run(monkeypatch, tmp_path, cals):
    """``cassi calibrate`` with ``calibrate_corpus`` replaced by one returning ``cals``
    (its exit status and printing are what is tested, not the fit)."""
    import importlib

    module = importlib.import_module("cassi_fit.calibrate_corpus")  # the name is a function too
    run = SimpleNamespace(workers=1, resumed=0, results=[], failure_summary=lambda: "")
    monkeypatch.setattr(module, "calibrate_corpus", lambda *a, **k: (run, [], cals))
    (tmp_path / "data").mkdir()
    return ["calibrate", str(tmp_path / "data"), "--out", str(tmp_path / "out"),
            "--subjects", ",".join(cals), "--quiet"]


def test_cli_calibrate_exits_3_on_a_failed_fit_unless_accepted(tmp_path, monkeypatch, capsys):
    failed = calibration.validate(_failed())
    args = _fake_corpus_run(monkeypatch, tmp_path, {"S01": failed})
    assert cli(args) == 3
    out, err = capsys.readouterr()
    assert "NOT CONVERGED  AT BOUND (jaw_scale_x)" in out and "-0.8..+1.8" in out
    lines = err.strip().splitlines()
    assert lines[0].startswith("cassi: S01: the calibration did not converge")
    assert lines[1].startswith("cassi: S01: the jaw shape reached its anatomical bound")
    assert lines[2] == ("cassi: 2 problem(s) in the calibrations (recorded in their files); "
                        "pass --accept-unconverged to accept them")
    assert cli([*args, "--accept-unconverged"]) == 0
    err = capsys.readouterr().err
    assert "did not converge" in err and "--accept-unconverged" not in err


def test_cli_calibrate_exits_0_when_every_fit_is_fine(tmp_path, monkeypatch, capsys):
    args = _fake_corpus_run(monkeypatch, tmp_path, {"S01": calibration.validate(GOOD)})
    assert cli(args) == 0
    assert capsys.readouterr().err == ""
