"""Data quality of a pellet file: unmarked mistracks and a per-file report.

Real XRMB files mark lost pellets with 1000000 (the validity mask), but some tracking
errors are not marked. :func:`detect_mistracks` flags, per frame and pellet, values that
cannot be true movement. The three tests and their thresholds (mm, s):

1. Range: a position outside the plausible box ``x in [-120, 60]``, ``y in [-90, 60]``
   (the pellet frame; real pellets span about x -65..25, y -35..30).
2. Jumps: a pellet cannot move faster than ``MAX_SPEED_MM_S`` = 500 mm/s (twice the
   fastest real pellet speeds, about 250 mm/s). A value further than one frame's worth of
   that speed (3.4 mm at 145.6 Hz) from the running median of the ``MEDIAN_WINDOW`` = 11
   frames around it is flagged, as is a spike whose jumps in and out both exceed it.
   The median follows smooth motion (it is exact for constant velocity), so only
   isolated excursions of up to five frames stand out. Beside gaps and at the
   file ends, where the window is one-sided, the allowance grows by the speed limit
   times the lag of the window's median time.
3. Jaw: MNI and MNM sit on one rigid bone, so their distance is constant up to noise
   (about 0.3 mm SD). A frame whose distance is further than ``max(5 robust SD, 2 mm)``
   from the median (robust SD = 1.4826 x median absolute deviation) flags both pellets,
   unless tests 1-2 already flag exactly one of them in that frame: then only that one
   (the distance cannot tell which pellet moved; the jump tests can).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .errors import MissingDataError
from .pellets import JAW_PELLETS, PELLET_NAMES, pellet_index
from .txy import PelletTrack, first_valid_frame

PLAUSIBLE_X_MM = (-120.0, 60.0)
PLAUSIBLE_Y_MM = (-90.0, 60.0)
MAX_SPEED_MM_S = 500.0
MEDIAN_WINDOW = 11
JAW_ROBUST_SDS = 5.0
JAW_MIN_DEVIATION_MM = 2.0
_MAD_TO_SD = 1.4826


def _frame_step(track: PelletTrack) -> float:
    """Median time between frames (s); the nominal step for fewer than two frames."""
    if track.n_frames < 2:
        return 6866e-6
    return float(np.median(np.diff(track.times)))


def _out_of_range(track: PelletTrack) -> np.ndarray:
    x, y = track.positions[..., 0], track.positions[..., 1]
    with np.errstate(invalid="ignore"):
        bad_x = (x < PLAUSIBLE_X_MM[0]) | (x > PLAUSIBLE_X_MM[1])
        bad_y = (y < PLAUSIBLE_Y_MM[0]) | (y > PLAUSIBLE_Y_MM[1])
    return bad_x | bad_y


def _distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance over the last axis using the coordinates valid in both; NaN if none."""
    d2 = (a - b) ** 2
    none = np.isnan(d2).all(axis=-1)
    return np.where(none, np.nan, np.sqrt(np.nansum(d2, axis=-1)))


def running_median(values: np.ndarray) -> np.ndarray:
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


def _jumps(track: PelletTrack, speed: float, step_s: float) -> np.ndarray:
    """``(n, 8)`` bool: too far from the running median, or a spike (test 2 above).

    Near gaps and file ends the window is one-sided and its median lags; it then stands
    for the median time of the frames it holds, so a pellet may be ``speed`` times that
    time difference further away (plus one frame's travel).
    """
    positions = track.positions
    n = positions.shape[0]
    tracked = track.valid.any(axis=-1)  # (n, 8)
    times = np.where(tracked, track.times[:, None], np.nan)
    median_time = running_median(times)
    allowed = speed * (step_s + np.abs(track.times[:, None] - median_time))
    with np.errstate(invalid="ignore"):
        far = _distance(positions, running_median(positions)) > allowed
        step = np.full((n + 1, 8), np.nan)
        step[1:n] = _distance(positions[1:], positions[:-1])
        spike = (step[:-1] > speed * step_s) & (step[1:] > speed * step_s)
    return far | spike


