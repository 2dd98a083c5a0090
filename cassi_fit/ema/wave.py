"""NDI Wave exports (tab-separated text, ``.tsv``): read and write.

The format (as a public reader of Wave exports, ``ultratils``' ``NDIData``, documents and
parses it; see docs/EMA.md): one frame a line, tab-separated; the first column is the
time (``Wav Time``, seconds, on the audio's clock); then one group of columns per sensor:
``Sensor ID``, ``Frame``, ``State``, ``Q0 Qx Qy Qz`` (orientation quaternion), ``Tx Ty Tz``
(position, mm, in the field generator's frame). A first line starting ``Wav Time`` is a
header; columns whose header is blank are skipped; a file without a header is read as
the fixed layout (time, then 10 columns per sensor).

Read liberally: CRLF or LF, a UTF-8 BOM, header names in any case with suffixes
(``Tx.1``, ``Tx[2]``), groups that lack ``Sensor ID``/``Frame`` columns (each ``State``
or ``Q0`` then starts a group). A value is untracked where the sensor's ``State`` is not
``OK`` or the field is empty or ``NaN``. Sensors are named ``S<id>`` from their
``Sensor ID`` column (else ``S<group>``, 1-based): a sensor map names them. Refused with a
:class:`DataFormatError` naming the file and line: a group without ``Tx Ty Tz``, a line
with another number of fields than the header, a value that is not a number, times that
do not increase.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._io import atomic_write, read_lines
from ..errors import DataFormatError
from ._raw import RawEma, check_times, is_number, rate_of

GROUP = ("sensor id", "frame", "state", "q0", "qx", "qy", "qz", "tx", "ty", "tz")
_SUFFIX = re.compile(r"[\s.\[\(_]*\d*[\]\)]?$")


def _column(name: str) -> str:
    """A header cell normalised: lower case, spaces collapsed, numeric suffix dropped."""
    text = " ".join(name.strip().lower().split())
    base = _SUFFIX.sub("", text) if text not in ("q0",) else text
    if base.startswith("q0") or text.startswith("q0"):
        return "q0"
    return base


def looks_like_wave(first_line: str) -> bool:
    """Whether a text file's first line is a Wave export header."""
    cells = [_column(c) for c in first_line.split("\t")]
    return bool(cells) and cells[0] == "wav time" or ("tx" in cells and "ty" in cells
                                                       and "tz" in cells)


def _groups(path: Path, header: list[str]) -> list[dict[str, int]]:
    """Per sensor, column name -> index, in file order."""
    groups: list[dict[str, int]] = []
    current: dict[str, int] = {}
    for j, cell in enumerate(header[1:], start=1):
        name = _column(cell)
        if not name:
            continue
        starts = name in ("sensor id", "sensor", "id") or (
            name in ("frame", "state", "q0", "tx") and name in current)
        if starts and current:
            groups.append(current)
            current = {}
        current["sensor id" if name in ("sensor", "id") else name] = j
    if current:
        groups.append(current)
    for g, group in enumerate(groups, start=1):
        missing = [c for c in ("tx", "ty", "tz") if c not in group]
        if missing:
            raise DataFormatError(path, 1, f"sensor group {g} has no {missing[0].upper()} column "
                                  "(a missing channel)")
    if not groups:
        raise DataFormatError(path, 1, "no sensor columns (Tx, Ty, Tz) in the header")
    return groups


def _number(path: Path, lineno: int, token: str) -> float:
    token = token.strip()
    if not token:
        return np.nan
    try:
        return float(token)
    except ValueError:
        raise DataFormatError(path, lineno, f"not a number: {token[:40]!r}") from None


