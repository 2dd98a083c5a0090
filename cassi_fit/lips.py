"""Where the lips meet: an articulograph recording's lip closure from its lip sensors.

The model's lip sites are where the X-ray microbeam pellets sit on the lips; an
articulograph lab glues its lip sensors elsewhere on the vermilion, so without a fitted
calibration the sensors' heights above the sites are taken from the recording
(``SubjectState.lip_rest``, :mod:`cassi_fit.initialize`). The first valid line alone says
how far the sensors are from the sites only if the speaker's lips are then as far apart
as the model's lips at rest (about 6 mm): a speaker who starts with the lips closed (the
IPS speaker mo1, before the first /m/) leaves the model's lips that far apart in every
closure.

Like the palate from the tongue's upper envelope (``palate.envelope_palate``), the
recording says where the lips touch: two lip sensors are nearest each other vertically in
the bilabial closures (and pauses with the lips shut), where the lips meet. The
*closing distance* is the low percentile :data:`CLOSED_PERCENTILE` of the upper sensor's
height above the lower one over the lines tracking both, mistracked values left out
(``gaps.usable_values``); the model's lips are placed so that they touch at it, their
opening at a line being the sensors' distance there less the closing distance (below it
the model's lips press together, ``collide.lips_apart``). The closing is split between
the lips in proportion to each sensor's vertical range of motion over the recording
(between the same low and high percentiles): the lip that moves more is taken to travel
more of the way to a closure (in bilabials the lower lip, carried by the jaw, does most).
Nothing is fitted to the sound. It is the run's choice ``lip_closure``
(``RunSpec``), **off by default**: on the one real recording it was tried on (mo1) the
model's lips now touch in the speaker's bilabial closures and the back rounded vowels come nearer,
but the formants' errors are not smaller overall (docs/ACOUSTICS.md;
``experiments/acoustic_tract_diagnosis.py``, table 4).

It assumes the lips touch on at least :data:`CLOSED_PERCENTILE` % of the tracked lines (mo1:
9 % of the lines are labelled /p b m/). A recording whose lips never close (no bilabial,
no pause with the lips shut) gets lips closed where they were only nearest: the note says
how many lines its labels mark as bilabial, or that none does. The labels are not used for
the distance itself: their boundaries are acoustic, the lips' closure is not bounded by
them (mo1's /b/: the sensors are 20.7 mm apart at their nearest inside the labelled
segment and 17 mm 40 ms after it), and most recordings have none.

**Saying where the lips' rest is wrong** (:func:`apart_in_closures`,
:func:`closures_line`): where a recording's labels mark bilabial closures, the model's lip
opening in those frames says whether the lips' rest it took is right. ``cassi acoustics``
and ``cassi animate`` (:func:`run_closures_line`) print one line when the median there is more than :data:`APART_MM` (mo1 with the
default: 7.3 mm over 72 frames; with ``lip_closure``: 1.9 mm, no line): the formants
depend on the lips' opening, and no sensor says where the lips are at rest.
"""

from __future__ import annotations

import numpy as np

#: The low percentile of the lip sensors' vertical distance taken as the lips touching
#: (1 %: robust to a few bad lines left by the mistrack detector, and within one closure
#: of 50 ms in 5 s of speech).
CLOSED_PERCENTILE = 1.0
#: The model's lip opening (mm, median over the frames labelled bilabial) above which its
#: lips are said to stay apart where the speaker's touch (:func:`closures_line`): the
#: model's lips at rest are about 6 mm apart; 2 mm leaves room for the labels' acoustic
#: boundaries (a closure's labelled frames include some of its release).
APART_MM = 2.0
#: Phone labels of bilabial stops and nasals (SAMPA, IPA, ARPAbet lowercased), for the note.
BILABIALS = ("p", "b", "m", "p_h", "em")


def is_bilabial(label) -> bool:
    """Whether a phone label names a bilabial stop or nasal (:data:`BILABIALS`, any case)."""
    return str(label).strip().lower() in BILABIALS


def closing_distance(track) -> tuple[float, float, tuple[float, float]] | None:
    """``(distance mm, time s, (upper range, lower range) mm)``: the lip sensors' closing
    distance (the upper one's height above the lower one at :data:`CLOSED_PERCENTILE`
    over the lines tracking both, mistracked values left out), the time of the first line
    at or below it, and each sensor's vertical range of motion (its heights between that
    percentile and its complement), in ``track``'s (subject) mm; None when fewer than two
    lines track both lips."""
    from .gaps import usable_values
    from .pellets import LL, UL

    good = usable_values(track)
    both = good[:, UL] & good[:, LL]
    if both.sum() < 2:
        return None
    y = np.asarray(track.positions, np.float64)[both][:, [UL, LL], 1]
    apart = y[:, 0] - y[:, 1]
    low, high = CLOSED_PERCENTILE, 100.0 - CLOSED_PERCENTILE
    distance = float(np.percentile(apart, low))
    ranges = np.diff(np.percentile(y, [low, high], axis=0), axis=0)[0]
    first = int(np.nonzero(both)[0][np.argmax(apart <= distance)])
    return distance, float(track.times[first]), (float(ranges[0]), float(ranges[1]))


