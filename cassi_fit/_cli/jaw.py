"""``cassi jaw RECORDING --method ... --csv OUT.csv``: jaw rotation per frame, as a table,
and truth-free diagnostics of the fit beside it (``OUT.diagnostics.csv``); with labels
beside the pellet file, a label column and ``OUT.segments.csv``. ``--jaw-sensors MNI`` (or
``MNM``) fits one jaw sensor and predicts the other (``MNM_pred_x_mm`` ...).
``cassi jaw DATASET --out DIR``: the same for every recording (``jaw_table.jaw_corpus``)."""

from __future__ import annotations

import math
from pathlib import Path

from cassi_fit.options import ALL_JAW_METHODS, JAW_SENSOR_SETS, SOLVERS

from ._options import (
    add_run_arguments,
    add_source_arguments,
    dataset_args,
    finish,
    load_recording_args,
    run_options,
)

DIAGNOSTIC_COLUMNS = ("method", "jaw_sensors", "frames_used", "jaw_distance_sd_mm",
                      "jaw_distance_range_mm", "residual_median_mm", "pivot_iqr_x_mm",
                      "pivot_iqr_y_mm", "pivot_plausible_fraction", "hidden_error_median_mm",
                      "hidden_error_p95_mm", "prior")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "jaw",
        help="jaw rotation per frame (paper's closed form or a least-squares fit) to CSV",
        description="RECORDING is a pellet (.txy) file, or DATASET_DIR SUBJECT TASK. The "
        "reference is the first line with both jaw pellets (MNI, MNM) tracked and neither "
        "mistracked (cassi info's detector); each row gives the motion p' = R(theta) p + t "
        "from it (theta > 0 = opening), the pivot, the rms pellet residual and a status word "
        "(ok, pivot-undefined, invalid-frame, mistracked, ...). Diagnostics that need no "
        "truth (jaw-pellet distance spread, pivot spread, share of anatomically plausible "
        "pivots) are printed and written to OUT.diagnostics.csv; see docs/JAW.md. Phone or "
        "word labels beside the pellet file (X.lab, X.TextGrid) add a label column and "
        "OUT.segments.csv (peak jaw opening and lip aperture per segment). --jaw-sensors MNI "
        "(or MNM) uses that jaw sensor alone, as most EMA corpora have one: the rotation is "
        "then not determined by the data, closed-form and frame-fit refuse, the pivot methods "
        "rest on a pivot prior and coupled-rotation on a coupling learned from two-sensor "
        "recordings (the prior is written to the diagnostics); the table gains the other "
        "sensor's predicted position (MNM_pred_x_mm, MNM_pred_y_mm) and, where the file has "
        "it, the diagnostics its error. With a DATASET "
        "folder alone and --out DIR: every recording, in parallel, to DIR/SUBJECT/TASK.jaw.csv "
        "(and TASK.segments.csv) and the corpus table DIR/jaw_corpus.csv (and .parquet).",
    )
    parser.add_argument("recording", nargs="+", metavar="RECORDING",
                        help="PELLET_FILE, or DATASET_DIR SUBJECT TASK, or DATASET_DIR "
                        "(with --out)")
    parser.add_argument("--method", choices=ALL_JAW_METHODS, default=None,
                        help="default: the paper's closed form with two jaw sensors, "
                        "coupled-rotation with one")
    parser.add_argument("--jaw-sensors", default=None, metavar="S",
                        help=f"the jaw sensors to use: {', '.join(JAW_SENSOR_SETS)} "
                        "(default: the jaw pellets the recording tracks)")
    add_source_arguments(parser)
    parser.add_argument("--solver", choices=SOLVERS, default=None,
                        help="iterative solver (default: the method's own: the closed form "
                        "for frame-fit, optimistix-lm for the pivot methods)")
    parser.add_argument("--smoothness", type=float, default=1.0, metavar="W",
                        help="smooth-pivot: weight of the pivot-path smoothness prior "
                        "(finite, > 0)")
    parser.add_argument("--compare-methods", action="store_true",
                        help="diagnostics for every method that can run with the jaw "
                        "sensors, not only --method")
    parser.add_argument("--csv", metavar="OUT.csv", help="table to write (one recording)")
    parser.add_argument("--out", metavar="DIR", help="output folder (DATASET form)")
    parser.add_argument("--no-labels", action="store_true",
                        help="ignore label files beside the pellet files")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_run_arguments(parser, force=False)
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    parser.set_defaults(func=run)


