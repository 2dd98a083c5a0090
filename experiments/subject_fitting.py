"""Subject-specific fitting: does calibration recover a speaker's face, and does it help?

    python experiments/subject_fitting.py [--out experiments/output] [--docs DIR] [--small]
                                          [--force]
    python experiments/subject_fitting.py --dataset DIR [--tasks tp005,tp010] [--out DIR]

Synthetic part (a corpus from ``cassi_fit.synth.generate_corpus``, seed ``SEED``, written
to a temporary folder and removed afterwards; the true anatomy of every subject is known):

1. Calibration recovery. ``calibrate.calibrate_dataset`` with each method (``"separate"``,
   ``"joint"``); per subject the estimated and true upper and lower lip thickness, face
   width and scale ``p/d`` with their percent errors, every residual group
   (``Calibration.residuals``, subject mm) and whether the fit converged:
   ``calibration_recovery.csv``, ``calibration_recovery.png`` (estimated vs true, the
   identity line and the +-5 % band), ``lower_lip_geometry.png`` (the lower lip's error
   against the tip-offset difference, ``GEOMETRY``).
2. Lip thickness vs pellet noise. The corpus regenerated at ``noise_scale`` 0, 1 and 2
   (times the default 0.21 mm per coordinate) and calibrated again; the median and largest
   |error| per level, method and lip: ``lip_noise.csv``, ``lip_noise.png``.
3. The evaluation (``cassi_fit.evaluate``) in the three ``SETTINGS``: CASSI-like
   (calibration ``"cassi"``, collisions off), calibrated (step 1's ``"separate"``
   calibrations) with collisions off, and calibrated with collisions projected. Each is
   written with ``write_table`` and ``plot_summary`` into its folder (``cassi_like/``,
   ``calibrated_only/``, ``calibrated/``); ``compare`` of the first and the last into
   ``evaluation_comparison.md``. Per recording, the 95th
   percentile over frames of the penetration depths (tongue in the teeth, tongue in the
   palate, lips in the teeth): ``penetration.csv``, ``penetration.png``.
4. A summary on stdout: the worst errors per method, whether the upper lip's errors are
   within ``TOLERANCE_PERCENT``, what remains of the lower lip's once the tip-offset
   difference is taken off, face width's difference from the setting, the rating totals
   of the evaluations.

Dataset part (``--dataset DIR``, instead of the synthetic one; there is no truth): the
calibration of every subject by both methods with its residuals
(``calibration_residuals.csv``), then step 3 on that dataset.

Face width is *set* from Headmeasures' ``face_width``, which on the synthetic corpus *is*
the truth: its "error" only says whether the model can reach the measurement, and is no
fitting accuracy. The lip thicknesses are inferred from the pellets of the first valid
lines, so their errors carry the pellet noise; the lower one also carries the difference
between the subject's incisor-tip-to-MNI geometry and the model's (``GEOMETRY``), which no
pellet observes. ``--docs DIR`` also writes the Markdown tables the documentation quotes
(``DOC_TABLES``), each headed by the command that wrote it. Nothing is overwritten: if an output exists the run stops before any
work, unless ``--force``.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
import time
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
SMALL = Plan(n_subjects=2, tasks=("tp106", "tp040"), noise_subjects=2, stride=5)
#: the notebook: one subject, one task, every step of the run
TINY = Plan(n_subjects=1, tasks=("tp106",), noise_subjects=1, stride=5)


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

    from cassi_fit.animate import animate
    from cassi_fit.dataset import Dataset
    from cassi_fit.errors import CassiError
    from cassi_fit.initialize import initialize

    ds = Dataset(root)
    rows = []
    for subject, cal in calibrations["separate"].items():
        for task in [t for t in ds.tasks(subject) if tasks is None or t in tasks]:
            row = {"subject": subject, "task": task, "status": "ok", "frames": 0}
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    rec = ds.load(subject, task)
                state = initialize(rec, model, calibration="cassi")
                plain = animate(state, rec, jaw=JAW, collisions="off", stride=stride)
                state = initialize(rec, model, calibration=cal)
                fitted = animate(state, rec, jaw=JAW, collisions="project", stride=stride)
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

DOCS_COMMAND = ("python experiments/subject_fitting.py --out experiments/output "
                "--docs docs/generated --force")
#: The Markdown files ``--docs`` writes (README.md and docs/ quote their tables verbatim).
DOC_TABLES = ("calibration_recovery.md", "lip_noise.md", "evaluation_totals.md",
              "penetration.md", "subject_fitting_cost.md")


def _header(title: str, text: str) -> str:
    return (f"<!-- written by `{DOCS_COMMAND}`; do not edit: `make experiments` rewrites it "
            f"-->\n# {title}\n\n{text}\n\n")


def _table(head: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def recovery_markdown(rows: list[dict]) -> str:
    """``calibration_recovery.md``: per method the worst errors, then per subject the lip
    errors beside the unobserved tip-offset difference (``GEOMETRY``)."""
    worst = worst_errors(rows)
    n = len({r["subject"] for r in rows})
    summary = []
    for m in METHODS:
        sel = [r for r in rows if r["method"] == m]
        rest = [abs(r["lower_lip_thickness_error_mm"] - r["tip_offset_difference_mm"])
                for r in sel]
        span = {g: [r[f"residual_{g}_mm"] for r in sel] for g in ("gonion", "gnathion")}
        summary.append([m, f"{worst[(m, 'upper_lip_thickness')]:.2f}",
                        f"{worst[(m, 'lower_lip_thickness')]:.2f}", f"{max(rest):.2f}",
                        f"{worst[(m, 'scale')]:.2f}",
                        *(f"{min(v):.2f}-{max(v):.2f}" for v in span.values()),
                        f"{max(r['residual_lips_in_teeth_mm'] for r in sel):.3f}",
                        f"{worst[(m, 'face_width')]:.2f}",
                        f"{sum(r['converged'] for r in sel)}/{len(sel)}"])
    per = {(r["method"], r["subject"]): r for r in rows}
    subjects = list(dict.fromkeys(r["subject"] for r in rows))
    detail = []
    for subj in subjects:
        a, b = per[METHODS[0], subj], per[METHODS[1], subj]
        detail.append([subj, f"{a['true_upper_lip_thickness_mm']:.2f}",
                       f"{a['upper_lip_thickness_error_percent']:+.2f}",
                       f"{b['upper_lip_thickness_error_percent']:+.2f}",
                       f"{a['true_lower_lip_thickness_mm']:.2f}",
                       f"{a['tip_offset_difference_mm']:+.2f}",
                       f"{a['lower_lip_thickness_error_mm']:+.2f}",
                       f"{a['lower_lip_thickness_error_percent']:+.2f}",
                       f"{b['lower_lip_thickness_error_percent']:+.2f}"])
    text = (f"The default synthetic corpus ({n} subjects, tasks {', '.join(FULL.tasks)}, seed "
            f"{SEED}), calibrated by both methods. |error| in percent of the truth. The "
            "lower-lip estimate places the *model's* lower incisor tip on the subject's jaw "
            "pellets; the synthetic subject's own tip-to-MNI geometry is drawn from dental "
            "norms (docs/SYNTHETIC.md), so the estimate is off by the difference (tip offset "
            "difference: how much further ahead of MNI, along MNM -> MNI, the subject's tip "
            "lies than the model's, subject mm). \"lower minus offset\": the largest "
            "|lower-lip error - offset difference| (mm), what remains once that difference is "
            "accounted for. Face width is set directly from Headmeasures (which on the "
            "synthetic corpus holds the truth): its column says the model reaches the "
            "measurement; it is no fitting accuracy.")
    return (_header("Calibration recovery (synthetic truth)", text)
            + _table(["method", "upper lip, worst abs error %", "lower lip, worst abs error %",
                      "lower minus offset, worst mm", "scale p/d, worst abs error %",
                      "gonion residual mm", "gnathion residual mm", "lips in teeth, max mm",
                      "face width (set from Headmeasures), worst abs difference %", "converged"],
                     summary)
            + "\nPer subject (lip errors signed; mm for the lower lip's, beside the offset "
            "difference that predicts it):\n\n"
            + _table(["subject", "upper lip true mm", "upper error % (separate)",
                      "upper error % (joint)", "lower lip true mm", "tip offset difference mm",
                      "lower error mm (separate)", "lower error % (separate)",
                      "lower error % (joint)"], detail))


def noise_markdown(summary: list[dict]) -> str:
    """``lip_noise.md``: median and largest |lip error| per noise level and method."""
    rows = [[f"{r['noise_sd_mm']:.2f}", r["method"], r["quantity"].split("_")[0],
             f"{r['median_abs_error_mm']:.3f}", f"{r['max_abs_error_mm']:.3f}",
             f"{r['max_abs_error_percent']:.2f}"] for r in summary]
    text = (f"The corpus regenerated at noise scales {', '.join(f'{n:g}' for n in NOISE_SCALES)}"
            f" ({summary[0]['subjects']} subjects) and calibrated again. The lower lip's error "
            "does not fall to 0 without noise: it is the unobserved tip-offset difference "
            "(calibration_recovery.md).")
    return (_header("Lip thickness vs pellet noise", text)
            + _table(["noise SD per coordinate mm", "method", "lip", "median abs error mm",
                      "max abs error mm", "max abs error %"], rows))


def totals_markdown(results: dict) -> str:
    """``evaluation_totals.md``: rating totals per setting beside CASSI's Table 2."""
    from cassi_fit.evaluate import CASSI_TOTALS, COMPONENTS

    def text(t):
        return "/".join(str(int(k)) for k in t)

    rows = [["CASSI's Table 2 (real subjects, rated by eye)",
             *(text(CASSI_TOTALS[c]) for c in COMPONENTS)]]
    for name, result in results.items():
        rated = sum(s.rated for s in result.subjects)
        totals = result.totals()
        rows.append([f"{SETTINGS[name][2]} ({rated} subjects)",
                     *(text(totals[c]) for c in COMPONENTS)])
    intro = ("Subjects rated EXCELLENT/VERY GOOD/GOOD/FAIR (CASSI's Table 2 layout; thresholds "
             f"in docs/EVALUATION.md), on the default synthetic corpus (tasks "
             f"{', '.join(FULL.tasks)}); jaw: {JAW}.")
    return _header("Evaluation totals", intro) + _table(["setting", *COMPONENTS], rows)


