"""Subject-specific calibration of the face model, fitted through the differentiable model.

CASSI used one generic face for every speaker and found that some faces fit it worse
than others; its future work proposes lip thickness per speaker from the first valid
line, and the face adjusted to the subject from ``Headmeasures.txt``. This module does
both, as a least-squares fit (optimistix Levenberg-Marquardt, ``jaw_fit.solve``) of the
model's conformation parameters, every residual computed on the vertices that
``deform.deform`` produces:

========================  ===============================================================
unknown                   residuals it answers to (model mm)
========================  ===============================================================
scale ``p/d``             (joint only) the model's MNI-MNM distance vs ``s`` x the
                          subject's on each recording's first valid line
upper lip thickness       model: UL site ahead of the upper incisor tip (x); subject: the
                          UL pellet's x on the first valid line (origin = incisor tip)
lower lip thickness       model: LL site ahead of the lower incisor tip along the
                          mandible's forward direction (MNM -> MNI); subject: the same for
                          the LL pellet, the tip being the model's, placed on the first
                          line's jaw pellets by the closed form (Eqs 1-3, 6-7)
face width                model: zygion to zygion; subject: Headmeasures ``face_width``
jaw shape (theta, kx, ky) model gonion and gnathion (x, y) vs Headmeasures', both points
                          (CASSI used one point's closed form; here a turn and a scale
                          along x and y, about the lower incisor tip: 3 unknowns for 4
                          residuals, so a residual remains)
(collisions)              every lip vertex's depth inside the teeth at rest (weighted
                          penalty, ``cassi_fit.collide``)
========================  ===============================================================

Lip thickness is defined as Headmeasures defines it (``docs/FORMATS.md``): how far the
lip pellet sits ahead of the incisor tip at rest. Each recording of the subject
contributes its first valid line (the report's "likely a gently closed mouth"); with
several recordings the fit is their least-squares compromise and the spread is reported.

Methods: ``"separate"`` fixes ``s = p / d`` (the median over the recordings, as CASSI's
per-file scale) and fits the jaw shape, then the face width, then the lips, each on its
own residuals; ``"joint"`` fits all of them and the scale at once. Mouth width and nose
protrusion come straight from Headmeasures (no pellet sees them). A subject without
Headmeasures keeps the model's jaw shape, face width, mouth and nose.

The result, :class:`Calibration`, is written one JSON file per subject
(``<SUBJECT>.calibration.json``) by ``cassi calibrate`` and read back by
``cassi animate --calibration`` and ``initialize(..., calibration=...)``. The record
itself, :class:`~cassi_fit.conformation.Calibration`, lives with the rest of the subject's
conformation in :mod:`cassi_fit.conformation`; the unknowns of the fit are the named
pytree :class:`Unknowns`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, Float

from .conformation import (
    BOUND_HIT_FRACTION,
    FORMAT,
    JAW_SCALE_BOUND,
    JAW_TURN_BOUND_RAD,
    Calibration,
    lips_ahead,
    plain,
    skin_landmarks,
    with_values,
)
from .dataset import Dataset, Recording, recording_source
from .errors import CassiError, DataFormatError, DegenerateGeometryError, MissingDataError
from .face_model import FaceModel
from .options import CALIBRATION_METHODS, check_choice
from .pellets import LL, MNI, MNM, PELLET_NAMES, UL, first_valid_line

#: Weight of the lips-in-teeth penalty residuals relative to a 1 mm lip residual.
COLLISION_WEIGHT = 10.0


class Unknowns(eqx.Module):
    """The unknowns of the calibration (model units), a pytree with named fields.

    ``log_scale``: log of ``p/d``; ``upper_lip``, ``lower_lip``: lip thickness change (mm);
    ``face_width``: face width change (mm); ``jaw_theta``: jaw shape rotation (rad) and
    ``log_jaw_scale (2,)``: the jaw's log scales along x and y, both about the model's
    lower incisor tip. The solver sees them flattened in this order (``ravel_pytree``).
    """

    log_scale: Float[Array, ""]
    upper_lip: Float[Array, ""]
    lower_lip: Float[Array, ""]
    face_width: Float[Array, ""]
    jaw_theta: Float[Array, ""]
    log_jaw_scale: Float[Array, " 2"]

    @classmethod
    def zeros(cls, dtype=float) -> Unknowns:
        """Every unknown 0 (scale 1, the model's own shape)."""
        z = jnp.zeros((), dtype)
        return cls(z, z, z, z, z, jnp.zeros(2, dtype))

    @classmethod
    def mask(cls, free, dtype=float) -> Unknowns:
        """1 for the fields named in ``free``, 0 elsewhere (which unknowns a stage fits)."""
        zero = cls.zeros(dtype)
        return cls(*(jnp.full(jnp.shape(getattr(zero, name)), float(name in free), dtype)
                     for name in UNKNOWN_NAMES))


def bounded_jaw(x: Unknowns) -> tuple[Float[Array, ""], Float[Array, " 2"]]:
    """``(theta rad, log scales (2,))`` of the jaw shape from the unknowns, each kept
    smoothly inside its anatomical bound ``B`` (``conformation.JAW_TURN_BOUND_RAD``,
    ``log JAW_SCALE_BOUND``) as ``B tanh(u / B)``: slope 1 at 0 and a bijection onto
    (-B, B), so a fit whose optimum lies inside the bounds reaches the same shape, and
    none goes beyond ``B``."""
    b = math.log(JAW_SCALE_BOUND)
    return (JAW_TURN_BOUND_RAD * jnp.tanh(x.jaw_theta / JAW_TURN_BOUND_RAD),
            b * jnp.tanh(x.log_jaw_scale / b))


def bounds_hit(x: Unknowns) -> tuple[str, ...]:
    """The jaw-shape unknowns of ``x`` at (``BOUND_HIT_FRACTION`` of) their bound."""
    theta, log_scale = (np.asarray(a, np.float64) for a in bounded_jaw(x))
    b = math.log(JAW_SCALE_BOUND)
    hit = [name for name, value in zip(("jaw_scale_x", "jaw_scale_y"), log_scale, strict=True)
           if abs(value) >= BOUND_HIT_FRACTION * b]
    if abs(float(theta)) >= BOUND_HIT_FRACTION * JAW_TURN_BOUND_RAD:
        hit.append("jaw_turn")
    return tuple(hit)


#: The unknowns' names, in order.
UNKNOWN_NAMES = ("log_scale", "upper_lip", "lower_lip", "face_width", "jaw_theta",
                 "log_jaw_scale")


# ------------------------------------------------------------------ the observations


def _first_line(recording):
    """``(first index, pellets (8, 2) mm with NaN for pellets never tracked)``."""
    source = recording_source(recording)
    first, tracked = first_valid_line(recording.track, source)
    pellets = np.array(recording.track.positions[first], np.float64)
    for j, name in enumerate(PELLET_NAMES):
        if name not in tracked:
            pellets[j] = np.nan
    d = float(np.linalg.norm(pellets[MNI] - pellets[MNM]))
    if not d > 0:
        raise DegenerateGeometryError(
            f"{source}: MNI and MNM coincide on the first valid line ({first + 1})"
        )
    return first, pellets


_INDEX = ("UL", "LL", "MNI", "MNM", "upper_incisor_tip", "lower_incisor_tip", "gonion",
          "gnathion", "zygion_left", "zygion_right")


def _data(model, pellets, head):
    """The arrays the residuals depend on (a pytree; subject mm unless named)."""
    p = np.asarray(pellets)  # (R, 8, 2) subject mm, NaN where never tracked
    return {
        "mask_ul": np.isfinite(p[:, UL, 0]).astype(float),
        "mask_ll": np.isfinite(p[:, LL]).all(-1).astype(float),
        "pellets": np.nan_to_num(p),
        "d": np.linalg.norm(p[:, MNI] - p[:, MNM], axis=-1),
        # the skin over the bony Headmeasures points, as the model's landmarks are skin
        "head_xy": skin_landmarks(model, head),
        "face_width": np.asarray(float(head.face_width)),
        "mouth_width": np.asarray(float(head.mouth_width)),
        "nose": np.asarray(float(head.nose_protrusion)),
    }


class _Problem:
    """The residuals of one subject (model mm); ``model`` may be rebuilt inside jit."""

    def __init__(self, model, data, measured):
        self.model, self.data, self.measured = model, data, measured
        self.index = {k: model.landmarks[k] for k in _INDEX}

    def params(self, x):
        """FaceParams of the :class:`Unknowns` ``x``."""
        from .deform import default_params

        m, data = self.model.measures, self.data
        dtype = x.log_scale.dtype
        s = jnp.exp(x.log_scale)
        names = ["upper_lip_thickness", "lower_lip_thickness", "face_width"]
        values = [x.upper_lip, x.lower_lip, 1.0 + x.face_width / m["face_width"]]
        if self.measured:
            from .rigid import rotation_matrix

            # the jaw's proportions (x, y scale) and a turn, both about the lower incisor
            # tip, so that the skin over the teeth stays where the teeth are
            tip = jnp.asarray(self.model.vertices)[self.index["lower_incisor_tip"], :2]
            tip = tip.astype(dtype)
            theta, log_scale = bounded_jaw(x)
            turn = tip - rotation_matrix(theta) @ tip
            names += ["jaw_shape_theta", "jaw_shape_translation", "jaw_shape_scale",
                      "mouth_width", "nose_tip"]
            values += [theta, turn, jnp.exp(log_scale), s * data["mouth_width"] / m["mouth_width"],
                       jnp.stack([s * data["nose"] - m["nose_protrusion"], jnp.zeros_like(s)])]
        p = default_params(dtype=dtype)
        return with_values(p, {k: jnp.asarray(v, dtype) for k, v in zip(names, values, strict=True)})

    def vertices(self, x):
        from .deform import deform

        return deform(self.model, self.params(x))

    def lip_thickness_model(self, v):
        """(upper, lower) on the model at rest, model mm."""
        i = self.index
        upper = v[i["UL"], 0] - v[i["upper_incisor_tip"], 0]
        fwd = v[i["MNI"], :2] - v[i["MNM"], :2]
        fwd = fwd / jnp.linalg.norm(fwd)
        lower = jnp.dot(v[i["LL"], :2] - v[i["lower_incisor_tip"], :2], fwd)
        return upper, lower

    def lip_thickness_observed(self, s):
        """Per recording (R,) (upper, lower) in model mm at scale ``s``: the lip pellets
        ahead of the incisor tips on the first valid line (the lower tip = the model's,
        placed on that line's jaw pellets by the paper's closed form)."""
        v = self.model.vertices
        i = self.index
        rest_jaw = jnp.stack([v[i["MNI"], :2], v[i["MNM"], :2]])
        tip = v[i["lower_incisor_tip"], :2]
        return jax.vmap(lambda pel: lips_ahead(rest_jaw, tip, pel, s))(self.data["pellets"])

    def lip_rest_offset(self, v, s):
        """(upper, lower) model mm: how far above the model's UL and LL sites the lip
        pellets sit on the first valid lines (the lower one after the model's jaw is placed
        on that line's jaw pellets), averaged over the recordings that track them."""
        from . import rigid
        from .jaw import closed_form

        i = self.index
        rest_jaw = jnp.stack([v[i["MNI"], :2], v[i["MNM"], :2]])
        w_ll = jnp.asarray(self.model.jaw_weights["cassi"])[i["LL"]]

        def one(pel):
            motion = closed_form(rest_jaw, s * pel[jnp.array([MNI, MNM])])
            theta, t = rigid.fractional((motion.theta, motion.translation), w_ll)
            ll = rigid.apply(theta, t, v[i["LL"], :2])
            return s * pel[UL, 1] - v[i["UL"], 1], s * pel[LL, 1] - ll[1]

        du, dl = jax.vmap(one)(self.data["pellets"])
        mu, ml = self.data["mask_ul"], self.data["mask_ll"]
        return (jnp.sum(mu * du) / jnp.maximum(jnp.sum(mu), 1.0),
                jnp.sum(ml * dl) / jnp.maximum(jnp.sum(ml), 1.0))

    def residual_groups(self, x, collisions):
        """Dict of residual vectors (model mm) at the :class:`Unknowns` ``x``."""
        from .collide import penalty_residuals

        data = self.data
        s = jnp.exp(x.log_scale)
        v = self.vertices(x)
        i = self.index
        upper, lower = self.lip_thickness_model(v)
        obs_u, obs_l = self.lip_thickness_observed(s)
        groups = {
            "upper_lip": data["mask_ul"] * (upper - obs_u),
            "lower_lip": data["mask_ll"] * (lower - obs_l),
            "jaw_pellets": jnp.linalg.norm(v[i["MNI"], :2] - v[i["MNM"], :2]) - s * data["d"],
        }
        if self.measured:
            ours = jnp.stack([v[i["gonion"], :2], v[i["gnathion"], :2]])
            groups["jaw_shape"] = (ours - s * data["head_xy"]).ravel()
            width = v[i["zygion_left"], 2] - v[i["zygion_right"], 2]
            groups["face_width"] = jnp.atleast_1d(width - s * data["face_width"])
        if collisions:
            depth = penalty_residuals(self.model, v, tongue=False, lips=True)
            groups["collision"] = math.sqrt(COLLISION_WEIGHT) * depth
        return groups


# ------------------------------------------------------------------------ the fit

_GROUPS = ("jaw_pellets", "upper_lip", "lower_lip", "jaw_shape", "face_width", "collision")
_STAGES = {  # method -> [(free unknowns, residual groups)]
    "separate": [
        (("jaw_theta", "log_jaw_scale"), ("jaw_shape",)),
        (("face_width",), ("face_width",)),
        (("upper_lip", "lower_lip"), ("upper_lip", "lower_lip", "collision")),
    ],
    "joint": [(UNKNOWN_NAMES, _GROUPS)],
}
# Without Headmeasures only these unknowns are seen by any residual.
_UNMEASURED = ("log_scale", "upper_lip", "lower_lip")


@eqx.filter_jit
def _stage_kernel(model, data, measured, x, mask, weights):
    """One compiled solver per (model topology, head measured): which unknowns are free
    (``mask``, an ``Unknowns`` of 0/1) and which residual groups count (``weights``) are
    arrays, so every stage of both methods, with or without the penalty, shares it."""
    from .jaw_fit import solve

    problem = _Problem(model, data, measured)
    flat, unravel = ravel_pytree(x)
    free = ravel_pytree(mask)[0]

    def residuals(y, base):
        g = problem.residual_groups(unravel(base + free * (y - base)), True)
        return jnp.concatenate([weights[k] * jnp.atleast_1d(g[k]) for k in _GROUPS if k in g])

    y, converged = solve(residuals, flat, flat, "optimistix-lm")
    return unravel(flat + free * (y - flat)), converged


def _solve_stage(model, data, measured, x, free, groups, collisions):
    """Least squares over the unknowns named in ``free`` (others held at ``x``) of the
    residual ``groups``; returns ``(x, converged)``."""
    dtype = x.log_scale.dtype
    weights = {g: jnp.asarray(float(g in groups), dtype) for g in _GROUPS}
    weights["collision"] = weights["collision"] * float(bool(collisions))
    y, converged = _stage_kernel(model, data, measured, x, Unknowns.mask(free, dtype), weights)
    return y, bool(converged)


def calibrate_subject(
    recordings: Iterable[Recording], model: FaceModel | None = None, *,
    method: str = "separate", collisions: bool = True,
) -> Calibration:
    """Calibrate the face model to one subject from its recordings (``dataset.Recording``
    objects, one or more, all of the same subject). Returns a :class:`Calibration`.

    Raises ``CassiError`` for an unknown method or recordings of different subjects,
    ``MissingDataError`` if no recording is given or a jaw pellet is never tracked,
    ``DegenerateGeometryError`` for coincident jaw pellets on a first valid line.
    """
    from .face_model import load_model

    check_choice("calibration method", method, CALIBRATION_METHODS)
    recordings = list(recordings)
    if not recordings:
        raise MissingDataError("calibration needs at least one recording of the subject")
    subjects = {r.subject.upper() for r in recordings}
    if len(subjects) != 1:
        raise CassiError(f"recordings of several subjects given: {', '.join(sorted(subjects))}")
    model = load_model() if model is None else model
    lines = [_first_line(r) for r in recordings]
    pellets = np.stack([p for _, p in lines])
    head, measured = recordings[0].head, not bool(recordings[0].head_is_default)
    dtype = jnp.asarray(model.vertices).dtype
    data = jax.tree.map(lambda a: jnp.asarray(a, dtype), _data(model, pellets, head))
    sites = np.asarray(model.vertices)[[model.landmarks["MNI"], model.landmarks["MNM"]], :2]
    s0 = float(np.linalg.norm(sites[0] - sites[1])) / float(np.median(np.asarray(data["d"])))
    x = eqx.tree_at(lambda u: u.log_scale, Unknowns.zeros(dtype), jnp.asarray(math.log(s0), dtype))
    converged = True
    for free, groups in _STAGES[method]:
        if not measured:
            free = tuple(k for k in free if k in _UNMEASURED)
            groups = tuple(g for g in groups if g not in ("jaw_shape", "face_width"))
        if not free:
            continue
        x, ok = _solve_stage(model, data, measured, x, free, groups, bool(collisions))
        converged &= ok
    problem = _Problem(model, data, measured)
    result = _summarise(problem, x, method, collisions, converged, recordings, lines)
    if result.bounds_hit:
        warnings.warn(f"subject {result.subject}: the jaw shape reached its anatomical bound "
                      f"({', '.join(result.bounds_hit)}; conformation.JAW_SCALE_BOUND, "
                      "JAW_TURN_BOUND_RAD): its Headmeasures do not fit an adult jaw of the "
                      "model's proportions", stacklevel=2)
    if not all(np.isfinite(v) for v in (result.scale, result.upper_lip_thickness,
                                        result.lower_lip_thickness, result.face_width)):
        raise CassiError(f"subject {result.subject}: calibration gave a non-finite value")
    return result


@eqx.filter_jit
def _summary_arrays(model, data, measured, x):
    """Everything :func:`_summarise` reports, in one compiled call per model topology."""
    from .collide import depths

    problem = _Problem(model, data, measured)
    v = problem.vertices(x)
    d = depths(model, v)
    lips = jnp.maximum(jnp.max(d["lips_upper"]), jnp.max(d["lips_lower"]))
    s = jnp.exp(x.log_scale)
    return (v, problem.residual_groups(x, False), problem.lip_thickness_model(v),
            problem.lip_thickness_observed(s), lips, problem.params(x),
            problem.lip_rest_offset(v, s))


def _summarise(problem, x, method, collisions, converged, recordings, lines):
    s = float(np.exp(x.log_scale))
    v, groups, model_t, obs, lips_depth, params, lip_rest = _summary_arrays(
        problem.model, problem.data, problem.measured, x)
    groups = {k: np.asarray(g) for k, g in groups.items()}
    upper, lower = (float(t) / s for t in model_t)
    obs_u, obs_l = (np.asarray(t) / s for t in obs)
    obs_u = np.where(np.asarray(problem.data["mask_ul"]) > 0, obs_u, np.nan)
    obs_l = np.where(np.asarray(problem.data["mask_ll"]) > 0, obs_l, np.nan)

    def rms(a):
        a = np.asarray(a, float).ravel()
        return float(np.sqrt(np.mean(a * a))) / s if a.size else 0.0

    residuals = {"upper_lip": rms(groups["upper_lip"]), "lower_lip": rms(groups["lower_lip"]),
                 "jaw_pellets": rms(groups["jaw_pellets"])}
    if "jaw_shape" in groups:
        js = groups["jaw_shape"].reshape(2, 2)
        residuals["gonion"] = float(np.linalg.norm(js[0])) / s
        residuals["gnathion"] = float(np.linalg.norm(js[1])) / s
        residuals["face_width"] = rms(groups["face_width"])
    # reported whether or not the fit was penalised
    residuals["lips_in_teeth"] = float(lips_depth) / s
    names = ["upper_lip_thickness", "lower_lip_thickness", "face_width", "mouth_width",
             "nose_tip", "jaw_shape_theta", "jaw_shape_translation", "jaw_shape_scale"]
    i = problem.index
    vn = np.asarray(v)
    return Calibration(
        subject=recordings[0].subject.upper(),
        method=method,
        scale=s,
        upper_lip_thickness=upper,
        lower_lip_thickness=lower,
        face_width=float(vn[i["zygion_left"], 2] - vn[i["zygion_right"], 2]) / s,
        mouth_width=float(problem.data["mouth_width"]) if problem.measured
        else problem.model.measures["mouth_width"] / s,
        nose_protrusion=float(problem.data["nose"]) if problem.measured
        else problem.model.measures["nose_protrusion"] / s,
        gonion=tuple(float(c) / s for c in vn[i["gonion"], :2]),
        gnathion=tuple(float(c) / s for c in vn[i["gnathion"], :2]),
        params={k: plain(np.asarray(getattr(params, k), float)) for k in names},
        lip_rest_offset=tuple(float(d) for d in lip_rest),
        residuals=residuals,
        observed={
            "upper_lip_thickness": [None if np.isnan(a) else float(a) for a in obs_u],
            "lower_lip_thickness": [None if np.isnan(a) else float(a) for a in obs_l],
        },
        recordings=tuple(r.task for r in recordings),
        first_lines=tuple(int(f) + 1 for f, _ in lines),
        head_is_default=not problem.measured,
        collisions=bool(collisions),
        converged=bool(converged),
        bounds_hit=bounds_hit(x) if problem.measured else (),
    )


# ------------------------------------------------------------------------- files


def calibration_path(folder: str | Path, subject: str) -> Path:
    """``folder/SUBJECT.calibration.json``."""
    return Path(folder) / f"{subject.upper()}.calibration.json"


def write_calibration(
    path: str | Path, calibration: Calibration, *, overwrite: bool = False
) -> Path:
    """Write one subject's calibration as JSON (atomically; an existing file only with
    ``overwrite``)."""
    from ._io import atomic_write

    return atomic_write(Path(path), calibration.to_json(), overwrite=overwrite)


_REQUIRED = ("subject", "method", "scale", "upper_lip_thickness", "lower_lip_thickness",
             "face_width", "params")


def read_calibration(path: str | Path) -> Calibration:
    """Read a ``<SUBJECT>.calibration.json``; ``DataFormatError`` naming the file (and the
    line, for invalid JSON) if it is not one."""
    from ._io import read_json

    path = Path(path)
    data = read_json(path, "calibration file")
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise DataFormatError(path, None, f"not a calibration file (format {FORMAT!r})")
    missing = [k for k in _REQUIRED if k not in data]
    if missing:
        raise DataFormatError(path, None, f"missing {', '.join(missing)}")
    known = {f for f in Calibration.__dataclass_fields__}
    data = {k: v for k, v in data.items() if k in known}
    defaults = {"mouth_width": float("nan"), "nose_protrusion": float("nan"),
                "gonion": (math.nan, math.nan), "gnathion": (math.nan, math.nan),
                "lip_rest_offset": (0.0, 0.0),
                "residuals": {}, "observed": {}, "recordings": (), "first_lines": (),
                "head_is_default": False, "collisions": False, "converged": True,
                "bounds_hit": ()}
    for k, v in defaults.items():
        data.setdefault(k, v)
    params = data["params"]
    allowed = {"upper_lip_thickness": (), "lower_lip_thickness": (), "face_width": (),
               "mouth_width": (), "nose_tip": (2,), "jaw_shape_theta": (),
               "jaw_shape_translation": (2,), "jaw_shape_scale": (2,)}
    if not isinstance(params, dict):
        raise DataFormatError(path, None, "params must be an object")
    for k, v in params.items():
        if k not in allowed:
            raise DataFormatError(path, None, f"unknown parameter {k!r}")
        a = np.asarray(v, float) if _numeric(v) else None
        if a is None or a.shape != allowed[k] or not np.all(np.isfinite(a)):
            raise DataFormatError(path, None, f"parameter {k}: expected {allowed[k] or 'a number'}")
    for k in ("scale", "upper_lip_thickness", "lower_lip_thickness", "face_width"):
        if not _numeric(data[k]) or not math.isfinite(float(data[k])) or float(data[k]) <= 0:
            raise DataFormatError(path, None, f"{k} must be a positive number")
    offset = data["lip_rest_offset"]
    if not _numeric(offset) or np.shape(offset) != (2,) or not np.all(np.isfinite(offset)):
        raise DataFormatError(path, None, "lip_rest_offset must be two numbers (mm)")
    data["lip_rest_offset"] = tuple(float(d) for d in offset)
    hit = data["bounds_hit"]
    if not isinstance(hit, (list, tuple)) or not all(isinstance(h, str) for h in hit):
        raise DataFormatError(path, None, "bounds_hit must be a list of names")
    data["bounds_hit"] = tuple(hit)
    data["gonion"], data["gnathion"] = tuple(data["gonion"]), tuple(data["gnathion"])
    data["recordings"], data["first_lines"] = tuple(data["recordings"]), tuple(data["first_lines"])
    return Calibration(**data)


def _numeric(v) -> bool:
    try:
        np.asarray(v, float)
    except (TypeError, ValueError):
        return False
    return True


def load_calibrations(folder: str | Path) -> dict[str, Calibration]:
    """All ``*.calibration.json`` in ``folder``: subject (upper case) -> Calibration."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingDataError(f"{folder}: calibration folder not found")
    out = {}
    for path in sorted(folder.glob("*.calibration.json")):
        cal = read_calibration(path)
        if cal.subject in out:
            raise DataFormatError(path, None, f"a second calibration of subject {cal.subject}")
        out[cal.subject] = cal
    if not out:
        raise MissingDataError(f"{folder}: no *.calibration.json files")
    return out


def calibration_choice(
    path: str | Path | None = None, subject: str = "", *, cassi: bool = False
) -> Calibration | str | None:
    """``initialize``'s ``calibration`` for the command line's ``--calibration PATH`` and
    ``--cassi``: ``"cassi"``, ``None`` (the default conformation), or the
    :class:`Calibration` read from ``PATH`` (a folder written by ``cassi calibrate``, whose
    ``SUBJECT.calibration.json`` is used, or one such file). ``CassiError`` if both are
    given."""
    if path and cassi:
        raise CassiError("--cassi and --calibration exclude each other")
    if cassi:
        return "cassi"
    if not path:
        return None
    path = Path(path)
    return read_calibration(calibration_path(path, subject) if path.is_dir() else path)


def calibrate_dataset(
    dataset: Dataset | str | Path, *, subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None, method: str = "separate", collisions: bool = True,
    model: FaceModel | None = None, progress: bool = False,
) -> dict[str, Calibration]:
    """Calibrate every subject of a ``dataset.Dataset`` (or its folder): subject ->
    Calibration. ``tasks``: the tasks whose first valid lines are used (default: all the
    subject's tasks)."""
    import warnings

    from .corpus import chosen_tasks
    from .dataset import Dataset
    from .face_model import load_model

    ds = dataset if isinstance(dataset, Dataset) else Dataset(dataset)
    model = load_model() if model is None else model
    names = ds.subjects() if subjects is None else [s.upper() for s in subjects]
    if not names or len(ds) == 0:
        raise MissingDataError(f"{ds.root}: no recordings (pellet files .txy) to calibrate from")
    out = {}
    iterator = names
    if progress:
        from tqdm import tqdm

        iterator = tqdm(names, desc="calibrating", unit="subject")
    for subject in iterator:
        wanted = chosen_tasks(ds, subject, tasks)  # the one rule of every dataset run
        if not wanted:
            raise MissingDataError(f"{ds.root}: subject {subject} has none of the tasks {tasks}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            recs = [ds.load(subject, t) for t in wanted]
        out[subject] = calibrate_subject(recs, model, method=method, collisions=collisions)
    return out


def write_summary(
    path: str | Path, calibrations: dict[str, Calibration], *, overwrite: bool = False
) -> Path:
    """A CSV, one row per subject: scale, the calibrated measures and the residuals."""
    from ._io import atomic_write

    res_keys = sorted({k for c in calibrations.values() for k in c.residuals})
    header = ["subject", "method", "scale", "upper_lip_thickness_mm", "lower_lip_thickness_mm",
              "face_width_mm", "converged", "bounds_hit"] + [f"residual_{k}_mm" for k in res_keys]
    rows = [",".join(header)]
    for name, c in calibrations.items():
        values = [name, c.method, f"{c.scale:.6f}", f"{c.upper_lip_thickness:.3f}",
                  f"{c.lower_lip_thickness:.3f}", f"{c.face_width:.3f}", str(c.converged),
                  ";".join(c.bounds_hit)]
        values += [f"{c.residuals.get(k, float('nan')):.4f}" for k in res_keys]
        rows.append(",".join(values))
    return atomic_write(Path(path), "\n".join(rows) + "\n", overwrite=overwrite)
