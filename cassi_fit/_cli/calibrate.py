"""``cassi calibrate DATASET``: one calibrated face per subject (lip thickness, face width,
jaw shape, scale), fitted through the differentiable model; see ``cassi_fit.calibrate``."""

from __future__ import annotations

import sys
from pathlib import Path

from cassi_fit.options import CALIBRATION_METHODS

from ._options import (
    add_run_arguments,
    add_source_arguments,
    add_speaker_argument,
    dataset_args,
    finish,
    names_option,
    run_options,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="fit each subject's lip thickness, face width, jaw shape and scale",
        description="For every subject of DATASET: lip thickness from the first valid line "
        "of each of its recordings, face width and jaw shape (gonion, gnathion) from "
        "Headmeasures.txt, and the p/d scale, fitted by least squares through the face "
        "model (docs/CALIBRATION.md). Writes OUT/SUBJECT.calibration.json per subject "
        "(use it with 'cassi animate --calibration OUT'), OUT/calibration_summary.csv and "
        "OUT/calibration_corpus.csv (every subject, failed ones with their error). Subjects "
        "are independent tasks: run in parallel (--jobs, --scheduler), resumable (--resume). "
        "A subject whose fit did not converge or whose jaw shape reached its anatomical "
        "bound is written with that recorded in its file and named on stderr, one line "
        "each. Exit status: 1 if any subject failed; else 3 if any calibration has such a "
        "problem, unless --accept-unconverged; else 0.",
    )
    parser.add_argument("dataset", metavar="DATASET", help="a dataset folder")
    parser.add_argument("--out", default="calibration", metavar="DIR",
                        help="folder for the files (default: ./calibration)")
    parser.add_argument("--method", choices=CALIBRATION_METHODS, default="separate",
                        help="separate (default: scale = p/d, then each part on its own "
                        "residuals) or joint (everything, the scale included, at once)")
    parser.add_argument("--subjects", metavar="LIST",
                        help="comma-separated subjects (default: all)")
    parser.add_argument("--tasks", metavar="LIST",
                        help="comma-separated tasks whose first valid lines are used "
                        "(default: all of the subject's)")
    parser.add_argument("--no-collisions", action="store_true",
                        help="leave out the penalty that keeps the lips out of the teeth")
    parser.add_argument("--accept-unconverged", action="store_true",
                        help="exit 0 even if a subject's fit did not converge or reached "
                        "an anatomical bound (still named on stderr and recorded in its "
                        "file)")
    add_source_arguments(parser)  # a dataset's articulograph files: --sensor-map, ...
    add_run_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--acoustic", action="store_true",
                        help="fit each subject's vocal tract (larynx drop, area-rule scales) to "
                        "the formants of the labelled vowels of its recordings with sound, to "
                        "OUT/SUBJECT.acoustic.json (cassi_fit.acoustic_fit)")
    add_speaker_argument(parser, "--acoustic, each recording's")
    parser.set_defaults(func=run)


def run(args) -> int:
    import warnings

    from cassi_fit.calibrate_corpus import calibrate_corpus
    from cassi_fit.calibration import CalibrationWarning, calibration_path
    from cassi_fit.dataset import Dataset
    from cassi_fit.errors import CassiError, OutputExistsError

    if args.acoustic:
        from .acoustics import calibrate_acoustic

        return calibrate_acoustic(args)
    root = Path(args.dataset)
    if not root.is_dir():
        raise CassiError(f"{root}: no such dataset folder")
    source = dataset_args(root, args)  # the folder, or a Dataset with its sensor map
    out = Path(args.out)
    subjects = names_option(args.subjects) or (
        source if isinstance(source, Dataset) else Dataset(root)).subjects()
    targets = [calibration_path(out, s) for s in subjects] + [out / "calibration_summary.csv"]
    if not (args.force or args.resume):
        existing = [str(p) for p in targets if p.exists()]
        if existing:
            raise OutputExistsError(f"{existing[0]}: file exists (pass --force to replace it "
                                    "or --resume to continue)")
    with warnings.catch_warnings():  # the problems are printed below, one line each
        warnings.simplefilter("ignore", CalibrationWarning)
        run, _, cals = calibrate_corpus(source, out, subjects=subjects,
                                        tasks=names_option(args.tasks), run_options=run_options(args),
                                        method=args.method, collisions=not args.no_collisions)
    print(f"{'subject':8} {'scale':>7} {'UL mm':>7} {'LL mm':>7} {'LL bias mm':>12} "
          f"{'face mm':>8}  residuals (mm)")
    for subject, c in cals.items():
        worst = max(c.residuals.items(), key=lambda kv: kv[1])
        bias = (f"{c.lower_lip_bias[0]:+.1f}..{c.lower_lip_bias[1]:+.1f}"
                if len(c.lower_lip_bias) == 2 else "?")
        flag = "" if c.converged else "  NOT CONVERGED"
        flag += f"  AT BOUND ({', '.join(c.bounds_hit)})" if c.bounds_hit else ""
        print(f"{subject:8} {c.scale:7.4f} {c.upper_lip_thickness:7.2f} "
              f"{c.lower_lip_thickness:7.2f} {bias:>12} {c.face_width:8.1f}  largest "
              f"{worst[0]} {worst[1]:.2f}{flag}")
    print(f"wrote {len(cals)} calibration file(s), calibration_summary.csv and "
          f"calibration_corpus.csv to {out} ({run.workers} worker(s)); LL bias: the lower "
          "lip's possible error (estimate minus truth, 95 % of the dental norms) from the "
          "incisor tip no pellet sees")
    status = finish(run)
    problems = [line for c in cals.values() for line in c.problems()]
    for line in problems:
        print(f"cassi: {line}", file=sys.stderr)
    if problems and not args.accept_unconverged:
        print(f"cassi: {len(problems)} problem(s) in the calibrations (recorded in their "
              "files); pass --accept-unconverged to accept them", file=sys.stderr)
        return status or 3
    return status
