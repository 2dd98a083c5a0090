"""Residual functions of the jaw fits, one frame or one recording, and the per-frame blocks
of the smooth pivot's normal equations.

Motions are ``p' = R(theta) p + t`` (paper Eqs 4-5; :mod:`cassi_fit.rigid`). Residuals are
in mm, ``moved - measured``, pellets in the jaw-code order [MNI, MNM].
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import rigid


def rigid_residuals(params: Float[Array, "3"], args: Any) -> Float[Array, "4"]:
    """One frame, ``params = (theta, tx, ty)``: ``R p_i + t - p_i'`` for both pellets, (4,) mm."""
    reference, current = args
    return (rigid.apply(params[0], params[1:], reference) - current).ravel()


def frame_scale(reference: Float[Array, "2 2"]) -> tuple[Float[Array, "2"], Float[Array, ""]]:
    """Centroid ``c`` (2,) mm and rms radius ``ell`` (mm) of the reference jaw points."""
    centre = jnp.mean(reference, axis=0)
    return centre, jnp.sqrt(jnp.mean(jnp.sum((reference - centre[None]) ** 2, axis=-1)))


def scaled_rigid_residuals(z: Float[Array, "3"], args: Any) -> Float[Array, "4"]:
    """One frame in scaled, centred coordinates ``z = (ell theta, s)``, (4,) mm.

    ``p' = R(theta)(p - c) + c + s`` with ``c`` the reference centroid and ``ell`` its rms
    radius. Both parameters are then in mm and decoupled: ``J^T J = 2 I`` at every ``z``
    (the rotation column sums to zero over the two pellets about their centroid), so the
    Levenberg-Marquardt damping ``lambda I`` acts evenly on all three.
    """
    reference, current = args
    centre, ell = frame_scale(reference)
    theta = z[0] / ell
    return (rigid.apply(theta, z[1:], reference - centre[None]) + centre[None] - current).ravel()


def unscale(z: Float[Array, "3"], reference: Float[Array, "2 2"]) -> Float[Array, "3"]:
    """``(ell theta, s)`` -> ``(theta, t)`` with ``t = c + s - R(theta) c``."""
    centre, ell = frame_scale(reference)
    theta = z[0] / ell
    return jnp.concatenate([theta[None], centre + z[1:] - rigid.apply(theta, jnp.zeros(2), centre)])


def scale(y: Float[Array, "3"], reference: Float[Array, "2 2"]) -> Float[Array, "3"]:
    """``(theta, t)`` -> ``(ell theta, s)``, the inverse of :func:`unscale`."""
    centre, ell = frame_scale(reference)
    s = y[1:] + rigid.apply(y[0], jnp.zeros(2), centre) - centre
    return jnp.concatenate([(ell * y[0])[None], s])


def best_angle_about(pivot: Float[Array, "2"], reference: Float[Array, "k 2"],
                     current: Float[Array, "k 2"]) -> Float[Array, ""]:
    """The theta minimising ``sum_i |R(theta)(p_i - q) + q - p_i'|^2``, one frame, rad.

    ``argmax_theta sum_i v_i . R u_i`` with ``u = p - q``, ``v = p' - q``: one atan2. Any
    number of points ``k`` (the two jaw pellets, or one). Where both sums vanish (pellets on
    the pivot) theta is 0, gradient 0 (double-where).
    """
    u, v = reference - pivot[None], current - pivot[None]
    cross = jnp.sum(v[:, 0] * u[:, 1] - v[:, 1] * u[:, 0])
    dot = jnp.sum(u * v)
    ok = (cross != 0.0) | (dot != 0.0)
    return jnp.where(ok, jnp.arctan2(jnp.where(ok, cross, 0.0), jnp.where(ok, dot, 1.0)), 0.0)


def about_pivot(pivot: Float[Array, "2"], reference: Float[Array, "k 2"],
                current: Float[Array, "k 2"], weight: Float[Array, ""]) -> Float[Array, " 2k"]:
    """Weighted residuals (2 k,) mm of one frame turned about ``pivot`` by its best angle."""
    theta = best_angle_about(pivot, reference, current)
    moved = rigid.apply(*rigid.from_pivot(theta, pivot), reference)
    return weight * (moved - current).ravel()


about_pivot_frames = jax.vmap(about_pivot, in_axes=(None, None, 0, 0))
about_pivots_frames = jax.vmap(about_pivot, in_axes=(0, None, 0, 0))


def fixed_pivot_residuals(pivot: Float[Array, "2"], args: Any) -> Float[Array, " 4n"]:
    """Parke's fixed pivot, angles projected out: ``pivot`` (2,) mm -> residuals (4 n,) mm."""
    reference, current, weight = args
    return about_pivot_frames(pivot, reference, current, weight).ravel()


def pivot_prior_residuals(pivot: Float[Array, "2"], args: Any) -> Float[Array, " r"]:
    """:func:`fixed_pivot_residuals` and a pivot prior: ``args = (reference, current,
    weight, prior_mean (2,), prior_weight (2,))`` -> the data residuals (2 k n,) mm and
    ``prior_weight * (pivot - prior_mean)`` (2,) mm (zero weight: no prior)."""
    reference, current, weight, prior_mean, prior_weight = args
    data = about_pivot_frames(pivot, reference, current, weight).ravel()
    return jnp.concatenate([data, prior_weight * (pivot - prior_mean)])


