"""Frames in batches: from scaled pellets to face parameters and vertices, compiled once.

Both pipeline stages use this module: :mod:`cassi_fit.initialize` (the rest pellet sites
and the first valid frame's parameters) and :mod:`cassi_fit.animate` (every frame), so
that initialization does not depend on animation.

* :func:`frame_params`: CASSI's parameters of a batch of frames (paper section 2, Table 1):
  tongue ``#55-#62 = scaled T1..T4 - the model's rest sites``, upper lip ``#63/#64``
  likewise, lower lip ``#65/#66 = scaled LL - where the jaw motion took the model's LL
  site``, the jaw ``= compose(motion since the first frame, initial motion)``.
  A tongue pellet the recording never tracks (XRMB files that lose T4; EMA corpora with
  three tongue sensors) is filled in from the tracked ones along the tongue
  (:func:`tongue_fill`), so the model's tongue follows the sensors it has. An
  articulograph's tongue sensors, glued elsewhere than XRMB's pellet sites, drive the
  sites through :func:`tongue_drive` from where they sit on the tongue
  (``SubjectState.tongue_sites``), so the tongue passes through each sensor there.
* :func:`batch_geometry`: the vertices and model pellet sites of a batch (one compiled,
  vmapped ``deform.deform``); each frame's posed vertices are handed down to
  ``collide.settle`` (the penetration depths, and with collisions the projection keeping
  the tongue's volume), which hands back the settled vertices.
* :func:`frame_bucket`, :func:`pad_frames`: frames are padded to a few sizes so that
  recordings of similar length (and different strides) share compiled functions.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Shaped

from . import rigid
from ._exported import exported
from .options import COLLISION_MODES, check_choice
from .pellets import LL, PELLET_NAMES, T1, T4, UL

# Frames are padded (64, 128, 256, 512, then multiples of 256) before the batched calls,
# so that recordings of similar length (and different strides) share compiled functions.
_FRAME_BUCKET = 64
_COLLISION_BATCH = 32


def frame_bucket(m: int) -> int:
    """Padded batch size for ``m`` frames: 64, 128, 256, 512, then multiples of 256."""
    if m > 8 * _FRAME_BUCKET:
        return 4 * _FRAME_BUCKET * math.ceil(m / (4 * _FRAME_BUCKET))
    return _FRAME_BUCKET * 2 ** max(math.ceil(math.log2(max(m, 1) / _FRAME_BUCKET)), 0)


def pad_frames(x: Shaped[ArrayLike, "m ..."], size: int) -> Shaped[Array, "size ..."]:
    """``x (m, ...)`` with its last row repeated along axis 0 up to ``size`` rows.

    Concrete arrays are padded in numpy, so that different ``m`` compile nothing."""
    if isinstance(x, jax.core.Tracer):
        return jnp.concatenate([x, jnp.repeat(x[-1:], size - x.shape[0], axis=0)])
    x = np.asarray(x)
    # device_put, not jnp.asarray: the latter copies through a function compiled per shape
    return jax.device_put(np.concatenate([x, np.repeat(x[-1:], size - x.shape[0], axis=0)]))


def unpad(tree: object, m: int) -> object:
    """The first ``m`` frames of every leaf (sliced in numpy: no compilation per ``m``)."""
    return jax.tree.map(lambda x: jax.device_put(np.asarray(x)[:m]), tree)


def tongue_fill(tracked: Bool[np.ndarray, " 4"],
                site_s: Float[np.ndarray, " 4"]) -> Float[np.ndarray, "4 4"]:
    """The matrix ``W (4, 4)`` that fills in the displacements of the tongue sites T1..T4
    a recording never tracks from those it does: ``filled = W @ displacement``.

    ``tracked (4,)``: which of T1..T4 the recording tracks; ``site_s (4,)`` mm: the
    model's arc lengths of the four sites along the tongue. A tracked site keeps its own
    displacement; a missing site between two tracked ones gets the linear interpolation
    in arc length; a missing site beyond the last (or before the first) tracked one gets
    that one's displacement (the tongue's back or tip follows its nearest sensor: with
    EMA's tip, blade and dorsum sensors on T1..T3, T4 moves with the dorsum). With no
    tongue pellet at all, every row is zero (the tongue stays at rest)."""
    tracked = np.asarray(tracked, bool)
    site_s = np.asarray(site_s, float)
    w = np.zeros((4, 4))
    have = np.flatnonzero(tracked)
    if have.size:
        w[:, have] = _along_the_tongue(site_s, site_s[have])
    return w


def _along_the_tongue(site_s: Float[np.ndarray, " 4"],
                      sensor_s: Float[np.ndarray, " n"]) -> Float[np.ndarray, "4 n"]:
    """``(4, n)``: each site's displacement from ``n`` sensors at the arc lengths
    ``sensor_s`` (increasing), linear in arc length between the two around it, the
    nearest one's beyond the first or last; a sensor at a site gives it its own."""
    fill = np.zeros((site_s.size, sensor_s.size))
    for k in range(site_s.size):
        before = np.flatnonzero(sensor_s <= site_s[k])
        after = np.flatnonzero(sensor_s >= site_s[k])
        if before.size and after.size and before[-1] != after[0]:
            i, j = before[-1], after[0]
            u = (site_s[k] - sensor_s[i]) / (sensor_s[j] - sensor_s[i])
            fill[k, i], fill[k, j] = 1.0 - u, u
        else:
            fill[k, before[-1] if before.size else after[0]] = 1.0
    return fill


