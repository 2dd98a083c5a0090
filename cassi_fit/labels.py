"""Phone and word labels beside a pellet file: HTK or ESPS ``.lab`` and Praat TextGrid.

A :class:`Labels` record holds one tier of time intervals (seconds, half-open
``[start, end)``, sorted, not overlapping) with their labels; :meth:`Labels.at` gives the
label at given times (``""`` where no interval covers the time) and :func:`segment_summary`
measures the jaw and the lips per labelled segment.

Formats (both written atomically, and read back identically by the readers):

* **HTK label file** ``X.lab``: one interval per line, ``start end label`` separated by white
  space; further fields on a line (HTK scores, auxiliary labels) are ignored, blank lines
  skipped. Times are either seconds or HTK's integer units of 100 ns. ``units="auto"``
  (the default) decides per file: HTK units when every time in the file is written as an
  integer and the largest is at least ``HTK_UNITS_THRESHOLD`` (1000); seconds otherwise
  (any decimal point or exponent, or only small integers such as ``0 1 a``). A recording
  of 1000 s or more labelled in whole seconds is the case this rule gets wrong: pass
  ``units="seconds"`` for it.
* **ESPS/xwaves label file** (``xlabel``; Festival's and the CSTR corpora's ``.lab``, CMU
  ARCTIC's): a header ended by a line holding ``#`` alone, then one line per interval,
  ``end colour label``: the interval ends at the time (seconds) and starts where the one
  before ended (the first at 0); a line without a label is silence left blank. Read when
  one of the first ``XLABEL_HEADER_LINES`` lines is ``#``.
* **Praat TextGrid** ``X.TextGrid`` (long or short text format), read through praatio;
  interval tiers only. Empty intervals (silence left blank) are not segments.

:func:`labels_for` finds ``X.lab`` / ``X.TextGrid`` beside ``X.txy`` (case-insensitive).
Every malformation (a non-numeric time, ``end < start``, unsorted or overlapping
intervals, a TextGrid praatio cannot read) raises one :class:`DataFormatError` naming the
file and, where one can be found, the line.

**Labels against the recording** (:func:`check_labels`; :func:`labels_for` runs it with
the pellet file's length). Labels share the pellets' clock (time 0 = the first frame);
the last label may end a little after the last frame (JW11 task 5: 5.019 s against
5.012 s). Beyond ``max(LABEL_TOLERANCE_S, 5 %)`` past the end, or spanning a fraction of
the recording that a unit mix-up explains, one line gives the numbers and the likely
cause: times in milliseconds or in samples read as seconds (1000 or 16000 times too
long), or read as HTK's 100 ns units (10000 or 625 times too short): an error, since every
label would be shifted or empty, with ``units=`` as the cure. Labels past the end that no
unit explains warn (:class:`LabelMismatchWarning`; those intervals are never reached),
unless every label starts past the end: an error too (nothing would ever be shown).
``accept_mismatch=True`` turns the errors into warnings and keeps the labels as they are.
"""

# jaxtyping's shape strings ("n 8 2") are not Python expressions:
from __future__ import annotations

import math
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from jaxtyping import Bool, Float, Shaped

from ._io import atomic_output_path, atomic_write, commit_output, register_input
from .errors import DataFormatError, MissingDataError
from .status import LengthFit, SegmentStatus

LAB_SUFFIX = ".lab"
TEXTGRID_SUFFIX = ".textgrid"
HTK_UNITS_PER_S = 10_000_000  # HTK time unit: 100 ns
HTK_UNITS_THRESHOLD = 1000  # all-integer times reaching this are HTK units (see above)
UNITS = ("auto", "seconds", "htk")
#: Labels may end this long (s), or 5 % of the recording, after the pellets' last frame.
LABEL_TOLERANCE_S = 0.25
LABEL_TOLERANCE_FRACTION = 0.05
#: How close (relative) a span ratio must be to a unit factor to be named as the cause.
UNIT_MATCH = 0.1
_SAMPLE_RATES_HZ = (8000, 16000, 22050, 44100, 48000)
#: (factor by which the labels' span is too long, what happened): ratio = span / length.
_UNIT_CAUSES = (
    (1000.0, "times in milliseconds read as seconds"),
    *((float(r), f"times in samples at {r} Hz read as seconds") for r in _SAMPLE_RATES_HZ),
    (1e-4, "times in milliseconds read as HTK units of 100 ns (write the times in seconds)"),
    *((r / 1e7, f"times in samples at {r} Hz read as HTK units of 100 ns")
      for r in _SAMPLE_RATES_HZ),
    (1e7, "times in HTK units of 100 ns read as seconds (pass units='htk')"),
)