def spline(knots: Float[Array, "m 2"], n: int, spacing: int) -> Float[Array, "n 2"]:
    """Piecewise-linear path (n, 2) through ``knots`` (m, 2) placed every ``spacing`` frames."""
    k = jnp.arange(n)
    j = k // spacing
    f = (k % spacing / spacing)[:, None]
    return (1.0 - f) * knots[j] + f * knots[jnp.minimum(j + 1, knots.shape[0] - 1)]


def smooth_pivot_residuals(knots: Float[Array, " 2m"], args: Any) -> Float[Array, " r"]:
    """Moving pivot: knots (2 m,) mm, flattened (m, 2) -> data residuals (4 n,) and prior
    residuals (2 (m-1),). For reference and tests on small problems (the fit itself never
    forms this vector's Jacobian).

    The prior is ``sqrt(smoothness) * (q_{k+1} - q_k)`` summed exactly over the frames of
    each knot interval: ``|dQ|^2 / spacing`` per interval.
    """
    reference, current, weight, smoothness, spacing = args
    knots = knots.reshape(-1, 2)
    path = spline(knots, current.shape[0], spacing)
    data = about_pivots_frames(path, reference, current, weight).ravel()
    prior = jnp.sqrt(smoothness / spacing) * (knots[1:] - knots[:-1]).ravel()
    return jnp.concatenate([data, prior])


def smooth_pivot_system(knots, reference, current, weight, smoothness, spacing, newton,
                        prior=None):
    """Cost, gradient (m, 2), the step matrix and the Gauss-Newton normal matrix of
    :func:`smooth_pivot_residuals` at ``knots`` (m, 2); each matrix block-tridiagonal as
    ``(diag (m, 2, 2), upper (m-1, 2, 2))``. ``prior = (mean (2,), weight (m, 2))`` adds the
    residuals ``weight_j * (Q_j - mean)`` for every knot (a pivot prior; weight 0: none, as
    on the knots no usable frame reaches).

    Assembled from per-frame blocks: frame ``k`` depends on its pivot ``q_k = (1-f) Q_j + f
    Q_j+1`` only, through a (4, 2) Jacobian ``J_k`` (angle projected out), so it adds
    ``w w' A_k`` to blocks (j, j), (j, j+1), (j+1, j+1) with ``A_k = J_k^T J_k`` (Gauss-Newton)
    or, for the step matrix when ``newton``, the exact 2x2 Hessian of the frame's cost
    ``|r_k|^2 / 2``. The Gauss-Newton matrix of the projected residuals misses the
    curvature the eliminated angle brings in; where the data hold little pivot information
    (slow movement) Gauss-Newton then converges only linearly (rate 0.8 on a 200,000-line
    recording with one opening per 5 s), Newton in 6-7 steps. The prior adds
    ``smoothness / spacing`` times the difference operator. O(n) memory: never forms the
    (4 n, 2 m) Jacobian nor the (n, m) spline weights.
    """
    n, m = current.shape[0], knots.shape[0]
    k = jnp.arange(n)
    j = k // spacing
    f = (k % spacing) / spacing
    path = (1.0 - f)[:, None] * knots[j] + f[:, None] * knots[j + 1]

    def frame(q, cur, w):
        def r(p):
            return about_pivot(p, reference, cur, w)

        jac, res = jax.jacfwd(r)(q), r(q)
        gn = jac.T @ jac
        hess = jax.hessian(lambda p: 0.5 * jnp.sum(r(p) ** 2))(q) if newton else gn
        return gn, hess, jac.T @ res, res

    a_gn, a_step, g, res = jax.vmap(frame)(path, current, weight)
    w0, w1 = 1.0 - f, f
    lam = smoothness / spacing
    eye = jnp.eye(2, dtype=a_gn.dtype)
    ends = jnp.zeros(m, a_gn.dtype).at[:-1].add(1.0).at[1:].add(1.0)

    def blocks(a):
        diag = jnp.zeros((m, 2, 2), a.dtype).at[j].add(w0[:, None, None] ** 2 * a)
        diag = diag.at[j + 1].add(w1[:, None, None] ** 2 * a)
        upper = jnp.zeros((m - 1, 2, 2), a.dtype).at[j].add((w0 * w1)[:, None, None] * a)
        return diag + lam * ends[:, None, None] * eye[None], upper - lam * eye[None]

    step = knots[1:] - knots[:-1]
    grad = jnp.zeros((m, 2), g.dtype).at[j].add(w0[:, None] * g).at[j + 1].add(w1[:, None] * g)
    grad = grad.at[:-1].add(-lam * step).at[1:].add(lam * step)
    cost = 0.5 * (jnp.sum(res**2) + lam * jnp.sum(step**2))
    gn, mat = blocks(a_gn), (blocks(a_step) if newton else None)
    if prior is not None:
        mean, w = prior
        off = w * (knots - mean[None])
        cost = cost + 0.5 * jnp.sum(off**2)
        grad = grad + w * off
        ridge = eye[None] * (w**2)[:, :, None]  # diag(w_j^2) per knot
        gn = (gn[0] + ridge, gn[1])
        mat = None if mat is None else (mat[0] + ridge, mat[1])
    return cost, grad, (gn if mat is None else mat), gn