def bilabial_lines(labels, times) -> int | None:
    """How many of the lines ``times`` (s) lie in an interval labelled as a bilabial
    (:data:`BILABIALS`) in any tier of ``labels`` (``labels.Labels`` tiers); None when no
    tier has such a label."""
    t = np.asarray(times, np.float64)
    inside, found = np.zeros(t.shape, bool), False
    for tier in labels or ():
        for start, end, name in zip(tier.starts, tier.ends, tier.labels, strict=True):
            if is_bilabial(name):
                found = True
                inside |= (t >= start) & (t < end)
    return int(inside.sum()) if found else None


def apart_in_closures(names, opening_mm) -> tuple[int, float] | None:
    """``(frames, median mm)``: how many frames are labelled as a bilabial
    (:data:`BILABIALS`; ``names (m,)``, each frame's label) and the model's median lip
    opening there (``opening_mm (m,)``, ``area_function.lip_opening``: where the speaker's
    lips touch, a model that places them right has them touching too, or pressed
    together); None without such a frame."""
    names = np.asarray(names, dtype=object).reshape(-1)
    opening = np.asarray(opening_mm, np.float64).reshape(-1)
    inside = np.array([is_bilabial(n) for n in names], bool)
    inside &= np.isfinite(opening)
    if not inside.any():
        return None
    return int(inside.sum()), float(np.median(opening[inside]))


def closures_line(found: tuple[int, float] | None, lip_closure: bool) -> str | None:
    """The one line saying the model's lips stay apart in the recording's labelled
    bilabial closures (``found``, :func:`apart_in_closures`), when their median opening
    there is more than :data:`APART_MM`: the lips' rest it was given is wrong by about
    that much (off ``lip_closure``, the first valid line taken as the lips at rest);
    None where they touch or nothing is labelled."""
    if found is None or not found[1] > APART_MM:
        return None
    n, apart = found
    why = ("the lip sensors' heights above the model's lip sites are not what the model "
           "took (with --lip-closure, from where the sensors are nearest)" if lip_closure else
           "the first valid line was not the lips at rest: --lip-closure takes them to "
           "touch where their sensors are nearest")
    return (f"lips: in the {n} frames labelled /p b m/ the model's lips are {apart:.1f} mm "
            f"apart (median), where the speaker's touch: {why}")


def run_closures_line(run) -> str | None:
    """:func:`closures_line` for a ``pipeline.RecordingRun`` (``cassi animate``): its labels
    as every output reads them (``labels.recording_labels``: beside the file or inside it;
    labels that do not fit the recording are read as they are, quietly: the video says so
    itself) at its frames' times, and the model's lip opening there. None without labels
    or without a labelled bilabial (the tract's geometry is then not built)."""
    import warnings

    from .area_function import lip_opening, tract_geometry
    from .errors import CassiError
    from .labels import recording_labels

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            labels = recording_labels(run.recording, accept_mismatch=True)
    except CassiError:  # unreadable labels: the outputs that use them say so
        return None
    if labels is None:
        return None
    names = labels.at(np.asarray(run.animation.times, np.float64))
    if not any(is_bilabial(n) for n in names):
        return None
    opening = lip_opening(tract_geometry(run.state.model), run.animation.vertices)
    return closures_line(apart_in_closures(names, opening), run.spec.lip_closure)


def lips_touching(model, vertices, rest, lip_rest, track, scale: float,
                  labels=()) -> tuple[tuple[float, float], str] | None:
    """``((upper, lower) model mm, note)``: the lip sensors' heights above the model's UL
    and LL sites (as ``SubjectState.lip_rest``) such that the model's lips touch where the
    sensors are at their closing distance (:func:`closing_distance`), from the first
    valid line's ``lip_rest`` and the model at rest (``vertices (V, 3)``, its sites
    ``rest (8, 2)`` without a lip offset; ``scale`` model mm per subject mm); the note says
    so in one line. None when the recording has no closing distance."""
    from .area_function import lip_opening, tract_geometry
    from .pellets import LL, UL

    found = closing_distance(track)
    if found is None:
        return None
    distance, when, (r_up, r_low) = found
    rest = np.asarray(rest)
    opening = float(lip_opening(tract_geometry(model), vertices))
    touching = float(rest[UL, 1] - rest[LL, 1] - opening)  # the sites' distance, lips touching
    close = scale * distance - (lip_rest[0] - lip_rest[1]) - touching
    up_share = r_up / (r_up + r_low) if r_up + r_low > 0 else 0.5
    offset = (lip_rest[0] + up_share * close, lip_rest[1] - (1.0 - up_share) * close)
    n = bilabial_lines(labels, track.times)
    labelled = ("no label marks a bilabial: if the lips never close, they are closed "
                "wrongly" if n is None else f"{n} lines labelled /p b m/")
    note = (f"the lips taken to touch where their sensors are nearest ({distance:.1f} mm "
            f"apart or less on {CLOSED_PERCENTILE:g} % of the lines, first at {when:.2f} s; "
            f"{labelled}): the model's lips brought {close:+.1f} mm nearer together than "
            f"with the first valid line at rest (the upper {up_share * close:+.1f}, the lower "
            f"{(1.0 - up_share) * close:+.1f} mm, by the sensors' ranges of motion "
            f"{r_up:.1f} and {r_low:.1f} mm); the sensors taken {offset[0]:+.1f} mm (upper) "
            f"and {offset[1]:+.1f} mm (lower) above the model's lip sites")
    return offset, note
