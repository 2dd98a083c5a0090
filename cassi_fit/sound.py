"""The sound beside a recording (``X.wav``), checked against the pellets' length.

An XRMB recording's sound and pellets start together (sample 0 = time 0) and last about
as long (JW11 task 5: 5.03 s of sound, 5.01 s of pellets). :func:`check_sound` reads the
``.wav`` header (and maps its samples) and compares: a sound within ``max(SOUND_TOLERANCE_S, 5 %)`` of the
recording is ``"ok"``; otherwise one line says the numbers and the likely cause:

* ``"rate"`` (an error): the samples would fill the recording at a standard rate other
  than the header's (16 kHz samples with a 44.1 kHz header give 1.8 s of sound for a 5 s
  recording; an 8 kHz header gives 10 s): the sound would play at the wrong speed and
  drift against the pellets. A file cut to exactly half or a quarter also fits a
  standard rate; the message names both causes.
* ``"shorter"``: less sound than pellets; an error when it covers less than half of the
  recording (a cut file, 0.1 s of sound), a warning otherwise (the end is silent).
* ``"longer"``: more sound than pellets, a warning (a video keeps the part the pellets
  cover).

* a **cut file** (an error, before the above): the header claims more samples than the
  file holds (half of a video would be silence); accepted, the samples held are checked.

``accept_mismatch=True`` turns every error into a :class:`SoundMismatchWarning` (the
sound is then used as it is: padded or cut, never resampled). The video writer and
``cassi info`` call it.

**Reading** (:func:`read_wav`, the one reader of sound files): what labs' files hold, not
only 16-bit PCM: integer PCM of 8, 16, 24 or 32 bits, 32- or 64-bit float, plain or in
``WAVE_FORMAT_EXTENSIBLE`` headers (through :mod:`scipy.io.wavfile`; the standard
library's ``wave`` reads 8-32-bit integer PCM in plain headers only); compressed ``.wav``
(ADPCM, mu-law...) is refused in one line naming the file. The formants are measured on
the first channel (:meth:`Sound.samples`).

**A recording's sound** is a :class:`Sound`: a ``.wav`` beside the recording file, or the
sound stored inside it (Haskins mview's ``AUDIO`` channel, an EMU bundle's media file),
used alike: :meth:`Sound.check` compares it with the recording and
:meth:`Sound.wav_file` gives a ``.wav`` path for the video writer (the file itself, or a
temporary copy of the sound held in memory).
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
import tempfile
import warnings
import wave
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from jaxtyping import Float

from .errors import DataFormatError
from .status import LengthFit

#: Below this difference (s), or 5 % of the recording, sound and pellets agree.
SOUND_TOLERANCE_S = 0.25
SOUND_TOLERANCE_FRACTION = 0.05
#: Rates a ``.wav`` header plausibly holds (Hz); the XRMB sound is 16 kHz or resampled.
STANDARD_RATES_HZ = (8000, 11025, 16000, 22050, 24000, 32000, 44100, 48000, 96000)
#: How close (relative) the implied rate must be to a standard one to be named.
RATE_MATCH = 0.02


class SoundMismatchWarning(UserWarning):
    """The sound's length does not fit the pellets' (accepted or only a warning)."""


@dataclass(frozen=True)
class SoundCheck:
    """The sound against the recording (JSON-ready through :meth:`to_dict`).

    ``rate_hz`` and ``n_samples`` from the header; ``sound_s`` = ``n_samples / rate_hz``;
    ``recording_s`` the pellets' length; ``status`` ``"ok"``, ``"rate"``, ``"shorter"``
    or ``"longer"``; ``likely_rate_hz`` the standard rate at which the samples would fill
    the recording (None if none fits); ``message`` the one line (None when ok)."""

    path: str
    rate_hz: int
    n_samples: int
    sound_s: float
    recording_s: float
    status: str
    likely_rate_hz: int | None
    message: str | None

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


@dataclass(frozen=True)
class WavInfo:
    """What a ``.wav`` holds: ``framerate`` (Hz), ``nchannels``, ``nframes`` (samples per
    channel the header claims), ``held`` (those the file holds: fewer in a cut file) and
    ``encoding`` (``"16-bit PCM"``, ``"32-bit float"``...; 24-bit PCM is read as 32-bit)."""

    framerate: int
    nchannels: int
    nframes: int
    held: int
    encoding: str


def _data_chunk(handle: io.BytesIO | Path) -> tuple[int, int, int] | None:
    """``(block bytes, data offset, data bytes claimed)`` of a RIFF/WAVE header: its
    ``fmt `` chunk's block alignment and where its ``data`` chunk starts and how long it
    says it is; None where the header is not one (:mod:`scipy.io.wavfile` says why)."""
    with (open(handle, "rb") if isinstance(handle, Path) else contextlib.nullcontext(handle)) as f:
        f.seek(0)
        if f.read(12)[8:12] != b"WAVE":
            return None
        block = None
        while len(head := f.read(8)) == 8:
            chunk, size = head[:4], struct.unpack("<I", head[4:])[0]
            if chunk == b"fmt ":
                block = struct.unpack("<H", f.read(16)[12:14])[0]
                f.seek(size - 16 + size % 2, io.SEEK_CUR)
            elif chunk == b"data":
                return (block, f.tell(), size) if block else None
            else:
                f.seek(size + size % 2, io.SEEK_CUR)
    return None


def read_wav(source: str | os.PathLike | bytes, *, where: str | os.PathLike | None = None,
             header_only: bool = False) -> tuple[WavInfo, np.ndarray]:
    """``(WavInfo, samples (held, channels))`` of a ``.wav`` file or its bytes, the samples
    in their stored type (:func:`as_float` scales them to [-1, 1]): integer PCM of 8 to 32
    bits (24-bit in 32-bit integers), 32- and 64-bit float, plain or
    ``WAVE_FORMAT_EXTENSIBLE`` (through :mod:`scipy.io.wavfile`). ``header_only`` maps the
    samples instead of reading them where it can. :class:`DataFormatError` naming the file
    (``where``, default the path) if it is missing, not a WAVE file, compressed, or has a
    rate or channel count of 0; a cut file is read (``held < nframes``, a partial last
    sample dropped): its callers say so."""
    from scipy.io import wavfile

    if isinstance(source, bytes):
        where, handle = where or "sound", io.BytesIO(source)
    else:
        where, handle = where or source, Path(source)
        if not handle.is_file():
            raise DataFormatError(where, None, "sound file not found (or not a regular file)")
    layout = _data_chunk(handle)

    def read(mmap: bool):
        with warnings.catch_warnings():  # a cut file, chunks it skips: said below or moot
            warnings.simplefilter("ignore", wavfile.WavFileWarning)
            if isinstance(handle, io.BytesIO):
                handle.seek(0)
            return wavfile.read(handle, mmap=mmap)

    mmap = header_only and isinstance(handle, Path)
    try:
        for attempt in range(3):
            try:
                rate, data = read(mmap)
                break
            except ValueError as exc:
                if attempt == 2 or not (mmap or ("reshape" in str(exc) and layout)):
                    raise
                if mmap:  # 24-bit samples cannot be mapped: read them
                    mmap = False
                    continue
                block, start, _ = layout  # cut inside a sample: drop its part
                raw = handle.read_bytes() if isinstance(handle, Path) else handle.getvalue()
                handle = io.BytesIO(raw[: start + (len(raw) - start) // block * block])
    except (ValueError, EOFError, OSError, IndexError, struct.error) as exc:
        reason = str(exc).strip().rstrip(".") or "empty or truncated header"
        raise DataFormatError(where, None, f"not a readable .wav file ({reason})") from None
    data = data[:, None] if data.ndim == 1 else data
    if rate <= 0 or data.shape[1] <= 0:
        raise DataFormatError(where, None, f"bad .wav header: rate {rate} Hz, "
                              f"{data.shape[1]} channels")
    held = data.shape[0]
    nframes = held if layout is None else max(layout[2] // layout[0], held)
    kind = "float" if data.dtype.kind == "f" else "PCM"
    info = WavInfo(int(rate), int(data.shape[1]), nframes, held,
                   f"{8 * data.dtype.itemsize}-bit {kind}")
    return info, data


def as_float(samples: np.ndarray) -> Float[np.ndarray, "n c"]:
    """Samples as :func:`read_wav` gives them, scaled to [-1, 1] (float64): integers by
    their type's range (8-bit PCM is unsigned), floats as they are."""
    x = np.asarray(samples)
    if x.dtype.kind == "f":
        return x.astype(np.float64)
    if x.dtype == np.uint8:
        return (x.astype(np.float64) - 128.0) / 128.0
    return x.astype(np.float64) / float(2 ** (8 * x.dtype.itemsize - 1))


