"""CASSI's animation: the fitted face moved by every data line (paper section 2).

Initialization (once per recording) lives in :mod:`cassi_fit.initialize`. Animation
(:func:`animate`), every ``stride``-th data line from the first valid one: tongue
``#55-#62 = scaled T1..T4 - the model's rest sites``, upper lip ``#63/#64`` likewise,
lower lip ``#65/#66 = scaled LL - where the jaw motion took the model's LL site``; the jaw
``= compose(motion since the first frame, initial motion)`` with the motion since the first
frame from ``jaw_fit.fit_jaw`` (reference = the first valid frame's scaled jaw pellets).
The vertices of all frames come from one compiled, vmapped call of ``deform.deform``.

Gaps (:mod:`cassi_fit.gaps`). Untracked and mistracked values are never passed on: they
are held or interpolated per pellet and flagged in ``Animation.repaired (m, 8)`` and
``Animation.frame_status (m,)`` (``cassi_fit.status.Status`` values: ``OK``, ``HELD``,
``INTERPOLATED``, ``MISTRACKED``). A recording whose jaw pellets are never tracked raises
``MissingDataError``.

Compilation. The compiled functions here are module-level ``eqx.filter_jit`` functions
that take the face model as an argument: its :class:`~cassi_fit.face_model.Topology` is a
hashable static field, so a second recording with the same model and the same frame
bucket (:func:`frame_bucket`) reuses every compilation.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Shaped

from . import rigid
from .dataset import Recording
from .errors import CassiError, MissingDataError
from .gaps import bad_values, frame_status, repair
from .jaw import closed_form
from .options import COLLISION_MODES, GAP_POLICIES, JAW_METHODS, check_choice
from .pellets import JAW_INDEX, LL, PELLET_NAMES, T1, T4, UL

# Deprecated alias (video.py and the animate notebook read it until the merge): frame
# statuses are ``cassi_fit.status.Status`` values now; print ``Status(x).label``.
# Frames are padded (64, 128, 256, 512, then multiples of 256) before the batched calls,
# so that recordings of similar length (and different strides) share compiled functions.
_FRAME_BUCKET = 64
_COLLISION_BATCH = 32
#: Volume-restoring passes after the collision projection (``_project_keeping_volume``).
TONGUE_VOLUME_PASSES = 3


class Animation(eqx.Module):
    """Per-frame result of :func:`animate`; ``m`` frames, ``V`` vertices.

    times ``(m,)`` s; frame_index ``(m,)`` data-line indices; params: a ``FaceParams``
    whose leaves carry a leading ``(m,)`` axis; vertices ``(m, V, 3)`` mm;
    pellets_measured ``(m, 8, 2)`` mm, scaled by ``p / d`` and repaired; pellets_model
    ``(m, 8, 2)`` mm, where the model puts its pellet sites; repaired ``(m, 8)`` bool;
    mistracked ``(m, 8)`` bool; frame_status ``(m,)`` int (``status.Status`` values);
    jaw_status ``(m,)`` int (``status.Status`` values); penetration: ``collide.REPORT_KEYS``
    -> ``(m,)`` mm, the deepest point of each kind per frame before any projection (empty
    if the model has no collision data); penetration_after: the same after projection
    (equal to ``penetration`` when collisions are off); stride, jaw method and collision
    mode, static.
    """

    times: np.ndarray
    frame_index: np.ndarray
    params: eqx.Module
    vertices: jax.Array
    pellets_measured: np.ndarray
    pellets_model: jax.Array
    repaired: np.ndarray
    mistracked: np.ndarray
    frame_status: np.ndarray
    jaw_status: np.ndarray
    penetration: dict
    penetration_after: dict
    stride: int = eqx.field(static=True)
    jaw_method: str = eqx.field(static=True)
    collisions: str = eqx.field(static=True, default="off")

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])


def _frame_inputs(state) -> dict:
    """The arrays one frame's parameters depend on (all arrays: safe to pass to jit)."""
    tracked = np.array([name in state.tracked_pellets for name in PELLET_NAMES])
    weights = state.model.jaw_weights[state.jaw_weights]
    return {
        "rest": state.rest_pellets,
        "tracked": jnp.asarray(tracked),
        "initial_jaw": state.initial_jaw,
        "conformation": state.conformation,
        "w_ll": jnp.asarray(weights)[state.model.landmarks["LL"]],
    }