def tongue_drive(tracked: Bool[np.ndarray, " 4"], site_s: Float[np.ndarray, " 4"],
                 sensor_s: Float[np.ndarray, " 4"], anchor_s: float,
                 anchor: str = "follow") -> Float[np.ndarray, "4 4"]:
    """The matrix ``W (4, 4)`` that drives the tongue sites T1..T4 from tongue sensors
    sitting elsewhere on the tongue: ``site displacements = W @ sensor displacements``.

    ``sensor_s (4,)`` mm: the arc lengths at which the recording's T1..T4 sensors sit
    (those of untracked roles are ignored; the tracked ones increasing); ``site_s``,
    ``tracked``: as :func:`tongue_fill`; ``anchor_s``, ``anchor``: the tongue's back
    anchor (``tongue.tongue_displacement``). Each site first gets the displacement of
    the sensors around it, linear in arc length (the nearest sensor's beyond the first or
    last: :func:`tongue_fill`'s rule with the sensors where they sit); then the least
    change to the sites (least squares) that makes the tongue's displacement field
    (``tongue_displacement``, linear in the sites' displacements) take each sensor's own
    displacement at that sensor's arc length, so the tongue passes through every sensor
    as it does through XRMB's pellets. Sensors at the sites give :func:`tongue_fill`'s
    matrix."""
    from .tongue import tongue_displacement

    tracked = np.asarray(tracked, bool)
    have = np.flatnonzero(tracked)
    w = np.zeros((4, 4))
    if have.size == 0:
        return w
    sensor_s = np.asarray(sensor_s, float)[have]
    site_s = np.asarray(site_s, float)
    fill = _along_the_tongue(site_s, sensor_s)
    basis = np.zeros((have.size, 4))  # the field at the sensors per unit site displacement
    for k in range(4):
        unit = np.zeros((4, 2))
        unit[k, 0] = 1.0
        basis[:, k] = np.asarray(tongue_displacement(
            jnp.asarray(sensor_s), jnp.asarray(site_s), jnp.asarray(unit), anchor_s,
            anchor), np.float64)[:, 0]
    w[:, have] = fill + np.linalg.pinv(basis) @ (np.eye(have.size) - basis @ fill)
    return w


def _frame_inputs(state: eqx.Module) -> dict:
    """The arrays one frame's parameters depend on (all arrays: safe to pass to jit)."""
    model, spec = state.model, state.spec
    tracked = np.array([name in state.tracked_pellets for name in PELLET_NAMES])
    weights = model.jaw_weights[spec.jaw_weights]
    from .deform import tongue_site_arcs

    site_s = tongue_site_arcs(model)
    sensor_s = getattr(state, "tongue_sites", None)
    if sensor_s is None:  # XRMB's pellets (and CASSI mode): the sensors at the sites
        fill = tongue_fill(tracked[T1 : T4 + 1], site_s)
    else:  # an articulograph's tongue sensors, where they sit on the tongue
        fill = tongue_drive(tracked[T1 : T4 + 1], site_s,
                            np.array([np.nan if x is None else x for x in sensor_s]),
                            float(model.measures["tongue_anchor_s"]), spec.tongue_anchor)
    # made in numpy and put on the device: jnp.asarray and indexing would each run (and
    # load from the compilation cache) an XLA computation per shape in every process
    dtype = jnp.asarray(state.rest_pellets).dtype
    return {
        "rest": state.rest_pellets,
        "tracked": jax.device_put(tracked),
        "tongue_fill": jax.device_put(np.asarray(fill, dtype)),
        "initial_jaw": state.initial_jaw,
        "conformation": state.conformation,
        "w_ll": jax.device_put(np.asarray(weights)[model.landmarks["LL"]]),
    }


