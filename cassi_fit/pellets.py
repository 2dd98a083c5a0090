"""The eight XRMB pellets, the mistrack detector and CASSI's first valid line: their one home.

Pellet order (columns of a ``.txy`` file, rows of every ``(..., 8, 2)`` array in the
toolkit): ``UL, LL, T1, T2, T3, T4, MNI, MNM``. MNI and MNM, on the lower incisor and the
mandible's molar, drive the jaw (paper Eqs 1-7).

**Mistracks.** :func:`detect_mistracks` flags tracked values that cannot be true movement
(range, jumps, jaw distance; the tests and thresholds are documented in
:mod:`cassi_fit.quality`, which re-exports it). It lives here, beside the rule below,
because the rule needs it and every data module may import this one.

**The first valid line.** CASSI starts at "the first line with no out-of-range value"
(paper section 2, initialization step 1). Real files lose a pellet for a whole recording
(often T4); the paper's rule then finds no line at all. The rule used everywhere here
(``cassi info``, ``quality_report``, ``txy.first_valid_frame``, ``initialize``, the
calibration, the jaw fit's reference) generalises it: *the first line on which every
pellet the file ever tracks is tracked (x and y) and none of them is flagged by*
:func:`detect_mistracks`. A mistrack on the paper's first line would otherwise set the
reference of the whole recording (every later jaw angle, the subject's scale); the rule
moves to the next clean line and says so (:class:`MistrackedFirstLineWarning`, naming the
file and the lines skipped). It equals the paper's rule whenever every pellet is tracked
somewhere and the first complete line is clean. A file whose jaw pellets are never
tracked, or with no clean complete line, has no first valid line
(:class:`~cassi_fit.errors.MissingDataError` naming the file). This module is numpy only.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np
from jaxtyping import Bool, Float
from numpy.lib.stride_tricks import sliding_window_view

from .errors import MissingDataError

#: The pellets in file order.
PELLET_NAMES = ("UL", "LL", "T1", "T2", "T3", "T4", "MNI", "MNM")
#: Indices into ``PELLET_NAMES``.
UL, LL, T1, T2, T3, T4, MNI, MNM = range(8)
#: The two jaw pellets [MNI, MNM], the reference of the jaw motion (paper Eqs 1-7).
JAW_PELLETS = ("MNI", "MNM")
#: Their indices, for fancy indexing: ``positions[..., JAW_INDEX, :]``.
JAW_INDEX = (MNI, MNM)

# Mistrack thresholds (mm, s); documented in cassi_fit.quality's docstring.
PLAUSIBLE_X_MM = (-120.0, 60.0)
PLAUSIBLE_Y_MM = (-90.0, 60.0)
MAX_SPEED_MM_S = 500.0
MEDIAN_WINDOW = 11
JAW_ROBUST_SDS = 5.0
JAW_MIN_DEVIATION_MM = 2.0
_MAD_TO_SD = 1.4826
_NOMINAL_STEP_S = 6866e-6


def pellet_index(name: str) -> int:
    """Index of a pellet in ``PELLET_NAMES`` (case-insensitive); ``ValueError`` if unknown."""
    key = str(name).upper()
    if key not in PELLET_NAMES:
        raise ValueError(f"unknown pellet {name!r}; expected one of {', '.join(PELLET_NAMES)}")
    return PELLET_NAMES.index(key)


class PelletTrackLike(Protocol):
    """What the rule and the detector read of a track (``txy.PelletTrack`` has it)."""

    times: np.ndarray  # (n,) s
    positions: np.ndarray  # (n, 8, 2) mm, NaN where untracked
    valid: np.ndarray  # (n, 8, 2) bool


class MistrackedFirstLineWarning(UserWarning):
    """The first complete line held a mistracked value; the first valid line moved on."""


class FirstLine(NamedTuple):
    """The first valid line of a recording: its 0-based ``index`` and the names of the
    pellets the file ever tracks (``tracked``, in ``PELLET_NAMES`` order)."""

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


# ------------------------------------------------------------------ the mistrack detector
def _frame_step(times: np.ndarray) -> float:
    """Median time between frames (s); the nominal step for fewer than two frames."""
    return float(np.median(np.diff(times))) if times.shape[0] >= 2 else _NOMINAL_STEP_S


def _out_of_range(positions: np.ndarray) -> np.ndarray:
    x, y = positions[..., 0], positions[..., 1]
    with np.errstate(invalid="ignore"):
        bad_x = (x < PLAUSIBLE_X_MM[0]) | (x > PLAUSIBLE_X_MM[1])
        bad_y = (y < PLAUSIBLE_Y_MM[0]) | (y > PLAUSIBLE_Y_MM[1])
    return bad_x | bad_y


def _distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance over the last axis using the coordinates valid in both; NaN if none."""
    d2 = (a - b) ** 2
    none = np.isnan(d2).all(axis=-1)
    return np.where(none, np.nan, np.sqrt(np.nansum(d2, axis=-1)))


