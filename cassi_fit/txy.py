"""X-ray microbeam pellet files (``.txy``): read, write.

The format (see ``docs/FORMATS.md``): plain text, one frame per line, 17 integer fields
separated by white space (tabs in the distribution): time in microseconds, then x and y
in micrometres for ``UL, LL, T1, T2, T3, T4, MNI, MNM``. The value ``1000000`` marks an
untracked value, per value. Real files start with rows that are all untracked, the first
at time 0; frames are 6866 us apart (about 145.6 Hz). Coordinates are in the pellet
frame: origin at the tip of the upper incisors, +x toward the front of the face, +y up.

In memory a :class:`PelletTrack` holds seconds and millimetres with a per-value validity
mask; positions are NaN exactly where the mask is False. This module is numpy only.
"""

from __future__ import annotations

import functools
import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import Bool, Float

from ._io import atomic_write, read_lines

if TYPE_CHECKING:
    from .mistracks import MistrackReport
from .errors import DataFormatError, MissingDataError
from .pellets import JAW_PELLETS, PELLET_NAMES, pellet_index, plausibility_problem

UNTRACKED = 1_000_000  # marker in files, per value (um)
FRAME_STEP_US = 6866  # about 145.6 Hz
N_FIELDS = 1 + 2 * len(PELLET_NAMES)  # 17

# Integers beyond this magnitude cannot be held exactly in float64 (and are no data).
_MAX_ABS_INT = 2**53
_INT_TOKEN = re.compile(r"[+-]?[0-9]+")
#: :data:`_INT_TOKEN` s joined by single spaces.
_INT_TOKENS = re.compile(r"[+-]?[0-9]+(?: [+-]?[0-9]+)*")


def frame_step(times: Float[np.ndarray, " n"]) -> float:
    """Seconds between data lines of frame ``times (n,)`` s: the median time step; XRMB's
    nominal ``FRAME_STEP_US`` for fewer than two frames. The one rule of a recording's
    line period (``PelletTrack.frame_step_s``, the sound's length, the evaluation's
    sustain window)."""
    times = np.asarray(times, np.float64)
    if times.shape[0] < 2:
        return FRAME_STEP_US * 1e-6
    return float(np.median(np.diff(times)))


