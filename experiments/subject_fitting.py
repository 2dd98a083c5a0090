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
import sys
import time
from pathlib import Path

import numpy as np
from subject_report import (
    DOC_TABLES,
    cost_markdown,
    noise_markdown,
    output_names,
    penetration_markdown,
    plot_geometry,
    plot_noise,
    plot_recovery,
    recovery_markdown,
    totals_markdown,
    write_evaluation,
)
from subject_rows import (
    FULL,
    METHODS,
    NOISE_SCALES,
    PENETRATION_KINDS,
    QUANTITIES,
    SETTINGS,
    SMALL,
    TOLERANCE_PERCENT,
    all_within,
    calibrate_all,
    csv_text,
    evaluate_both,
    make_corpus,
    noise_study,
    noise_summary,
    penetration_rows,
    recovery_rows,
    true_values,
    worst_errors,
)


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
