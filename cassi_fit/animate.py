"""CASSI's pipeline: fit the face to a subject once, then animate it from every data line.

Initialization (paper section 2; :func:`initialize`), once per recording:

1. the first valid line: the first frame in which every pellet the file ever tracks is
   tracked (a pellet the file never tracks stays at the model's rest site, flagged);
2. pellets to model: every coordinate scaled by ``p / d``, ``d = |MNI - MNM|`` of the
   subject in that frame, ``p`` the same distance between the model's jaw pellet sites.
   Both frames have their origin at the upper incisor tip, so no translation is needed;
3. the lower teeth and the jaw: the closed form (Eqs 1-3, 6-7, ``jaw.closed_form``) from
   the model's jaw sites to the scaled first-frame jaw pellets;
4. the palate from the scaled PAL.DAT (``palate.with_palate``; the model's own if absent);
5. the jaw's shape from the scaled Headmeasures gonion and gnathion against the model's
   gonion and gnathion, by the same closed form (rows [gnathion, gonion]);
6. beyond the paper (its future work): face and mouth width from Headmeasures, lip
   thickness per speaker (from Headmeasures, or, where the subject has only the default
   measures, from the first valid line: lip pellet ahead of the incisors), nose tip from
   the nose protrusion; tongue (#55-#62) and lips (#63-#66) from the first frame.

Animation (:func:`animate`), every ``stride``-th data line from the first valid one:
tongue ``#55-#62 = scaled T1..T4 - the model's rest sites``, upper lip ``#63/#64`` likewise,
lower lip ``#65/#66 = scaled LL - where the jaw motion took the model's LL site``; the jaw
``= compose(motion since the first frame, initial motion)`` with the motion since the first
frame from ``jaw_fit.fit_jaw`` (reference = the first valid frame's scaled jaw pellets).
The vertices of all frames come from one jitted, vmapped call of ``deform.deform``.

Gaps. Untracked values (NaN) and mistracked values (``quality.detect_mistracks``) are
never passed on: per pellet they are replaced by the last good value (``"hold"``) or by
linear interpolation between good neighbours (``"interpolate"``; the ends are held), and
flagged in ``Animation.repaired (m, 8)`` and ``Animation.frame_status (m,)``:
``FRAME_OK`` 0, ``FRAME_HELD`` 1 (an untracked value held), ``FRAME_INTERPOLATED`` 2 (an
untracked value interpolated), ``FRAME_MISTRACKED`` 3 (a mistracked value replaced; takes
precedence). A recording whose jaw pellets are never tracked raises ``MissingDataError``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import rigid
from .errors import CassiError, DegenerateGeometryError, MissingDataError

PELLETS = ("UL", "LL", "T1", "T2", "T3", "T4", "MNI", "MNM")
UL, LL, T1, T4, MNI, MNM = 0, 1, 2, 5, 6, 7
JAW_METHODS = ("closed-form", "frame-fit", "fixed-pivot", "smooth-pivot")
GAP_POLICIES = ("hold", "interpolate")
COLLISION_MODES = ("off", "project")
CONFORMATIONS = ("measures", "cassi")

FRAME_OK, FRAME_HELD, FRAME_INTERPOLATED, FRAME_MISTRACKED = 0, 1, 2, 3
FRAME_STATUS_NAMES = {
    FRAME_OK: "ok",
    FRAME_HELD: "held",
    FRAME_INTERPOLATED: "interpolated",
    FRAME_MISTRACKED: "mistracked",
}
# Frames are padded (64, 128, 256, 512, then multiples of 256) before the batched calls,
# so that recordings of similar length (and different strides) share compiled functions.
_FRAME_BUCKET = 64


class SubjectState(eqx.Module):
    """The model fitted to one subject (the result of CASSI's initialization).

    model: the face model with the subject's palate. scale: ``p / d`` (model mm per
    subject mm). first_frame: index of the first valid data line. reference_jaw ``(2, 2)``
    mm: the scaled jaw pellets [MNI, MNM] of that line. initial_jaw: ``(theta rad,
    t (2,) mm)``, the closed-form motion from the model's jaw sites onto them.
    conformation: ``FaceParams`` of the subject's shape (jaw shape, widths, lip thickness,
    nose) with no animation; rest_pellets ``(8, 2)`` mm: the model's pellet sites in that
    shape, from which the tongue and lip parameters are measured (with a calibration, UL
    and LL raised by its ``lip_rest_offset``). initial_params: the parameters of the first
    valid frame.
    """

    model: eqx.Module
    scale: float = eqx.field(static=True)
    first_frame: int = eqx.field(static=True)
    reference_jaw: jax.Array
    initial_jaw: tuple
    conformation: eqx.Module
    rest_pellets: jax.Array
    initial_params: eqx.Module
    tracked_pellets: tuple = eqx.field(static=True)
    jaw_weights: str = eqx.field(static=True)
    tongue_anchor: str = eqx.field(static=True)
    gap_policy: str = eqx.field(static=True)
    source: str = eqx.field(static=True)


class Animation(eqx.Module):
    """Per-frame result of :func:`animate`; ``m`` frames, ``V`` vertices.

    times ``(m,)`` s; frame_index ``(m,)`` data-line indices; params: a ``FaceParams``
    whose leaves carry a leading ``(m,)`` axis; vertices ``(m, V, 3)`` mm;
    pellets_measured ``(m, 8, 2)`` mm, scaled by ``p / d`` and repaired; pellets_model
    ``(m, 8, 2)`` mm, where the model puts its pellet sites; repaired ``(m, 8)`` bool;
    mistracked ``(m, 8)`` bool; frame_status ``(m,)`` int (``FRAME_STATUS_NAMES``);
    jaw_status ``(m,)`` int (``jaw.STATUS_NAMES``); penetration: ``collide.REPORT_KEYS``
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


