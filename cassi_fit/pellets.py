"""The eight XRMB pellets and CASSI's first valid line: their one home.

Pellet order (columns of a ``.txy`` file, rows of every ``(..., 8, 2)`` array in the
toolkit): ``UL, LL, T1, T2, T3, T4, MNI, MNM``. MNI and MNM, on the lower incisor and the
mandible's molar, drive the jaw (paper Eqs 1-7).

**The first valid line.** CASSI starts at "the first line with no out-of-range value"
(paper section 2, initialization step 1). Real files lose a pellet for a whole recording
(often T4); the paper's rule then finds no line at all. The one rule used everywhere here
(:func:`first_valid_line`: ``cassi info``, ``quality_report``, ``initialize``, the
calibration, the jaw fit's reference) generalises it: *the first line on which every
pellet the file ever tracks is tracked (x and y) and none of them is mistracked* (the
track's one mistrack detection, ``PelletTrack.mistracks``, :mod:`cassi_fit.mistracks`).
A mistrack on the paper's first line would otherwise set the reference of the whole
recording (every later jaw angle, the subject's scale); the rule moves to the next clean
line and says so (:class:`MistrackedFirstLineWarning`, naming the file and the lines
skipped). It equals the paper's rule whenever every pellet is tracked somewhere and the
first complete line is clean. Given ``pellets`` (e.g. ``JAW_PELLETS`` for the jaw fit's
reference) the same rule looks at those pellets only. A file whose jaw pellets are never
tracked, or with no clean complete line, has no first valid line
(:class:`~cassi_fit.errors.MissingDataError` naming the file). This module is numpy only;
it reads a track's mistracks from the track and never runs the detector itself.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np
from jaxtyping import Bool, Float

from .errors import MissingDataError

#: The pellets in file order.
PELLET_NAMES = ("UL", "LL", "T1", "T2", "T3", "T4", "MNI", "MNM")
#: Indices into ``PELLET_NAMES``.
UL, LL, T1, T2, T3, T4, MNI, MNM = range(8)
#: The two jaw pellets [MNI, MNM], the reference of the jaw motion (paper Eqs 1-7).
JAW_PELLETS = ("MNI", "MNM")
#: Their indices, for fancy indexing: ``positions[..., JAW_INDEX, :]``.
JAW_INDEX = (MNI, MNM)


def pellet_index(name: str) -> int:
    """Index of a pellet in ``PELLET_NAMES`` (case-insensitive); ``ValueError`` if unknown."""
    key = str(name).upper()
    if key not in PELLET_NAMES:
        raise ValueError(f"unknown pellet {name!r}; expected one of {', '.join(PELLET_NAMES)}")
    return PELLET_NAMES.index(key)


class PelletTrackLike(Protocol):
    """What the rule and the detector read of a track (``txy.PelletTrack`` has it).
    ``mistracks``: the track's one mistrack detection (a
    ``cassi_fit.mistracks.MistrackReport``, with ``flags (n, 8)``), read by the rule."""

    times: np.ndarray  # (n,) s
    positions: np.ndarray  # (n, 8, 2) mm, NaN where untracked
    valid: np.ndarray  # (n, 8, 2) bool

    @property
    def frame_step_s(self) -> float: ...  # s between lines (txy.frame_step)

    @property
    def mistracks(self): ...


class MistrackedFirstLineWarning(UserWarning):
    """The first complete line held a mistracked value; the first valid line moved on."""


class FirstLine(NamedTuple):
    """The first valid line of a recording: its 0-based ``index`` and the names of the
    pellets the rule looked at (``tracked``, in ``PELLET_NAMES`` order: by default every
    pellet the file ever tracks)."""

    index: int
    tracked: tuple[str, ...]


def source_of(track: PelletTrackLike, source: str | None = None) -> str:
    """The name used in error messages: ``source``, else the track's file, else a stand-in."""
    if source is not None:
        return str(source)
    path = getattr(track, "path", None)
    return str(path) if path is not None else "<pellet track>"


def ever_tracked(valid: Bool[np.ndarray, "n 8 2"]) -> Bool[np.ndarray, " 8"]:
    """``(8,)`` bool: pellets tracked (x and y) on at least one line of ``valid (n, 8, 2)``."""
    return np.asarray(valid, bool).all(axis=-1).any(axis=0)