def read_wave_tsv(path: str | os.PathLike) -> RawEma:
    """Read an NDI Wave export into a :class:`RawEma` (seconds, mm, the field generator's
    frame); see the module docstring for the format and every refusal."""
    path, lines = read_lines(path)
    if not lines:
        raise DataFormatError(path, None, "empty file")
    first = lines[0][1].split("\t")
    if _column(first[0]) == "wav time" or not is_number(first[0]):
        header, rows = first, lines[1:]
    else:
        width = len(first)
        if (width - 1) % len(GROUP):
            raise DataFormatError(path, lines[0][0], f"no header and {width} fields: not 1 time "
                                  f"column and groups of {len(GROUP)} per sensor")
        header = ["Wav Time"] + [c for _ in range((width - 1) // len(GROUP)) for c in GROUP]
        rows = lines
    groups = _groups(path, header)
    if not rows:
        raise DataFormatError(path, None, "no frames after the header")
    n, k = len(rows), len(groups)
    times = np.empty(n)
    positions = np.full((n, k, 3), np.nan)
    quats = np.full((n, k, 4), np.nan)
    ids: list[str | None] = [None] * k
    for i, (lineno, line) in enumerate(rows):
        fields = line.split("\t")
        if len(fields) > len(header) and not any(f.strip() for f in fields[len(header):]):
            fields = fields[: len(header)]  # trailing tabs
        if len(fields) != len(header):
            raise DataFormatError(path, lineno, f"{len(fields)} fields, the header has "
                                  f"{len(header)}")
        times[i] = _number(path, lineno, fields[0])
        for g, group in enumerate(groups):
            state = fields[group["state"]].strip().lower() if "state" in group else "ok"
            if ids[g] is None and "sensor id" in group and fields[group["sensor id"]].strip():
                ids[g] = fields[group["sensor id"]].strip()
            xyz = [_number(path, lineno, fields[group[c]]) for c in ("tx", "ty", "tz")]
            if state == "ok":
                positions[i, g] = xyz
                if all(c in group for c in ("q0", "qx", "qy", "qz")):
                    quats[i, g] = [_number(path, lineno, fields[group[c]])
                                   for c in ("q0", "qx", "qy", "qz")]
    check_times(path, times, [ln for ln, _ in rows])
    names = []
    for g, sensor_id in enumerate(ids, start=1):
        label = f"S{int(float(sensor_id))}" if sensor_id and is_number(sensor_id) else f"S{g}"
        names.append(label if label not in names else f"S{g}")
    return RawEma(format="wave", times=times, names=tuple(names), positions=positions,
                  rate_hz=rate_of(times), units="mm", path=path, orientation=quats,
                  axes="the Wave field generator's frame (NDI)", frame=None,
                  notes=(f"{k} sensor group(s); a value is tracked where State is OK",))



def wave_text(times: np.ndarray, positions: np.ndarray, sensor_ids: list[int]) -> str:
    """A Wave export's text: header, then per frame the time and per sensor
    ``id, frame, state, Q0 Qx Qy Qz (1 0 0 0), Tx Ty Tz``; an untracked sensor-frame has
    State ``Missing`` and empty values. ``positions (n, k, 3)`` mm, NaN untracked."""
    head = ["Wav Time"]
    for _ in sensor_ids:
        head += ["Sensor ID", "Frame", "State", "Q0", "Qx", "Qy", "Qz", "Tx", "Ty", "Tz"]
    out = ["\t".join(head)]
    for i, t in enumerate(times.tolist()):
        cells = [f"{t:.6f}"]
        for g, sid in enumerate(sensor_ids):
            p = positions[i, g]
            if np.isfinite(p).all():
                cells += [str(sid), str(i + 1), "OK", "1", "0", "0", "0"]
                cells += [f"{v:.4f}" for v in p.tolist()]
            else:
                cells += [str(sid), str(i + 1), "Missing"] + [""] * 7
        out.append("\t".join(cells))
    return "\r\n".join(out) + "\r\n"


def write_wave_tsv(path: str | os.PathLike, raw: RawEma, *, overwrite: bool = False) -> Path:
    """Write ``raw`` (3D) as a Wave export, sensors numbered 1.. in ``raw.names`` order
    (``S<i>``: a sensor map names them), positions to 0.1 um. Written atomically; never
    replaces an input, nor an existing file unless ``overwrite``."""
    if raw.dims != 3:
        raise DataFormatError(path, None, "cannot write a Wave export from 2D positions")
    text = wave_text(raw.times, raw.positions, list(range(1, len(raw.names) + 1)))
    return atomic_write(path, text, overwrite=overwrite, data_file=True)
