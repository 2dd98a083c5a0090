"""The jaw methods as objects (equinox Modules), each with its compiled kernel.

A method's ``_estimate(reference, current, usable, sensors)`` gets the reference of the jaw
sensors used (k, 2) mm (k = 2: [MNI, MNM]; k = 1: the one sensor named in ``sensors``), the
frames (n, k, 2) mm (unusable frames already replaced by the reference) and the usable mask
(n,), and returns an :class:`Estimate`: per-frame motions, residuals, unit covariances and
solver results. :func:`cassi_fit.jaw_fit.fit_jaw` turns that into a ``JawFit``. Every
method states how many jaw sensors it can use (``jaw_sensors_needed``) and, where it needs
both, why (``needs_both``): :func:`check_sensors` refuses with that reason.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Bool, Float

from .. import jaw
from ..errors import DegenerateGeometryError, InvalidChoiceError, MissingDataError
from ..options import ALL_JAW_METHODS, check_choice
from ..status import SolverResult
from ._kernels import (
    about_pivot_params,
    closed_form_kernel,
    fixed_pivot_kernel,
    frame_fit_kernel,
    procrustes_kernel,
    smooth_pivot_kernel,
)
from ._priors import (
    DEFAULT_COUPLINGS,
    PIVOT_FROM_DATA,
    POPULATION_CONDYLE,
    PRIOR_NOISE_MM,
    JawCoupling,
    PivotPrior,
)
from ._solve import as_solver
from ._solvers import LevenbergMarquardt, Solver

DEFAULT_KNOT_SPACING = 16  # frames (about 0.11 s at 145.6 Hz) between pivot-path knots
_OK = int(SolverResult.SUCCESSFUL)


class Estimate(NamedTuple):
    """What a method found, per frame (numpy)."""

    params: np.ndarray  # (n, 3) theta, tx, ty
    residuals: np.ndarray  # (n, 2 k) mm
    unit_cov: np.ndarray  # (n, 3, 3)
    result: np.ndarray  # (n,) SolverResult codes
    n_params: int
    path: np.ndarray | None = None  # (n, 2) pivot path of the pivot models
    unit_pivot_cov: np.ndarray | None = None  # (n, 2, 2)
    prior: str = ""  # the prior the motion rests on, stated (JawFit.prior)
    covariance: np.ndarray | None = None  # (n, 3, 3): absolute, instead of s^2 unit_cov


# ---------------------------------------------------------------------- helpers
def initial_pivot(reference: np.ndarray, current: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Linear least squares for ``q`` in ``t_k = (I - R_k) q`` from Procrustes motions.

    ``(I - R)^T (I - R) = (2 - 2 cos theta) I``, so frames weigh in by their rotation.
    """
    m = jaw.procrustes_frames(reference, current)
    theta, t = np.asarray(m.theta)[usable], np.asarray(m.translation)[usable]
    gain = np.sum(2.0 - 2.0 * np.cos(theta))
    if gain == 0.0:
        raise DegenerateGeometryError("jaw data: the jaw never rotates, so no pivot exists")
    c, s = np.cos(theta), np.sin(theta)
    # (I - R)^T t with R = [[c, s], [-s, c]]
    rhs = np.stack([(1 - c) * t[:, 0] + s * t[:, 1], -s * t[:, 0] + (1 - c) * t[:, 1]], -1)
    return rhs.sum(axis=0) / gain


#: The step budget of the pivot methods' default solver: their pivot can lie in a long,
#: shallow valley (one jaw sensor; or a jaw that translates as it turns, as real ones do),
#: where Levenberg-Marquardt reaches the answer but crawls to its convergence test; their
#: steps are cheap (a few parameters). The per-frame fit keeps ``DEFAULT_MAX_STEPS``.
PIVOT_MAX_STEPS = 1000


def _optional_solver(solver):
    """None (the method's default), or ``solver`` as a :class:`Solver` (objects or aliases)."""
    return None if solver is None else as_solver(solver)