def _likely_rate(n_samples: int, recording_s: float, header_hz: int) -> int | None:
    if recording_s <= 0:
        return None
    implied = n_samples / recording_s
    for rate in STANDARD_RATES_HZ:
        if rate != header_hz and abs(implied - rate) <= RATE_MATCH * rate:
            return rate
    return None


def check_sound(path: str | os.PathLike | Sound, recording_s: float, *,
                accept_mismatch: bool = False) -> SoundCheck:
    """Compare the ``.wav`` at ``path`` with a recording of ``recording_s`` seconds (e.g.
    ``PelletTrack.length_s``); see the module docstring.

    Returns a :class:`SoundCheck`. A mismatch that would make a wrong result raises
    :class:`DataFormatError` naming the file (one line: the numbers and the likely
    cause), unless ``accept_mismatch``; a lesser one, or an accepted one, warns
    (:class:`SoundMismatchWarning`).
    """
    if isinstance(path, Sound):
        return path.check(recording_s, accept_mismatch=accept_mismatch)
    info, _ = read_wav(path, header_only=True)
    return _check(str(path), info, recording_s, accept_mismatch)


def _check(where: str, info: WavInfo, recording_s: float, accept_mismatch: bool) -> SoundCheck:
    rate, n, held = info.framerate, info.nframes, info.held
    if held < n:
        message = (f"the header claims {n} samples ({n / rate:.3g} s) but the file holds "
                   f"{held} ({held / rate:.3g} s): the file is cut")
        if not accept_mismatch:
            raise DataFormatError(where, None, message + " (accept it with "
                                  "accept_mismatch=True)")
        warnings.warn(f"{where}: {message}", SoundMismatchWarning, stacklevel=3)
        n = held
    sound_s = n / rate
    recording_s = float(recording_s)
    tolerance = max(SOUND_TOLERANCE_S, SOUND_TOLERANCE_FRACTION * recording_s)
    likely = _likely_rate(n, recording_s, rate)
    numbers = (f"{sound_s:.3g} s of sound ({n} samples at {rate} Hz) for {recording_s:.3g} s "
               "of pellets")
    if abs(sound_s - recording_s) <= tolerance:
        return SoundCheck(where, rate, n, sound_s, recording_s, LengthFit.OK.label, None,
                          None)
    if likely is not None:
        status, error = LengthFit.RATE.label, True
        cause = (f"the header's rate is likely wrong: the samples fill the recording at "
                 f"{likely} Hz")
        if sound_s < recording_s:
            cause += ", or the file is cut"
    elif sound_s < recording_s:
        status, error = LengthFit.SHORTER.label, sound_s < 0.5 * recording_s
        cause = (f"the file looks cut: a video would be silent after {sound_s:.3g} s")
    else:
        status, error = LengthFit.LONGER.label, False
        cause = f"a video keeps the first {recording_s:.3g} s"
    message = f"{numbers}: {cause}"
    if error and not accept_mismatch:
        raise DataFormatError(where, None, message + " (accept it with accept_mismatch=True)")
    warnings.warn(f"{where}: {message}", SoundMismatchWarning, stacklevel=3)
    return SoundCheck(where, rate, n, sound_s, recording_s, status, likely, message)