def _load_recording(args):
    """The recording named by ``[path]`` or ``[dataset_dir, subject, task]`` (any format the
    toolkit reads; the articulograph options of ``add_source_arguments``); the head
    measures' default warning is left out (the jaw fit does not use them)."""
    import warnings

    from cassi_fit.dataset import DefaultHeadMeasuresWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return load_recording_args(args.recording, args)


def diagnostics_path(out: Path) -> Path:
    """``OUT.csv`` -> ``OUT.diagnostics.csv`` (beside the table)."""
    stem = out.name[:-4] if out.name.lower().endswith(".csv") else out.name
    return out.with_name(stem + ".diagnostics.csv")


def segments_path(out: Path) -> Path:
    """``OUT.csv`` -> ``OUT.segments.csv`` (beside the table)."""
    stem = out.name[:-4] if out.name.lower().endswith(".csv") else out.name
    return out.with_name(stem + ".segments.csv")


def format_diagnostics(rows) -> str:
    """CSV text of :class:`cassi_fit.jaw_fit.JawDiagnostics` rows (``tables.csv_text``,
    4 decimals); a measure that does not exist for the fit (the jaw sensors' distance
    with one of them, the hidden sensor's error with both) is blank."""
    from cassi_fit.tables import blank_if_nan, csv_text

    rows = [{k: blank_if_nan(v) for k, v in row.to_dict().items()} for row in rows]
    return csv_text(rows, DIAGNOSTIC_COLUMNS, digits=4)


def print_diagnostics(rows) -> None:
    from cassi_fit.jaw_fit import PLAUSIBLE_PIVOT_X_MM as X
    from cassi_fit.jaw_fit import PLAUSIBLE_PIVOT_Y_MM as Y

    print(f"diagnostics (jaw-pellet distance SD/range mm; median residual mm; pivot IQR x/y "
          f"mm; share of pivots in x {X[0]:.0f}..{X[1]:.0f}, y {Y[0]:.0f}..{Y[1]:.0f} mm):")
    for r in rows:
        hidden = ("" if r.hidden_error_median_mm != r.hidden_error_median_mm else
                  f"  hidden sensor error {r.hidden_error_median_mm:.2f} median, "
                  f"{r.hidden_error_p95_mm:.2f} p95")
        distance = (f"{r.jaw_distance_sd_mm:.3f}/{r.jaw_distance_range_mm:.3f}"
                    if math.isfinite(r.jaw_distance_sd_mm) else "-/- (one jaw sensor)")
        print(f"  {r.method:16s} distance {distance}"
              f"  residual {r.residual_median_mm:.3f}  pivot IQR {r.pivot_iqr_x_mm:.1f}/"
              f"{r.pivot_iqr_y_mm:.1f}  plausible {100 * r.pivot_plausible_fraction:.0f} %"
              f"{hidden}")


def run(args) -> int:
    from cassi_fit.errors import CassiError

    # a folder with --csv: its one recording (refused in one line when it holds several)
    corpus_form = (len(args.recording) == 1 and Path(args.recording[0]).is_dir()
                   and not args.csv)
    if corpus_form:
        if args.compare_methods:
            raise CassiError("a DATASET folder takes --out DIR (not --compare-methods); one "
                             "recording takes --csv OUT.csv")
        if not args.out:
            raise CassiError(f"{args.recording[0]}: a dataset folder; give --out DIR for "
                             "its tables (or --csv OUT.csv for a folder of one recording, "
                             "DATASET SUBJECT TASK --csv OUT.csv for one of several)")
        return run_dataset(args)
    if args.out or not args.csv:
        raise CassiError("one recording takes --csv OUT.csv (--out DIR is for a DATASET "
                         "folder alone)")
    if args.jobs is not None or args.scheduler or args.resume:
        raise CassiError("--jobs, --scheduler and --resume are for a DATASET folder")
    return run_one(args)


def jaw_spec_from_args(args):
    """The run spec of ``--method`` (with ``--solver``, ``--smoothness``) and
    ``--jaw-sensors`` (``jaw_table.jaw_spec``: float64), checked before any work."""
    from cassi_fit.jaw_fit import jaw_method
    from cassi_fit.jaw_table import jaw_spec

    jaw = None if args.method is None else jaw_method(args.method, solver=args.solver,
                                                      smoothness=args.smoothness)
    return jaw_spec(jaw=jaw, jaw_sensors=args.jaw_sensors)


