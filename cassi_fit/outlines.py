"""Palate outline (``PAL.DAT``) and pharyngeal wall (``PHA.DAT``) files.

Format (see ``docs/FORMATS.md``): plain text, one point per line, two integer columns x
and y in micrometres in the pellet frame, right-aligned with leading spaces, CRLF line
ends. The palate runs front to back (x decreasing) with 9 to 52 points in real files;
the pharyngeal wall has 2 points. Loaded as ``(n, 2)`` float64 mm.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from jaxtyping import Float

from ._io import atomic_write, read_lines
from .errors import DataFormatError
from .txy import UNTRACKED, parse_int

#: kind -> (minimum number of points, description used in messages)
OUTLINE_KINDS = {"palate": (2, "palate outline"), "pharynx": (2, "pharyngeal wall")}


def read_outline(
    path: str | os.PathLike, *, kind: str = "palate", check: bool = True
) -> Float[np.ndarray, "n 2"]:
    """Read a ``PAL.DAT`` / ``PHA.DAT`` file: ``(n, 2)`` float64 mm, file order.

    ``kind`` is ``"palate"`` or ``"pharynx"``; both need at least 2 points. Raises
    :class:`DataFormatError` naming file and line for a line without exactly two fields,
    a token that is not an integer, the untracked marker 1000000, an empty file, or too
    few points; with ``check`` (default), for an implausible outline
    (:func:`outline_problem`: units, order, position).
    """
    if kind not in OUTLINE_KINDS:
        raise ValueError(f"unknown outline kind {kind!r}; expected one of {sorted(OUTLINE_KINDS)}")
    min_points, what = OUTLINE_KINDS[kind]
    path, lines = read_lines(path)
    if not lines:
        raise DataFormatError(path, None, f"empty file (no {what} points)")
    points = []
    for lineno, line in lines:
        tokens = line.split()
        if len(tokens) != 2:
            raise DataFormatError(
                path, lineno, f"expected 2 fields (x y in um), found {len(tokens)}"
            )
        xy = [parse_int(path, lineno, t) for t in tokens]
        if UNTRACKED in xy:
            raise DataFormatError(path, lineno, f"untracked marker {UNTRACKED} in a {what}")
        points.append(xy)
    if len(points) < min_points:
        raise DataFormatError(
            path, None, f"{what} has {len(points)} point(s); at least {min_points} are needed"
        )
    result = np.asarray(points, dtype=np.float64) / 1e3
    if check:
        problem = outline_problem(result, kind)
        if problem is not None:
            index, message = problem
            raise DataFormatError(path, None if index is None else lines[index][0], message)
    return result


# ------------------------------------------------------------------ plausibility
#: Palate and pharynx positions (mm, pellet frame) any speaker's trace lies within
#: (docs/FORMATS.md, "Plausibility"): the palate starts at or behind the incisor tip and
#: runs back 15-110 mm, above the tip; the pharyngeal wall is well behind the incisors.
PALATE_X_RANGE_MM = (-110.0, 5.0)
PALATE_Y_RANGE_MM = (-5.0, 45.0)
PALATE_MIN_LENGTH_MM = 15.0
#: A palate point may lie at most this far in front of the previous one (the trace
#: climbs the alveolar ridge nearly vertically; anything more is a shuffled order).
PALATE_MAX_FORWARD_STEP_MM = 2.0
PHARYNX_X_RANGE_MM = (-130.0, -20.0)
PHARYNX_Y_RANGE_MM = (-90.0, 60.0)
#: ``PHA.DAT``'s first and last points (the two the wall is built from,
#: ``cassi_fit.pharynx.midline``) must be this far apart in height: the trace covers the
#: wall behind the tongue root over tens of millimetres (JW11: 41 mm; the synthetic
#: subjects: 40 to 57 mm); two points closer than this (coincident ones included) give
#: no direction for the wall.
PHARYNX_MIN_HEIGHT_MM = 10.0
#: ... and the wall runs down more than across (within 45 degrees of vertical): the
#: posterior pharyngeal wall is near vertical (JW11: 0.05 degrees off it; the synthetic
#: subjects: at most 15 degrees).
PHARYNX_MAX_TILT_DEG = 45.0


def _units(points: np.ndarray, x_range: tuple[float, float], y_range: tuple[float, float]
           ) -> str | None:
    """A units hint when the whole outline is tiny (mm written as um) or far too large."""
    size = float(np.max(np.abs(points)))
    if size < 0.2:
        return f"all points within {size:.3g} mm of the origin: values look like millimetres; " \
            "the files are in micrometres"
    limit = max(abs(v) for v in (*x_range, *y_range))
    if size > 2 * limit:
        return f"a point {size:.0f} mm from the origin: coordinates look scaled " \
            f"(about x{size / limit:.0f}); the files are in micrometres"
    return None


def _outside(points: np.ndarray, x_range, y_range, where: str) -> tuple[int, str] | None:
    bad = ((points[:, 0] < x_range[0]) | (points[:, 0] > x_range[1])
           | (points[:, 1] < y_range[0]) | (points[:, 1] > y_range[1]))
    if bad.any():
        k = int(np.argmax(bad))
        x, y = points[k]
        return k, (f"point ({x:.1f}, {y:.1f}) mm is outside x {x_range[0]:.0f}..{x_range[1]:.0f},"
                   f" y {y_range[0]:.0f}..{y_range[1]:.0f} mm ({where}; +x forward, +y up)")
    return None


def _coincident(points: np.ndarray, what: str) -> str | None:
    """A message when every point of an outline is the same point (a degenerate trace)."""
    if np.all(points == points[0]):
        x, y = points[0]
        return (f"all {len(points)} points coincide at ({x:.3f}, {y:.3f}) mm: a degenerate "
                f"{what} (a trace of one point has no shape)")
    return None


def _wall_problem(pts: np.ndarray) -> tuple[int | None, str] | None:
    """The pharyngeal wall's geometry: its end points (the two the wall is built from)
    ``PHARYNX_MIN_HEIGHT_MM`` apart in height, within ``PHARYNX_MAX_TILT_DEG`` of
    vertical."""
    (x0, y0), (x1, y1) = pts[0], pts[-1]
    height, across = abs(y0 - y1), abs(x0 - x1)
    if height < PHARYNX_MIN_HEIGHT_MM:
        return len(pts) - 1, (
            f"a degenerate pharyngeal wall: its first and last points are {height:.1f} mm "
            f"apart in height (y {y0:.1f} and {y1:.1f} mm), not at least "
            f"{PHARYNX_MIN_HEIGHT_MM:.0f} mm: PHA.DAT holds the wall's top and bottom, "
            "which give the wall its direction")
    tilt = float(np.degrees(np.arctan2(across, height)))
    if tilt > PHARYNX_MAX_TILT_DEG:
        return len(pts) - 1, (
            f"the pharyngeal wall runs {tilt:.0f} degrees off vertical (x {x0:.1f} to "
            f"{x1:.1f}, y {y0:.1f} to {y1:.1f} mm), more than {PHARYNX_MAX_TILT_DEG:.0f}: "
            "the posterior wall runs down behind the tongue (x and y swapped?)")
    return None


def outline_problem(
    points: Float[np.ndarray, "n 2"], kind: str = "palate"
) -> tuple[int | None, str] | None:
    """Why an outline (mm, pellet frame) is implausible, as ``(point index or None,
    message)``, or None. Both: not every point the same (a degenerate trace). Palate:
    the units, the position (``PALATE_*_RANGE_MM``: behind the incisor tip and above
    it), the order (front to back, over at least ``PALATE_MIN_LENGTH_MM``, no step
    forward beyond ``PALATE_MAX_FORWARD_STEP_MM``). Pharynx: the units, the position
    (``PHARYNX_*_RANGE_MM``), the wall's end points ``PHARYNX_MIN_HEIGHT_MM`` apart in
    height and within ``PHARYNX_MAX_TILT_DEG`` of vertical."""
    pts = np.asarray(points, dtype=np.float64)
    what = "pharyngeal wall" if kind == "pharynx" else "palate outline"
    same = _coincident(pts, what)
    if same is not None:
        return None, same
    if kind == "pharynx":
        hint = _units(pts, PHARYNX_X_RANGE_MM, PHARYNX_Y_RANGE_MM)
        if hint:
            return None, hint
        return _outside(pts, PHARYNX_X_RANGE_MM, PHARYNX_Y_RANGE_MM,
                        "the pharyngeal wall lies behind the mouth") or _wall_problem(pts)
    hint = _units(pts, PALATE_X_RANGE_MM, PALATE_Y_RANGE_MM)
    if hint:
        return None, hint
    run = pts[0, 0] - pts[-1, 0]
    if run < PALATE_MIN_LENGTH_MM:
        return None, (f"the palate runs {run:.1f} mm from front to back (x {pts[0, 0]:.1f} to "
                      f"{pts[-1, 0]:.1f} mm), not at least {PALATE_MIN_LENGTH_MM:.0f} mm: "
                      "reversed? PAL.DAT runs front to back")
    forward = np.diff(pts[:, 0]) > PALATE_MAX_FORWARD_STEP_MM
    if forward.any():
        k = int(np.argmax(forward)) + 1
        step = pts[k, 0] - pts[k - 1, 0]
        return k, (f"point {k + 1} is {step:.1f} mm in front of the one before: the palate "
                   "must run front to back (points shuffled or zig-zag?)")
    return _outside(pts, PALATE_X_RANGE_MM, PALATE_Y_RANGE_MM,
                    "the palate lies behind and above the upper incisor tip")


def outlines_problem(
    palate: Float[np.ndarray, "n 2"], pharynx: Float[np.ndarray, "m 2"]
) -> str | None:
    """Why a subject's palate and pharyngeal wall (mm, pellet frame) cannot both be
    right, or None: the wall must lie behind the palate's back end (every wall point's x
    below the last palate point's), since the velum hangs between them (JW11: 29 mm
    behind; the synthetic subjects: 5 to 16 mm)."""
    back = float(np.asarray(palate, dtype=np.float64)[-1, 0])
    front = float(np.max(np.asarray(pharynx, dtype=np.float64)[:, 0]))
    if front >= back:
        return (f"the pharyngeal wall (x up to {front:.1f} mm) is not behind the palate's "
                f"back end (x {back:.1f} mm): the velum hangs between them; the wrong "
                "subject's PHA.DAT or PAL.DAT?")
    return None


def write_outline(
    path: str | os.PathLike, points_mm: Float[np.ndarray, "n 2"], *, overwrite: bool = False
) -> Path:
    """Write ``(n, 2)`` mm points as an outline file: integer um, leading spaces, CRLF.

    Rounded to the nearest um, so reading back is exact at that resolution. Written
    atomically; never replaces an input file, nor an existing file unless ``overwrite``.
    """
    path = Path(path)
    pts = np.asarray(points_mm, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 1:
        raise DataFormatError(path, None, f"cannot write: points must be (n, 2), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise DataFormatError(path, None, "cannot write: non-finite outline point")
    um = np.round(pts * 1e3).astype(np.int64)
    if np.any(np.abs(um) >= UNTRACKED):
        raise DataFormatError(path, None, f"cannot write: a point is beyond +-{UNTRACKED} um")
    text = "".join(f" {x:>7d} {y:>7d}\r\n" for x, y in um.tolist())
    return atomic_write(path, text, overwrite=overwrite, data_file=True)