def penetration_markdown(rows: list[dict]) -> str:
    """``penetration.md``: per kind, the median and largest over recordings of the 95th
    percentile depth in each setting."""
    ok = [r for r in rows if r["status"] == "ok"]
    out = []
    for kind in PENETRATION_KINDS:
        cells = []
        for s in ("cassi_like", "calibrated_before", "calibrated_after"):
            v = [r[f"{s}_{kind}_p95_mm"] for r in ok]
            cells.append(f"{np.median(v):.2f} / {np.max(v):.2f}")
        out.append([kind.replace("_", " "), *cells])
    intro = (f"Per recording ({len(ok)} of {len(rows)} animated), the {PENETRATION_PERCENTILE:g}th "
             "percentile over frames of the penetration depth (mm); cells: median / largest "
             "over recordings.")
    return (_header("Penetration depths", intro)
            + _table(["kind", "CASSI-like", "calibrated, collisions off",
                      "calibrated, collisions projected"], out))


def cost_markdown(seconds: dict, recordings: int, subjects: int) -> str:
    """``subject_fitting_cost.md``: wall time of each step of this run (one run, 2 cores)."""
    intro = (f"Wall time of one run of the experiment ({subjects} subjects, {recordings} "
             "recordings), including JAX compilation; one run on a shared 2-core machine, so "
             "expect a spread of tens of percent.")
    return (_header("Cost of the subject-fitting experiment", intro)
            + _table(["step", "seconds"], [[k, f"{v:.0f}"] for k, v in seconds.items()]))


