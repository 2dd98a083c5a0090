"""Edinburgh Speech Tools "EST Track" files (MOCHA-TIMIT, mngu0): read and write.

The format (Edinburgh Speech Tools' track files; checked on a real MOCHA-TIMIT file and
the corpus's public MATLAB tools, see docs/EMA.md): a text header, then the frames.

* Header: the first line ``EST_File Track``; then ``key value`` lines up to the line
  ``EST_Header_End``. Keys read: ``DataType`` (``binary`` or ``ascii``), ``ByteOrder``
  (``01`` little-endian, ``10`` big-endian; binary only), ``NumFrames``, ``NumChannels``,
  ``BreaksPresent`` (``true``: each frame carries a break flag), ``Channel_<i> <name>``.
  Other keys (``EqualSpace``, ``CommentChar``, ``name``...) are ignored; blank lines and
  CRLF line ends are accepted; a channel name keeps no surrounding spaces (MOCHA writes
  ``v_x `` with one).
* Frames: ``time, [break flag,] channel_0 ... channel_{N-1}``: float32 values in binary
  files (byte order as the header says), white-space separated numbers one frame a line in
  ascii files. A break flag of 0 marks a frame without data (every value untracked); NaN
  marks one untracked value.

Units and axes are not in the file. MOCHA-TIMIT (recognised by its channel names ``ui li
ul ll tt tb td v bn``): hundredths of a millimetre, 2D midsagittal, origin near the
upper-incisor coil, x toward the back of the head, y up, 500 Hz; converted here to mm (the
axes are turned by :mod:`cassi_fit.ema.track`). Any other EST file: millimetres (mngu0;
a sensor map's ``[file] scale_mm`` says otherwise), axes unknown.

Refused with a :class:`DataFormatError` naming the file and the line or byte offset: a
header without ``EST_Header_End``, a missing or non-numeric count, a channel count that
does not match the ``Channel_<i>`` lines, a binary body of the wrong size (truncated, or a
header that lies about the frame count), an ascii line with the wrong number of values,
times that do not increase, a sensor with a missing axis channel.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._io import atomic_write
from ..errors import DataFormatError
from ._raw import RawEma, assemble_channels, check_times, is_number, rate_of, read_bytes

MAGIC = b"EST_File"
HEADER_END = b"EST_Header_End"
#: MOCHA-TIMIT's sensors (channel prefixes): the corpus's own names.
MOCHA_SENSORS = frozenset({"ui", "li", "ul", "ll", "tt", "tb", "td", "v", "bn"})
MOCHA_SCALE_MM = 0.01  # MOCHA's numbers are hundredths of a millimetre
_MAX_HEADER = 1 << 20


def is_est(head: bytes) -> bool:
    """Whether a file's first bytes are an EST header (after an optional BOM/space)."""
    return head.lstrip(b"\xef\xbb\xbf \t\r\n").startswith(MAGIC)


def _header(path: Path, raw: bytes) -> tuple[dict[str, str], dict[int, str], int, int]:
    """``(keys, channels, body offset, number of header lines)``."""
    end = raw.find(HEADER_END, 0, _MAX_HEADER)
    if not is_est(raw[:64]):
        raise DataFormatError(path, 1, "not an EST Track file (no 'EST_File' line)")
    if end < 0:
        raise DataFormatError(path, None, "EST header has no 'EST_Header_End' line")
    newline = raw.find(b"\n", end)
    body = len(raw) if newline < 0 else newline + 1
    try:
        text = raw[:end].decode("ascii")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise DataFormatError(path, line, "EST header holds a byte that is not ASCII") from None
    keys: dict[str, str] = {}
    channels: dict[int, str] = {}
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    for lineno, line in enumerate(lines, start=1):
        stripped = line.strip()
        if lineno == 1:
            kind = stripped.split()[1:2]
            if kind and kind[0].lower() != "track":
                raise DataFormatError(path, 1, f"an EST {kind[0]} file, not a Track")
            continue
        if not stripped:
            continue
        key, _, value = line.lstrip().partition(" ")
        if key.lower().startswith("channel_"):
            try:
                index = int(key[len("channel_"):])
            except ValueError:
                raise DataFormatError(path, lineno, f"bad channel key {key!r}") from None
            if index in channels:
                raise DataFormatError(path, lineno, f"Channel_{index} given twice")
            channels[index] = value.strip()
        else:
            keys[key.lower()] = value.strip()
    return keys, channels, body, len(lines)


