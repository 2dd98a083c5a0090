"""The subject's conformation: the face's shape before any animation, in one place.

Three sources (``initialize(..., calibration=...)``, docs/PIPELINE.md):

* the default (:func:`default_conformation`, ``mode="measures"``): paper step 5 (the jaw
  shape from the subject's gonion and gnathion, :func:`jaw_shape`) and, beyond the paper
  (its future work), face and mouth width and nose from Headmeasures and the lip
  thickness (:func:`lip_thickness`) from Headmeasures or the first valid line;
* ``mode="cassi"``: only what the paper did (the jaw shape);
* a :class:`~cassi_fit.calibration.Calibration`: the subject's shape fitted through the
  model by ``cassi_fit.calibrate`` (``cassi calibrate``), read back from its JSON file;
  the record, its file and its bounds live in :mod:`cassi_fit.calibration`.

Gonion and gnathion in Headmeasures are bone points (paper section 3); the model's are
skin vertices: :func:`skin_landmarks` maps the one onto the other by the soft-tissue
thickness of ``headmeasures.SOFT_TISSUE_THICKNESS_MM``. A fitted jaw shape is kept within
``calibration.JAW_SCALE_BOUND`` and ``JAW_TURN_BOUND_RAD`` (adult proportions); a subject
whose values hit a bound is flagged (``Calibration.bounds_hit``).

Lip thickness is Headmeasures' (docs/FORMATS.md): how far the lip pellet sits ahead of
the incisor tip at rest; :func:`lips_ahead` measures it on one data line.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import rigid
from ._exported import exported
from .dataset import Recording
from .deform import FaceParams, default_params
from .face_model import FaceModel
from .headmeasures import SOFT_TISSUE_THICKNESS_MM, HeadMeasures
from .jaw import closed_form
from .options import CONFORMATIONS, check_choice
from .pellets import LL, MNI, MNM, UL


def with_values(params: FaceParams, values: dict) -> FaceParams:
    """``params`` with the fields named in ``values`` replaced (``FaceParams`` names)."""
    if not values:
        return params
    names = tuple(values)
    return eqx.tree_at(lambda p: tuple(getattr(p, k) for k in names), params,
                       tuple(values[k] for k in names))


def lips_ahead(
    rest_jaw: Float[Array, "2 2"], tip: Float[Array, " 2"], pellets: Float[Array, "8 2"], s: float | Float[Array, ""]
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Lip thickness as Headmeasures defines it, seen on one data line, in model mm:
    ``(upper, lower)``, the UL pellet ahead of the upper incisor tip (x) and the LL pellet
    ahead of the lower incisor tip along the jaw line (MNM -> MNI). ``pellets (8, 2)``
    subject mm, ``s`` the scale; the lower tip is the model's (``tip (2,)``), placed on
    the line's jaw pellets by the paper's closed form (Eqs 1-3, 6-7) from the model's jaw
    sites ``rest_jaw (2, 2)`` [MNI, MNM]. Exported (:mod:`cassi_fit._exported`): a new
    process loads it; ``s`` is passed as an array (a number as ``jax.jit`` takes it: weakly
    typed), never as a constant of the computation."""
    return _lips_ahead(rest_jaw, tip, pellets, jnp.asarray(s))


@exported
def _lips_ahead(rest_jaw, tip, pellets, s):
    dtype = pellets.dtype
    motion = closed_form(rest_jaw.astype(dtype), s * pellets[jnp.array([MNI, MNM])])
    tip_here = rigid.apply(motion.theta, motion.translation, tip.astype(dtype))
    forward = (pellets[MNI] - pellets[MNM]) / jnp.linalg.norm(pellets[MNI] - pellets[MNM])
    return s * pellets[UL, 0], jnp.dot(s * pellets[LL] - tip_here, forward)


_closed_form_one = jax.jit(closed_form)  # one frame; eager dispatch of its small ops is slow


def _xy(model, name) -> np.ndarray:
    return np.asarray(model.vertices)[model.landmarks[name], :2]


def skin_normal(model: FaceModel, name: str) -> Float[np.ndarray, " 2"]:
    """The outward unit normal of the model's rest skin at landmark ``name``, its x, y
    (midsagittal) part ``(2,)``: area-weighted over the faces around the vertex."""
    v = np.asarray(model.vertices, np.float64)
    faces = np.asarray(model.faces)
    around = faces[(faces == model.landmarks[name]).any(axis=1)]
    a, b, c = (v[around[:, k]] for k in range(3))
    n = np.cross(b - a, c - a).sum(axis=0)
    return n[:2] / np.linalg.norm(n)


