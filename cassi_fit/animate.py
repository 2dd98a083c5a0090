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
bucket (:func:`cassi_fit.frames.frame_bucket`) reuses every compilation. The batched frame
machinery (parameters, geometry, padding) is :mod:`cassi_fit.frames`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .dataset import Recording
from .errors import MissingDataError
from .frames import batch_geometry, frame_bucket, frame_params, pad_frames, unpad
from .gaps import bad_values, frame_status, repair
from .pellets import JAW_INDEX, PELLET_NAMES, T1


class Animation(eqx.Module):
    """Per-frame result of :func:`animate`; ``m`` frames, ``V`` vertices.

    times ``(m,)`` s; frame_index ``(m,)`` data-line indices; params: a ``FaceParams``
    whose leaves carry a leading ``(m,)`` axis; vertices ``(m, V, 3)`` mm;
    pellets_measured ``(m, 8, 2)`` mm, scaled by ``p / d`` and repaired; pellets_model
    ``(m, 8, 2)`` mm, where the model puts its pellet sites (an articulograph's tongue
    sensors: the tongue's midline where they sit on it, ``SubjectState.tongue_sites``,
    so each is drawn and compared beside its own sensor); repaired ``(m, 8)`` bool;
    mistracked ``(m, 8)`` bool; mistrack_reasons ``(m, 8)`` int, the detector's reasons
    (``mistracks.Reason`` bits, 0 where not mistracked); frame_status ``(m,)`` int
    (``status.Status`` values);
    jaw_status ``(m,)`` int (``status.Status`` values); penetration: ``collide.REPORT_KEYS``
    -> ``(m,)`` mm, the deepest point of each kind per frame before any projection (empty
    if the model has no collision data); penetration_after: the same after projection
    (equal to ``penetration`` when collisions are off); stride, jaw method and collision
    mode, static; line_step_s: the recording's data-line period in seconds
    (``PelletTrack.frame_step_s``), so a frame lasts ``stride * line_step_s``.
    """

    times: np.ndarray
    frame_index: np.ndarray
    params: eqx.Module
    vertices: jax.Array
    pellets_measured: np.ndarray
    pellets_model: jax.Array
    repaired: np.ndarray
    mistracked: np.ndarray
    mistrack_reasons: np.ndarray
    frame_status: np.ndarray
    jaw_status: np.ndarray
    penetration: dict
    penetration_after: dict
    stride: int = eqx.field(static=True)
    jaw_method: str = eqx.field(static=True)
    line_step_s: float = eqx.field(static=True)
    collisions: str = eqx.field(static=True, default="off")

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])

    @property
    def frame_step_s(self) -> float:
        """Seconds between two frames of the animation: ``stride * line_step_s``."""
        return self.stride * self.line_step_s


def _sensor_points(state, vertices, sites):
    """``sites (m, 8, 2)`` with the tongue rows T1..T4 moved, for an articulograph's
    tongue sensors, to the posed tongue's midline where each sensor sits
    (``state.tongue_sites``); unchanged for XRMB's pellets and CASSI mode."""
    arcs = getattr(state, "tongue_sites", None)
    if arcs is None:
        return sites
    from .deform import tongue_points_at

    have = [k for k, x in enumerate(arcs) if x is not None]
    rows = np.asarray(sites).copy()
    rows[:, [T1 + k for k in have]] = tongue_points_at(
        state.model, vertices, [arcs[k] for k in have])
    return jnp.asarray(rows, jnp.asarray(sites).dtype)


def _jaw_sensors(state, spec) -> tuple[str, ...]:
    """The jaw sensors the animation uses: the spec's choice, else every jaw pellet the
    recording tracks; a chosen sensor the recording lacks is one error naming it."""
    if spec.jaw_sensors is None:
        return state.jaw_sensors
    lacking = [p for p in spec.jaw_sensors if p not in state.jaw_sensors]
    if lacking:
        raise MissingDataError(f"{state.source}: jaw sensor {', '.join(lacking)} is never "
                               "tracked (jaw sensors: "
                               f"{', '.join(state.jaw_sensors) or 'none'})")
    return spec.jaw_sensors


def _jaw_since_first(state, jaw_pellets, method, sensors, size):
    """``(theta (size,), t (size, 2), status (m,))``: the jaw from the first valid line to
    each frame, by the jaw method object ``method`` (``jaw_fit.fit_jaw``) on the jaw
    ``sensors``, padded to ``size`` frames; ``jaw_pellets (m, 2, 2)`` scaled mm, rows
    [MNI, MNM]. The fit is padded to ``size`` (one compilation per size bucket; the padding
    weighs nothing)."""
    from .jaw_fit import fit_jaw

    m = jaw_pellets.shape[0]
    fit = fit_jaw(state.reference_jaw, jaw_pellets, method=method, jaw_sensors=sensors,
                  pad_to=size)
    return pad_frames(fit.theta, size), pad_frames(fit.translation, size), fit.status[:m]


def animate(state: eqx.Module, recording: Recording, **changes: object) -> Animation:
    """Animate the face over ``recording`` (every ``stride``-th data line from the first
    valid one, ``ceil((n - first) / stride)`` frames) with the ``SubjectState`` ``state``
    (``cassi_fit.initialize.initialize``), as the state's run spec says
    (``state.spec``: the jaw method, stride, collisions, gap policy).

    ``changes``: fields of that spec to change for this animation (``jaw=``, ``stride=``,
    ``collisions=``, ``gap_policy=``; checked by the spec). ``jaw``: a jaw method object of
    ``jaw_fit`` or its name (the paper's closed form, or a least-squares fit).
    ``collisions``: ``"off"`` (CASSI: parts may pass through each other) or ``"project"``
    (the tongue pushed out of the teeth, the palate and the pharyngeal wall, the lips out
    of the teeth, every frame; ``cassi_fit.collide``). Either way the penetration depths of
    every frame are measured and returned. Returns an :class:`Animation`. An unknown
    option raises ``InvalidChoiceError``.
    """
    spec = state.spec.replace(**changes) if changes else state.spec
    track = recording.track
    untracked, mistracked = bad_values(track)
    bad = untracked | mistracked
    positions = repair(np.asarray(track.positions), bad, spec.gap_policy)
    rows = np.arange(state.first_frame, track.times.shape[0], spec.stride)
    scaled = state.scale * positions[rows]
    sensors = _jaw_sensors(state, spec)
    method = spec.jaw_method_for(sensors)
    used = [PELLET_NAMES.index(p) for p in sensors]
    if not (~bad[:, used].any(axis=1)).any():
        raise MissingDataError(f"{state.source}: the jaw pellets are never tracked well")
    m, size = len(rows), frame_bucket(len(rows))
    theta, translation, jaw_status = _jaw_since_first(
        state, scaled[:, list(JAW_INDEX)], method, sensors, size
    )
    params = frame_params(state, pad_frames(scaled, size), theta, translation)
    from .collide import has_collision_data

    report = has_collision_data(state.model)
    out = batch_geometry(state.model, params, collisions=spec.collisions, report=report,
                         **spec.deform_style)
    vertices, sites, params = unpad((out[0], out[1], params), m)
    sites = _sensor_points(state, vertices, sites)
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
        mistrack_reasons=np.asarray(track.mistracks.reasons)[rows],
        frame_status=frame_status(untracked[rows] & tracked, mistracked[rows], spec.gap_policy),
        jaw_status=jaw_status,
        penetration=before,
        penetration_after=after,
        stride=spec.stride,
        jaw_method=method.name,
        collisions=spec.collisions,
        line_step_s=track.frame_step_s,
    )