def _default_solver(method, max_steps: int | None = None) -> Solver:
    """The method's solver, else :class:`LevenbergMarquardt` (with ``max_steps``, if given)."""
    if method.solver is not None:
        return method.solver
    return LevenbergMarquardt() if max_steps is None else LevenbergMarquardt(max_steps=max_steps)


def _optional_array(shape_doc):
    def convert(value):
        return None if value is None else np.asarray(value, dtype=float)

    convert.__doc__ = shape_doc
    return convert


def _prior_text(prior, path, usable):
    """The prior, stated, and how far the fitted pivot (median over the usable frames) lies
    from its mean in SDs: far means the data disagree with the prior (a jaw that translates
    more than a rotation about that pivot explains)."""
    if not prior.informative:
        return prior.describe()
    fitted = np.median(np.asarray(path)[usable], axis=0)
    z = float(np.sqrt(np.sum(((fitted - prior.mean_mm) / np.asarray(prior.sd_mm)) ** 2)))
    return (f"{prior.describe()}; fitted pivot ({fitted[0]:.1f}, {fitted[1]:.1f}) mm, "
            f"{z:.1f} SD from the prior")


def _pivot_estimate(reference, current, usable, path, unit_pivot_cov, result, n_extra, prior):
    params, unit_cov, res = (np.asarray(a) for a in about_pivot_params(
        reference, current, np.asarray(path, _dtype_of(reference))))
    return Estimate(params, res, unit_cov, np.full(len(usable), int(result), np.int32),
                    int(usable.sum()) + n_extra, path, unit_pivot_cov,
                    _prior_text(prior, path, usable))


