"""Real recordings as the referee: every model predicts a sensor it never saw.

    python experiments/real_referee.py DATASET [--out DIR] [--docs DIR] [--force]
        [--label NAME] [--subjects S ...] [--tasks T ...]
        [--synthetic DIR|default|none] [--synthetic-subjects N] [--synthetic-tasks T ...]

DATASET is any folder of XRMB recordings (either layout, ``cassi_fit.dataset.Dataset``),
e.g. the real JW11 task 5 in /work/shared/data/xrmb_jw11/. Beside it the same is run on the
synthetic corpus (``cassi_fit.synth.ensure_default_corpus()``, its speech tasks
``SYNTHETIC_TASKS``; ``--synthetic-subjects`` and ``--synthetic-tasks`` choose a subset,
``--synthetic DIR`` another corpus, ``--synthetic none`` none). Per recording, three
held-out tests, each scored on the frames where every pellet it uses and the hidden one
are tracked and not flagged by the mistrack detector (``PelletTrack.mistracks``), the
reference frame excluded:

- **Jaw** (:func:`jaw_part`). With both jaw sensors present, each is hidden in turn (MNM
  predicted from MNI alone, MNI from MNM alone). Methods: the library's single-sensor jaw
  methods (:func:`single_sensor_methods`, ``jaw_from_track(..., jaw_sensors=SEEN)``,
  ``JawFit.hidden_predicted``); "coupled-rotation" gets a coupling learned on other
  speakers only (:class:`Couplings`). Baselines: ``static`` (the hidden sensor stays at
  its reference-frame position) and ``translate`` (it moves as the seen sensor does).
  References that saw both sensors: ``two-pellet fixed pivot`` (``jaw_from_track(method=
  "fixed-pivot")`` on both pellets, its motion applied to the hidden sensor's reference
  position) and ``two-pellet pivot, seen angle`` (that pivot, each frame's angle from the
  seen sensor alone: a single-sensor method with a perfect pivot prior). Score: the
  distance (mm) between the predicted and the measured hidden sensor.
- **Tongue** (:func:`tongue_part`). With all four tongue pellets present, T2 and T3 are
  hidden in turn (the recording loaded with that pellet never tracked) and the toolkit's
  own pipeline (``pipeline.run_recording``) runs in the improved mode (thick tongue) and in
  the cassi mode (CASSI's flat tongue), every ``TONGUE_STRIDE``-th line; whatever the
  pipeline does with a never-tracked tongue pellet (today ``frames.tongue_fill``: its
  displacement interpolated in arc length between its neighbours') is what is scored.
  Scores: ``surface``, the distance from the measured hidden pellet to the model tongue's
  upper midsagittal contour (the polyline of its upper-midline vertices,
  ``deform.tongue_midline``: the section of the tongue's surface at z = 0); ``site``, the
  distance to where the model puts the hidden pellet (``Animation.pellets_model``);
  ``along``, the distance along the contour from that site to the foot of the
  perpendicular from the measured pellet (the tangential part of ``site``). Baseline:
  linear interpolation between the neighbouring pellets (``surface``: the distance to the
  chord between them; ``site``: the point at the model's rest arc-length fraction along it).
- **Lips** (:func:`lips_part`). The lower lip (LL, held out) predicted from the jaw
  alone: the jaw's motion from the reference frame (the pipeline's jaw method with both
  jaw pellets, ``run_spec.IMPROVED.jaw_method_for(("MNI", "MNM"))``: the closed form) applied to LL's reference position with
  the model's lower-lip jaw weight (``rigid.fractional``; CASSI's weight 1.11 and Parke's
  1.0). Baselines: ``static`` and ``moves with MNI``. The jaw pellets are not held out
  here; UL has no model predictor (the model moves it by its own pellet only): not scored.

Statistics: the median and 95th percentile of the per-frame errors, per recording and
pooled over a dataset's recordings (frames pooled), each with a 95 % percentile-bootstrap
interval of ``BOOTSTRAP`` resamples: within a recording a moving-block bootstrap (blocks of
``BLOCK_S`` seconds of consecutive scored frames: neighbouring frames share movement and
noise); pooled, subjects resampled with replacement (with all their recordings), then
blocks within each recording. Paired comparisons: a method's statistic minus a baseline's
(or a reference's) on the same resampled frames, with its interval; ``better``/``worse``
only where the interval excludes 0, else ``tie``. Every resample is seeded from names
(dataset, subject, task, part), so a re-run of one recording reproduces its rows exactly.

Writes ``real_referee.csv`` (every row), ``real_referee_couplings.csv`` (the couplings
learned) and ``real_referee.md`` (the side-by-side tables, rendered from the CSVs) into
--out (default experiments/output) and, with --docs, into that folder too; the Markdown's
first line names the command. Outputs are checked before any work and never replaced
without --force. Fits and animations run on tracks padded with untracked frames to a
multiple of ``PAD_FRAMES`` (:func:`padded`), so that they compile once per length class.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from referee_parts import (
    COLUMNS,
    COUPLING_COLUMNS,
    COUPLING_DIGITS,
    OUTPUT_NAMES,
    SYNTHETIC_LABEL,
    SYNTHETIC_TASKS,
)
from referee_report import issue_check, markdown
from referee_rows import parse_rows, run


# ------------------------------------------------------------------------------- main
def _command(argv) -> str:
    """The command line as the Markdown header names it; an absolute path as seen from the
    current folder (the checkout, under make), so the header names no one machine's path."""
    import os

    return " ".join(["python experiments/real_referee.py",
                     *(os.path.relpath(a) if os.path.isabs(a) else a for a in argv)])


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="a folder of XRMB recordings (e.g. the real JW11)")
    parser.add_argument("--label", help="the dataset's name in the tables (default: the "
                        "folder's name)")
    parser.add_argument("--subjects", nargs="+", help="only these subjects of DATASET")
    parser.add_argument("--tasks", nargs="+", help="only these tasks of DATASET")
    parser.add_argument("--synthetic", default="default", help="the synthetic corpus beside "
                        "it: a folder, 'default' (ensure_default_corpus) or 'none'")
    parser.add_argument("--synthetic-subjects", type=int, help="only the first N subjects")
    parser.add_argument("--synthetic-tasks", nargs="+", default=list(SYNTHETIC_TASKS),
                        help=f"synthetic tasks (default: {' '.join(SYNTHETIC_TASKS)})")
    parser.add_argument("--out", default="experiments/output", help="folder for the tables")
    parser.add_argument("--docs", help="also write the tables into this folder")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)

    from cassi_fit._io import atomic_write, check_outputs
    from cassi_fit.errors import CassiError
    from cassi_fit.tables import csv_text

    root = Path(args.dataset)
    if not root.is_dir():
        print(f"real_referee: {root}: not a folder", file=sys.stderr)
        return 1
    folders = [Path(args.out)] + ([Path(args.docs)] if args.docs else [])
    try:  # refuse before any work, as the toolkit's writers do
        outputs = check_outputs([f / n for f in folders for n in OUTPUT_NAMES],
                                overwrite=args.force)
    except CassiError as exc:
        print(f"real_referee: {exc} (pass --force to replace it)", file=sys.stderr)
        return 1

    import jax

    jax.config.update("jax_enable_x64", True)  # errors of a few hundredths of a mm
    from cassi_fit import synth

    def progress(text):
        print(f"real_referee: {text}", file=sys.stderr, flush=True)

    label = args.label or root.name
    datasets = [(label, root, args.subjects, args.tasks)]
    if args.synthetic != "none":
        corpus = synth.ensure_default_corpus() if args.synthetic == "default" \
            else Path(args.synthetic)
        names = None if args.synthetic_subjects is None \
            else synth.subject_names(args.synthetic_subjects)
        datasets.append((SYNTHETIC_LABEL, corpus, names, args.synthetic_tasks))
    rows, couplings = run(datasets, progress=progress)
    table = csv_text(rows, COLUMNS)
    coupling_table = csv_text(couplings, COUPLING_COLUMNS, digits=COUPLING_DIGITS)
    # the Markdown shows exactly what the CSVs hold
    rows, couplings = parse_rows(table), parse_rows(coupling_table)
    text = markdown(rows, _command(argv), couplings)
    content = {OUTPUT_NAMES[0]: table, OUTPUT_NAMES[1]: coupling_table, OUTPUT_NAMES[2]: text}
    for path in outputs:
        atomic_write(path, content[path.name], overwrite=args.force)
    print(issue_check(rows, label))
    return 0


if __name__ == "__main__":
    sys.exit(main())
