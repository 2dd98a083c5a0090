"""What every articulograph reader returns: :class:`RawEma`, sensors in the file's own frame.

A reader turns one file into named sensors with positions in millimetres (the file's units
converted), in the file's axes and origin, NaN where a value is untracked; nothing is
mapped, corrected or rotated yet (:mod:`cassi_fit.ema.track` does that). Shared helpers:
reading a file's bytes (regular files only, registered as input so no writer replaces
it), splitting channel names into sensor and axis, telling a number from a name in a
header, and the checks on times.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import Float

from .._io import register_input
from ..errors import DataFormatError, MissingDataError

if TYPE_CHECKING:
    from ..labels import Labels
    from ..sound import Sound

#: Axis suffixes of position channels (``ul_x``, ``T1_py``, ``UL.X``), and of orientation or
#: quality channels that are kept aside (never mistaken for a position).
POSITION_AXES = {"x": 0, "y": 1, "z": 2, "px": 0, "py": 1, "pz": 2, "posx": 0, "posy": 1,
                 "posz": 2, "tx": 0, "ty": 1, "tz": 2}
OTHER_AXES = ("ox", "oy", "oz", "phi", "theta", "rms", "q0", "qx", "qy", "qz", "extra",
              "ph", "pt", "az", "el")
_SPLIT = re.compile(r"^(?P<sensor>.*?)[\s_.\-]*(?P<axis>[A-Za-z0-9]+)$")


@dataclass(frozen=True, eq=False)
class RawEma:
    """One articulograph recording as its file holds it (units converted to mm).

    Attributes:
        format: the format family (``"est"``, ``"ag500"``, ``"ag501"``, ``"wave"``,
            ``"mview"``, ``"array"``).
        times: ``(n,)`` float64 seconds, strictly increasing.
        names: the ``k`` sensor names as the file spells them (stripped).
        positions: ``(n, k, d)`` float64 mm, ``d`` = 2 (midsagittal data) or 3, in the
            file's axes and origin; NaN where untracked (per value).
        rate_hz: the sampling rate the file states, else ``1 / median step``.
        units: what the file's numbers were and the factor applied (for the report).
        axes: what the file's axes are, with the source of that fact.
        frame: a documented frame convention (``"mocha"``) or None (unknown: a device
            frame, to be corrected and rotated).
        path: the file read, or None.
        orientation: ``(n, k, q)`` sensor orientation values (angles or quaternions) as in
            the file, or None.
        notes: anything the reader decided that a user should know (unused channels...).
        sound: the sound stored inside the file (a :class:`cassi_fit.sound.Sound`: mview's
            ``AUDIO`` channel, an EMU bundle's media file), or None.
        labels: the label tiers stored inside the file (:class:`cassi_fit.labels.Labels`:
            mview ``WORDS``/``PHONES``/``LABELS``, an EMU bundle's levels), or ``()``.
    """

    format: str
    times: np.ndarray
    names: tuple[str, ...]
    positions: np.ndarray
    rate_hz: float
    units: str
    axes: str
    frame: str | None = None
    path: Path | None = None
    orientation: np.ndarray | None = None
    notes: tuple[str, ...] = field(default=())
    sound: Sound | None = None
    labels: tuple[Labels, ...] = field(default=())

    def __post_init__(self):
        times = np.asarray(self.times, dtype=np.float64)
        positions = np.asarray(self.positions, dtype=np.float64)
        names = tuple(str(s) for s in self.names)
        if times.ndim != 1 or positions.ndim != 3 or positions.shape[:2] != (
                times.shape[0], len(names)) or positions.shape[2] not in (2, 3):
            raise ValueError(f"RawEma: times (n,), positions (n, k, 2 or 3) for k names; got "
                             f"{times.shape}, {positions.shape}, {len(names)} names")
        if len(set(names)) != len(names):
            dup = sorted({s for s in names if names.count(s) > 1})
            raise DataFormatError(self.path, None, f"sensor name(s) {', '.join(dup)} appear "
                                  "twice")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "notes", tuple(self.notes))
        object.__setattr__(self, "labels", tuple(self.labels))
        if self.path is not None:
            object.__setattr__(self, "path", Path(self.path))

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])

    @property
    def dims(self) -> int:
        """2 for midsagittal data, 3 for 3D articulographs."""
        return int(self.positions.shape[2])

    def sensor(self, name: str) -> Float[np.ndarray, "n d"]:
        """``(n, d)`` mm positions of one sensor (NaN where untracked)."""
        return self.positions[:, self.names.index(name), :]


def read_bytes(path: str | os.PathLike, what: str = "file") -> tuple[Path, bytes]:
    """The bytes of a regular file, registered as input; one clear error otherwise."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
        if stat.S_ISDIR(mode):
            raise DataFormatError(path, None, "is a folder, not a file")
        if not stat.S_ISREG(mode):
            raise DataFormatError(path, None, "not a regular file (a pipe, device or socket)")
        raw = path.read_bytes()
    except FileNotFoundError:
        raise MissingDataError(f"{path}: no such {what}") from None
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read: {exc.strerror or exc}") from None
    register_input(path)
    return path, raw


def split_channel(name: str) -> tuple[str, str | None]:
    """``(sensor, axis)`` of a channel name: ``"ul_x"`` -> ``("ul", "x")``, ``"T1_py"`` ->
    ``("T1", "py")``, ``"UL X"`` -> ``("UL", "x")``; axis None when the name has no axis
    suffix. The axis is lower case; the sensor keeps the file's spelling."""
    text = name.strip()
    match = _SPLIT.match(text)
    if match and match.group("sensor"):
        axis = match.group("axis").lower()
        if axis in POSITION_AXES or axis in OTHER_AXES:
            return match.group("sensor").strip(" _.-"), axis
    return text, None


def check_times(path: Path | None, times: np.ndarray, lines: list[int] | None = None) -> None:
    """Times must be finite and strictly increasing: a :class:`DataFormatError` naming the
    line (``lines[k]`` is frame k's line in a text file) or the frame otherwise."""
    where = (lambda k: (lines[k], "")) if lines is not None else (lambda k: (None,
                                                                            f" (frame {k})"))
    bad = ~np.isfinite(times)
    if bad.any():
        k = int(np.argmax(bad))
        line, at = where(k)
        raise DataFormatError(path, line, f"time is not a finite number{at}")
    steps = np.diff(times)
    if (steps <= 0).any():
        k = int(np.argmax(steps <= 0)) + 1
        line, at = where(k)
        raise DataFormatError(path, line, f"time {times[k]:.6f} s does not increase (previous "
                              f"{times[k - 1]:.6f} s){at}")


def rate_of(times: np.ndarray) -> float:
    """``1 / median step`` in Hz, rounded to a whole number when within 0.01 % of one
    (float32 times give 499.9999 for 500 Hz); 0 for fewer than two frames."""
    if times.shape[0] < 2:
        return 0.0
    rate = float(1.0 / np.median(np.diff(times)))
    return float(round(rate)) if abs(rate - round(rate)) <= 1e-4 * rate else rate


def assemble_channels(path: Path | None, channels: list[str], values: np.ndarray,
                      *, unused: tuple[str, ...] = ("****", "")) -> tuple[
                          tuple[str, ...], np.ndarray, np.ndarray | None, list[str]]:
    """Group named channels into sensors: ``(names, positions (n, k, d), orientation,
    notes)`` from ``values (n, c)`` whose columns are ``channels``.

    Position channels are ``<sensor>_<axis>`` (:func:`split_channel`). Every sensor must
    have the same position axes (x, y, and z when the file is 3D): a missing one is a
    :class:`DataFormatError` naming the sensor and the channel, never a shifted column.
    Channels named in ``unused`` (MOCHA's ``****``) are skipped with a note; orientation
    channels are kept in ``orientation`` (per sensor, in file order, NaN-padded).
    """
    notes: list[str] = []
    sensors: dict[str, dict[int, int]] = {}
    orient: dict[str, list[int]] = {}
    skipped = [c.strip() for c in channels if c.strip() in unused]
    for j, raw_name in enumerate(channels):
        name = raw_name.strip()
        if name in unused:
            continue
        sensor, axis = split_channel(name)
        if axis is None:
            raise DataFormatError(path, None, f"channel {j} {name!r} names no axis (expected "
                                  "names such as ul_x, ul_y or T1_py)")
        if axis in POSITION_AXES:
            axes = sensors.setdefault(sensor, {})
            if POSITION_AXES[axis] in axes:
                raise DataFormatError(path, None, f"channel {j} {name!r}: sensor {sensor!r} "
                                      f"has a second {axis} channel")
            axes[POSITION_AXES[axis]] = j
        else:
            orient.setdefault(sensor, []).append(j)
    if skipped:
        notes.append(f"{len(skipped)} unused channel(s) named {skipped[0]!r} skipped")
    if not sensors:
        raise DataFormatError(path, None, "no position channels (x, y) found")
    dims = 3 if any(2 in a for a in sensors.values()) else 2
    for sensor, axes in sensors.items():
        missing = [c for c in range(dims) if c not in axes]
        if missing:
            have = ", ".join(channels[j].strip() for j in axes.values())
            raise DataFormatError(path, None, f"sensor {sensor!r} has no {'xyz'[missing[0]]} "
                                  f"channel (it has {have}): a missing channel")
    names = tuple(sensors)
    positions = np.stack([np.stack([values[:, sensors[s][c]] for c in range(dims)], axis=-1)
                          for s in names], axis=1)
    orientation = None
    if orient:
        q = max(len(v) for v in orient.values())
        orientation = np.full((values.shape[0], len(names), q), np.nan)
        for i, s in enumerate(names):
            for m, j in enumerate(orient.get(s, [])):
                orientation[:, i, m] = values[:, j]
        stray = sorted(set(orient) - set(names))
        if stray:
            notes.append(f"orientation channels of {', '.join(stray)} have no positions: "
                         "ignored")
    return names, positions, orientation, notes


#: A position farther than this (mm) from its sensor's median is no measurement (an
#: articulograph's field is about 300 mm across; a head moves far less): untracked.
ABSURD_MM = 500.0


def untrack_impossible(positions: np.ndarray, names: tuple[str, ...],
                       references: tuple[str, ...] = ()) -> tuple[np.ndarray, list[str]]:
    """``positions (n, k, d)`` mm with the values no tracker measures set to NaN, and notes.

    - **dead channels**: a sensor's coordinate that is exactly 0 in every frame (a channel
      exported as zeros: MOCHA's ``li`` or ``tt`` when the coil failed, a CSV column) makes
      the whole sensor untracked, never a sensor moving on the axis. In 3D data a
      coordinate that is 0 for *every* sensor is a midsagittal recording lifted into 3D,
      not a dead channel.
    - **dropouts to zero**: frames where at least two coordinates of a sensor are exactly 0
      (both, in 2D data), e.g. a jaw sensor's x and y zeroed with z kept;
    - **absurd values**: a position more than :data:`ABSURD_MM` from the sensor's median.

    Head ``references`` are spared the zero rules: a head-normalised export may hold its
    reference exactly at the origin."""
    positions = np.array(positions, dtype=np.float64, copy=True)
    n, k, d = positions.shape
    notes: list[str] = []
    if n == 0:
        return positions, notes
    tracked = np.isfinite(positions).all(-1)
    zero = positions == 0.0
    lifted = [c for c in range(d) if d == 3 and np.all(zero[:, :, c] | ~tracked)]
    for j, name in enumerate(names):
        ok = tracked[:, j]
        if name in references or not ok.any():
            continue
        dead = [c for c in range(d) if c not in lifted and ok.sum() > 1
                and zero[ok, j, c].all()]
        if dead:
            positions[:, j] = np.nan
            notes.append(f"{name}: {'/'.join('xyz'[c] for c in dead)} exactly 0 in every "
                         "frame (a dead channel): the sensor is untracked")
            continue
        drop = ok & (zero[:, j, [c for c in range(d) if c not in lifted]].sum(-1)
                     >= min(2, d - len(lifted)))
        if drop.any():
            positions[drop, j] = np.nan
            notes.append(f"{name}: {int(drop.sum())} frame(s) with coordinates exactly 0 (a "
                         "dropout to zero): untracked")
    for j, name in enumerate(names):
        ok = np.isfinite(positions[:, j]).all(-1)
        if not ok.any():
            continue
        far = ok & (np.linalg.norm(positions[:, j] - np.median(positions[ok, j], axis=0),
                                   axis=-1) > ABSURD_MM)
        if far.any():
            positions[far, j] = np.nan
            notes.append(f"{name}: {int(far.sum())} frame(s) more than {ABSURD_MM:g} mm from "
                         "the sensor's median position (absurd values): untracked")
    return positions, notes


def is_number(token: str) -> bool:
    """Whether a text file's token reads as a number (a header of names or a line of data)."""
    try:
        float(token)
    except ValueError:
        return False
    return True
