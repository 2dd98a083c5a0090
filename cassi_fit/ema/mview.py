"""Haskins ``mview`` data files (MATLAB ``.mat``): read and write.

The format (mview's own input convention, as documented by its Python port PhonoScape and
read there with ``scipy.io.loadmat``; see docs/EMA.md): a variable holding a struct array
with one entry per channel, fields ``NAME`` (text), ``SRATE`` (Hz) and ``SIGNAL``
(``[samples x dims]``); optional fields (``SOURCE``, ``SENTENCE``, ``COLOR``, ``NCOMPS``...)
are ignored. A channel whose ``SIGNAL`` has one column is a scalar and is not a sensor;
the first one at an audio rate (``AUDIO``, usually first) is the recording's **sound**
(:class:`cassi_fit.sound.Sound`, kind ``"mview AUDIO"``; samples in [-1, 1], or 16-bit
integers which are scaled). A movement channel has 2 or 3 position columns (mm) and,
beyond the third, orientation angles.

**Labels in the file**: fields ``WORDS``, ``PHONES`` and ``LABELS`` of any entry (usually
``AUDIO``'s), each a struct array of intervals with a text field (``LABEL``, ``NAME``,
``WORD``, ``PHONE`` or ``TEXT``) and a time field (``OFFS``, ``OFFSET``, ``OFFSETS``,
``TIME`` or ``TIMES``: ``[start end]`` seconds, or one time for a point label), become
label tiers ``words``, ``phones``, ``labels`` (:attr:`RawEma.labels`). Times that only
fit the recording as milliseconds are read as milliseconds, with a note; a tier whose
intervals are not in time order is an error naming the file and the tier. Haskins' processing
leaves data head-corrected in an occlusal frame, but the file does not say which axis is
which: :mod:`cassi_fit.ema.track` finds the frame (or a sensor map's ``[file]`` table says
it). NaN is an untracked value.

Which variable: the one named ``variable``, else the only struct array with those
fields, else the one named like the file's stem; several candidates are an error naming
them. MATLAB v7.3 files are HDF5 and are refused with the way out (save with ``-v7``).
Refused with a :class:`DataFormatError` naming the file: no such struct, a movement
channel with another rate or length than the others, a channel without a name.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._io import atomic_write
from ..errors import DataFormatError
from ._raw import RawEma, read_bytes

FIELDS = ("NAME", "SRATE", "SIGNAL")
AUDIO_RATE_MIN_HZ = 5000.0  # mview's rule: a one-column channel at this rate is sound


def is_mat(head: bytes) -> bool:
    """Whether a file starts like a MATLAB 5 (or 7.3) ``.mat`` file."""
    return head.startswith(b"MATLAB 5.0 MAT-file") or head.startswith(b"MATLAB 7.3 MAT-file")


def _text(value) -> str:
    value = np.asarray(value)
    if value.dtype.kind in "US":
        return "".join(str(v) for v in value.ravel()).strip()
    if value.dtype == object and value.size == 1:
        return _text(value.ravel()[0])
    return str(value).strip()


def _scalar(value) -> float:
    return float(np.asarray(value, dtype=np.float64).ravel()[0])


def _candidates(contents: dict) -> dict[str, np.ndarray]:
    found = {}
    for key, value in contents.items():
        if key.startswith("__") or not isinstance(value, np.ndarray):
            continue
        names = value.dtype.names or ()
        if all(f in names for f in FIELDS):
            found[key] = value
    return found


def _variable(path: Path, found: dict, variable: str | None) -> str:
    """Which struct variable to read (module docstring)."""
    if variable is not None:
        if variable not in found:
            raise DataFormatError(path, None, f"no mview struct variable {variable!r} (found: "
                                  f"{', '.join(found) or 'none'})")
        return variable
    if len(found) == 1:
        return next(iter(found))
    if path.stem in found:
        return path.stem
    raise DataFormatError(path, None, f"{len(found)} mview struct variables "
                          f"({', '.join(found) or 'none with NAME, SRATE, SIGNAL'}): "
                          "name one (variable=)")


def read_mview(path: str | os.PathLike, *, variable: str | None = None) -> RawEma:
    """Read an mview ``.mat`` file into a :class:`RawEma` (seconds from 0 at ``SRATE``,
    mm); see the module docstring for the format and every refusal."""
    from scipy.io import loadmat

    path, raw = read_bytes(path, ".mat file")
    if raw.startswith(b"MATLAB 7.3"):
        raise DataFormatError(path, None, "a MATLAB v7.3 (HDF5) file: save it with "
                              "save(..., '-v7') to read it here")
    try:
        import io

        contents = loadmat(io.BytesIO(raw), squeeze_me=False, struct_as_record=True)
    except Exception as exc:  # scipy raises many kinds on a damaged file: one error here
        raise DataFormatError(path, None, f"not a readable MATLAB file ({exc})") from None
    found = _candidates(contents)
    key = _variable(path, found, variable)
    entries = found[key].ravel()
    names, signals, rates, notes = [], [], [], []
    sound = None
    for i, entry in enumerate(entries):
        name = _text(entry["NAME"])
        if not name:
            raise DataFormatError(path, None, f"{key}({i + 1}) has no NAME")
        try:
            signal = np.asarray(entry["SIGNAL"], dtype=np.float64)
            rate = _scalar(entry["SRATE"])
        except (ValueError, TypeError, IndexError):
            raise DataFormatError(path, None, f"{key}({i + 1}) {name}: SIGNAL or SRATE is not "
                                  "numeric") from None
        if not (np.isfinite(rate) and rate > 0):
            raise DataFormatError(path, None, f"{key}({i + 1}) {name}: SRATE {rate!r} is not a "
                                  "rate")
        if signal.ndim == 1 or (signal.ndim == 2 and min(signal.shape) == 1):
            if rate >= AUDIO_RATE_MIN_HZ and sound is None:
                sound = _sound(path, name, signal.ravel(), rate, notes)
            else:
                kind = "sound" if rate >= AUDIO_RATE_MIN_HZ else "a scalar channel"
                notes.append(f"{name}: {kind} at {rate:g} Hz, not a sensor (not used)")
            continue
        if signal.ndim != 2:
            raise DataFormatError(path, None, f"{key}({i + 1}) {name}: SIGNAL has shape "
                                  f"{signal.shape}, expected samples x dims")
        names.append(name)
        signals.append(signal)
        rates.append(rate)
    if not names:
        raise DataFormatError(path, None, f"{key} holds no movement channel (2 or 3 columns)")
    for name, signal, rate in zip(names, signals, rates, strict=True):
        if rate != rates[0] or signal.shape[0] != signals[0].shape[0]:
            raise DataFormatError(path, None, f"{name}: {signal.shape[0]} samples at {rate:g} "
                                  f"Hz, but {names[0]} has {signals[0].shape[0]} at "
                                  f"{rates[0]:g} Hz (movement channels must share both)")
    dims = 3 if max(s.shape[1] for s in signals) >= 3 else 2
    for name, signal in zip(names, signals, strict=True):
        if signal.shape[1] < dims:
            raise DataFormatError(path, None, f"{name}: {signal.shape[1]} columns, others "
                                  f"have {dims} (a missing channel)")
    positions = np.stack([s[:, :dims] for s in signals], axis=1)
    extra = [s.shape[1] - dims for s in signals]
    orientation = None
    if max(extra) > 0:
        orientation = np.full(positions.shape[:2] + (max(extra),), np.nan)
        for j, s in enumerate(signals):
            orientation[:, j, : s.shape[1] - dims] = s[:, dims:]
    n = positions.shape[0]
    times = np.arange(n) / rates[0]
    labels = _label_tiers(path, entries, n / rates[0], notes)
    return RawEma(format="mview", times=times, names=tuple(names), positions=positions,
                  rate_hz=rates[0], units="mm (mview)", path=path, orientation=orientation,
                  axes="not stated by the file (Haskins data are usually head-corrected)",
                  frame=None, notes=(f"variable {key!r}", *notes), sound=sound,
                  labels=labels)


def _sound(path: Path, name: str, samples: np.ndarray, rate: float, notes: list[str]):
    from ..sound import Sound

    if not np.isfinite(samples).all():
        notes.append(f"{name}: sound with non-finite samples (not used)")
        return None
    peak = float(np.max(np.abs(samples))) if samples.size else 0.0
    if peak > 1.0:
        scale = 32768.0 if peak <= 32768.0 else peak
        samples = samples / scale
        notes.append(f"{name}: sound samples up to {peak:.6g} divided by {scale:g}")
    notes.append(f"{name}: the recording's sound ({samples.size / rate:.3g} s at "
                 f"{rate:g} Hz)")
    return Sound.from_samples(samples, rate, f"{path}: {name}", "mview AUDIO")


LABEL_FIELDS = {"WORDS": "words", "PHONES": "phones", "LABELS": "labels"}
_TEXT_FIELDS = ("LABEL", "NAME", "WORD", "PHONE", "TEXT")
_TIME_FIELDS = ("OFFS", "OFFSET", "OFFSETS", "TIME", "TIMES")


def _intervals(path: Path, field_name: str, value) -> list[tuple[float, float, str]]:
    value = np.asarray(value)
    names = value.dtype.names or ()
    text = next((f for f in _TEXT_FIELDS if f in names), None)
    when = next((f for f in _TIME_FIELDS if f in names), None)
    if value.size == 0:
        return []
    if text is None or when is None:
        raise DataFormatError(path, None, f"{field_name}: labels need a text field "
                              f"({'/'.join(_TEXT_FIELDS)}) and a time field "
                              f"({'/'.join(_TIME_FIELDS)}); it has {', '.join(names) or 'none'}")
    out = []
    for k, item in enumerate(value.ravel()):
        try:
            times = np.asarray(item[when], np.float64).ravel()
        except (TypeError, ValueError):
            times = np.array([])
        if times.size not in (1, 2):
            raise DataFormatError(path, None, f"{field_name}({k + 1}): {when} must be [start "
                                  "end] or one time")
        out.append((float(times[0]), float(times[-1]), _text(item[text])))
    return out


def _label_tiers(path: Path, entries, length_s: float, notes: list[str]) -> tuple:
    """The label tiers stored in the struct's ``WORDS``/``PHONES``/``LABELS`` fields."""
    from ..labels import Labels

    names = entries.dtype.names or ()
    tiers = []
    for field_name, tier in LABEL_FIELDS.items():
        if field_name not in names:
            continue
        rows = [r for entry in entries for r in _intervals(path, field_name, entry[field_name])]
        if not rows:
            continue
        rows.sort(key=lambda r: r[0])
        times = np.array([[a, b] for a, b, _ in rows])
        last = float(times.max())
        if last > 1.05 * length_s + 0.25 and last / 1000.0 <= 1.05 * length_s + 0.25:
            times = times / 1000.0
            notes.append(f"{field_name}: times read as milliseconds (as seconds they run to "
                         f"{last:.4g} s, past the recording's {length_s:.3g} s)")
        try:
            tiers.append(Labels(times[:, 0], times[:, 1], [r[2] for r in rows], tier, path))
        except DataFormatError as exc:
            raise DataFormatError(path, None, f"{field_name}: {exc.reason}") from None
        notes.append(f"{field_name}: {len(rows)} labels (tier {tier!r})")
    return tuple(tiers)


