"""The sound beside a recording (``X.wav``), checked against the pellets' length.

An XRMB recording's sound and pellets start together (sample 0 = time 0) and last about
as long (JW11 task 5: 5.03 s of sound, 5.01 s of pellets). :func:`check_sound` reads the
``.wav`` header only and compares: a sound within ``max(SOUND_TOLERANCE_S, 5 %)`` of the
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
``cassi info`` call it; this module is the standard library's ``wave`` only.

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
import tempfile
import warnings
import wave
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

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


def open_pcm(path: str | os.PathLike, *, samples: bool = True
             ) -> tuple[wave._wave_params, bytes]:
    """``(parameters, sample bytes)`` of the integer-PCM ``.wav`` at ``path`` (``b""``
    without ``samples``: the header only), nothing checked beyond what :mod:`wave` reads;
    :class:`DataFormatError` naming the file if it is missing, not a WAVE file, truncated,
    compressed or float."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(path, None, "sound file not found (or not a regular file)")
    try:
        with wave.open(str(path), "rb") as src:
            params = src.getparams()
            data = src.readframes(params.nframes) if samples else b""
    except (wave.Error, EOFError, OSError) as exc:
        reason = str(exc) or "empty or truncated header"
        if "unknown format: 3" in reason:
            reason = "float samples; only integer PCM is read"
        raise DataFormatError(path, None, f"not a readable PCM .wav file ({reason})") from None
    return params, data


def read_header(path: str | os.PathLike) -> wave._wave_params:
    """The parameters of a PCM ``.wav`` (header only); :class:`DataFormatError` naming the
    file if it is missing, not a WAVE file, compressed or float, or has a rate or channel
    count of 0."""
    path = Path(path)
    params, _ = open_pcm(path, samples=False)
    if params.framerate <= 0 or params.nchannels <= 0:
        raise DataFormatError(path, None, f"bad .wav header: rate {params.framerate} Hz, "
                              f"{params.nchannels} channels")
    return params


def _likely_rate(n_samples: int, recording_s: float, header_hz: int) -> int | None:
    if recording_s <= 0:
        return None
    implied = n_samples / recording_s
    for rate in STANDARD_RATES_HZ:
        if rate != header_hz and abs(implied - rate) <= RATE_MATCH * rate:
            return rate
    return None


def _held_frames(params: wave._wave_params, data: bytes) -> int:
    return len(data) // max(params.sampwidth * params.nchannels, 1)


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
    path = Path(path)
    params, data = open_pcm(path)
    read_header(path)  # a rate or channel count of 0
    return _check(str(path), params, _held_frames(params, data), recording_s,
                  accept_mismatch)


def _check(where: str, params: wave._wave_params, held: int, recording_s: float,
           accept_mismatch: bool) -> SoundCheck:
    rate, n = int(params.framerate), int(params.nframes)
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

    def _open(self) -> tuple[wave._wave_params, bytes]:
        if self.path is not None:
            return open_pcm(self.path)
        try:
            with wave.open(io.BytesIO(self.data), "rb") as src:
                params = src.getparams()
                return params, src.readframes(params.nframes)
        except (wave.Error, EOFError) as exc:
            reason = str(exc) or "empty or truncated header"
            raise DataFormatError(self.source, None, f"not a readable PCM .wav sound "
                                  f"({reason})") from None

    def params(self) -> wave._wave_params:
        """The sound's ``.wav`` parameters (rate, channels, samples...)."""
        params, _ = self._open()
        if params.framerate <= 0 or params.nchannels <= 0:
            raise DataFormatError(self.source, None, f"bad .wav header: rate "
                                  f"{params.framerate} Hz, {params.nchannels} channels")
        return params

    def check(self, recording_s: float, *, accept_mismatch: bool = False) -> SoundCheck:
        """:func:`check_sound` for this sound."""
        params, data = self._open()
        self.params()
        return _check(self.source, params, _held_frames(params, data), recording_s,
                      accept_mismatch)

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
        params = self.params()
        return (f"{self.source} ({self.kind}): {params.nframes / params.framerate:.3g} s at "
                f"{params.framerate} Hz, {params.nchannels} channel(s)")
