"""``cassi evaluate DATASET``: CASSI's Table 2 ratings, measured (``cassi_fit.evaluate``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cassi_fit.options import COLLISION_MODES, JAW_METHODS, MODES

from ._corpus import add_run_arguments, finish, run_options


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
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--calibration", metavar="DIR",
                       help="per-subject calibration files written by `cassi calibrate`")
    which.add_argument("--cassi", action="store_true",
                       help="the same as --mode cassi")
    parser.add_argument("--mode", choices=MODES, default=None,
                        help="improved (default) or cassi: every choice of the paper (flat "
                        "tongue of zero thickness, back anchored behind and below T4, only "
                        "the jaw shape adjusted, no collisions; docs/CASSI_MODE.md)")
    parser.add_argument("--collisions", choices=COLLISION_MODES, default=None,
                        help="push the tongue and lips out of the teeth and palate (project) "
                        "or not (off; the default)")
    parser.add_argument("--jaw", choices=JAW_METHODS, default="closed-form",
                        help="how the jaw moves (as in `cassi animate`; default closed-form)")
    parser.add_argument("--stride", type=int, default=1, metavar="N",
                        help="use every Nth data line (default 1: every line)")
    parser.add_argument("--tasks", nargs="+", metavar="TASK",
                        help="only these tasks (names or comma-separated lists, e.g. tp040 "
                        "tp106); default: every task of every subject")
    parser.add_argument("--subjects", nargs="+", metavar="SUBJECT",
                        help="only these subjects (default: all)")
    add_run_arguments(parser)  # recordings in parallel: --jobs, --scheduler, --resume, --force
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def _words(values: list[str] | None) -> list[str] | None:
    """``["a,b", "c"]`` -> ``["a", "b", "c"]`` (None stays None)."""
    if values is None:
        return None
    return [w.strip() for v in values for w in v.split(",") if w.strip()]


def run(args: argparse.Namespace) -> int:
    from cassi_fit.errors import CassiError, OutputExistsError

    if args.stride < 1:
        raise CassiError(f"--stride must be at least 1, got {args.stride}")
    from cassi_fit._cli.animate import chosen_mode

    mode = chosen_mode(args)
    if mode == "cassi" and args.collisions == "project":
        raise CassiError("--cassi (--mode cassi) means the paper's choices, without collision "
                         "handling; drop --collisions project or --cassi")
    if mode == "cassi" and args.calibration:
        raise CassiError("--mode cassi and --calibration exclude each other")
    dataset = Path(args.dataset)
    if not dataset.is_dir():
        raise CassiError(f"{dataset}: no such dataset folder")
    out = Path(args.out)
    from cassi_fit.evaluate import OUTPUT_NAMES, SUMMARY_NAME

    targets = [out / name for name in (*OUTPUT_NAMES, SUMMARY_NAME)]
    existing = [str(p) for p in targets if p.exists()]
    if existing and not (args.force or args.resume):  # refuse before the (slow) evaluation
        raise OutputExistsError(f"{', '.join(existing)}: file exists (pass --force to replace)")
    calibrations = "cassi" if args.cassi else args.calibration
    if args.calibration and not Path(args.calibration).is_dir():
        raise CassiError(f"--calibration {args.calibration}: no such folder")
    from cassi_fit.corpus import evaluate_corpus
    from cassi_fit.evaluate import markdown_table, write_report

    run, result = evaluate_corpus(dataset, out, calibrations=calibrations,
                                  collisions=args.collisions or "off", jaw=args.jaw,
                                  stride=args.stride, tasks=_words(args.tasks),
                                  subjects=_words(args.subjects), mode=mode,
                                  **run_options(args))
    print(markdown_table(result), end="")
    # all or nothing: an interrupted run leaves none of the tables and figure
    written = write_report(result, out, overwrite=args.force or args.resume,
                           summary_name=SUMMARY_NAME)
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr)
    return max(finish(run), 1 if not any(s.rated for s in result.subjects) else 0)