# ------------------------------------------------------------------ figures


def _save(fig, path, overwrite):
    import matplotlib.pyplot as plt

    from cassi_fit._io import atomic_write

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return atomic_write(path, buffer.getvalue(), overwrite=overwrite)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_recovery(rows, path, overwrite=False):
    """Estimated vs true, one panel per quantity, identity line and the +-5 % band."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(QUANTITIES), figsize=(4.0 * len(QUANTITIES), 4.0))
    for ax, q in zip(axes, QUANTITIES, strict=True):
        col = _column(q)
        truth = np.array([r[f"true_{col}"] for r in rows])
        lo, hi = truth.min(), truth.max()
        pad = 0.08 * (hi - lo) + 0.02 * hi
        line = np.array([lo - pad, hi + pad])
        ax.fill_between(line, line * (1 - TOLERANCE_PERCENT / 100),
                        line * (1 + TOLERANCE_PERCENT / 100), color="0.88",
                        label=f"+-{TOLERANCE_PERCENT:g} %")
        ax.plot(line, line, color="0.4", lw=1, label="estimate = truth")
        for method, marker in zip(METHODS, "ox", strict=False):
            sel = [r for r in rows if r["method"] == method]
            ax.plot([r[f"true_{col}"] for r in sel], [r[col] for r in sel], marker, ms=5,
                    ls="none", mfc="none" if marker == "o" else None, label=method)
        unit = f" ({QUANTITIES[q]})" if QUANTITIES[q] else ""
        ax.set(xlim=line, ylim=line, xlabel=f"true{unit}", ylabel=f"estimated{unit}",
               title=q.replace("_", " ") + (" p/d" if q == "scale" else ""), aspect="equal")
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Calibration recovery on the synthetic corpus ({len(rows) // len(METHODS)} "
                 "subjects)")
    return _save(fig, path, overwrite)


def plot_geometry(rows, path, overwrite=False):
    """Lower-lip error (mm) vs the tip-offset difference the estimate cannot see, both
    methods, with the identity line (the error the difference predicts)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(4.6, 4.2))
    x = np.array([r["tip_offset_difference_mm"] for r in rows])
    line = np.array([x.min() - 0.3, x.max() + 0.3])
    ax.plot(line, line, color="0.4", lw=1, label="error = offset difference")
    for method, marker in zip(METHODS, "ox", strict=False):
        sel = [r for r in rows if r["method"] == method]
        ax.plot([r["tip_offset_difference_mm"] for r in sel],
                [r["lower_lip_thickness_error_mm"] for r in sel], marker, ms=5, ls="none",
                mfc="none" if marker == "o" else None, label=method)
    ax.set(xlabel="subject's minus model's tip ahead of MNI (mm)",
           ylabel="lower lip estimate - truth (mm)",
           title="Lower lip: the unobserved incisor geometry", aspect="equal")
    ax.legend(fontsize=7)
    return _save(fig, path, overwrite)


