"""Closed form or fit? Jaw-rotation methods compared on synthetic truth (and on real data).

    python experiments/jaw_comparison.py --out experiments/output [--small] [--dataset DIR] [--force]

Synthetic part (cassi_fit.synth, true jaw motion known): for each noise level (0, 0.1, 0.3,
0.6 mm per coordinate) and each method, per frame: angle error, pivot error (against the
true motion's fixed point), and the error of the lower incisor tip and of the chin point
(gnathion) moved by the estimated motion. Binned by the true |theta| from the reference
frame. Writes ``jaw_comparison.csv``, ``pivot_error_vs_theta.png`` (with the angle below
which the closed-form pivot is not trustworthy), ``point_error_vs_noise.png``.
Dataset part (no truth): per recording and method the median residual, a pivot scatter,
and the rms angle difference to the per-frame fit: ``dataset_methods.csv``,
``dataset_pivots.png``.
"""

from __future__ import annotations

import argparse
import io
import sys

import numpy as np

NOISES_MM = (0.0, 0.1, 0.3, 0.6)
THETA_BINS_DEG = (0.0, 1.0, 2.0, 4.0, 8.0, 16.0, 90.0)
TRUST_PIVOT_MM = 5.0  # a pivot is "trustworthy" when its median error is below this
METHODS = ("closed-form", "frame-fit", "fixed-pivot", "smooth-pivot")


def _true_motion(truth, f0):
    """Per-frame true motion (theta, t) from frame ``f0`` and its fixed point."""
    import jax

    from cassi_fit import rigid

    rel = jax.vmap(rigid.relative, in_axes=((None, None), (0, 0)))(
        (truth.theta[f0], truth.translation[f0]), (truth.theta, truth.translation))
    pivot, defined = jax.vmap(lambda th, t: rigid.pivot((th, t)))(*rel)
    return np.asarray(rel[0]), np.asarray(rel[1]), np.asarray(pivot), np.asarray(defined)


def _moved(theta, t, point):
    return np.stack([np.cos(theta) * point[0] + np.sin(theta) * point[1] + t[:, 0],
                     -np.sin(theta) * point[0] + np.cos(theta) * point[1] + t[:, 1]], -1)


def _frame_errors(track, truth, anatomy, method):
    """Per-frame errors of one method on one recording: dict of (n_used,) arrays."""
    from cassi_fit import rigid
    from cassi_fit.jaw_fit import jaw_from_track
    from cassi_fit.txy import JAW_PELLETS, first_valid_frame

    f0 = first_valid_frame(track, JAW_PELLETS)
    fit = jaw_from_track(track, method=method)
    theta, t, pivot, defined = _true_motion(truth, f0)
    use = fit.status <= 1
    out = {"theta_deg": np.rad2deg(np.abs(theta)), "angle_err_deg":
           np.rad2deg(np.abs(fit.theta - theta))}
    out["pivot_err_mm"] = np.where(defined & fit.pivot_defined,
                                   np.linalg.norm(fit.pivot - pivot, axis=1), np.inf)
    for name, rest in (("incisor", anatomy.lower_incisor_tip_rest), ("chin", anatomy.chin_rest)):
        at_f0 = np.asarray(rigid.apply(truth.theta[f0], truth.translation[f0], rest))
        err = _moved(fit.theta, fit.translation, at_f0) - _moved(theta, t, at_f0)
        out[f"{name}_err_mm"] = np.linalg.norm(err, axis=1)
    return {k: v[use] for k, v in out.items()}