def running_median(values: Float[np.ndarray, "n ..."]) -> Float[np.ndarray, "n ..."]:
    """NaN-aware median over ``MEDIAN_WINDOW`` frames centred on each frame (axis 0).

    NaN where a window holds no value. Sorting puts NaN last, so the median of the
    ``count`` values is the mean of the sorted entries ``(count - 1) // 2`` and
    ``count // 2`` (several times faster than ``np.nanmedian``).
    """
    half = MEDIAN_WINDOW // 2
    pad = np.full((half,) + values.shape[1:], np.nan)
    windows = sliding_window_view(np.concatenate([pad, values, pad]), MEDIAN_WINDOW, axis=0)
    ordered = np.sort(windows, axis=-1)
    count = np.sum(~np.isnan(windows), axis=-1, keepdims=True)
    lo = np.take_along_axis(ordered, np.maximum(count - 1, 0) // 2, axis=-1)
    hi = np.take_along_axis(ordered, count // 2, axis=-1)
    return np.where(count > 0, 0.5 * (lo + hi), np.nan)[..., 0]


def _jumps(track: PelletTrackLike, speed: float, step_s: float) -> np.ndarray:
    """``(n, 8)`` bool: too far from the running median, or a spike (quality's test 2).

    Near gaps and file ends the window is one-sided and its median lags; it then stands
    for the median time of the frames it holds, so a pellet may be ``speed`` times that
    time difference further away (plus one frame's travel).
    """
    positions = np.asarray(track.positions, np.float64)
    times_s = np.asarray(track.times, np.float64)
    n = positions.shape[0]
    tracked = np.asarray(track.valid, bool).any(axis=-1)  # (n, 8)
    median_time = running_median(np.where(tracked, times_s[:, None], np.nan))
    allowed = speed * (step_s + np.abs(times_s[:, None] - median_time))
    with np.errstate(invalid="ignore"):
        far = _distance(positions, running_median(positions)) > allowed
        step = np.full((n + 1, 8), np.nan)
        step[1:n] = _distance(positions[1:], positions[:-1])
        spike = (step[:-1] > speed * step_s) & (step[1:] > speed * step_s)
    return far | spike


def jaw_distance(track: PelletTrackLike) -> Float[np.ndarray, " n"]:
    """``(n,)`` MNI-MNM distance in mm, NaN where either jaw pellet is not fully tracked."""
    positions = np.asarray(track.positions, np.float64)
    ok = np.asarray(track.valid, bool)[:, JAW_INDEX, :].all(axis=(1, 2))
    diff = np.where(ok[:, None], positions[:, MNI] - positions[:, MNM], 0.0)
    return np.where(ok, np.linalg.norm(diff, axis=-1), np.nan)


def _jaw_outliers(distance: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: jaw distance far from its median (quality's test 3)."""
    ok = np.isfinite(distance)
    if ok.sum() < 3:
        return np.zeros(distance.shape, bool)
    median = np.median(distance[ok])
    robust_sd = _MAD_TO_SD * np.median(np.abs(distance[ok] - median))
    limit = max(JAW_ROBUST_SDS * robust_sd, JAW_MIN_DEVIATION_MM)
    return ok & (np.abs(np.where(ok, distance, median) - median) > limit)


def detect_mistracks(track: PelletTrackLike) -> Bool[np.ndarray, "n 8"]:
    """``(n, 8)`` bool: True where a tracked pellet value cannot be true movement.

    ``track``: a ``txy.PelletTrack`` (times s, positions mm, valid mask). Values marked
    untracked (1000000) are never flagged here; they are already in ``track.valid``. The
    three tests and their thresholds are documented in :mod:`cassi_fit.quality`.
    """
    valid = np.asarray(track.valid, bool)
    flags = _out_of_range(np.asarray(track.positions, np.float64))
    flags |= _jumps(track, MAX_SPEED_MM_S, _frame_step(np.asarray(track.times, np.float64)))
    jaw = _jaw_outliers(jaw_distance(track))
    cols = list(JAW_INDEX)
    one_known = flags[:, cols].sum(axis=-1) == 1  # the jump tests already found the culprit
    flags[:, cols] |= (jaw & ~one_known)[:, None]
    return flags & valid.any(axis=-1)


# ------------------------------------------------------------------ the first valid line
def clean_lines(
    track: PelletTrackLike, pellets: Sequence[int], mistracked: Bool[np.ndarray, "n 8"] | None = None
) -> tuple[Bool[np.ndarray, " n"], Bool[np.ndarray, " n"]]:
    """``(complete, clean)``, each ``(n,)`` bool: lines on which the pellets (indices) are
    all tracked in x and y, and those of them on which none is mistracked."""
    cols = list(pellets)
    tracked_xy = np.asarray(track.valid, bool).all(axis=-1)  # (n, 8)
    flags = detect_mistracks(track) if mistracked is None else np.asarray(mistracked, bool)
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
    mistracked: Bool[np.ndarray, "n 8"] | None = None,
) -> FirstLine:
    """CASSI's first valid line by the rule of the module docstring.

    ``track``: a ``txy.PelletTrack`` (times, positions, valid); ``source`` names the file
    in errors (default: ``track.path``); ``mistracked``: a precomputed
    :func:`detect_mistracks` mask (computed when None). Raises ``MissingDataError`` if a
    jaw pellet is never tracked, or if no line has every ever-tracked pellet tracked and
    clean; warns (:class:`MistrackedFirstLineWarning`) when mistracks moved the line.
    """
    where = source_of(track, source)
    ever = ever_tracked(track.valid)
    missing = [PELLET_NAMES[j] for j in JAW_INDEX if not ever[j]]
    if missing:
        raise MissingDataError(f"{where}: jaw pellet(s) {', '.join(missing)} never tracked")
    names = tuple(p for p, e in zip(PELLET_NAMES, ever, strict=True) if e)
    index = _first_clean(track, np.flatnonzero(ever), names, where, mistracked,
                         "first valid line")
    return FirstLine(index, names)


def first_clean_line(
    track: PelletTrackLike,
    pellets: Sequence[str],
    source: str | None = None,
    *,
    mistracked: Bool[np.ndarray, "n 8"] | None = None,
) -> int:
    """The same rule for the given ``pellets`` only (e.g. ``JAW_PELLETS`` for the jaw
    fit's reference): the first line on which they are all tracked and none is
    mistracked. ``MissingDataError`` naming the file if there is none."""
    where = source_of(track, source)
    return _first_clean(track, [pellet_index(p) for p in pellets], tuple(pellets), where,
                        mistracked, f"first line with {', '.join(pellets)}")


def _first_clean(track, columns, names, where, mistracked, what) -> int:
    """The first line on which the pellets ``columns`` (named ``names``) are all tracked and
    none is mistracked; ``MissingDataError`` naming ``where`` if there is none; warns when
    mistracks moved the line (``what`` names it in the warning)."""
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
    return index


# ------------------------------------------------------------------ plausibility
#: MNI-MNM distance (mm): lower incisor to lower molar pellet, 20-70 mm for any adult
#: (docs/FORMATS.md, "Plausibility", for the sources).
JAW_DISTANCE_RANGE_MM = (20.0, 70.0)


def robust_positions(
    track: PelletTrackLike, mistracked: Bool[np.ndarray, "n 8"] | None = None
) -> Float[np.ndarray, "8 2"]:
    """``(8, 2)`` mm: each pellet's median position over its tracked, non-mistracked
    frames (over all its tracked frames when fewer than half are clean: a file in the
    wrong units is flagged everywhere); NaN for a pellet never tracked. ``mistracked``
    None: the detector's range and jaw-distance tests only (:func:`static_mistracks`)."""
    flags = static_mistracks(track) if mistracked is None else np.asarray(mistracked, bool)
    tracked = np.asarray(track.valid, bool).all(axis=-1)
    positions = np.asarray(track.positions, np.float64)
    out = np.full((len(PELLET_NAMES), 2), np.nan)
    for p in range(len(PELLET_NAMES)):
        clean = tracked[:, p] & ~flags[:, p]
        use = clean if clean.sum() * 2 >= tracked[:, p].sum() and clean.any() else tracked[:, p]
        if use.any():
            out[p] = np.median(positions[use, p], axis=0)
    return out


def static_mistracks(track: PelletTrackLike) -> Bool[np.ndarray, "n 8"]:
    """``(n, 8)`` bool: :func:`detect_mistracks` without its jump test (range and jaw
    distance only). Several times faster; enough for medians, which the jump test's
    isolated excursions of at most five frames cannot move (used on reading a file)."""
    flags = _out_of_range(np.asarray(track.positions, np.float64))
    flags[:, list(JAW_INDEX)] |= _jaw_outliers(jaw_distance(track))[:, None]
    return flags & np.asarray(track.valid, bool).any(axis=-1)


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

    On :func:`robust_positions` (``mistracked``: a :func:`detect_mistracks` mask, or None
    for :func:`static_mistracks`): the MNI-MNM distance must lie in
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
