"""Carstens AG500 / AG501 position files (``.pos``): read and write.

The format (from two independent public readers: Praat's ``EMA.cpp`` and the
``org.m2ci.msp.ema`` Java library with its test files; see docs/EMA.md):

* AG501 (and AG500 files written by newer software): a text header, then the samples.
  Line 1 ``AG50xDATA_V00<v>`` (v = 1, 2 or 3), line 2 the header's total size in bytes as
  8 decimal digits (``00000070``), then ``NumberOfChannels=<N>`` and
  ``SamplingFrequencyHz=<F>`` lines, padding (``\\0``, ``\\x1A``) up to that size. Other
  ``key=value`` lines are accepted and ignored; CRLF is accepted.
* AG500 (older software): no header at all; 12 channels at 200 Hz.
* Samples: little-endian float32, frame after frame, each frame ``N`` channels of 7 values:
  ``x, y, z`` (mm), ``phi, theta`` (degrees: the sensor's orientation), ``rms`` (the fit's
  residual) and one more value. Positions are in the device's frame (the transmitter
  cube's), not the head's: :mod:`cassi_fit.ema.track` corrects the head and rotates into
  the occlusal frame.

The file carries no sensor names: channels are named ``Ch1`` ... ``ChN`` (1-based, as the
device numbers them) and a sensor map names them (docs/EMA.md). A NaN value is untracked;
a channel whose x, y and z are all exactly 0 in a frame is untracked there (unused
channels hold zeros). Refused with a :class:`DataFormatError` naming the file and byte
offset: a header whose size or counts are missing or not numbers, a header longer than the
file, a body that is not a whole number of frames (truncated), a headerless file whose
size is not a whole number of 12-channel frames.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._io import atomic_write
from ..errors import DataFormatError
from ._raw import RawEma, read_bytes

MAGIC = b"AG50xDATA_V00"
VALUES_PER_CHANNEL = 7  # x, y, z, phi, theta, rms, extra
AG500_CHANNELS = 12
AG500_RATE_HZ = 200.0
_KEY = re.compile(rb"^([A-Za-z_][A-Za-z0-9_]*)=(.*)$")


def is_ag50x(head: bytes) -> bool:
    """Whether a file starts with the AG501 (or newer AG500) text header."""
    return head.startswith(MAGIC)


def channel_names(n: int) -> tuple[str, ...]:
    """``Ch1`` ... ``Chn``: the names given to a ``.pos`` file's channels."""
    return tuple(f"Ch{i + 1}" for i in range(n))


def _parse_header(path: Path, raw: bytes) -> tuple[int, int, float, str]:
    """``(body offset, channels, rate Hz, version)`` of an AG50x header."""
    lines = raw[:4096].replace(b"\r\n", b"\n").split(b"\n")
    version = lines[0][len(MAGIC):len(MAGIC) + 1].decode("ascii", "replace")
    if version not in ("1", "2", "3"):
        raise DataFormatError(path, 1, f"unknown AG50x header version {lines[0][:20]!r}")
    size_text = lines[1].strip() if len(lines) > 1 else b""
    if not size_text.isdigit():
        raise DataFormatError(path, 2, f"header size {size_text[:20]!r} is not a number "
                              "(expected 8 digits, e.g. 00000070)")
    size = int(size_text)
    if size > len(raw):
        raise DataFormatError(path, 2, f"header size {size} bytes is more than the file's "
                              f"{len(raw)} bytes")
    keys: dict[str, str] = {}
    for line in raw[:size].replace(b"\r\n", b"\n").split(b"\n")[2:]:
        match = _KEY.match(line.strip(b"\0\x1a \t"))
        if match:
            keys[match.group(1).decode("ascii").lower()] = match.group(2).decode(
                "ascii", "replace").strip()
    try:
        channels = int(keys["numberofchannels"])
        rate = float(keys["samplingfrequencyhz"])
    except KeyError as exc:
        raise DataFormatError(path, None, f"AG50x header has no {exc.args[0]} line "
                              "(NumberOfChannels=, SamplingFrequencyHz=)") from None
    except ValueError:
        raise DataFormatError(path, None, "AG50x header: NumberOfChannels or "
                              "SamplingFrequencyHz is not a number") from None
    if not (0 < channels <= 64) or not (0 < rate <= 10000):
        raise DataFormatError(path, None, f"AG50x header: {channels} channels at {rate} Hz is "
                              "not a recording (1-64 channels, up to 10 kHz)")
    return size, channels, rate, version