def skin_landmarks(model: FaceModel, head: HeadMeasures) -> Float[np.ndarray, "2 2"]:
    """The skin points ``[[gonion], [gnathion]]`` (subject mm, pellet frame) over the
    subject's bony gonion and gnathion (Headmeasures ``head``): each moved outwards by
    its soft-tissue thickness (``headmeasures.SOFT_TISSUE_THICKNESS_MM``) along the
    model's skin normal there (:func:`skin_normal`)."""
    bone = np.array([[head.gonion_x, head.gonion_y], [head.gnathion_x, head.gnathion_y]])
    t = SOFT_TISSUE_THICKNESS_MM
    return bone + np.stack([t["gonion"] * skin_normal(model, "gonion"),
                            t["gnathion"] * skin_normal(model, "gnathion")])


def jaw_shape(model: FaceModel, head: HeadMeasures, scale: float) -> tuple[float, Float[np.ndarray, " 2"]]:
    """Paper step 5: the closed form from the model's [gnathion, gonion] (skin) to the
    subject's, the skin over its bony Headmeasures points (:func:`skin_landmarks`) times
    ``scale``, as ``(theta rad, t (2,) mm)``; neutral if degenerate (jaw status
    DEGENERATE or worse)."""
    reference = np.stack([_xy(model, "gnathion"), _xy(model, "gonion")])
    current = scale * skin_landmarks(model, head)[::-1]
    motion = _closed_form_one(jnp.asarray(reference), jnp.asarray(current))
    if int(motion.status) >= 2:
        return 0.0, np.zeros(2)
    return float(motion.theta), np.asarray(motion.translation)


def lip_thickness(
    model: FaceModel, first: Float[np.ndarray, "8 2"], scale: float, head: HeadMeasures,
    head_is_default: bool,
) -> Float[np.ndarray, " 2"]:
    """Millimetres added to the model's lip thickness parameters ``(upper, lower)``.

    From the subject's Headmeasures ``head`` if it has them, else (the report's future
    work) from the first valid line ``first (8, 2)`` subject mm, taken as a gently closed
    mouth (:func:`lips_ahead`). Kept within [-1/2, +1] of the model's own thickness so
    that a bad first line cannot turn a lip inside out.
    """
    own = np.array([model.measures["upper_lip_thickness"], model.measures["lower_lip_thickness"]])
    forward = _xy(model, "MNI") - _xy(model, "MNM")
    forward = forward / np.linalg.norm(forward)
    if not head_is_default:
        wanted = scale * np.array([head.upper_lip_thickness, head.lower_lip_thickness])
    else:
        rest_jaw = np.stack([_xy(model, "MNI"), _xy(model, "MNM")])
        seen = lips_ahead(jnp.asarray(rest_jaw), jnp.asarray(_xy(model, "lower_incisor_tip")),
                          jnp.asarray(first), scale)
        wanted = np.where(np.isfinite(seen), np.asarray(seen, np.float64), own)
    delta = np.clip(wanted - own, -0.5 * own, own)
    # the thickness parameters move the vermilion along x: the lower one counts along
    # the model's forward direction
    return delta / np.array([1.0, forward[0]])


def default_conformation(
    model: FaceModel, recording: Recording, first: Float[np.ndarray, "8 2"], scale: float, mode: str = "measures"
) -> FaceParams:
    """``FaceParams`` of the subject's shape (no animation) from its Headmeasures and
    first valid line ``first (8, 2)`` subject mm; ``mode``: ``"measures"`` (everything of
    the module docstring) or ``"cassi"`` (the jaw shape only, as the paper)."""
    check_choice("conformation", mode, CONFORMATIONS)
    head, default = recording.head, bool(recording.head_is_default)
    params = default_params(model)
    changes = {}
    if mode == "measures":
        upper, lower = lip_thickness(model, first, scale, head, default)
        changes.update(upper_lip_thickness=upper, lower_lip_thickness=lower)
    if not default:
        theta, t = jaw_shape(model, head, scale)
        changes.update(jaw_shape_theta=theta, jaw_shape_translation=t)
        if mode == "measures":
            nose = scale * head.nose_protrusion - model.measures["nose_protrusion"]
            changes.update(
                face_width=scale * head.face_width / model.measures["face_width"],
                mouth_width=scale * head.mouth_width / model.measures["mouth_width"],
                nose_tip=np.array([nose, 0.0]),
            )
    return with_values(params, {k: jnp.asarray(v, jnp.asarray(getattr(params, k)).dtype)
                                for k, v in changes.items()})
