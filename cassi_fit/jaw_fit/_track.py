"""``jaw_from_track``: the jaw fits on a :class:`cassi_fit.txy.PelletTrack` (the adapter from
pellet files, with the first-valid-line rule and the mistrack detector)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DegenerateGeometryError, InvalidChoiceError, MissingDataError
from ..status import Status
from ._fit import JawFit, fit_jaw
from ._methods import JawMethod

if TYPE_CHECKING:
    from ..txy import PelletTrack


def jaw_from_track(track: PelletTrack, *, method: JawMethod | str = "closed-form",
                   reference_frame: int | None = None, **options: Any) -> JawFit:
    """:func:`fit_jaw` on a :class:`cassi_fit.txy.PelletTrack`'s MNI and MNM pellets.

    Values flagged by the mistrack detector (``PelletTrack.mistracks``, :mod:`cassi_fit.mistracks`)
    are not used: their frames get status MISTRACKED (values interpolated, as for
    untracked frames, which get INVALID_FRAME). The reference is ``reference_frame`` (an
    index in ``[0, n)`` whose jaw pellets are tracked and not mistracked) or, by default,
    the first frame in which both jaw pellets are tracked and neither is mistracked:
    CASSI's first valid line for the jaw, moved past a mistracked line so that one bad
    value cannot tilt every frame. ``options`` (``solver``, ``smoothness``, ...) go to
    :func:`fit_jaw` with a method alias. Errors name the file.
    """
    from ..pellets import JAW_PELLETS, first_valid_line, pellet_index

    where = str(track.path) if track.path is not None else "<pellet track>"
    cols = [pellet_index(p) for p in JAW_PELLETS]
    tracked = track.frame_valid(JAW_PELLETS)
    flags = track.mistracks.flags  # the track's one detection
    mistracked = flags[:, cols].any(axis=1) & tracked
    usable = tracked & ~mistracked
    n = track.n_frames
    if reference_frame is None:  # the one first-valid-line rule (pellets), for the jaw pellets
        reference_frame = first_valid_line(track, where, pellets=JAW_PELLETS,
                                           mistracked=flags).index
    elif (isinstance(reference_frame, bool) or not isinstance(reference_frame, (int, np.integer))
          or not 0 <= reference_frame < n):
        raise InvalidChoiceError(f"{where}: reference_frame must be a frame index in "
                                 f"[0, {n}), got {reference_frame!r}")
    elif not usable[reference_frame]:
        why = "mistracked" if mistracked[reference_frame] else "untracked"
        raise MissingDataError(f"{where}: jaw pellets {why} in reference frame {reference_frame}")
    jaw_points = track.positions[:, cols, :]
    try:
        fit = fit_jaw(jaw_points[reference_frame], jaw_points, method=method, valid=usable,
                      **options)
    except (MissingDataError, DegenerateGeometryError) as exc:
        raise type(exc)(f"{where}: {exc}") from None
    return replace(fit, status=np.where(mistracked, Status.MISTRACKED, fit.status).astype(
        np.int32), reference_frame=reference_frame)
