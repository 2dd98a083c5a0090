"""``fit_jaw``: one recording's jaw motion by a method object, as a :class:`JawFit`, from
both jaw sensors or from one (the other then predicted)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from jaxtyping import Array, Bool, Float

from .. import jaw
from ..errors import DegenerateGeometryError, InvalidChoiceError, MissingDataError
from ..options import JAW_SENSOR_SETS
from ..status import SolverResult, Status, fitted
from ._kernels import pivot_with_covariance, translation_about
from ._methods import JawMethod, as_method, check_sensors
from ._solvers import Solver

ArrayLike = Array | np.ndarray
#: The jaw sensors, in the jaw code's order (index 0 = MNI, 1 = MNM).
JAW_SENSORS = ("MNI", "MNM")
#: Frames per padding bucket of a recording's jaw fit (:func:`jaw_bucket`): one
#: compilation covers every recording up to 7 s; the padding costs nothing for the closed
#: form, and up to 3x a short recording's fitting time for "frame-fit" (still far below
#: one compilation, 2-3 s a length).
JAW_FRAME_BUCKET = 1024


def jaw_bucket(n: int) -> int:
    """The frames ``n`` frames are padded to for a jaw fit (``fit_jaw(pad_to=...)``): the
    next multiple of :data:`JAW_FRAME_BUCKET`."""
    return JAW_FRAME_BUCKET * max(math.ceil(n / JAW_FRAME_BUCKET), 1)


def jaw_sensor_set(sensors: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """``sensors`` (``"MNI,MNM"``, ``"MNI"``, ``("MNM",)`` ...) as a tuple in the jaw order;
    :class:`InvalidChoiceError` for anything but both jaw sensors or one of them."""
    names = sensors.split(",") if isinstance(sensors, str) else list(sensors)
    names = [str(n).strip().upper() for n in names if str(n).strip()]
    chosen = tuple(n for n in JAW_SENSORS if n in names)
    if len(chosen) != len(names) or len(set(names)) != len(names) or not chosen:
        raise InvalidChoiceError(f"jaw sensors must be one of {', '.join(JAW_SENSOR_SETS)}, "
                                 f"got {sensors!r}")
    return chosen


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
    noise_mm: the pooled pellet-noise estimate ``s`` (NaN for "coupled-rotation", which
    leaves no residual); method, solver: their alias names; reference_frame: the frame used
    as the reference by :func:`jaw_from_track` (None when the caller gave the reference to
    :func:`fit_jaw`). jaw_sensors: the sensors the fit used (``("MNI", "MNM")``, or one);
    hidden_sensor: with one, the other (None otherwise); hidden_predicted (n, 2) mm: where
    the motion puts the hidden sensor, ``R(theta) p_hidden_ref + t`` (None when its
    reference position is unknown or both sensors were used); prior: the prior the motion
    rests on, stated ("" for none; a pivot prior, or a coupling, with its source).
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
    jaw_sensors: tuple[str, ...] = JAW_SENSORS
    hidden_sensor: str | None = None
    hidden_predicted: np.ndarray | None = None
    prior: str = ""

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


def _check_reference(reference, sensors):
    if not np.all(np.isfinite(reference)):
        raise MissingDataError(f"jaw reference: {' or '.join(sensors)} untracked (non-finite) "
                               f"in the reference")
    if len(sensors) == 2 and np.all(reference[0] == reference[1]):
        raise DegenerateGeometryError(
            f"jaw reference: MNI and MNM coincide at {reference[0].tolist()} mm"
        )


def _prepare(reference, current, valid, sensors):
    """Validate; returns (reference (k, 2), safe current (n, k, 2), usable mask, base
    status) of the ``k`` sensors used."""
    reference = np.asarray(reference, dtype=float)
    current = np.asarray(current, dtype=float)
    if reference.shape != (2, 2) or current.ndim != 3 or current.shape[1:] != (2, 2):
        raise ValueError(
            f"jaw data: expected reference (2, 2) and current (n, 2, 2), got "
            f"{reference.shape} and {current.shape}"
        )
    used = [JAW_SENSORS.index(s) for s in sensors]
    reference, current = reference[used], current[:, used]
    _check_reference(reference, sensors)
    n = current.shape[0]
    valid = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
    if valid.shape != (n,):
        raise ValueError(f"jaw data: valid must have shape ({n},), got {valid.shape}")
    if len(used) == 2:
        status = np.asarray(jaw.closed_form_frames(reference, current).status).astype(np.int32)
    else:
        finite = np.isfinite(current).all(axis=(1, 2))
        status = np.where(finite, Status.OK, Status.NON_FINITE).astype(np.int32)
    status = np.where(valid, status, Status.INVALID_FRAME)
    usable = fitted(status)
    if not usable.any():
        raise MissingDataError(f"jaw data: no frame where {' and '.join(sensors)} "
                               f"{'are' if len(used) == 2 else 'is'} tracked")
    safe = np.where(usable[:, None, None], current, reference[None])
    return reference, safe, usable, np.where(usable, 0, status).astype(np.int32)


def _hidden(reference, sensors, params):
    """The hidden sensor's name and predicted path (n, 2) mm (None, None with both)."""
    if len(sensors) == 2:
        return None, None
    (hidden,) = [s for s in JAW_SENSORS if s not in sensors]
    p = np.asarray(reference, float)[JAW_SENSORS.index(hidden)]
    if not np.all(np.isfinite(p)):
        return hidden, None
    c, s = np.cos(params[:, 0]), np.sin(params[:, 0])
    turned = np.stack([c * p[0] + s * p[1], -s * p[0] + c * p[1]], -1)
    return hidden, turned + params[:, 1:]


