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

from ._io import atomic_write
from .errors import DataFormatError
from .txy import UNTRACKED, parse_int, read_lines

#: kind -> (minimum number of points, description used in messages)
OUTLINE_KINDS = {"palate": (2, "palate outline"), "pharynx": (2, "pharyngeal wall")}


def read_outline(path: str | os.PathLike, *, kind: str = "palate") -> np.ndarray:
    """Read a ``PAL.DAT`` / ``PHA.DAT`` file: ``(n, 2)`` float64 mm, file order.

    ``kind`` is ``"palate"`` or ``"pharynx"``; both need at least 2 points. Raises
    :class:`DataFormatError` naming file and line for a line without exactly two fields,
    a token that is not an integer, the untracked marker 1000000, an empty file, or too
    few points.
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
    return np.asarray(points, dtype=np.float64) / 1e3


def write_outline(path: str | os.PathLike, points_mm: np.ndarray, *, overwrite: bool = False) -> Path:
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
