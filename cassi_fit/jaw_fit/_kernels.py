"""The compiled kernels of the jaw methods (module-level ``eqx.filter_jit`` / ``jax.jit``:
each compiles once per shape and static configuration) and the per-frame covariances. The
methods' kernels are :func:`cassi_fit._exported.exported`: a new process loads them instead
of tracing them again."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .. import jaw, rigid
from .._exported import exported
from . import _solvers
from ._residuals import (
    best_angle_about,
    pivot_prior_residuals,
    rigid_residuals,
    scale,
    scaled_rigid_residuals,
    smooth_pivot_system,
    spline,
    unscale,
)
from ._solve import least_squares


def motion_params(motion):
    return jnp.concatenate([motion.theta[None], motion.translation])


def unit_covariance(params, reference, current):
    """``(J^T J)^-1`` (3, 3) of the frame's rigid residuals at ``params``."""
    jac = jax.jacfwd(rigid_residuals)(params, (reference, current))
    return jnp.linalg.inv(jac.T @ jac)


@exported
def closed_form_kernel(reference, current):
    """Per frame: the closed form, and noise propagated through it: ``G G^T`` with
    ``G = d(theta, t)/d(current)``."""

    def one(cur):
        y = motion_params(jaw.closed_form(reference, cur))
        g = jax.jacfwd(lambda c: motion_params(jaw.closed_form(reference, c)))(cur)
        g = g.reshape(3, 4)
        return y, rigid_residuals(y, (reference, cur)), g @ g.T

    return jax.vmap(one)(current)


@exported
def frame_fit_kernel(solver, reference, current, start):
    """Per frame least squares from ``start`` (n, 3) motions (None: each frame's Procrustes
    motion): ``(params, residuals, result, unit covariance)``."""
    if start is None:
        start = jax.vmap(lambda c: motion_params(jaw.procrustes(reference, c)))(current)

    def one(cur, y0):
        z, result = least_squares(scaled_rigid_residuals, scale(y0, reference),
                                  (reference, cur), solver, gradient_stop=True)
        y = unscale(z, reference)
        return y, rigid_residuals(y, (reference, cur)), result, unit_covariance(
            y, reference, cur)

    return jax.vmap(one)(current, start)


@exported
def procrustes_kernel(reference, current):
    """Per frame, the frame fit's exact answer, in closed form: the two-point least-squares
    rigid motion (2D Procrustes/Kabsch, :func:`jaw.procrustes`), its residuals and its unit
    covariance ``(J^T J)^-1`` at the solution (the Gauss-Newton normal matrix; for the
    rigid residuals it does not depend on the data, only on theta)."""

    def one(cur):
        y = motion_params(jaw.procrustes(reference, cur))
        return y, rigid_residuals(y, (reference, cur)), unit_covariance(y, reference, cur)

    return jax.vmap(one)(current)


@exported
def fixed_pivot_kernel(solver, reference, current, weight, pivot0, prior):
    """Compiled fixed-pivot fit, ``prior = (mean (2,), weight (2,))``: ``-> (q, result, J)``."""
    args = (reference, current, weight, *prior)
    pivot, result = least_squares(pivot_prior_residuals, pivot0, args, solver)
    return pivot, result, jax.jacfwd(pivot_prior_residuals)(pivot, args)


@exported
def smooth_pivot_kernel(config, reference, current, weight, smoothness, knots0, prior):
    """Compiled smooth-pivot fit. ``config = (damped, max_steps, tol, spacing)`` (static);
    ``prior = (mean (2,), weight (m, 2))``, per knot. Returns the pivot path (n, 2), its unit covariance
    (n, 2, 2) (``(J^T J)^-1`` blocks mapped through the spline, selected inversion), the
    solver result and the knots (m, 2)."""
    from ._linalg import block_tridiagonal_inverse_blocks

    damped, max_steps, tol, spacing = config
    n = current.shape[0]

    def system(knots):
        return smooth_pivot_system(knots, reference, current, weight, smoothness, spacing,
                                   newton=damped, prior=prior)

    # through the module, so that a test can stub the structured solver out
    knots, result = _solvers.minimise_block_tridiagonal(system, knots0, damped=damped,
                                                        max_steps=max_steps, tol=tol)
    _, _, _, (diag, upper) = system(knots)
    ridge = 1e-12 * jnp.max(jnp.abs(jnp.diagonal(diag, axis1=1, axis2=2)))
    c_diag, c_up = block_tridiagonal_inverse_blocks(diag + ridge * jnp.eye(2)[None], upper)
    k = jnp.arange(n)
    j = k // spacing
    f = ((k % spacing) / spacing)[:, None, None]
    c01 = c_up[j]
    # pivot q_k = (1 - f) Q_j + f Q_j+1: only blocks (j, j), (j, j+1), (j+1, j+1) matter
    unit_cov = ((1 - f) ** 2 * c_diag[j] + (1 - f) * f * (c01 + jnp.swapaxes(c01, 1, 2))
                + f**2 * c_diag[j + 1])
    return spline(knots, n, spacing), unit_cov, result, knots


@exported
def pivot_with_covariance(params, covariance):
    """Per frame: the fixed point of ``params = (theta, tx, ty)`` and its (2, 2)
    covariance."""

    def one(y, cov):
        point, defined = rigid.pivot((y[0], y[1:]))
        jac = jax.jacfwd(lambda z: rigid.pivot((z[0], z[1:]))[0])(y)
        return point, defined, jnp.where(defined, jac @ cov @ jac.T,
                                         jnp.diag(jnp.full(2, jnp.inf)))

    return jax.vmap(one)(params, covariance)


def unit_covariance_about(theta, pivot, reference):
    """One sensor: ``(theta, t)``'s unit covariance (3, 3) given the pivot, ``g g^T / |j|^2``
    with ``g = d(theta, t)/d theta`` and ``j`` the sensor's residual derivative in theta
    (the pivot's own uncertainty is in ``JawFit.pivot_covariance``)."""

    def motion(th):
        return jnp.concatenate([th[None], rigid.from_pivot(th, pivot)[1]])

    g = jax.jacfwd(motion)(theta)
    j = jax.jacfwd(lambda th: rigid.apply(*rigid.from_pivot(th, pivot), reference).ravel())(theta)
    return jnp.outer(g, g) / jnp.sum(j**2)


@exported
def about_pivot_params(reference, current, path):
    """Per frame: best angle about the pivot ``path`` (n, 2) -> params (theta, tx, ty),
    unit covariance, residuals. ``reference`` (k, 2): both jaw sensors (the rigid motion's
    covariance) or one (the covariance given the pivot: one point cannot fix three
    parameters)."""

    def one(cur, pivot):
        best = best_angle_about(pivot, reference, cur)
        theta, t = rigid.from_pivot(best, pivot)
        y = jnp.concatenate([theta[None], t])
        if reference.shape[0] == 1:
            cov = unit_covariance_about(best, pivot, reference)
        else:
            cov = unit_covariance(y, reference, cur)
        return y, cov, rigid_residuals(y, (reference, cur))

    return jax.vmap(one)(current, path)


@exported
def translation_about(theta, pivot):
    """Per frame: the translation of the rotation by ``theta`` (n,) about ``pivot`` (n, 2)."""
    return jax.vmap(lambda th, q: rigid.from_pivot(th, q)[1])(theta, pivot)