class Segment(NamedTuple):
    """One labelled interval, seconds."""

    start: float
    end: float
    label: str


@dataclass(frozen=True, eq=False)
class Labels:
    """One tier of labelled intervals.

    starts, ends: ``(n,)`` float64 seconds, ``starts[k] <= ends[k] <= starts[k+1]``;
    labels: n strings; tier: the tier's name (``"labels"`` for a ``.lab`` file);
    path: the file read, or None.
    """

    starts: Float[np.ndarray, " n"]
    ends: Float[np.ndarray, " n"]
    labels: tuple[str, ...]
    tier: str = "labels"
    path: Path | None = None

    def __post_init__(self):
        starts = np.asarray(self.starts, dtype=np.float64).reshape(-1)
        ends = np.asarray(self.ends, dtype=np.float64).reshape(-1)
        labels = tuple(str(s) for s in self.labels)
        if not starts.shape == ends.shape == (len(labels),):
            raise ValueError(f"Labels: {starts.shape[0]} starts, {ends.shape[0]} ends and "
                             f"{len(labels)} labels")
        _check_intervals(self.path, starts, ends, None)
        object.__setattr__(self, "starts", starts)
        object.__setattr__(self, "ends", ends)
        object.__setattr__(self, "labels", labels)
        if self.path is not None:
            object.__setattr__(self, "path", Path(self.path))

    def __len__(self) -> int:
        return len(self.labels)

    def segments(self) -> list[Segment]:
        """The intervals in time order."""
        return [Segment(float(s), float(e), lab)
                for s, e, lab in zip(self.starts, self.ends, self.labels, strict=True)]

    def at(self, times: Float[np.ndarray, " m"]) -> Shaped[np.ndarray, " m"]:
        """The label at each time (seconds): a ``(m,)`` str array, ``""`` where no
        interval ``[start, end)`` covers the time."""
        times = np.asarray(times, dtype=np.float64)
        if not len(self):
            return np.full(times.shape, "", dtype=str)
        k = np.searchsorted(self.starts, times, side="right") - 1
        kk = np.clip(k, 0, len(self) - 1)
        inside = (k >= 0) & (times < self.ends[kk])
        return np.where(inside, np.asarray(self.labels, dtype=str)[kk], "")


class LabelMismatchWarning(UserWarning):
    """Labels do not fit the recording's length (accepted, or only past its end)."""


@dataclass(frozen=True)
class LabelCheck:
    """Labels against the recording: ``n_intervals``, the labels' ``last_end_s``, the
    recording's ``recording_s``, ``status`` (``"ok"``, ``"units"``: a unit mix-up
    explains the span, ``"past-end"``: intervals after the end), ``n_past_end``
    intervals starting after the end, and the one-line ``message`` (None when ok)."""

    path: str | None
    n_intervals: int
    last_end_s: float
    recording_s: float
    status: str
    n_past_end: int
    message: str | None


def _unit_cause(ratio: float) -> str | None:
    for factor, cause in _UNIT_CAUSES:
        if abs(ratio / factor - 1.0) <= UNIT_MATCH:
            return cause
    return None