@dataclass(frozen=True, eq=False)
class PelletTrack:
    """One pellet file in memory.

    Attributes:
        times: ``(n,)`` float64, seconds.
        positions: ``(n, 8, 2)`` float64, mm, pellet order ``PELLET_NAMES``, last axis
            ``(x, y)``; NaN exactly where ``valid`` is False.
        valid: ``(n, 8, 2)`` bool, False where the file held the marker 1000000.
        path: the file it came from, or None.
        extra_names: names of sensors with no CASSI role (an articulograph's velum, lip
            corners, parasagittal tongue or reference sensors), ``k`` of them; empty for
            XRMB files.
        extra_positions: ``(n, k, 2)`` float64 mm in the same frame as ``positions``, NaN
            exactly where ``extra_valid`` is False (``(n, 0, 2)`` when there are none).
        extra_valid: ``(n, k, 2)`` bool.

    A role with no sensor (e.g. T4 with three tongue sensors, MNM with one jaw sensor) is
    never valid. :attr:`frame_step_s` is the median time step: nothing may assume XRMB's
    6866 us (articulographs record at 50 to 500 Hz).
    """

    times: np.ndarray
    positions: np.ndarray
    valid: np.ndarray
    path: Path | None = None
    extra_names: tuple[str, ...] = ()
    extra_positions: np.ndarray | None = None
    extra_valid: np.ndarray | None = None

    def __post_init__(self):
        times = np.asarray(self.times, dtype=np.float64)
        valid = np.asarray(self.valid, dtype=bool)
        positions = np.where(valid, np.asarray(self.positions, dtype=np.float64), np.nan)
        n = times.shape[0] if times.ndim == 1 else -1
        if times.ndim != 1 or positions.shape != (n, len(PELLET_NAMES), 2):
            raise ValueError(
                f"PelletTrack: times must be (n,) and positions (n, 8, 2); got "
                f"{times.shape} and {positions.shape}"
            )
        if valid.shape != positions.shape:
            raise ValueError(
                f"PelletTrack: valid has shape {valid.shape}, expected {positions.shape}"
            )
        _check_times(self.path, times, warn_gaps=False)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "valid", valid)
        if self.path is not None:
            object.__setattr__(self, "path", Path(self.path))
        self._set_extras(n)

    def _set_extras(self, n: int) -> None:
        """Normalise the extra sensors: a tuple of names, ``(n, k, 2)`` arrays, NaN where
        not valid; a shape that does not match the names is a ``ValueError``."""
        names = tuple(str(s) for s in self.extra_names)
        k = len(names)
        if self.extra_positions is None and self.extra_valid is None:
            extra = np.full((n, k, 2), np.nan)
            valid = np.zeros((n, k, 2), bool)
        else:
            extra = np.asarray(self.extra_positions, dtype=np.float64)
            valid = (np.isfinite(extra) if self.extra_valid is None
                     else np.asarray(self.extra_valid, dtype=bool))
        if extra.shape != (n, k, 2) or valid.shape != (n, k, 2):
            raise ValueError(
                f"PelletTrack: extra_positions and extra_valid must be ({n}, {k}, 2) for "
                f"{k} extra sensor(s); got {extra.shape} and {valid.shape}"
            )
        if len(set(names)) != k:
            raise ValueError(f"PelletTrack: extra sensor names repeat: {names}")
        object.__setattr__(self, "extra_names", names)
        object.__setattr__(self, "extra_positions", np.where(valid, extra, np.nan))
        object.__setattr__(self, "extra_valid", valid)

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])

    @property
    def frame_step_s(self) -> float:
        """Seconds between data lines: the median time step (XRMB 6.866 ms; MOCHA 2 ms,
        mngu0 5 ms, AG501 4 ms, SPARC 20 ms); XRMB's nominal ``FRAME_STEP_US`` for a track
        of fewer than two frames. The one home of a recording's line period: nothing else
        assumes XRMB's 6866 us."""
        return frame_step(self.times)

    @property
    def length_s(self) -> float:
        """The recording's length (s): time 0 to the end of its last frame (the last time
        plus one line period, :attr:`frame_step_s`); 0 for a track without frames. What its
        sound and labels are checked against."""
        if self.n_frames == 0:
            return 0.0
        return float(self.times[-1] + self.frame_step_s)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame (0 for fewer than two frames)."""
        return float(self.times[-1] - self.times[0]) if self.n_frames > 1 else 0.0

    @functools.cached_property
    def mistracks(self) -> MistrackReport:
        """The track's one mistrack detection (:func:`cassi_fit.mistracks.detect`),
        computed on first use and kept: every user reads this one result. The arrays
        must not be changed in place after it is computed."""
        from .mistracks import detect

        return detect(self)

    def extra(self, name: str) -> Float[np.ndarray, "n 2"]:
        """``(n, 2)`` mm positions of the extra sensor ``name`` (NaN where untracked);
        ``ValueError`` naming the extra sensors if there is no such sensor."""
        if name not in self.extra_names:
            known = ", ".join(self.extra_names) or "none"
            raise ValueError(f"no extra sensor {name!r} (extra sensors: {known})")
        return self.extra_positions[:, self.extra_names.index(name), :]

    def pellet(self, name: str) -> Float[np.ndarray, "n 2"]:
        """``(n, 2)`` mm positions of one pellet (NaN where untracked)."""
        return self.positions[:, pellet_index(name), :]

    def frame_valid(self, pellets: Sequence[str] = PELLET_NAMES) -> Bool[np.ndarray, " n"]:
        """``(n,)`` bool: True where x and y of every pellet in ``pellets`` are tracked."""
        idx = [pellet_index(p) for p in pellets]
        return self.valid[:, idx, :].all(axis=(1, 2))

    def __repr__(self) -> str:
        where = f", path={str(self.path)!r}" if self.path is not None else ""
        extra = f", extra_names={self.extra_names!r}" if self.extra_names else ""
        return f"PelletTrack(n_frames={self.n_frames}{extra}{where})"


def _where(track: PelletTrack) -> str:
    return str(track.path) if track.path is not None else "<pellet track>"


def require_tracked(track: PelletTrack, pellets: Sequence[str] = JAW_PELLETS) -> None:
    """Raise :class:`MissingDataError` naming the file if any of ``pellets`` is never tracked.

    The jaw method needs MNI and MNM; a file in which one of them never has a valid x and
    y cannot be used for it.
    """
    never = [p for p in pellets if not track.frame_valid((p,)).any()]
    if never:
        raise MissingDataError(f"{_where(track)}: pellet(s) {', '.join(never)} never tracked")


#: Times: XRMB tasks last seconds to about a minute; three hours (1.5 million frames) is
#: beyond any recording, while long synthetic or concatenated files (200k lines = 23
#: minutes) stay readable.
MAX_TIME_S = 3 * 3600.0
#: No recording pauses this long between two frames: an error naming the line.
MAX_GAP_S = 60.0
#: Frame spacing (median step) accepted: 1 to 100 ms (the files' is 6.866 ms).
FRAME_STEP_RANGE_S = (1e-3, 0.1)
#: A step longer than this between two frames is reported (TimeGapWarning).
LONG_GAP_S = 1.0


class TimeGapWarning(UserWarning):
    """Two consecutive frames of a pellet file are more than ``LONG_GAP_S`` apart."""


def _check_times(path: Path | None, times: np.ndarray, lines: Sequence[int] | None = None,
                 *, warn_gaps: bool = True) -> None:
    """Refuse times that are not finite, negative, beyond ``MAX_TIME_S``, not strictly
    increasing or with a gap over ``MAX_GAP_S``; warn about a gap over ``LONG_GAP_S``. ``times`` in s; ``lines``:
    the file's line number of each frame (for messages), else frame numbers."""
    where = path if path is not None else "<pellet track>"
    line = (lambda k: lines[k]) if lines is not None else (lambda k: None)
    at = "" if lines is not None else " (frame {k})"
    checks = (
        (~np.isfinite(times), "time is not a finite number"),
        (times < 0, "time {t} us is negative (XRMB times start at 0)"),
        (times > MAX_TIME_S, "time {t} us is beyond " + f"{MAX_TIME_S:.0f} s, longer than any "
         "XRMB task (times must be in microseconds)"),
    )
    for bad, message in checks:
        if bad.any():
            k = int(np.argmax(bad))
            t = f"{times[k] * 1e6:.0f}" if np.isfinite(times[k]) else str(times[k])
            raise DataFormatError(where, line(k), message.format(t=t) + at.format(k=k))
    steps = np.diff(times)
    if (steps <= 0).any():
        k = int(np.argmax(steps <= 0)) + 1
        raise DataFormatError(where, line(k), f"time {times[k] * 1e6:.0f} us does not increase "
                              f"(previous {times[k - 1] * 1e6:.0f} us){at.format(k=k)}")
    if (steps > MAX_GAP_S).any():
        k = int(np.argmax(steps > MAX_GAP_S)) + 1
        raise DataFormatError(where, line(k), f"{steps[k - 1]:.0f} s gap after the previous "
                              f"frame (more than {MAX_GAP_S:.0f} s: a wrong time?){at.format(k=k)}")
    if warn_gaps and steps.size and (steps > LONG_GAP_S).any():
        k = int(np.argmax(steps > LONG_GAP_S)) + 1
        name = f"{where}:{line(k)}" if lines is not None else f"{where} (frame {k})"
        warnings.warn(f"{name}: {steps[k - 1]:.1f} s gap after the previous frame "
                      "(sound and pellets may not line up there)", TimeGapWarning, stacklevel=4)


