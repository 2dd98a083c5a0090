"""``cassi evaluate DATASET``: CASSI's Table 2 ratings, measured (``cassi_fit.evaluate``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._options import (
    add_model_arguments,
    add_run_arguments,
    add_selection_arguments,
    add_source_arguments,
    dataset_args,
    finish,
    names_option,
    run_options,
    spec_from_args,
)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="rate teeth, lips and tongue per subject from measured problems (CASSI Table 2)",
        description="Animate every recording of DATASET, measure the problems CASSI looked "
        "for by eye (lower teeth sloping, teeth overlapping or apart, lips apart or crossing, "
        "the tongue through the front teeth, ...), count them per subject and rate teeth, lips "
        "and tongue EXCELLENT (0 problems), VERY GOOD (1), GOOD (2) or FAIR (3 or more). "
        "Prints the table in Table 2's layout and writes evaluation_subjects.csv, "
        "evaluation_recordings.csv, evaluation.md and evaluation_summary.png into --out. "
        "Thresholds and their reasons: docs/EVALUATION.md.",
    )
    parser.add_argument("dataset", metavar="DATASET", help="dataset folder (either layout)")
    parser.add_argument("--out", default="evaluation", metavar="DIR",
                        help="output folder (default: evaluation/ in the current folder)")
    add_model_arguments(parser)  # the same run options as `cassi animate`
    add_selection_arguments(parser)
    add_source_arguments(parser)  # a dataset's articulograph files: --sensor-map, ...
    add_run_arguments(parser)  # recordings in parallel: --jobs, --scheduler, --resume, --force
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cassi_fit.errors import CassiError, OutputExistsError

    spec = spec_from_args(args)  # checked before anything is read or run
    dataset = Path(args.dataset)
    if not dataset.is_dir():
        raise CassiError(f"{dataset}: no such dataset folder")
    out = Path(args.out)
    from cassi_fit.evaluate import OUTPUT_NAMES, SUMMARY_NAME

    targets = [out / name for name in (*OUTPUT_NAMES, SUMMARY_NAME)]
    existing = [str(p) for p in targets if p.exists()]
    if existing and not (args.force or args.resume):  # refuse before the (slow) evaluation
        raise OutputExistsError(f"{', '.join(existing)}: file exists (pass --force to replace)")
    from cassi_fit.evaluate import evaluate_corpus, markdown_table, write_report

    run, _, result = evaluate_corpus(dataset_args(dataset, args), out, spec=spec, tasks=names_option(args.tasks),
                                     subjects=names_option(args.subjects),
                                     run_options=run_options(args))
    print(markdown_table(result), end="")
    flagged = {r.item.subject: r.row["calibration_problems"] for r in run.results
               if r.row.get("calibration_problems")}
    for subject, problems in flagged.items():  # a fitted calibration that is not trusted
        print(f"cassi: warning: {subject}: calibration: {problems}", file=sys.stderr)
    # all or nothing: an interrupted run leaves none of the tables and figure
    written = write_report(result, out, overwrite=args.force or args.resume,
                           summary_name=SUMMARY_NAME)
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr)
    return max(finish(run), 1 if not any(s.rated for s in result.subjects) else 0)
