"""``cassi jaw RECORDING --method ... --csv OUT.csv``: jaw rotation per frame, as a table."""

from __future__ import annotations

METHODS = ("closed-form", "frame-fit", "fixed-pivot", "smooth-pivot")  # = jaw_fit.METHODS
SOLVERS = ("optimistix-lm", "optimistix-gn", "optimistix-dogleg", "jaxopt-lm", "jaxopt-gn")
COLUMNS = ("time_s", "theta_deg", "pivot_a_mm", "pivot_b_mm", "tx_mm", "ty_mm", "residual_mm",
           "status")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "jaw",
        help="jaw rotation per frame (paper's closed form or a least-squares fit) to CSV",
        description="RECORDING is a pellet (.txy) file, or DATASET_DIR SUBJECT TASK. The "
        "reference is the first frame with both jaw pellets (MNI, MNM) tracked; each row "
        "gives the motion p' = R(theta) p + t from it (theta > 0 = opening), the pivot, the "
        "rms pellet residual and a status word (ok, pivot-undefined, invalid-frame, ...). "
        "fixed-pivot or smooth-pivot is recommended for speech: see docs/JAW.md.",
    )
    parser.add_argument("recording", nargs="+", metavar="RECORDING",
                        help="PELLET_FILE, or DATASET_DIR SUBJECT TASK")
    parser.add_argument("--method", choices=METHODS, default="closed-form")
    parser.add_argument("--solver", choices=SOLVERS, default="optimistix-lm")
    parser.add_argument("--smoothness", type=float, default=1.0, metavar="W",
                        help="smooth-pivot: weight of the pivot-path smoothness prior")
    parser.add_argument("--csv", required=True, metavar="OUT.csv", help="table to write")
    parser.add_argument("--force", action="store_true", help="replace an existing OUT.csv")
    parser.set_defaults(func=run)


def _load_track(parts):
    """The PelletTrack named by ``[path]`` or ``[dataset_dir, subject, task]``."""
    import warnings

    from cassi_fit.errors import CassiError

    if len(parts) == 1:
        from cassi_fit.txy import read_txy

        return read_txy(parts[0])
    if len(parts) == 3:
        from cassi_fit.dataset import Dataset

        with warnings.catch_warnings():  # head measures are not used by the jaw fit
            warnings.simplefilter("ignore", UserWarning)
            return Dataset(parts[0]).load(parts[1], parts[2]).track
    raise CassiError(f"RECORDING is a pellet file or DATASET_DIR SUBJECT TASK, got {parts}")


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


def run(args) -> int:
    import jax

    # The CSV reports pivots to a micrometre; at small angles they need float64 (the pivot
    # is a quotient by sin(theta/2)), so the command computes in float64.
    jax.config.update("jax_enable_x64", True)
    from pathlib import Path

    from cassi_fit._io import atomic_write
    from cassi_fit.errors import OutputExistsError
    from cassi_fit.jaw_fit import jaw_from_track

    out = Path(args.csv)
    if out.exists() and not args.force:  # refuse before the (slower) fit
        raise OutputExistsError(f"{out}: file exists (pass --force to replace it)")
    track = _load_track(args.recording)
    fit = jaw_from_track(track, method=args.method, solver=args.solver,
                         smoothness=args.smoothness)
    atomic_write(out, format_rows(track.times, fit), overwrite=args.force)
    ok = int((fit.status <= 1).sum())
    print(f"{out}: {track.n_frames} frames, {ok} fitted ({args.method}"
          f"{'' if args.method == 'closed-form' else ', ' + fit.solver}), "
          f"noise estimate {fit.noise_mm:.3f} mm{'' if fit.converged else ', NOT converged'}")
    return 0
