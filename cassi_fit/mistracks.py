"""Mistracks: tracked pellet values that cannot be true movement, each with its reason.

XRMB files mark a lost pellet with 1000000 (``PelletTrack.valid``), but a tracker also
writes wrong values without marking them. :func:`detect` finds the shapes real trackers
produce and says, per frame and pellet, why (:class:`Reason`, bits of one integer, so a
value may carry several). A track's detection is computed once and kept on it
(``PelletTrack.mistracks``); every user (the first valid line, ``quality_report``,
``gaps``, the jaw fit, ``cassi info``) reads that one result (:func:`mistrack_report`).

Only values tracked in x and y are judged (a value with one coordinate marked is
untracked for the rest of the toolkit); the range test also looks at a lone coordinate.

**The tests, in the order they run** (mm, s; each constant below):

1. ``range``: outside the box ``x in [-120, 60]``, ``y in [-90, 60]`` (real pellets span
   about x -65..25, y -35..30).
2. ``dropout``: a value exactly at the origin (0, 0), the upper incisor tip, where no
   pellet can be (the tracker's reset); two pellets at exactly the same position (lost
   pellets written with one marker); a run of two or more identical values that the
   jump tests (4) reject (the tracker jumped to a marker and stayed).
3. ``plateau``: one value (x and y, to the micrometre) repeated on ``PLATEAU_FRAMES`` = 8
   or more consecutive frames while most other tracked pellets move. XRMB values are
   integer micrometres and carry measurement noise: in JW11 task 5 (one recording of
   one speaker) no pellet repeats its x and y even once on consecutive frames, and one
   coordinate alone repeats on at most 4. Where repeats are ordinary the test stands
   down: when every pellet is still at once, or when the pellet repeats a value on
   shorter runs at least 3 times and on ``PLATEAU_QUANTISED`` = 0.5 % of its frames (its
   values are coarser than its noise: the synthetic corpus without noise, or with its
   slow "drift" noise alone).
4. kinematics, on the values that passed 1-3, per pellet:
   ``jump``: a value further from the running median of ``MEDIAN_WINDOW`` = 11 frames
   than a pellet moving at ``MAX_SPEED_MM_S`` could be (isolated excursions of up to five
   frames), or a one-frame spike whose deviation from its neighbours' midpoint needs an
   acceleration beyond ``MAX_ACCELERATION_MM_S2`` (the spike's second difference at
   least ``SPIKE_RATIO`` times its neighbours'), or a short excursion: a jump out and a
   jump back within five frames, each a step that departs from its neighbours' velocity
   by more than that acceleration allows. ``persistent-jump``: the track is cut
   where a step needs more than ``MAX_SPEED_MM_S``; starting from the longest stretch
   whose geometry holds (5), a stretch is kept when it can be reached from the kept
   stretch before it at that speed (a stretch of at most five frames, cut off on both
   sides, only when nothing was rejected in between), else it is rejected (an excursion that comes back, of any
   length; ``jump`` when it lasts at most five frames). A rejected stretch that
   never comes back (it runs to a gap or the end) is rejected only when it lasts at most
   five frames or its geometry fails on most of its frames: a lasting jump whose
   geometry holds is taken for true movement. ``swap``: a rejected stretch that begins
   or ends with two pellets trading positions. ``edge``: a rejected stretch at the first
   or last value of a tracked stretch, and a spike on that value (it has one neighbour,
   so its deviation from the line through the next two values is tested).
   Every limit adds ``NOISE_SDS`` = 4 times the pellet's own noise (the robust SD of its
   second differences, x and y together): real XRMB data are smooth (0.04-0.06 mm on
   JW11), synthetic data with white noise are not (about 0.5 mm).
5. geometry, on the values that passed 1-4 (a value flagged there takes no part):
   ``jaw-distance``: MNI and MNM are on one bone, so their distance is constant up to
   noise (SD 0.30 mm on JW11): a frame further than ``max(JAW_ROBUST_SDS = 5 robust SD,
   JAW_MIN_DEVIATION_MM = 2 mm)`` from its median flags both (the distance cannot say
   which moved). ``tongue-spacing``: the distance between neighbouring tongue pellets,
   beyond ``max(5 robust SD, TONGUE_SPACING_MIN_MM = 6 mm)`` (the tongue stretches: on
   JW11 T3-T4 spans 5.7 mm, on the synthetic corpus a spacing moves up to 4.3 mm from its
   median); blamed on the pellet with more violated neighbours, else on both.
   ``lip-incisor``: UL's distance to the upper incisor tip (the origin) beyond
   ``max(5 robust SD, UPPER_LIP_MIN_MM = 6 mm)``, LL's to MNI beyond ``max(5 robust SD,
   LOWER_LIP_MIN_MM = 12 mm)`` (the lower lip moves on the jaw by up to 8.6 mm in the
   synthetic labiodentals and bilabials, 4 mm on JW11); blamed on the lip (on MNI instead
   when the jaw distance has just flagged MNI alone). ``order``: the anatomical order,
   frame by frame, violated by more than ``ORDER_MARGIN_MM`` = 5 mm: T1 in front of T2,
   T2 of T3, T3 of T4, MNI of MNM, UL of the upper incisor tip, LL of MNI (x); UL above
   LL (y). Real gaps are 8-15 mm (JW11: at least 9.9 mm between tongue pellets, 8 mm
   from LL to MNI); the margin lets a bunched or curled tongue stack its pellets.
   Robust SD = 1.4826 x median absolute deviation, over the values that passed 1-4.
6. ``drift``: a value flagged only by test 5's distances (and perhaps its order), on at
   least ``DRIFT_MIN_FRAMES`` = 6 consecutive frames: it slid away without a jump.

**The limits' basis.** The fastest pellet in JW11 task 5 moves at 262 mm/s (T1) and
accelerates at 5.6 m/s²; the synthetic corpus stays below about 290 mm/s and, outside its
deliberately non-physical "thrust" jaw, 9 m/s². ``MAX_SPEED_MM_S`` = 500 mm/s and
``MAX_ACCELERATION_MM_S2`` = 20 m/s² are about twice and three times those. No published
maximum could be verified with the sources at hand (the abstracts of McClean 2000, JSLHR
43:205-216, and of Tasko & Westbury, "Defining and measuring speech movement events",
JSLHR, an XRMB study, say that they measure peak speeds; their numbers were not
reachable), so the limits rest on these recordings: one real speaker.
docs/FORMATS.md ("Mistracks") gives the measured detection and false-alarm rates and
what the detector cannot see.

This module is numpy only.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from jaxtyping import Bool, Float, UInt
from numpy.lib.stride_tricks import sliding_window_view

from .pellets import (
    LL,
    MNI,
    MNM,
    PELLET_NAMES,
    T1,
    T2,
    T3,
    T4,
    UL,
    PelletTrackLike,
)

# ------------------------------------------------------------------ thresholds (mm, s)
PLAUSIBLE_X_MM = (-120.0, 60.0)
PLAUSIBLE_Y_MM = (-90.0, 60.0)
MAX_SPEED_MM_S = 500.0
MAX_ACCELERATION_MM_S2 = 20_000.0
MEDIAN_WINDOW = 11
SPIKE_RATIO = 1.5
EDGE_RATIO = 3.0
NOISE_SDS = 4.0
PLATEAU_FRAMES = 8
PLATEAU_QUANTISED = 0.005
SHORT_FRAMES = MEDIAN_WINDOW // 2  # an excursion this short is a "jump"
JAW_ROBUST_SDS = 5.0
JAW_MIN_DEVIATION_MM = 2.0
TONGUE_SPACING_SDS = 5.0
TONGUE_SPACING_MIN_MM = 6.0
LIP_SDS = 5.0
UPPER_LIP_MIN_MM = 6.0
LOWER_LIP_MIN_MM = 12.0
DRIFT_MIN_FRAMES = 6
ORDER_MARGIN_MM = 5.0
_MAD_TO_SD = 1.4826


class Reason(enum.IntFlag):
    """Why a value is mistracked (bits: a value may have several reasons)."""

    RANGE = 1
    DROPOUT = 2
    PLATEAU = 4
    JUMP = 8
    PERSISTENT_JUMP = 16
    SWAP = 32
    EDGE = 64
    ORDER = 128
    JAW_DISTANCE = 256
    TONGUE_SPACING = 512
    LIP_INCISOR = 1024
    DRIFT = 2048

    @property
    def label(self) -> str:
        """The word written in tables and messages: ``"persistent-jump"``, ..."""
        return (self.name or "").lower().replace("_", "-")


#: Every reason, in bit order.
REASONS = tuple(Reason)
_DISTANCES = Reason.JAW_DISTANCE | Reason.TONGUE_SPACING | Reason.LIP_INCISOR
_GEOMETRY = _DISTANCES | Reason.ORDER


def reason_label(bits: int) -> str:
    """``"plateau+drift"`` for the reasons set in ``bits``; ``""`` for none."""
    return "+".join(r.label for r in REASONS if int(bits) & r)


@dataclass(frozen=True, eq=False)
class MistrackReport:
    """One track's mistracks: ``reasons (n, 8)`` integer bits of :class:`Reason`, 0 where
    the value is not mistracked (untracked values are 0: they are marked, not wrong)."""

    reasons: UInt[np.ndarray, "n 8"]

    @property
    def flags(self) -> Bool[np.ndarray, "n 8"]:
        """``(n, 8)`` bool: True where a value is mistracked."""
        return self.reasons != 0

    def has(self, reason: Reason) -> Bool[np.ndarray, "n 8"]:
        """``(n, 8)`` bool: values flagged for ``reason`` (among others)."""
        return (self.reasons & int(reason)) != 0

    def counts(self) -> dict[str, dict[str, int]]:
        """``{pellet: {reason label: values}}`` for every pellet (``PELLET_NAMES`` order)
        and every reason found for it; a value with two reasons counts under both."""
        per_reason = {r.label: self.has(r).sum(axis=0) for r in REASONS}  # (8,) each
        return {p: {label: int(c[i]) for label, c in per_reason.items() if c[i]}
                for i, p in enumerate(PELLET_NAMES)}

    def frame_labels(self) -> list[str]:
        """One string per frame: ``""`` when nothing is mistracked, else the pellets and
        their reasons, e.g. ``"MNI:dropout T2:swap+order"`` (for a table's column)."""
        out = [""] * self.reasons.shape[0]
        for k in np.flatnonzero(self.flags.any(axis=1)):
            out[k] = mistrack_labels(self.reasons[k])
        return out


def mistrack_labels(reasons: UInt[np.ndarray, " 8"]) -> str:
    """One frame's mistracks as words: ``"MNI:dropout T2:swap+order"`` (``reasons``: the
    frame's ``(8,)`` :class:`Reason` bits); ``""`` when none."""
    return " ".join(f"{PELLET_NAMES[p]}:{reason_label(reasons[p])}"
                    for p in np.flatnonzero(reasons))


def mistrack_report(track: PelletTrackLike) -> MistrackReport:
    """The track's one detection: ``track.mistracks`` (computed once, kept on a
    ``txy.PelletTrack``), or :func:`detect` for any other object with times, positions
    and valid."""
    report = getattr(track, "mistracks", None)
    return report if isinstance(report, MistrackReport) else detect(track)


def detect_mistracks(track: PelletTrackLike) -> Bool[np.ndarray, "n 8"]:
    """``(n, 8)`` bool: True where a tracked value is mistracked (the track's one
    detection, :func:`mistrack_report`); the reasons are in its report."""
    return mistrack_report(track).flags


# ------------------------------------------------------------------ helpers
def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.sum(v * v, axis=-1))


