"""``cassi jaw RECORDING --method ... --csv OUT.csv``: jaw rotation per frame, as a table,
and truth-free diagnostics of the fit beside it (``OUT.diagnostics.csv``)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from cassi_fit.options import JAW_METHODS, SOLVERS

COLUMNS = ("time_s", "theta_deg", "pivot_a_mm", "pivot_b_mm", "tx_mm", "ty_mm", "residual_mm",
           "status")
DIAGNOSTIC_COLUMNS = ("method", "frames_used", "jaw_distance_sd_mm", "jaw_distance_range_mm",
                      "residual_median_mm", "pivot_iqr_x_mm", "pivot_iqr_y_mm",
                      "pivot_plausible_fraction")
# Names of files that hold a recording's data (lower case): never replaced by an output,
# whether or not this command reads them (issue 12).
_DATA_NAMES = ("pal.dat", "pha.dat", "headmeasures.txt")
_DATA_SUFFIXES = ("_pal.dat", "_pha.dat", ".txy", ".wav")


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
        "pivots) are printed and written to OUT.diagnostics.csv; see docs/JAW.md.",
    )
    parser.add_argument("recording", nargs="+", metavar="RECORDING",
                        help="PELLET_FILE, or DATASET_DIR SUBJECT TASK")
    parser.add_argument("--method", choices=JAW_METHODS, default="closed-form")
    parser.add_argument("--solver", choices=SOLVERS, default="optimistix-lm")
    parser.add_argument("--smoothness", type=float, default=1.0, metavar="W",
                        help="smooth-pivot: weight of the pivot-path smoothness prior "
                        "(finite, > 0)")
    parser.add_argument("--compare-methods", action="store_true",
                        help="diagnostics for all four methods, not only --method")
    parser.add_argument("--csv", required=True, metavar="OUT.csv", help="table to write")
    parser.add_argument("--force", action="store_true", help="replace an existing OUT.csv")
    parser.set_defaults(func=run)


def _regular_file(path) -> Path:
    """``path`` if it is a regular file; one clear error for anything else (a FIFO would
    block the reader forever, a folder or device gives no pellet data)."""
    from cassi_fit.errors import MissingDataError

    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:
        raise MissingDataError(f"{path}: no such pellet file") from None
    if not stat.S_ISREG(mode):
        raise MissingDataError(f"{path}: not a regular file (a folder, pipe or device); "
                               f"give a pellet (.txy) file")
    return path


def _load_track(parts):
    """The PelletTrack named by ``[path]`` or ``[dataset_dir, subject, task]``."""
    import warnings

    from cassi_fit.errors import CassiError

    if len(parts) == 1:
        from cassi_fit.txy import read_txy

        return read_txy(_regular_file(parts[0]))
    if len(parts) == 3:
        from cassi_fit.dataset import Dataset

        dataset = Dataset(parts[0])
        _regular_file(dataset.pellet_path(parts[1], parts[2]))
        with warnings.catch_warnings():  # head measures are not used by the jaw fit
            warnings.simplefilter("ignore", UserWarning)
            return dataset.load(parts[1], parts[2]).track
    raise CassiError(f"RECORDING is a pellet file or DATASET_DIR SUBJECT TASK, got {parts}")


def _check_output(out: Path, inputs: list[Path], force: bool) -> None:
    """Refuse, before any work, an output that would replace an input or any recording
    data file (pellet file, PAL.DAT, PHA.DAT, Headmeasures, .wav), be a folder, sit under
    a file, or replace an existing file without ``--force``."""
    from cassi_fit.errors import OutputExistsError

    real = os.path.realpath(out)
    if any(os.path.realpath(p) == real for p in inputs):
        raise OutputExistsError(f"{out}: refusing to overwrite an input file")
    name = out.name.lower()
    if out.exists() and (name in _DATA_NAMES or name.endswith(_DATA_SUFFIXES)):
        raise OutputExistsError(f"{out}: refusing to replace a recording's data file")
    if out.is_dir():
        raise OutputExistsError(f"{out}: is a folder; give a file name for the table")
    parent = next((p for p in out.parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise OutputExistsError(f"{out}: {parent} is a file, not a folder")
    if out.exists() and not force:
        raise OutputExistsError(f"{out}: file exists (pass --force to replace it)")


def diagnostics_path(out: Path) -> Path:
    """``OUT.csv`` -> ``OUT.diagnostics.csv`` (beside the table)."""
    stem = out.name[:-4] if out.name.lower().endswith(".csv") else out.name
    return out.with_name(stem + ".diagnostics.csv")


def format_rows(times, fit) -> str:
    """The CSV text: a header, then one row per frame (see ``COLUMNS``)."""
    import numpy as np

    lines = [",".join(COLUMNS)]
    theta_deg = np.rad2deg(fit.theta)
    for k, name in enumerate(fit.status_names):
        values = (times[k], theta_deg[k], fit.pivot[k, 0], fit.pivot[k, 1],
                  fit.translation[k, 0], fit.translation[k, 1], fit.residual[k])
        lines.append(",".join(f"{v:.6f}" for v in values) + f",{name}")
    return "\n".join(lines) + "\n"


def format_diagnostics(rows) -> str:
    """CSV text of :class:`cassi_fit.jaw_fit.JawDiagnostics` rows."""
    lines = [",".join(DIAGNOSTIC_COLUMNS)]
    for row in rows:
        d = row.to_dict()
        lines.append(",".join(d[c] if isinstance(d[c], str) else
                              (str(d[c]) if isinstance(d[c], int) else f"{d[c]:.4f}")
                              for c in DIAGNOSTIC_COLUMNS))
    return "\n".join(lines) + "\n"


def print_diagnostics(rows) -> None:
    from cassi_fit.jaw_fit import PLAUSIBLE_PIVOT_X_MM as X
    from cassi_fit.jaw_fit import PLAUSIBLE_PIVOT_Y_MM as Y

    print(f"diagnostics (jaw-pellet distance SD/range mm; median residual mm; pivot IQR x/y "
          f"mm; share of pivots in x {X[0]:.0f}..{X[1]:.0f}, y {Y[0]:.0f}..{Y[1]:.0f} mm):")
    for r in rows:
        print(f"  {r.method:13s} distance {r.jaw_distance_sd_mm:.3f}/{r.jaw_distance_range_mm:.3f}"
              f"  residual {r.residual_median_mm:.3f}  pivot IQR {r.pivot_iqr_x_mm:.1f}/"
              f"{r.pivot_iqr_y_mm:.1f}  plausible {100 * r.pivot_plausible_fraction:.0f} %")


def run(args) -> int:
    import jax

    # The CSV reports pivots to a micrometre; at small angles they need float64 (the pivot
    # is a quotient by sin(theta/2)), so the command computes in float64.
    jax.config.update("jax_enable_x64", True)
    from cassi_fit._io import atomic_write
    from cassi_fit.jaw_fit import jaw_diagnostics, jaw_from_track, jaw_method
    from cassi_fit.status import Status
    from cassi_fit.txy import JAW_PELLETS, pellet_index

    method = jaw_method(args.method, solver=args.solver, smoothness=args.smoothness)
    out = Path(args.csv)
    diag_out = diagnostics_path(out)
    inputs = [Path(args.recording[0])] if len(args.recording) == 1 else []
    for path in (out, diag_out):  # refuse before the (slower) fit
        _check_output(path, inputs, args.force)
    track = _load_track(args.recording)
    if track.path is not None:
        for path in (out, diag_out):
            _check_output(path, [track.path], args.force)
    fit = jaw_from_track(track, method=method)
    jaw_points = track.positions[:, [pellet_index(p) for p in JAW_PELLETS], :]
    rows = [jaw_diagnostics(fit, jaw_points)]
    if args.compare_methods:
        others = [jaw_method(m, solver=args.solver, smoothness=args.smoothness)
                  for m in JAW_METHODS if m != args.method]
        rows += [jaw_diagnostics(jaw_from_track(track, method=m), jaw_points) for m in others]
    atomic_write(out, format_rows(track.times, fit), overwrite=args.force)
    atomic_write(diag_out, format_diagnostics(rows), overwrite=args.force)
    ok = int((fit.status <= 1).sum())
    mistracked = int((fit.status == Status.MISTRACKED).sum())
    print(f"{out}: {track.n_frames} frames, {ok} fitted ({args.method}"
          f"{'' if args.method == 'closed-form' else ', ' + fit.solver}), "
          f"{mistracked} mistracked, noise estimate {fit.noise_mm:.3f} mm"
          f"{'' if fit.converged else ', NOT converged'}")
    print_diagnostics(rows)
    print(f"{diag_out}: diagnostics written")
    return 0
