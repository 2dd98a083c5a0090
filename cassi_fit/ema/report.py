"""What the toolkit did to an articulograph recording: :class:`SensorReport`.

A :class:`~cassi_fit.dataset.Recording` made from an EMA file carries one (its
``sensors``), so that every command can say where its pellets came from: the file's
format, rate and units, the role of each sensor, the head correction with its per-frame
residual, the occlusal frame and its source, and each sensor's distance from the
midsagittal plane. ``to_dict`` gives the JSON-ready summary ``cassi info --json`` prints.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np


def _stats(values: np.ndarray) -> dict[str, float | None]:
    finite = values[np.isfinite(values)]
    if not finite.size:
        return {"median": None, "p95": None, "max": None}
    return {"median": float(np.median(finite)), "p95": float(np.percentile(finite, 95)),
            "max": float(finite.max())}


@dataclass(frozen=True, eq=False)
class SensorReport:
    """An articulograph recording's provenance and corrections.

    Attributes:
        format: the file's format (``est``, ``ag500``, ``ag501``, ``wave``, ``mview``,
            ``array``).
        rate_hz: the sampling rate (Hz).
        units: the file's units and the conversion applied.
        file_axes: the file's axes as documented (or "not stated").
        dims: 2 (midsagittal data) or 3.
        sensor_map: the map used (a built-in name or a TOML file).
        roles: CASSI role -> sensor name, or None for a role no sensor plays.
        extras: sensors with no CASSI role, kept in the track's ``extra_*``.
        references: the head-reference sensors used.
        head_correction: what the references removed, in words.
        head_residual_mm: ``(n,)`` RMS residual of the rigid fit to the references per
            frame (NaN where not fitted).
        head_rotation_deg, head_translation_mm: ``(n,)`` the size of the head motion
            removed per frame (relative to the head frame).
        frames_without_references: frames whose sensors were marked untracked because
            they lacked the references.
        frame_source: how the occlusal frame was found.
        frame_rotation: ``(d, d)`` rows = the toolkit's axes in the head frame.
        frame_origin: ``(d,)`` the origin in the head frame (mm).
        midsagittal_distance_mm: sensor -> median signed distance from the midsagittal
            plane (mm, + toward the subject's left); empty for 2D data.
        bite_plane: the bite-plane recording used, or None.
        notes: what the readers and the conversion decided that a user should know.
        placement: how the occlusal frame was estimated from the data, with its
            uncertainty (:meth:`cassi_fit.ema.placement.Placement.to_dict`), or None.
        head_fits: the per-frame rigid motions of the head correction
            (:class:`cassi_fit.ema.head.RigidFits`: ``R p + t`` takes the file's
            coordinates into the head frame), or None without references.
    """

    format: str
    rate_hz: float
    units: str
    file_axes: str
    dims: int
    sensor_map: str
    roles: Mapping[str, str | None]
    extras: tuple[str, ...]
    references: tuple[str, ...]
    head_correction: str
    head_residual_mm: np.ndarray
    head_rotation_deg: np.ndarray
    head_translation_mm: np.ndarray
    frames_without_references: int
    frame_source: str
    frame_rotation: np.ndarray
    frame_origin: np.ndarray
    midsagittal_distance_mm: Mapping[str, float] = field(default_factory=dict)
    bite_plane: str | None = None
    notes: tuple[str, ...] = ()
    head_fits: object = None  # cassi_fit.ema.head.RigidFits: per frame R, t (device -> head)
    placement: dict | None = None  # how the frame was estimated, with its uncertainty

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary: arrays as median / 95th percentile / max."""
        return {
            "format": self.format,
            "rate_hz": self.rate_hz,
            "units": self.units,
            "file_axes": self.file_axes,
            "dims": self.dims,
            "sensor_map": self.sensor_map,
            "roles": dict(self.roles),
            "extras": list(self.extras),
            "references": list(self.references),
            "head_correction": self.head_correction,
            "head_residual_mm": _stats(self.head_residual_mm),
            "head_rotation_deg": _stats(self.head_rotation_deg),
            "head_translation_mm": _stats(self.head_translation_mm),
            "frames_without_references": self.frames_without_references,
            "frame_source": self.frame_source,
            "frame_rotation": np.round(self.frame_rotation, 6).tolist(),
            "frame_origin_mm": np.round(self.frame_origin, 4).tolist(),
            "midsagittal_distance_mm": {k: round(float(v), 3)
                                        for k, v in self.midsagittal_distance_mm.items()},
            "bite_plane": self.bite_plane,
            "notes": list(self.notes),
            "placement": self.placement,
        }