def _source(recording) -> str:
    path = getattr(recording, "path", None) or getattr(recording.track, "path", None)
    return str(path) if path is not None else f"{recording.subject}/{recording.task}"


# --------------------------------------------------------------------------- gaps


def _check_choice(name, value, choices):
    if value not in choices:
        raise CassiError(f"{name} must be one of {', '.join(choices)}; got {value!r}")


def bad_values(track) -> tuple[np.ndarray, np.ndarray]:
    """``(untracked, mistracked)``, each ``(n, 8)`` bool: a pellet untracked in x or y, and
    a tracked value that ``quality.detect_mistracks`` flags."""
    from .quality import detect_mistracks

    untracked = ~np.asarray(track.valid).all(axis=-1)
    mistracked = np.asarray(detect_mistracks(track), bool) & ~untracked
    return untracked, mistracked


def repair(positions, bad, policy="hold") -> np.ndarray:
    """Replace the ``bad (n, 8)`` values of ``positions (n, 8, 2)`` mm, pellet by pellet.

    ``"hold"``: the last good value before (the first good one for a leading gap);
    ``"interpolate"``: linear in the frame index between the good neighbours (held at the
    ends). A pellet with no good value at all is left NaN (the caller decides).
    """
    _check_choice("gap policy", policy, GAP_POLICIES)
    out = np.array(positions, dtype=np.float64)
    n = out.shape[0]
    frames = np.arange(n)
    for p in range(out.shape[1]):
        good = ~bad[:, p]
        if good.all() or not good.any():
            continue
        known = np.flatnonzero(good)
        if policy == "interpolate":
            for axis in range(2):
                out[:, p, axis] = np.interp(frames, known, out[known, p, axis])
        else:
            last = np.maximum.accumulate(np.where(good, frames, -1))
            source = np.where(last >= 0, last, known[0])
            out[:, p] = out[source, p]
    return out


def frame_status(untracked, mistracked, policy) -> np.ndarray:
    """``(n,)`` codes: FRAME_MISTRACKED if a value was mistracked, else FRAME_HELD or
    FRAME_INTERPOLATED (by ``policy``) if one was untracked, else FRAME_OK."""
    gap = FRAME_INTERPOLATED if policy == "interpolate" else FRAME_HELD
    status = np.where(untracked.any(axis=1), gap, FRAME_OK)
    return np.where(mistracked.any(axis=1), FRAME_MISTRACKED, status).astype(np.int32)


