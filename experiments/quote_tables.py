"""Copy the generated tables into the documents that quote them, byte for byte.

    python experiments/quote_tables.py [--check] [FILE ...]

A document quotes a generated table with a marker line directly above it:

    <!-- quoted from docs/generated/NAME.md, table K -->

(K counts the Markdown tables of that file from 1). This script replaces the table below
each marker by the current table K of NAME.md (or inserts it, if the marker is followed by
no table), in README.md and docs/*.md unless FILEs are given. A figure in prose is quoted
inline, between two markers:

    <!-- quoted from docs/generated/NAME.md, table K, row R, column C[, number N] -->0.68<!-- end quote -->

R is a data row's number (from 1, below the header) or, in double quotes, the text of its
first cell; C a column's number (from 1); with ``number N`` the N-th number in that cell
(``0.68`` of ``0.68 [0.49, 0.93]``), else the whole cell. The text between the markers is
replaced by that value. ``make experiments`` and
``make bench`` run it after the scripts that write docs/generated/, so a quoted figure
cannot go stale; tests/test_docs_tables.py checks the result. ``--check`` changes nothing
and exits 1 if a quoted table differs from its source. A marker naming a missing file or
table is an error naming the document and line.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARKER = re.compile(r"^<!-- quoted from (docs/generated/[\w.-]+\.md), table (\d+) -->$")
INLINE = re.compile(r"<!-- quoted from (docs/generated/[\w.-]+\.md), table (\d+), "
                    r"row (\d+|\"[^\"]+\"), column (\d+)(?:, number (\d+))? -->(.*?)"
                    r"<!-- end quote -->")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def tables(text: str) -> list[list[str]]:
    """The Markdown tables of ``text``: runs of consecutive lines starting with '|'."""
    out, block = [], []
    for line in [*text.splitlines(), ""]:
        if line.startswith("|"):
            block.append(line)
        elif block:
            out.append(block)
            block = []
    return out


def cells(line: str) -> list[str]:
    """The cells of a Markdown table line, stripped."""
    return [c.strip() for c in line.strip().strip("|").split("|")]


def quoted_value(match: re.Match, where: str, root: Path = ROOT) -> str:
    """The figure an inline marker (:data:`INLINE`) names, from its source table now.
    Raises ``ValueError`` naming ``where`` if the table, row, column or number is missing."""
    name, number, row, column, nth = match.group(1, 2, 3, 4, 5)
    source = root / name
    found = tables(source.read_text(encoding="utf-8")) if source.is_file() else []
    if not 1 <= int(number) <= len(found):
        raise ValueError(f"{where}: {name} has no table {number}")
    data = [cells(line) for line in found[int(number) - 1][2:]]
    if row.startswith('"'):
        rows = [r for r in data if r[0] == row[1:-1]]
    else:
        rows = data[int(row) - 1:int(row)] if int(row) >= 1 else []
    if len(rows) != 1 or not 1 <= int(column) <= len(rows[0]):
        raise ValueError(f"{where}: {name} table {number} has no one row {row} with a "
                         f"column {column}")
    cell = rows[0][int(column) - 1]
    if nth is None:
        return cell
    numbers = NUMBER.findall(cell)
    if not 1 <= int(nth) <= len(numbers):
        raise ValueError(f"{where}: {name} table {number} row {row} column {column} "
                         f"({cell!r}) has no number {nth}")
    return numbers[int(nth) - 1]


def requote_inline(text: str, where: str, root: Path = ROOT) -> str:
    """``text`` with the figure between every pair of inline markers made current."""
    out = []
    for k, line in enumerate(text.split("\n"), 1):
        out.append(INLINE.sub(lambda m, k=k: m.group(0).replace(
            "-->" + m.group(6) + "<!--", "-->" + quoted_value(m, f"{where}:{k}", root) + "<!--",
            1), line))
    return "\n".join(out)


def requote(text: str, where: str, root: Path = ROOT) -> str:
    """``text`` with the table under every marker replaced by its source's; ``where`` names
    the document in errors. Raises ``ValueError`` for a marker without a source table."""
    lines = text.splitlines()
    out, k = [], 0
    while k < len(lines):
        out.append(lines[k])
        match = MARKER.match(lines[k])
        k += 1
        if not match:
            continue
        source, number = root / match.group(1), int(match.group(2))
        found = tables(source.read_text(encoding="utf-8")) if source.is_file() else []
        if not 1 <= number <= len(found):
            raise ValueError(f"{where}:{k}: {match.group(1)} has no table {number}")
        out += found[number - 1]
        while k < len(lines) and lines[k].startswith("|"):
            k += 1  # the old copy
    return requote_inline("\n".join(out) + ("\n" if text.endswith("\n") else ""), where, root)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", help="documents (default README.md, docs/*.md)")
    parser.add_argument("--check", action="store_true", help="only report stale copies")
    args = parser.parse_args(argv)
    files = [Path(f) for f in args.files] or [ROOT / "README.md",
                                              *sorted((ROOT / "docs").glob("*.md"))]
    stale = []
    for path in files:
        text = path.read_text(encoding="utf-8")
        try:
            new = requote(text, str(path))
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        if new != text:
            stale.append(path)
            if not args.check:
                path.write_text(new, encoding="utf-8")
    verb = "stale" if args.check else "updated"
    for path in stale:
        print(f"{verb}: {path}")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
