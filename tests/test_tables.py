"""The one table writer (cassi_fit.tables): cells, CSV, Markdown, Parquet, atomicity."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from cassi_fit.errors import OutputExistsError
from cassi_fit.tables import cell, csv_text, markdown_text, table_columns, write_table

ROWS = [
    {"task": "tp005", "subject": "JW11", "theta_deg": 1.5, "ok": True, "n": np.int64(3)},
    {"subject": "JW11", "task": "tp006", "theta_deg": float("nan"), "ok": False, "n": 4,
     "note": 'a, "quoted" | piped'},
]


def test_cells_are_printed_one_way():
    assert cell(None) == ""
    assert cell(True) == "true" and cell(np.bool_(False)) == "false"
    assert cell(np.float32(0.5)) == "0.500000"
    assert cell(1.23456789, digits=2) == "1.23"
    assert cell(float("-inf")) == "-inf" and cell(np.nan) == "nan"
    assert cell(np.int64(7)) == "7" and cell("x") == "x"


def test_columns_put_the_identifiers_first_then_first_seen_order():
    assert table_columns(ROWS) == ["subject", "task", "theta_deg", "ok", "n", "note"]


def test_csv_round_trips_through_the_csv_module():
    text = csv_text(ROWS, digits={"theta_deg": 3})
    back = list(csv.DictReader(io.StringIO(text)))
    assert back[0]["theta_deg"] == "1.500" and back[1]["theta_deg"] == "nan"
    assert back[1]["note"] == 'a, "quoted" | piped'
    assert back[0]["note"] == ""  # a missing cell is empty


def test_markdown_escapes_pipes_and_renames_headers():
    text = markdown_text(ROWS, ["subject", "theta_deg", "note"], headers={"theta_deg": "θ (deg)"})
    lines = text.splitlines()
    assert lines[0] == "| subject | θ (deg) | note |"
    assert lines[1] == "|---|---|---|"
    assert lines[2] == "| JW11 | 1.50 |  |"
    assert "\\|" in lines[3]


def test_write_table_is_atomic_and_keeps_existing_files(tmp_path):
    out = tmp_path / "t.csv"
    written = write_table(ROWS, out, markdown="# Title")
    assert written == [out, tmp_path / "t.md"]
    assert (tmp_path / "t.md").read_text().startswith("# Title\n\n| subject |")
    with pytest.raises(OutputExistsError):
        write_table(ROWS, out)
    write_table(ROWS[:1], out, overwrite=True)
    assert out.read_text().count("\n") == 2
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_markdown_only(tmp_path):
    (path,) = write_table(ROWS, tmp_path / "only.md", markdown="Title")
    assert path.suffix == ".md" and not (tmp_path / "only.csv").exists()


def test_parquet_keeps_the_values(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    written = write_table(ROWS, tmp_path / "t.csv", parquet=True)
    table = pq.read_table(written[-1]).to_pylist()
    assert table[0]["theta_deg"] == 1.5 and table[1]["n"] == 4