def _check_frame_step(path: Path, times: np.ndarray) -> None:
    """The median frame spacing must be a plausible XRMB rate (``FRAME_STEP_RANGE_S``)."""
    if times.size < 2:
        return
    step = frame_step(times)
    lo, hi = FRAME_STEP_RANGE_S
    if not lo <= step <= hi:
        raise DataFormatError(path, None, f"median frame spacing {step * 1e6:.0f} us is outside "
                              f"{lo * 1e6:.0f}-{hi * 1e6:.0f} us (XRMB frames are {FRAME_STEP_US} "
                              "us apart; are the times in microseconds?)")


def parse_int(path: Path, lineno: int, token: str) -> int:
    """A decimal integer token (ASCII digits, optional sign) or a DataFormatError."""
    if not _INT_TOKEN.fullmatch(token):
        raise DataFormatError(path, lineno, f"not an integer: {token[:40]!r}")
    if len(token) > 20:  # before int(): Python refuses to parse very long digit strings
        raise DataFormatError(path, lineno, f"integer out of range: {token[:40]}...")
    value = int(token)
    if abs(value) > _MAX_ABS_INT:
        raise DataFormatError(path, lineno, f"integer out of range: {token[:40]}")
    return value


def _parse_row(path: Path, lineno: int, line: str) -> list[int]:
    tokens = line.split()
    if len(tokens) != N_FIELDS:
        raise DataFormatError(
            path,
            lineno,
            f"expected {N_FIELDS} fields (time, then x y for 8 pellets), found {len(tokens)}",
        )
    try:  # fast path; the checked path below finds and names the bad token
        if all(_INT_TOKEN.fullmatch(t) for t in tokens):
            values = [int(t) for t in tokens]
            if max(abs(v) for v in values) <= _MAX_ABS_INT:
                return values
    except ValueError:
        pass
    return [parse_int(path, lineno, t) for t in tokens]


def _parse_rows(path: Path, lines: list[tuple[int, str]]) -> np.ndarray:
    """``(n, 17)`` int64: every line's fields (:func:`_parse_row`). A whole file of
    well-formed lines is checked at once (one match over its tokens, 2-3x faster); any
    other file line by line, which finds and names the first bad one."""
    split = [s.split() for _, s in lines]
    if all(len(tokens) == N_FIELDS for tokens in split):
        flat = [t for tokens in split for t in tokens]
        if _INT_TOKENS.fullmatch(" ".join(flat)):
            values = list(map(int, flat))
            if max(map(abs, values)) <= _MAX_ABS_INT:
                return np.array(values, dtype=np.int64).reshape(len(split), N_FIELDS)
    return np.array([_parse_row(path, n, s) for n, s in lines], dtype=np.int64)


