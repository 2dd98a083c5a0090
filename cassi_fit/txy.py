"""X-ray microbeam pellet files (``.txy``): read, write, first valid frame.

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

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._io import atomic_write, register_input
from .errors import DataFormatError, MissingDataError
from .pellets import JAW_PELLETS, PELLET_NAMES, first_clean_line, first_valid_line, pellet_index

UNTRACKED = 1_000_000  # marker in files, per value (um)
FRAME_STEP_US = 6866  # about 145.6 Hz
N_FIELDS = 1 + 2 * len(PELLET_NAMES)  # 17

# Integers beyond this magnitude cannot be held exactly in float64 (and are no data).
_MAX_ABS_INT = 2**53
_INT_TOKEN = re.compile(r"[+-]?[0-9]+")


@dataclass(frozen=True, eq=False)
class PelletTrack:
    """One pellet file in memory.

    Attributes:
        times: ``(n,)`` float64, seconds.
        positions: ``(n, 8, 2)`` float64, mm, pellet order ``PELLET_NAMES``, last axis
            ``(x, y)``; NaN exactly where ``valid`` is False.
        valid: ``(n, 8, 2)`` bool, False where the file held the marker 1000000.
        path: the file it came from, or None.
    """

    times: np.ndarray
    positions: np.ndarray
    valid: np.ndarray
    path: Path | None = None

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
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "valid", valid)
        if self.path is not None:
            object.__setattr__(self, "path", Path(self.path))

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame (0 for fewer than two frames)."""
        return float(self.times[-1] - self.times[0]) if self.n_frames > 1 else 0.0

    def pellet(self, name: str) -> np.ndarray:
        """``(n, 2)`` mm positions of one pellet (NaN where untracked)."""
        return self.positions[:, pellet_index(name), :]

    def frame_valid(self, pellets: Sequence[str] = PELLET_NAMES) -> np.ndarray:
        """``(n,)`` bool: True where x and y of every pellet in ``pellets`` are tracked."""
        idx = [pellet_index(p) for p in pellets]
        return self.valid[:, idx, :].all(axis=(1, 2))

    def __repr__(self) -> str:
        where = f", path={str(self.path)!r}" if self.path is not None else ""
        return f"PelletTrack(n_frames={self.n_frames}{where})"


def _where(track: PelletTrack) -> str:
    return str(track.path) if track.path is not None else "<pellet track>"


def first_valid_frame(track: PelletTrack, pellets: Sequence[str] | None = None) -> int:
    """Index of CASSI's first valid line (initialisation step 1).

    Default: the one rule of :func:`cassi_fit.pellets.first_valid_line` (the first frame
    in which every pellet the file ever tracks is tracked and none is mistracked;
    ``MissingDataError`` if a jaw pellet is never tracked). With ``pellets``: the same
    rule for those pellets only (:func:`cassi_fit.pellets.first_clean_line`), e.g.
    ``JAW_PELLETS`` for the jaw fit's reference. Raises :class:`MissingDataError` naming
    the file if there is no such frame.
    """
    if pellets is None:
        return first_valid_line(track, _where(track)).index
    return first_clean_line(track, pellets, _where(track))


def require_tracked(track: PelletTrack, pellets: Sequence[str] = JAW_PELLETS) -> None:
    """Raise :class:`MissingDataError` naming the file if any of ``pellets`` is never tracked.

    The jaw method needs MNI and MNM; a file in which one of them never has a valid x and
    y cannot be used for it.
    """
    never = [p for p in pellets if not track.frame_valid((p,)).any()]
    if never:
        raise MissingDataError(f"{_where(track)}: pellet(s) {', '.join(never)} never tracked")


def _decode(path: Path, raw: bytes) -> str:
    """UTF-8 text without a BOM; a decoding failure names the line."""
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise DataFormatError(path, line, "not a text file (invalid UTF-8 byte)") from None


def read_lines(path: str | os.PathLike) -> tuple[Path, list[tuple[int, str]]]:
    """Read a text data file: register it as input, decode, return ``(lineno, line)`` pairs.

    Accepts a UTF-8 BOM, CRLF or LF. Blank (white-space only) lines are dropped; line
    numbers are 1-based in the file as stored. Shared by the toolkit's text readers.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise DataFormatError(path, None, "is a folder, not a file") from None
    except FileNotFoundError:
        raise MissingDataError(f"{path}: no such file") from None
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read: {exc.strerror or exc}") from None
    register_input(path)
    text = _decode(path, raw)
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = [(i + 1, s) for i, s in enumerate(text.split("\n")) if s.strip()]
    return path, lines


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


def read_txy(path: str | os.PathLike) -> PelletTrack:
    """Read a pellet file into a :class:`PelletTrack` (seconds, mm, validity mask).

    Accepts tabs or any white space, CRLF or LF, blank lines (skipped), a UTF-8 BOM.
    Raises :class:`DataFormatError` (file and line) for a wrong field count, a token that
    is not an integer, an empty file, or times that do not strictly increase; and
    :class:`MissingDataError` if no value in the file is tracked at all.
    """
    path, lines = read_lines(path)
    if not lines:
        raise DataFormatError(path, None, "empty file (no data lines)")
    rows = np.array([_parse_row(path, n, s) for n, s in lines], dtype=np.int64)
    times_us = rows[:, 0]
    bad = np.flatnonzero(np.diff(times_us) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise DataFormatError(
            path,
            lines[k][0],
            f"time {times_us[k]} us does not increase (previous {times_us[k - 1]} us)",
        )
    coords = rows[:, 1:].reshape(-1, len(PELLET_NAMES), 2)
    valid = coords != UNTRACKED
    if not valid.any():
        raise MissingDataError(f"{path}: no tracked value at all (every value is {UNTRACKED})")
    positions = np.where(valid, coords / 1e3, np.nan)
    return PelletTrack(times=times_us / 1e6, positions=positions, valid=valid, path=path)


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
