"""SSFF track files (Simple Signal File Format, EMU-SDMS / wrassp): read and write.

The format (as EMU-SDMS's ``wrassp`` writes it, and as the IPS Munich EMA bundles hold it):
an ASCII header of lines,

- ``SSFF -- (c) SHLRC`` (the magic line);
- ``Machine IBM-PC`` (little-endian records) or ``Machine SPARC`` (big-endian; ``SUN``,
  ``SGI`` and ``MAC`` are read as big-endian too);
- ``Record_Freq 200.0`` (records per second), ``Start_Time 0.0`` (s, the first record's
  time);
- one ``Column <name> <type> <count>`` line per field, in record order, ``type`` one of
  ``DOUBLE FLOAT LONG SHORT BYTE CHAR`` (8, 4, 4, 2, 1, 1 bytes);
- optional typed values ``<name> <type> <value>`` (``Original_Freq DOUBLE 24000.0``), kept;
- ``-----------------`` ending the header (one newline after it);

then the binary records, each the columns in order. A header missing its magic line,
``Machine``, ``Record_Freq`` or any ``Column``, an unknown type or machine, a count that is
not a positive whole number, or a body that is not a whole number of records is one
:class:`~cassi_fit.errors.DataFormatError` naming the file (and the header line).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._io import atomic_write
from ..errors import DataFormatError

MAGIC = "SSFF -- (c) SHLRC"
END = "-----------------"
#: SSFF type -> numpy kind (the byte order is the header's).
TYPES = {"DOUBLE": "f8", "FLOAT": "f4", "LONG": "i4", "SHORT": "i2", "BYTE": "i1",
         "CHAR": "u1"}
_LITTLE = ("IBM-PC", "PC", "INTEL", "VAX", "LITTLE")
_BIG = ("SPARC", "SUN", "SGI", "MAC", "MOTOROLA", "BIG")


@dataclass(frozen=True, eq=False)
class SsffTrack:
    """One SSFF file: ``columns`` (name -> ``(n, count)`` float64 array, file order),
    ``rate_hz``, ``start_s`` (the first record's time), ``values`` (the header's typed
    values, e.g. ``Original_Freq``), ``path`` (or a description of where it came from)."""

    columns: dict[str, np.ndarray]
    rate_hz: float
    start_s: float
    values: dict[str, float] = field(default_factory=dict)
    path: Path | str | None = None

    @property
    def n_records(self) -> int:
        return next(iter(self.columns.values())).shape[0] if self.columns else 0

    @property
    def times(self) -> np.ndarray:
        """``(n,)`` seconds of the records: ``start_s + k / rate_hz``."""
        return self.start_s + np.arange(self.n_records) / self.rate_hz


def _header_end(where, raw: bytes) -> tuple[int, list[str]]:
    if not raw.startswith(MAGIC.encode()):
        raise DataFormatError(where, 1, f"not an SSFF file (the first line is not {MAGIC!r})")
    marker = ("\n" + END).encode()
    at = raw.find(marker)
    if at < 0:
        raise DataFormatError(where, None, f"SSFF header never ends (no {END!r} line)")
    line_end = raw.find(b"\n", at + len(marker))
    body = len(raw) if line_end < 0 else line_end + 1
    try:
        text = raw[:at].decode("ascii")
    except UnicodeDecodeError:
        raise DataFormatError(where, None, "SSFF header is not ASCII text") from None
    return body, text.replace("\r", "").split("\n")


def _number(where, lineno: int, token: str, what: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise DataFormatError(where, lineno, f"{what} {token!r} is not a number") from None
    if not math.isfinite(value):
        raise DataFormatError(where, lineno, f"{what} {token!r} is not a finite number")
    return value


def _parse_header(where, lines: list[str]):
    machine = rate = None
    start = 0.0
    columns: list[tuple[str, str, int]] = []
    values: dict[str, float] = {}
    for lineno, line in enumerate(lines[1:], start=2):
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "Machine" and len(tokens) >= 2:
            name = " ".join(tokens[1:]).upper()
            if name in _LITTLE:
                machine = "<"
            elif name in _BIG:
                machine = ">"
            else:
                raise DataFormatError(where, lineno, f"unknown Machine {name!r} (IBM-PC: "
                                      "little-endian, SPARC: big-endian)")
        elif key == "Record_Freq" and len(tokens) == 2:
            rate = _number(where, lineno, tokens[1], "Record_Freq")
            if rate <= 0:
                raise DataFormatError(where, lineno, f"Record_Freq {rate:g} is not a rate")
        elif key == "Start_Time" and len(tokens) == 2:
            start = _number(where, lineno, tokens[1], "Start_Time")
        elif key == "Column":
            if len(tokens) != 4 or tokens[2].upper() not in TYPES:
                raise DataFormatError(where, lineno, f"expected 'Column <name> <type> "
                                      f"<count>' with a type of {', '.join(TYPES)}, got "
                                      f"{line.strip()!r}")
            count = tokens[3]
            if not count.isdigit() or int(count) < 1:
                raise DataFormatError(where, lineno, f"column {tokens[1]!r}: count {count!r} "
                                      "is not a positive whole number")
            if any(c[0] == tokens[1] for c in columns):
                raise DataFormatError(where, lineno, f"column {tokens[1]!r} appears twice")
            columns.append((tokens[1], tokens[2].upper(), int(count)))
        elif len(tokens) == 3 and tokens[1].upper() in TYPES:
            try:
                values[key] = float(tokens[2])
            except ValueError:
                pass  # a text value (CHAR): not needed here
    for what, value in (("Machine", machine), ("Record_Freq", rate)):
        if value is None:
            raise DataFormatError(where, None, f"SSFF header has no {what} line")
    if not columns:
        raise DataFormatError(where, None, "SSFF header has no Column line")
    return machine, float(rate), float(start), columns, values


def parse_ssff(raw: bytes, where: str | os.PathLike | None = None) -> SsffTrack:
    """An :class:`SsffTrack` from the bytes of an SSFF file; ``where`` names it in
    errors (a path, or e.g. ``bundle.json: ssffFiles[2] (jaw)``)."""
    body_at, lines = _header_end(where, raw)
    machine, rate, start, columns, values = _parse_header(where, lines)
    dtype = np.dtype([(name, f"{machine}{TYPES[kind]}", (count,))
                      for name, kind, count in columns])
    body = raw[body_at:]
    if len(body) % dtype.itemsize:
        raise DataFormatError(where, None, f"SSFF body of {len(body)} bytes is not a whole "
                              f"number of {dtype.itemsize}-byte records (a cut file?)")
    records = np.frombuffer(body, dtype=dtype)
    out = {name: records[name].astype(np.float64).reshape(records.shape[0], count)
           for name, _, count in columns}
    return SsffTrack(out, rate, start, values, where)


def read_ssff(path: str | os.PathLike) -> SsffTrack:
    """Read an SSFF file (module docstring); errors name the file."""
    from ._raw import read_bytes

    path, raw = read_bytes(path, "SSFF file")
    return parse_ssff(raw, path)


def ssff_bytes(columns: dict[str, np.ndarray], rate_hz: float, *, start_s: float = 0.0,
               kind: str = "FLOAT", machine: str = "IBM-PC",
               values: dict[str, float] | None = None) -> bytes:
    """The bytes of an SSFF file holding ``columns`` (name -> ``(n,)`` or ``(n, count)``)
    as ``kind`` values, records ``rate_hz`` apart from ``start_s``."""
    order = "<" if machine.upper() in _LITTLE else ">"
    arrays = {k: np.asarray(v, np.float64).reshape(len(v), -1) for k, v in columns.items()}
    lines = [MAGIC, f"Machine {machine}", f"Record_Freq {float(rate_hz)!r}",
             f"Start_Time {float(start_s)!r}"]
    lines += [f"Column {k} {kind} {v.shape[1]}" for k, v in arrays.items()]
    lines += [f"{k} DOUBLE {float(v)!r}" for k, v in (values or {}).items()]
    lines.append(END)
    dtype = np.dtype([(k, f"{order}{TYPES[kind]}", (v.shape[1],)) for k, v in arrays.items()])
    n = {v.shape[0] for v in arrays.values()}
    if len(n) != 1:
        raise ValueError(f"SSFF columns must have one length, got {sorted(n)}")
    records = np.zeros(n.pop(), dtype=dtype)
    for k, v in arrays.items():
        records[k] = v
    return ("\n".join(lines) + "\n").encode("ascii") + records.tobytes()


def write_ssff(path: str | os.PathLike, columns: dict[str, np.ndarray], rate_hz: float, *,
               overwrite: bool = False, **options) -> Path:
    """Write an SSFF file atomically (:func:`ssff_bytes`'s options)."""
    return atomic_write(Path(path), ssff_bytes(columns, rate_hz, **options),
                        overwrite=overwrite, data_file=True)
