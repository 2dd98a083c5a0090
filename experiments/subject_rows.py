"""The computations of experiments/subject_fitting.py: the plans and settings, the
corpus, the calibrations and the truth they are checked against, the recovery, noise
and penetration rows, and the evaluation of both settings.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SEED = 0


METHODS = ("separate", "joint")


#: Estimated quantities compared with the truth: name -> unit ("" = dimensionless).
QUANTITIES = {"upper_lip_thickness": "mm", "lower_lip_thickness": "mm", "face_width": "mm",
              "scale": ""}


#: ``all_within``'s default quantities (the summary applies it to the upper lip only: the
#: lower lip carries the unobserved tip offset, face width is set, not fitted).
CHECKED = ("upper_lip_thickness", "lower_lip_thickness", "face_width")


TOLERANCE_PERCENT = 5.0


LIPS = ("upper_lip_thickness", "lower_lip_thickness")


NOISE_SCALES = (0.0, 1.0, 2.0)


JAW = "closed-form"  # the evaluation's default, used by both settings


PENETRATION_PERCENTILE = 95.0


#: Per-frame penetration depth of a kind = the deepest of these ``collide.REPORT_KEYS``.
PENETRATION_KINDS = {
    "tongue_in_teeth": ("tongue_upper_teeth", "tongue_lower_teeth"),
    "tongue_in_palate": ("tongue_palate",),
    "lips_in_teeth": ("lips_upper_teeth", "lips_lower_teeth"),
}


#: The evaluation settings: output folder -> (calibration, collisions, label).
SETTINGS = {
    "cassi_like": ("cassi", "off", "CASSI-like (paper's conformation, collisions off)"),
    "calibrated_only": ("separate", "off", "calibrated (separate), collisions off"),
    "calibrated": ("separate", "project", "calibrated (separate) + collisions projected"),
}


#: Geometry the lower-lip estimate cannot see (subject mm, along the jaw line MNM -> MNI):
#: row column -> meaning. The estimate places the *model's* lower incisor tip on the
#: subject's jaw pellets, so it is off by exactly how much further ahead of MNI the
#: subject's tip is than the model's (``tip_offset_difference_mm``), plus pellet noise.
GEOMETRY = {
    "true_tip_ahead_of_mni_mm": "subject's lower incisor tip ahead of MNI (synthetic truth)",
    "model_tip_ahead_of_mni_mm": "the model's, in subject mm (divided by the true scale p/d)",
    "tip_offset_difference_mm": "true minus model: the lower-lip error it predicts",
}


@dataclass(frozen=True)
class Plan:
    """How much to run: subjects and tasks of the corpus, subjects of the noise study."""

    n_subjects: int
    tasks: tuple[str, ...]
    noise_subjects: int
    stride: int = 1  # the evaluation's and the penetration's every stride-th data line


FULL = Plan(n_subjects=15, tasks=("tp106", "tp040", "tp020_2"), noise_subjects=15)


#: ``--small`` (the tests' run). Every 12th line: each recording's frames (at most 58 of
#: these tasks) fit the smallest frame bucket (``cassi_fit.frames.frame_bucket``: 64), so
#: every recording of the plan shares one compiled animation and computes half the frames
#: of the next bucket.
SMALL = Plan(n_subjects=2, tasks=("tp106", "tp040"), noise_subjects=2, stride=12)


#: the notebook: one subject, every step of the run; the tasks and stride of ``SMALL`` (the
#: same compilations: a calibration's depends on the number of recordings per subject)
TINY = Plan(n_subjects=1, tasks=("tp106", "tp040"), noise_subjects=1, stride=12)


# ------------------------------------------------------------------ pure helpers


def percent_error(estimate: float, truth: float) -> float:
    """Signed error of ``estimate`` relative to ``truth``, percent."""
    return 100.0 * (float(estimate) - float(truth)) / float(truth)


def _column(quantity: str) -> str:
    return f"{quantity}_mm" if QUANTITIES[quantity] == "mm" else quantity


def recovery_rows(calibrations: dict, truths: dict | None = None) -> list[dict]:
    """One row per method and subject.

    ``calibrations``: method -> {subject -> Calibration} (only the attributes named in
    ``QUANTITIES``, ``residuals``, ``converged`` and ``head_is_default`` are read);
    ``truths``: subject -> {quantity -> true value} (and optionally the ``GEOMETRY``
    keys, copied), or None (no truth: no error columns).
    Residual columns are the union of the groups over all calibrations (NaN where a
    calibration lacks one).
    """
    groups = sorted({k for cals in calibrations.values() for c in cals.values()
                     for k in c.residuals})
    rows = []
    for method, cals in calibrations.items():
        for subject, cal in cals.items():
            row = {"method": method, "subject": subject, "converged": bool(cal.converged),
                   "head_is_default": bool(cal.head_is_default)}
            for q in QUANTITIES:
                row[_column(q)] = float(getattr(cal, q))
                if truths is not None:
                    row[f"true_{_column(q)}"] = float(truths[subject][q])
                    row[f"{q}_error_percent"] = percent_error(getattr(cal, q), truths[subject][q])
            if truths is not None and "lower_lip_thickness" in QUANTITIES:
                row["lower_lip_thickness_error_mm"] = float(
                    cal.lower_lip_thickness - truths[subject]["lower_lip_thickness"])
                for k in (k for k in GEOMETRY if k in truths[subject]):
                    row[k] = float(truths[subject][k])
            for g in groups:
                row[f"residual_{g}_mm"] = float(cal.residuals.get(g, np.nan))
            rows.append(row)
    return rows


def worst_errors(rows: list[dict], quantities=tuple(QUANTITIES)) -> dict:
    """``(method, quantity) -> largest |error| (percent)`` over the subjects of ``rows``
    (NaN if any is NaN)."""
    errors = {}
    for row in rows:
        for q in quantities:
            errors.setdefault((row["method"], q), []).append(row[f"{q}_error_percent"])
    return {key: float(np.max(np.abs(v))) for key, v in errors.items()}


def all_within(rows: list[dict], quantities=CHECKED, tolerance=TOLERANCE_PERCENT) -> bool:
    """Whether every row's |error| of every quantity is below ``tolerance`` percent
    (a non-finite error is not within)."""
    errors = np.array([[row[f"{q}_error_percent"] for q in quantities] for row in rows], float)
    return bool(errors.size) and bool(np.all(np.abs(errors) < tolerance))


def noise_summary(rows: list[dict], quantities=LIPS) -> list[dict]:
    """Per noise level, method and quantity: the median and largest |error| over the
    subjects, mm and percent. ``rows``: recovery rows with a ``noise_scale`` key."""
    from cassi_fit.synth import DEFAULT_NOISE_MM

    out = []
    keys = dict.fromkeys((r["noise_scale"], r["method"]) for r in rows)
    for noise, method in keys:
        sel = [r for r in rows if r["noise_scale"] == noise and r["method"] == method]
        for q in quantities:
            col = _column(q)
            mm = np.abs([r[col] - r[f"true_{col}"] for r in sel])
            pct = np.abs([r[f"{q}_error_percent"] for r in sel])
            out.append({"noise_scale": float(noise),
                        "noise_sd_mm": float(noise) * float(DEFAULT_NOISE_MM),
                        "method": method, "quantity": q, "subjects": len(sel),
                        "median_abs_error_mm": float(np.median(mm)),
                        "max_abs_error_mm": float(np.max(mm)),
                        "median_abs_error_percent": float(np.median(pct)),
                        "max_abs_error_percent": float(np.max(pct))})
    return out


def depth_percentiles(penetration: dict, q: float = PENETRATION_PERCENTILE) -> dict:
    """``collide.REPORT_KEYS -> (m,)`` per-frame depths (mm) -> the ``q``-th percentile
    over frames of each ``PENETRATION_KINDS`` depth (the deepest of its keys per frame)."""
    out = {}
    for kind, keys in PENETRATION_KINDS.items():
        per_frame = np.max(np.stack([np.asarray(penetration[k], float) for k in keys]), axis=0)
        out[kind] = float(np.percentile(per_frame, q))
    return out


def csv_text(rows: list[dict]) -> str:
    """Rows of dicts (the first row's keys are the columns) as CSV; floats to 6 digits."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(list(rows[0]))
    for r in rows:
        writer.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in r.values()])
    return buffer.getvalue()