def _noise_variance(residuals, usable, n_params):
    dof = residuals.shape[1] * int(usable.sum()) - n_params
    return float(np.sum(residuals[usable] ** 2) / dof) if dof > 0 else float("nan")


def _fit_padded(reference, current, method, valid, jaw_sensors, pad_to: int) -> JawFit:
    """:func:`fit_jaw` of ``current (n, 2, 2)`` followed by ``pad_to - n`` untracked frames
    (never usable: they weigh nothing), cut back to the ``n`` given frames."""
    n = np.shape(current)[0]
    padded = np.concatenate([np.asarray(current, float), np.full((pad_to - n, 2, 2), np.nan)])
    use = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
    fit = fit_jaw(reference, padded, method=method, jaw_sensors=jaw_sensors,
                  valid=np.concatenate([use, np.zeros(pad_to - n, bool)]), pad_to=pad_to)
    return replace(fit, **{f.name: getattr(fit, f.name)[:n] for f in fields(fit)
                           if np.ndim(getattr(fit, f.name)) and
                           np.shape(getattr(fit, f.name))[0] == pad_to})


def fit_jaw(
    reference: Float[ArrayLike, "2 2"],
    current: Float[ArrayLike, "n 2 2"],
    *,
    method: JawMethod | str = "closed-form",
    valid: Bool[ArrayLike, " n"] | None = None,
    jaw_sensors: str | tuple[str, ...] = JAW_SENSORS,
    solver: Solver | str | None = None,
    smoothness: float | None = None,
    knot_spacing: int | None = None,
    pad_to: int | None = None,
) -> JawFit:
    """Jaw motion from ``reference`` (2, 2) mm [MNI, MNM] to each frame of ``current``
    (n, 2, 2) mm, by ``method``: an object (:class:`ClosedForm`, :class:`FrameFit`,
    :class:`FixedPivot`, :class:`SmoothPivot`) or its alias; with an alias, ``solver``,
    ``smoothness`` and ``knot_spacing`` are passed on to :func:`jaw_method` (the old call
    form). ``valid`` (n,) bool marks frames to use; the others, and frames with an
    untracked or coincident jaw pellet, get a status and interpolated values.

    ``jaw_sensors``: both (default) or one of ``"MNI"``, ``"MNM"``: the fit then uses that
    sensor alone (the other's columns of ``current`` are not read) and predicts the other
    from its reference position (``JawFit.hidden_predicted``; NaN reference: no
    prediction). With one sensor the rotation is not determined by the data: "closed-form"
    and "frame-fit" refuse, the pivot methods rest on a pivot prior, "coupled-rotation" on
    a coupling learned from two-sensor recordings (``JawFit.prior`` says which).

    Raises :class:`MissingDataError` / :class:`DegenerateGeometryError` when no motion
    can be computed at all (untracked or coincident reference, no usable frame, no rotation
    for a pivot model), :class:`InvalidChoiceError` for a bad method or option, or a
    method that cannot run with the sensors given (with its reason).

    ``pad_to``: fit ``pad_to`` frames, the given ones followed by untracked ones, and
    return the given ones (unchanged: the padding is not usable, so it weighs nothing), so
    that one compilation serves every length up to ``pad_to``. By default the frames'
    bucket, :func:`jaw_bucket` (``n`` up to 1024 frames share one compilation per method:
    a jaw fit over recordings of many lengths compiles once, not once a length); ``pad_to=n``
    fits the given frames alone. A method whose model holds the length
    (``JawMethod.paddable`` False: a frame-fit start given per frame) is not padded.
    """
    method = as_method(method, solver, smoothness, knot_spacing)
    if pad_to is None:
        pad_to = jaw_bucket(np.shape(current)[0])
    if pad_to > np.shape(current)[0] and method.paddable:
        return _fit_padded(reference, current, method, valid, jaw_sensors, pad_to)
    sensors = jaw_sensor_set(jaw_sensors)
    check_sensors(method, sensors)
    full_reference = np.asarray(reference, dtype=float)
    reference, current, usable, base_status = _prepare(reference, current, valid, sensors)
    est = method._estimate(reference, current, usable, sensors)
    s2 = _noise_variance(est.residuals, usable, est.n_params)
    unit = est.unit_cov if est.covariance is None else est.covariance
    scale = 1.0 if est.covariance is not None else s2
    covariance = np.where(usable[:, None, None], scale * unit, 0.0)
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
    hidden, predicted = _hidden(full_reference, sensors, params)
    return JawFit(
        theta=params[:, 0], translation=params[:, 1:], pivot=pivot,
        pivot_defined=defined & usable, residual=np.where(usable, residual, 0.0),
        status=status, solver_result=result, covariance=covariance,
        pivot_covariance=pivot_cov, noise_mm=float(np.sqrt(s2)), method=method.name,
        solver=method.solver_name, jaw_sensors=sensors, hidden_sensor=hidden,
        hidden_predicted=predicted, prior=est.prior,
    )