def first_valid_line(track, source: str) -> tuple[int, tuple[str, ...]]:
    """CASSI's first valid line: the first frame in which every pellet the file ever
    tracks is tracked. Returns ``(index, tracked pellet names)``; raises
    ``MissingDataError`` naming ``source`` if a jaw pellet is never tracked."""
    tracked_xy = np.asarray(track.valid).all(axis=-1)
    ever = tracked_xy.any(axis=0)
    missing = [PELLETS[j] for j in (MNI, MNM) if not ever[j]]
    if missing:
        raise MissingDataError(f"{source}: jaw pellet(s) {', '.join(missing)} never tracked")
    complete = tracked_xy[:, ever].all(axis=1)
    if not complete.any():
        names = ", ".join(p for p, e in zip(PELLETS, ever, strict=True) if e)
        raise MissingDataError(f"{source}: no line in which {names} are all tracked")
    return int(np.argmax(complete)), tuple(p for p, e in zip(PELLETS, ever, strict=True) if e)


# --------------------------------------------------------------------------- initialization


@jax.jit
def _closed_form_one(reference, current):
    """``jaw.closed_form`` compiled (one frame; eager dispatch of its many small ops is slow)."""
    from .jaw import closed_form

    return closed_form(reference, current)


def _xy(model, vertices, name) -> np.ndarray:
    return np.asarray(vertices)[model.landmarks[name], :2]


def _jaw_shape(model, head, scale):
    """Paper step 5: the closed form from the model's [gnathion, gonion] to the subject's
    (scaled Headmeasures), as ``(theta, t)``; neutral if degenerate."""
    reference = np.stack(
        [_xy(model, model.vertices, "gnathion"), _xy(model, model.vertices, "gonion")]
    )
    current = scale * np.array([[head.gnathion_x, head.gnathion_y], [head.gonion_x, head.gonion_y]])
    motion = _closed_form_one(jnp.asarray(reference), jnp.asarray(current))
    if int(motion.status) >= 2:
        return 0.0, np.zeros(2)
    return float(motion.theta), np.asarray(motion.translation)


def _lip_thickness(model, first, scale, head, head_is_default):
    """Millimetres added to the model's lip thickness parameters ``(upper, lower)``.

    Lip thickness as Headmeasures defines it: the lip pellet ahead of the incisor tip
    (upper: along x; lower: along the mandible's forward direction MNM -> MNI). From the
    subject's measures if it has them, else (the report's future work) from the first
    valid line, taken as a gently closed mouth, the lower incisor tip being the model's
    placed on that line's jaw pellets. Kept within [-1/2, +1] of the model's own
    thickness so that a bad first line cannot turn a lip inside out.
    """
    own = np.array([model.measures["upper_lip_thickness"], model.measures["lower_lip_thickness"]])
    v = np.asarray(model.vertices)
    lm = model.landmarks
    forward = v[lm["MNI"], :2] - v[lm["MNM"], :2]
    forward = forward / np.linalg.norm(forward)
    if not head_is_default:
        wanted = scale * np.array([head.upper_lip_thickness, head.lower_lip_thickness])
    else:
        from .calibrate import lips_ahead

        seen = lips_ahead(jnp.asarray(v[[lm["MNI"], lm["MNM"]], :2]),
                          jnp.asarray(v[lm["lower_incisor_tip"], :2]), jnp.asarray(first), scale)
        wanted = np.where(np.isfinite(seen), np.asarray(seen, np.float64), own)
    delta = np.clip(wanted - own, -0.5 * own, own)
    # the thickness parameters move the vermilion along x: the lower one counts along
    # the model's forward direction
    return delta / np.array([1.0, forward[0]])


def _conformation(model, recording, first, scale, mode="measures"):
    """FaceParams of the subject's shape (no animation); see the module docstring, step
    6. ``mode="cassi"``: only what the paper did (the jaw shape from gonion/gnathion)."""
    from .deform import default_params

    head, default = recording.head, bool(recording.head_is_default)
    params = default_params(model)
    changes = {}
    if mode == "measures":
        upper, lower = _lip_thickness(model, first, scale, head, default)
        changes.update(upper_lip_thickness=upper, lower_lip_thickness=lower)
    if not default:
        theta, t = _jaw_shape(model, head, scale)
        changes.update(jaw_shape_theta=theta, jaw_shape_translation=t)
        if mode == "measures":
            nose = scale * head.nose_protrusion - model.measures["nose_protrusion"]
            changes.update(
                face_width=scale * head.face_width / model.measures["face_width"],
                mouth_width=scale * head.mouth_width / model.measures["mouth_width"],
                nose_tip=np.array([nose, 0.0]),
            )
    if not changes:
        return params
    names = tuple(changes)
    values = tuple(jnp.asarray(changes[k], jnp.asarray(getattr(params, k)).dtype) for k in names)
    return eqx.tree_at(lambda p: tuple(getattr(p, k) for k in names), params, values)


