"""The task library of the synthetic corpus: what each task asks the articulators to do.

A task turns into *control trajectories* on the frame grid: one smooth curve per control
(jaw angle, lip closure, tongue gestures, voicing ...). :mod:`cassi_fit.synth` maps the
controls to pellet positions through a subject's anatomy; this module knows nothing about
anatomy. Speech tasks are phone strings: each phone sets targets for some controls (the
others carry over from the previous phone, a crude coarticulation); the piecewise constant
targets are smoothed by a Gaussian (tens of ms), which bounds the speeds.

Controls and units (``CONTROLS``):
    jaw_deg        jaw opening, degrees (>= 0; rest = closed = 0)
    lip_close      0..1, bilabial closure (lower lip up, upper lip down)
    lip_round      0..1, both lips forward
    labiodental    0..1, lower lip back and up under the upper incisors
    tip_up         0..1, tongue tip raised toward the alveolar ridge (1 reaches it)
    tip_fwd        mm, tongue tip forward of its rest
    body_up        mm, tongue dorsum raised
    body_fwd       mm, tongue body forward (negative = back)
    voicing        0..1, vocal folds vibrating (for the synthetic audio)
    frication      0..1, turbulence noise (for the synthetic audio)

Task names follow the XRMB database's numbering (``tp001`` .. ``tp118``; a repeated trial
is ``tp020_2``). The numbers chosen here are this toolkit's own, except that jaw wagging
is task 106 as in the paper.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import CassiError

CONTROLS = (
    "jaw_deg",
    "lip_close",
    "lip_round",
    "labiodental",
    "tip_up",
    "tip_fwd",
    "body_up",
    "body_fwd",
    "voicing",
    "frication",
)
_C = {name: i for i, name in enumerate(CONTROLS)}

# Gaussian smoothing of the targets, seconds, per control (jaw slower than lips and tip).
_SMOOTHING_S = {
    "jaw_deg": 0.045,
    "lip_close": 0.030,
    "lip_round": 0.040,
    "labiodental": 0.025,
    "tip_up": 0.042,
    "tip_fwd": 0.040,
    "body_up": 0.035,
    "body_fwd": 0.045,
    "voicing": 0.010,
    "frication": 0.010,
}

# Vowels set every articulatory control (what a vowel does not use returns to neutral).
_VOWEL = dict(lip_close=0.0, labiodental=0.0, tip_fwd=0.0, voicing=1.0, frication=0.0)
_V = {  # jaw_deg, body_up, body_fwd, lip_round, tip_up
    "a": (7.5, -5.0, -7.0, 0.0, 0.0),
    "A": (7.0, -2.0, 2.0, 0.0, 0.0),  # the vowel of "bad"
    "e": (5.0, 3.0, 4.0, 0.0, 0.1),
    "i": (2.5, 7.0, 6.5, 0.0, 0.2),
    "o": (6.0, 0.0, -6.0, 0.6, 0.0),
    "u": (3.0, 6.0, -8.0, 1.0, 0.0),
    "@": (4.0, 0.0, 0.0, 0.1, 0.0),  # schwa
}
# Consonants set only what they use; lip closure, labiodental and tip raising are released
# unless set. voicing / frication always set.
_K = {
    "p": dict(lip_close=1.0, jaw_deg=2.5, voicing=0.0),
    "b": dict(lip_close=1.0, jaw_deg=2.5, voicing=1.0),
    "m": dict(lip_close=1.0, jaw_deg=2.5, voicing=1.0),
    "f": dict(labiodental=1.0, jaw_deg=2.0, voicing=0.0, frication=1.0),
    "v": dict(labiodental=1.0, jaw_deg=2.0, voicing=1.0, frication=0.6),
    "t": dict(tip_up=1.0, tip_fwd=3.0, jaw_deg=2.5, voicing=0.0),
    "d": dict(tip_up=1.0, tip_fwd=3.0, jaw_deg=2.5, voicing=1.0),
    "n": dict(tip_up=1.0, tip_fwd=3.0, jaw_deg=2.5, voicing=1.0),
    "s": dict(tip_up=0.9, tip_fwd=4.0, jaw_deg=1.5, voicing=0.0, frication=1.0),
    "z": dict(tip_up=0.9, tip_fwd=4.0, jaw_deg=1.5, voicing=1.0, frication=0.6),
    "S": dict(tip_up=0.85, lip_round=0.5, jaw_deg=2.0, voicing=0.0, frication=1.0),
    "l": dict(tip_up=1.0, jaw_deg=4.0, voicing=1.0),
    "r": dict(tip_up=0.5, tip_fwd=-6.0, lip_round=0.4, jaw_deg=3.0, voicing=1.0),
    "k": dict(body_up=11.0, body_fwd=-1.0, jaw_deg=3.0, voicing=0.0),
    "g": dict(body_up=11.0, body_fwd=-1.0, jaw_deg=3.0, voicing=1.0),
    "w": dict(lip_round=1.0, body_up=5.0, body_fwd=-4.0, jaw_deg=2.0, voicing=1.0),
    "j": dict(body_up=8.0, body_fwd=5.0, jaw_deg=2.0, voicing=1.0),
    "h": dict(voicing=0.0, frication=0.3),
}
_PAUSE = dict(
    jaw_deg=1.0, lip_close=0.0, lip_round=0.0, labiodental=0.0, tip_up=0.0, tip_fwd=0.0,
    body_up=0.0, body_fwd=0.0, voicing=0.0, frication=0.0,
)  # fmt: skip
_DURATION_S = {"vowel": 0.14, "stop": 0.075, "fricative": 0.10, "sonorant": 0.07, "pause": 0.25}
_KIND = {**{c: "stop" for c in "pbtdkg"}, **{c: "fricative" for c in "fvszSh"}}


def _phone_targets(phone: str) -> tuple[dict, str]:
    """``(targets, duration kind)`` of one phone symbol ('|' is a pause)."""
    if phone == "|":
        return dict(_PAUSE), "pause"
    if phone in _V:
        jaw, up, fwd, rnd, tip = _V[phone]
        return dict(
            _VOWEL, jaw_deg=jaw, body_up=up, body_fwd=fwd, lip_round=rnd, tip_up=tip
        ), "vowel"
    if phone in _K:
        base = dict(lip_close=0.0, labiodental=0.0, tip_up=0.0, frication=0.0)
        return {**base, **_K[phone]}, _KIND.get(phone, "sonorant")
    raise ValueError(f"unknown phone {phone!r} in a task text")


@dataclass(frozen=True)
class TaskSpec:
    """One task of the library.

    ``kind`` is one of jaw_wagging, syllables, vcv, words, sentence, paragraph, swallow, protrusion.
    ``text`` is the phone string of speech tasks ('|' = pause, ' ' = word boundary),
    ``prompt`` what the subject reads, ``duration_s`` the nominal length (s) of tasks that
    are not phone strings, ``audio`` whether the corpus writes a synthetic ``.wav``,
    ``tempo`` how much longer than the default each phone lasts (slow syllable repetition).
    """

    name: str
    kind: str
    prompt: str
    text: str = ""
    duration_s: float = 4.0
    audio: bool = False
    tempo: float = 1.0


TASKS: dict[str, TaskSpec] = {
    t.name: t
    for t in (
        TaskSpec("tp005", "syllables", "sa sa sa sa sa sa sa sa sa sa (slow repetition)",
                 "| sa sa sa sa sa sa sa sa sa sa |", audio=True, tempo=2.0),
        TaskSpec("tp011", "vcv", "aba ada aga ibi idi igi ufu usu",
                 "| aba | ada | aga | ibi | idi | igi | ufu | usu |", audio=True),
        TaskSpec("tp020", "words", "bad, pit, cat, seed, food, goal, sun",
                 "| bAd | pit | kAt | sid | fud | gol | s@n |", audio=True),
        TaskSpec("tp020_2", "words", "bad, pit, cat, seed, food, goal, sun (second trial)",
                 "| bAd | pit | kAt | sid | fud | gol | s@n |", audio=True),
        TaskSpec("tp040", "sentence", "She had your dark suit in greasy wash water all year.",
                 "| Si hAd jor dark sut in grisi waS wat@r ol jir |", audio=True),
        TaskSpec("tp069", "paragraph",
                 "When the sunlight strikes raindrops in the air, they act as a prism and "
                 "form a rainbow. The rainbow is a division of white light into many "
                 "beautiful colours.",
                 "| wen d@ s@nlait straiks rendraps in di er | de Akt Az @ prizm And form @ "
                 "renbo | d@ renbo iz @ divizon @v wait lait intu meni bjutif@l k@l@rz |",
                 audio=True),
        TaskSpec("tp101", "swallow", "swallow (water)", duration_s=3.0),
        TaskSpec("tp104", "protrusion", "maximum tongue protrusion", duration_s=4.0),
        TaskSpec("tp106", "jaw_wagging", "jaw wagging", duration_s=4.0),
    )
}  # fmt: skip
JAW_WAGGING_TASK = "tp106"
SENTENCE_TASK = "tp040"
DEFAULT_TASKS = ("tp011", "tp020", "tp020_2", "tp040", "tp101", "tp104", "tp106")


def _speech_keyframes(text: str, rng: np.random.Generator) -> list[tuple[float, dict]]:
    """``[(duration s, targets)]`` for a phone string; tempo and durations jitter per trial."""
    tempo = rng.uniform(0.9, 1.12)
    frames = []
    for phone in text:
        if phone == " ":
            continue
        targets, kind = _phone_targets(phone)
        frames.append((_DURATION_S[kind] * tempo * rng.uniform(0.85, 1.15), targets))
    return frames


def _piecewise_targets(keyframes, n: int, dt: float) -> np.ndarray:
    """``(n, n_controls)`` step function: each keyframe's targets hold for its duration.

    Controls a keyframe does not set keep their previous value; before the first keyframe
    and after the last the pause (rest) targets hold.
    """
    out = np.empty((n, len(CONTROLS)))
    current = np.array([_PAUSE[c] for c in CONTROLS], dtype=float)
    start = 0.0
    out[:] = current
    for duration, targets in keyframes:
        for name, value in targets.items():
            current[_C[name]] = value
        i0, i1 = int(round(start / dt)), int(round((start + duration) / dt))
        out[i0:i1] = current
        start += duration
    i_end = min(int(round(start / dt)), n)
    out[i_end:] = np.array([_PAUSE[c] for c in CONTROLS])
    return out


def _smooth(controls: np.ndarray, dt: float, slowness: float = 1.0) -> np.ndarray:
    """Gaussian smoothing per control (edges held at their end values); ``slowness``
    multiplies the smoothing widths (non-speech gestures are slower)."""
    from scipy.ndimage import gaussian_filter1d

    out = np.empty_like(controls)
    for name, i in _C.items():
        out[:, i] = gaussian_filter1d(
            controls[:, i], slowness * _SMOOTHING_S[name] / dt, mode="nearest"
        )
    return out


def _jaw_wagging(n: int, dt: float, rng: np.random.Generator) -> np.ndarray:
    """Wide, repeated opening and closing: 19-25 degrees at 1.2-1.5 Hz, raised cosines."""
    t = np.arange(n) * dt
    amplitude = rng.uniform(19.0, 25.0)
    freq = rng.uniform(1.2, 1.5)
    t0 = rng.uniform(0.25, 0.4)
    cycles = max(1, int(np.floor((t[-1] - t0 - 0.2) * freq)))
    phase = 2 * np.pi * freq * (t - t0)
    active = (t >= t0) & (t <= t0 + cycles / freq)
    controls = np.tile([_PAUSE[c] for c in CONTROLS], (n, 1)).astype(float)
    controls[:, _C["jaw_deg"]] = np.where(active, amplitude * 0.5 * (1 - np.cos(phase)), 0.0)
    controls[:, _C["jaw_deg"]] += 0.5
    return controls


def _swallow_keyframes(rng: np.random.Generator) -> list[tuple[float, dict]]:
    """Lips close, tip to the ridge, a dorsum wave front to back pressing on the palate."""
    j = rng.uniform(0.85, 1.15)
    return [
        (0.35 * j, dict(_PAUSE)),
        (0.30 * j, dict(lip_close=1.0, jaw_deg=0.3)),
        (0.30 * j, dict(tip_up=1.3, tip_fwd=0.5, body_up=4.0)),
        (0.35 * j, dict(body_up=16.0, body_fwd=3.0)),
        (0.35 * j, dict(body_up=16.0, body_fwd=-4.0)),
        (0.30 * j, dict(tip_up=0.3, body_up=6.0, body_fwd=-2.0)),
        (0.30 * j, dict(lip_close=0.0, tip_up=0.0, body_up=0.0, body_fwd=0.0, jaw_deg=1.0)),
    ]


def _protrusion_keyframes(rng: np.random.Generator) -> list[tuple[float, dict]]:
    """Open, push the tongue as far forward as it goes, hold, retract (twice)."""
    reach = rng.uniform(20.0, 26.0)
    frames = [(0.3, dict(_PAUSE))]
    for _ in range(2):
        frames += [
            (0.25, dict(jaw_deg=9.0, body_fwd=4.0)),
            (0.7, dict(jaw_deg=10.0, tip_fwd=reach, body_fwd=9.0, body_up=-2.0)),
            (0.45, dict(jaw_deg=4.0, tip_fwd=0.0, body_fwd=0.0, body_up=0.0)),
        ]
    return frames


def _keyframes(spec: TaskSpec, rng) -> list[tuple[float, dict]] | None:
    if spec.text:
        return [(d * spec.tempo, t) for d, t in _speech_keyframes(spec.text, rng)]
    builders: dict[str, Callable] = {
        "swallow": _swallow_keyframes,
        "protrusion": _protrusion_keyframes,
    }
    return builders[spec.kind](rng) if spec.kind in builders else None


def task_duration(spec: TaskSpec, rng: np.random.Generator) -> tuple[float, list | None]:
    """``(seconds, keyframes)``: the natural length of one trial of ``spec``."""
    frames = _keyframes(spec, rng)
    if frames is None:
        return spec.duration_s, None
    return sum(d for d, _ in frames) + 0.15, frames


def task_labels(spec: TaskSpec, keyframes, start_s: float) -> tuple:
    """The phone and word tiers (``labels.Labels``, tiers ``phones`` and ``words``) of a
    speech task's trial: each phone over its keyframe's span (the targets' schedule, from
    ``start_s``, the first keyframe's time in the recording), pauses (``|``) unlabelled, a
    word over its phones (its label the phone string); ``()`` for a task without text.
    The articulators reach a phone's targets after it begins (the controls are smoothed):
    the intervals are the speaker's plan, as a forced aligner's are the sound's."""
    from ..labels import Labels

    if not spec.text or keyframes is None:
        return ()
    durations = iter(d for d, _ in keyframes)  # one per phone symbol, pauses included
    phones, words, word, t = [], [], [], float(start_s)

    def end_word():  # a space or a pause ends the word being spoken
        if word:
            words.append((word[0][0], word[-1][1], "".join(w[2] for w in word)))
            word.clear()

    for symbol in spec.text:
        if symbol == " ":
            end_word()
            continue
        duration = next(durations)
        if symbol == "|":
            end_word()
        else:
            phones.append((t, t + duration, symbol))
            word.append(phones[-1])
        t += duration
    end_word()

    def tier(rows, name):
        starts, ends, labels = zip(*rows, strict=True) if rows else ((), (), ())
        return Labels(np.array(starts, float), np.array(ends, float), labels, tier=name)

    return tier(phones, "phones"), tier(words, "words")


def control_trajectories(spec: TaskSpec, keyframes, n: int, dt: float, rng) -> np.ndarray:
    """``(n, len(CONTROLS))`` smooth control curves of one trial on a grid of step ``dt`` s."""
    if spec.kind == "jaw_wagging":
        return _jaw_wagging(n, dt, rng)
    slowness = 1.0 if spec.text else 2.5
    return _smooth(_piecewise_targets(keyframes, n, dt), dt, slowness)


class UnknownTaskError(CassiError, ValueError):
    """A task name that the synthetic task library does not have."""


def get_task(name: str) -> TaskSpec:
    """The task called ``name`` (case-insensitive); UnknownTaskError lists the known ones."""
    key = str(name).strip().lower()
    if key not in TASKS:
        raise UnknownTaskError(f"unknown task {name!r}; known tasks: {', '.join(TASKS)}")
    return TASKS[key]
