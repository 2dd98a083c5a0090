"""``jaw_from_track``: the jaw fits on a :class:`cassi_fit.txy.PelletTrack` (the adapter from
pellet files, with the first-valid-line rule and the mistrack detector), and
``learn_jaw_coupling``: the one-sensor coupling prior learned from two-sensor tracks."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DegenerateGeometryError, InvalidChoiceError, MissingDataError
from ..status import Status, fitted
from ._fit import JAW_SENSORS, JawFit, fit_jaw, jaw_sensor_set
from ._methods import JawMethod
from ._priors import JawCoupling

if TYPE_CHECKING:
    from ..txy import PelletTrack


def jaw_from_track(track: PelletTrack, *, method: JawMethod | str = "closed-form",
                   reference_frame: int | None = None,
                   jaw_sensors: str | tuple[str, ...] = JAW_SENSORS, **options: Any) -> JawFit:
    """:func:`fit_jaw` on a :class:`cassi_fit.txy.PelletTrack`'s MNI and MNM pellets, or on
    one of them (``jaw_sensors``: ``"MNI"`` or ``"MNM"``; the other, where the track has
    it at the reference frame, is then predicted: ``JawFit.hidden_predicted``).

    Values flagged by the mistrack detector (``PelletTrack.mistracks``, :mod:`cassi_fit.mistracks`)
    are not used: their frames get status MISTRACKED (values interpolated, as for
    untracked frames, which get INVALID_FRAME). The reference is ``reference_frame`` (an
    index in ``[0, n)`` whose jaw pellets are tracked and not mistracked) or, by default,
    the first frame in which both jaw pellets are tracked and neither is mistracked:
    CASSI's first valid line for the jaw, moved past a mistracked line so that one bad
    value cannot tilt every frame. With one sensor, only that sensor's values count (for
    the reference, the statuses and the mistracks). ``options`` (``solver``,
    ``smoothness``, ...) go to :func:`fit_jaw` with a method alias. Errors name the file.
    """
    from ..pellets import JAW_PELLETS, first_valid_line, pellet_index

    where = str(track.path) if track.path is not None else "<pellet track>"
    sensors = jaw_sensor_set(jaw_sensors)
    cols = [pellet_index(p) for p in sensors]
    tracked = track.frame_valid(sensors)
    flags = track.mistracks.flags  # the track's one detection
    mistracked = flags[:, cols].any(axis=1) & tracked
    usable = tracked & ~mistracked
    n = track.n_frames
    if reference_frame is None:  # the one first-valid-line rule (pellets), for the jaw pellets
        reference_frame = first_valid_line(track, where, pellets=sensors,
                                           mistracked=flags).index
    elif (isinstance(reference_frame, bool) or not isinstance(reference_frame, (int, np.integer))
          or not 0 <= reference_frame < n):
        raise InvalidChoiceError(f"{where}: reference_frame must be a frame index in "
                                 f"[0, {n}), got {reference_frame!r}")
    elif not usable[reference_frame]:
        why = "mistracked" if mistracked[reference_frame] else "untracked"
        raise MissingDataError(f"{where}: jaw pellets {why} in reference frame {reference_frame}")
    both = [pellet_index(p) for p in JAW_PELLETS]
    jaw_points = track.positions[:, both, :]
    reference = jaw_points[reference_frame].copy()
    flagged = flags[reference_frame, both] | ~track.valid[reference_frame, both].all(axis=-1)
    reference[flagged] = np.nan  # a hidden sensor bad there is not predicted
    try:
        fit = fit_jaw(reference, jaw_points, method=method, valid=usable,
                      jaw_sensors=sensors, **options)
    except (MissingDataError, DegenerateGeometryError) as exc:
        raise type(exc)(f"{where}: {exc}") from None
    return replace(fit, status=np.where(mistracked, Status.MISTRACKED, fit.status).astype(
        np.int32), reference_frame=reference_frame)


def learn_jaw_coupling(tracks: Sequence[PelletTrack], sensor: str = "MNI", *,
                       source: str, rad_per_mm_sd: tuple[float, float] = (0.0, 0.0)
                       ) -> JawCoupling:
    """A :class:`JawCoupling` learned from two-sensor recordings: the rotation of the
    per-frame least-squares motion of both jaw pellets ("frame-fit") regressed on
    ``sensor``'s displacement from each recording's reference frame (mm), over every
    track's frames with status OK or PIVOT_UNDEFINED. No intercept: at the reference both
    are 0. ``theta_sd_rad`` is the rms scatter about the line; ``rad_per_mm_sd`` (the
    spread between speakers, which one source cannot measure) and ``source`` (where the
    recordings come from) are the caller's to state.
    """
    from ..pellets import pellet_index

    (sensor,) = jaw_sensor_set(sensor)
    rows, targets = [], []
    for track in tracks:
        fit = jaw_from_track(track, method="frame-fit")
        used = fitted(fit.status)
        p = track.positions[:, pellet_index(sensor)]
        rows.append((p - p[fit.reference_frame])[used])
        targets.append(fit.theta[used])
    d, theta = np.concatenate(rows), np.concatenate(targets)
    if len(theta) < 3:
        raise MissingDataError(f"jaw coupling: {len(theta)} usable frames; need at least 3")
    coef, *_ = np.linalg.lstsq(d, theta, rcond=None)
    scatter = float(np.sqrt(np.sum((theta - d @ coef) ** 2) / (len(theta) - 2)))
    return JawCoupling(sensor, tuple(coef), scatter, rad_per_mm_sd, len(theta), source)
