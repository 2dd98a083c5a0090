"""``Headmeasures.txt``: ten measurements of each subject's head (the toolkit's own format).

No public description of the original file exists, so the toolkit defines its own (see
``docs/FORMATS.md``): a header row ``subject`` followed by the ten field names of
:class:`HeadMeasures` (any order, case-insensitive), then one row per subject; fields
separated by tabs or any white space; ``#`` starts a comment (whole line or trailing);
values in mm, decimals allowed. Gonion and gnathion are in the pellet frame (origin at
the upper incisor tip, +x forward, +y up); the rest are distances.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from ._io import atomic_write, read_lines
from .errors import DataFormatError


@dataclass(frozen=True)
class HeadMeasures:
    """Ten head measurements of one subject, all in mm.

    ``gonion_*`` (the angle of the jaw) and ``gnathion_*`` (the point of the chin) are
    positions in the pellet frame; CASSI adjusts the jaw and chin from them
    (initialisation step 5). The others are distances (Farkas-style anthropometry).
    """

    gonion_x: float
    gonion_y: float
    gnathion_x: float
    gnathion_y: float
    face_width: float  # bizygomatic breadth
    jaw_width: float  # bigonial breadth
    mouth_width: float  # cheilion to cheilion
    upper_lip_thickness: float  # UL pellet (on the vermilion) ahead of the upper incisor tip
    lower_lip_thickness: float  # LL pellet ahead of the lower incisor tip, along MNM -> MNI
    nose_protrusion: float  # subnasale to pronasale

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


FIELD_NAMES = tuple(f.name for f in fields(HeadMeasures))
#: Fields that are lengths and must be positive.
POSITIVE_FIELDS = FIELD_NAMES[4:]

#: Which fields are points on the bone and which are soft-tissue (skin) measures. The
#: paper (section 3): "Both the gonion and the gnathion are part of the jaw bone", so
#: gonion and gnathion are bony landmarks (as on a cephalogram); the face model's
#: ``gonion`` and ``gnathion`` landmarks are skin vertices, reached from the bone by
#: :data:`SOFT_TISSUE_THICKNESS_MM` (``conformation.skin_landmarks``). The widths are
#: skin-to-skin anthropometry (Farkas), the lip thicknesses pellet (on the vermilion) to
#: incisor tip, and the nose subnasale to pronasale: all soft tissue.
BONE_FIELDS = ("gonion_x", "gonion_y", "gnathion_x", "gnathion_y")
SOFT_TISSUE_FIELDS = tuple(f for f in FIELD_NAMES if f not in BONE_FIELDS)

#: Soft-tissue thickness (mm) over the bony landmarks, adult means from the facial
#: reconstruction tables: over gnathion/menton about 7 mm (Rhine & Moore 1984, "beneath
#: chin", normal build, 6-8 mm; Stephan & Simpson 2008, J Forensic Sci 53:1257, pooled
#: adult gnathion of the same order); over gonion about 12 mm (Rhine & Moore 1984,
#: "gonion", normal build 11-12 mm; larger, 15-20 mm, in CT studies of heavier builds).
#: Applied along the model's skin normal at the landmark, projected on the midsagittal
#: plane (the pellet frame).
SOFT_TISSUE_THICKNESS_MM = {"gnathion": 7.0, "gonion": 12.0}

#: The face model at rest, used when a dataset has no measures for a subject, so that a
#: subject whose row equals these leaves the face unchanged (tests/test_cassi_mode.py).
#: Bony gonion and gnathion: the model's skin landmarks (-84.3, -35.0) and (-4, -49.5) mm
#: moved inwards by the thicknesses above along the skin normal (their sagittal parts
#: (-0.115, -0.183) and (0.377, -0.926)); they agree with adult bone: gnathion 43 mm below
#: the incisor tip (anterior lower face height 40-45 mm), gonion 81 mm behind and 35 mm
#: below it. The rest are the model's own measures (model/model.json "measures": face
#: width, jaw width, mouth width, lip thickness, nose), which sit in the adult ranges of
#: Farkas' norms (bizygomatic 130-140, bigonial 95-105, mouth 45-55, nose 17-23 mm).
#: Rebuilding the model with other proportions means updating these.
DEFAULT_HEAD_MEASURES = HeadMeasures(
    gonion_x=-82.946,
    gonion_y=-32.808,
    gnathion_x=-6.641,
    gnathion_y=-43.017,
    face_width=131.557,
    jaw_width=103.47,
    mouth_width=48.913,
    upper_lip_thickness=14.9,
    lower_lip_thickness=15.004,
    nose_protrusion=20.0,
)

#: Plausible range (mm) of each measure for any adult (docs/FORMATS.md, "Plausibility",
#: for the sources): the Farkas (1994) adult norms widened to about +-6 SD, and the
#: landmark positions in the pellet frame (gonion behind and below the incisor tip,
#: gnathion below it).
PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
    "gonion_x": (-130.0, -50.0),
    "gonion_y": (-80.0, 0.0),
    "gnathion_x": (-40.0, 30.0),
    "gnathion_y": (-75.0, -20.0),
    "face_width": (100.0, 175.0),
    "jaw_width": (70.0, 140.0),
    "mouth_width": (30.0, 80.0),
    "upper_lip_thickness": (2.0, 35.0),
    "lower_lip_thickness": (2.0, 35.0),
    "nose_protrusion": (8.0, 40.0),
}


def _in(column: str, value: float) -> bool:
    lo, hi = PLAUSIBLE_RANGES[column]
    return lo <= value <= hi


def measure_problem(column: str, value: float) -> str | None:
    """Why ``value`` (mm) is implausible for ``column``, with the likely unit, or None."""
    if _in(column, value):
        return None
    lo, hi = PLAUSIBLE_RANGES[column]
    hint = ""
    for factor, unit in ((10.0, "centimetres"), (1000.0, "metres"), (0.001, "micrometres")):
        if _in(column, value * factor):
            hint = f": looks like {unit}; Headmeasures values are in mm"
            break
    else:
        if column.startswith("gonion_x") and value > 0:
            hint = ": the gonion (angle of the jaw) cannot be in front of the face"
    return f"{column}: implausible value {value:g} mm (expected {lo:g} to {hi:g}){hint}"


def head_problem(measures: HeadMeasures) -> str | None:
    """The first implausible measure of ``measures`` (ranges, then the gonion behind the
    gnathion and the jaw narrower than the face), or None."""
    for column in FIELD_NAMES:
        problem = measure_problem(column, float(getattr(measures, column)))
        if problem is not None:
            return problem
    if measures.gonion_x >= measures.gnathion_x:
        return "gonion_x: the gonion must lie behind the gnathion (gonion_x < gnathion_x)"
    if measures.jaw_width >= measures.face_width:
        return "jaw_width: the jaw (bigonial) must be narrower than the face (bizygomatic)"
    return None


_NUMBER = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")
_SUBJECT = re.compile(r"[A-Za-z0-9_.-]+")


def _strip_comment(line: str) -> str:
    return line.split("#", 1)[0]


def _parse_header(path: Path, lineno: int, tokens: list[str]) -> list[str]:
    names = [t.lower() for t in tokens]
    if not names or names[0] != "subject":
        raise DataFormatError(path, lineno, "header must start with the column 'subject'")
    cols = names[1:]
    unknown = [c for c in cols if c not in FIELD_NAMES]
    if unknown:
        raise DataFormatError(path, lineno, f"unknown column(s) {', '.join(unknown)}")
    dupes = sorted({c for c in cols if cols.count(c) > 1})
    if dupes:
        raise DataFormatError(path, lineno, f"duplicate column(s) {', '.join(dupes)}")
    missing = [f for f in FIELD_NAMES if f not in cols]
    if missing:
        raise DataFormatError(path, lineno, f"missing column(s) {', '.join(missing)}")
    return cols


def _parse_value(path: Path, lineno: int, column: str, token: str) -> float:
    if not _NUMBER.fullmatch(token):
        raise DataFormatError(path, lineno, f"{column}: not a number: {token[:40]!r}")
    value = float(token)
    if not math.isfinite(value) or abs(value) > 1e4:
        raise DataFormatError(path, lineno, f"{column}: implausible value {token[:40]} mm")
    if column in POSITIVE_FIELDS and value <= 0:
        raise DataFormatError(path, lineno, f"{column}: must be positive, got {token}")
    return value


def read_headmeasures(
    path: str | os.PathLike, *, check: bool = True
) -> dict[str, HeadMeasures]:
    """Read a ``Headmeasures.txt``: subject name (upper case) -> :class:`HeadMeasures`.

    Raises :class:`DataFormatError` naming file and line for an empty file, a header
    with unknown, duplicate or missing columns, a row with the wrong number of fields,
    a value that is not a finite number, a non-positive distance, or a repeated subject;
    with ``check`` (default), for an implausible row (:func:`head_problem`: a value out
    of ``PLAUSIBLE_RANGES``, with the likely unit; a gonion in front of the gnathion).
    """
    path, lines = read_lines(path)
    return parse_headmeasures(path, lines, check=check)


def parse_headmeasures(path: str | os.PathLike, lines: list[tuple[int, str]], *,
                       check: bool = True) -> dict[str, HeadMeasures]:
    """The one parser of a ``Headmeasures.txt``'s ``(lineno, line)`` pairs (``path``
    names the file in errors); as :func:`read_headmeasures`, which reads the file."""
    rows = [(n, _strip_comment(s).split()) for n, s in lines]
    rows = [(n, toks) for n, toks in rows if toks]
    if not rows:
        raise DataFormatError(path, None, "empty file (expected a header row naming the columns)")
    header_line, header = rows[0]
    cols = _parse_header(path, header_line, header)
    result: dict[str, HeadMeasures] = {}
    for lineno, tokens in rows[1:]:
        if len(tokens) != len(cols) + 1:
            raise DataFormatError(
                path,
                lineno,
                f"expected {len(cols) + 1} fields (subject and {len(cols)} values), found {len(tokens)}",
            )
        subject = tokens[0].upper()
        if not _SUBJECT.fullmatch(subject):
            raise DataFormatError(path, lineno, f"bad subject name {tokens[0][:40]!r}")
        if subject in result:
            raise DataFormatError(path, lineno, f"subject {subject} appears twice")
        values = {
            c: _parse_value(path, lineno, c, t) for c, t in zip(cols, tokens[1:], strict=True)
        }
        result[subject] = HeadMeasures(**values)
        problem = head_problem(result[subject]) if check else None
        if problem is not None:
            raise DataFormatError(path, lineno, f"{subject} {problem}")
    return result


def write_headmeasures(
    path: str | os.PathLike, measures: Mapping[str, HeadMeasures], *, overwrite: bool = False
) -> Path:
    """Write ``Headmeasures.txt``: header, one row per subject (upper case), tabs, CRLF.

    Values are written with 3 decimals (um resolution). Written atomically; never
    replaces an input file, nor an existing file unless ``overwrite``.
    """
    path = Path(path)
    out = [
        "# Headmeasures.txt (cassi_fit format): ten measures per subject, mm; "
        "gonion and gnathion in the pellet frame"
    ]
    out.append("\t".join(("subject",) + FIELD_NAMES))
    written: set[str] = set()
    for subject, m in measures.items():
        name = str(subject).upper()
        if not _SUBJECT.fullmatch(name) or name in written:
            raise DataFormatError(path, None, f"cannot write: bad or repeated subject {subject!r}")
        written.add(name)
        values = [float(getattr(m, f)) for f in FIELD_NAMES]
        if not all(math.isfinite(v) for v in values) or min(values[4:]) <= 0:
            raise DataFormatError(
                path, None, f"cannot write: non-finite or non-positive measure for {name}"
            )
        out.append("\t".join([name] + [f"{v:.3f}" for v in values]))
    text = "".join(s + "\r\n" for s in out)
    return atomic_write(path, text, overwrite=overwrite, data_file=True)