def _frame_params_of(inputs: dict, scaled, motion_since_first):
    """The FaceParams of one frame. ``scaled (8, 2)`` mm: the pellets times ``p / d``
    (values of never-tracked pellets are ignored); ``motion_since_first``: ``(theta, t)``
    of the jaw from the first valid line to this one."""
    rest, tracked = inputs["rest"], inputs["tracked"]
    # never-tracked pellets sit at the model's rest sites: their parameters stay 0
    scaled = jnp.where(tracked[:, None], jnp.nan_to_num(scaled), rest)
    motion = rigid.compose(motion_since_first, inputs["initial_jaw"])
    ll_after_jaw = rigid.apply(*rigid.fractional(motion, inputs["w_ll"]), rest[LL])
    lower_lip = jnp.where(tracked[LL], scaled[LL] - ll_after_jaw, 0.0)
    conformation = inputs["conformation"]
    dtype = jnp.asarray(conformation.tongue).dtype
    values = (
        motion[0],
        motion[1],
        scaled[T1 : T4 + 1] - rest[T1 : T4 + 1],
        scaled[UL] - rest[UL],
        lower_lip,
    )
    return eqx.tree_at(
        lambda p: (p.jaw_theta, p.jaw_translation, p.tongue, p.upper_lip, p.lower_lip),
        conformation,
        tuple(jnp.asarray(v, dtype) for v in values),
    )


@jax.jit
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
    return _batched_params(_frame_inputs(state), scaled, theta, translation)


def _project_keeping_volume(model, vertices, tongue_shape):
    """``collide.project``; for the thick tongue, then ``TONGUE_VOLUME_PASSES`` times:
    the tongue's volume restored to what it was before the projection
    (``tongue.keep_volume``: its width scaled) and projected again. Pushing the tongue
    out of the teeth and the palate takes up to about 6 % of its volume off; each pass
    gives back most of what is left (docs/TONGUE.md)."""
    from . import collide
    from .tongue import closed_mesh_volume, keep_volume, tongue_faces

    if tongue_shape != "thick":  # CASSI's flat sheet has no volume to keep
        return collide.project(model, vertices)
    volume = closed_mesh_volume(vertices, tongue_faces(model))
    vertices = collide.project(model, vertices)
    for _ in range(TONGUE_VOLUME_PASSES):
        vertices = collide.project(model, keep_volume(model, vertices, volume))
    return vertices


@eqx.filter_jit
def _geometry_kernel(model, params, style, collisions, report):
    """Compiled once per (model topology, frame count, the static options); ``style``:
    the ``deform.deform`` keywords as a tuple of pairs (hashable)."""
    from . import collide
    from .deform import deform, model_pellets

    def one(p):
        vertices = deform(model, p, **dict(style))
        before = collide.report(model, vertices) if report else None
        if collisions == "project":
            vertices = _project_keeping_volume(model, vertices, dict(style)["tongue_shape"])
        after = before
        if report and collisions == "project":
            after = collide.report(model, vertices)
        return vertices, model_pellets(model, vertices), before, after

    if not report and collisions == "off":
        return jax.vmap(one)(params)
    # the collision tests' per-vertex, per-segment intermediates stay in cache when
    # frames go through in small batches (3-4x faster than one vmap over all)
    return jax.lax.map(one, params, batch_size=_COLLISION_BATCH)


def batch_geometry(
    model: eqx.Module, params: eqx.Module, *, jaw_weights: str = "cassi", tongue_anchor: str = "follow",
    collisions: str = "off", report: bool = False, tongue_shape: str = "thick",
    lip_rounding: bool = True,
) -> tuple:
    """All frames of ``params`` (FaceParams with a leading ``(m,)`` axis) in one compiled
    call: vertices ``(m, V, 3)`` and model pellet sites ``(m, 8, 2)`` mm; with ``report``,
    also the per-frame penetration depths before and after projection (two dicts of
    ``(m,)`` mm, keys ``collide.REPORT_KEYS``). ``m`` is not padded here. ``jaw_weights``,
    ``tongue_anchor``, ``tongue_shape``, ``lip_rounding``: as ``deform.deform``."""
    check_choice("collisions", collisions, COLLISION_MODES)
    style = (("jaw_weights", jaw_weights), ("tongue_anchor", tongue_anchor),
             ("tongue_shape", tongue_shape), ("lip_rounding", bool(lip_rounding)))
    out = _geometry_kernel(model, params, style, collisions, bool(report))
    return out if report else out[:2]


def style_of(state: eqx.Module) -> dict:
    """The ``deform.deform`` keywords a ``SubjectState`` was initialized with."""
    return {"jaw_weights": state.jaw_weights, "tongue_anchor": state.tongue_anchor,
            "tongue_shape": getattr(state, "tongue_shape", "thick"),
            "lip_rounding": bool(getattr(state, "lip_rounding", True))}


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


def _unpad(tree, m: int):
    """The first ``m`` frames of every leaf (sliced in numpy: no compilation per ``m``)."""
    return jax.tree.map(lambda x: jax.device_put(np.asarray(x)[:m]), tree)


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
    vertices, sites = batch_geometry(state.model, batch, collisions=collisions, **style_of(state))
    return _unpad((vertices, sites), m)


