"""No table of numbers in README.md or docs/*.md can go stale (issue 11, point 7).

Every Markdown table there (consecutive lines starting with ``|``) either appears byte for
byte in a file of docs/generated/ (written by ``make experiments`` or ``make bench``, each
file's first line naming the command that wrote it), or has no digit at all, or is one of
the few *specification* tables listed in ``SPECIFICATIONS`` (inputs of the code, such as
thresholds and equation numbers, not measurements), each with the reason; where such a
table quotes a code constant with its value, the value is checked against the code.
"""

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GENERATED = ROOT / "docs" / "generated"
sys.path.insert(0, str(ROOT / "experiments"))
import quote_tables  # noqa: E402

#: (document, the table's header line) -> why it may hold digits without being generated.
SPECIFICATIONS = {
    ("docs/ARCHITECTURE.md", "| layer | module | what lives there |"):
        "layer numbers of the architecture, not measurements",
    ("docs/CALIBRATION.md", "| unknown (model units) | residuals (model mm) | source |"):
        "the fit's unknowns, with the paper's parameter and equation numbers",
    ("docs/EVALUATION.md", "| problems | rating |"):
        "CASSI's rating rule (number of problems -> rating)",
    ("docs/EVALUATION.md", "| problem | measure | threshold | counts | why |"):
        "thresholds: code constants, checked against cassi_fit.evaluate below",
    ("docs/EVALUATION.md", "| item | measure | threshold | why |"):
        "thresholds: code constants, checked against cassi_fit.evaluate below",
    ("docs/FORMATS.md", "| field | content |"): "file-format fields",
    ("docs/FORMATS.md", "| column | meaning (mm) | default |"):
        "Headmeasures columns and their documented defaults",
    ("docs/PIPELINE.md", "| step | paper | here |"): "the paper's steps and equation numbers",
    ("docs/PIPELINE.md", "| status | label | meaning |"): "status codes (cassi_fit.status)",
    ("docs/SYNTHETIC.md", "| task | kind | what | audio |"): "the synthetic tasks' names",
    ("docs/SYNTHETIC.md", "| quantity (`NORMS` key) | mean, SD | source |"):
        "the generator's input norms (synth.NORMS), with their sources",
    ("docs/SYNTHETIC.md", "| family | condyle offset `d_t` | what it tests | source |"):
        "the jaw-kinematics families' definitions",
    ("docs/SYNTHETIC.md", "| column | meaning |"): "truth-file columns",
    ("docs/CASSI_MODE.md", "| Choice | The paper | CASSI mode | Improved mode |"):
        "the CASSI mode's choices against the paper's sections (percentages are the paper's)",
    ("docs/CASSI_MODE.md", "| Landmark | Soft tissue | Source |"):
        "soft-tissue thickness inputs (headmeasures.SOFT_TISSUE_THICKNESS_MM), with sources",
    ("docs/FORMATS.md", "| input | result |"): "what each kind of bad input gives (behaviour)",
    ("docs/FORMATS.md", "| check | why | catches |"):
        "the plausibility checks' definitions and bounds (code constants)",
    ("docs/FORMATS.md", "| column | range | basis |"):
        "Headmeasures plausible ranges (headmeasures.PLAUSIBLE_RANGES), with their basis",
}


tables = quote_tables.tables  # the Markdown tables of a text, as the quoting script sees them


def documents() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def generated_text() -> str:
    """All generated files, concatenated, each line-terminated (for line-aligned search)."""
    return "".join("\n" + p.read_text(encoding="utf-8") for p in sorted(GENERATED.glob("*.md")))


def stale_tables(docs=None, generated=None) -> list[str]:
    """``document:line: header`` of every table that is neither generated, digit-free nor a
    listed specification."""
    generated = generated_text() if generated is None else generated
    bad = []
    for doc in documents() if docs is None else docs:
        text = doc.read_text(encoding="utf-8")
        lines = text.splitlines()
        start = 0
        for block in tables(text):
            start = lines.index(block[0], start)
            name = doc.relative_to(ROOT).as_posix() if doc.is_relative_to(ROOT) else doc.name
            quoted = "\n" + "\n".join(block) + "\n" in generated
            if quoted or not re.search(r"\d", "\n".join(block)):
                start += len(block)
                continue
            if (name, block[0]) not in SPECIFICATIONS:
                bad.append(f"{name}:{start + 1}: {block[0]}")
            start += len(block)
    return bad


def test_every_table_of_numbers_is_generated_or_a_listed_specification():
    bad = stale_tables()
    assert not bad, ("tables of numbers neither copied byte for byte from docs/generated/ "
                     "(make experiments / make bench) nor listed specifications:\n"
                     + "\n".join(bad))


def test_the_check_catches_a_changed_figure_and_passes_a_quoted_one(tmp_path):
    quoted = "| a | b |\n|---|---|\n| x | 1.5 |\n"
    doc = tmp_path / "doc.md"
    doc.write_text("text\n\n" + quoted + "\nmore\n")
    assert stale_tables([doc], "\n# gen\n\n" + quoted) == []
    # one digit changed, a row left out, or a table with no generated source: flagged
    for generated in ("\n" + quoted.replace("1.5", "1.6"), "\n| a | b |\n|---|---|\n", ""):
        assert stale_tables([doc], generated) == ["doc.md:3: | a | b |"]
    # a table without digits needs no source
    doc.write_text("| a | b |\n|---|---|\n| x | y |\n")
    assert stale_tables([doc], "") == []