def _jaw_distance(track: PelletTrack) -> np.ndarray:
    """``(n,)`` MNI-MNM distance in mm, NaN where either jaw pellet is not fully tracked."""
    a = track.pellet(JAW_PELLETS[0])
    b = track.pellet(JAW_PELLETS[1])
    ok = track.frame_valid(JAW_PELLETS)
    return np.where(ok, np.linalg.norm(np.where(ok[:, None], a - b, 0.0), axis=-1), np.nan)


def _jaw_outliers(distance: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: jaw distance far from its median (test 3 above)."""
    ok = np.isfinite(distance)
    if ok.sum() < 3:
        return np.zeros(distance.shape, bool)
    median = np.median(distance[ok])
    robust_sd = _MAD_TO_SD * np.median(np.abs(distance[ok] - median))
    limit = max(JAW_ROBUST_SDS * robust_sd, JAW_MIN_DEVIATION_MM)
    return ok & (np.abs(np.where(ok, distance, median) - median) > limit)


def detect_mistracks(track: PelletTrack) -> np.ndarray:
    """``(n, 8)`` bool: True where a tracked pellet value cannot be true movement.

    Values marked untracked (1000000) are never flagged here; they are already in
    ``track.valid``. See the module docstring for the three tests and their thresholds.
    """
    flags = _out_of_range(track) | _jumps(track, MAX_SPEED_MM_S, _frame_step(track))
    jaw = _jaw_outliers(_jaw_distance(track))
    cols = [pellet_index(name) for name in JAW_PELLETS]
    one_known = flags[:, cols].sum(axis=-1) == 1  # the jump tests already found the culprit
    flags[:, cols] |= (jaw & ~one_known)[:, None]
    return flags & track.valid.any(axis=-1)


@dataclass(frozen=True)
class QualityReport:
    """Per-file data quality (JSON-ready through :meth:`to_dict`).

    ``valid_fraction`` and ``n_mistracked`` are per pellet (``PELLET_NAMES`` keys): the
    fraction of frames with x and y tracked, and the number of tracked frames flagged by
    :func:`detect_mistracks`. ``all_valid_fraction`` is the fraction of frames with all
    eight pellets tracked. Jaw distances (MNI-MNM, mm) are over frames with both jaw
    pellets tracked and not flagged; None when there are none. ``first_valid_frame`` is
    CASSI's first valid line by the one rule of :func:`cassi_fit.pellets.first_valid_line`
    (every pellet the file ever tracks is tracked; None if there is none) and
    ``first_jaw_frame`` the first with both jaw pellets tracked.
    """

    path: str | None
    n_frames: int
    duration_s: float
    first_valid_frame: int | None
    first_jaw_frame: int | None
    valid_fraction: dict[str, float]
    all_valid_fraction: float
    jaw_distance_median_mm: float | None
    jaw_distance_sd_mm: float | None
    n_mistracked: dict[str, int]

    def to_dict(self) -> dict:
        return asdict(self)


def _first(track: PelletTrack, pellets=None) -> int | None:
    """``first_valid_frame`` (the pellets module's rule by default), None if there is none."""
    try:
        return first_valid_frame(track, pellets)
    except MissingDataError:
        return None


def quality_report(track: PelletTrack) -> QualityReport:
    """Summarise validity, unmarked mistracks and jaw-distance spread of one track."""
    flags = detect_mistracks(track)
    tracked = track.valid.all(axis=-1)  # (n, 8)
    distance = _jaw_distance(track)
    jaw_flag = flags[:, [pellet_index(p) for p in JAW_PELLETS]].any(axis=-1)
    good = distance[np.isfinite(distance) & ~jaw_flag]
    n = max(track.n_frames, 1)
    return QualityReport(
        path=None if track.path is None else str(track.path),
        n_frames=track.n_frames,
        duration_s=track.duration,
        first_valid_frame=_first(track),
        first_jaw_frame=_first(track, JAW_PELLETS),
        valid_fraction={p: float(tracked[:, i].sum() / n) for i, p in enumerate(PELLET_NAMES)},
        all_valid_fraction=float(tracked.all(axis=-1).sum() / n),
        jaw_distance_median_mm=float(np.median(good)) if good.size else None,
        jaw_distance_sd_mm=float(np.std(good)) if good.size else None,
        n_mistracked={p: int(flags[:, i].sum()) for i, p in enumerate(PELLET_NAMES)},
    )