def synthetic_table(small: bool):
    """Rows (dicts) of the binned comparison over noise levels, methods and recordings."""
    from cassi_fit.synth import make_subject, synth_recording

    n_subjects, tasks, duration = (1, ("tp106",), 3.0) if small else (3, ("tp106", "tp040"), 6.0)
    pooled = {}
    for s in range(n_subjects):
        anatomy = make_subject(f"S9{s}", np.random.default_rng(100 + s))
        for task in tasks:
            for noise in NOISES_MM:
                track, truth = synth_recording(anatomy, task, seed=(s, len(task), 7),
                                               noise_mm=noise, duration_s=duration,
                                               dropouts=False, mistracks=False)
                for method in METHODS:
                    errs = _frame_errors(track, truth, anatomy, method)
                    for k, v in errs.items():
                        pooled.setdefault((method, noise), {}).setdefault(k, []).append(v)
    rows = []
    for (method, noise), errs in pooled.items():
        errs = {k: np.concatenate(v) for k, v in errs.items()}
        for lo, hi in zip(THETA_BINS_DEG[:-1], THETA_BINS_DEG[1:], strict=True):
            sel = (errs["theta_deg"] >= lo) & (errs["theta_deg"] < hi)
            if not sel.any():
                continue
            row = {"method": method, "noise_mm": noise, "theta_lo_deg": lo, "theta_hi_deg": hi,
                   "frames": int(sel.sum())}
            for k in ("angle_err_deg", "pivot_err_mm", "incisor_err_mm", "chin_err_mm"):
                v = errs[k][sel]
                v = v[np.isfinite(v)]  # pivot undefined (theta = 0) in truth or estimate
                row[f"median_{k}"] = float(np.median(v)) if v.size else float("inf")
            rows.append(row)
    return rows


def trust_threshold(rows, method="closed-form", noise=0.3):
    """Smallest |theta| (deg) from which every bin's median pivot error is < TRUST_PIVOT_MM."""
    bins = sorted((r for r in rows if r["method"] == method and r["noise_mm"] == noise),
                  key=lambda r: r["theta_lo_deg"])
    threshold = None
    for r in bins:
        if r["median_pivot_err_mm"] < TRUST_PIVOT_MM:
            threshold = r["theta_lo_deg"] if threshold is None else threshold
        else:
            threshold = None
    return threshold


def _csv(rows) -> str:
    keys = list(rows[0])
    buf = io.StringIO()
    buf.write(",".join(keys) + "\n")
    for r in rows:
        buf.write(",".join(f"{r[k]:.6g}" if isinstance(r[k], float) else str(r[k])
                           for k in keys) + "\n")
    return buf.getvalue()


def _figures(rows, out, overwrite):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cassi_fit._io import atomic_write

    figs = {}
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for method in METHODS:
        sel = [r for r in rows if r["method"] == method and r["noise_mm"] == 0.3]
        mids = [np.sqrt(max(r["theta_lo_deg"], 0.25) * r["theta_hi_deg"]) for r in sel]
        ax.plot(mids, [r["median_pivot_err_mm"] for r in sel], "o-", label=method)
    threshold = trust_threshold(rows)
    ax.axhline(TRUST_PIVOT_MM, color="grey", ls=":")
    if threshold is not None:
        ax.axvline(max(threshold, 0.25), color="red", ls="--",
                   label=f"closed form trustworthy from {threshold:g} deg")
    ax.set(xscale="log", yscale="log", xlabel="|theta| from reference (deg)",
           ylabel="median pivot error (mm)", title="Pivot error at 0.3 mm pellet noise")
    ax.legend(fontsize=8)
    figs["pivot_error_vs_theta.png"] = fig
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for method in METHODS:
        noise = sorted({r["noise_mm"] for r in rows})
        med = [np.average([r["median_chin_err_mm"] for r in rows
                           if r["method"] == method and r["noise_mm"] == n],
                          weights=[r["frames"] for r in rows
                                   if r["method"] == method and r["noise_mm"] == n])
               for n in noise]
        ax.plot(noise, med, "o-", label=method)
    ax.set(xlabel="pellet noise SD (mm)", ylabel="chin point error (mm, median)",
           title="Error of the chin point moved by the estimated jaw motion")
    ax.legend(fontsize=8)
    figs["point_error_vs_noise.png"] = fig
    for name, fig in figs.items():
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        atomic_write(out / name, buf.getvalue(), overwrite=overwrite)
    return list(figs)


