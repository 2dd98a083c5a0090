"""The formants measured from a recording's sound: Praat's Burg tracker (praat-parselmouth).

:func:`measure_formants` runs Praat's ``To Formant (burg)`` (Boersma & Weenink, Praat; the
field's reference implementation, through praat-parselmouth, Jadoul, Thompson & de Boer
2018) on the sound and reads F1-F3 and their bandwidths at the given frame times. The
formant ceiling is the speaker's option: Praat's own advice is 5000 Hz for an adult male,
5500 Hz for an adult female (``CEILING_HZ``); a wrong ceiling splits or merges formants, so
a study sets it per speaker.

A frame's measurement is *reliable* only where all three hold, and an unreliable frame is
never scored (``FormantTrack.reason`` says why, ``share_reliable`` how many are left):

* ``silence``: the frame's intensity is more than ``SILENCE_DB`` below the recording's
  loudest frame;
* ``unvoiced``: Praat's pitch tracker (``To Pitch``, 75-500 Hz) finds no voicing there;
* ``wide bandwidth``: a bandwidth of F1-F3 is over ``MAX_BANDWIDTH_HZ`` (or a formant is
  missing): no clear resonance to measure.

**The speaker from the voice** (:func:`voice_speaker`): the median F0 of the sound's voiced
frames (Praat's pitch tracker, as above: :func:`voice_pitch`, run once per sound, its track
read by :func:`median_f0` and handed to :func:`measure_formants` as ``pitch``) against ``F0_BOUNDARY_HZ`` = 160 Hz: an adult
male voice below it, an adult female voice at or above it. Typical speaking F0 is 120 Hz
for men and 210 Hz for women (Traunmueller & Eriksson 1995, "The frequency range of the
voice fundamental in the speech of male and female adults", Stockholm University); 160 Hz
is their geometric mean (159 Hz; F0 ranges compare on a log scale, in semitones, as they
show), and it lies in the gap between the typical adult male (85-155 Hz) and female
(165-255 Hz) speaking F0 of Baken (2000, *Clinical Measurement of Speech and Voice*, 2nd
ed., p. 177, after Fitch & Holbrook 1970). A voice's F0 is not its sex: a child, a low
female or a high male voice is misjudged. The toolkit's norms stay the adult male ones
unless asked (``cassi_fit.acoustics.speaker_norms``); the voice's F0 only says when another
might fit.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import Bool, Float, Shaped

if TYPE_CHECKING:
    import parselmouth

CEILING_HZ = {"male": 5000.0, "female": 5500.0}
WINDOW_S = 0.025
N_FORMANTS_BURG = 5
SILENCE_DB = 30.0
MAX_BANDWIDTH_HZ = 1000.0
PITCH_FLOOR_HZ = 75.0
PITCH_CEILING_HZ = 500.0
#: The median speaking F0 (Hz) at and above which a voice is taken as an adult female's
F0_BOUNDARY_HZ = 160.0


@dataclass(frozen=True, eq=False)
class FormantTrack:
    """F1-F3 measured at ``times (m,)`` s: ``frequency``, ``bandwidth`` ``(m, 3)`` Hz (NaN
    where Praat found none), ``reliable (m,)`` and ``reason (m,)`` (``""`` where reliable,
    else ``silence`` / ``unvoiced`` / ``wide bandwidth``), the ``ceiling_hz`` used."""

    times: Float[np.ndarray, " m"]
    frequency: Float[np.ndarray, "m 3"]
    bandwidth: Float[np.ndarray, "m 3"]
    reliable: Bool[np.ndarray, " m"]
    reason: Shaped[np.ndarray, " m"]
    ceiling_hz: float

    @property
    def share_reliable(self) -> float:
        """The share of frames measured reliably (0 for no frames)."""
        return float(np.mean(self.reliable)) if len(self.times) else 0.0


def _to_pitch(sound: parselmouth.Sound) -> parselmouth.Pitch:
    """Praat's ``To Pitch`` (75-500 Hz) of a parselmouth Sound: the one pitch analysis."""
    return sound.to_pitch(pitch_floor=PITCH_FLOOR_HZ, pitch_ceiling=PITCH_CEILING_HZ)