def _count(path: Path, keys: dict[str, str], key: str) -> int | None:
    text = keys.get(key.lower())
    if text is None:
        return None
    try:
        value = int(text)
    except ValueError:
        raise DataFormatError(path, None, f"header {key} {text!r} is not a whole number") from None
    if value < 0:
        raise DataFormatError(path, None, f"header {key} {value} is negative")
    return value


def _binary_body(path: Path, raw: bytes, offset: int, width: int, n_frames: int | None,
                 order: str) -> np.ndarray:
    size = len(raw) - offset
    frame_bytes = 4 * width
    if size % frame_bytes:
        full = size // frame_bytes
        raise DataFormatError(path, None, f"binary body truncated: {size} bytes after the "
                              f"header are {full} frames of {width} float32 and "
                              f"{size - full * frame_bytes} bytes more (byte offset "
                              f"{offset + full * frame_bytes})")
    found = size // frame_bytes
    if n_frames is not None and found != n_frames:
        raise DataFormatError(path, None, f"header NumFrames {n_frames}, but the binary body "
                              f"holds {found} frames of {width} float32 (byte offset {offset})")
    dtype = np.dtype("<f4" if order == "01" else ">f4")
    return np.frombuffer(raw, dtype=dtype, offset=offset).reshape(found, width).astype(
        np.float64)


def _ascii_body(path: Path, raw: bytes, offset: int, width: int, n_frames: int | None,
                first_line: int) -> tuple[np.ndarray, list[int]]:
    try:
        text = raw[offset:].decode("ascii")
    except UnicodeDecodeError as exc:
        line = first_line + raw[offset: offset + exc.start].count(b"\n")
        raise DataFormatError(path, line, "ascii body holds a byte that is not ASCII") from None
    rows, lines = [], []
    for i, line in enumerate(text.replace("\r\n", "\n").replace("\r", "\n").split("\n")):
        tokens = line.split()
        if not tokens:
            continue
        lineno = first_line + i
        if len(tokens) != width:
            raise DataFormatError(path, lineno, f"expected {width} values a frame (time, "
                                  f"break flag if BreaksPresent, channels), found {len(tokens)}")
        try:
            rows.append([float(t) for t in tokens])
        except ValueError:
            bad = next(t for t in tokens if not is_number(t))
            raise DataFormatError(path, lineno, f"not a number: {bad[:40]!r}") from None
        lines.append(lineno)
    if n_frames is not None and len(rows) != n_frames:
        raise DataFormatError(path, None, f"header NumFrames {n_frames}, but the body holds "
                              f"{len(rows)} frames")
    return np.array(rows, dtype=np.float64).reshape(len(rows), width), lines


