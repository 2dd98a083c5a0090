"""Planar rigid motions of the mandible, in the paper's sign convention.

A motion is a pair ``(theta, t)``: ``theta`` in radians (scalar), ``t`` in mm, shape ``(2,)``,
acting on a point ``p`` of the midsagittal (pellet) plane as ``p' = R(theta) p + t`` with

    R(theta) = [[ cos theta, sin theta],
                [-sin theta, cos theta]]

which is Parke's rotation of the paper's Eqs 4-5: ``x' - a = (x - a) cos + (y - b) sin``,
``y' - b = -(x - a) sin + (y - b) cos``. With +x toward the front of the face and +y up,
positive ``theta`` turns the front of the jaw down: jaw opening is positive.

The pair ``(theta, t)`` stays finite for every motion, including a pure translation
(``theta = 0``), where the pivot of Eqs 6-7 runs off to infinity. The pivot is derived on
demand by :func:`pivot`, which reports where it is undefined instead of dividing by zero.

Identification used below: a 2D vector ``(x, y)`` is the complex number ``x + i y``; then
``R(theta) v = exp(-i theta) v``.

All functions are written for one motion; ``jax.vmap`` them over frames.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

#: A rigid motion in the midsagittal plane: ``(theta rad, t (2,) mm)``, ``p' = R(theta) p + t``.
Motion = tuple[Float[ArrayLike, ""], Float[ArrayLike, "2"]]

# Below this |theta/2| the ratios sin(w x)/sin(x) and x/sin(x) are evaluated by their Taylor
# series (error below 1e-18 relative), so that value and gradient are exact at theta = 0.
_SMALL_HALF_ANGLE = 1e-3


def rotation_matrix(theta: Float[ArrayLike, ""]) -> Float[Array, "2 2"]:
    """``R(theta)`` of Eqs 4-5, shape ``(2, 2)``; positive theta = jaw opening (clockwise)."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array([[c, s], [-s, c]])


def apply(
    theta: Float[ArrayLike, ""], t: Float[ArrayLike, "2"], points: Float[ArrayLike, "*n d"]
) -> Float[Array, "*n d"]:
    """Move ``points`` (..., 2) or (..., 3) mm by the motion; a third (lateral) axis is kept."""
    points = jnp.asarray(points)
    c, s = jnp.cos(theta), jnp.sin(theta)
    x, y = points[..., 0], points[..., 1]
    moved = jnp.stack([c * x + s * y + t[0], -s * x + c * y + t[1]], axis=-1)
    if points.shape[-1] == 2:
        return moved
    return jnp.concatenate([moved, points[..., 2:]], axis=-1)


def from_pivot(theta: Float[ArrayLike, ""], pivot: Float[ArrayLike, "2"]) -> Motion:
    """The motion that rotates by ``theta`` about ``pivot`` (a, b): ``t = (I - R) pivot``."""
    pivot = jnp.asarray(pivot)
    return theta, pivot - apply(theta, jnp.zeros(2, pivot.dtype), pivot)


def compose(second: Motion, first: Motion) -> Motion:
    """The motion ``first`` followed by ``second``; each is ``(theta, t)``."""
    theta1, t1 = first
    theta2, t2 = second
    return theta1 + theta2, apply(theta2, t2, t1)


def inverse(motion: Motion) -> Motion:
    """The motion that undoes ``motion``."""
    theta, t = motion
    return -theta, -apply(-theta, jnp.zeros_like(t), t)


def relative(reference: Motion, current: Motion) -> Motion:
    """The motion that takes the pose ``reference`` to the pose ``current``.

    Both are poses given as motions from a common rest pose; the result is
    ``current o reference^-1``.
    """
    return compose(current, inverse(reference))


def _sin_ratio(w, x):
    """``sin(w x) / sin(x)``, exact (value and gradient) at ``x = 0`` via a double ``where``.

    The series: w [1 + x^2 (1 - w^2)/6 + x^4 (7/360 - w^2/36 + w^4/120)].
    """
    small = jnp.abs(x) < _SMALL_HALF_ANGLE
    x_safe = jnp.where(small, 1.0, x)  # keeps the unused branch (and its gradient) finite
    direct = jnp.sin(w * x_safe) / jnp.sin(x_safe)
    x2 = x * x
    series = w * (1.0 + x2 * (1.0 - w * w) / 6.0 + x2 * x2 * (7.0 / 360.0 - w * w / 36.0 + w**4 / 120.0))
    return jnp.where(small, series, direct)


def fractional(motion: Motion, weight: Float[ArrayLike, ""]) -> Motion:
    """The motion that turns by ``weight * theta`` about the same pivot (Parke's region weights).

    Parke moves jaw regions by a percentage of the jaw rotation about its pivot; with the
    pivot at infinity (pure translation) that becomes ``weight * t``. In complex form the
    translation is ``t * (1 - e^{-i w theta}) / (1 - e^{-i theta})``
    ``= t * sin(w theta/2)/sin(theta/2) * e^{-i (w - 1) theta / 2}``, finite and smooth for
    ``|theta| < 2 pi`` and equal to ``weight * t`` at ``theta = 0``.
    """
    theta, t = motion
    gain = _sin_ratio(weight, theta / 2.0)
    # e^{-i phi} v is R(phi) v, i.e. apply(phi, 0, v), here with phi = (w - 1) theta / 2.
    turned = apply((weight - 1.0) * theta / 2.0, jnp.zeros_like(t), t)
    return weight * theta, gain * turned


def pivot(motion: Motion) -> tuple[Float[Array, "2"], Bool[Array, ""]]:
    """The fixed point ``(a, b)`` of a motion and whether it exists.

    Returns ``(pivot (2,), defined)``. For ``theta = 0`` (pure translation, or no motion)
    there is no fixed point: ``defined`` is False and the pivot returned is ``(0, 0)``
    with zero gradient; no division by zero happens on either branch.
    In complex form ``pivot = t e^{i theta/2} / (2 i sin(theta/2))``.
    """
    theta, t = motion
    half = theta / 2.0
    defined = jnp.sin(half) != 0.0
    sin_safe = jnp.where(defined, jnp.sin(half), 1.0)
    # t * e^{i half} / (2 i sin half): rotate t by e^{i half} (= apply(-half)), then
    # divide by 2 i: (x + i y) / (2 i) = (y - i x) / 2.
    u = apply(-half, jnp.zeros_like(t), t)
    q = jnp.stack([u[1], -u[0]]) / (2.0 * sin_safe)
    return jnp.where(defined, q, jnp.zeros_like(q)), defined