def jaw_distance(track: PelletTrackLike) -> Float[np.ndarray, " n"]:
    """``(n,)`` MNI-MNM distance in mm, NaN where either jaw pellet is not fully tracked."""
    positions = np.asarray(track.positions, np.float64)
    ok = np.asarray(track.valid, bool)[:, JAW_INDEX, :].all(axis=(1, 2))
    diff = np.where(ok[:, None], positions[:, MNI] - positions[:, MNM], 0.0)
    return np.where(ok, np.linalg.norm(diff, axis=-1), np.nan)


def _mistracked(track: PelletTrackLike, mistracked) -> np.ndarray:
    """``(n, 8)`` bool: the given mask, else the track's one detection."""
    return np.asarray(track.mistracks.flags if mistracked is None else mistracked, bool)


# ------------------------------------------------------------------ the first valid line
def clean_lines(
    track: PelletTrackLike, pellets: Sequence[int], mistracked: Bool[np.ndarray, "n 8"] | None = None
) -> tuple[Bool[np.ndarray, " n"], Bool[np.ndarray, " n"]]:
    """``(complete, clean)``, each ``(n,)`` bool: lines on which the pellets (indices) are
    all tracked in x and y, and those of them on which none is mistracked
    (``mistracked``: an ``(n, 8)`` mask, default the track's own detection)."""
    cols = list(pellets)
    tracked_xy = np.asarray(track.valid, bool).all(axis=-1)  # (n, 8)
    flags = _mistracked(track, mistracked)
    complete = tracked_xy[:, cols].all(axis=1)
    return complete, complete & ~flags[:, cols].any(axis=1)


def _say_moved(where: str, complete: np.ndarray, index: int, what: str) -> None:
    skipped = np.flatnonzero(complete[:index])
    if skipped.size:
        lines = ", ".join(str(k + 1) for k in skipped[:5]) + (", ..." if skipped.size > 5 else "")
        warnings.warn(
            f"{where}: {what} moved to data line {index + 1}: the {skipped.size} earlier "
            f"complete line(s) ({lines}) hold mistracked values",
            MistrackedFirstLineWarning,
            stacklevel=3,
        )


def first_valid_line(
    track: PelletTrackLike,
    source: str | None = None,
    *,
    pellets: Sequence[str] | None = None,
    mistracked: Bool[np.ndarray, "n 8"] | None = None,
) -> FirstLine:
    """CASSI's first valid line by the one rule of the module docstring: its 0-based
    ``index`` and the pellets it looked at (``tracked``).

    ``track``: a ``txy.PelletTrack`` (times, positions, valid, mistracks); ``source``
    names the file in errors (default: ``track.path``). ``pellets``: None for every
    pellet the file ever tracks (both jaw pellets never tracked raise
    ``MissingDataError``; one jaw sensor, as most articulograph corpora have, is enough),
    or the names of the pellets to look at (e.g. ``JAW_PELLETS``, the jaw fit's
    reference). ``mistracked``: an ``(n, 8)`` mask to use instead of the track's own
    detection. Raises ``MissingDataError`` naming the file if no line has those pellets
    tracked and clean; warns (:class:`MistrackedFirstLineWarning`) when mistracks moved
    the line.
    """
    where = source_of(track, source)
    if pellets is None:
        ever = ever_tracked(track.valid)
        if not any(ever[j] for j in JAW_INDEX):  # one jaw sensor (EMA's usual) is enough
            raise MissingDataError(f"{where}: jaw pellets {', '.join(JAW_PELLETS)} never "
                                   "tracked")
        columns = list(np.flatnonzero(ever))
        what = "first valid line"
    else:
        columns = [pellet_index(p) for p in pellets]
        what = f"first line with {', '.join(PELLET_NAMES[c] for c in columns)}"
    names = tuple(PELLET_NAMES[c] for c in columns)
    complete, clean = clean_lines(track, columns, mistracked)
    listed = ", ".join(names)
    if not complete.any():
        raise MissingDataError(f"{where}: no line in which {listed} are all tracked")
    if not clean.any():
        raise MissingDataError(
            f"{where}: every line with {listed} all tracked holds a mistracked value "
            "(check times and units: see docs/FORMATS.md)"
        )
    index = int(np.argmax(clean))
    _say_moved(where, complete, index, what)
    return FirstLine(index, names)


