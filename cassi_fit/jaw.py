"""Jaw rotation from the two jaw pellets, in closed form (paper section 3.1, Eqs 1-7).

One frame: ``reference`` and ``current`` are ``(2, 2)`` arrays in mm, rows ``[MNI, MNM]``
(index 0 = the incisor pellet, 1 = the molar pellet), columns ``(x, y)`` of the pellet frame.
The motion found takes the reference jaw to the current jaw: ``p' = R(theta) p + t`` with
``R`` of Eqs 4-5 (see :mod:`cassi_fit.rigid`); theta > 0 is jaw opening.

Three closed forms live here, all written for one frame (``jax.vmap`` them over frames):

* :func:`closed_form_paper` -- Eqs 1-3 and 6-7 verbatim, kept for reproduction. It divides
  by ``2 - 2 cos theta`` and ``sin theta`` and takes the arctangent of ratios, so it is NaN
  or infinite at theta = 0 and quadrant-blind for steep jaw lines.
* :func:`closed_form` -- the same motion, numerically sound: theta from one ``atan2``,
  the translation that maps the MNI pellet exactly (the paper's Eqs 6-7 use point 1), the
  pivot derived by :func:`cassi_fit.rigid.pivot`, a status code instead of a division by zero.
* :func:`procrustes` -- the least-squares rigid motion of the two points (Kabsch), the
  exact reference for the per-frame fit in :mod:`cassi_fit.jaw_fit`.

Compiled once, for every caller: :func:`closed_form_frames` and :func:`procrustes_frames`
(one reference, ``n`` frames; module-level kernels, :func:`cassi_fit._exported.exported`:
a shape is traced once per process, and a new process loads it instead of tracing it).
One frame is ``current[None]``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jaxtyping import Float

from ._exported import exported
from .status import Status


class JawMotion(NamedTuple):
    """The jaw's motion in one frame (or, vmapped, in each of ``n`` frames).

    theta: rad, opening positive. translation: (2,) mm, ``p' = R(theta) p + t``, always
    finite. pivot: (2,) mm, the fixed point (a, b) of Eqs 6-7, (0, 0) where undefined.
    pivot_defined: bool. status: int, a :class:`cassi_fit.status.Status` (0 ok, 1 pivot
    undefined, 2 degenerate, 3 non-finite input; ``Status(code).label`` is its word). Where status >= 2 theta, t and pivot are all 0.
    """

    theta: Array
    translation: Array
    pivot: Array
    pivot_defined: Array
    status: Array


def closed_form_paper(
    reference: Float[Array, "2 2"], current: Float[Array, "2 2"]
) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """Eqs 1-3 and 6-7 exactly as published. Returns ``(theta, a, b)`` (rad, mm, mm).

    Eq 1: tan alpha = (y1 - y2)/(x1 - x2); Eq 2: the same for beta in the current frame;
    Eq 3: theta = alpha - beta; Eq 6 gives b and Eq 7 gives a from point 1 (MNI) and its
    moved position. Undefined (NaN/inf) at theta = 0 and wrong by pi when the jaw line
    turns past vertical: that is the published method, reproduced, not repaired.
    """
    (x1, y1), (x2, y2) = reference[0], reference[1]
    (x1p, y1p), (x2p, y2p) = current[0], current[1]
    alpha = jnp.arctan((y1 - y2) / (x1 - x2))  # Eq 1
    beta = jnp.arctan((y1p - y2p) / (x1p - x2p))  # Eq 2
    theta = alpha - beta  # Eq 3
    c, s = jnp.cos(theta), jnp.sin(theta)
    x, y, xp, yp = x1, y1, x1p, y1p
    b = ((yp + x * s - y * c) * (1 - c) - (xp - x * c - y * s) * s) / (2 - 2 * c)  # Eq 6
    a = (yp + x * s - y * c - b * (1 - c)) / s  # Eq 7
    return theta, a, b


def _safe_inputs(reference, current):
    """Replace a frame with any non-finite coordinate by a harmless one (double-``where``).

    Returns ``(reference, current, finite)``; downstream values are masked by ``finite``,
    so neither the value nor the gradient of the bad frame can carry a NaN.
    """
    finite = jnp.all(jnp.isfinite(reference)) & jnp.all(jnp.isfinite(current))
    placeholder = jnp.array([[1.0, 0.0], [0.0, 0.0]], dtype=jnp.result_type(reference, current))
    return (
        jnp.where(finite, reference, placeholder),
        jnp.where(finite, current, placeholder),
        finite,
    )


def _atan_coefficients(degree: int = 5) -> np.ndarray:
    """``P`` (highest power first) with ``atan(w) ~ w + w z P(z)``, ``z = w^2``, for
    ``|w| <= tan(pi/8)``: least squares on Chebyshev nodes, in float64. Max error 4e-11 rad,
    far below float32's resolution (6e-8 at pi)."""
    zmax = np.tan(np.pi / 8.0) ** 2
    z = zmax * (1.0 - np.cos(np.pi * (np.arange(200) + 0.5) / 200)) / 2.0
    w = np.sqrt(z)
    return np.polyfit(z, (np.arctan(w) - w) / (w * z), degree)