def _identifier(stem: str) -> str:
    """A MATLAB variable name from a file stem (letters, digits, ``_``; a letter first)."""
    name = re.sub(r"\W", "_", stem)
    return name if name[:1].isalpha() else f"v{name}"


def write_mview(path: str | os.PathLike, raw: RawEma, *, variable: str | None = None,
                audio: tuple[np.ndarray, float] | None = None, labels=(),
                overwrite: bool = False) -> Path:
    """Write ``raw`` as an mview ``.mat`` file (MATLAB 5 format, through
    ``scipy.io.savemat``): one struct array named ``variable`` (default the file's stem),
    ``AUDIO`` first when ``audio = (samples, rate)`` is given, then one entry per sensor
    (``SIGNAL`` ``[n x dims]`` mm, NaN untracked); ``labels`` (``Labels`` tiers named
    ``words``, ``phones`` or ``labels``) go in the first entry's ``WORDS``/``PHONES``/
    ``LABELS`` field (``LABEL`` and ``OFFS`` = ``[start end]`` s). Written atomically;
    never replaces an input, nor an existing file unless ``overwrite``."""
    import io

    from scipy.io import savemat

    path = Path(path)
    entries = []
    if audio is not None:
        entries.append(("AUDIO", float(audio[1]), np.asarray(audio[0], np.float64)[:, None]))
    entries += [(name, float(raw.rate_hz), raw.positions[:, j, :])
                for j, name in enumerate(raw.names)]
    by_field = {f: t for t in labels for f, name in LABEL_FIELDS.items() if t.tier == name}
    fields = FIELDS + tuple(by_field)
    struct = np.empty((1, len(entries)), dtype=[(f, object) for f in fields])
    for j, (name, rate, signal) in enumerate(entries):
        extra = [_label_struct(by_field[f]) if j == 0 else np.zeros((0, 0))
                 for f in by_field]
        struct[0, j] = (name, rate, signal, *extra)
    buffer = io.BytesIO()
    savemat(buffer, {variable or _identifier(path.stem): struct}, format="5",
            do_compression=False)
    return atomic_write(path, buffer.getvalue(), overwrite=overwrite, data_file=True)


def _label_struct(tier) -> np.ndarray:
    out = np.empty((1, len(tier)), dtype=[("LABEL", object), ("OFFS", object)])
    for k, seg in enumerate(tier.segments()):
        out[0, k] = (seg.label, np.array([[seg.start, seg.end]]))
    return out