def plot_noise(summary, path, overwrite=False):
    """Median (solid) and largest (dashed) |lip thickness error| vs pellet noise; colour:
    the lip, marker: the method."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for (method, marker), (k, q) in ((m, q) for m in zip(METHODS, "ox", strict=False)
                                     for q in enumerate(LIPS)):
        sel = sorted((r for r in summary if r["method"] == method and r["quantity"] == q),
                     key=lambda r: r["noise_sd_mm"])
        x = [r["noise_sd_mm"] for r in sel]
        label = f"{q.split('_')[0]} lip, {method}"
        for stat, ls in (("median", "-"), ("max", "--")):
            ax.plot(x, [r[f"{stat}_abs_error_percent"] for r in sel], marker=marker, ls=ls,
                    color=f"C{k}", mfc="none", label=f"{label}: {stat}")
    ax.axhline(TOLERANCE_PERCENT, color="tab:red", lw=1, ls=":")
    ax.set(xlabel="pellet noise SD per coordinate (mm)", ylabel="|lip thickness error| (%)",
           title=f"Lip thickness estimate vs pellet noise ({sel[0]['subjects']} subjects)")
    ax.legend(fontsize=6, ncol=2)
    return _save(fig, path, overwrite)


def plot_penetration(rows, path, overwrite=False):
    """Per kind, the 95th-percentile depth of every recording in each setting (a grey line
    joins one recording's values)."""
    plt = _pyplot()
    labels = {"cassi_like": "CASSI-like", "calibrated_before": "calibrated,\nbefore projection",
              "calibrated_after": "calibrated,\nprojected"}
    ok = [r for r in rows if r["status"] == "ok"]
    fig, axes = plt.subplots(1, len(PENETRATION_KINDS), figsize=(12, 3.8), sharey=True)
    for ax, kind in zip(axes, PENETRATION_KINDS, strict=True):
        values = np.array([[r[f"{s}_{kind}_p95_mm"] for s in labels] for r in ok]).reshape(-1, 3)
        x = np.arange(len(labels))
        for v in values:
            ax.plot(x, v, color="0.75", lw=0.7)
        for j in x:
            ax.plot(np.full(len(values), j), values[:, j], "o", color=f"C{j}", ms=4)
        ax.set_xticks(x, list(labels.values()), fontsize=8)
        ax.set_xlim(-0.4, len(labels) - 0.6)
        ax.set_title(kind.replace("_", " "))
    axes[0].set_ylabel(f"{PENETRATION_PERCENTILE:g}th percentile over frames (mm)")
    fig.suptitle(f"Per-frame penetration depth, {len(ok)} recordings", y=1.03)
    return _save(fig, path, overwrite)


# ------------------------------------------------------------------ outputs and summary


def output_names(synthetic: bool) -> list[str]:
    """The files a run writes, relative to ``--out``."""
    from cassi_fit.evaluate import OUTPUT_NAMES

    names = (["calibration_recovery.csv", "calibration_recovery.png", "lower_lip_geometry.png",
              "lip_noise.csv", "lip_noise.png"] if synthetic else ["calibration_residuals.csv"])
    for folder in SETTINGS:
        names += [f"{folder}/{n}" for n in (*OUTPUT_NAMES, "evaluation_summary.png")]
    return names + ["evaluation_comparison.md", "penetration.csv", "penetration.png"]


def write_evaluation(results: dict, penetration: list[dict], out: Path, overwrite: bool):
    """Step 3's files: both tables and summaries, the comparison, the penetration."""
    from cassi_fit._io import atomic_write
    from cassi_fit.evaluate import compare, plot_summary, write_table

    for folder, result in results.items():
        write_table(result, out / folder, overwrite=overwrite)
        plot_summary(result, out / folder / "evaluation_summary.png", overwrite=overwrite)
    a, b = results["cassi_like"], results["calibrated"]
    text = compare(a, b, labels=(SETTINGS["cassi_like"][2], SETTINGS["calibrated"][2]))
    failed = [f"{r.subject} {r.task} ({r.error})" for k in SETTINGS
              for r in results[k].failed]
    atomic_write(out / "evaluation_comparison.md",
                 "# CASSI-like vs calibrated + collisions\n\n" + text
                 + ("\nNot evaluated: " + "; ".join(failed) + "\n" if failed else ""),
                 overwrite=overwrite)
    atomic_write(out / "penetration.csv", csv_text(penetration), overwrite=overwrite)
    plot_penetration(penetration, out / "penetration.png", overwrite=overwrite)


def summary_lines(recovery: list[dict] | None, noise: list[dict] | None, results: dict,
                  penetration: list[dict] | None = None) -> list[str]:
    """The stdout summary (step 4); a part given as None (or empty) is left out."""
    lines = []
    if recovery:
        worst = worst_errors(recovery)
        for m in METHODS:
            sel = [r for r in recovery if r["method"] == m]
            lines.append(f"{m:9s} worst |error|: " + ", ".join(
                f"{q.replace('_thickness', '').replace('_', ' ')} {worst[(m, q)]:.2f}%"
                for q in QUANTITIES if q != "face_width") + f"; converged {sum(r['converged'] for r in sel)}"
                f"/{len(sel)}")
        verdict = "yes" if all_within(recovery, ("upper_lip_thickness",)) else "NO"
        lines.append(f"upper lip thickness errors within {TOLERANCE_PERCENT:g}%: {verdict}")
        rest = max(abs(r["lower_lip_thickness_error_mm"] - r["tip_offset_difference_mm"])
                   for r in recovery)
        lines.append(f"lower lip: largest |error - tip offset difference| {rest:.2f} mm "
                     "(the difference no pellet observes; calibration_recovery.md)")
        lines.append("face width is set from Headmeasures (not fitted): largest |difference| "
                     f"{max(worst[(m, 'face_width')] for m in METHODS):.2f}%")
    if noise:
        for r in (r for r in noise if r["method"] == "separate"):
            lines.append(f"noise x{r['noise_scale']:g} {r['quantity']:20s} |error| median "
                         f"{r['median_abs_error_mm']:.3f} mm, max {r['max_abs_error_mm']:.3f} mm"
                         f" ({r['max_abs_error_percent']:.2f}%)")
    for name, result in results.items():
        totals = result.totals()
        lines.append(f"ratings {SETTINGS[name][2]}: " + "; ".join(
            f"{c} {'/'.join(map(str, t))}" for c, t in totals.items())
            + " (EXCELLENT/VERY GOOD/GOOD/FAIR)")
    ok = [r for r in penetration or () if r["status"] == "ok"]
    for kind in PENETRATION_KINDS if ok else ():
        med = [float(np.median([r[f"{s}_{kind}_p95_mm"] for r in ok]))
               for s in ("cassi_like", "calibrated_before", "calibrated_after")]
        lines.append(f"{kind:16s} p95 depth, median over recordings: CASSI-like {med[0]:.2f} "
                     f"mm, calibrated {med[1]:.2f} mm, projected {med[2]:.2f} mm")
    return lines


# ------------------------------------------------------------------ main


def _run_synthetic(plan, out, force, model, clock, docs=None):
    import tempfile

    from cassi_fit._io import atomic_write

    with tempfile.TemporaryDirectory(prefix="cassi_subject_fitting_") as workdir:
        root = make_corpus(Path(workdir) / "corpus", plan)
        cals = calibrate_all(root, model)
        truths = true_values(root, cals[METHODS[0]], model)
        recovery = recovery_rows(cals, truths)
        atomic_write(out / "calibration_recovery.csv", csv_text(recovery), overwrite=force)
        plot_recovery(recovery, out / "calibration_recovery.png", overwrite=force)
        plot_geometry(recovery, out / "lower_lip_geometry.png", overwrite=force)
        clock("calibration recovery (both methods)")
        noise = noise_summary(noise_study(workdir, plan, model))
        atomic_write(out / "lip_noise.csv", csv_text(noise), overwrite=force)
        plot_noise(noise, out / "lip_noise.png", overwrite=force)
        clock(f"lip thickness vs noise ({len(NOISE_SCALES)} corpora x both methods)")
        results = evaluate_both(root, cals, model, progress=sys.stderr.isatty(),
                                stride=plan.stride)
        penetration = penetration_rows(root, cals, model, stride=plan.stride)
        write_evaluation(results, penetration, out, force)
        clock(f"evaluation ({len(SETTINGS)} settings) and penetration")
    if docs is not None:
        texts = {"calibration_recovery.md": recovery_markdown(recovery),
                 "lip_noise.md": noise_markdown(noise),
                 "evaluation_totals.md": totals_markdown(results),
                 "penetration.md": penetration_markdown(penetration),
                 "subject_fitting_cost.md": cost_markdown(
                     clock.seconds, len(penetration), plan.n_subjects)}
        for name, text in texts.items():
            atomic_write(Path(docs) / name, text, overwrite=force)
    return summary_lines(recovery, noise, results, penetration)


def _run_dataset(root, tasks, out, force, model, clock, stride=1):
    from cassi_fit._io import atomic_write
    from cassi_fit.dataset import Dataset
    from cassi_fit.errors import MissingDataError

    ds = Dataset(root)
    subjects = [s for s in ds.subjects() if tasks is None or set(tasks) & set(ds.tasks(s))]
    if not subjects:
        raise MissingDataError(f"{root}: no subject has any of the tasks {', '.join(tasks)}")
    progress = sys.stderr.isatty()
    cals = calibrate_all(ds, model, tasks=tasks, subjects=subjects, progress=progress)
    rows = recovery_rows(cals)
    atomic_write(out / "calibration_residuals.csv", csv_text(rows), overwrite=force)
    clock("calibration")
    results = evaluate_both(ds, cals, model, tasks=tasks, progress=progress, stride=stride)
    penetration = penetration_rows(root, cals, model, tasks, stride=stride)
    write_evaluation(results, penetration, out, force)
    clock("evaluation")
    lines = []
    for m in METHODS:
        sel = [r for r in rows if r["method"] == m]
        res = {k: max(r[k] for r in sel) for k in sel[0] if k.startswith("residual_")}
        lines.append(f"{m:9s} converged {sum(r['converged'] for r in sel)}/{len(sel)}; largest "
                     "residuals (mm): " + ", ".join(f"{k[9:-3]} {v:.2f}" for k, v in res.items()))
    return lines + summary_lines(None, None, results, penetration)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="experiments/output", help="folder for the outputs")
    parser.add_argument("--small", action="store_true",
                        help=f"{SMALL.n_subjects} subjects, tasks {','.join(SMALL.tasks)}, "
                        f"every {SMALL.stride}th line evaluated (default {FULL.n_subjects} "
                        f"subjects, {','.join(FULL.tasks)}, every line)")
    parser.add_argument("--dataset", metavar="DIR",
                        help="run on this dataset instead (no truth: calibration residuals "
                        "and the evaluation only)")
    parser.add_argument("--tasks", help="with --dataset: comma-separated tasks (default all)")
    parser.add_argument("--stride", type=int, default=1,
                        help="with --dataset: evaluate every STRIDE-th data line (default 1)")
    parser.add_argument("--docs", metavar="DIR",
                        help="also write the documentation's Markdown tables (DOC_TABLES) "
                        "into DIR (synthetic runs only; make experiments: docs/generated)")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)
    if args.tasks and not args.dataset:
        parser.error("--tasks goes with --dataset (the synthetic tasks are fixed)")
    if args.docs and args.dataset:
        parser.error("--docs goes with the synthetic run (the tables quote its truth)")
    import jax

    # Lip thickness errors of a few hundredths of a mm are compared: float32 would blur them.
    jax.config.update("jax_enable_x64", True)
    from cassi_fit.errors import CassiError
    from cassi_fit.face_model import load_model

    out = Path(args.out)
    paths = [out / n for n in output_names(args.dataset is None)]
    paths += [Path(args.docs) / n for n in DOC_TABLES] if args.docs else []
    existing = [p for p in paths if p.exists()]
    if existing and not args.force:
        print(f"error: {existing[0]} exists (and {len(existing) - 1} more outputs); "
              "pass --force to replace them", file=sys.stderr)
        return 1
    start = last = time.perf_counter()

    def clock(step):
        nonlocal last
        now = time.perf_counter()
        print(f"[{step}: {now - last:.0f} s]", flush=True)
        clock.seconds[step] = now - last
        last = now

    clock.seconds = {}

    model = load_model()
    try:
        if args.dataset:
            tasks = [t.strip().lower() for t in args.tasks.split(",")] if args.tasks else None
            lines = _run_dataset(args.dataset, tasks, out, args.force, model, clock,
                                 args.stride)
        else:
            lines = _run_synthetic(SMALL if args.small else FULL, out, args.force, model, clock,
                                   args.docs)
    except CassiError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print("\n".join(lines))
    print(f"outputs in {out} ({time.perf_counter() - start:.0f} s in all)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