_ATAN_P = tuple(float(c) for c in _atan_coefficients())


def _atan2_float32(y, x):
    """``atan2(y, x)`` in (-pi, pi] from arithmetic alone, for float32 and narrower.

    XLA's CPU arctangent is a scalar loop (about 60 ns an element here; numpy's SIMD one
    under 1 ns), so the closed form computes it from vectorisable operations: the ratio of
    the smaller to the larger of ``|x|, |y|``, reduced to ``|w| <= tan(pi/8)`` by
    ``atan(r) = pi/4 + atan((r - 1)/(r + 1))``, a polynomial (:func:`_atan_coefficients`),
    and the octant restored. Callers pass ``(x, y) != (0, 0)``. ``y = -0.0`` with ``x < 0``
    gives +pi, as the closed form's range asks.
    """
    ax, ay = jnp.abs(x), jnp.abs(y)
    swap = ay > ax
    r = jnp.where(swap, ax, ay) / jnp.where(swap, ay, ax)  # in [0, 1]
    big = r > np.tan(np.pi / 8.0)
    w = jnp.where(big, (r - 1.0) / (r + 1.0), r)
    z = w * w
    poly = jnp.zeros_like(z)
    for c in _ATAN_P:
        poly = poly * z + c
    a = w + w * z * poly
    a = jnp.where(big, np.pi / 4.0 + a, a)
    a = jnp.where(swap, np.pi / 2.0 - a, a)
    a = jnp.where(x < 0.0, np.pi - a, a)
    return jnp.where(y < 0.0, -a, a)


def _turn_angle(u, v):
    """The theta with ``R(theta) u`` parallel to ``v`` (Eq 3: alpha - beta), in (-pi, pi],
    and its cosine and sine.

    ``u, v``: (2,) direction vectors. One ``atan2(cross, dot)`` replaces the two
    arctangents of ratios, so the quadrant is right and there is no division (in float32
    it is :func:`_atan2_float32`); ``cos`` and ``sin`` are ``(dot, cross) / |(dot,
    cross)|``, no further transcendental. Returns ``(theta, cos, sin, ok)``; where a vector
    has zero length (``ok`` False) theta is 0, cos 1, sin 0, with zero gradient: the
    arguments are swapped for ``(0, 1)`` before use (double-``where``).
    """
    cross = v[0] * u[1] - v[1] * u[0]  # sin(alpha - beta) |u||v|
    dot = u[0] * v[0] + u[1] * v[1]  # cos(alpha - beta) |u||v|
    ok = jnp.any(u != 0.0) & jnp.any(v != 0.0)
    cross, dot = jnp.where(ok, cross, 0.0), jnp.where(ok, dot, 1.0)
    if jnp.finfo(cross.dtype).bits <= 32:
        theta = _atan2_float32(cross, dot)
    else:
        theta = jnp.arctan2(cross, dot)
    # atan2(-0.0, negative) is -pi (and so, once rounded, is atan2(-tiny, negative)): fold it
    # to +pi so that the range is (-pi, pi].
    theta = jnp.where(theta == -jnp.pi, jnp.pi, theta)
    norm = jnp.sqrt(cross**2 + dot**2)  # |u||v| > 0 where ok
    return jnp.where(ok, theta, 0.0), dot / norm, cross / norm, ok


def _rotate(c, s, p):
    """``R(theta) p`` from ``cos``, ``sin`` (Eqs 4-5; as :func:`cassi_fit.rigid.apply`)."""
    return jnp.stack([c * p[0] + s * p[1], -s * p[0] + c * p[1]])


def _fixed_point(c, s, t):
    """The motion's fixed point ``q = (I - R)^-1 t`` from ``cos``, ``sin`` (Eqs 6-7, as
    :func:`cassi_fit.rigid.pivot`) and whether it exists (theta != 0).

    ``(I - R)^-1 t = (t + k t_perp) / 2`` with ``t_perp = (ty, -tx)`` and ``k = cot(theta/2)
    = sin / (1 - cos) = (1 + cos) / sin``: the second form where ``cos >= 0`` (no
    cancellation near theta = 0, where the pivot recedes to infinity as ``1/theta``), the
    first elsewhere. At theta = 0 (``sin = 0``, ``cos > 0``) it is undefined: (0, 0) with
    zero gradient (double-``where``)."""
    near = c >= 0.0
    den = jnp.where(near, s, 1.0 - c)
    defined = den != 0.0
    k = jnp.where(near, 1.0 + c, s) / jnp.where(defined, den, 1.0)
    q = 0.5 * (t + k * jnp.stack([t[1], -t[0]]))
    return jnp.where(defined, q, jnp.zeros_like(q)), defined


