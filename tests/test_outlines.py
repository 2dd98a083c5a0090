"""PAL.DAT / PHA.DAT: fixtures, round trip, bad input with file and line."""

from pathlib import Path

import numpy as np
import pytest

from cassi_fit.errors import DataFormatError, OutputExistsError
from cassi_fit.outlines import read_outline, write_outline

FIXTURES = Path(__file__).parent / "fixtures"


def test_fixtures():
    palate = read_outline(FIXTURES / "PAL.DAT")
    assert palate.shape == (9, 2)
    np.testing.assert_array_equal(palate[0], [-4.123, 4.012])
    np.testing.assert_array_equal(palate[-1], [-60.0, 27.01])
    assert np.all(np.diff(palate[:, 0]) < 0)  # front to back
    pharynx = read_outline(FIXTURES / "PHA.DAT", kind="pharynx")
    assert pharynx.shape == (2, 2)


def test_round_trip_and_format(tmp_path):
    rng = np.random.default_rng(1)  # a random palate: front to back, above the incisor tip
    pts = np.stack([np.sort(rng.uniform(-60, -4, 20))[::-1], rng.uniform(4, 27, 20)], axis=1)
    p = write_outline(tmp_path / "PAL.DAT", pts)
    raw = p.read_bytes()
    assert raw.count(b"\r\n") == 20 and all(s.startswith(b" ") for s in raw.split(b"\r\n")[:-1])
    np.testing.assert_array_equal(read_outline(p), np.round(pts * 1e3) / 1e3)
    with pytest.raises(OutputExistsError):
        write_outline(p, pts, overwrite=True)  # it is an input now


@pytest.mark.parametrize(
    "text, line, match",
    [
        ("  -4000  4000\r\n  -5000\r\n", 2, "expected 2 fields"),
        ("  -4000  4000\r\n  -5000  5000  1\r\n", 2, "expected 2 fields"),
        ("  -4000  4000\r\n\r\n  -5000  abc\r\n", 3, "not an integer"),
        ("  -4000  4000\r\n  -5.5  5000\r\n", 2, "not an integer"),
        ("  -4000  4000\r\n  1000000  1000000\r\n", 2, "untracked"),
        ("  -4000  4000\r\n", None, "at least 2"),
        ("", None, "empty"),
    ],
)
def test_bad_input(tmp_path, text, line, match):
    p = tmp_path / "PAL.DAT"
    p.write_text(text, newline="")
    with pytest.raises(DataFormatError, match=match) as info:
        read_outline(p)
    assert info.value.line == line and info.value.path == str(p)


def test_bad_kind_and_bad_points(tmp_path):
    with pytest.raises(ValueError, match="kind"):
        read_outline(FIXTURES / "PAL.DAT", kind="tongue")
    with pytest.raises(DataFormatError, match="non-finite"):
        write_outline(tmp_path / "a.dat", [[0.0, np.nan], [1.0, 2.0]])
    with pytest.raises(DataFormatError, match=r"\(n, 2\)"):
        write_outline(tmp_path / "a.dat", [1.0, 2.0])


# ------------------------------------------------------------ degenerate outlines (issue 24)
@pytest.mark.parametrize(
    "kind, text, line, match",
    [
        ("pharynx", "  -73530   15572\r\n  -73530   15572\r\n", None,
         r"all 2 points coincide at \(-73\.530, 15\.572\) mm: a degenerate pharyngeal wall"),
        ("pharynx", "  -73530   15572\r\n  -73530   15000\r\n", 2,
         "a degenerate pharyngeal wall: its first and last points are 0.6 mm apart in height"),
        ("pharynx", "  -90000   10000\r\n  -60000   10000\r\n", 2, "0.0 mm apart in height"),
        ("pharynx", "  -100000   15572\r\n  -60000  -10000\r\n", 2,
         "runs 57 degrees off vertical"),
        ("palate", "  -20000   10000\r\n" * 5, None,
         r"all 5 points coincide at \(-20\.000, 10\.000\) mm: a degenerate palate outline"),
    ],
)
def test_degenerate_outlines_name_the_file(tmp_path, kind, text, line, match):
    """A PHA.DAT whose points coincide (or lie level) passed `cassi info` and then failed
    in the wall's builder with a message naming no file: it is refused on reading."""
    p = tmp_path / ("PHA.DAT" if kind == "pharynx" else "PAL.DAT")
    p.write_text(text, newline="")
    with pytest.raises(DataFormatError, match=match) as info:
        read_outline(p, kind=kind)
    assert info.value.path == str(p) and info.value.line == line
    assert str(info.value).startswith(str(p)) and "\n" not in str(info.value)
    read_outline(p, kind=kind, check=False)  # well formed: an expert may still read it


def test_real_walls_pass_and_the_wall_is_behind_the_palate():
    """The fixture and the synthetic subjects' walls pass; a wall in front of the palate's
    back end (the wrong subject's file) is refused by outlines_problem."""
    import zoo

    from cassi_fit.outlines import outline_problem, outlines_problem

    palate = read_outline(FIXTURES / "PAL.DAT")
    pharynx = read_outline(FIXTURES / "PHA.DAT", kind="pharynx")
    assert outlines_problem(palate, pharynx) is None
    for i in range(8):
        anatomy = zoo.subject(i)
        assert outline_problem(anatomy.pharynx, "pharynx") is None
        assert outlines_problem(anatomy.palate, anatomy.pharynx) is None
    forward = np.array([[-40.0, 15.0], [-40.0, -28.0]])  # in range, but inside the mouth
    assert outline_problem(forward, "pharynx") is None
    assert "not behind the palate's back end (x -60.0 mm)" in outlines_problem(palate, forward)
