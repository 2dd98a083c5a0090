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

The result, :class:`~cassi_fit.calibration.Calibration`, is written one JSON file per
subject (``<SUBJECT>.calibration.json``) by ``cassi calibrate`` and read back by
``cassi animate --calibration`` and ``initialize(..., calibration=...)``. The record and
its file (schema, reading, writing, the folder layout) live in
:mod:`cassi_fit.calibration`. The unknowns of the fit (the named pytree ``Unknowns``), its
residuals and the compiled kernels live in :mod:`cassi_fit.calibrate_residuals`.

A fit that fails says so: a stage that does not converge, a jaw shape at its anatomical
bound (held there while the rest is solved again: :func:`_solve_stage`), both recorded
in the calibration and its file and warned (``CalibrationWarning``); the lower lip's
unobservable bias is reported with its size (:func:`lower_lip_bias`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Float

from .calibrate_residuals import (
    GROUPS,
    UNKNOWN_NAMES,
    Problem,
    Unknowns,
    bounded_jaw,
    stage_kernel,
    summary_arrays,
)
from .calibration import (
    BOUND_HIT_FRACTION,
    JAW_SCALE_BOUND,
    JAW_TURN_BOUND_RAD,
    Calibration,
    calibration_records,
    plain,
    warn_problems,
)
from .conformation import skin_landmarks
from .dataset import Dataset, Recording
from .errors import CassiError, DegenerateGeometryError, MissingDataError
from .face_model import FaceModel
from .options import CALIBRATION_METHODS, check_choice
from .pellets import LL, MNI, MNM, PELLET_NAMES, UL, first_valid_line


def bounds_hit(x: Unknowns) -> tuple[str, ...]:
    """The jaw-shape unknowns of ``x`` at (``BOUND_HIT_FRACTION`` of) their bound."""
    theta, log_scale = (np.asarray(a, np.float64) for a in bounded_jaw(x))
    b = math.log(JAW_SCALE_BOUND)
    hit = [name for name, value in zip(("jaw_scale_x", "jaw_scale_y"), log_scale, strict=True)
           if abs(value) >= BOUND_HIT_FRACTION * b]
    if abs(float(theta)) >= BOUND_HIT_FRACTION * JAW_TURN_BOUND_RAD:
        hit.append("jaw_turn")
    return tuple(hit)


# ------------------------------------------------------------------ the observations


def _first_line(recording):
    """``(first index, pellets (8, 2) mm with NaN for pellets never tracked)``."""
    source = recording.source
    first, tracked = first_valid_line(recording.track, source)
    missing = [name for name in ("MNI", "MNM") if name not in tracked]
    if missing:  # one jaw sensor starts an animation, but p/d is the two sensors' distance
        raise MissingDataError(f"{source}: calibration needs both jaw pellets (the scale p/d "
                               f"is their distance); {', '.join(missing)} is never tracked")
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


#: A subject's recordings are padded to a multiple of this many rows (copies of the first,
#: weighing nothing: ``rows`` 0), so that subjects with up to as many recordings share one
#: compiled solver (16-18 s a compilation on two cores) instead of one per count.
RECORDING_BUCKET = 4


def recording_bucket(r: int) -> int:
    """The rows ``r`` recordings are padded to: the next multiple of :data:`RECORDING_BUCKET`."""
    return RECORDING_BUCKET * max(math.ceil(r / RECORDING_BUCKET), 1)


def _data(model, pellets, head):
    """The arrays the residuals depend on (a pytree; subject mm unless named), the
    recordings' rows padded to :func:`recording_bucket` with copies of the first that
    weigh nothing (``rows`` 1 for a recording, 0 for padding; the lips' masks 0 there)."""
    p = np.asarray(pellets)  # (R, 8, 2) subject mm, NaN where never tracked
    r = len(p)
    p = np.concatenate([p, np.repeat(p[:1], recording_bucket(r) - r, axis=0)])
    rows = (np.arange(len(p)) < r).astype(float)
    return {
        "rows": rows,
        "mask_ul": rows * np.isfinite(p[:, UL, 0]),
        "mask_ll": rows * np.isfinite(p[:, LL]).all(-1),
        "pellets": np.nan_to_num(p),
        "d": np.linalg.norm(p[:, MNI] - p[:, MNM], axis=-1),
        # the skin over the bony Headmeasures points, as the model's landmarks are skin
        "head_xy": skin_landmarks(model, head),
        "face_width": np.asarray(float(head.face_width)),
        "mouth_width": np.asarray(float(head.mouth_width)),
        "nose": np.asarray(float(head.nose_protrusion)),
    }


#: The share of subjects whose lower-lip bias lies within :func:`lower_lip_bias`'s range
#: (a normal's central 95 %: mean +- 1.96 SD).
LOWER_LIP_BIAS_COVERAGE_SD = 1.96


def lower_lip_bias(
    model: FaceModel, pellets: Float[np.ndarray, "r 8 2"], scale: float
) -> tuple[float, float]:
    """``(low, high)`` subject mm: the range (:data:`LOWER_LIP_BIAS_COVERAGE_SD`, 95 %) of
    the lower-lip estimate's error, estimate minus truth, that the unobserved incisor tip
    causes, from the first valid lines ``pellets (r, 8, 2)`` subject mm and ``scale`` p/d.

    No pellet sees the lower incisor tip: the estimate places the *model's* tip on the
    subject's jaw pellets, so it is off by how much further ahead of MNI, along the jaw
    line MNM -> MNI, the subject's tip lies than the model's (docs/CALIBRATION.md). The
    model's is known; the subject's is ``depth sin(phi) - labial cos(phi)``, with MNI
    ``depth`` below the incisal edge along the crown and ``labial`` ahead of it, and
    ``phi`` the crown's tilt forward of vertical less the jaw line's fall (the fall seen
    on the first lines, median over them). ``depth``, ``labial`` and the tilt take the
    dental norms of ``synth.NORMS`` (``mni_depth``, ``mni_labial``, ``incisor_tilt_deg``,
    with their sources in docs/SYNTHETIC.md); their spread is carried to first order.
    The synthetic corpus draws its subjects from the same norms, so it cannot test this
    range, only its geometry; a real speaker's pellet may sit elsewhere on the crown.
    """
    from .synth import NORMS

    v = np.asarray(model.vertices, np.float64)[:, :2]
    mni, mnm, tip = (v[model.landmarks[k]] for k in ("MNI", "MNM", "lower_incisor_tip"))
    forward = (mni - mnm) / np.linalg.norm(mni - mnm)
    model_ahead = float(np.dot(tip - mni, forward)) / float(scale)
    line = np.asarray(pellets, np.float64)[:, MNI] - np.asarray(pellets, np.float64)[:, MNM]
    fall = float(np.median(np.arctan2(-line[:, 1], line[:, 0])))
    (depth, sd_depth), (labial, sd_labial) = NORMS["mni_depth"], NORMS["mni_labial"]
    tilt, sd_tilt = (math.radians(a) for a in NORMS["incisor_tilt_deg"])
    phi = tilt - fall
    mean = depth * math.sin(phi) - labial * math.cos(phi)
    sd = math.hypot(math.hypot(math.sin(phi) * sd_depth, math.cos(phi) * sd_labial),
                    (depth * math.cos(phi) + labial * math.sin(phi)) * sd_tilt)
    half = LOWER_LIP_BIAS_COVERAGE_SD * sd
    return (mean - half - model_ahead, mean + half - model_ahead)



_STAGES = {  # method -> [(stage name (calibration.STAGES), free unknowns, residual groups)]
    "separate": [
        ("jaw_shape", ("jaw_theta", "log_jaw_scale"), ("jaw_shape",)),
        ("face_width", ("face_width",), ("face_width",)),
        ("lips", ("upper_lip", "lower_lip"), ("upper_lip", "lower_lip", "collision")),
    ],
    "joint": [("joint", UNKNOWN_NAMES, GROUPS)],
}
# Without Headmeasures only these unknowns are seen by any residual.
_UNMEASURED = ("log_scale", "upper_lip", "lower_lip")

def _pressing_on_a_bound(x, gradient, free):
    """Flat 0/1 over the unknowns: the free jaw-shape unknowns of ``x`` that sit at
    (``BOUND_HIT_FRACTION`` of) their bound while the cost still falls outwards (the
    gradient's sign opposite to the unknown's: the constrained optimum is on the bound)."""
    theta, log_scale = (np.asarray(a, np.float64) for a in bounded_jaw(x))
    zero = np.zeros(())
    near = Unknowns(zero, zero, zero, zero, np.abs(theta) / JAW_TURN_BOUND_RAD,
                    np.abs(log_scale) / math.log(JAW_SCALE_BOUND))
    near = np.asarray(ravel_pytree(near)[0]) >= BOUND_HIT_FRACTION
    u = np.asarray(ravel_pytree(x)[0], np.float64)
    outwards = np.asarray(gradient, np.float64) * u < 0
    return (near & outwards & (free > 0)).astype(np.float64)


def _stage_weights(groups, collisions, dtype):
    """The residual groups' weights of a stage: 1 for ``groups`` (the penalty only with
    ``collisions``), 0 for the others."""
    weights = {g: jnp.asarray(float(g in groups), dtype) for g in GROUPS}
    weights["collision"] = weights["collision"] * float(bool(collisions))
    return weights


def _solve_stage(model, data, measured, x, free, groups, collisions):
    """Least squares over the unknowns named in ``free`` (others held at ``x``) of the
    residual ``groups``; returns ``(x, converged)``.

    A jaw-shape unknown whose optimum lies beyond its anatomical bound never converges in
    the bounded parameterisation (:func:`bounded_jaw`: the solver walks ``u`` out along
    ``tanh``'s flat tail, gaining less and less, until its step budget ends; S09 of the
    default corpus, docs/CALIBRATION.md). Such an unknown is held where it is, within
    ``1 - BOUND_HIT_FRACTION`` of the bound (an active bound, as a bounded solver would
    hold it), and the others are solved again: ``converged`` is that solve's verdict, and
    the bound is reported by :func:`bounds_hit`.
    """
    dtype = x.log_scale.dtype
    weights = _stage_weights(groups, collisions, dtype)
    mask = Unknowns.mask(free, dtype)
    y, converged, gradient = stage_kernel(model, data, measured, x, mask, weights)
    if bool(converged):
        return y, True
    flat_mask, unravel = ravel_pytree(mask)
    held = _pressing_on_a_bound(y, gradient, np.asarray(flat_mask))
    if not held.any():
        return y, False
    mask = unravel(jnp.asarray(np.asarray(flat_mask) * (1.0 - held), dtype))
    y, converged, _ = stage_kernel(model, data, measured, y, mask, weights)
    return y, bool(converged)


def _prepare(recordings, model):
    """What every stage starts from: ``(data, measured, x0, lines)``: the residuals'
    arrays (:func:`_data`), whether the subject has Headmeasures, the unknowns at the
    start (the model's shape, ``s = p / d`` with ``d`` the median first-line jaw pellet
    distance) and each recording's ``(first valid line, its pellets)``."""
    lines = [_first_line(r) for r in recordings]
    pellets = np.stack([p for _, p in lines])
    head, measured = recordings[0].head, not bool(recordings[0].head_is_default)
    dtype = jnp.asarray(model.vertices).dtype
    data = jax.tree.map(lambda a: jnp.asarray(a, dtype), _data(model, pellets, head))
    sites = np.asarray(model.vertices)[[model.landmarks["MNI"], model.landmarks["MNM"]], :2]
    d = np.asarray(data["d"])[:len(recordings)]  # the recordings' rows, not the padding
    s0 = float(np.linalg.norm(sites[0] - sites[1])) / float(np.median(d))
    x = eqx.tree_at(lambda u: u.log_scale, Unknowns.zeros(dtype), jnp.asarray(math.log(s0), dtype))
    return data, measured, x, lines


def calibrate_subject(
    recordings: Iterable[Recording], model: FaceModel | None = None, *,
    method: str = "separate", collisions: bool = True,
) -> Calibration:
    """Calibrate the face model to one subject from its recordings (``dataset.Recording``
    objects, one or more, all of the same subject). Returns a :class:`Calibration`.

    A stage that does not converge, a jaw shape that reaches its anatomical bound, or a
    value outside the calibration file's plausible ranges (``calibration.SCHEMA``; such
    a calibration is not written) is recorded in the result (``converged``,
    ``unconverged``, ``bounds_hit``) and warned (one ``calibration.CalibrationWarning``
    per line of ``Calibration.problems()``); the lower lip's unobservable bias is in
    ``lower_lip_bias`` (:func:`lower_lip_bias`).

    Raises ``CassiError`` for an unknown method, recordings of different subjects or a
    non-finite result; ``MissingDataError`` if no recording is given or a jaw pellet is
    never tracked; ``DegenerateGeometryError`` for coincident jaw pellets on a first
    valid line.
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
    data, measured, x, lines = _prepare(recordings, model)
    unconverged = []
    for stage, free, groups in _STAGES[method]:
        if not measured:
            free = tuple(k for k in free if k in _UNMEASURED)
            groups = tuple(g for g in groups if g not in ("jaw_shape", "face_width"))
        if not free:
            continue
        x, ok = _solve_stage(model, data, measured, x, free, groups, bool(collisions))
        if not ok:
            unconverged.append(stage)
    problem = Problem(model, data, measured)
    result = _summarise(problem, x, method, collisions, tuple(unconverged), recordings, lines)
    if not all(np.isfinite(v) for v in (result.scale, result.upper_lip_thickness,
                                        result.lower_lip_thickness, result.face_width)):
        raise CassiError(f"subject {result.subject}: calibration gave a non-finite value")
    warn_problems(result, stacklevel=2)
    return result


#: The residual groups with one row per recording (padded rows dropped in the summary).
_PER_RECORDING = ("upper_lip", "lower_lip", "jaw_pellets")


def _summarise(problem, x, method, collisions, unconverged, recordings, lines):
    s = float(np.exp(x.log_scale))
    v, groups, model_t, obs, lips_depth, params, lip_rest = summary_arrays(
        problem.model, problem.data, problem.measured, x)
    r = len(recordings)  # the recordings' rows; the padding's are dropped
    groups = {k: np.asarray(g)[:r] if k in _PER_RECORDING else np.asarray(g)
              for k, g in groups.items()}
    upper, lower = (float(t) / s for t in model_t)
    obs_u, obs_l = (np.asarray(t)[:r] / s for t in obs)
    obs_u = np.where(np.asarray(problem.data["mask_ul"])[:r] > 0, obs_u, np.nan)
    obs_l = np.where(np.asarray(problem.data["mask_ll"])[:r] > 0, obs_l, np.nan)

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
        converged=not unconverged,
        bounds_hit=bounds_hit(x) if problem.measured else (),
        unconverged=unconverged,
        lower_lip_bias=lower_lip_bias(problem.model, np.asarray(problem.data["pellets"])[:r], s),
    )


# ------------------------------------------------------------------ datasets


def calibrate_dataset(
    dataset: Dataset | str | Path, *, subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None, method: str = "separate", collisions: bool = True,
    model: FaceModel | None = None, progress: bool = False,
) -> dict[str, Calibration]:
    """Calibrate every subject of a ``dataset.Dataset`` (or its folder): subject ->
    Calibration. ``tasks``: the tasks whose first valid lines are used, chosen as every
    dataset run chooses them (``corpus.chosen_tasks``; default: all the subject's tasks).
    Each subject's problems are warned (``CalibrationWarning``) as
    :func:`calibrate_subject` does."""
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
    path: str | Path, calibrations: Mapping[str, Calibration], *, overwrite: bool = False
) -> Path:
    """A CSV, one row per subject (``calibration.calibration_records``): scale, the
    calibrated measures, convergence, bounds hit, the lower lip's possible bias and the
    residuals (mm)."""
    from .tables import write_table

    return write_table(calibration_records(calibrations), path, overwrite=overwrite)[0]