def check_labels(labels: Labels, recording_s: float, *,
                 accept_mismatch: bool = False) -> LabelCheck:
    """Check ``labels`` against a recording of ``recording_s`` seconds (time 0 to the end
    of the last frame); see the module docstring. Raises :class:`DataFormatError`
    naming the label file when a unit mix-up explains the labels' span (unless
    ``accept_mismatch``); warns (:class:`LabelMismatchWarning`) for intervals past the
    end, or for an accepted mismatch."""
    where = labels.path if labels.path is not None else "<labels>"
    recording_s = float(recording_s)
    n = len(labels)
    if not n or recording_s <= 0:
        return LabelCheck(None if labels.path is None else str(labels.path), n, 0.0,
                          recording_s, LengthFit.OK.label, 0, None)
    last = float(labels.ends.max())
    tolerance = max(LABEL_TOLERANCE_S, LABEL_TOLERANCE_FRACTION * recording_s)
    past = int((labels.starts >= recording_s).sum())
    numbers = (f"{n} labels span 0-{last:.4g} s, the recording {recording_s:.4g} s "
               f"({past} start after its end)")
    cause = _unit_cause(last / recording_s) if last > 0 else None
    status = LengthFit.OK.label
    if cause is not None and abs(last - recording_s) > tolerance:
        status, message, error = LengthFit.UNITS.label, f"{numbers}: likely {cause}", True
    elif past == n:
        status, error = LengthFit.PAST_END.label, True
        message = (f"{numbers}: every label starts after the recording ends, none would be "
                   "shown (times in other units, labels of another recording, or a "
                   "different time origin?)")
    elif last > recording_s + tolerance:
        status, error = LengthFit.PAST_END.label, False
        message = (f"{numbers}: labels past the end are never shown (labels of another "
                   "recording, or a different time origin?)")
    if status == LengthFit.OK.label:
        return LabelCheck(None if labels.path is None else str(labels.path), n, last,
                          recording_s, status, past, None)
    if error and not accept_mismatch:
        raise DataFormatError(where, None, message + " (accept them with accept_mismatch=True)")
    warnings.warn(f"{where}: {message}", LabelMismatchWarning, stacklevel=2)
    return LabelCheck(None if labels.path is None else str(labels.path), n, last,
                      recording_s, status, past, message)


def _check_intervals(path, starts, ends, lines) -> None:
    """DataFormatError for the first non-finite, negative, reversed, unsorted or
    overlapping interval; ``lines[k]`` is interval k's line in the file (or None)."""
    line = (lambda k: None) if lines is None else (lambda k: lines[k])
    for k in range(len(starts)):
        s, e = starts[k], ends[k]
        if not (math.isfinite(s) and math.isfinite(e)):
            raise DataFormatError(path, line(k), f"interval {k + 1}: non-finite time")
        if s < 0:
            raise DataFormatError(path, line(k), f"interval {k + 1}: negative start {s:g} s")
        if e < s:
            raise DataFormatError(path, line(k), f"interval {k + 1}: end {e:g} s is before "
                                  f"start {s:g} s")
        if k and s < starts[k - 1]:
            raise DataFormatError(path, line(k), f"interval {k + 1}: not sorted (starts at "
                                  f"{s:g} s, the previous one at {starts[k - 1]:g} s)")
        if k and s < ends[k - 1]:
            raise DataFormatError(path, line(k), f"interval {k + 1}: overlaps the previous "
                                  f"interval (starts at {s:g} s, the previous ends at "
                                  f"{ends[k - 1]:g} s)")


# ------------------------------------------------------------------------ HTK .lab
_INTEGER = re.compile(r"[+-]?[0-9]+")


def _lab_rows(path: Path) -> tuple[list[tuple[int, str, str, str]], bool]:
    """``(rows (line, start, end, label), ESPS)``: the intervals of an HTK label file, or
    of an ESPS one (``True``: its times are seconds)."""
    from ._io import read_lines  # BOM, CRLF, encodings: as for pellet files

    _, lines = read_lines(path)
    header_end = _xlabel_header_end(lines)
    if header_end is not None:
        return _xlabel_rows(path, lines[header_end + 1:]), True
    rows = []
    for lineno, text in lines:
        fields = text.split()
        if len(fields) < 3:
            raise DataFormatError(path, lineno, f"expected 'start end label', got {text!r}")
        rows.append((lineno, *fields[:3]))
    return rows, False