def read_pos(path: str | os.PathLike, *, channels: int | None = None,
             rate: float | None = None) -> RawEma:
    """Read a Carstens ``.pos`` file (AG501 with its header, or a headerless AG500 file)
    into a :class:`RawEma` (mm, the device frame, channels ``Ch1``...).

    ``channels`` and ``rate`` are for a headerless file recorded with other settings than
    AG500's 12 channels at 200 Hz; a header's values win (a disagreement is an error).
    """
    path, raw = read_bytes(path, ".pos file")
    if is_ag50x(raw):
        offset, n_ch, hz, version = _parse_header(path, raw)
        for given, found, what in ((channels, n_ch, "channels"), (rate, hz, "rate")):
            if given is not None and float(given) != float(found):
                raise DataFormatError(path, None, f"the header says {found:g} {what}, "
                                      f"{given:g} was given")
        fmt = "ag501"
        source = f"AG50x header version {version}"
    else:
        offset, n_ch = 0, int(channels or AG500_CHANNELS)
        hz = float(rate or AG500_RATE_HZ)
        fmt = "ag500"
        source = f"no header: AG500 layout, {n_ch} channels at {hz:g} Hz"
    frame_bytes = 4 * VALUES_PER_CHANNEL * n_ch
    size = len(raw) - offset
    if size == 0:
        raise DataFormatError(path, None, "no samples after the header")
    if size % frame_bytes:
        full = size // frame_bytes
        hint = "" if fmt == "ag501" else (" (a headerless file is read as AG500: 12 channels "
                                          "of 7 float32; is this a .pos file?)")
        raise DataFormatError(path, None, f"truncated: {size} bytes of samples are {full} "
                              f"frames of {n_ch} channels x 7 float32 and "
                              f"{size - full * frame_bytes} bytes more (byte offset "
                              f"{offset + full * frame_bytes}){hint}")
    values = np.frombuffer(raw, dtype="<f4", offset=offset).astype(np.float64)
    if fmt == "ag501":
        _check_channel_count(path, values, n_ch)
    values = values.reshape(-1, n_ch, VALUES_PER_CHANNEL)
    positions = values[..., :3].copy()
    unused = (positions == 0).all(axis=-1)
    positions[unused] = np.nan
    n = values.shape[0]
    times = np.arange(n) / hz
    notes = [source]
    never = [f"Ch{i + 1}" for i in range(n_ch) if np.isnan(positions[:, i]).all()]
    if never:
        notes.append(f"channel(s) {', '.join(never)} never tracked (all NaN or zero)")
    return RawEma(format=fmt, times=times, names=channel_names(n_ch), positions=positions,
                  rate_hz=hz, units="mm (x, y, z), degrees (phi, theta)",
                  axes="the articulograph's device frame (Carstens)", frame=None, path=path,
                  orientation=values[..., 3:], notes=tuple(notes))


def _median_step(values: np.ndarray, n_ch: int) -> float:
    """The median frame-to-frame move (mm) of the tracked positions read as ``n_ch``
    channels (inf when nothing is tracked twice in a row)."""
    pos = values.reshape(-1, n_ch, VALUES_PER_CHANNEL)[..., :3]
    pos = np.where((pos == 0).all(-1, keepdims=True), np.nan, pos)
    steps = np.linalg.norm(np.diff(pos, axis=0), axis=-1)
    steps = steps[np.isfinite(steps)]
    return float(np.median(steps)) if steps.size else np.inf


def _check_channel_count(path: Path, values: np.ndarray, n_ch: int) -> None:
    """An error naming the file when the samples fit another channel count far better
    than the header's: read with the wrong count, consecutive "frames" jump between
    different sensors (tens of mm) instead of moving a fraction of a millimetre."""
    total = values.size // VALUES_PER_CHANNEL
    claimed = _median_step(values, n_ch)
    if not (np.isfinite(claimed) and claimed > 0.5) or total // n_ch < 4:
        return
    fits = {m: _median_step(values, m) for m in range(1, 65)
            if m != n_ch and total % m == 0 and total // m >= 4}
    better = [m for m, step in fits.items() if step * 10 < claimed]
    if better:
        m = min(better)
        raise DataFormatError(path, None, f"the header says {n_ch} channels, but the samples "
                              f"fit {m} channels: read as {n_ch}, each sensor jumps "
                              f"{claimed:.3g} mm between frames (median), as {m} it moves "
                              f"{fits[m]:.3g} mm (a wrong NumberOfChannels line)")


def ag501_header(n_channels: int, rate_hz: float) -> bytes:
    """The AG501 header (version 2) as Carstens writes it: 70 bytes for two-digit channel
    counts and rates, padded with ``\\0`` and ending in ``\\x1A``."""
    lines = f"NumberOfChannels={n_channels}\nSamplingFrequencyHz={rate_hz:g}\n".encode("ascii")
    size = len(b"AG50xDATA_V002\n") + 9 + len(lines) + 2
    return b"AG50xDATA_V002\n" + f"{size:08d}\n".encode("ascii") + lines + b"\0\x1a"


def write_pos(path: str | os.PathLike, raw: RawEma, *, header: bool = True,
              overwrite: bool = False) -> Path:
    """Write ``raw`` (3D, uniform rate) as a ``.pos`` file: the AG501 header (unless
    ``header`` is False: the AG500 layout, which has 12 channels at 200 Hz), then 7
    float32 per channel (x, y, z mm; phi, theta from ``raw.orientation`` if present else
    0; rms 0; extra 0). Untracked values are written as NaN. Written atomically; never
    replaces an input, nor an existing file unless ``overwrite``."""
    if raw.dims != 3:
        raise DataFormatError(path, None, "cannot write a .pos file from 2D positions")
    n, k = raw.n_frames, len(raw.names)
    if not header and (k != AG500_CHANNELS or raw.rate_hz != AG500_RATE_HZ):
        raise DataFormatError(path, None, "a headerless (AG500) .pos file holds 12 channels "
                              "at 200 Hz")
    values = np.zeros((n, k, VALUES_PER_CHANNEL))
    values[..., :3] = raw.positions
    if raw.orientation is not None:
        m = min(2, raw.orientation.shape[-1])
        values[..., 3:3 + m] = raw.orientation[..., :m]
    data = values.astype("<f4").tobytes()
    if header:
        data = ag501_header(k, raw.rate_hz) + data
    return atomic_write(path, data, overwrite=overwrite, data_file=True)
