"""Truth-free diagnostics of a jaw fit on a real recording."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from jaxtyping import Array, Float

from ..status import fitted
from ._fit import JawFit

ArrayLike = Array | np.ndarray

#: The anatomically plausible region for a jaw pivot, in the pellet frame (origin at the
#: upper incisor tip, +x forward, +y up; mm). The mandibular condyle sits about 90-100 mm
#: behind and 20-30 mm above the incisor tip (docs/JAW.md; /work/shared/FACE_MODEL_NOTES.md;
#: the synthetic subjects draw it there too); the margin of 30 mm on every side covers
#: speakers' sizes, the condyle's forward-downward slide along the articular eminence
#: during opening (up to 10-20 mm), and effective rotation centres found in speech data
#: below and in front of the condyle (Edwards & Harris 1990, J Speech Hear Res 33:550-562;
#: Ostry, Vatikiotis-Bateson & Gribble 1997, JSLHR 40:1341-1351).
PLAUSIBLE_PIVOT_X_MM = (-100.0 - 30.0, -90.0 + 30.0)
PLAUSIBLE_PIVOT_Y_MM = (20.0 - 30.0, 30.0 + 30.0)


@dataclass(frozen=True)
class JawDiagnostics:
    """Truth-free checks of one jaw fit on a real recording (mm; fractions in [0, 1]).

    frames_used: frames with status OK or PIVOT_UNDEFINED. jaw_distance_sd_mm /
    jaw_distance_range_mm: SD and range (max - min) of the MNI-MNM distance over those
    frames: the rigid-body residual of the data (a rigid jaw keeps it constant; pellet
    noise of ``s`` mm gives an SD of about ``s``). residual_median_mm: the median rms
    pellet misfit of the method. pivot_iqr_x_mm / pivot_iqr_y_mm: interquartile range of
    the pivot over frames where it is defined (0 for "fixed-pivot"; many mm for the
    closed form at small angles). pivot_plausible_fraction: fraction of used frames whose
    pivot is defined and inside ``PLAUSIBLE_PIVOT_X_MM`` x ``PLAUSIBLE_PIVOT_Y_MM``.
    jaw_sensors: the sensors the fit used (``"MNI,MNM"``, ``"MNI"``, ``"MNM"``); prior: the
    prior the fit rests on (``JawFit.prior``). hidden_error_median_mm / _p95_mm: with one
    sensor, where the recording has the other, the distance between its prediction and
    its measured position over the used frames where it is tracked (a held-out check;
    NaN otherwise).
    """

    method: str
    frames_used: int
    jaw_distance_sd_mm: float
    jaw_distance_range_mm: float
    residual_median_mm: float
    pivot_iqr_x_mm: float
    pivot_iqr_y_mm: float
    pivot_plausible_fraction: float
    jaw_sensors: str = "MNI,MNM"
    prior: str = ""
    hidden_error_median_mm: float = float("nan")
    hidden_error_p95_mm: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        """The fields as a table row."""
        return dict(self.__dict__)


def jaw_diagnostics(fit: JawFit, current: Float[ArrayLike, "n 2 2"]) -> JawDiagnostics:
    """:class:`JawDiagnostics` of ``fit`` on its data ``current`` (n, 2, 2) mm [MNI, MNM]
    (with one sensor, the other's columns may be NaN)."""
    current = np.asarray(current, float)
    used = fitted(fit.status)
    if current.shape != (len(used), 2, 2):
        raise ValueError(f"jaw diagnostics: current must be ({len(used)}, 2, 2), "
                         f"got {current.shape}")
    distance = np.linalg.norm(current[used, 0] - current[used, 1], axis=-1)
    distance = distance[np.isfinite(distance)]
    defined = used & fit.pivot_defined
    pivot = fit.pivot[defined]

    def iqr(x):
        return float(np.subtract(*np.percentile(x, [75, 25]))) if x.size else float("nan")

    inside = ((pivot[:, 0] >= PLAUSIBLE_PIVOT_X_MM[0]) & (pivot[:, 0] <= PLAUSIBLE_PIVOT_X_MM[1])
              & (pivot[:, 1] >= PLAUSIBLE_PIVOT_Y_MM[0]) & (pivot[:, 1] <= PLAUSIBLE_PIVOT_Y_MM[1]))
    n_used = int(used.sum())
    hidden = (float("nan"), float("nan"))
    if fit.hidden_predicted is not None:
        measured = current[:, ("MNI", "MNM").index(fit.hidden_sensor)]
        seen = used & np.isfinite(measured).all(axis=1)
        if seen.any():
            error = np.linalg.norm(fit.hidden_predicted[seen] - measured[seen], axis=1)
            hidden = (float(np.median(error)), float(np.percentile(error, 95)))
    return JawDiagnostics(
        method=fit.method, frames_used=n_used,
        jaw_distance_sd_mm=float(np.std(distance)) if distance.size else float("nan"),
        jaw_distance_range_mm=float(np.ptp(distance)) if distance.size else float("nan"),
        residual_median_mm=float(np.median(fit.residual[used])) if n_used else float("nan"),
        pivot_iqr_x_mm=iqr(pivot[:, 0]), pivot_iqr_y_mm=iqr(pivot[:, 1]),
        pivot_plausible_fraction=float(inside.sum() / n_used) if n_used else 0.0,
        jaw_sensors=",".join(fit.jaw_sensors), prior=fit.prior,
        hidden_error_median_mm=hidden[0], hidden_error_p95_mm=hidden[1],
    )