# ------------------------------------------------------------------ the steps


def make_corpus(root, plan: Plan, noise_scale: float = 1.0, n_subjects: int | None = None):
    """The synthetic corpus of ``plan`` (seed ``SEED``, no audio) written to ``root``."""
    from cassi_fit.synth import generate_corpus

    return generate_corpus(root, n_subjects=n_subjects or plan.n_subjects, seed=SEED,
                           tasks=plan.tasks, noise_scale=noise_scale, audio=False)


def true_values(root, subjects, model) -> dict:
    """subject -> {quantity -> truth} from each subject's ``anatomy.json``; the true scale
    is the model's MNI-MNM distance over the subject's (rigid, noise-free) one. Also the
    ``GEOMETRY`` columns: where the subject's lower incisor tip lies ahead of MNI along
    the jaw line, against the model's (subject mm)."""
    from cassi_fit.synth import load_anatomy

    v = np.asarray(model.vertices)[:, :2]
    mni, mnm, tip = (v[model.landmarks[k]] for k in ("MNI", "MNM", "lower_incisor_tip"))
    p = float(np.linalg.norm(mni - mnm))
    model_ahead = float(np.dot(tip - mni, (mni - mnm) / p))  # model mm
    out = {}
    for s in subjects:
        a = load_anatomy(root, s)
        scale = p / a.jaw_pellet_distance
        forward = (a.mni_rest - a.mnm_rest) / a.jaw_pellet_distance
        true_ahead = float(np.dot(a.lower_incisor_tip_rest - a.mni_rest, forward))
        out[s] = {"upper_lip_thickness": a.upper_lip_thickness,
                  "lower_lip_thickness": a.lower_lip_thickness,
                  "face_width": a.face_width, "scale": scale,
                  "true_tip_ahead_of_mni_mm": true_ahead,
                  "model_tip_ahead_of_mni_mm": model_ahead / scale,
                  "tip_offset_difference_mm": true_ahead - model_ahead / scale}
    return out


