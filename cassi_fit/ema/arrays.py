"""Sensor positions as arrays: numpy arrays in Python, ``.npy``/``.npz``/CSV files on disk.

An array has one row per frame and its columns in a named **layout**: a list of column
names ``<sensor><axis>`` (``TDX``, ``UL_x``, ``ul y``), or a built-in name:

* ``"sparc"``: the Speech Articulatory Coding model's ``ema`` output, ``(frames, 12)`` at
  50 Hz, columns ``TDX TDY TBX TBY TTX TTY LIX LIY ULX ULY LLX LLY`` (tongue dorsum,
  blade, tip, lower incisor, upper lip, lower lip; checked in the model's README). The
  model was trained on mngu0 but its README does not give units, and its outputs span a
  few units around 0 (public code that plots them uses axes of -4 to 4): they are
  **normalised**, not millimetres. So ``"sparc"`` needs a way back to mm: the per-column
  means and standard deviations of the data the model learnt from (``mean_mm``,
  ``sd_mm``: ``mm = mean + sd * value``), or ``units="mm"`` when the values already are
  millimetres (another model, or data you denormalised). Without either it is refused
  with that explanation: a normalised array drawn as millimetres would be a face a few
  millimetres wide.
* ``"mngu0"``: the same columns, in millimetres (mngu0's EMA after its own processing).

Axes: the columns' x and y are taken as the midsagittal plane's; which way is forward and
up is decided from the anatomy when the array's frame is not known
(:mod:`cassi_fit.ema.track`). Rate: given (``rate`` Hz), or a time column in a CSV/``.npz``.
NaN is an untracked value.

Files: ``.npy`` (one ``(frames, columns)`` array), ``.npz`` (the array ``ema``, or the only
2-D array, with optional ``times`` (s) or ``rate``), CSV (a header row of column names,
which then is the layout, optionally a ``time``/``time_s``/``t`` column in seconds; or no
header and a layout). Refused with a :class:`DataFormatError`: a column count that does not
match the layout, a column name without an axis, a sensor with one axis only, a missing
rate, a non-number in a CSV (naming the line).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from jaxtyping import Float

from ..errors import DataFormatError
from ._raw import RawEma, check_times, is_number, rate_of, read_bytes

SPARC_COLUMNS = ("TDX", "TDY", "TBX", "TBY", "TTX", "TTY", "LIX", "LIY", "ULX", "ULY",
                 "LLX", "LLY")
SPARC_RATE_HZ = 50.0
#: Built-in layouts: name -> (columns, units of the values).
LAYOUTS = {"sparc": (SPARC_COLUMNS, "normalised"), "mngu0": (SPARC_COLUMNS, "mm")}
UNITS = ("mm", "cm", "m", "normalised")
_UNIT_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
_COLUMN = re.compile(r"^(?P<sensor>.+?)[\s_.\-]*(?P<axis>[xyzXYZ])$")
_TIME_NAMES = ("time", "time_s", "t", "times", "sec", "seconds")


def layout_columns(layout: str | Sequence[str]) -> tuple[tuple[str, ...], str | None]:
    """``(columns, units or None)`` of a built-in layout name or a list of column names."""
    if isinstance(layout, str):
        key = layout.strip().lower()
        if key not in LAYOUTS:
            raise DataFormatError(None, None, f"unknown layout {layout!r} (built in: "
                                  f"{', '.join(LAYOUTS)}; or give the column names)")
        return LAYOUTS[key]
    return tuple(str(c) for c in layout), None


def parse_columns(path: Path | None, columns: Sequence[str]) -> tuple[tuple[str, ...], list[
        tuple[str, int]]]:
    """Sensor names (first-seen order) and per column ``(sensor, axis index)``."""
    parsed, sensors = [], {}
    for j, name in enumerate(columns):
        match = _COLUMN.match(name.strip())
        if not match:
            raise DataFormatError(path, None, f"column {j} {name!r} names no axis (x, y, z)")
        sensor, axis = match.group("sensor"), "xyz".index(match.group("axis").lower())
        if axis in sensors.setdefault(sensor, set()):
            raise DataFormatError(path, None, f"column {j} {name!r}: sensor {sensor!r} has a "
                                  "second column for that axis")
        sensors[sensor].add(axis)
        parsed.append((sensor, axis))
    dims = 3 if any(2 in a for a in sensors.values()) else 2
    for sensor, axes in sensors.items():
        if axes != set(range(dims)):
            missing = "xyz"[min(set(range(dims)) - axes)]
            raise DataFormatError(path, None, f"sensor {sensor!r} has no {missing} column (a "
                                  "missing channel)")
    return tuple(sensors), parsed


def raw_from_array(
    values: Float[np.ndarray, "n c"],
    *,
    layout: str | Sequence[str],
    rate: float | None = None,
    times: Float[np.ndarray, " n"] | None = None,
    units: str | None = None,
    mean_mm: Float[np.ndarray, " c"] | None = None,
    sd_mm: Float[np.ndarray, " c"] | None = None,
    path: Path | None = None,
) -> RawEma:
    """A :class:`RawEma` from a ``(frames, columns)`` array in ``layout`` (module
    docstring). ``rate`` Hz or ``times (n,)`` s (one of them); ``units`` one of
    :data:`UNITS` (default the layout's, else mm); a ``"normalised"`` array needs
    ``mean_mm`` and ``sd_mm`` (per column, mm)."""
    try:
        values = np.asarray(values, dtype=np.float64)
    except (ValueError, TypeError):
        raise DataFormatError(path, None, f"the array holds {np.asarray(values).dtype} values, "
                              "not numbers") from None
    columns, layout_units = layout_columns(layout)
    if values.ndim != 2 or values.shape[1] != len(columns):
        raise DataFormatError(path, None, f"array of shape {values.shape}: the layout has "
                              f"{len(columns)} columns ({' '.join(columns)})")
    names, parsed = parse_columns(path, columns)
    units = (units or layout_units or "mm").lower().replace("normalized", "normalised")
    if units not in UNITS:
        raise DataFormatError(path, None, f"units {units!r}: expected one of {', '.join(UNITS)}")
    if (mean_mm is None) != (sd_mm is None):
        raise DataFormatError(path, None, "give both mean_mm and sd_mm (or neither)")
    if mean_mm is not None:
        mean = np.broadcast_to(np.asarray(mean_mm, np.float64), (len(columns),))
        sd = np.broadcast_to(np.asarray(sd_mm, np.float64), (len(columns),))
        values = mean + sd * values
        units_note = "normalised, denormalised with the given means and SDs (mm)"
    elif units == "normalised":
        raise DataFormatError(path, None, "the values are normalised, not millimetres "
                              f"(layout {layout!r}): give mean_mm and sd_mm, the per-column "
                              "means and SDs of the data the model learnt from, or "
                              "units='mm' if they are millimetres (docs/EMA.md, arrays)")
    else:
        values = values * _UNIT_MM[units]
        units_note = units if units == "mm" else f"{units}, converted to mm"
    n = values.shape[0]
    if times is None:
        if rate is None or not np.isfinite(rate) or rate <= 0:
            raise DataFormatError(path, None, "an array needs its rate (rate=..., Hz) or times")
        times = np.arange(n) / float(rate)
    times = np.asarray(times, np.float64)
    if times.shape != (n,):
        raise DataFormatError(path, None, f"{times.shape[0]} times for {n} frames")
    check_times(path, times)
    dims = 1 + max(a for _, a in parsed)
    positions = np.full((n, len(names), dims), np.nan)
    for j, (sensor, axis) in enumerate(parsed):
        positions[:, names.index(sensor), axis] = values[:, j]
    return RawEma(format="array", times=times, names=names, positions=positions,
                  rate_hz=float(rate) if rate else rate_of(times), units=units_note,
                  axes="the array's x and y (midsagittal plane assumed)" if dims == 2
                  else "the array's axes", frame=None, path=path,
                  notes=(f"layout {layout if isinstance(layout, str) else 'given'}: "
                         f"{' '.join(columns)}",))


def _csv(path: Path) -> tuple[list[str] | None, np.ndarray, list[int]]:
    from .._io import read_lines

    _, lines = read_lines(path)
    if not lines:
        raise DataFormatError(path, None, "empty file")
    split = (lambda s: [t.strip() for t in s.split(",")]) if "," in lines[0][1] else str.split
    header = split(lines[0][1])
    numeric = all(is_number(t) for t in header)
    rows = lines if numeric else lines[1:]
    data = []
    for lineno, text in rows:
        tokens = split(text)
        if len(tokens) != len(header):
            raise DataFormatError(path, lineno, f"{len(tokens)} fields, expected {len(header)}")
        try:
            data.append([float(t) if t else np.nan for t in tokens])
        except ValueError:
            bad = next(t for t in tokens if t and not is_number(t))
            raise DataFormatError(path, lineno, f"not a number: {bad[:40]!r}") from None
    return (None if numeric else header), np.array(data, np.float64).reshape(
        len(data), len(header)), [ln for ln, _ in rows]



def read_array(path: str | os.PathLike, *, layout: str | Sequence[str] | None = None,
               rate: float | None = None, units: str | None = None,
               mean_mm: Float[np.ndarray, " c"] | None = None,
               sd_mm: Float[np.ndarray, " c"] | None = None) -> RawEma:
    """Read a ``.npy``, ``.npz`` or CSV array file into a :class:`RawEma`; see the module
    docstring (a CSV header is the layout; otherwise ``layout`` is needed)."""
    path = Path(path)
    suffix = path.suffix.lower()
    times = None
    if suffix in (".npy", ".npz"):
        import io

        _, raw = read_bytes(path, "array file")
        try:
            loaded = np.load(io.BytesIO(raw), allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise DataFormatError(path, None, f"not a readable numpy file ({exc})") from None
        if suffix == ".npz":
            arrays = dict(loaded)
            two_d = [k for k, v in arrays.items() if v.ndim == 2]
            key = "ema" if "ema" in arrays else (two_d[0] if len(two_d) == 1 else None)
            if key is None:
                raise DataFormatError(path, None, f"no array named 'ema' and {len(two_d)} "
                                      f"2-D arrays ({', '.join(two_d)}): which one?")
            values = arrays[key]
            times = next((arrays[k] for k in ("times", "time") if k in arrays), None)
            if rate is None and "rate" in arrays:
                rate = float(np.asarray(arrays["rate"]).ravel()[0])
        else:
            values = loaded
        if values.ndim == 3:  # (frames, sensors, dims)
            values = values.reshape(values.shape[0], -1)
    elif suffix in (".csv", ".txt", ".tsv"):
        header, values, lines = _csv(path)
        if header is not None:
            time_cols = [j for j, h in enumerate(header) if h.lower() in _TIME_NAMES]
            if time_cols:
                times = values[:, time_cols[0]]
                check_times(path, times, lines)
                keep = [j for j in range(len(header)) if j not in time_cols]
                values, header = values[:, keep], [header[j] for j in keep]
            layout = layout or header
    else:
        raise DataFormatError(path, None, "array files end in .npy, .npz or .csv")
    if layout is None:
        raise DataFormatError(path, None, "an array file needs a layout (e.g. 'sparc', or the "
                              "column names)")
    return raw_from_array(values, layout=layout, rate=rate, times=times, units=units,
                          mean_mm=mean_mm, sd_mm=sd_mm, path=path)