#: An ESPS/xwaves label file's header ends at a line holding ``#`` alone; searched for in
#: this many first lines (its header: ``signal``, ``type``, ``color``, ``separator``,
#: ``nfields``, a comment or two).
XLABEL_HEADER_LINES = 20


def _xlabel_header_end(lines: list[tuple[int, str]]) -> int | None:
    """The index of the ``#`` line ending an ESPS label file's header, or None (an HTK
    file: its first line is an interval)."""
    for k, (_, text) in enumerate(lines[:XLABEL_HEADER_LINES]):
        if text.strip() == "#":
            return k
    return None


def _xlabel_rows(path: Path, lines: list[tuple[int, str]]) -> list[tuple[int, str, str, str]]:
    """ESPS/xwaves (``xlabel``) rows ``end colour label``: each interval ends at its time
    and starts at the one before (the first at 0), in seconds; an interval with no label
    (``end colour`` alone) is silence left blank, not a segment. Returned as HTK rows
    ``(line, start, end, label)``."""
    rows, start = [], "0"
    for lineno, text in lines:
        fields = text.split(None, 2)
        if len(fields) < 2:
            raise DataFormatError(path, lineno, f"expected 'end colour label' (an ESPS label "
                                  f"file, its header ended by '#'), got {text!r}")
        label = fields[2].strip() if len(fields) > 2 else ""
        if label:
            rows.append((lineno, start, fields[0], label))
        start = fields[0]
    return rows


def _lab_time(path: Path, lineno: int, token: str) -> float:
    try:
        return float(token)
    except ValueError:
        raise DataFormatError(path, lineno, f"time {token!r} is not a number") from None


def read_lab(path: str | os.PathLike, *, units: str = "auto") -> Labels:
    """Read an HTK label file (see the module doc for ``units``: "auto", "seconds",
    "htk") or an ESPS/xwaves one (its header ended by ``#``; seconds). An empty file
    gives an empty :class:`Labels`."""
    if units not in UNITS:
        raise ValueError(f"units must be one of {', '.join(UNITS)}, got {units!r}")
    path = Path(path)
    rows, esps = _lab_rows(path)
    register_input(path)
    if esps and units == "auto":
        units = "seconds"  # ESPS label files time in seconds
    times = np.array([[_lab_time(path, n, a), _lab_time(path, n, b)] for n, a, b, _ in rows],
                     dtype=np.float64).reshape(-1, 2)
    if units == "auto":
        integers = all(_INTEGER.fullmatch(t) for _, a, b, _ in rows for t in (a, b))
        units = "htk" if rows and integers and times.max() >= HTK_UNITS_THRESHOLD else "seconds"
    if units == "htk":
        times = times / HTK_UNITS_PER_S  # a division: 1000000 units read back as 0.1 s
    lines = [n for n, *_ in rows]
    _check_intervals(path, times[:, 0], times[:, 1], lines)
    return Labels(times[:, 0], times[:, 1], tuple(r[3] for r in rows), "labels", path)


def write_lab(path: str | os.PathLike, labels: Labels, *, units: str = "seconds",
              overwrite: bool = False) -> Path:
    """Write an HTK label file: seconds (shortest exact decimal, read back identically)
    or ``units="htk"`` (integer 100 ns units, rounded). Labels must be non-empty words
    without white space."""
    if units not in ("seconds", "htk"):
        raise ValueError(f"units must be 'seconds' or 'htk', got {units!r}")
    path = Path(path)
    out = []
    for k, (s, e, lab) in enumerate(labels.segments()):
        if not lab or any(c.isspace() for c in lab):
            raise DataFormatError(path, None, f"cannot write interval {k + 1}: label {lab!r} "
                                  "is empty or holds white space")
        if units == "htk":
            out.append(f"{round(s * HTK_UNITS_PER_S)} {round(e * HTK_UNITS_PER_S)} {lab}\n")
        else:
            out.append(f"{s!r} {e!r} {lab}\n")
    return atomic_write(path, "".join(out), overwrite=overwrite)