def calibrate_all(root, model, tasks=None, subjects=None, progress=False) -> dict:
    """method -> {subject -> Calibration} for every method in ``METHODS``."""
    from cassi_fit.calibrate import calibrate_dataset

    return {m: calibrate_dataset(root, subjects=subjects, tasks=tasks, method=m, model=model,
                                 progress=progress) for m in METHODS}


def noise_study(workdir, plan: Plan, model) -> list[dict]:
    """Step 2: recovery rows (with ``noise_scale``) of corpora at every ``NOISE_SCALES``."""
    rows = []
    for noise in NOISE_SCALES:
        root = make_corpus(Path(workdir) / f"noise_{noise:g}", plan, noise,
                           n_subjects=plan.noise_subjects)
        cals = calibrate_all(root, model)
        truths = true_values(root, cals[METHODS[0]], model)
        rows += [{"noise_scale": noise, **r} for r in recovery_rows(cals, truths)]
    return rows


def evaluate_both(root, calibrations: dict, model, tasks=None, progress=False,
                  settings=tuple(SETTINGS), stride: int = 1) -> dict:
    """Step 3: folder name (``settings``, names of ``SETTINGS``) -> ``EvaluationResult``."""
    from cassi_fit.evaluate import evaluate_dataset

    out = {}
    for name in settings:
        calibration, collisions, _ = SETTINGS[name]
        cal = calibration if calibration == "cassi" else calibrations[calibration]
        out[name] = evaluate_dataset(root, calibration=cal, collisions=collisions, tasks=tasks,
                                     subjects=list(calibrations[METHODS[0]]), jaw=JAW,
                                     model=model, progress=progress, stride=stride)
    return out


def penetration_rows(root, calibrations: dict, model, tasks=None, stride: int = 1) -> list[dict]:
    """Per recording and setting, ``depth_percentiles`` of the animation: CASSI-like (no
    projection) and calibrated before and after projection. A recording that cannot be
    animated gets a row with its error as ``status`` (as in the evaluation)."""
    import warnings

    from cassi_fit.dataset import Dataset
    from cassi_fit.errors import CassiError
    from cassi_fit.pipeline import run_recording

    ds = Dataset(root)
    rows = []
    for subject, cal in calibrations["separate"].items():
        for task in [t for t in ds.tasks(subject) if tasks is None or t in tasks]:
            row = {"subject": subject, "task": task, "status": "ok", "frames": 0}
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    rec = ds.load(subject, task)
                plain = run_recording(rec, model=model, calibration="cassi", jaw=JAW,
                                      collisions="off", stride=stride).animation
                fitted = run_recording(rec, model=model, calibration=cal, jaw=JAW,
                                       collisions="project", stride=stride).animation
            except CassiError as exc:
                rows.append({**row, "status": f"error: {exc}"})
                continue
            row["frames"] = plain.n_frames
            for label, depths in (("cassi_like", plain.penetration_after),
                                  ("calibrated_before", fitted.penetration),
                                  ("calibrated_after", fitted.penetration_after)):
                for kind, value in depth_percentiles(depths).items():
                    row[f"{label}_{kind}_p95_mm"] = value
            rows.append(row)
    return rows


# ------------------------------------------------------------------ documentation tables