def initialize(
    recording,
    model=None,
    *,
    calibration=None,
    jaw_weights="cassi",
    tongue_anchor="follow",
    gap_policy="hold",
) -> SubjectState:
    """Fit the face model to the subject of ``recording`` (CASSI's initialization).

    ``recording``: a ``dataset.Recording``. ``model``: a ``FaceModel`` (default
    ``load_model()``). ``calibration``: ``None`` (the subject's shape from its
    Headmeasures and first valid line, step 6 of the module docstring), ``"cassi"`` (only
    what the paper did: the jaw shape from gonion and gnathion), or a
    ``calibrate.Calibration`` of this subject (its scale and fitted shape; ``cassi
    calibrate``). Returns a :class:`SubjectState`; see the module docstring for the
    steps. Raises ``MissingDataError`` (jaw pellets never tracked),
    ``DegenerateGeometryError`` (coincident jaw pellets on the first valid line) or
    ``CassiError`` (a calibration of another subject).
    """
    from .deform import model_pellets
    from .face_model import load_model
    from .palate import with_palate

    _check_choice("jaw weights", jaw_weights, ("cassi", "parke"))
    _check_choice("tongue anchor", tongue_anchor, ("fixed", "follow", "none"))
    _check_choice("gap policy", gap_policy, GAP_POLICIES)
    source = _source(recording)
    model = load_model() if model is None else model
    track = recording.track
    first, tracked = first_valid_line(track, source)
    pellets = np.asarray(track.positions[first], np.float64)  # (8, 2) mm, subject
    d = float(np.linalg.norm(pellets[MNI] - pellets[MNM]))
    sites = np.asarray(model_pellets(model, model.vertices))
    p = float(np.linalg.norm(sites[MNI] - sites[MNM]))
    if not d > 0.0:
        raise DegenerateGeometryError(
            f"{source}: MNI and MNM coincide on the first valid line ({first + 1})"
        )
    scale = p / d
    fitted = calibration is not None and not isinstance(calibration, str)
    if fitted:
        if calibration.subject.upper() != str(recording.subject).upper():
            raise CassiError(
                f"{source}: the calibration is of subject {calibration.subject}, "
                f"not {recording.subject}"
            )
        scale = float(calibration.scale)
    elif calibration is not None:
        _check_choice("calibration", calibration, CONFORMATIONS)
    if recording.palate is not None:
        model = with_palate(model, scale * np.asarray(recording.palate, np.float64))
    if fitted:
        conformation = calibration.face_params(jnp.asarray(model.vertices).dtype)
    else:
        conformation = _conformation(model, recording, pellets, scale, calibration or "measures")
    # Compiled, not eager, and at the batch size animate() will use for every line of this
    # recording, so that both share one compilation (the extra frames cost ~0.1 s).
    size = frame_bucket(track.times.shape[0] - first)
    batch = jax.tree.map(lambda x: jnp.broadcast_to(x, (size, *jnp.shape(x))), conformation)
    rest = _geometry(model, batch, jaw_weights, tongue_anchor)[1][0]
    if fitted:  # the lips' vertical rest where the first valid lines have them
        rest = rest.at[UL, 1].add(calibration.lip_rest_offset[0])
        rest = rest.at[LL, 1].add(calibration.lip_rest_offset[1])
    reference = jnp.asarray(scale * pellets[[MNI, MNM]])
    initial = _closed_form_one(rest[jnp.array([MNI, MNM])], reference)
    state = SubjectState(
        model=model,
        scale=scale,
        first_frame=first,
        reference_jaw=reference,
        initial_jaw=(initial.theta, initial.translation),
        conformation=conformation,
        rest_pellets=rest,
        initial_params=conformation,
        tracked_pellets=tracked,
        jaw_weights=jaw_weights,
        tongue_anchor=tongue_anchor,
        gap_policy=gap_policy,
        source=source,
    )
    first_params = _batched_params(
        _frame_inputs(state),
        jnp.broadcast_to(scale * pellets, (size, 8, 2)),
        jnp.zeros(size),
        jnp.zeros((size, 2)),
    )
    first_params = jax.tree.map(lambda x: x[0], first_params)
    return eqx.tree_at(lambda s: s.initial_params, state, first_params)


