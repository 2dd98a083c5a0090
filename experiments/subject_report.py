"""The outputs of experiments/subject_fitting.py: the Markdown tables the documentation
quotes, the figures, and the evaluation's files.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from subject_rows import (
    FULL,
    JAW,
    LIPS,
    METHODS,
    NOISE_SCALES,
    PENETRATION_KINDS,
    PENETRATION_PERCENTILE,
    QUANTITIES,
    SEED,
    SETTINGS,
    TOLERANCE_PERCENT,
    _column,
    csv_text,
    worst_errors,
)

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