def read_est(path: str | os.PathLike) -> RawEma:
    """Read an EST Track file (binary in either byte order, or ascii) into a
    :class:`RawEma` (seconds, mm; MOCHA's hundredths of a mm converted).

    See the module docstring for the format, units and every refusal.
    """
    path, raw = read_bytes(path, "EST Track file")
    if raw.startswith(b"\xef\xbb\xbf"):  # a UTF-8 BOM (byte offsets below count after it)
        raw = raw[3:]
    keys, channels, offset, n_header_lines = _header(path, raw)
    n_channels = _count(path, keys, "NumChannels")
    n_frames = _count(path, keys, "NumFrames")
    if n_channels is None:
        n_channels = len(channels)
    if sorted(channels) != list(range(n_channels)):
        raise DataFormatError(path, None, f"header NumChannels {n_channels}, but Channel_ lines "
                              f"name {len(channels)} channel(s) "
                              f"({', '.join(map(str, sorted(channels))) or 'none'})")
    breaks = keys.get("breakspresent", "false").lower() in ("true", "1", "yes")
    width = n_channels + 1 + int(breaks)
    data_type = keys.get("datatype", "binary").lower()
    lines = None
    if data_type == "binary":
        order = keys.get("byteorder", "01")
        if order not in ("01", "10"):
            raise DataFormatError(path, None, f"ByteOrder {order!r}: expected 01 (little-"
                                  "endian) or 10 (big-endian)")
        body = _binary_body(path, raw, offset, width, n_frames, order)
    elif data_type == "ascii":
        body, lines = _ascii_body(path, raw, offset, width, n_frames, n_header_lines + 1)
    else:
        raise DataFormatError(path, None, f"DataType {data_type!r}: expected binary or ascii")
    if body.shape[0] == 0:
        raise DataFormatError(path, None, "no frames")
    times = body[:, 0]
    check_times(path, times, lines)
    values = body[:, 1 + int(breaks):]
    if breaks:
        values = np.where((body[:, 1] == 0)[:, None], np.nan, values)
    names, positions, orientation, notes = assemble_channels(
        path, [channels[i] for i in range(n_channels)], values)
    mocha = {s.lower() for s in names} >= {"ui", "li", "ul", "ll", "tt"} and positions.shape[2] == 2
    if mocha:
        positions = positions * MOCHA_SCALE_MM
        units, axes, frame = ("hundredths of a mm (MOCHA-TIMIT), x 0.01 to mm",
                              "MOCHA-TIMIT: x toward the back of the head, y up, origin near "
                              "the upper-incisor coil (the corpus's MATLAB tools)", "mocha")
    else:
        units, axes, frame = ("mm (EST Track files carry no unit; mngu0 is in mm)",
                              "not stated by the file", None)
    if breaks and (body[:, 1] == 0).all():
        notes.append("every frame is marked as a break (no data)")
    return RawEma(format="est", times=times, names=names, positions=positions,
                  rate_hz=rate_of(times), units=units, axes=axes, frame=frame, path=path,
                  orientation=orientation, notes=tuple(notes))


def est_bytes(times: np.ndarray, channels: list[str], values: np.ndarray, *,
              ascii: bool = False, byte_order: str = "01", breaks: bool = True) -> bytes:
    """An EST Track file's bytes: ``times (n,)`` s, ``values (n, c)`` for ``channels``
    (NaN allowed: an untracked value), break flags all 1, float32 (binary) or ``%.6g``
    text (ascii)."""
    n, c = values.shape
    head = ["EST_File Track", f"DataType {'ascii' if ascii else 'binary'}"]
    if not ascii:
        head.append(f"ByteOrder {byte_order}")
    head += [f"NumFrames {n}", f"NumChannels {c}", "EqualSpace 1",
             f"BreaksPresent {'true' if breaks else 'false'}", "CommentChar ;", ""]
    head += [f"Channel_{i} {name}" for i, name in enumerate(channels)]
    head.append("EST_Header_End")
    cols = [times[:, None]] + ([np.ones((n, 1))] if breaks else []) + [values]
    body = np.concatenate(cols, axis=1)
    if ascii:
        text = "".join(" ".join(f"{v:.9g}" for v in row) + "\n" for row in body.tolist())
        return ("\n".join(head) + "\n" + text).encode("ascii")
    dtype = "<f4" if byte_order == "01" else ">f4"
    return ("\n".join(head) + "\n").encode("ascii") + body.astype(dtype).tobytes()


def write_est(path: str | os.PathLike, raw: RawEma, *, ascii: bool = False,
              byte_order: str = "01", overwrite: bool = False) -> Path:
    """Write ``raw``'s positions (mm) as an EST Track file, channels ``<name>_x``,
    ``<name>_y`` (and ``_z``) per sensor; binary float32 in ``byte_order`` or ascii.
    Written atomically; never replaces an input file, nor an existing file unless
    ``overwrite``."""
    channels = [f"{s}_{a}" for s in raw.names for a in "xyz"[: raw.dims]]
    values = raw.positions.reshape(raw.n_frames, -1)
    data = est_bytes(raw.times, channels, values, ascii=ascii, byte_order=byte_order)
    return atomic_write(path, data, overwrite=overwrite, data_file=True)