def _finish(theta, c, s, t, ok, finite):
    """Assemble a :class:`JawMotion` from ``(theta, cos, sin, t)`` and the validity flags."""
    good = ok & finite
    theta = jnp.where(good, theta, 0.0)
    c, s = jnp.where(good, c, 1.0), jnp.where(good, s, 0.0)
    t = jnp.where(good, t, jnp.zeros_like(t))
    pivot, defined = _fixed_point(c, s, t)
    defined = defined & good
    status = jnp.where(
        ~finite,
        int(Status.NON_FINITE),
        jnp.where(~ok, int(Status.DEGENERATE),
                  jnp.where(defined, int(Status.OK), int(Status.PIVOT_UNDEFINED))),
    )
    status = jnp.asarray(status, jnp.int32)
    return JawMotion(theta, t, jnp.where(defined, pivot, 0.0), defined, status)


def closed_form(reference: Float[Array, "2 2"], current: Float[Array, "2 2"]) -> JawMotion:
    """The paper's motion (Eqs 1-3, 6-7), numerically sound. One frame; vmap over frames.

    reference, current: (2, 2) mm, rows [MNI, MNM]. theta = alpha - beta from the jaw line
    (wrapped to (-pi, pi]); the translation maps the MNI pellet exactly,
    ``t = p1' - R(theta) p1``, as Eqs 6-7 do; the pivot is the motion's fixed point.
    At theta = 0 the pivot is undefined (status 1; value (0, 0), zero gradient), the motion
    stays finite and differentiable. Coincident jaw pellets give status 2, a NaN or
    infinite coordinate status 3; in both cases theta = 0, t = 0, never NaN.
    """
    reference, current = jnp.asarray(reference), jnp.asarray(current)
    reference, current, finite = _safe_inputs(reference, current)
    theta, c, s, ok = _turn_angle(reference[0] - reference[1], current[0] - current[1])
    t = current[0] - _rotate(c, s, reference[0])
    return _finish(theta, c, s, t, ok, finite)


def procrustes(reference: Float[Array, "2 2"], current: Float[Array, "2 2"]) -> JawMotion:
    """The least-squares rigid motion of both jaw points (Kabsch), one frame.

    Minimises ``sum_i |R(theta) p_i + t - p_i'|^2`` over the two pellets: theta turns the
    centred reference points onto the centred current ones (for two points that is the
    jaw-line angle of Eq 3) and ``t`` maps the centroid onto the centroid. Same status
    rules as :func:`closed_form`.
    """
    reference, current = jnp.asarray(reference), jnp.asarray(current)
    reference, current, finite = _safe_inputs(reference, current)
    c_ref, c_cur = jnp.mean(reference, axis=0), jnp.mean(current, axis=0)
    theta, c, s, ok = _turn_angle(reference[0] - c_ref, current[0] - c_cur)
    t = c_cur - _rotate(c, s, c_ref)
    return _finish(theta, c, s, t, ok, finite)


@exported
def _closed_form_frames(reference, current):
    return jax.vmap(closed_form, in_axes=(None, 0))(reference, current)


@exported
def _procrustes_frames(reference, current):
    return jax.vmap(procrustes, in_axes=(None, 0))(reference, current)


def closed_form_frames(reference: Float[Array, "2 2"], current: Float[Array, "n 2 2"]) -> JawMotion:
    """:func:`closed_form` for every frame of ``current`` (n, 2, 2) mm from one ``reference``
    (2, 2) mm, compiled once per shape and dtype: a :class:`JawMotion` whose leaves have a
    leading ``n`` axis (theta (n,) rad, translation (n, 2) mm, pivot (n, 2) mm,
    pivot_defined (n,), status (n,)). The toolkit's one compiled closed form."""
    return _closed_form_frames(reference, current)  # jit takes numpy and JAX arrays


def procrustes_frames(reference: Float[Array, "2 2"], current: Float[Array, "n 2 2"]) -> JawMotion:
    """:func:`procrustes` for every frame of ``current`` (n, 2, 2) mm, compiled once per shape
    and dtype; leaves as :func:`closed_form_frames`."""
    return _procrustes_frames(reference, current)
