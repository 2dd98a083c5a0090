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

The detector's code lives in :mod:`cassi_fit.pellets` (re-exported here), beside the one
first-valid-line rule, which skips lines holding a flagged value.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .errors import MissingDataError
from .pellets import (  # the detector's code lives beside the first-valid-line rule it serves
    JAW_MIN_DEVIATION_MM,
    JAW_PELLETS,
    JAW_ROBUST_SDS,
    MAX_SPEED_MM_S,
    MEDIAN_WINDOW,
    PELLET_NAMES,
    PLAUSIBLE_X_MM,
    PLAUSIBLE_Y_MM,
    MistrackedFirstLineWarning,
    clean_lines,
    detect_mistracks,
    ever_tracked,
    first_clean_line,
    first_valid_line,
    jaw_distance,
    pellet_index,
    running_median,
)
from .txy import PelletTrack

__all__ = [
    "JAW_MIN_DEVIATION_MM", "JAW_ROBUST_SDS", "MAX_SPEED_MM_S", "MEDIAN_WINDOW",
    "PLAUSIBLE_X_MM", "PLAUSIBLE_Y_MM", "QualityReport", "detect_mistracks",
    "quality_report", "running_median",
]


@dataclass(frozen=True)
class QualityReport:
    """Per-file data quality (JSON-ready through :meth:`to_dict`).

    ``valid_fraction`` and ``n_mistracked`` are per pellet (``PELLET_NAMES`` keys): the
    fraction of frames with x and y tracked, and the number of tracked frames flagged by
    :func:`detect_mistracks`. ``all_valid_fraction`` is the fraction of frames with all
    eight pellets tracked. Jaw distances (MNI-MNM, mm) are over frames with both jaw
    pellets tracked and not flagged; None when there are none. ``first_valid_frame`` is
    CASSI's first valid line by the one rule of :func:`cassi_fit.pellets.first_valid_line`
    (every pellet the file ever tracks is tracked and none is mistracked; None if there
    is none) and ``first_jaw_frame`` the same for the jaw pellets alone;
    ``first_complete_frame`` is the paper's line (all tracked, mistracks or not): when it
    differs from ``first_valid_frame``, mistracks moved the reference.
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
    first_complete_frame: int | None = None

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _first(track: PelletTrack, flags: np.ndarray, pellets: tuple[str, ...] | None = None
           ) -> tuple[int | None, int | None]:
    """``(clean, complete)``: the rule's line (None if there is none) and the paper's."""
    import warnings

    cols = np.flatnonzero(ever_tracked(track.valid)) if pellets is None else [
        pellet_index(p) for p in pellets]
    complete, _ = clean_lines(track, cols, flags)
    paper = int(np.argmax(complete)) if complete.any() else None
    with warnings.catch_warnings():  # the report shows the move (first_complete_frame)
        warnings.simplefilter("ignore", MistrackedFirstLineWarning)
        try:
            if pellets is None:
                return first_valid_line(track, mistracked=flags).index, paper
            return first_clean_line(track, pellets, mistracked=flags), paper
        except MissingDataError:
            return None, paper


def quality_report(track: PelletTrack) -> QualityReport:
    """Summarise validity, unmarked mistracks and jaw-distance spread of one track."""
    flags = detect_mistracks(track)
    tracked = track.valid.all(axis=-1)  # (n, 8)
    distance = jaw_distance(track)
    jaw_flag = flags[:, [pellet_index(p) for p in JAW_PELLETS]].any(axis=-1)
    good = distance[np.isfinite(distance) & ~jaw_flag]
    n = max(track.n_frames, 1)
    first, complete = _first(track, flags)
    return QualityReport(
        path=None if track.path is None else str(track.path),
        n_frames=track.n_frames,
        duration_s=track.duration,
        first_valid_frame=first,
        first_jaw_frame=_first(track, flags, JAW_PELLETS)[0],
        valid_fraction={p: float(tracked[:, i].sum() / n) for i, p in enumerate(PELLET_NAMES)},
        all_valid_fraction=float(tracked.all(axis=-1).sum() / n),
        jaw_distance_median_mm=float(np.median(good)) if good.size else None,
        jaw_distance_sd_mm=float(np.std(good)) if good.size else None,
        n_mistracked={p: int(flags[:, i].sum()) for i, p in enumerate(PELLET_NAMES)},
        first_complete_frame=complete,
    )
