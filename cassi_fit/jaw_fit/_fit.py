"""``fit_jaw``: one recording's jaw motion by a method object, as a :class:`JawFit`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Array, Bool, Float

from .. import jaw
from ..errors import DegenerateGeometryError, MissingDataError
from ..status import SolverResult, Status
from ._methods import JawMethod, as_method, pivot_with_covariance, translation_about
from ._solvers import Solver

ArrayLike = Array | np.ndarray


@dataclass(frozen=True)
class JawFit:
    """One recording's jaw motion, per frame (``n`` frames); numpy arrays.

    theta (n,) rad, opening positive; translation (n, 2) mm, ``p' = R(theta) p + t``
    from the reference jaw; pivot (n, 2) mm: the fixed point of the frame's motion (for
    "fixed-pivot" the recording's pivot, for "smooth-pivot" the pivot path), (0, 0) where
    undefined; pivot_defined (n,) bool; residual (n,) mm, rms pellet misfit of the frame;
    status (n,) int, a :class:`cassi_fit.status.Status` (OK, PIVOT_UNDEFINED, DEGENERATE,
    NON_FINITE, INVALID_FRAME (values interpolated), NOT_CONVERGED, MISTRACKED; its word is
    ``Status(code).label``); solver_result (n,) int, a
    :class:`cassi_fit.status.SolverResult`: how the solve of that frame (per-frame methods)
    or of the recording (pivot methods) ended, SUCCESSFUL for the closed form and for frames
    not fitted; covariance (n, 3, 3) of ``(theta, tx, ty)`` (rad, mm) given the frame's
    data; pivot_covariance (n, 2, 2) mm^2 for the uncertainty ellipse (inf where undefined);
    noise_mm: the pooled pellet-noise estimate ``s``; method, solver: their alias names;
    reference_frame: the frame used as the reference by :func:`jaw_from_track` (None when
    the caller gave the reference to :func:`fit_jaw`).
    """

    theta: np.ndarray
    translation: np.ndarray
    pivot: np.ndarray
    pivot_defined: np.ndarray
    residual: np.ndarray
    status: np.ndarray
    solver_result: np.ndarray
    covariance: np.ndarray
    pivot_covariance: np.ndarray
    noise_mm: float
    method: str
    solver: str
    reference_frame: int | None = None

    @property
    def converged(self) -> bool:
        """Every solve reported success (``solver_result`` all SUCCESSFUL)."""
        return bool(np.all(self.solver_result == SolverResult.SUCCESSFUL))

    @property
    def failure(self) -> SolverResult | None:
        """The most frequent way the solve failed (None when it converged)."""
        failed = self.solver_result[self.solver_result != SolverResult.SUCCESSFUL]
        return None if failed.size == 0 else SolverResult(int(np.bincount(failed).argmax()))


def _interpolate(values, usable):
    """Fill unusable frames of ``values`` (n, ...) by linear interpolation over frame index
    (held constant beyond the ends)."""
    frames = np.arange(values.shape[0])
    flat = values.reshape(values.shape[0], -1).copy()
    for col in range(flat.shape[1]):
        flat[:, col] = np.interp(frames, frames[usable], flat[usable, col])
    return flat.reshape(values.shape)


def _check_reference(reference):
    if not np.all(np.isfinite(reference)):
        raise MissingDataError("jaw reference: MNI or MNM untracked (non-finite) in the reference")
    if np.all(reference[0] == reference[1]):
        raise DegenerateGeometryError(
            f"jaw reference: MNI and MNM coincide at {reference[0].tolist()} mm"
        )


def _prepare(reference, current, valid):
    """Validate; returns (reference, safe current, usable mask, base status)."""
    reference = np.asarray(reference, dtype=float)
    current = np.asarray(current, dtype=float)
    if reference.shape != (2, 2) or current.ndim != 3 or current.shape[1:] != (2, 2):
        raise ValueError(
            f"jaw data: expected reference (2, 2) and current (n, 2, 2), got "
            f"{reference.shape} and {current.shape}"
        )
    _check_reference(reference)
    n = current.shape[0]
    valid = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
    if valid.shape != (n,):
        raise ValueError(f"jaw data: valid must have shape ({n},), got {valid.shape}")
    status = np.asarray(jaw.closed_form_frames(reference, current).status).astype(np.int32)
    status = np.where(valid, status, Status.INVALID_FRAME)
    usable = status <= Status.PIVOT_UNDEFINED
    if not usable.any():
        raise MissingDataError("jaw data: no frame where both jaw pellets are tracked")
    safe = np.where(usable[:, None, None], current, reference[None])
    return reference, safe, usable, np.where(usable, 0, status).astype(np.int32)


def _noise_variance(residuals, usable, n_params):
    dof = residuals.shape[1] * int(usable.sum()) - n_params
    return float(np.sum(residuals[usable] ** 2) / dof) if dof > 0 else 0.0


def fit_jaw(
    reference: Float[ArrayLike, "2 2"],
    current: Float[ArrayLike, "n 2 2"],
    *,
    method: JawMethod | str = "closed-form",
    valid: Bool[ArrayLike, " n"] | None = None,
    solver: Solver | str | None = None,
    smoothness: float | None = None,
    knot_spacing: int | None = None,
) -> JawFit:
    """Jaw motion from ``reference`` (2, 2) mm [MNI, MNM] to each frame of ``current``
    (n, 2, 2) mm, by ``method``: an object (:class:`ClosedForm`, :class:`FrameFit`,
    :class:`FixedPivot`, :class:`SmoothPivot`) or its alias; with an alias, ``solver``,
    ``smoothness`` and ``knot_spacing`` are passed on to :func:`jaw_method` (the old call
    form). ``valid`` (n,) bool marks frames to use; the others, and frames with an
    untracked or coincident jaw pellet, get a status and interpolated values.
    Raises :class:`MissingDataError` / :class:`DegenerateGeometryError` when no motion
    can be computed at all (untracked or coincident reference, no usable frame, no rotation
    for a pivot model), :class:`InvalidChoiceError` for a bad method or option.
    """
    method = as_method(method, solver, smoothness, knot_spacing)
    reference, current, usable, base_status = _prepare(reference, current, valid)
    est = method._estimate(reference, current, usable)
    s2 = _noise_variance(est.residuals, usable, est.n_params)
    covariance = np.where(usable[:, None, None], s2 * est.unit_cov, 0.0)
    params = _interpolate(est.params, usable)
    if est.path is None:
        pivot, defined, pivot_cov = (
            np.asarray(a) for a in pivot_with_covariance(params, covariance)
        )
        pivot = np.where(defined[:, None], pivot, 0.0)
    else:
        pivot, defined = np.asarray(est.path, float), np.ones(len(usable), bool)
        pivot_cov = s2 * np.asarray(est.unit_pivot_cov)
        params[:, 1:] = np.asarray(translation_about(params[:, 0], pivot))
    result = np.where(usable, est.result, SolverResult.SUCCESSFUL).astype(np.int32)
    status = np.where(defined, Status.OK, Status.PIVOT_UNDEFINED)
    status = np.where(result == SolverResult.SUCCESSFUL, status, Status.NOT_CONVERGED)
    status = np.where(usable, status, base_status).astype(np.int32)
    k = est.residuals.shape[1] // 2
    residual = np.sqrt(np.sum(est.residuals**2, axis=1) / k)  # rms over the pellets used
    return JawFit(
        theta=params[:, 0], translation=params[:, 1:], pivot=pivot,
        pivot_defined=defined & usable, residual=np.where(usable, residual, 0.0),
        status=status, solver_result=result, covariance=covariance,
        pivot_covariance=pivot_cov, noise_mm=float(np.sqrt(s2)), method=method.name,
        solver=method.solver_name,
    )
