"""Gaps in a pellet recording: which values cannot be used, their repair, frame status.

A value is *bad* when it is untracked (the file's marker 1000000, NaN in memory) or
mistracked (tracked but flagged by the mistrack detector: the track's one detection,
``PelletTrack.mistracks``, whose reasons say why; :mod:`cassi_fit.mistracks`). Bad values
are never passed on to the model: per pellet they are replaced by the last good value
(``"hold"``) or by linear interpolation between good neighbours (``"interpolate"``; the
ends are held), and each frame is given a :class:`~cassi_fit.status.Status`: ``MISTRACKED``
if a mistracked value was replaced (takes precedence), else ``HELD`` or ``INTERPOLATED``
if an untracked value was, else ``OK``. This module is numpy only.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Bool, Float, Int

from .mistracks import mistrack_report
from .options import GAP_POLICIES, check_choice
from .status import Status
from .txy import PelletTrack


def bad_values(track: PelletTrack) -> tuple[Bool[np.ndarray, "n 8"], Bool[np.ndarray, "n 8"]]:
    """``(untracked, mistracked)``, each ``(n, 8)`` bool: a pellet untracked in x or y, and
    a tracked value the mistrack detector flags (``track.mistracks``: computed once per
    track; its ``reasons`` say why). ``track``: a ``PelletTrack``."""
    untracked = ~np.asarray(track.valid).all(axis=-1)
    mistracked = mistrack_report(track).flags & ~untracked
    return untracked, mistracked


def usable_values(track: PelletTrack) -> Bool[np.ndarray, "n 8"]:
    """``(n, 8)`` bool: the values tracked and not flagged by the mistrack detector
    (:func:`bad_values`), the ones an estimate from the whole recording may use."""
    untracked, mistracked = bad_values(track)
    return ~(untracked | mistracked)


def repair(
    positions: Float[np.ndarray, "n 8 2"], bad: Bool[np.ndarray, "n 8"], policy: str = "hold"
) -> Float[np.ndarray, "n 8 2"]:
    """Replace the ``bad (n, 8)`` values of ``positions (n, 8, 2)`` mm, pellet by pellet.

    ``"hold"``: the last good value before (the first good one for a leading gap);
    ``"interpolate"``: linear in the frame index between the good neighbours (held at the
    ends). A pellet with no good value at all is left as it is (NaN; the caller decides).
    An unknown policy raises ``InvalidChoiceError``.
    """
    check_choice("gap policy", policy, GAP_POLICIES)
    out = np.array(positions, dtype=np.float64)
    frames = np.arange(out.shape[0])
    for p in range(out.shape[1]):
        good = ~bad[:, p]
        if good.all() or not good.any():
            continue
        known = np.flatnonzero(good)
        if policy == "interpolate":
            for axis in range(2):
                out[:, p, axis] = np.interp(frames, known, out[known, p, axis])
        else:
            last = np.maximum.accumulate(np.where(good, frames, -1))
            source = np.where(last >= 0, last, known[0])
            out[:, p] = out[source, p]
    return out


def frame_status(
    untracked: Bool[np.ndarray, "n 8"], mistracked: Bool[np.ndarray, "n 8"], policy: str
) -> Int[np.ndarray, " n"]:
    """``(n,)`` int32 ``Status`` values: ``MISTRACKED`` if a value was mistracked, else
    ``HELD`` or ``INTERPOLATED`` (by ``policy``) if one was untracked, else ``OK``."""
    check_choice("gap policy", policy, GAP_POLICIES)
    gap = Status.INTERPOLATED if policy == "interpolate" else Status.HELD
    status = np.where(untracked.any(axis=1), int(gap), int(Status.OK))
    return np.where(mistracked.any(axis=1), int(Status.MISTRACKED), status).astype(np.int32)