# ------------------------------------------------------------------ plausibility
#: MNI-MNM distance (mm): lower incisor to lower molar pellet, 20-70 mm for any adult
#: (docs/FORMATS.md, "Plausibility", for the sources).
JAW_DISTANCE_RANGE_MM = (20.0, 70.0)


def robust_positions(
    track: PelletTrackLike, mistracked: Bool[np.ndarray, "n 8"] | None = None
) -> Float[np.ndarray, "8 2"]:
    """``(8, 2)`` mm: each pellet's median position over its tracked, non-mistracked
    frames (over all its tracked frames when fewer than half are clean: a file in the
    wrong units is flagged everywhere); NaN for a pellet never tracked. ``mistracked``:
    an ``(n, 8)`` mask, default the track's own detection."""
    flags = _mistracked(track, mistracked)
    tracked = np.asarray(track.valid, bool).all(axis=-1)
    positions = np.asarray(track.positions, np.float64)
    out = np.full((len(PELLET_NAMES), 2), np.nan)
    for p in range(len(PELLET_NAMES)):
        clean = tracked[:, p] & ~flags[:, p]
        use = clean if clean.sum() * 2 >= tracked[:, p].sum() and clean.any() else tracked[:, p]
        if use.any():
            out[p] = np.median(positions[use, p], axis=0)
    return out


def _units_hint(distance: float) -> str:
    lo, hi = JAW_DISTANCE_RANGE_MM
    if distance * 1000 >= lo and distance * 1000 <= hi:
        return "values look like millimetres; XRMB files are in micrometres"
    if distance > hi:
        return f"coordinates look scaled (about x{distance / 42:.0f} of a real jaw)"
    return "check the units (XRMB files are in micrometres)"


#: Anatomical order that holds for every speaker, on median positions:
#: (a, b, axis, what is wrong): a's median must exceed b's along axis (0 x forward, 1 y up).
_ORDER = (
    (UL, LL, 1, "upper lip UL below lower lip LL"),
    (MNI, MNM, 0, "molar pellet MNM in front of incisor pellet MNI"),
    (T1, T4, 0, "tongue back T4 in front of tongue tip T1"),
    (UL, T1, 0, "tongue tip T1 in front of the upper lip UL"),
)


def plausibility_problem(
    track: PelletTrackLike, mistracked: Bool[np.ndarray, "n 8"] | None = None
) -> str | None:
    """What makes a track's geometry implausible for any speaker, or None if nothing does.

    On :func:`robust_positions` (``mistracked``: an ``(n, 8)`` mask, default the track's
    own detection): the MNI-MNM distance must lie in
    ``JAW_DISTANCE_RANGE_MM`` (with a units hint otherwise); UL above LL; MNM behind MNI;
    T4 behind T1; T1 behind UL (each when both pellets are tracked). The message says
    what is wrong, with the medians, and the likely cause (units, swapped x/y).
    """
    med = robust_positions(track, mistracked)
    if np.isfinite(med[list(JAW_INDEX)]).all():
        distance = float(np.linalg.norm(med[MNI] - med[MNM]))
        lo, hi = JAW_DISTANCE_RANGE_MM
        if not lo <= distance <= hi:
            return (f"median jaw pellet distance MNI-MNM {distance:.4g} mm is outside "
                    f"{lo:.0f}-{hi:.0f} mm: {_units_hint(distance)}")
    for a, b, axis, what in _ORDER:
        if np.isfinite(med[[a, b], axis]).all() and med[a, axis] <= med[b, axis]:
            c = "xy"[axis]
            return (f"{what} (median {c}: {PELLET_NAMES[a]} {med[a, axis]:.1f} mm, "
                    f"{PELLET_NAMES[b]} {med[b, axis]:.1f} mm): are x and y swapped or "
                    "mirrored? (+x forward, +y up; docs/FORMATS.md)")
    return None