# ---------------------------------------------------------------------- TextGrid
_PRAAT_TOKEN = re.compile(r'"((?:[^"]|"")*)"|(!.*)|([^\s"]+)')
# the long format's words around the values ("xmin =", "intervals [3]:", "tiers?")
_PRAAT_WORD = re.compile(r"[A-Za-z_]+\??|=|\[[0-9]*\]:?|.*:")


def _praat_tokens(text: str) -> list[tuple[int, str, bool]]:
    """Praat's text-file tokens ``(line, token, is_string)``. Praat reads a text file as
    a stream of numbers and quoted strings (``""`` inside a string is a quote; ``!``
    starts a comment), which is why the long and short formats are one stream."""
    out = []
    for m in _PRAAT_TOKEN.finditer(text):
        if m.group(2) is not None:
            continue
        line = text.count("\n", 0, m.start()) + 1
        if m.group(1) is not None:
            out.append((line, m.group(1).replace('""', '"'), True))
        else:
            out.append((line, m.group(3), False))
    return out


def _locate_textgrid_error(path: Path, text: str) -> tuple[int | None, str] | None:
    """Walk the token stream of a text TextGrid and return ``(line, problem)`` for the
    first bad number or bad interval, or None if the stream looks sound."""
    values = [(ln, tok, s) for ln, tok, s in _praat_tokens(text)
              if s or not _PRAAT_WORD.fullmatch(tok)]
    if [tok for _, tok, _ in values[:2]] != ["ooTextFile", "TextGrid"]:
        return None  # not the text format: leave the diagnosis to praatio
    pos = 2

    def number():
        nonlocal pos
        while pos < len(values) and not values[pos][2] and values[pos][1].startswith("<"):
            pos += 1  # <exists>
        if pos >= len(values):
            raise _Located(values[-1][0] if values else None, "file ends early")
        ln, tok, is_string = values[pos]
        pos += 1
        try:
            return ln, float(tok) if not is_string else float("x")
        except ValueError:
            raise _Located(ln, f"expected a number, got {tok!r}") from None

    try:
        number(), number()  # xmin, xmax
        _, n_tiers = number()
        for _ in range(int(n_tiers)):
            kind, name = values[pos][1], values[pos + 1][1]
            pos += 2
            number(), number()
            _, n = number()
            last_end, width = -math.inf, 3 if kind == "IntervalTier" else 2
            for _ in range(int(n)):
                ln, start = number()
                end = number()[1] if width == 3 else start
                pos += 1  # the label
                if width == 3 and end < start:
                    raise _Located(ln, f"tier {name!r}: interval end {end:g} s is before "
                                   f"its start {start:g} s")
                if width == 3 and start < last_end:
                    raise _Located(ln, f"tier {name!r}: interval at {start:g} s overlaps the "
                                   f"previous one (ends at {last_end:g} s) or is not sorted")
                last_end = end
    except _Located as exc:
        return exc.line, exc.problem
    except (IndexError, ValueError):
        return None
    return None


class _Located(Exception):
    def __init__(self, line, problem):
        self.line, self.problem = line, problem


def _praat_text(path: Path) -> str:
    """The file's text: Praat writes UTF-8 or, for some characters, UTF-16 with a BOM."""
    import codecs

    raw = path.read_bytes()
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return raw.decode("utf-16", errors="replace")
    return raw.decode("utf-8-sig", errors="replace")


def _open_textgrid(path: Path):
    """praatio's grid; DataFormatError with the line for what the token walk locates
    (checked also when praatio accepts the file: it drops blank intervals unchecked)."""
    from praatio import textgrid

    located = _locate_textgrid_error(path, _praat_text(path))
    if located is not None:
        raise DataFormatError(path, located[0], located[1])
    try:
        return textgrid.openTextgrid(str(path), includeEmptyIntervals=False,
                                     reportingMode="silence")
    except Exception as exc:  # praatio raises many types; one clear error instead
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataFormatError(path, None, f"not a readable TextGrid ({first})") from None