def voice_pitch(samples: Float[np.ndarray, " n"], rate_hz: float) -> parselmouth.Pitch | None:
    """Praat's pitch track of the sound (``To Pitch``, 75-500 Hz), the one analysis both
    :func:`median_f0` (the voice's F0, which can choose the speaker's norms and with them
    the formant ceiling) and :func:`measure_formants` (voicing) read: a caller that needs
    both computes it once and passes it on (``pitch=``). None for no sound, a non-positive
    rate, a non-finite sample or a sound too short for the pitch window."""
    import parselmouth

    samples = np.asarray(samples, dtype=np.float64).reshape(-1)
    if samples.size == 0 or not rate_hz > 0 or not np.all(np.isfinite(samples)):
        return None
    try:
        return _to_pitch(parselmouth.Sound(samples, sampling_frequency=float(rate_hz)))
    except parselmouth.PraatError:  # shorter than Praat's pitch window: nothing voiced
        return None


def measure_formants(
    samples: Float[np.ndarray, " n"], rate_hz: float, times: Float[np.ndarray, " m"], *,
    ceiling_hz: float = CEILING_HZ["male"], max_bandwidth_hz: float = MAX_BANDWIDTH_HZ,
    silence_db: float = SILENCE_DB, pitch: parselmouth.Pitch | None = None,
) -> FormantTrack:
    """Praat's Burg formants F1-F3 of ``samples`` at ``times`` (s), reliability marked
    (module docstring). ``pitch``: :func:`voice_pitch` of these same samples where the
    caller has it already (Praat's pitch tracker is not run again); None: run here.
    ``ValueError`` for an empty sound or a non-positive rate."""
    import parselmouth

    samples = np.asarray(samples, dtype=np.float64).reshape(-1)
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    if samples.size == 0 or not rate_hz > 0:
        raise ValueError(f"measure_formants: {samples.size} samples at {rate_hz} Hz")
    sound = parselmouth.Sound(samples, sampling_frequency=float(rate_hz))
    formant = sound.to_formant_burg(time_step=0.005, max_number_of_formants=N_FORMANTS_BURG,
                                    maximum_formant=float(ceiling_hz), window_length=WINDOW_S)
    pitch = _to_pitch(sound) if pitch is None else pitch
    intensity = sound.to_intensity(minimum_pitch=PITCH_FLOOR_HZ)
    freq = np.array([[formant.get_value_at_time(k, t) for k in (1, 2, 3)] for t in times]).reshape(-1, 3)
    bw = np.array([[formant.get_bandwidth_at_time(k, t) for k in (1, 2, 3)] for t in times]).reshape(-1, 3)
    f0 = np.array([pitch.get_value_at_time(t) for t in times])
    level = np.array([intensity.get_value(t) for t in times], dtype=np.float64)
    loudest = np.nanmax(intensity.values) if intensity.values.size else np.nan
    reason = np.full(times.shape, "", dtype=object)
    wide = ~np.all(np.isfinite(freq) & np.isfinite(bw) & (bw <= max_bandwidth_hz), axis=1)
    reason[wide] = "wide bandwidth"
    reason[~np.isfinite(f0)] = "unvoiced"
    reason[~(level >= loudest - silence_db)] = "silence"
    reason = reason.astype(str)
    return FormantTrack(times, freq, bw, reason == "", reason, float(ceiling_hz))


def measure_wav(path: str | os.PathLike, times: Float[np.ndarray, " m"], **options) -> FormantTrack:
    """:func:`measure_formants` of the ``.wav`` at ``path``."""
    from .sound import Sound

    samples, rate = Sound.from_file(path).samples()
    return measure_formants(samples, rate, times, **options)


def median_f0(samples: Float[np.ndarray, " n"], rate_hz: float) -> float | None:
    """The median F0 (Hz) of the sound's voiced frames (Praat's ``To Pitch``, 75-500 Hz);
    None for no sound, a non-positive rate, a sound too short for the pitch window or no
    voiced frame (never NaN). :func:`pitch_median_f0` where the pitch is at hand."""
    return pitch_median_f0(voice_pitch(samples, rate_hz))


def pitch_median_f0(pitch: parselmouth.Pitch | None) -> float | None:
    """The median F0 (Hz) of a :func:`voice_pitch` track's voiced frames; None without a
    track or a voiced frame (never NaN)."""
    if pitch is None:
        return None
    voiced = pitch.selected_array["frequency"]
    voiced = voiced[voiced > 0]
    return float(np.median(voiced)) if voiced.size else None


def voice_speaker(f0_hz: float | None) -> str | None:
    """``"female"`` for a median F0 at or above :data:`F0_BOUNDARY_HZ`, ``"male"`` below
    it, None without one (module docstring)."""
    if f0_hz is None or not np.isfinite(f0_hz):
        return None
    return "female" if f0_hz >= F0_BOUNDARY_HZ else "male"