def run_dataset(args) -> int:
    """``cassi jaw DATASET --out DIR``."""
    from cassi_fit.jaw_table import jaw_corpus

    result = jaw_corpus(dataset_args(args.recording[0], args), args.out, spec=jaw_spec_from_args(args),
                        labels=not args.no_labels, run_options=run_options(args))
    run = result.run
    ok = len(run.results) - len(run.failed)
    what = args.method or "closed-form, or coupled-rotation with one jaw sensor"
    print(f"{ok} of {len(run.results)} recordings fitted ({what}) on {run.workers} "
          f"worker(s); tables: {', '.join(str(p) for p in result.tables)}")
    return finish(run)


def run_one(args) -> int:
    """``cassi jaw RECORDING --csv OUT.csv``: the runner's jaw stage (no model), its tables
    (``jaw_table.write_jaw_tables``) and the diagnostics."""
    from cassi_fit._io import atomic_write, check_outputs, register_input
    from cassi_fit.jaw_fit import jaw_diagnostics
    from cassi_fit.jaw_table import write_jaw_tables
    from cassi_fit.pipeline import JAW, run_recording
    from cassi_fit.txy import JAW_PELLETS, pellet_index

    spec = jaw_spec_from_args(args)  # a bad method or sensor set: refused before any work
    out = Path(args.csv)
    diag_out, seg_out = diagnostics_path(out), segments_path(out)
    outputs = [out, diag_out, seg_out]
    if len(args.recording) == 1:
        register_input(args.recording[0])  # about to be read: never an output
    check_outputs(outputs, overwrite=args.force)  # before reading (a data file is no output)
    recording = _load_recording(args)
    check_outputs(outputs, overwrite=args.force)  # and every file it read, before the fit
    run = run_recording(recording, spec, stages=JAW)
    fit, track = run.jaw, recording.track
    jaw_points = track.positions[:, [pellet_index(p) for p in JAW_PELLETS], :]
    rows = [jaw_diagnostics(fit, jaw_points)]
    if args.compare_methods:
        rows += [jaw_diagnostics(run_recording(recording, spec.replace(jaw=m), stages=JAW).jaw,
                                 jaw_points) for m in _other_methods(args, fit)]
    written = write_jaw_tables(run, out, seg_out, labels=not args.no_labels,
                               overwrite=args.force)
    atomic_write(diag_out, format_diagnostics(rows), overwrite=args.force)
    if written.labels is not None:
        found = written.labels
        print(f"{seg_out}: {len(written.segments)} labelled segments "
              f"({found.path.name if found.path else found.tier})")
    _print_fit(out, track, fit)
    print_diagnostics(rows)
    print(f"{diag_out}: diagnostics written")
    return 0


def _other_methods(args, fit) -> list:
    """The methods ``--compare-methods`` adds: every other one that runs with the fit's
    jaw sensors."""
    from cassi_fit.jaw_fit import jaw_method

    others = [jaw_method(m, solver=args.solver, smoothness=args.smoothness)
              for m in ALL_JAW_METHODS if m != fit.method]
    return [m for m in others if len(fit.jaw_sensors) in m.jaw_sensors_needed]


def _print_fit(out: Path, track, fit) -> None:
    """One line: frames, fitted, method (solver, sensors), mistracked, noise; the prior."""
    from cassi_fit.status import Status, fitted

    ok = int(fitted(fit.status).sum())
    mistracked = int((fit.status == Status.MISTRACKED).sum())
    sensors = fit.jaw_sensors
    noise = (f"noise estimate {fit.noise_mm:.3f} mm" if math.isfinite(fit.noise_mm) else
             "no noise estimate (a fit with one jaw sensor leaves no residual)")
    print(f"{out}: {track.n_frames} frames, {ok} fitted ({fit.method}"
          f"{'' if fit.solver == fit.method else ', ' + fit.solver}"
          f"{'' if len(sensors) == 2 else ', ' + sensors[0] + ' alone'}), "
          f"{mistracked} mistracked, {noise}"
          f"{'' if fit.converged else ', NOT converged (' + fit.failure.label + ')'}")
    if fit.prior:
        print(f"prior: {fit.prior}")
