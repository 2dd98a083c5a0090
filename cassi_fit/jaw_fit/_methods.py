"""The jaw methods as objects (equinox Modules), each with its compiled kernel.

A method's ``_estimate(reference, current, usable)`` gets the reference jaw (2, 2) mm, the
frames (n, 2, 2) mm (unusable frames already replaced by the reference) and the usable mask
(n,), and returns an :class:`Estimate`: per-frame motions, residuals, unit covariances and
solver results. :func:`cassi_fit.jaw_fit.fit_jaw` turns that into a ``JawFit``.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from .. import jaw, rigid
from ..errors import DegenerateGeometryError, InvalidChoiceError
from ..options import JAW_METHODS, check_choice
from ..status import SolverResult
from . import _solvers
from ._residuals import (
    best_angle_about,
    fixed_pivot_residuals,
    rigid_residuals,
    scale,
    scaled_rigid_residuals,
    smooth_pivot_system,
    spline,
    unscale,
)
from ._solve import as_solver, least_squares
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


# ---------------------------------------------------------------- compiled kernels
def _motion_params(motion):
    return jnp.concatenate([motion.theta[None], motion.translation])


def _unit_covariance(params, reference, current):
    """``(J^T J)^-1`` (3, 3) of the frame's rigid residuals at ``params``."""
    jac = jax.jacfwd(rigid_residuals)(params, (reference, current))
    return jnp.linalg.inv(jac.T @ jac)


@eqx.filter_jit
def _closed_form_kernel(reference, current):
    """Per frame: the closed form, and noise propagated through it: ``G G^T`` with
    ``G = d(theta, t)/d(current)``."""

    def one(cur):
        y = _motion_params(jaw.closed_form(reference, cur))
        g = jax.jacfwd(lambda c: _motion_params(jaw.closed_form(reference, c)))(cur)
        g = g.reshape(3, 4)
        return y, rigid_residuals(y, (reference, cur)), g @ g.T

    return jax.vmap(one)(current)


@eqx.filter_jit
def _frame_fit_kernel(solver, reference, current, start):
    """Per frame least squares from ``start`` (n, 3) motions (None: each frame's Procrustes
    motion): ``(params, residuals, result, unit covariance)``."""
    if start is None:
        start = jax.vmap(lambda c: _motion_params(jaw.procrustes(reference, c)))(current)

    def one(cur, y0):
        z, result = least_squares(scaled_rigid_residuals, scale(y0, reference),
                                  (reference, cur), solver, gradient_stop=True)
        y = unscale(z, reference)
        return y, rigid_residuals(y, (reference, cur)), result, _unit_covariance(
            y, reference, cur)

    return jax.vmap(one)(current, start)


@eqx.filter_jit
def _fixed_pivot_kernel(solver, reference, current, weight, pivot0):
    """Compiled fixed-pivot fit: ``-> (q, result, J)``."""
    args = (reference, current, weight)
    pivot, result = least_squares(fixed_pivot_residuals, pivot0, args, solver)
    return pivot, result, jax.jacfwd(fixed_pivot_residuals)(pivot, args)


@eqx.filter_jit
def _smooth_pivot_kernel(config, reference, current, weight, smoothness, knots0):
    """Compiled smooth-pivot fit. ``config = (damped, max_steps, tol, spacing)`` (static).
    Returns the pivot path (n, 2), its unit covariance (n, 2, 2) (``(J^T J)^-1`` blocks
    mapped through the spline, selected inversion) and the solver result."""
    from ._linalg import block_tridiagonal_inverse_blocks

    damped, max_steps, tol, spacing = config
    n = current.shape[0]

    def system(knots):
        return smooth_pivot_system(knots, reference, current, weight, smoothness, spacing,
                                   newton=damped)

    # through the module, so that a test can stub the structured solver out
    knots, result = _solvers.minimise_block_tridiagonal(system, knots0, damped=damped,
                                                        max_steps=max_steps, tol=tol)
    _, _, _, (diag, upper) = system(knots)
    ridge = 1e-12 * jnp.max(jnp.abs(jnp.diagonal(diag, axis1=1, axis2=2)))
    c_diag, c_up = block_tridiagonal_inverse_blocks(diag + ridge * jnp.eye(2), upper)
    k = jnp.arange(n)
    j = k // spacing
    f = ((k % spacing) / spacing)[:, None, None]
    c01 = c_up[j]
    # pivot q_k = (1 - f) Q_j + f Q_j+1: only blocks (j, j), (j, j+1), (j+1, j+1) matter
    unit_cov = ((1 - f) ** 2 * c_diag[j] + (1 - f) * f * (c01 + jnp.swapaxes(c01, 1, 2))
                + f**2 * c_diag[j + 1])
    return spline(knots, n, spacing), unit_cov, result