@jax.jit
def _closed_form_batch(reference, current):
    fit = jax.vmap(closed_form, in_axes=(None, 0))(reference, current)
    return fit.theta, fit.translation, fit.status


def _jaw_since_first(state, jaw_pellets, method, solver, size):
    """``(theta (size,), t (size, 2), status (m,))``: the jaw from the first valid line to
    each frame, by ``method``, padded to ``size`` frames; ``jaw_pellets (m, 2, 2)`` scaled
    mm, rows [MNI, MNM]. The closed form is per frame, so it runs on the padded frames
    (one compilation per size bucket); a fit sees only the real frames."""
    m = jaw_pellets.shape[0]
    if method == "closed-form":
        theta, t, status = _closed_form_batch(state.reference_jaw, pad_frames(jaw_pellets, size))
        return theta, t, np.asarray(status)[:m]
    from .jaw_fit import fit_jaw

    kwargs = {} if solver is None else {"solver": solver}
    fit = fit_jaw(state.reference_jaw, jnp.asarray(jaw_pellets), method=method, **kwargs)
    return pad_frames(fit.theta, size), pad_frames(fit.translation, size), np.asarray(fit.status)


def animate(
    state: eqx.Module,
    recording: Recording,
    *,
    jaw: str = "closed-form",
    solver: object = None,
    stride: int = 1,
    gap_policy: str | None = None,
    collisions: str = "off",
) -> Animation:
    """Animate the face over ``recording`` (every ``stride``-th data line from the first
    valid one, ``ceil((n - first) / stride)`` frames) with the ``SubjectState`` ``state``
    (``cassi_fit.initialize.initialize``).

    ``jaw``: one of ``options.JAW_METHODS`` (the paper's closed form, or a fit from
    ``jaw_fit``, which gets ``solver`` if given). ``gap_policy``: ``"hold"`` or
    ``"interpolate"`` (default: the state's). ``collisions``: ``"off"`` (CASSI: parts may
    pass through each other) or ``"project"`` (the tongue pushed out of the teeth and the
    palate, the lips out of the teeth, every frame; ``cassi_fit.collide``). Either way the
    penetration depths of every frame are measured and returned. Returns an
    :class:`Animation`. An unknown option raises ``InvalidChoiceError``.
    """
    if isinstance(jaw, str):
        check_choice("jaw method", jaw, JAW_METHODS)
    check_choice("collisions", collisions, COLLISION_MODES)
    policy = state.gap_policy if gap_policy is None else gap_policy
    check_choice("gap policy", policy, GAP_POLICIES)
    if int(stride) != stride or stride < 1:
        raise CassiError(f"stride must be a positive integer, got {stride}")
    track = recording.track
    untracked, mistracked = bad_values(track)
    bad = untracked | mistracked
    positions = repair(np.asarray(track.positions), bad, policy)
    rows = np.arange(state.first_frame, track.times.shape[0], int(stride))
    scaled = state.scale * positions[rows]
    if not (~bad[:, list(JAW_INDEX)].any(axis=1)).any():
        raise MissingDataError(f"{state.source}: the jaw pellets are never tracked well")
    m, size = len(rows), frame_bucket(len(rows))
    theta, translation, jaw_status = _jaw_since_first(
        state, scaled[:, list(JAW_INDEX)], jaw, solver, size
    )
    params = frame_params(state, pad_frames(scaled, size), theta, translation)
    from .collide import has_collision_data, require_collision_data

    report = has_collision_data(state.model)
    if collisions != "off":
        require_collision_data(state.model)
    out = batch_geometry(state.model, params, collisions=collisions, report=report,
                         **style_of(state))
    vertices, sites, params = _unpad((out[0], out[1], params), m)
    before, after = ({k: np.asarray(v)[:m] for k, v in d.items()} for d in out[2:]) if report \
        else ({}, {})
    tracked = np.array([name in state.tracked_pellets for name in PELLET_NAMES])
    return Animation(
        times=np.asarray(track.times)[rows],
        frame_index=rows,
        params=params,
        vertices=vertices,
        pellets_measured=np.where(tracked[:, None], scaled, np.nan),
        pellets_model=sites,
        repaired=bad[rows] & tracked,
        mistracked=mistracked[rows],
        frame_status=frame_status(untracked[rows] & tracked, mistracked[rows], policy),
        jaw_status=jaw_status,
        penetration=before,
        penetration_after=after,
        stride=int(stride),
        jaw_method=jaw if isinstance(jaw, str) else type(jaw).__name__,
        collisions=collisions,
    )
