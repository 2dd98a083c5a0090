"""The eight XRMB pellets and CASSI's first valid line: the one home of both.

Pellet order (columns of a ``.txy`` file, rows of every ``(..., 8, 2)`` array in the
toolkit): ``UL, LL, T1, T2, T3, T4, MNI, MNM``. MNI and MNM, on the lower incisor and the
mandible's molar, drive the jaw (paper Eqs 1-7).

**The first valid line.** CASSI starts at "the first line with no out-of-range value"
(paper section 2, initialization step 1). Real files lose a pellet for a whole recording
(often T4); the paper's rule then finds no line at all. The rule used everywhere here
(``cassi info``, ``quality_report``, ``txy.first_valid_frame``, ``initialize``, the
calibration) generalises it: *the first line on which every pellet the file ever tracks
is tracked* (x and y). It equals the paper's rule whenever every pellet is tracked
somewhere. A file whose jaw pellets are never tracked has no first valid line
(:class:`~cassi_fit.errors.MissingDataError` naming the file): nothing can be animated.
This module is numpy only.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

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
    """What the rule reads of a track (``txy.PelletTrack`` has it)."""

    valid: np.ndarray  # (n, 8, 2) bool


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


def ever_tracked(valid: np.ndarray) -> np.ndarray:
    """``(8,)`` bool: pellets tracked (x and y) on at least one line of ``valid (n, 8, 2)``."""
    return np.asarray(valid, bool).all(axis=-1).any(axis=0)


def first_valid_line(track: PelletTrackLike, source: str | None = None) -> FirstLine:
    """CASSI's first valid line by the rule of the module docstring.

    ``track``: anything with ``valid (n, 8, 2)`` bool (a ``txy.PelletTrack``); ``source``
    names the file in errors (default: ``track.path``). Raises ``MissingDataError`` if a
    jaw pellet is never tracked, or if no line has every ever-tracked pellet at once.
    """
    where = source_of(track, source)
    tracked_xy = np.asarray(track.valid, bool).all(axis=-1)  # (n, 8)
    ever = tracked_xy.any(axis=0)
    missing = [PELLET_NAMES[j] for j in JAW_INDEX if not ever[j]]
    if missing:
        raise MissingDataError(f"{where}: jaw pellet(s) {', '.join(missing)} never tracked")
    complete = tracked_xy[:, ever].all(axis=1)
    names = tuple(p for p, e in zip(PELLET_NAMES, ever, strict=True) if e)
    if not complete.any():
        raise MissingDataError(f"{where}: no line in which {', '.join(names)} are all tracked")
    return FirstLine(int(np.argmax(complete)), names)