def _choose_tier(path: Path, grid, tier: str | None):
    from praatio import textgrid

    names = [n for n in grid.tierNames if isinstance(grid.getTier(n), textgrid.IntervalTier)]
    if not names:
        raise DataFormatError(path, None, "no interval tier")
    return grid.getTier(tier_name(names, tier, path, "interval tier"))


def textgrid_tiers(path: str | os.PathLike) -> list[tuple[str, int]]:
    """The interval tiers of a Praat TextGrid, ``(name, labelled intervals)`` in the file's
    order: what ``--tier`` / ``tier=`` can name (``cassi info`` lists them)."""
    from praatio import textgrid

    grid = _open_textgrid(Path(path))
    return [(name, len(grid.getTier(name).entries)) for name in grid.tierNames
            if isinstance(grid.getTier(name), textgrid.IntervalTier)]


def read_textgrid(path: str | os.PathLike, *, tier: str | None = None) -> Labels:
    """One interval tier of a Praat TextGrid: ``tier`` by name (case-insensitive), or the
    one :func:`tier_name` chooses among its interval tiers (phones, then words, then one
    speaker's, then the first)."""
    path = Path(path)
    if not path.is_file():
        raise MissingDataError(f"{path}: no such label file")
    grid = _open_textgrid(path)
    register_input(path)
    chosen = _choose_tier(path, grid, tier)
    entries = [e for e in chosen.entries if e.label.strip()]
    starts = np.array([e.start for e in entries], dtype=np.float64)
    ends = np.array([e.end for e in entries], dtype=np.float64)
    return Labels(starts, ends, tuple(e.label for e in entries), chosen.name, path)


def write_textgrid(path: str | os.PathLike, labels: Labels, *, overwrite: bool = False,
                   duration: float | None = None) -> Path:
    """Write ``labels`` as a one-tier TextGrid (long text format, tier ``labels.tier``)
    spanning 0 to ``duration`` seconds (default: the last end). Gaps become empty
    intervals, which :func:`read_textgrid` skips, so the round trip is exact."""
    from praatio import textgrid
    from praatio.utilities.constants import Interval

    end = float(labels.ends[-1]) if len(labels) else 0.0
    duration = end if duration is None else float(duration)
    entries = [Interval(s, e, lab) for s, e, lab in labels.segments()]
    grid = textgrid.Textgrid(0.0, duration)
    grid.addTier(textgrid.IntervalTier(labels.tier, entries, 0.0, duration))
    tmp, final = atomic_output_path(path, overwrite=overwrite)
    try:
        grid.save(str(tmp), format="long_textgrid", includeBlankSpaces=True,
                  reportingMode="silence")
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return commit_output(tmp, final)