def read_txy(path: str | os.PathLike, *, check: bool = True) -> PelletTrack:
    """Read a pellet file into a :class:`PelletTrack` (seconds, mm, validity mask).

    Accepts tabs or any white space, CRLF or LF, blank lines (skipped), a UTF-8 BOM.
    Raises :class:`DataFormatError` (file and line) for a wrong field count, a token that
    is not an integer, an empty file, times that are negative, beyond ``MAX_TIME_S``,
    that do not strictly increase or jump by more than ``MAX_GAP_S``, a frame spacing outside ``FRAME_STEP_RANGE_S``; with
    ``check`` (default), for implausible geometry or units
    (:func:`cassi_fit.pellets.plausibility_problem`); and :class:`MissingDataError` if no
    value in the file is tracked at all. A gap over ``LONG_GAP_S`` warns
    (:class:`TimeGapWarning`, naming the line).
    """
    path, lines = read_lines(path)
    if not lines:
        raise DataFormatError(path, None, "empty file (no data lines)")
    rows = _parse_rows(path, lines)
    times = rows[:, 0] / 1e6
    _check_times(path, times, [n for n, _ in lines])
    coords = rows[:, 1:].reshape(-1, len(PELLET_NAMES), 2)
    valid = coords != UNTRACKED
    if not valid.any():
        raise MissingDataError(f"{path}: no tracked value at all (every value is {UNTRACKED})")
    positions = np.where(valid, coords / 1e3, np.nan)
    track = PelletTrack(times=times, positions=positions, valid=valid, path=path)
    if check:
        _check_frame_step(path, times)
        problem = plausibility_problem(track)
        if problem is not None:
            raise DataFormatError(path, None, problem)
    return track


def _to_int_rows(path: Path, track: PelletTrack) -> np.ndarray:
    """``(n, 17)`` int64 rows: us, um, markers; refuses values the format cannot hold."""
    if not np.all(np.isfinite(track.times)):
        raise DataFormatError(path, None, "cannot write: non-finite time")
    times_us = np.round(track.times * 1e6).astype(np.int64)
    if np.any(np.diff(times_us) <= 0):
        raise DataFormatError(
            path, None, "cannot write: times do not strictly increase at 1 us resolution"
        )
    pos = np.where(track.valid, track.positions, 0.0)
    if not np.all(np.isfinite(pos)):
        raise DataFormatError(path, None, "cannot write: a position marked valid is not finite")
    um = np.round(pos * 1e3).astype(np.int64)
    if np.any(track.valid & (np.abs(um) >= UNTRACKED)):
        raise DataFormatError(
            path, None, f"cannot write: a valid position is beyond +-{UNTRACKED} um"
        )
    um = np.where(track.valid, um, UNTRACKED)
    return np.concatenate([times_us[:, None], um.reshape(-1, 2 * len(PELLET_NAMES))], axis=1)


def write_txy(path: str | os.PathLike, track: PelletTrack, *, overwrite: bool = False) -> Path:
    """Write ``track`` as a pellet file: integer us and um, tab separated, CRLF line ends.

    Untracked values are written as 1000000. Values are rounded to the nearest um / us,
    so ``read_txy(write_txy(p, t))`` reproduces ``t`` exactly at that resolution. Written
    atomically; never replaces an input file, nor an existing file unless ``overwrite``.
    """
    path = Path(path)
    rows = _to_int_rows(path, track)
    text = "".join("\t".join(map(str, r)) + "\r\n" for r in rows.tolist())
    return atomic_write(path, text, overwrite=overwrite, data_file=True)


def pad_untracked(track: PelletTrack, n_rows: int) -> PelletTrack:
    """Prepend ``n_rows`` all-untracked frames, one frame step apart, as real files have.

    The new first frame is at ``track.times[0] - n_rows * FRAME_STEP_US``, which must not
    be negative (real files start at time 0).
    """
    step = FRAME_STEP_US * 1e-6
    t0 = track.times[0] - n_rows * step
    if n_rows < 0 or t0 < -1e-9:
        raise ValueError(f"cannot prepend {n_rows} rows before t = {track.times[0]:.6f} s")
    lead = t0 + step * np.arange(n_rows)
    shape = (n_rows, len(PELLET_NAMES), 2)
    return PelletTrack(
        times=np.concatenate([lead, track.times]),
        positions=np.concatenate([np.full(shape, np.nan), track.positions]),
        valid=np.concatenate([np.zeros(shape, bool), track.valid]),
        path=track.path,
    )