def running_median(values: Float[np.ndarray, "n ..."]) -> Float[np.ndarray, "n ..."]:
    """NaN-aware median over ``MEDIAN_WINDOW`` frames centred on each frame (axis 0).

    NaN where a window holds no value. Sorting puts NaN last, so the median of the
    ``count`` values is the mean of the sorted entries ``(count - 1) // 2`` and
    ``count // 2`` (several times faster than ``np.nanmedian``).
    """
    half = MEDIAN_WINDOW // 2
    pad = np.full((half,) + values.shape[1:], np.nan)
    windows = sliding_window_view(np.concatenate([pad, values, pad]), MEDIAN_WINDOW, axis=0)
    ordered = np.sort(windows, axis=-1)
    count = np.sum(~np.isnan(windows), axis=-1, keepdims=True)
    lo = np.take_along_axis(ordered, np.maximum(count - 1, 0) // 2, axis=-1)
    hi = np.take_along_axis(ordered, count // 2, axis=-1)
    return np.where(count > 0, 0.5 * (lo + hi), np.nan)[..., 0]


def _robust(values: np.ndarray) -> tuple[float, float]:
    """``(median, robust SD)`` of the finite values; NaN, NaN if there are fewer than 3."""
    ok = values[np.isfinite(values)]
    if ok.size < 3:
        return np.nan, np.nan
    median = float(np.median(ok))
    return median, _MAD_TO_SD * float(np.median(np.abs(ok - median)))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of the runs of True in a 1-D bool array."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


# ------------------------------------------------------------------ 1-3 simple tests
def _out_of_range(positions: np.ndarray) -> np.ndarray:
    x, y = positions[..., 0], positions[..., 1]
    with np.errstate(invalid="ignore"):
        bad_x = (x < PLAUSIBLE_X_MM[0]) | (x > PLAUSIBLE_X_MM[1])
        bad_y = (y < PLAUSIBLE_Y_MM[0]) | (y > PLAUSIBLE_Y_MM[1])
    return bad_x | bad_y


def _dropouts(positions: np.ndarray, tracked: np.ndarray) -> np.ndarray:
    """``(n, 8)``: at the origin exactly, or exactly where another pellet is."""
    out = tracked & (positions == 0.0).all(axis=-1)
    for a in range(positions.shape[1]):
        for b in range(a + 1, positions.shape[1]):
            same = tracked[:, a] & tracked[:, b] & (positions[:, a] == positions[:, b]).all(-1)
            out[:, a] |= same
            out[:, b] |= same
    return out


def _plateaus(positions: np.ndarray, tracked: np.ndarray, times: np.ndarray,
              allow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(stuck, marker)`` ``(n, 8)``: runs of at least ``PLATEAU_FRAMES`` identical
    values of one pellet while most other tracked pellets change value; ``marker`` those
    entered by a step faster than ``MAX_SPEED_MM_S`` (plus ``allow (8,)`` mm): the
    tracker jumped to a marker value and stayed, rather than sticking where it was."""
    n = positions.shape[0]
    marker = np.zeros(tracked.shape, bool)
    same = np.zeros(tracked.shape, bool)
    same[1:] = tracked[1:] & tracked[:-1] & (positions[1:] == positions[:-1]).all(axis=-1)
    out = np.zeros(tracked.shape, bool)
    for p in range(tracked.shape[1]):
        runs = _runs(same[:, p])
        short = sum(stop - start for start, stop in runs if stop - start + 1 < PLATEAU_FRAMES)
        if short >= max(3, PLATEAU_QUANTISED * same[:, p].size):
            continue  # values coarser than their noise: a still pellet repeats them
        for start, stop in runs:
            if stop - start + 1 < PLATEAU_FRAMES:
                continue
            frames = slice(start, stop)  # the steps of the run (frame k vs k - 1)
            others = [q for q in range(tracked.shape[1]) if q != p
                      and tracked[start - 1:stop, q].mean() >= 0.5]
            moving = [q for q in others if (~same[frames, q] & tracked[frames, q]).mean() > 0.5]
            if others and len(moving) * 2 > len(others):
                first = max(start - 1, 0)
                out[first:min(stop, n), p] = True
                if first > 0 and tracked[first - 1, p]:
                    marker[first:min(stop, n), p] = not _reachable(
                        positions[first - 1, p], times[first - 1], positions[first, p],
                        times[first], allow[p])
    return out & ~marker, marker


# ------------------------------------------------------------------ 4 kinematics
def _noise(positions: np.ndarray) -> np.ndarray:
    """``(8,)`` mm: each pellet's robust SD of its second differences (x and y together)."""
    d2 = positions[2:] - 2.0 * positions[1:-1] + positions[:-2]
    out = np.zeros(positions.shape[1])
    for p in range(positions.shape[1]):
        sds = [_robust(d2[:, p, axis])[1] for axis in range(2)]
        out[p] = float(np.hypot(*sds)) if np.isfinite(sds).all() else 0.0
    return out


def _second_difference(positions: np.ndarray) -> np.ndarray:
    """``(n, 8)`` mm: ``|p[k+1] - 2 p[k] + p[k-1]|``, NaN at the ends and next to gaps."""
    m = np.full(positions.shape[:2], np.nan)
    m[1:-1] = _norm(positions[2:] - 2.0 * positions[1:-1] + positions[:-2])
    return m


def _median_jumps(positions: np.ndarray, times: np.ndarray, step_s: float) -> np.ndarray:
    """``(n, 8)``: too far from the running median, or a spike whose jumps in and out
    both exceed one frame's travel at ``MAX_SPEED_MM_S``.

    Near gaps and file ends the window is one-sided and its median lags; it then stands
    for the median time of the frames it holds, so a pellet may be ``MAX_SPEED_MM_S``
    times that time difference further away (plus one frame's travel).
    """
    n = positions.shape[0]
    tracked = np.isfinite(positions).all(axis=-1)
    median_time = running_median(np.where(tracked, times[:, None], np.nan))
    allowed = MAX_SPEED_MM_S * (step_s + np.abs(times[:, None] - median_time))
    with np.errstate(invalid="ignore"):
        far = _norm(positions - running_median(positions)) > allowed
        step = np.full((n + 1, positions.shape[1]), np.nan)
        step[1:n] = _norm(positions[1:] - positions[:-1])
        limit = MAX_SPEED_MM_S * step_s
        spike = (step[:-1] > limit) & (step[1:] > limit)
    return far | spike


def _shift(a: np.ndarray, k: int, fill) -> np.ndarray:
    """``out[i] = a[i - k]`` along axis 0 (``fill`` where ``i - k`` is outside)."""
    out = np.full_like(a, fill)
    n = a.shape[0]
    if abs(k) < n:
        if k >= 0:
            out[k:] = a[:n - k]
        else:
            out[:k] = a[-k:]
    return out


def _spikes(positions: np.ndarray, noise: np.ndarray, step_s: float) -> tuple[np.ndarray, ...]:
    """``(spike, edge)`` ``(n, 8)``: one-frame spikes beyond the acceleration limit, inside
    a tracked stretch and on its first or last value."""
    m = _second_difference(positions)
    limit = MAX_ACCELERATION_MM_S2 * step_s**2 + NOISE_SDS * noise  # (8,)
    filled = np.where(np.isfinite(m), m, 0.0)
    tracked = np.isfinite(positions).all(axis=-1)
    with np.errstate(invalid="ignore"):
        big = m > limit
        spike = big & (m > SPIKE_RATIO * np.maximum(_shift(filled, 1, 0.0),
                                                     _shift(filled, -1, 0.0)))
    # a stretch's first value k (k - 1 untracked): filled[k + 1] is its deviation from
    # the line through the next two values; the last value likewise
    first = tracked & ~_shift(tracked, 1, False)
    last = tracked & ~_shift(tracked, -1, False)
    after, after2 = _shift(filled, -1, 0.0), _shift(filled, -2, 0.0)
    before, before2 = _shift(filled, 1, 0.0), _shift(filled, 2, 0.0)
    edge_first = first & (after > limit) & (after > EDGE_RATIO * after2)
    edge_last = last & (before > limit) & (before > EDGE_RATIO * before2)
    # the value beside a spiked edge sees the spike as its own (its other neighbour has
    # no second difference): the edge test has already named the culprit
    spike &= ~_shift(edge_first, 1, False) & ~_shift(edge_last, -1, False)
    return spike, edge_first | edge_last


def _excursions(positions: np.ndarray, noise: np.ndarray, step_s: float) -> np.ndarray:
    """``(n, 8)``: short excursions, out and back within ``SHORT_FRAMES`` frames.

    A step's jump ``J[k] = (p[k] - p[k-1]) - ((p[k-1] - p[k-2]) + (p[k+1] - p[k])) / 2``
    (the step less its neighbours' mean) is near 0 for smooth motion; a
    value that jumps by ``h`` and comes back ``m`` frames later gives ``J = h`` at the way
    out and ``-h`` at the way back. Both beyond ``MAX_ACCELERATION_MM_S2 dt^2`` plus
    ``NOISE_SDS`` times the pellet's noise, and opposite within half their size: the
    values between are flagged.
    """
    n, k = positions.shape[:2]
    out = np.zeros((n, k), bool)
    if n < 4:
        return out
    jump = np.full(positions.shape, np.nan)
    step = positions[1:] - positions[:-1]  # step[k - 1] = p[k] - p[k - 1]
    jump[2:-1] = step[1:-1] - 0.5 * (step[:-2] + step[2:])
    size = _norm(jump)
    limit = MAX_ACCELERATION_MM_S2 * step_s**2 + NOISE_SDS * noise  # (8,)
    filled = np.where(np.isfinite(size), size, 0.0)
    with np.errstate(invalid="ignore"):
        # a jump's neighbours see half of it (side lobes): only local maxima count
        big = (size > limit) & (filled >= np.maximum(_shift(filled, 1, 0.0),
                                                     _shift(filled, -1, 0.0)))
    for p in range(k):
        for way_out in np.flatnonzero(big[:, p]):
            for back in range(way_out + 1, min(way_out + SHORT_FRAMES + 1, n)):
                if not big[back, p]:
                    continue
                gap = _norm(jump[way_out, p] + jump[back, p])
                if gap <= 0.5 * max(size[way_out, p], size[back, p]):
                    out[way_out:back, p] = True
                    break
    return out


def _reachable(pa: np.ndarray, ta: float, pb: np.ndarray, tb: float, allow: float) -> bool:
    """Can a pellet at ``pa`` (time ``ta``) be at ``pb`` (time ``tb``)?"""
    return bool(_norm(pb - pa) <= MAX_SPEED_MM_S * abs(tb - ta) + allow)


def _stretches(positions: np.ndarray, times: np.ndarray, p: int, allow: float,
               geometry_bad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pellet ``p``'s rejected values: ``(rejected, swapped, at_edge)``, each ``(n,)``.

    The tracked values are cut where a step is faster than ``MAX_SPEED_MM_S`` (plus
    ``allow``); from the longest piece whose geometry mostly holds, pieces are kept
    outward while reachable from the last kept value (module docstring, test 4).
    """
    n = positions.shape[0]
    rejected, swapped, at_edge = (np.zeros(n, bool) for _ in range(3))
    idx = np.flatnonzero(np.isfinite(positions[:, p]).all(axis=-1))
    if idx.size < 2:
        return rejected, swapped, at_edge
    xy, t = positions[idx, p], times[idx]
    fast = _norm(xy[1:] - xy[:-1]) > MAX_SPEED_MM_S * np.diff(t) + allow
    if not fast.any():
        return rejected, swapped, at_edge
    pieces = np.split(np.arange(idx.size), np.flatnonzero(fast) + 1)
    bad_share = [geometry_bad[idx[q], p].mean() for q in pieces]
    order = sorted(range(len(pieces)), key=lambda q: (bad_share[q] > 0.5, -len(pieces[q]), q))
    main = order[0]
    keep = np.zeros(len(pieces), bool)
    keep[main] = True
    for direction in (1, -1):
        ref = pieces[main][-1] if direction == 1 else pieces[main][0]
        q = main + direction
        pending: list[int] = []
        while 0 <= q < len(pieces):
            piece = pieces[q]
            near = piece[0] if direction == 1 else piece[-1]
            # across rejected pieces, a short piece is no new reference: it may be one
            # more wrong value that the generous reach over a few frames lets through
            outermost = not 0 <= q + direction < len(pieces)
            across = bool(pending) and piece.size <= SHORT_FRAMES and not outermost
            if not across and _reachable(xy[ref], t[ref], xy[near], t[near], allow):
                keep[q] = True
                pending = []
                ref = piece[-1] if direction == 1 else piece[0]
            else:
                pending.append(q)
            q += direction
        # pieces that never came back: rejected only when short or geometrically wrong
        if pending:
            tail = np.concatenate([pieces[k] for k in pending])
            if tail.size > SHORT_FRAMES and geometry_bad[idx[tail], p].mean() <= 0.5:
                keep[pending] = True
    tracked_p = np.isfinite(positions[:, p]).all(axis=-1)
    for q in np.flatnonzero(~keep):
        frames = idx[pieces[q]]
        rejected[frames] = True
        if _swapped(positions, idx, pieces[q], p, allow, times):
            swapped[frames] = True
        lo, hi = frames[0], frames[-1]
        if lo == 0 or not tracked_p[lo - 1] or hi == n - 1 or not tracked_p[hi + 1]:
            at_edge[frames] = True
    return rejected, swapped, at_edge


def _swapped(positions, idx, piece, p, allow, times) -> bool:
    """Does the rejected ``piece`` of pellet ``p`` begin or end with ``p`` and another
    pellet trading positions (each where the other just was)?"""
    ends = []
    if piece[0] > 0:
        ends.append((idx[piece[0] - 1], idx[piece[0]]))
    if piece[-1] + 1 < idx.size:
        ends.append((idx[piece[-1]], idx[piece[-1] + 1]))
    for before, after in ends:
        dt = times[after] - times[before]
        for q in range(positions.shape[1]):
            if q == p or not np.isfinite(positions[[before, after], q]).all():
                continue
            if (_reachable(positions[before, q], 0.0, positions[after, p], dt, allow)
                    and _reachable(positions[before, p], 0.0, positions[after, q], dt, allow)):
                return True
    return False


# ------------------------------------------------------------------ 5 geometry
#: (front/top pellet, behind/below pellet or None for the upper incisor tip, axis)
_ORDER = (
    (T1, T2, 0), (T2, T3, 0), (T3, T4, 0), (MNI, MNM, 0), (UL, LL, 1), (UL, None, 0),
    (LL, MNI, 0),
)
_TONGUE_PAIRS = ((T1, T2), (T2, T3), (T3, T4))


def _distance(positions: np.ndarray, a: int, b: int | None) -> np.ndarray:
    """``(n,)`` mm between pellets ``a`` and ``b`` (``None``: the origin); NaN if untracked."""
    other = 0.0 if b is None else positions[:, b]
    return _norm(positions[:, a] - other)


def _violations(d: np.ndarray, sds: float, floor: float) -> np.ndarray:
    median, sd = _robust(d)
    if not np.isfinite(median):
        return np.zeros(d.shape, bool)
    with np.errstate(invalid="ignore"):
        return np.abs(d - median) > max(sds * sd, floor)


def _order_violations(positions: np.ndarray) -> list[tuple[int, int | None, np.ndarray]]:
    """``[(a, b, (n,) bool)]``: ``a`` is more than ``ORDER_MARGIN_MM`` behind (below) ``b``."""
    out = []
    for a, b, axis in _ORDER:
        other = 0.0 if b is None else positions[:, b, axis]
        with np.errstate(invalid="ignore"):
            out.append((a, b, positions[:, a, axis] < other - ORDER_MARGIN_MM))
    return out


def _distance_violations(positions: np.ndarray) -> list[tuple[Reason, int, int | None, np.ndarray]]:
    out = [(Reason.JAW_DISTANCE, MNI, MNM, _violations(
        _distance(positions, MNI, MNM), JAW_ROBUST_SDS, JAW_MIN_DEVIATION_MM))]
    out += [(Reason.TONGUE_SPACING, a, b, _violations(
        _distance(positions, a, b), TONGUE_SPACING_SDS, TONGUE_SPACING_MIN_MM))
        for a, b in _TONGUE_PAIRS]
    out += [(Reason.LIP_INCISOR, a, b, _violations(_distance(positions, a, b), LIP_SDS, floor))
            for a, b, floor in ((UL, None, UPPER_LIP_MIN_MM), (LL, MNI, LOWER_LIP_MIN_MM))]
    return out


def _geometry_bad(positions: np.ndarray) -> np.ndarray:
    """``(n, 8)``: a value in a violated relation of test 5 (blamed on nobody yet)."""
    bad = np.zeros(positions.shape[:2], bool)
    for a, b, v in _order_violations(positions):
        bad[:, a] |= v
        if b is not None:
            bad[:, b] |= v
    for _, a, b, v in _distance_violations(positions):
        bad[:, a] |= v
        if b is not None:
            bad[:, b] |= v
    return bad


def _blame(reasons: np.ndarray, positions: np.ndarray) -> None:
    """Test 5 on ``positions`` (NaN where tests 1-4 flag a value), blamed as the module
    says; adds the bits to ``reasons`` in place. The distances go first (the jaw before
    LL-MNI, which needs to know whether MNI is wrong), the order last."""
    distances = _distance_violations(positions)
    tongue_count = np.zeros(positions.shape[:2], int)
    for reason, a, b, v in distances:
        if reason == Reason.TONGUE_SPACING:
            tongue_count[:, a] += v
            tongue_count[:, b] += v
    for reason, a, b, v in distances:
        _blame_pair(reasons, reason, a, b, v, tongue_count)
    for a, b, v in _order_violations(positions):
        _blame_pair(reasons, Reason.ORDER, a, b, v, tongue_count)


def _blame_pair(reasons, reason, a, b, v, tongue_count) -> None:
    """Blame the violation ``v (n,)`` of pellets ``a`` and ``b`` (None: the incisor tip)."""
    if b is None:
        reasons[v, a] |= np.uint16(reason)
        return
    flagged = reasons != 0
    only_a = flagged[:, a] & ~flagged[:, b]
    only_b = flagged[:, b] & ~flagged[:, a]
    if (a, b) == (LL, MNI):  # LL rides on MNI: LL, unless MNI alone is flagged
        blame_a, blame_b = ~only_b, only_b
    else:
        ca, cb = tongue_count[:, a], tongue_count[:, b]
        neither = ~only_a & ~only_b
        blame_a = only_a | (neither & (ca >= cb))
        blame_b = only_b | (neither & (cb >= ca))
    reasons[v & blame_a, a] |= np.uint16(reason)
    reasons[v & blame_b, b] |= np.uint16(reason)


# ------------------------------------------------------------------ the detector
def detect(track: PelletTrackLike) -> MistrackReport:
    """The mistrack detector (module docstring): a :class:`MistrackReport` of ``track``
    (times s ``(n,)``, positions mm ``(n, 8, 2)``, valid ``(n, 8, 2)``, its line period
    ``frame_step_s``).

    Prefer :func:`mistrack_report` (or ``PelletTrack.mistracks``), which computes it once
    per track. Values marked untracked (1000000) are never flagged.
    """
    raw = np.asarray(track.positions, np.float64)
    valid = np.asarray(track.valid, bool)
    times = np.asarray(track.times, np.float64)
    n, k = raw.shape[:2]
    reasons = np.zeros((n, k), np.uint16)
    tracked = valid.all(axis=-1)
    positions = np.where(tracked[..., None], raw, np.nan)
    if n == 0:
        return MistrackReport(reasons)
    step_s = track.frame_step_s  # the one rule of the line period (txy.frame_step)
    # 1-3
    reasons[_out_of_range(np.where(valid, raw, np.nan)) & valid.any(axis=-1)] |= np.uint16(Reason.RANGE)
    reasons[_dropouts(positions, tracked)] |= np.uint16(Reason.DROPOUT)
    stuck, marker = _plateaus(positions, tracked, times, NOISE_SDS * _noise(positions))
    reasons[stuck] |= np.uint16(Reason.PLATEAU)
    reasons[marker] |= np.uint16(Reason.DROPOUT)
    usable = np.where((reasons == 0)[..., None], positions, np.nan)
    # 4
    noise = _noise(usable)
    reasons[_median_jumps(usable, times, step_s)] |= np.uint16(Reason.JUMP)
    spike, edge = _spikes(usable, noise, step_s)
    reasons[spike | _excursions(usable, noise, step_s)] |= np.uint16(Reason.JUMP)
    reasons[edge] |= np.uint16(Reason.EDGE)
    geometry_bad = _geometry_bad(usable)
    for p in range(k):
        rejected, swapped, at_edge = _stretches(usable, times, p, NOISE_SDS * noise[p],
                                                geometry_bad)
        for start, stop in _runs(rejected):
            frames = slice(start, stop)
            values = usable[frames, p]
            if stop - start >= 2 and (values == values[0]).all():
                reasons[frames, p] |= np.uint16(Reason.DROPOUT)  # jumped to a marker and stayed
            short = stop - start <= SHORT_FRAMES
            reasons[frames, p] |= np.uint16(Reason.JUMP if short else Reason.PERSISTENT_JUMP)
        reasons[swapped, p] |= np.uint16(Reason.SWAP)
        reasons[at_edge, p] |= np.uint16(Reason.EDGE)
    # 5
    _blame(reasons, np.where((reasons != 0)[..., None], np.nan, positions))
    # 6
    distance = (reasons & np.uint16(_DISTANCES)) != 0
    geometric_only = distance & ((reasons & np.uint16(0xFFFF & ~int(_GEOMETRY))) == 0)
    for p in range(k):
        for start, stop in _runs(geometric_only[:, p]):
            if stop - start >= DRIFT_MIN_FRAMES:
                reasons[start:stop, p] |= np.uint16(Reason.DRIFT)
    reasons[~tracked & ~valid.any(axis=-1)] = 0
    return MistrackReport(reasons)
