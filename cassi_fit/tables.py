"""Tables: the one writer every table of the toolkit goes through (CSV, Markdown, Parquet).

A table is a sequence of rows, each a mapping from column name to a cell (a number, a
string, a bool, or None). :func:`write_table` writes it atomically (``_io.atomic_write``:
no partial file, inputs never replaced, existing files kept unless ``overwrite``) as CSV,
and on request as a Markdown table and as Parquet beside it; :func:`csv_text` and
:func:`markdown_text` give the text alone. Cells are printed one way everywhere
(:func:`cell`): floats with a fixed number of decimals (``digits``, default
:data:`FLOAT_DIGITS`), ``nan`` for NaN, booleans as ``true``/``false``, None as an empty
cell. So a table is byte-identical whatever computed it (one process or many, any order of
completion). numpy only through the values it is given; pyarrow only for Parquet.
"""

from __future__ import annotations

import csv
import io
import math
import numbers
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from ._io import atomic_write

#: Decimals written for floats by default: a micrometre, a micro-degree, a microsecond.
FLOAT_DIGITS = 6
#: Columns that come first when a table's columns are taken from its rows.
ID_COLUMNS = ("subject", "task", "status", "error")

Row = Mapping[str, object]


def blank_if_nan(value: object) -> object:
    """None (a blank cell: nothing was measured or predicted) for a NaN number, else the
    value as it is; :func:`cell` itself spells NaN out."""
    return None if isinstance(value, numbers.Real) and math.isnan(value) else value


def cell(value: object, digits: int = FLOAT_DIGITS) -> str:
    """One cell as text: None -> ``""``, bools -> ``true``/``false``, floats (numpy's
    too) with ``digits`` decimals (``nan``, ``inf``, ``-inf`` spelled out), integers and
    strings as they are."""
    if type(value) is float:  # the common case first: Python's format spells nan/inf too
        return f"{value:.{digits}f}"
    if type(value) is int:
        return str(value)
    if value is None:
        return ""
    if isinstance(value, bool) or type(value).__name__ in ("bool", "bool_"):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        v = float(value)
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:.{digits}f}"
    return str(value)


def table_columns(rows: Sequence[Row]) -> list[str]:
    """``ID_COLUMNS`` first (those present), then the others in first-seen order."""
    seen = dict.fromkeys(c for c in ID_COLUMNS if any(c in r for r in rows))
    for row in rows:
        seen.update(dict.fromkeys(row))
    return list(seen)


def _columns(rows: Sequence[Row], columns: Sequence[str] | None) -> list[str]:
    return table_columns(rows) if columns is None else list(columns)


def _digits_of(column: str, digits: int | Mapping[str, int]) -> int:
    if isinstance(digits, Mapping):
        return int(digits.get(column, FLOAT_DIGITS))
    return int(digits)


def csv_text(rows: Sequence[Row], columns: Sequence[str] | None = None, *,
             digits: int | Mapping[str, int] = FLOAT_DIGITS) -> str:
    """The rows as CSV text (``csv`` module quoting, ``\\n`` line ends), a header line of
    ``columns`` (default :func:`table_columns`), missing cells empty. ``digits``: decimals
    for floats, one number or per column (others :data:`FLOAT_DIGITS`)."""
    columns = _columns(rows, columns)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    places = [(c, _digits_of(c, digits)) for c in columns]
    for row in rows:
        writer.writerow([cell(row.get(c), d) for c, d in places])
    return buffer.getvalue()


def _markdown_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_text(rows: Sequence[Row], columns: Sequence[str] | None = None, *,
                  digits: int | Mapping[str, int] = 2,
                  headers: Mapping[str, str] | None = None) -> str:
    """The rows as a GitHub-flavoured Markdown table: a header line (``headers`` may
    rename columns), a rule, one line per row. Floats with ``digits`` decimals (default
    2; one number or per column), ``|`` escaped."""
    columns = _columns(rows, columns)
    names = [(headers or {}).get(c, c) for c in columns]
    lines = ["| " + " | ".join(_markdown_cell(n) for n in names) + " |",
             "|" + "|".join("---" for _ in columns) + "|"]
    for row in rows:
        cells = (cell(row.get(c), _digits_of(c, digits)) for c in columns)
        lines.append("| " + " | ".join(_markdown_cell(t) for t in cells) + " |")
    return "\n".join(lines) + "\n"


def parquet_available() -> bool:
    """Whether pyarrow (the ``corpus`` extra) is importable."""
    try:
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def parquet_bytes(rows: Sequence[Row], columns: Sequence[str] | None = None) -> bytes:
    """The rows as a Parquet file's bytes (pyarrow; values as they are, not as text)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = _columns(rows, columns)
    table = pa.Table.from_pylist([{c: _plain(r.get(c)) for c in columns} for r in rows])
    buffer = io.BytesIO()
    pq.write_table(table, buffer)
    return buffer.getvalue()


def _plain(value: object) -> object:
    """numpy scalars as Python scalars (pyarrow infers column types from them)."""
    item = getattr(value, "item", None)
    return item() if callable(item) and not isinstance(value, (str, bytes)) else value


def write_table(rows: Sequence[Row], path: str | os.PathLike, *,
                columns: Sequence[str] | None = None, overwrite: bool = False,
                digits: int | Mapping[str, int] = FLOAT_DIGITS,
                markdown: bool | str = False, parquet: bool | None = False,
                headers: Mapping[str, str] | None = None) -> list[Path]:
    """Write ``rows`` to ``path`` as CSV (:func:`csv_text`), atomically; returns the paths
    written, the CSV first.

    ``markdown``: also a Markdown table (:func:`markdown_text`) beside it with the suffix
    ``.md`` (``True``), or a title line to put above that table (a string).
    ``parquet``: also ``.parquet`` beside it (``True``), or only when pyarrow is
    importable (``None``). ``path`` may end in ``.md`` alone when only Markdown is wanted:
    then no CSV is written. ``overwrite``: replace existing files (never an input).
    """
    path = Path(path)
    columns = _columns(rows, columns)
    written = []
    if path.suffix.lower() == ".md":
        return [atomic_write(path, _markdown_file(rows, columns, markdown, headers),
                             overwrite=overwrite)]
    written.append(atomic_write(path, csv_text(rows, columns, digits=digits),
                                overwrite=overwrite))
    if markdown:
        written.append(atomic_write(path.with_suffix(".md"),
                                    _markdown_file(rows, columns, markdown, headers),
                                    overwrite=overwrite))
    if parquet_available() if parquet is None else parquet:
        written.append(atomic_write(path.with_suffix(".parquet"), parquet_bytes(rows, columns),
                                    overwrite=overwrite))
    return written


def _markdown_file(rows, columns, title, headers) -> str:
    table = markdown_text(rows, columns, headers=headers)
    return f"{title}\n\n{table}" if isinstance(title, str) and title else table