def dataset_report(root, out, overwrite, limit):
    """Methods compared on a real dataset (no truth): table and pivot scatter."""
    import warnings

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cassi_fit._io import atomic_write
    from cassi_fit.dataset import Dataset
    from cassi_fit.jaw_fit import jaw_from_track

    data = Dataset(root)
    rows, fig = [], plt.figure(figsize=(6, 5))
    ax = fig.gca()
    pairs = [(s, t) for s in data.subjects() for t in data.tasks(s)][:limit]
    for subject, task in pairs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            track = data.load(subject, task).track
        fits = {m: jaw_from_track(track, method=m) for m in METHODS}
        for m, fit in fits.items():
            use = fit.status <= 1
            diff = np.rad2deg(fit.theta[use] - fits["frame-fit"].theta[use])
            rows.append({"subject": subject, "task": task, "method": m,
                         "median_residual_mm": float(np.median(fit.residual[use])),
                         "rms_theta_diff_to_frame_fit_deg": float(np.sqrt(np.mean(diff**2))),
                         "pivot_median_a_mm": float(np.median(fit.pivot[use, 0])),
                         "pivot_median_b_mm": float(np.median(fit.pivot[use, 1]))})
            if m in ("closed-form", "fixed-pivot"):
                ax.plot(fit.pivot[use, 0], fit.pivot[use, 1], "." if m == "closed-form" else "o",
                        ms=2 if m == "closed-form" else 6, alpha=0.4 if m == "closed-form" else 1,
                        label=f"{subject} {task} {m}")
    ax.set(xlim=(-200, 50), ylim=(-150, 100), xlabel="pivot a (mm)", ylabel="pivot b (mm)",
           title="Per-frame closed-form pivots vs the fixed-pivot fit")
    ax.legend(fontsize=6)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write(out / "dataset_pivots.png", buf.getvalue(), overwrite=overwrite)
    if rows:
        atomic_write(out / "dataset_methods.csv", _csv(rows), overwrite=overwrite)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="folder for the table and figures")
    parser.add_argument("--small", action="store_true", help="one subject, one task (fast)")
    parser.add_argument("--dataset", help="also compare the methods on this dataset folder")
    parser.add_argument("--limit", type=int, default=6, help="dataset recordings to use")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)
    from pathlib import Path

    outputs = ["jaw_comparison.csv", "pivot_error_vs_theta.png", "point_error_vs_noise.png"]
    if args.dataset:
        outputs += ["dataset_methods.csv", "dataset_pivots.png"]
    existing = [Path(args.out) / n for n in outputs if (Path(args.out) / n).exists()]
    if existing and not args.force:  # refuse before any work, as the toolkit's writers do
        print(f"jaw_comparison: {existing[0]} exists (pass --force to replace it)",
              file=sys.stderr)
        return 1

    import jax

    # Errors of a few hundredths of a mm are compared here: float32 would blur them.
    jax.config.update("jax_enable_x64", True)
    from cassi_fit._io import atomic_write

    out = Path(args.out)
    rows = synthetic_table(args.small)
    atomic_write(out / "jaw_comparison.csv", _csv(rows), overwrite=args.force)
    _figures(rows, out, overwrite=args.force)
    threshold = trust_threshold(rows)
    print(f"closed-form pivot trustworthy (median error < {TRUST_PIVOT_MM} mm at 0.3 mm noise) "
          f"from |theta| >= {threshold} deg" if threshold is not None else
          "closed-form pivot never trustworthy at 0.3 mm noise in this run")
    for r in rows:
        if r["noise_mm"] == 0.3:
            print(f"{r['method']:13s} |theta| {r['theta_lo_deg']:4g}-{r['theta_hi_deg']:<4g} deg "
                  f"pivot {r['median_pivot_err_mm']:9.2f} mm  chin {r['median_chin_err_mm']:.3f}"
                  f" mm  angle {r['median_angle_err_deg']:.3f} deg")
    if args.dataset:
        dataset_report(args.dataset, out, args.force, args.limit)
    return 0


if __name__ == "__main__":
    sys.exit(main())