# --------------------------------------------------------------------------- animation


def _frame_inputs(state: SubjectState) -> dict:
    """The arrays one frame's parameters depend on (all arrays: safe to pass to jit)."""
    tracked = np.array([name in state.tracked_pellets for name in PELLETS])
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
    """FaceParams with a leading frame axis from ``scaled (m, 8, 2)``, ``theta (m,)``,
    ``translation (m, 2)``."""
    return jax.vmap(lambda s, a, t: _frame_params_of(inputs, s, (a, t)))(scaled, theta, translation)


# Functions compiled per model content (``model_call``): geometry, calibration, evaluation.
_GEOMETRY_CACHE: dict = {}
_COLLISION_BATCH = 32


def _digest(value, h) -> None:
    if isinstance(value, np.ndarray):
        h.update(f"{value.dtype}{value.shape}".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, dict):
        for key in sorted(value, key=str):
            h.update(repr(key).encode())
            _digest(value[key], h)
    elif isinstance(value, (list, tuple)):
        for item in value:
            _digest(item, h)
    else:
        h.update(repr(value).encode())


def _model_key(model, leaves) -> str:
    import dataclasses
    import hashlib

    h = hashlib.sha1()
    for f in dataclasses.fields(model):
        if f.metadata.get("static", False):
            h.update(f.name.encode())
            _digest(getattr(model, f.name), h)
    for leaf in leaves:  # non-array leaves are constants of the compiled function
        _digest(
            (np.shape(leaf), str(getattr(leaf, "dtype", type(leaf).__name__)))
            if _is_array(leaf)
            else leaf,
            h,
        )
    return h.hexdigest()


def _is_array(x) -> bool:
    return isinstance(x, (jax.Array, np.ndarray, np.generic, float, int))


def model_call(model, tag, make, *args):
    """``make(model)(*args)``, compiled once per model *content* and hashable ``tag``.

    ``FaceModel`` keeps numpy arrays in static fields, which ``jit`` can neither hash nor
    compare across model objects; so the compiled function receives only the model's array
    leaves, rebuilds the model inside (its static parts closed over) and calls
    ``make(rebuilt)``. Used by the geometry here, the calibration and the evaluation."""
    leaves, treedef = jax.tree.flatten(model)
    key = (_model_key(model, leaves), tag)
    compiled = _GEOMETRY_CACHE.get(key)
    if compiled is None:
        constant = [None if _is_array(x) else x for x in leaves]

        def run(arrays, *a):
            it = iter(arrays)
            rebuilt = jax.tree.unflatten(treedef, [next(it) if c is None else c for c in constant])
            return make(rebuilt)(*a)

        compiled = _GEOMETRY_CACHE[key] = jax.jit(run)
    return compiled([x for x in leaves if _is_array(x)], *args)


def _geometry(model, params, jaw_weights, tongue_anchor, collisions="off", report=False):
    """All frames at once: vertices ``(m, V, 3)`` and model pellet sites ``(m, 8, 2)``;
    with ``report``, also the per-frame penetration depths before and after projection
    (two dicts of ``(m,)``, keys ``collide.REPORT_KEYS``)."""

    def make(rebuilt):
        from . import collide
        from .deform import deform, model_pellets

        def one(p):
            vertices = deform(rebuilt, p, jaw_weights=jaw_weights, tongue_anchor=tongue_anchor)
            before = collide.report(rebuilt, vertices) if report else None
            if collisions == "project":
                vertices = collide.project(rebuilt, vertices)
            after = before
            if report and collisions == "project":
                after = collide.report(rebuilt, vertices)
            return vertices, model_pellets(rebuilt, vertices), before, after

        def run(batch):
            if not report and collisions == "off":
                return jax.vmap(one)(batch)
            # the collision tests' per-vertex, per-segment intermediates stay in cache when
            # frames go through in small batches (3-4x faster than one vmap over all)
            return jax.lax.map(one, batch, batch_size=_COLLISION_BATCH)

        return run

    tag = ("geometry", jaw_weights, tongue_anchor, collisions, report)
    out = model_call(model, tag, make, params)
    return out if report else out[:2]


