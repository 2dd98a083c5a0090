"""Data quality of a pellet file: a per-file report of validity and mistracks.

Real XRMB files mark lost pellets with 1000000 (the validity mask); tracking errors that
are not marked are found by the mistrack detector (:mod:`cassi_fit.mistracks`, where its
tests, thresholds and reasons are documented). A track's detection is computed once (``PelletTrack.mistracks``)
and this report reads it, as do the first valid line, ``gaps`` and the jaw fit.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np

from .errors import MissingDataError
from .mistracks import (
    mistrack_report,
)
from .pellets import (
    JAW_PELLETS,
    PELLET_NAMES,
    MistrackedFirstLineWarning,
    clean_lines,
    ever_tracked,
    first_valid_line,
    jaw_distance,
    pellet_index,
)
from .txy import PelletTrack

__all__ = ["QualityReport", "quality_report"]


@dataclass(frozen=True)
class QualityReport:
    """Per-file data quality (JSON-ready through :meth:`to_dict`).

    ``valid_fraction`` and ``n_mistracked`` are per pellet (``PELLET_NAMES`` keys): the
    fraction of frames with x and y tracked, and the number of tracked frames flagged by
    the mistrack detector; ``mistrack_reasons`` says why, per pellet and reason
    (``{pellet: {reason label: values}}``, :class:`~cassi_fit.mistracks.Reason`; a value
    with two reasons counts under both). ``all_valid_fraction`` is the fraction of frames
    with every pellet the file ever tracks tracked (the set ``first_valid_frame``'s rule
    reads, :func:`cassi_fit.pellets.ever_tracked`): all eight where each is tracked
    somewhere, as in XRMB; in an articulograph file the pellets its sensors stand for (one
    jaw sensor, three tongue sensors: six). ``never_tracked`` names the pellets left out
    (``PELLET_NAMES`` order; empty when all eight are tracked somewhere); a file that
    tracks none has 0. Jaw distances (MNI-MNM, mm) are over frames with both
    jaw pellets tracked and not flagged; None when there are none. ``first_valid_frame``
    is CASSI's first valid line by the one rule of
    :func:`cassi_fit.pellets.first_valid_line` (every pellet the file ever tracks is
    tracked and none is mistracked; None if there is none) and ``first_jaw_frame`` the
    same for the jaw pellets alone; ``first_complete_frame`` is the paper's line (all
    tracked, mistracks or not): when it differs from ``first_valid_frame``, mistracks
    moved the reference.
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
    mistrack_reasons: dict[str, dict[str, int]] | None = None
    never_tracked: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _first(track: PelletTrack, flags: np.ndarray, pellets: tuple[str, ...] | None = None
           ) -> tuple[int | None, int | None]:
    """``(clean, complete)``: the rule's line (None if there is none) and the paper's."""
    cols = np.flatnonzero(ever_tracked(track.valid)) if pellets is None else [
        pellet_index(p) for p in pellets]
    complete, _ = clean_lines(track, cols, flags)
    paper = int(np.argmax(complete)) if complete.any() else None
    with warnings.catch_warnings():  # the report shows the move (first_complete_frame)
        warnings.simplefilter("ignore", MistrackedFirstLineWarning)
        try:
            return first_valid_line(track, pellets=pellets, mistracked=flags).index, paper
        except MissingDataError:
            return None, paper


def quality_report(track: PelletTrack) -> QualityReport:
    """Summarise validity, unmarked mistracks (with their reasons) and the jaw-distance
    spread of one track (its one mistrack detection, ``track.mistracks``)."""
    report = mistrack_report(track)
    flags = report.flags
    tracked = track.valid.all(axis=-1)  # (n, 8)
    ever = ever_tracked(track.valid)  # (8,): the pellets the file tracks on some frame
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
        all_valid_fraction=float(tracked[:, ever].all(axis=-1).sum() / n) if ever.any() else 0.0,
        jaw_distance_median_mm=float(np.median(good)) if good.size else None,
        jaw_distance_sd_mm=float(np.std(good)) if good.size else None,
        n_mistracked={p: int(flags[:, i].sum()) for i, p in enumerate(PELLET_NAMES)},
        first_complete_frame=complete,
        mistrack_reasons=report.counts(),
        never_tracked=tuple(p for p, e in zip(PELLET_NAMES, ever, strict=True) if not e),
    )