def _frame_params_of(inputs: dict, scaled, motion_since_first):
    """The FaceParams of one frame. ``scaled (8, 2)`` mm: the pellets times ``p / d``
    (values of never-tracked pellets are ignored); ``motion_since_first``: ``(theta, t)``
    of the jaw from the first valid line to this one."""
    rest, tracked = inputs["rest"], inputs["tracked"]
    # never-tracked pellets sit at the model's rest sites: their own parameters are 0
    scaled = jnp.where(tracked[:, None], jnp.nan_to_num(scaled), rest)
    motion = rigid.compose(motion_since_first, inputs["initial_jaw"])
    ll_after_jaw = rigid.apply(*rigid.fractional(motion, inputs["w_ll"]), rest[LL])
    lower_lip = jnp.where(tracked[LL], scaled[LL] - ll_after_jaw, 0.0)
    conformation = inputs["conformation"]
    dtype = jnp.asarray(conformation.tongue).dtype
    tongue = inputs["tongue_fill"] @ (scaled[T1 : T4 + 1] - rest[T1 : T4 + 1])
    values = (motion[0], motion[1], tongue, scaled[UL] - rest[UL], lower_lip)
    return eqx.tree_at(
        lambda p: (p.jaw_theta, p.jaw_translation, p.tongue, p.upper_lip, p.lower_lip),
        conformation,
        tuple(jnp.asarray(v, dtype) for v in values),
    )


@exported  # a new process loads it instead of tracing it (cassi_fit._exported)
def _batched_params(inputs, scaled, theta, translation):
    return jax.vmap(lambda s, a, t: _frame_params_of(inputs, s, (a, t)))(scaled, theta, translation)


def frame_params(
    state: eqx.Module,
    scaled: Float[Array, "m 8 2"],
    theta: Float[Array, " m"],
    translation: Float[Array, "m 2"],
) -> eqx.Module:
    """FaceParams with a leading frame axis ``(m,)`` for the ``SubjectState`` ``state``:
    ``scaled (m, 8, 2)`` mm, the pellets times ``p / d``; ``theta (m,)`` rad and
    ``translation (m, 2)`` mm, the jaw motion since the first valid line. One compiled
    call per frame count ``m`` (pass padded frames, :func:`pad_frames`)."""
    inputs = _frame_inputs(state)
    return _batched_params(inputs, scaled, theta, translation)


@exported
def _geometry_kernel(model, params, style, collisions, report):
    """Compiled once per (model topology, frame count, the static options); ``style``:
    the ``deform.deform`` keywords as a tuple of pairs (hashable). Exported
    (:mod:`cassi_fit._exported`): with the penetration depths measured its trace takes
    longer than its XLA executable's load from the compilation cache, in every process."""
    from . import collide
    from .deform import deform, model_pellets

    def one(p):
        vertices = deform(model, p, **dict(style))
        vertices, before, after = collide.settle(model, vertices, collisions=collisions,
                                                 measure=report,
                                                 tongue_shape=dict(style)["tongue_shape"])
        return vertices, model_pellets(model, vertices), before, after

    if not report and collisions == "off":
        return jax.vmap(one)(params)
    # the collision tests' per-vertex, per-segment intermediates stay in cache when
    # frames go through in small batches (3-4x faster than one vmap over all)
    return jax.lax.map(one, params, batch_size=_COLLISION_BATCH)


def batch_geometry(
    model: eqx.Module, params: eqx.Module, *, jaw_weights: str = "cassi",
    tongue_anchor: str = "follow", collisions: str = "off", report: bool = False,
    tongue_shape: str = "thick", lip_rounding: bool = True,
) -> tuple:
    """All frames of ``params`` (FaceParams with a leading ``(m,)`` axis) in one compiled
    call: vertices ``(m, V, 3)`` and model pellet sites ``(m, 8, 2)`` mm; with ``report``,
    also the per-frame penetration depths before and after projection (two dicts of
    ``(m,)`` mm, keys ``collide.REPORT_KEYS``). ``m`` is not padded here. ``jaw_weights``,
    ``tongue_anchor``, ``tongue_shape``, ``lip_rounding``: as ``deform.deform``. A model
    without collision data (``collide.has_collision_data``) raises ``CassiError`` when
    ``collisions`` or ``report`` asks for them."""
    check_choice("collisions", collisions, COLLISION_MODES)
    if collisions != "off" or report:  # a model without collision data: one clear error
        from .collide import require_collision_data

        require_collision_data(model)
    style = (("jaw_weights", jaw_weights), ("tongue_anchor", tongue_anchor),
             ("tongue_shape", tongue_shape), ("lip_rounding", bool(lip_rounding)))
    out = _geometry_kernel(model, params, style, collisions, bool(report))
    return out if report else out[:2]


def geometry(
    state: eqx.Module, params: eqx.Module, collisions: str = "off"
) -> tuple[Float[Array, "m V 3"], Float[Array, "m 8 2"]]:
    """Vertices ``(m, V, 3)`` and model pellet sites ``(m, 8, 2)`` mm of a batch of params
    for the ``SubjectState`` ``state``, in one compiled call (frames padded to a size
    bucket so the compilation is reused); ``collisions="project"`` pushes the tongue and
    lips out of the teeth and palate."""
    check_choice("collisions", collisions, COLLISION_MODES)
    m = int(jnp.shape(params.jaw_theta)[0])
    batch = jax.tree.map(lambda x: pad_frames(x, frame_bucket(m)), params)
    vertices, sites = batch_geometry(state.model, batch, collisions=collisions,
                                     **state.spec.deform_style)
    return unpad((vertices, sites), m)
