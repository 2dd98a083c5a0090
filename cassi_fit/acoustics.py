"""The vocal tract heard: the model's formants of every frame against the recording's.

:func:`recording_acoustics` takes a recording's run (``pipeline.run_recording``), makes the
area function of every animated frame (:mod:`cassi_fit.area_function`), its formants
through the lossy tube (:mod:`cassi_fit.tube`) and measures the sound's formants at the
same times (:mod:`cassi_fit.formant_track`). Frames are *scored* where the label is a
vowel (:func:`is_vowel`), the measurement is reliable and the model found F1-F3; the share
of the vowels' frames scored is reported beside every figure (``share_scored``).
:meth:`Acoustics.frame_rows` and :meth:`Acoustics.segment_rows` are the per-frame and
per-vowel-segment tables (``cassi acoustics --csv``), :func:`plot_acoustics` the figure of
the model's formant tracks over the spectrogram (``--plot``).

**The speaker's norms** (:func:`speaker_norms`, the one place they are chosen for
``cassi acoustics``, ``cassi calibrate --acoustic`` and the tract view): ``male`` (the
default: the adult male norms the toolkit has always used), ``female``, or ``auto``, heard
in the recording's own voice (the median F0 of its voiced frames against
``formant_track.F0_BOUNDARY_HZ``). They set the larynx's drop below the hyoid of the tract
the sensors drive (``area_function.LARYNX_DROP_MM``), Praat's formant ceiling
(``formant_track.CEILING_HZ``, unless a ceiling is given) and the acoustic calibration's
prior centre. The female norms are not the default: on the one female voice measured (EMU
mo1) they made the model's formants worse overall (``docs/ACOUSTICS.md``).
:meth:`SpeakerNorms.line` says which norms, and with the default ones whether the voice's
F0 suggests the female norms. ``auto`` without a sound or a voiced frame: the male norms.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Bool, Float

from . import area_function as af
from . import tube
from .formant_track import (
    CEILING_HZ,
    F0_BOUNDARY_HZ,
    FormantTrack,
    measure_formants,
    pitch_median_f0,
    voice_pitch,
    voice_speaker,
)
from .tables import blank_if_nan

if TYPE_CHECKING:
    import parselmouth

    from .labels import Labels
    from .pipeline import RecordingRun

#: Vowel labels matched whole (SAMPA with its length marks removed, ARPAbet in lower case
#: without stress digits, TIMIT's and Buckeye's extra vowels, the Edinburgh MRPA and
#: Unisyn/Combilex sets of MOCHA-TIMIT's and mngu0's labels, plain letters): a label whose
#: stress digits and ``:`` length marks removed is here is a vowel (:func:`is_vowel`).
VOWELS = frozenset(
    "a e i o u y @ 6 E I O U Y V Q A { } 2 9 3 & aI aU OY eI oU @U OI ai au oi ei ou "
    "aa ae ah ao aw ax ay eh er ey ih iy ow oy uh uw "
    # TIMIT: ix, ux, axr, ax-h; Buckeye's nasalised vowels
    "ix ux axr ax-h aan aen ahn aon awn ayn ehn eyn ihn iyn own oyn uhn uwn "
    # MRPA (MOCHA-TIMIT; Festival's British English) and Unisyn (mngu0): long vowels
    # doubled, centring diphthongs with @, r-coloured schwas
    "ii uu oo @@ i@ e@ u@ @@r @r".split())

#: The IPA chart's vowel letters and the rhotic schwas (Montreal Forced Aligner's
#: ``english_mfa``/``german_mfa``, hand transcriptions): see :func:`is_vowel`.
IPA_VOWEL_LETTERS = frozenset(
    "i y ɨ ʉ ɯ u ɪ ʏ ʊ e ø ɘ ɵ ɤ o ə ɛ œ ɜ ɞ ʌ ɔ æ ɐ a ɶ ɑ ɒ ɚ ɝ".split())
_OFFGLIDES = frozenset("jw")  # MFA's diphthongs: aj aw ej ow ɔj = a vowel letter + j or w


def _ipa_letters(core: str) -> str:
    """``core`` decomposed (NFD) without its combining marks (nasalisation, ◌̯, syllabic
    ◌̩, tie bars, ...), modifier letters (ː ˑ ˈ ˌ ʰ ʲ ...) and modifier symbols (˞)."""
    import unicodedata  # here, not at the top: this block is the vowels' alone

    return "".join(c for c in unicodedata.normalize("NFD", core)
                   if not unicodedata.category(c).startswith("M")
                   and unicodedata.category(c) not in ("Lm", "Sk"))


def is_vowel(label: str) -> bool:
    """True for a vowel label, in any of these phone sets:

    * SAMPA (case kept; ``a: 2 9 3 6 @ { } & Q V`` are vowels), the lower-case ARPAbet
      and the MRPA/Unisyn vowels (``ii uu oo @@ i@ e@ u@``: MOCHA-TIMIT, mngu0) of
      :data:`VOWELS`, matched whole once ``:`` length marks and trailing stress digits
      (``0 1 2``) are removed; upper-case ARPAbet is matched in lower case
      (``AA1``, ``IY0``, ``ER``). TIMIT's ``ix ux axr ax-h`` and Buckeye's nasalised
      vowels (``aan``, ``iyn``, ...) are vowels. ``er`` is a vowel, ``r`` is not. The
      syllabic consonants ``el em en eng`` are **not** vowels: their formants are a
      consonant's, not a vowel's, so they are not scored. The stress digit is kept where
      it is the whole label: SAMPA's ``2`` (and ``2:``) is a vowel.
    * IPA: after removing combining diacritics (nasalisation, non-syllabic ◌̯,
      centralisation, syllabicity, ...; by Unicode category), modifier letters (length
      ``ː ˑ``, stress ``ˈ ˌ``, aspiration, ...) and modifier symbols (rhoticity ``˞``), a
      label of one or two of :data:`IPA_VOWEL_LETTERS` (a monophthong, or a diphthong such
      as ``aɪ``, ``aɪ̯`` or ``a͡ɪ``) or one vowel letter followed by ``j`` or ``w`` (MFA's
      ``aj aw ej ow ɔj``). A lone ``j`` or ``w`` and syllabic consonants (``n̩``, ``l̩``)
      are not vowels.

    Ambiguous labels keep their SAMPA reading: ``y``/``Y`` (TIMIT's and CMU's glide /j/)
    are vowels, as they have always been here. Silence and noise labels (``sil sp spn``,
    ``<p:>``, ``#``, empty) are not vowels."""
    core = label.strip().replace(":", "")
    core = core.rstrip("012") or core
    if not core:
        return False
    if core in VOWELS or core.lower() in VOWELS:
        return True
    letters = _ipa_letters(core)
    if letters in VOWELS:  # SAMPA with an X-SAMPA diacritic, e.g. r-coloured "@`"
        return True
    if 1 <= len(letters) <= 2 and all(c in IPA_VOWEL_LETTERS for c in letters):
        return True
    return (len(letters) == 2 and letters[0] in IPA_VOWEL_LETTERS
            and letters[1] in _OFFGLIDES)


def unscored_line(labels: Labels | None) -> str | None:
    """One line saying why no frame of a recording can be scored, for a researcher whose
    labels the toolkit does not take for vowels: no labels at all, or no vowel
    (:func:`is_vowel`) among those of the tier used; None when some label is a vowel."""
    if labels is None or not len(labels):
        return ("no labels (X.lab or X.TextGrid beside the file, or a tier inside it): nothing "
                "is scored; --csv gives every frame's model and measured formants")
    if any(is_vowel(s) for s in labels.labels):
        return None
    names = sorted(set(labels.labels))
    shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
    return (f"no vowel among the {len(labels)} labels of the tier {labels.tier!r} ({shown}): "
            "nothing is scored (vowels are read in SAMPA, ARPAbet, TIMIT or IPA; --tier "
            "chooses another tier)")


#: ``speaker=`` of :func:`speaker_norms` (``cassi acoustics --speaker``; None, the male
#: norms, the default)
SPEAKERS = ("male", "female", "auto")


@dataclass(frozen=True)
class SpeakerNorms:
    """The adult norms a recording is heard with: ``speaker`` (``male`` or ``female``),
    ``source`` (how: ``default`` for the male norms asked for or by default, ``given`` for
    the female norms asked for, ``voice`` heard in the sound by ``auto``, or, ``auto``
    falling back to the male norms, ``no sound`` / ``no voiced frame``) and the voice's
    median ``f0_hz`` (None where there is no voiced sound or it was not measured)."""

    speaker: str
    source: str
    f0_hz: float | None

    @property
    def larynx_drop_mm(self) -> float:
        return af.LARYNX_DROP_MM[self.speaker]

    @property
    def ceiling_hz(self) -> float:
        return CEILING_HZ[self.speaker]

    @property
    def why(self) -> str:
        """How the norms were chosen, in words."""
        return {"default": "the default",
                "given": "as asked",
                "voice": f"a {self.speaker} voice, median F0 {self.f0_hz or 0:.0f} Hz",
                "no sound": "no sound to hear the voice by",
                "no voiced frame": "no voiced frame in the sound"}[self.source]

    @property
    def voice_suggests_female(self) -> bool:
        """The default male norms, and a voice whose median F0 is at or above
        :data:`~cassi_fit.formant_track.F0_BOUNDARY_HZ` (an adult female's, typically)."""
        return self.source == "default" and voice_speaker(self.f0_hz) == "female"

    def line(self, *, ceiling_hz: float | None = None, larynx: str | None = None) -> str:
        """One line: the norms used (what ``cassi acoustics`` prints), with the default
        norms and a voice above the F0 boundary a hint to ``--speaker female`` (or ``auto``);
        ``ceiling_hz`` and ``larynx`` (in words) where a given ceiling or a fitted tract
        took the norms' place."""
        larynx = larynx or f"larynx {self.larynx_drop_mm:.0f} mm below the hyoid"
        ceiling = (f"formant ceiling {self.ceiling_hz:.0f} Hz" if ceiling_hz is None
                   else f"formant ceiling {ceiling_hz:.0f} Hz as given")
        asked = ", as asked" if self.source == "given" else ""
        said = f"speaker: adult {self.speaker} norms{asked} ({larynx}, {ceiling})"
        if self.voice_suggests_female:
            return (f"{said}; the voice's median F0 is {self.f0_hz:.0f} Hz, above "
                    f"{F0_BOUNDARY_HZ:.0f} Hz: --speaker female (or auto) for the adult "
                    "female norms")
        if self.source == "voice":
            side = "at or above" if self.speaker == "female" else "below"
            return (f"{said}, from the voice: median F0 {self.f0_hz:.0f} Hz, {side} "
                    f"{F0_BOUNDARY_HZ:.0f} Hz")
        if self.source in ("default", "given"):
            return said
        return f"{said}: {self.why}"


def speaker_norms(speaker: str | None = None, samples: Float[np.ndarray, " n"] | None = None,
                  rate_hz: float | None = None, *,
                  pitch: parselmouth.Pitch | None = None) -> SpeakerNorms:
    """The :class:`SpeakerNorms` for ``speaker`` (:data:`SPEAKERS`; module docstring):
    None: the male norms by default; ``male`` or ``female`` as given (asked for, so the
    line gives no hint); ``auto`` from the voice of ``samples`` at ``rate_hz`` (the male
    norms without one). The voice's median F0 is measured whenever
    there is a sound (for the line's hint), from ``pitch``
    (``formant_track.voice_pitch(samples, rate_hz)``, where the caller has it for the
    formants' voicing too) or, None, by Praat's pitch tracker here. ``ValueError`` for
    another ``speaker``."""
    if speaker is not None and speaker not in SPEAKERS:
        raise ValueError(f"speaker {speaker!r}: one of {', '.join(SPEAKERS)}")
    sound = samples is not None and rate_hz is not None and np.size(samples) > 0
    if sound and pitch is None:
        pitch = voice_pitch(samples, rate_hz)
    f0 = pitch_median_f0(pitch) if sound else None
    if speaker is None:
        return SpeakerNorms("male", "default", f0)
    if speaker != "auto":
        return SpeakerNorms(speaker, "given", f0)
    heard = voice_speaker(f0)
    if heard is None:
        return SpeakerNorms("male", "no voiced frame" if sound else "no sound", None)
    return SpeakerNorms(heard, "voice", f0)


def model_formants(geometry: af.TractGeometry, vertices: Float[jax.Array, "m V 3"],
                   tract: af.TractParams, scale: float, chunk: int = 256):
    """``(frequency (m, 4), bandwidth (m, 4), areas (m, n), lengths (m, n))`` of every
    frame, in chunks of ``chunk`` frames (one compilation per chunk size, shared by every
    subject of the model's topology)."""
    from .acoustic_fit import _tract_areas

    out = []
    m = vertices.shape[0]
    for start in range(0, m, chunk):
        v = vertices[start:start + chunk]
        n = v.shape[0]
        if n < chunk and m > chunk:  # pad the last chunk: no second compilation
            v = jnp.concatenate([v, jnp.broadcast_to(v[-1:], (chunk - n,) + v.shape[1:])])
        a, ln = _tract_areas(geometry, v, tract, jnp.asarray(scale, v.dtype))
        f = tube.formants_batch(a, ln)
        out.append([np.asarray(x)[:n] for x in (f.frequency, f.bandwidth, a, ln)])
    return tuple(np.concatenate(parts) for parts in zip(*out, strict=True))


@dataclass(frozen=True, eq=False)
class Acoustics:
    """One recording's model and measured formants at the animation's frame ``times``:
    ``model`` and ``model_bandwidth`` ``(m, 4)`` Hz, ``measured`` the
    :class:`FormantTrack`, ``labels (m,)``, ``areas`` and ``lengths`` ``(m, n)`` mm^2, mm;
    ``scored (m,)``; ``tract`` the :class:`~cassi_fit.area_function.TractParams` used; the
    subject's ``geometry``, the frames' ``vertices`` and ``scale`` (for a calibration);
    ``norms`` the :class:`SpeakerNorms` it was heard with (and their F0)."""

    times: Float[np.ndarray, " m"]
    model: Float[np.ndarray, "m 4"]
    model_bandwidth: Float[np.ndarray, "m 4"]
    measured: FormantTrack
    labels: np.ndarray
    areas: Float[np.ndarray, "m n"]
    lengths: Float[np.ndarray, "m n"]
    tract: af.TractParams
    geometry: af.TractGeometry
    vertices: jax.Array
    scale: float
    norms: SpeakerNorms

    @property
    def vowel(self) -> Bool[np.ndarray, " m"]:
        return np.array([is_vowel(s) for s in self.labels], bool)

    @property
    def scored(self) -> Bool[np.ndarray, " m"]:
        return self.vowel & self.measured.reliable & np.all(np.isfinite(self.model[:, :3]), 1)

    @property
    def share_scored(self) -> float:
        """The share of the vowels' frames that are scored (0 without vowels)."""
        v = self.vowel
        return float(self.scored[v].mean()) if v.any() else 0.0

    @property
    def lips_in_closures(self) -> tuple[int, float] | None:
        """``(frames, median mm)``: the frames labelled as a bilabial and the model's lip
        opening there (``lips.apart_in_closures``), None without such a frame: where the
        speaker's lips touch, the model's lips should too."""
        from .lips import apart_in_closures

        return apart_in_closures(self.labels, af.lip_opening(self.geometry, self.vertices))

    def scored_line(self) -> str:
        """The share of the vowels' frames scored, and why the others are not (the
        measurement's reason: silence, unvoiced, wide bandwidth; or no model formant),
        in one line."""
        vowel = self.vowel
        line = f"{100 * self.share_scored:.0f} % of the vowels' frames scored"
        left = vowel & ~self.scored
        if not left.any():
            return line
        why = np.where(self.measured.reliable, "no model formant",
                       np.asarray(self.measured.reason, dtype=object))[left]
        names, counts = np.unique(why.astype(str), return_counts=True)
        order = np.argsort(-counts, kind="stable")
        parts = ", ".join(f"{counts[k]} {names[k]}" for k in order)
        return f"{line} ({int(vowel.sum())} vowel frames; not scored: {parts})"

    @property
    def relative_error(self) -> Float[np.ndarray, "m 3"]:
        """``model / measured - 1`` for F1-F3 (NaN where not scored)."""
        err = self.model[:, :3] / self.measured.frequency - 1.0
        return np.where(self.scored[:, None], err, np.nan)

    def frame_rows(self) -> list[dict]:
        rows = []
        for k, t in enumerate(self.times):
            row = {"time_s": float(t), "label": str(self.labels[k]), "scored": bool(self.scored[k]),
                   "reason": str(self.measured.reason[k]),
                   "vocal_tract_mm": float(self.lengths[k].sum())}
            for j in range(3):
                row[f"F{j + 1}_model_hz"] = _cell(self.model[k, j])
                row[f"F{j + 1}_measured_hz"] = _cell(self.measured.frequency[k, j])
            rows.append(row)
        return rows

    def segment_rows(self) -> list[dict]:
        """One row per vowel segment (a run of frames with one vowel label): its frames,
        the frames scored, the median model and measured F1-F3 and the median relative
        errors over the scored frames."""
        rows, k, m = [], 0, len(self.times)
        while k < m:
            j = k
            while j < m and self.labels[j] == self.labels[k]:
                j += 1
            if is_vowel(str(self.labels[k])):
                s = np.arange(k, j)[self.scored[k:j]]
                row = {"start_s": float(self.times[k]), "end_s": float(self.times[j - 1]),
                       "vowel": str(self.labels[k]), "frames": j - k, "scored": len(s)}
                for q in range(3):  # blank where no frame of the segment is scored
                    row[f"F{q + 1}_model_hz"] = _median(self.model[s, q])
                    row[f"F{q + 1}_measured_hz"] = _median(self.measured.frequency[s, q])
                    row[f"F{q + 1}_error"] = _median(self.relative_error[s, q])
                rows.append(row)
            k = j
        return rows


def _cell(value) -> float | None:
    """A table's cell: None (blank) for NaN (a frame the sound gives no formant for)."""
    return blank_if_nan(float(value))


def _median(values) -> float | None:
    return _cell(np.median(values)) if len(values) else None


def recording_sound(recording, *, accept_mismatch: bool = False
                    ) -> tuple[Float[np.ndarray, " n"], float]:
    """``(samples, rate_hz)`` of the recording's sound (a ``.wav`` beside the file or the
    sound inside it), checked against the recording's length as every output checks it
    (``sound.check_sound``: a cut file, a wrong rate or under half the recording is one
    error naming the file unless ``accept_mismatch``; a lesser mismatch warns: frames the
    sound does not cover are never scored); ``MissingDataError`` naming the recording if
    it has none."""
    from .errors import MissingDataError

    sound = recording.sound
    if sound is None:
        raise MissingDataError(f"{recording.subject}/{recording.task}: no sound (a .wav "
                               "beside the file or inside it): the formants cannot be measured")
    sound.check(recording.track.length_s, accept_mismatch=accept_mismatch)
    return sound.samples()


def recording_acoustics(
    run: RecordingRun, *, samples: Float[np.ndarray, " n"] | None = None,
    rate_hz: float | None = None, labels: Labels | None = None, ceiling_hz: float | None = None,
    tract: af.TractParams | None = None, speaker: str | None = None,
) -> Acoustics:
    """The :class:`Acoustics` of a :class:`~cassi_fit.pipeline.RecordingRun`. The sound is
    the recording's ``.wav`` unless ``samples`` and ``rate_hz`` are given; the labels are
    those beside the pellet file unless ``labels`` (a :class:`~cassi_fit.labels.Labels`) is
    given. ``speaker`` (:func:`speaker_norms`: None, the male norms by
    default, ``male`` or ``female`` as asked, or ``auto`` from the voice) sets the norms: the tract's larynx unless ``tract`` is given, Praat's
    ceiling unless ``ceiling_hz`` is. ``MissingDataError`` if there is no sound."""
    from .labels import recording_labels

    rec, anim = run.recording, run.animation
    if samples is None:
        samples, rate_hz = recording_sound(rec)
    if labels is None:  # beside the file or inside it (mview, EMU levels)
        labels = recording_labels(rec)
    times = np.asarray(anim.times, np.float64)
    names = labels.at(times) if labels is not None else np.full(times.shape, "")
    # Praat's pitch tracker once: the voice's F0 (the norms, chosen before the formants:
    # they can set the ceiling) and the formants' voicing read the same track
    pitch = voice_pitch(samples, rate_hz)
    norms = speaker_norms(speaker, samples, rate_hz, pitch=pitch)
    dtype = jnp.asarray(anim.vertices).dtype
    tract = af.default_tract(dtype, norms.speaker) if tract is None else tract
    geometry = af.tract_geometry(run.state.model)
    freq, bw, areas, lengths = model_formants(geometry, anim.vertices, tract, run.state.scale)
    ceiling_hz = norms.ceiling_hz if ceiling_hz is None else ceiling_hz
    measured = measure_formants(samples, rate_hz, times, ceiling_hz=ceiling_hz, pitch=pitch)
    return Acoustics(times, freq, bw, measured, names, areas, lengths, tract, geometry,
                     anim.vertices, float(run.state.scale), norms)


#: ``tube.spectrum`` of many tracts at the same frequencies (compiled once per shape).
_batched_spectrum = jax.jit(jax.vmap(tube.spectrum, in_axes=(None, 0, 0)))

#: The frequencies of the tract view's spectrum (Hz): 0-5 kHz, F1-F4's range.
PANEL_HZ = np.arange(25.0, 5000.0 + 1.0, 25.0)


def _spectra(areas, lengths, frequency_hz, chunk: int = 256) -> np.ndarray:
    """``(m, k)`` dB of the lossy tube of every frame at ``frequency_hz``, in chunks of
    ``chunk`` frames (one compilation per chunk size)."""
    run = _batched_spectrum
    f = jnp.asarray(frequency_hz)
    out, m = [], len(areas)
    for start in range(0, m, chunk):
        a, ln = areas[start:start + chunk], lengths[start:start + chunk]
        n = len(a)
        if n < chunk and m > chunk:  # the last chunk padded: no second compilation
            a = np.concatenate([a, np.repeat(a[-1:], chunk - n, axis=0)])
            ln = np.concatenate([ln, np.repeat(ln[-1:], chunk - n, axis=0)])
        out.append(np.asarray(run(f, jnp.asarray(a), jnp.asarray(ln)))[:n])
    return np.concatenate(out) if out else np.zeros((0, len(frequency_hz)))


def tract_panels(run: RecordingRun, *, tract: af.TractParams | None = None,
                 calibration: str | os.PathLike | None = None,
                 ceiling_hz: float | None = None, speaker: str | None = None) -> list[dict]:
    """What ``cassi animate --views ...,tract`` draws beside the face, per animation frame
    of ``run``: ``lengths_mm``, ``areas_mm2`` (the area function, glottis first, as
    :func:`recording_acoustics` makes it), ``frequency_hz`` (:data:`PANEL_HZ`) and
    ``gain_db`` (the lossy tube's transfer function), ``model_hz`` (F1-F3) and
    ``measured_hz`` (the sound's F1-F3 where the recording has a sound and the
    measurement is reliable at that frame, else NaN), ``tract`` (which vocal tract, the
    line ``cassi animate`` prints) and ``tract_label`` (the same, short: what the view
    draws). ``tract``: default the subject's acoustic calibration when ``calibration``
    (what ``--calibration`` names) holds one (``acoustic_fit.calibrated_tract``), else the
    adult norms of ``speaker`` (:func:`speaker_norms`, as :func:`recording_acoustics`;
    ``tract`` names them where they are not the default male norms)."""
    from .acoustic_fit import calibrated_tract

    anim = run.animation
    samples, rate_hz = None, None
    sound = getattr(run.recording, "sound", None)
    if sound is not None:
        samples, rate_hz = sound.samples()
    # Praat's pitch tracker once: the voice's F0 (read only where it chooses the norms,
    # auto) and the measured formants' voicing
    pitch = None if samples is None else voice_pitch(samples, rate_hz)
    norms = speaker_norms(speaker, samples if speaker == "auto" else None, rate_hz, pitch=pitch)
    if tract is None:
        found = calibrated_tract(calibration, run.recording.subject)
        tract, label = found.tract, found.label()
        words = found.missing(run.recording.subject) or f"vocal tract: {label}"
    else:
        label = "as given"
        words = f"vocal tract: {label}"
    if tract is None:
        tract = af.default_tract(jnp.asarray(anim.vertices).dtype, norms.speaker)
        if norms.source != "default":  # the default male norms keep the words they always had
            label = f"{label}, {norms.speaker} ({norms.why})"
            words = f"{words}, {norms.speaker} ({norms.why})"
    geometry = af.tract_geometry(run.state.model)
    freq, _, areas, lengths = model_formants(geometry, anim.vertices, tract, run.state.scale)
    gain = _spectra(areas, lengths, PANEL_HZ)
    measured = np.full((len(freq), 3), np.nan)
    if samples is not None:
        track = measure_formants(samples, rate_hz, np.asarray(anim.times, np.float64),
                                 ceiling_hz=norms.ceiling_hz if ceiling_hz is None else ceiling_hz,
                                 pitch=pitch)
        measured = np.where(track.reliable[:, None], track.frequency[:, :3], np.nan)
    return [{"lengths_mm": lengths[k], "areas_mm2": areas[k], "frequency_hz": PANEL_HZ,
             "gain_db": gain[k], "model_hz": freq[k, :3], "measured_hz": measured[k],
             "tract": words, "tract_label": label}
            for k in range(len(freq))]


def plot_acoustics(result: Acoustics, samples: Float[np.ndarray, " n"], rate_hz: float,
                   path: str | os.PathLike, *, title: str = "") -> Path:
    """The spectrogram with the measured (dots) and model (lines) F1-F3 and the vowel
    labels, written to ``path`` (PNG); returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 4.5))
    # a broadband spectrogram as a phonetician reads one: pre-emphasised (a first difference,
    # +6 dB/octave, so that F2-F3 show beside F1) and 50 dB of dynamic range below the
    # loudest cell (Praat's default), silence white
    x = np.asarray(samples, np.float64)
    x = np.concatenate([x[:1], x[1:] - 0.97 * x[:-1]])
    spec, _, _, image = ax.specgram(x, NFFT=int(0.008 * rate_hz), Fs=rate_hz,
                                    noverlap=int(0.006 * rate_hz), cmap="Greys", scale="dB")
    top = 10.0 * np.log10(max(float(np.max(spec)), 1e-30))
    image.set_clim(top - 50.0, top)
    colours = ("tab:red", "tab:green", "tab:blue")
    for q in range(3):
        meas = np.where(result.measured.reliable, result.measured.frequency[:, q], np.nan)
        ax.plot(result.times, meas, ".", ms=2.5, color=colours[q], alpha=0.6)
        ax.plot(result.times, result.model[:, q], "-", lw=1.2, color=colours[q],
                label=f"F{q + 1} model (line), measured (dots)")
    for row in result.segment_rows():
        ax.axvspan(row["start_s"], row["end_s"], color="gold", alpha=0.15)
        ax.text(0.5 * (row["start_s"] + row["end_s"]), 4700, row["vowel"], ha="center", fontsize=9)
    ax.set_ylim(0, 5000)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(title or f"model vs measured formants; {100 * result.share_scored:.0f} % of "
                          "the vowels' frames scored")
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