@dataclass(frozen=True, eq=False)
class Sound:
    """A recording's sound: a ``.wav`` file (``path``), or PCM ``.wav`` bytes held in
    memory (``data``: the sound stored inside a recording file), with ``source`` naming it
    in messages (the path, or ``rec.mat: AUDIO``) and ``kind`` saying where it was found
    (``"wav beside"``, ``"mview AUDIO"``, ``"EMU media"``)."""

    source: str
    kind: str
    path: Path | None = None
    data: bytes | None = None

    def __post_init__(self):
        if (self.path is None) == (self.data is None):
            raise ValueError("Sound: give a path or the .wav bytes (one of them)")

    @classmethod
    def from_file(cls, path: str | os.PathLike, kind: str = "wav beside") -> Sound:
        return cls(str(path), kind, path=Path(path))

    @classmethod
    def from_samples(cls, samples, rate_hz: float, source: str, kind: str) -> Sound:
        """A sound from float samples in [-1, 1] (``(n,)`` or ``(n, channels)``), stored
        as 16-bit PCM."""
        values = np.asarray(samples, np.float64)
        values = values[:, None] if values.ndim == 1 else values
        pcm = np.round(np.clip(values, -1.0, 32767 / 32768) * 32768).astype("<i2")
        buffer = io.BytesIO()
        with wave.open(buffer, "wb") as out:
            out.setnchannels(pcm.shape[1])
            out.setsampwidth(2)
            out.setframerate(int(round(rate_hz)))
            out.writeframes(pcm.tobytes())
        return cls(source, kind, data=buffer.getvalue())

    def read(self, *, header_only: bool = False) -> tuple[WavInfo, np.ndarray]:
        """:func:`read_wav` of this sound (the file, or the bytes held)."""
        return read_wav(self.path if self.path is not None else self.data, where=self.source,
                        header_only=header_only)

    def info(self) -> WavInfo:
        """The sound's rate, channels, length and encoding (:class:`WavInfo`)."""
        return self.read(header_only=True)[0]

    def samples(self) -> tuple[Float[np.ndarray, " n"], float]:
        """``(samples in [-1, 1], rate Hz)``: the first channel (a recording's microphone:
        a second channel is often a trigger or a second microphone), all it holds."""
        info, data = self.read()
        return as_float(data[:, 0]), float(info.framerate)

    def check(self, recording_s: float, *, accept_mismatch: bool = False) -> SoundCheck:
        """:func:`check_sound` for this sound."""
        return _check(self.source, self.info(), recording_s, accept_mismatch)

    @contextlib.contextmanager
    def wav_file(self) -> Iterator[Path]:
        """A ``.wav`` path holding this sound while the context lasts: the file itself, or
        a temporary file (removed afterwards) for a sound held in memory."""
        if self.path is not None:
            yield self.path
            return
        with tempfile.TemporaryDirectory(prefix="cassi-sound-") as folder:
            path = Path(folder) / "sound.wav"
            path.write_bytes(self.data)
            yield path

    def describe(self) -> str:
        """One line: where the sound is, its rate, channels and length."""
        info = self.info()
        return (f"{self.source} ({self.kind}): {info.held / info.framerate:.3g} s at "
                f"{info.framerate} Hz, {info.nchannels} channel(s), {info.encoding}")