# --------------------------------------------------------------------- discovery
def read_labels(path: str | os.PathLike, *, tier: str | None = None,
                units: str = "auto") -> Labels:
    """Read ``.lab`` (``units``) or ``.TextGrid`` (``tier``), chosen by the suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == LAB_SUFFIX:
        if not path.is_file():
            raise MissingDataError(f"{path}: no such label file")
        return read_lab(path, units=units)
    if suffix == TEXTGRID_SUFFIX:
        return read_textgrid(path, tier=tier)
    raise DataFormatError(path, None, "label files end in .lab or .TextGrid")


def label_path_for(pellet_path: str | os.PathLike) -> Path | None:
    """``X.TextGrid`` or else ``X.lab`` beside ``X.txy`` (any case), or None."""
    pellet_path = Path(pellet_path)
    stem = pellet_path.stem.lower()
    try:
        found = {p.name.lower(): p for p in pellet_path.parent.iterdir() if p.is_file()}
    except OSError:
        return None
    for suffix in (TEXTGRID_SUFFIX, LAB_SUFFIX):
        if stem + suffix in found:
            return found[stem + suffix]
    return None


def labels_for(pellet_path: str | os.PathLike, *, tier: str | None = None,
               units: str = "auto", recording_s: float | None = None,
               accept_mismatch: bool = False) -> Labels | None:
    """The labels beside a pellet file (see :func:`label_path_for`), or None if there
    are none. A TextGrid is preferred to a ``.lab`` when both exist.

    The labels are checked against the recording (:func:`check_labels`): its length
    ``recording_s`` (s), by default read from the pellet file's last line (time plus one
    frame); ``accept_mismatch`` keeps labels whose times do not fit (with a warning)."""
    found = label_path_for(pellet_path)
    if found is None:
        return None
    labels = read_labels(found, tier=tier, units=units)
    if recording_s is None:
        recording_s = _pellet_seconds(Path(pellet_path))
    if recording_s is not None:
        check_labels(labels, recording_s, accept_mismatch=accept_mismatch)
    return labels


def _pellet_seconds(pellet_path: Path) -> float | None:
    """The length (s) of a pellet file: its last line's time (us) plus one frame step;
    None if the file cannot say (its reader reports the problem)."""
    from .txy import FRAME_STEP_US

    if not pellet_path.is_file():  # a FIFO would block: the reader refuses it in one line
        return None
    try:
        with open(pellet_path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(size - 4096, 0))
            tail = fh.read().decode("utf-8", errors="replace")
        last = [line for line in tail.splitlines() if line.strip()][-1]
        return (int(last.split()[0]) + FRAME_STEP_US) / 1e6
    except (OSError, IndexError, ValueError):
        return None


# ------------------------------------------------------------ which tier is used
#: Tier names (lower case) taken first when none is named: phones, then words (a TextGrid
#: beside the file and the tiers inside it alike). ``mau``, ``ort-mau``: BAS WebMAUS's
#: phone and word tiers; ``segment``: EMU's usual phone level.
PHONE_TIERS = ("phones", "phone", "segment", "segments", "phonetic", "phn", "mau")
WORD_TIERS = ("words", "word", "wrd", "ort-mau", "ort")


def tier_name(names, tier: str | None = None, where=None, kind: str = "label tier"
              ) -> str | None:
    """Which of the tiers ``names`` a recording's labels come from: ``tier`` (any case;
    else a :class:`MissingDataError` listing them), else the first of
    :data:`PHONE_TIERS`, then :data:`WORD_TIERS`, then one speaker's (the Montreal
    Forced Aligner's ``SPEAKER - phones``, then ``SPEAKER - words``; several speakers'
    are refused in one line: ``--tier`` / ``tier=`` chooses), then the first tier; None
    for no tier."""
    names = list(names)
    by_lower = {}
    for n in names:
        by_lower.setdefault(n.lower(), n)
    if tier is not None:
        if tier.lower() not in by_lower:
            raise MissingDataError(f"{where or 'the recording'}: no {kind} {tier!r} "
                                   f"(tiers: {', '.join(names) or 'none'})")
        return by_lower[tier.lower()]
    for default in PHONE_TIERS + WORD_TIERS:
        if default in by_lower:
            return by_lower[default]
    for default in ("phones", "words"):
        found = [n for n in names if n.lower().endswith(f" - {default}")]
        if len(found) > 1:
            raise MissingDataError(f"{where or 'the recording'}: {len(found)} speakers' "
                                   f"{default} tiers ({', '.join(found)}): --tier (tier=) "
                                   "chooses one")
        if found:
            return found[0]
    return names[0] if names else None


def choose_tier(tiers, tier: str | None = None, where=None) -> Labels | None:
    """The tier of ``tiers`` (:class:`Labels`) that :func:`tier_name` chooses."""
    tiers = list(tiers)
    name = tier_name([t.tier for t in tiers], tier, where)
    return next((t for t in tiers if t.tier == name), None)


def recording_labels(recording, *, tier: str | None = None, units: str = "auto",
                     recording_s: float | None = None,
                     accept_mismatch: bool = False) -> Labels | None:
    """The labels every output uses for a ``dataset.Recording``: a file beside it
    (:func:`labels_for`), else the tiers inside it (``recording.labels``: mview
    ``WORDS``/``PHONES``, EMU levels; :func:`choose_tier`), else None; checked against
    its length (``recording_s``, default the track's) as :func:`labels_for` checks.
    ``tier``: default the recording's own choice (``Recording.label_tier``: ``--tier``),
    else :func:`tier_name`'s."""

    if tier is None:
        tier = getattr(recording, "label_tier", None)
    if recording_s is None:
        recording_s = recording.track.length_s
    path = getattr(recording, "path", None)
    if path is not None and label_path_for(path) is not None:
        return labels_for(path, tier=tier, units=units, recording_s=recording_s,
                          accept_mismatch=accept_mismatch)
    chosen = choose_tier(getattr(recording, "labels", ()) or (), tier, path)
    if chosen is not None:
        check_labels(chosen, recording_s, accept_mismatch=accept_mismatch)
    return chosen


# ----------------------------------------------------------- per-segment summaries
SEGMENT_COLUMNS = ("label", "start_s", "end_s", "frames", "status", "jaw_peak_opening_deg",
                   "jaw_peak_time_s", "jaw_min_opening_deg", "lip_aperture_max_mm",
                   "lip_aperture_min_mm", "lip_aperture_min_time_s")


def segment_summary(
    times: Float[np.ndarray, " n"],
    theta: Float[np.ndarray, " n"],
    pellets: Float[np.ndarray, "n 8 2"],
    labels: Labels,
    *,
    usable: Bool[np.ndarray, " n"] | None = None,
) -> list[dict]:
    """One row per labelled segment (:data:`SEGMENT_COLUMNS`).

    times (n,) s; theta (n,) rad, jaw opening from the reference frame (``JawFit.theta``);
    pellets (n, 8, 2) mm in ``txy.PELLET_NAMES`` order (NaN where untracked); lip
    aperture = ``|UL - LL|`` mm. ``usable`` (n,) marks frames whose jaw angle counts
    (e.g. ``JawFit.status == 0``; default all). A segment's frames are those with
    ``start <= t < end``. ``status`` says why values are missing (None in the row):
    "no-frames" (shorter than a frame step), "jaw-untracked", "lips-untracked".
    """
    from .txy import pellet_index

    times = np.asarray(times, dtype=np.float64)
    theta_deg = np.rad2deg(np.asarray(theta, dtype=np.float64))
    usable = np.ones(times.shape, bool) if usable is None else np.asarray(usable, bool)
    pellets = np.asarray(pellets, dtype=np.float64)
    gap = pellets[:, pellet_index("UL")] - pellets[:, pellet_index("LL")]
    aperture = np.hypot(gap[:, 0], gap[:, 1])  # NaN where either lip pellet is untracked
    rows = []
    for seg in labels.segments():
        inside = (times >= seg.start) & (times < seg.end)
        row = dict.fromkeys(SEGMENT_COLUMNS)
        row.update(label=seg.label, start_s=seg.start, end_s=seg.end,
                   frames=int(inside.sum()), status=SegmentStatus.OK.label)
        jaw_k = np.flatnonzero(inside & usable & np.isfinite(theta_deg))
        lip_k = np.flatnonzero(inside & np.isfinite(aperture))
        if jaw_k.size:
            peak = jaw_k[np.argmax(theta_deg[jaw_k])]
            row.update(jaw_peak_opening_deg=float(theta_deg[peak]),
                       jaw_peak_time_s=float(times[peak]),
                       jaw_min_opening_deg=float(theta_deg[jaw_k].min()))
        if lip_k.size:
            low = lip_k[np.argmin(aperture[lip_k])]
            row.update(lip_aperture_max_mm=float(aperture[lip_k].max()),
                       lip_aperture_min_mm=float(aperture[low]),
                       lip_aperture_min_time_s=float(times[low]))
        if not inside.any():
            row["status"] = SegmentStatus.NO_FRAMES.label
        elif not jaw_k.size:
            row["status"] = SegmentStatus.JAW_UNTRACKED.label
        elif not lip_k.size:
            row["status"] = SegmentStatus.LIPS_UNTRACKED.label
        rows.append(row)
    return rows