def test_every_marked_quote_is_its_source_table_now():
    # `make experiments` / `make bench` end with experiments/quote_tables.py, which copies
    # the table under each "<!-- quoted from docs/generated/X.md, table K -->" marker
    marked = 0
    for doc in documents():
        text = doc.read_text(encoding="utf-8")
        marked += len(re.findall(quote_tables.MARKER.pattern, text, re.M))
        assert quote_tables.requote(text, doc.name) == text, f"{doc.name}: run make experiments"
    assert marked >= 8


def test_requote_replaces_a_stale_copy_and_names_a_missing_source(tmp_path):
    gen = tmp_path / "docs" / "generated"
    gen.mkdir(parents=True)
    (gen / "t.md").write_text("<!-- written by x -->\n| a |\n|---|\n| 1 |\n\n| b |\n|---|\n| 2 |\n")
    doc = "x\n<!-- quoted from docs/generated/t.md, table 2 -->\n| b |\n|---|\n| 9 |\n\ny\n"
    assert quote_tables.requote(doc, "doc.md", tmp_path) == doc.replace("9", "2")
    new = "<!-- quoted from docs/generated/t.md, table 1 -->\n\nz\n"
    assert quote_tables.requote(new, "doc.md", tmp_path) == new.replace("\n\n", "\n| a |\n|---|\n| 1 |\n\n")
    with pytest.raises(ValueError, match="doc.md:1: docs/generated/t.md has no table 3"):
        quote_tables.requote("<!-- quoted from docs/generated/t.md, table 3 -->\n", "doc.md", tmp_path)


def test_every_listed_specification_still_exists():
    # a stale entry would silently let a future table with that header through
    present = set()
    for doc in documents():
        name = doc.relative_to(ROOT).as_posix()
        present |= {(name, block[0]) for block in tables(doc.read_text(encoding="utf-8"))}
    assert set(SPECIFICATIONS) <= present, sorted(set(SPECIFICATIONS) - present)


def test_every_generated_file_names_the_command_that_wrote_it():
    files = sorted(GENERATED.glob("*.md"))
    assert files
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    for path in files:
        first = path.read_text(encoding="utf-8").splitlines()[0]
        match = re.match(r"<!-- written by `?(?:python )?((?:experiments|benchmarks)/\w+\.py)",
                         first)
        assert match, (path.name, first)
        assert (ROOT / match.group(1)).is_file(), (path.name, match.group(1))
        # and `make experiments` or `make bench` runs that script
        assert f"$(BIN)/python {match.group(1)}" in makefile, (path.name, match.group(1))


def test_quoted_thresholds_are_the_code_constants():
    import cassi_fit.evaluate as ev

    text = (ROOT / "docs" / "EVALUATION.md").read_text(encoding="utf-8")
    quoted = re.findall(r"`([A-Z][A-Z_]+)` (-?\d+(?:\.\d+)?)", text)
    assert len(quoted) >= 10
    for name, value in quoted:
        assert getattr(ev, name) == pytest.approx(float(value)), name


def test_every_figure_quoted_inline_is_its_source_cell_now():
    # figures in prose sit between "<!-- quoted from docs/generated/X.md, table K, row R,
    # column C, number N -->" and "<!-- end quote -->"; quote_tables.py rewrites them
    inline = 0
    for doc in documents():
        text = doc.read_text(encoding="utf-8")
        inline += len(quote_tables.INLINE.findall(text))
        assert quote_tables.requote_inline(text, doc.name) == text, f"{doc.name}: make experiments"
        assert text.count("<!-- end quote -->") == len(quote_tables.INLINE.findall(text)), doc.name
    assert inline >= 20  # the single-sensor figures of README, JAW, EMA and ONE_SENSOR


def test_an_inline_quote_takes_its_cell_and_names_what_is_missing(tmp_path):
    gen = tmp_path / "docs" / "generated"
    gen.mkdir(parents=True)
    (gen / "t.md").write_text("<!-- written by x -->\n| m | median [CI] |\n|---|---|\n"
                              "| a | 0.68 [0.49, 0.93] |\n| b | 1.5 |\n")
    mark = "<!-- quoted from docs/generated/t.md, table 1, row {}, column 2{} -->{}<!-- end quote -->"
    doc = "x " + mark.format('"a"', ", number 1", "9.9") + " mm, " + mark.format(2, "", "?") + "\n"
    want = "x " + mark.format('"a"', ", number 1", "0.68") + " mm, " + mark.format(2, "", "1.5") + "\n"
    assert quote_tables.requote(doc, "doc.md", tmp_path) == want
    assert quote_tables.requote(want, "doc.md", tmp_path) == want
    for row, number, message in (('"c"', "", "no one row"), ('"a"', ", number 4", "no number 4")):
        with pytest.raises(ValueError, match=f"doc.md:1: .*{message}"):
            quote_tables.requote(mark.format(row, number, "") + "\n", "doc.md", tmp_path)