@jax.jit
@jax.vmap
def pivot_with_covariance(params, covariance):
    """The fixed point of ``params = (theta, tx, ty)`` and its (2, 2) covariance."""

    def fixed_point(y):
        return rigid.pivot((y[0], y[1:]))[0]

    point, defined = rigid.pivot((params[0], params[1:]))
    jac = jax.jacfwd(fixed_point)(params)
    cov = jnp.where(defined, jac @ covariance @ jac.T, jnp.diag(jnp.full(2, jnp.inf)))
    return point, defined, cov


@jax.jit
def _about_pivot_params(reference, current, path):
    """Per frame: best angle about the pivot ``path`` (n, 2) -> params (theta, tx, ty),
    unit covariance, residuals."""

    def one(cur, pivot):
        theta, t = rigid.from_pivot(best_angle_about(pivot, reference, cur), pivot)
        y = jnp.concatenate([theta[None], t])
        return y, _unit_covariance(y, reference, cur), rigid_residuals(y, (reference, cur))

    return jax.vmap(one)(current, path)


translation_about = jax.jit(jax.vmap(lambda theta, q: rigid.from_pivot(theta, q)[1]))


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


def _optional_array(shape_doc):
    def convert(value):
        return None if value is None else np.asarray(value, dtype=float)

    convert.__doc__ = shape_doc
    return convert


def _pivot_estimate(reference, current, usable, path, unit_pivot_cov, result, n_extra):
    params, unit_cov, res = (np.asarray(a) for a in _about_pivot_params(
        reference, current, jnp.asarray(path, jnp.asarray(reference).dtype)))
    return Estimate(params, res, unit_cov, np.full(len(usable), int(result), np.int32),
                    int(usable.sum()) + n_extra, path, unit_pivot_cov)


# ---------------------------------------------------------------------- methods
class JawMethod(eqx.Module):
    """A jaw-motion method: an object passed to :func:`cassi_fit.jaw_fit.fit_jaw` as
    ``method=``; ``name`` is its command-line alias (:data:`cassi_fit.options.JAW_METHODS`)."""

    name: ClassVar[str]

    @abc.abstractmethod
    def _estimate(self, reference, current, usable) -> Estimate:
        """Per-frame motion of ``current`` (usable frames filled with the reference)."""

    @property
    def solver_name(self) -> str:
        """What ``JawFit.solver`` reports."""
        return self.solver.name


class ClosedForm(JawMethod):
    """The paper's Eqs 1-3, 6-7 in the numerically sound form, per frame; no solver."""

    name: ClassVar[str] = "closed-form"

    @property
    def solver_name(self) -> str:
        """``"closed-form"`` (no solver)."""
        return "closed-form"

    def _estimate(self, reference, current, usable):
        params, res, unit_cov = (np.asarray(a) for a in _closed_form_kernel(reference, current))
        return Estimate(params, res, unit_cov, np.full(len(usable), _OK, np.int32),
                        3 * int(usable.sum()))


class FrameFit(JawMethod):
    """Rotation + translation fitted to both pellets, per frame (vmapped).

    solver: a solver object (default :class:`LevenbergMarquardt`) or an alias.
    start: None (the Procrustes motion, i.e. the minimum: the solver confirms it), or the
    initial motion ``(theta rad, tx mm, ty mm)``, shape (3,) for every frame or (n, 3).
    """

    solver: Solver = eqx.field(default=LevenbergMarquardt(), converter=as_solver)
    start: Float[np.ndarray, "*n 3"] | None = eqx.field(
        default=None, converter=_optional_array("(3,) or (n, 3)"))

    name: ClassVar[str] = "frame-fit"

    def _estimate(self, reference, current, usable):
        n = current.shape[0]
        start = None if self.start is None else jnp.asarray(
            np.broadcast_to(self.start, (n, 3)), jnp.asarray(reference).dtype)
        params, res, result, unit_cov = (np.asarray(a) for a in _frame_fit_kernel(
            self.solver, reference, current, start))
        result = np.where(usable, result, _OK).astype(np.int32)
        return Estimate(params, res, unit_cov, result, 3 * int(usable.sum()))