def _knots_reached(usable: np.ndarray, spacing: int, m: int) -> np.ndarray:
    """(m,) bool: the knots of a path through ``m`` knots every ``spacing`` frames that a
    usable frame's pivot depends on (frame ``k`` on knots ``k // spacing`` and the next).
    The others, before the first usable frame and after the last, carry no data: the path's
    smoothness alone sets them, so they are not its parameters, and untracked frames
    appended to a recording (``fit_jaw(pad_to=...)``) leave its fit unchanged."""
    frames = np.flatnonzero(usable)
    reached = np.zeros(m, bool)
    if frames.size == 0:
        reached[:] = True
    else:
        reached[frames[0] // spacing: frames[-1] // spacing + 2] = True
    return reached


def _pivot_prior(method, k: int) -> PivotPrior:
    """The method's prior, else the sensor count's default: none with both sensors, the
    population condyle with one."""
    if method.pivot_prior is not None:
        return method.pivot_prior
    return PIVOT_FROM_DATA if k == 2 else POPULATION_CONDYLE


def _start_pivot(method, prior, reference, current, usable):
    """The initial pivot: the method's ``start``, else from the Procrustes motions (both
    sensors), else the prior's mean (one sensor; the population condyle without one)."""
    if method.start is not None:
        return method.start
    if reference.shape[0] == 2:
        return initial_pivot(reference, current, usable)
    return np.asarray((prior if prior.informative else POPULATION_CONDYLE).mean_mm)


def _dtype_of(reference) -> np.dtype:
    """``jnp.asarray(reference).dtype`` (JAX's dtype for it, float64 or float32) without
    making the array: in a new process that is a compiled conversion (with the compilation
    cache's look-up, milliseconds) for a dtype alone. The kernels' array arguments below
    are numpy arrays of that dtype for the same reason: the exported kernel (or
    ``eqx.filter_jit``) takes them as it took JAX's, the same values and types."""
    if isinstance(reference, np.ndarray):
        return jax.dtypes.canonicalize_dtype(reference.dtype)
    return jnp.asarray(reference).dtype


def _prior_arrays(prior, dtype, noise_mm=PRIOR_NOISE_MM):
    return (np.asarray(prior.mean_mm, dtype), np.asarray(prior.weight(noise_mm), dtype))


def effective_noise(reference: np.ndarray, current: np.ndarray, usable: np.ndarray,
                    path: np.ndarray) -> float:
    """The data's noise for weighing them against a prior (mm per coordinate): the rms of
    the residuals about the pivot ``path`` (n, 2), inflated by ``(1 + rho) / (1 - rho)``
    for their correlation ``rho`` between consecutive usable frames (an AR(1) series of
    ``n`` values holds about ``n (1 - rho) / (1 + rho)`` independent ones)."""
    _, _, res = about_pivot_params(reference, current,
                                    np.asarray(path, _dtype_of(reference)))
    res = np.asarray(res)[usable]
    power = float(np.mean(res**2))
    if res.shape[0] < 3 or power == 0.0:
        return max(np.sqrt(power), PRIOR_NOISE_MM)
    rho = float(np.sum(res[1:] * res[:-1]) / np.sum(res**2))
    rho = min(max(rho, 0.0), 1.0 - 1.0 / res.shape[0])
    return float(np.sqrt(power * (1.0 + rho) / (1.0 - rho)))


# ---------------------------------------------------------------------- methods
_TWO_REASON = ("with one sensor the rotation is not determined by the data (one point's "
               "position fixes two of a rigid motion's three parameters); use fixed-pivot "
               "or smooth-pivot (with a pivot prior) or coupled-rotation")


class JawMethod(eqx.Module):
    """A jaw-motion method: an object passed to :func:`cassi_fit.jaw_fit.fit_jaw` as
    ``method=``; ``name`` is its command-line alias (:data:`cassi_fit.options.ALL_JAW_METHODS`).
    ``jaw_sensors_needed``: the numbers of jaw sensors it runs with; ``needs_both``: why
    it cannot run with one (the refusal's reason)."""

    name: ClassVar[str]
    jaw_sensors_needed: ClassVar[tuple[int, ...]] = (2,)
    needs_both: ClassVar[str] = _TWO_REASON
    #: whether untracked frames appended after the last leave the fit of the others
    #: unchanged (``fit_jaw(pad_to=...)``)
    paddable: ClassVar[bool] = True

    @abc.abstractmethod
    def _estimate(self, reference, current, usable, sensors) -> Estimate:
        """Per-frame motion of ``current`` (usable frames filled with the reference)."""

    @property
    def solver_name(self) -> str:
        """What ``JawFit.solver`` reports."""
        return _default_solver(self).name


class ClosedForm(JawMethod):
    """The paper's Eqs 1-3, 6-7 in the numerically sound form, per frame; no solver."""

    name: ClassVar[str] = "closed-form"

    @property
    def solver_name(self) -> str:
        """``"closed-form"`` (no solver)."""
        return "closed-form"

    needs_both: ClassVar[str] = ("the closed form (Eqs 1-3) turns the line through the two "
                                 "jaw pellets; " + _TWO_REASON)

    def _estimate(self, reference, current, usable, sensors):
        params, res, unit_cov = (np.asarray(a) for a in closed_form_kernel(reference, current))
        return Estimate(params, res, unit_cov, np.full(len(usable), _OK, np.int32),
                        3 * int(usable.sum()))


class FrameFit(JawMethod):
    """Rotation + translation fitted to both pellets, per frame (vmapped).

    The two-point rigid problem has a closed-form least-squares solution (2D Procrustes:
    theta turns the centred reference onto the centred frame, t maps centroid to centroid;
    :func:`cassi_fit.jaw.procrustes`), with its covariance from the Gauss-Newton normal
    matrix at the solution: that is what runs by default (``JawFit.solver`` =
    ``"procrustes"``). Given a ``solver`` or a ``start``, the fit iterates instead, per
    frame, from ``start`` (None: the Procrustes motion) with ``solver`` (None:
    :class:`LevenbergMarquardt`): for the solver comparison, and as a check of the closed
    form. start: the initial motion ``(theta rad, tx mm, ty mm)``, (3,) for every frame or
    (n, 3).
    """

    solver: Solver | None = eqx.field(default=None, converter=_optional_solver)
    start: Float[np.ndarray, "*n 3"] | None = eqx.field(
        default=None, converter=_optional_array("(3,) or (n, 3)"))

    name: ClassVar[str] = "frame-fit"

    @property
    def paddable(self) -> bool:  # type: ignore[override]
        """A start given per frame, (n, 3), holds the length: not padded."""
        return self.start is None or np.ndim(self.start) < 2

    @property
    def iterative(self) -> bool:
        """Whether the fit iterates (a solver or a start given) or is the closed form."""
        return self.solver is not None or self.start is not None

    @property
    def solver_name(self) -> str:
        """``"procrustes"`` (the closed form) or the iterating solver's alias."""
        return _default_solver(self).name if self.iterative else "procrustes"

    def _estimate(self, reference, current, usable, sensors):
        n = current.shape[0]
        if not self.iterative:
            params, res, unit_cov = (np.asarray(a) for a in procrustes_kernel(reference,
                                                                                current))
            return Estimate(params, res, unit_cov, np.full(n, _OK, np.int32),
                            3 * int(usable.sum()))
        start = None if self.start is None else np.asarray(
            np.broadcast_to(self.start, (n, 3)), _dtype_of(reference))
        params, res, result, unit_cov = (np.asarray(a) for a in frame_fit_kernel(
            _default_solver(self), reference, current, start))
        result = np.where(usable, result, _OK).astype(np.int32)
        return Estimate(params, res, unit_cov, result, 3 * int(usable.sum()))


class FixedPivot(JawMethod):
    """Parke's fixed pivot: one pivot for the recording, one angle per frame (projected out).

    solver: a solver object or an alias (None: :class:`LevenbergMarquardt` with
    ``PIVOT_MAX_STEPS`` steps). start: None (linear least squares on the Procrustes motions,
    ``t_k = (I - R_k) q``; with one sensor the prior's mean) or the initial pivot (2,) mm.
    pivot_prior: a :class:`PivotPrior` added as residuals; None: none with both jaw sensors,
    :data:`POPULATION_CONDYLE` with one (the sensor's short arc alone fixes the pivot
    badly, or not at all: a free one-sensor pivot may run off to infinity, where the motion
    is a translation); :data:`PIVOT_FROM_DATA`: none, explicitly.
    """

    solver: Solver | None = eqx.field(default=None, converter=_optional_solver)
    start: Float[np.ndarray, "2"] | None = eqx.field(
        default=None, converter=_optional_array("(2,) mm"))
    pivot_prior: PivotPrior | None = None

    name: ClassVar[str] = "fixed-pivot"
    jaw_sensors_needed: ClassVar[tuple[int, ...]] = (1, 2)

    def _estimate(self, reference, current, usable, sensors):
        prior = _pivot_prior(self, reference.shape[0])
        pivot0 = _start_pivot(self, prior, reference, current, usable)
        dtype = _dtype_of(reference)
        n = current.shape[0]

        solver = _default_solver(self, PIVOT_MAX_STEPS)

        def solve_with(noise_mm, start):
            return fixed_pivot_kernel(
                solver, reference, current, usable.astype(float), np.asarray(start, dtype),
                _prior_arrays(prior, dtype, noise_mm))

        pivot, result, jac = solve_with(PRIOR_NOISE_MM, pivot0)
        if prior.informative:  # weigh the data by their independent information
            noise = effective_noise(reference, current, usable, np.broadcast_to(pivot, (n, 2)))
            pivot, result, jac = solve_with(noise, pivot)
        jac = np.asarray(jac)
        path = np.broadcast_to(np.asarray(pivot), (n, 2))
        unit = np.broadcast_to(np.linalg.pinv(jac.T @ jac), (n, 2, 2))
        return _pivot_estimate(reference, current, usable, path, unit, result, 2, prior)

    def _with_noise(self, reference, current, usable, prior):
        """The posterior pivot (2,) and the effective noise of its residuals (mm): where a
        smooth pivot with a prior starts, and what weighs its data against the prior."""
        fixed = FixedPivot(solver=self.solver, start=self.start, pivot_prior=prior)
        est = fixed._estimate(reference, current, usable, ())
        pivot = np.asarray(est.path[0])
        n = current.shape[0]
        return pivot, effective_noise(reference, current, usable, np.broadcast_to(pivot, (n, 2)))


class SmoothPivot(JawMethod):
    """A pivot moving along a linear spline (a knot every ``knot_spacing`` frames) with the
    smoothness prior ``smoothness * sum_k |q_k+1 - q_k|^2`` (mm^2 per frame step).

    smoothness: finite and > 0 (``inf`` is :class:`FixedPivot`). solver: chooses damping
    (``damped`` solvers: Levenberg-Marquardt; Gauss-Newton ones: undamped first) and the
    step budget of the structured block-tridiagonal solver (damped: Newton steps on the
    exact per-frame Hessians; Gauss-Newton solvers: Gauss-Newton steps); None as
    :class:`FixedPivot`. start: None (as :class:`FixedPivot`) or an initial pivot (2,) mm
    for every knot. pivot_prior: as :class:`FixedPivot`, on every knot the data reach with
    ``1/m`` of its information (``m`` such knots), so that the path as a whole carries one
    prior. Knots no usable frame reaches (before the first, after the last) follow the
    smoothness alone and are not counted as parameters, so the fit pads to a frame bucket
    like the others (one compilation for every length up to ``jaw_bucket``).
    """

    smoothness: float = 1.0
    knot_spacing: int = DEFAULT_KNOT_SPACING
    solver: Solver | None = eqx.field(default=None, converter=_optional_solver)
    start: Float[np.ndarray, "2"] | None = eqx.field(
        default=None, converter=_optional_array("(2,) mm"))
    pivot_prior: PivotPrior | None = None

    name: ClassVar[str] = "smooth-pivot"
    jaw_sensors_needed: ClassVar[tuple[int, ...]] = (1, 2)

    def __check_init__(self):
        try:
            value = float(self.smoothness)
        except (TypeError, ValueError):
            value = float("nan")
        if not (np.isfinite(value) and value > 0.0):
            raise InvalidChoiceError(
                f"smoothness must be a finite number > 0, got {self.smoothness!r}")
        if int(self.knot_spacing) != self.knot_spacing or self.knot_spacing < 1:
            raise InvalidChoiceError(
                f"knot_spacing must be a whole number of frames >= 1, got {self.knot_spacing!r}")

    @property
    def solver_name(self) -> str:
        """``"block-tridiagonal-lm"`` (damped solvers) or ``"block-tridiagonal-gn"``."""
        return "block-tridiagonal-" + ("lm" if _default_solver(self).damped else "gn")

    def _estimate(self, reference, current, usable, sensors):
        n, spacing = current.shape[0], int(self.knot_spacing)
        m = (n - 1) // spacing + 2
        reached = _knots_reached(usable, spacing, m)
        prior = _pivot_prior(self, reference.shape[0])
        pivot0 = _start_pivot(self, prior, reference, current, usable)
        dtype = _dtype_of(reference)
        solver = _default_solver(self, PIVOT_MAX_STEPS)
        tol = solver.tolerances(dtype)[0]
        config = (bool(solver.damped), int(solver.max_steps), float(tol), spacing)

        def solve_with(noise_mm, knots):
            # the prior's information shared among the knots the data reach: the path as a
            # whole carries one prior, as the fixed pivot does (each knot's own would add up
            # m-fold); the knots beyond them follow the path's smoothness alone
            mean, weight = _prior_arrays(prior, dtype, noise_mm / np.sqrt(reached.sum()))
            return smooth_pivot_kernel(
                config, reference, current, usable.astype(float),
                np.asarray(float(self.smoothness), dtype), np.asarray(knots, dtype),
                (mean, np.where(reached[:, None], weight[None], 0.0).astype(dtype)))

        if prior.informative:
            # a moving pivot can follow one sensor anywhere, so its own residuals say nothing
            # of the data's noise: the fixed pivot's (with the same prior) weigh them, and
            # its pivot is the start
            pivot0, noise = FixedPivot._with_noise(self, reference, current, usable, prior)
        else:
            noise = PRIOR_NOISE_MM
        path, unit, result, _ = solve_with(noise, np.tile(pivot0, (m, 1)))
        return _pivot_estimate(reference, current, usable, np.asarray(path), np.asarray(unit),
                               result, 2 * int(reached.sum()), prior)


class CoupledRotation(JawMethod):
    """One jaw sensor: the rotation from a :class:`JawCoupling` (a prior learned from
    two-sensor recordings), ``theta_k = a . (p'_k - p_ref)``, and the translation that maps
    the sensor exactly, ``t_k = p'_k - R(theta_k) p_ref``: rotation *and* translation, as
    the real jaw moves (on the real JW11 recording the rotation is linear in the incisor's
    displacement with R^2 = 0.99).

    The data say nothing about theta beyond the coupling (one point fixes two of three
    parameters), so its uncertainty is the prior's: ``theta_sd_rad^2 + sum (sd * d)^2``;
    the sensor is matched exactly, so the fit leaves no residual and ``JawFit.noise_mm`` is
    NaN; the translation also carries the sensor's noise (``PRIOR_NOISE_MM``). coupling:
    None for :data:`DEFAULT_COUPLINGS` of the sensor used.
    """

    coupling: JawCoupling | None = None

    name: ClassVar[str] = "coupled-rotation"
    jaw_sensors_needed: ClassVar[tuple[int, ...]] = (1,)

    @property
    def solver_name(self) -> str:
        """``"coupled"`` (no solver)."""
        return "coupled"

    def _estimate(self, reference, current, usable, sensors):
        (sensor,) = sensors
        coupling = DEFAULT_COUPLINGS[sensor] if self.coupling is None else self.coupling
        if coupling.sensor != sensor:
            raise InvalidChoiceError(f"coupled-rotation: the coupling is for {coupling.sensor}'s "
                                     f"displacement, but the sensor used is {sensor}")
        p = np.asarray(reference, float)[0]
        d = np.asarray(current, float)[:, 0] - p
        theta = d @ np.asarray(coupling.rad_per_mm)
        c, s = np.cos(theta), np.sin(theta)
        turned = np.stack([c * p[0] + s * p[1], -s * p[0] + c * p[1]], -1)
        params = np.column_stack([theta, np.asarray(current, float)[:, 0] - turned])
        var = coupling.theta_sd_rad**2 + np.sum((d * np.asarray(coupling.rad_per_mm_sd)) ** 2, 1)
        g = np.column_stack([np.ones_like(theta), -(-s * p[0] + c * p[1]), -(-c * p[0] - s * p[1])])
        covariance = var[:, None, None] * g[:, :, None] * g[:, None, :]
        covariance[:, 1:, 1:] += PRIOR_NOISE_MM**2 * np.eye(2)  # t carries the sensor's noise
        n = len(theta)
        return Estimate(params, np.zeros((n, 2)), np.zeros((n, 3, 3)),
                        np.full(n, _OK, np.int32), 2 * n, prior=coupling.describe(),
                        covariance=covariance)


def check_sensors(method: JawMethod, sensors: tuple[str, ...]) -> None:
    """Refuse, with the method's reason, a method that cannot run with ``sensors``."""
    k = len(sensors)
    if k in method.jaw_sensors_needed:
        return
    if k == 1:
        raise InvalidChoiceError(f"{method.name} needs both jaw sensors (MNI and MNM): "
                                 f"{method.needs_both}")
    raise InvalidChoiceError(f"{method.name} is for one jaw sensor (jaw sensors MNI or MNM): "
                             f"with both the rotation is measured; use frame-fit, "
                             f"fixed-pivot or smooth-pivot")


def jaw_method(name: str, *, solver: Solver | str | None = None, smoothness: float = 1.0,
               knot_spacing: int = DEFAULT_KNOT_SPACING) -> JawMethod:
    """The method object for a command-line alias (:data:`cassi_fit.options.ALL_JAW_METHODS`).

    ``solver`` (object or alias in :data:`cassi_fit.options.SOLVERS`; checked even for the
    methods that do not use one; None: the method's own, e.g. the closed form for
    "frame-fit"; a solver makes "frame-fit" iterate), ``smoothness`` and ``knot_spacing``
    (frames) for "smooth-pivot". Raises :class:`~cassi_fit.errors.InvalidChoiceError` on a
    bad name, solver or smoothness.
    """
    check_choice("jaw method", name, ALL_JAW_METHODS)
    solver = _optional_solver(solver)
    if name == "coupled-rotation":
        return CoupledRotation()
    if name == "closed-form":
        return ClosedForm()
    if name == "frame-fit":
        return FrameFit(solver=solver)
    if name == "fixed-pivot":
        return FixedPivot(solver=solver)
    return SmoothPivot(smoothness=smoothness, knot_spacing=knot_spacing, solver=solver)


def method_for_sensors(method: JawMethod | str | None, sensors: tuple[str, ...]
                       ) -> JawMethod:
    """The jaw method for a recording whose jaw ``sensors`` are those given (both, or one
    of ``"MNI"``, ``"MNM"``): ``method`` (an object or an alias), or by default (None) the
    paper's closed form with two and :class:`CoupledRotation` with one. A method that
    cannot run with those sensors is refused with its reason (:func:`check_sensors`)."""
    if method is None:
        method = ClosedForm() if len(sensors) == 2 else CoupledRotation()
    elif isinstance(method, str):
        method = jaw_method(method)
    check_sensors(method, tuple(sensors))
    return method


def tracked_jaw_sensors(valid: Bool[np.ndarray, "n 8 2"], source: Any = None
                        ) -> tuple[str, ...]:
    """The jaw pellets a recording ever tracks (``valid``: a ``PelletTrack``'s), in the jaw
    order: the default jaw sensors of a fit (``MissingDataError``, naming ``source`` (the
    recording's file) when given, if none)."""
    from ..pellets import JAW_INDEX, JAW_PELLETS

    ever = np.asarray(valid)[:, list(JAW_INDEX)].all(axis=2).any(axis=0)
    if not ever.any():
        where = "" if source is None else f"{source}: "
        raise MissingDataError(f"{where}jaw pellets {', '.join(JAW_PELLETS)} never tracked")
    return tuple(p for p, e in zip(JAW_PELLETS, ever, strict=True) if e)


def as_method(method: JawMethod | str, solver: Any, smoothness: Any, knot_spacing: Any
              ) -> JawMethod:
    """``method`` as an object: an alias with its options, or the object itself (whose
    options belong to it: passing them again is an error)."""
    if isinstance(method, str):
        options = {k: v for k, v in (("solver", solver), ("smoothness", smoothness),
                                      ("knot_spacing", knot_spacing)) if v is not None}
        return jaw_method(method, **options)
    if not isinstance(method, JawMethod):
        raise InvalidChoiceError(f"method must be a jaw method object or one of "
                                 f"{', '.join(ALL_JAW_METHODS)}, not {method!r}")
    if any(v is not None for v in (solver, smoothness, knot_spacing)):
        raise InvalidChoiceError("solver, smoothness and knot_spacing belong to the method "
                                 "object (e.g. SmoothPivot(smoothness=...)), not to fit_jaw")
    return method