def frame_bucket(m: int) -> int:
    """Padded batch size: 64, 128, 256, 512, then multiples of 256."""
    if m > 8 * _FRAME_BUCKET:
        return 4 * _FRAME_BUCKET * math.ceil(m / (4 * _FRAME_BUCKET))
    return _FRAME_BUCKET * 2 ** max(math.ceil(math.log2(max(m, 1) / _FRAME_BUCKET)), 0)


def pad_frames(x, size: int):
    """``x`` with its last row repeated along axis 0 up to ``size`` rows."""
    x = jnp.asarray(x)
    return jnp.concatenate([x, jnp.repeat(x[-1:], size - x.shape[0], axis=0)])


def geometry(state: SubjectState, params, collisions="off"):
    """Vertices ``(m, V, 3)`` and model pellet sites ``(m, 8, 2)`` of a batch of params,
    in one compiled call (frames padded to a size bucket so the compilation is reused);
    ``collisions="project"`` pushes the tongue and lips out of the teeth and palate."""
    _check_choice("collisions", collisions, COLLISION_MODES)
    m = int(jnp.shape(params.jaw_theta)[0])
    batch = jax.tree.map(lambda x: pad_frames(x, frame_bucket(m)), params)
    vertices, sites = _geometry(
        state.model, batch, state.jaw_weights, state.tongue_anchor, collisions
    )
    return vertices[:m], sites[:m]


@jax.jit
def _closed_form_batch(reference, current):
    from .jaw import closed_form

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
    state: SubjectState,
    recording,
    *,
    jaw="closed-form",
    solver=None,
    stride=1,
    gap_policy=None,
    collisions="off",
) -> Animation:
    """Animate the face over ``recording`` (every ``stride``-th data line from the first
    valid one, ``ceil((n - first) / stride)`` frames).

    ``jaw``: one of ``JAW_METHODS`` (the paper's closed form, or a fit from ``jaw_fit``,
    which gets ``solver`` if given). ``gap_policy``: ``"hold"`` or ``"interpolate"``
    (default: the state's). ``collisions``: ``"off"`` (CASSI: parts may pass through each
    other) or ``"project"`` (the tongue pushed out of the teeth and the palate, the lips
    out of the teeth, every frame; ``cassi_fit.collide``). Either way the penetration
    depths of every frame are measured and returned. Returns an :class:`Animation`.
    """
    _check_choice("jaw method", jaw, JAW_METHODS)
    _check_choice("collisions", collisions, COLLISION_MODES)
    policy = state.gap_policy if gap_policy is None else gap_policy
    _check_choice("gap policy", policy, GAP_POLICIES)
    if int(stride) != stride or stride < 1:
        raise CassiError(f"stride must be a positive integer, got {stride}")
    track = recording.track
    untracked, mistracked = bad_values(track)
    bad = untracked | mistracked
    positions = repair(np.asarray(track.positions), bad, policy)
    rows = np.arange(state.first_frame, track.times.shape[0], int(stride))
    scaled = state.scale * positions[rows]
    jaw_ok = ~bad[:, [MNI, MNM]].any(axis=1)
    if not jaw_ok.any():
        raise MissingDataError(f"{_source(recording)}: the jaw pellets are never tracked well")
    m, size = len(rows), frame_bucket(len(rows))
    theta, translation, jaw_status = _jaw_since_first(
        state, scaled[:, [MNI, MNM]], jaw, solver, size
    )
    params = _batched_params(_frame_inputs(state), pad_frames(scaled, size), theta, translation)
    from .collide import has_collision_data

    report = has_collision_data(state.model)
    if collisions != "off" and not report:
        from .collide import _require

        _require(state.model)
    out = _geometry(
        state.model, params, state.jaw_weights, state.tongue_anchor, collisions, report
    )
    vertices, sites = out[0][:m], out[1][:m]
    before, after = ({k: np.asarray(v)[:m] for k, v in d.items()} for d in out[2:]) if report \
        else ({}, {})
    params = jax.tree.map(lambda x: x[:m], params)
    tracked = np.array([name in state.tracked_pellets for name in PELLETS])
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
        jaw_method=jaw,
        collisions=collisions,
    )
