"""Headmeasures.txt: fixture, round trip, defaults, every documented bad-input error."""

import dataclasses
from pathlib import Path

import pytest

from cassi_fit.errors import DataFormatError, OutputExistsError
from cassi_fit.headmeasures import (
    DEFAULT_HEAD_MEASURES,
    FIELD_NAMES,
    HeadMeasures,
    read_headmeasures,
    write_headmeasures,
)

FIXTURES = Path(__file__).parent / "fixtures"
HEADER = "subject\t" + "\t".join(FIELD_NAMES)
ROW = "S01\t-85\t-35\t0\t-43\t135\t100\t50\t12\t11\t20"


def test_fixture():
    m = read_headmeasures(FIXTURES / "Headmeasures.txt")
    assert sorted(m) == ["S01", "S02"]  # names upper-cased
    assert m["S01"].gonion_x == -84.5 and m["S02"].nose_protrusion == 21.0


def test_defaults_are_plausible():
    d = DEFAULT_HEAD_MEASURES
    assert len(FIELD_NAMES) == 10
    assert d.gonion_x < -60 and d.gonion_y < 0 and d.gnathion_y < d.gonion_y
    assert d.face_width > d.jaw_width > d.mouth_width > 0


def test_round_trip_and_refusals(tmp_path):
    a = dataclasses.replace(DEFAULT_HEAD_MEASURES, gonion_x=-81.2346, face_width=131.0004)
    p = write_headmeasures(tmp_path / "Headmeasures.txt", {"jw11": a, "S02": DEFAULT_HEAD_MEASURES})
    back = read_headmeasures(p)
    assert back["S02"] == DEFAULT_HEAD_MEASURES
    assert back["JW11"].gonion_x == -81.235 and back["JW11"].face_width == 131.0
    with pytest.raises(OutputExistsError):
        write_headmeasures(p, back, overwrite=True)
    with pytest.raises(DataFormatError, match="repeated"):
        write_headmeasures(tmp_path / "b.txt", {"s1": a, "S1": a})


def test_columns_in_any_order_and_case(tmp_path):
    cols = list(reversed(FIELD_NAMES))
    vals = [str(getattr(DEFAULT_HEAD_MEASURES, c) + 0.5) for c in cols]
    p = tmp_path / "h.txt"
    p.write_text("SUBJECT " + " ".join(c.upper() for c in cols) + "\nx1 " + " ".join(vals) + "\n")
    m = read_headmeasures(p)["X1"]
    assert m.nose_protrusion == pytest.approx(DEFAULT_HEAD_MEASURES.nose_protrusion + 0.5)
    assert m.gonion_x == pytest.approx(DEFAULT_HEAD_MEASURES.gonion_x + 0.5)


@pytest.mark.parametrize(
    "text, line, match",
    [
        ("", None, "empty"),
        ("# only a comment\n", None, "empty"),
        ("name " + " ".join(FIELD_NAMES) + "\n", 1, "subject"),
        (HEADER + " chin_angle\n", 1, "unknown column"),
        (HEADER.replace("\tjaw_width", "") + "\n", 1, "missing column.*jaw_width"),
        (HEADER + " face_width\n", 1, "duplicate"),
        ("#c\n" + HEADER + "\n" + ROW + "\t7\n", 3, "expected 11 fields"),
        (HEADER + "\n" + ROW.replace("135", "wide") + "\n", 2, "face_width: not a number"),
        (HEADER + "\n" + ROW.replace("135", "nan") + "\n", 2, "not a number"),
        (HEADER + "\n" + ROW.replace("135", "-135") + "\n", 2, "positive"),
        (HEADER + "\n" + ROW + "\n\n" + ROW.replace("S01", "s01") + "\n", 4, "twice"),
    ],
)
def test_bad_input(tmp_path, text, line, match):
    p = tmp_path / "Headmeasures.txt"
    p.write_text(text)
    with pytest.raises(DataFormatError, match=match) as info:
        read_headmeasures(p)
    assert info.value.line == line and info.value.path == str(p)


def test_header_only_is_an_empty_table(tmp_path):
    p = tmp_path / "h.txt"
    p.write_text(HEADER + "\r\n")
    assert read_headmeasures(p) == {}
    assert isinstance(DEFAULT_HEAD_MEASURES, HeadMeasures)
