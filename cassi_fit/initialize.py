"""CASSI's initialization: the face model fitted to one subject, once per recording.

Paper section 2; :func:`initialize`:

1. the first valid line (:func:`cassi_fit.pellets.first_valid_line`): the first frame in
   which every pellet the file ever tracks is tracked (a pellet the file never tracks
   stays at the model's rest site, flagged);
2. pellets to model: every coordinate scaled by ``p / d``, ``d = |MNI - MNM|`` of the
   subject in that frame, ``p`` the same distance between the model's jaw pellet sites.
   Both frames have their origin at the upper incisor tip, so no translation is needed;
3. the lower teeth and the jaw: the closed form (Eqs 1-3, 6-7, ``jaw.closed_form``) from
   the model's jaw sites to the scaled first-frame jaw pellets;
4. the pharyngeal wall from the scaled PHA.DAT (``pharynx.with_pharynx``; the model's
   default wall if absent), then the palate from the scaled PAL.DAT (``palate.with_palate``,
   joined to the model's upper teeth, its velum in front of the wall; the model's own
   centreline if absent);
5. the jaw's shape from the scaled Headmeasures gonion and gnathion against the model's
   gonion and gnathion, by the same closed form (``conformation.jaw_shape``);
6. beyond the paper (its future work): face and mouth width from Headmeasures, lip
   thickness per speaker, nose tip (``conformation.default_conformation``), or a fitted
   ``conformation.Calibration``; tongue (#55-#62) and lips (#63-#66) from the first frame.

A :class:`Mode` bundles every choice of a run (``MODES``: ``"improved"``, the toolkit's
defaults; ``"cassi"``, the paper's choices, docs/CASSI_MODE.md); ``initialize(...,
mode=...)`` and :func:`animate_recording` take its name or the record, and an explicit
keyword overrides the mode's value.

:func:`animate_recording` runs initialization and :func:`cassi_fit.animate.animate` with
the command line's options (``cassi animate``, ``cassi export``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from .animate import Animation, animate, batch_geometry, frame_bucket, frame_params
from .conformation import Calibration, default_conformation
from .dataset import Recording, recording_source
from .errors import CassiError, DegenerateGeometryError
from .face_model import FaceModel
from .jaw import closed_form
from .options import (
    CONFORMATIONS,
    GAP_POLICIES,
    JAW_WEIGHTS,
    MODES,
    TONGUE_ANCHORS,
    TONGUE_SHAPES,
    check_choice,
)
from .pellets import LL, MNI, MNM, UL, first_valid_line

_closed_form_one = jax.jit(closed_form)  # one frame; eager dispatch of its small ops is slow


@dataclass(frozen=True)
class Mode:
    """Every choice of a run, in one record (docs/CASSI_MODE.md gives each against the
    paper). ``conformation``: ``None`` (the subject's shape from Headmeasures and the first
    valid line) or ``"cassi"`` (only the jaw shape, paper step 5); ``tongue_shape``,
    ``tongue_anchor``, ``jaw_weights``, ``lip_rounding``: as ``deform.deform``;
    ``collisions``, ``jaw``, ``stride``: as ``animate.animate``; ``gap_policy``: as
    ``gaps.repair``. Use :func:`mode_named` or ``dataclasses.replace`` to vary one."""

    name: str
    conformation: str | None
    tongue_shape: str
    tongue_anchor: str
    jaw_weights: str
    lip_rounding: bool
    collisions: str
    jaw: str
    stride: int
    gap_policy: str


#: The toolkit's defaults: a thick tongue whose back follows T4, lip rounding, the
#: subject's conformation from Headmeasures (collisions are a further option).
IMPROVED = Mode("improved", None, "thick", "follow", "cassi", True, "off", "closed-form", 1,
                "hold")
#: The paper's choices: a flat tongue of zero thickness (section 5), its back anchored
#: behind and below T4 (section 4), Parke's regions x 1.11111 (section 3.1), only the
#: jaw shape adjusted (section 3), the closed form per frame (Eqs 1-7), no collisions,
#: no lip rounding (both future work). ``stride=10`` gives the Indigo's rate (section 2).
CASSI = Mode("cassi", "cassi", "flat", "fixed", "cassi", False, "off", "closed-form", 1,
             "hold")
_MODES = {"improved": IMPROVED, "cassi": CASSI}


def mode_named(mode: str | Mode | None, **changes: object) -> Mode:
    """The :class:`Mode` of ``mode`` (a name of ``options.MODES``, a record, or None for
    ``"improved"``), with the fields in ``changes`` that are not None replaced."""
    if mode is None:
        mode = IMPROVED
    elif not isinstance(mode, Mode):
        mode = _MODES[check_choice("mode", mode, MODES)]
    return replace(mode, **{k: v for k, v in changes.items() if v is not None})


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
    valid frame. tracked_pellets: the names of the pellets the file ever tracks.
    jaw_weights, tongue_anchor, tongue_shape, lip_rounding, gap_policy: the run's
    choices; mode: the name of the :class:`Mode` they came from.
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
    tongue_shape: str = eqx.field(static=True, default="thick")
    lip_rounding: bool = eqx.field(static=True, default=True)
    mode: str = eqx.field(static=True, default="improved")


def _scale(model, pellets: Float[np.ndarray, "8 2"], source: str, first: int) -> float:
    """``p / d`` (step 2), or ``DegenerateGeometryError`` for coincident jaw pellets."""
    from .deform import model_pellets

    d = float(np.linalg.norm(pellets[MNI] - pellets[MNM]))
    sites = np.asarray(model_pellets(model, model.vertices))
    if not d > 0.0:
        raise DegenerateGeometryError(
            f"{source}: MNI and MNM coincide on the first valid line ({first + 1})"
        )
    return float(np.linalg.norm(sites[MNI] - sites[MNM])) / d


def _rest_pellets(model, conformation, size, mode, calibration):
    """The model's pellet sites ``(8, 2)`` mm in the subject's shape, computed by the same
    compiled call (batch ``size``) that animate() will use for this recording."""
    batch = jax.tree.map(lambda x: jnp.broadcast_to(x, (size, *jnp.shape(x))), conformation)
    rest = batch_geometry(model, batch, jaw_weights=mode.jaw_weights,
                          tongue_anchor=mode.tongue_anchor, tongue_shape=mode.tongue_shape,
                          lip_rounding=mode.lip_rounding)[1][0]
    if calibration is not None:  # the lips' vertical rest where the first valid lines have them
        rest = rest.at[UL, 1].add(calibration.lip_rest_offset[0])
        rest = rest.at[LL, 1].add(calibration.lip_rest_offset[1])
    return rest


def initialize(
    recording: Recording,
    model: FaceModel | None = None,
    *,
    calibration: Calibration | str | None = None,
    jaw_weights: str | None = None,
    tongue_anchor: str | None = None,
    gap_policy: str | None = None,
    mode: str | Mode | None = None,
    tongue_shape: str | None = None,
    lip_rounding: bool | None = None,
) -> SubjectState:
    """Fit the face model to the subject of ``recording`` (CASSI's initialization).

    ``recording``: a ``dataset.Recording``. ``model``: a ``FaceModel`` (default
    ``load_model()``). ``calibration``: ``None`` (the subject's shape from its
    Headmeasures and first valid line, step 6 of the module docstring), ``"cassi"`` (only
    what the paper did: the jaw shape from gonion and gnathion), or a
    :class:`~cassi_fit.conformation.Calibration` of this subject (its scale and fitted
    shape; ``cassi calibrate``). Returns a :class:`SubjectState`. Raises
    ``MissingDataError`` (jaw pellets never tracked), ``DegenerateGeometryError``
    (coincident jaw pellets on the first valid line), ``InvalidChoiceError`` (an unknown
    option) or ``CassiError`` (a calibration of another subject, or a fitted calibration
    in the ``"cassi"`` mode). ``mode``: a :class:`Mode` or its name (default
    ``"improved"``); ``jaw_weights``, ``tongue_anchor``, ``tongue_shape``,
    ``lip_rounding``, ``gap_policy`` and ``calibration``, when given, override it.
    """
    from .face_model import load_model
    from .palate import DEFAULT_OUTLINE, with_palate
    from .pharynx import has_pharynx, with_pharynx

    mode = mode_named(mode, jaw_weights=jaw_weights, tongue_anchor=tongue_anchor,
                      gap_policy=gap_policy, tongue_shape=tongue_shape,
                      lip_rounding=lip_rounding)
    check_choice("jaw weights", mode.jaw_weights, JAW_WEIGHTS)
    check_choice("tongue anchor", mode.tongue_anchor, TONGUE_ANCHORS)
    check_choice("tongue shape", mode.tongue_shape, TONGUE_SHAPES)
    check_choice("gap policy", mode.gap_policy, GAP_POLICIES)
    fitted = calibration if isinstance(calibration, Calibration) else None
    if fitted is not None and mode.conformation == "cassi":
        raise CassiError("the cassi mode uses the paper's conformation; a fitted "
                         "calibration belongs to the improved mode")
    calibration = mode.conformation if calibration is None else calibration
    if calibration is not None and fitted is None:
        check_choice("calibration", calibration, CONFORMATIONS)
    source = recording_source(recording)
    model = load_model() if model is None else model
    track = recording.track
    first, tracked = first_valid_line(track, source)
    pellets = np.asarray(track.positions[first], np.float64)  # (8, 2) mm, subject
    scale = _scale(model, pellets, source, first)
    if fitted is not None:
        if fitted.subject.upper() != str(recording.subject).upper():
            raise CassiError(
                f"{source}: the calibration is of subject {fitted.subject}, not {recording.subject}"
            )
        scale = float(fitted.scale)
    pharynx = getattr(recording, "pharynx", None)
    if pharynx is not None and has_pharynx(model):
        model = with_pharynx(model, scale * np.asarray(pharynx, np.float64))
    if recording.palate is not None:
        model = with_palate(model, scale * np.asarray(recording.palate, np.float64))
    elif pharynx is not None and has_pharynx(model):  # the velum in front of this wall
        model = with_palate(model, DEFAULT_OUTLINE)
    if fitted is not None:
        conformation = fitted.face_params(jnp.asarray(model.vertices).dtype)
    else:
        conformation = default_conformation(model, recording, pellets, scale,
                                            calibration or "measures")
    # at the batch size animate() will use for every line of this recording, so that both
    # share one compilation (the extra frames cost ~0.1 s)
    size = frame_bucket(track.times.shape[0] - first)
    rest = _rest_pellets(model, conformation, size, mode, fitted)
    reference = jnp.asarray(scale * pellets[[MNI, MNM]])
    initial = _closed_form_one(rest[jnp.array([MNI, MNM])], reference)
    state = SubjectState(
        model=model, scale=scale, first_frame=first, reference_jaw=reference,
        initial_jaw=(initial.theta, initial.translation), conformation=conformation,
        rest_pellets=rest, initial_params=conformation, tracked_pellets=tracked,
        jaw_weights=mode.jaw_weights, tongue_anchor=mode.tongue_anchor,
        gap_policy=mode.gap_policy, source=source, tongue_shape=mode.tongue_shape,
        lip_rounding=bool(mode.lip_rounding), mode=mode.name,
    )  # fmt: skip
    first_params = frame_params(
        state, np.broadcast_to(scale * pellets, (size, 8, 2)), np.zeros(size), np.zeros((size, 2))
    )
    first_params = jax.tree.map(lambda x: x[0], first_params)
    return eqx.tree_at(lambda s: s.initial_params, state, first_params)


def animate_recording(
    recording: Recording,
    model: FaceModel | None = None,
    *,
    calibration: Calibration | str | None = None,
    jaw: str | None = None,
    stride: int | None = None,
    jaw_weights: str | None = None,
    tongue_anchor: str | None = None,
    gap_policy: str | None = None,
    collisions: str | None = None,
    mode: str | Mode | None = None,
    tongue_shape: str | None = None,
    lip_rounding: bool | None = None,
) -> tuple[SubjectState, Animation]:
    """:func:`initialize`, then :func:`cassi_fit.animate.animate` (the options of ``cassi
    animate``); every option not given comes from ``mode`` (default ``"improved"``);
    returns ``(state, animation)``."""
    mode = mode_named(mode, jaw=jaw, stride=stride, jaw_weights=jaw_weights,
                      tongue_anchor=tongue_anchor, gap_policy=gap_policy,
                      collisions=collisions, tongue_shape=tongue_shape,
                      lip_rounding=lip_rounding)
    state = initialize(recording, model, calibration=calibration, mode=mode)
    return state, animate(state, recording, jaw=mode.jaw, stride=mode.stride,
                          collisions=mode.collisions)