class FixedPivot(JawMethod):
    """Parke's fixed pivot: one pivot for the recording, one angle per frame (projected out).

    solver: a solver object or an alias. start: None (linear least squares on the
    Procrustes motions, ``t_k = (I - R_k) q``) or the initial pivot (2,) mm.
    """

    solver: Solver = eqx.field(default=LevenbergMarquardt(), converter=as_solver)
    start: Float[np.ndarray, "2"] | None = eqx.field(
        default=None, converter=_optional_array("(2,) mm"))

    name: ClassVar[str] = "fixed-pivot"

    def _estimate(self, reference, current, usable):
        pivot0 = initial_pivot(reference, current, usable) if self.start is None else self.start
        pivot, result, jac = _fixed_pivot_kernel(
            self.solver, reference, current, usable.astype(float),
            jnp.asarray(pivot0, jnp.asarray(reference).dtype))
        jac = np.asarray(jac)
        n = current.shape[0]
        path = np.broadcast_to(np.asarray(pivot), (n, 2))
        unit = np.broadcast_to(np.linalg.pinv(jac.T @ jac), (n, 2, 2))
        return _pivot_estimate(reference, current, usable, path, unit, result, 2)


class SmoothPivot(JawMethod):
    """A pivot moving along a linear spline (a knot every ``knot_spacing`` frames) with the
    smoothness prior ``smoothness * sum_k |q_k+1 - q_k|^2`` (mm^2 per frame step).

    smoothness: finite and > 0 (``inf`` is :class:`FixedPivot`). solver: chooses damping
    (``damped`` solvers: Levenberg-Marquardt; Gauss-Newton ones: undamped first) and the
    step budget of the structured block-tridiagonal solver (damped: Newton steps on the
    exact per-frame Hessians; Gauss-Newton solvers: Gauss-Newton steps). start: None (as
    :class:`FixedPivot`) or an initial pivot (2,) mm for every knot.
    """

    smoothness: float = 1.0
    knot_spacing: int = DEFAULT_KNOT_SPACING
    solver: Solver = eqx.field(default=LevenbergMarquardt(), converter=as_solver)
    start: Float[np.ndarray, "2"] | None = eqx.field(
        default=None, converter=_optional_array("(2,) mm"))

    name: ClassVar[str] = "smooth-pivot"

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
        return "block-tridiagonal-" + ("lm" if self.solver.damped else "gn")

    def _estimate(self, reference, current, usable):
        n, spacing = current.shape[0], int(self.knot_spacing)
        m = (n - 1) // spacing + 2
        pivot0 = initial_pivot(reference, current, usable) if self.start is None else self.start
        dtype = jnp.asarray(reference).dtype
        tol = self.solver.tolerances(dtype)[0]
        config = (bool(self.solver.damped), int(self.solver.max_steps), float(tol), spacing)
        path, unit, result = _smooth_pivot_kernel(
            config, reference, current, usable.astype(float),
            jnp.asarray(float(self.smoothness), dtype),
            jnp.asarray(np.tile(pivot0, (m, 1)), dtype))
        return _pivot_estimate(reference, current, usable, np.asarray(path), np.asarray(unit),
                               result, 2 * m)


def jaw_method(name: str, *, solver: Solver | str = "optimistix-lm", smoothness: float = 1.0,
               knot_spacing: int = DEFAULT_KNOT_SPACING) -> JawMethod:
    """The method object for a command-line alias (:data:`cassi_fit.options.JAW_METHODS`).

    ``solver`` (object or alias in :data:`cassi_fit.options.SOLVERS`; checked even for
    "closed-form", which does not use it), ``smoothness`` and ``knot_spacing`` (frames)
    for "smooth-pivot". Raises :class:`~cassi_fit.errors.InvalidChoiceError` on a bad name,
    solver or smoothness.
    """
    check_choice("jaw method", name, JAW_METHODS)
    solver = as_solver(solver)
    if name == "closed-form":
        return ClosedForm()
    if name == "frame-fit":
        return FrameFit(solver=solver)
    if name == "fixed-pivot":
        return FixedPivot(solver=solver)
    return SmoothPivot(smoothness=smoothness, knot_spacing=knot_spacing, solver=solver)


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
                                 f"{', '.join(JAW_METHODS)}, not {method!r}")
    if any(v is not None for v in (solver, smoothness, knot_spacing)):
        raise InvalidChoiceError("solver, smoothness and knot_spacing belong to the method "
                                 "object (e.g. SmoothPivot(smoothness=...)), not to fit_jaw")
    return method
