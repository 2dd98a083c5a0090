"""Closed form or fit? Jaw-rotation methods compared per regime on synthetic truth.

    python experiments/jaw_comparison.py --out DIR [--docs DIR] [--small] [--force]
                                         [--dataset DIR] [--limit N]

Synthetic part (cassi_fit.synth; the true jaw motion is known). Every jaw method
(cassi_fit.options.JAW_METHODS, called through ``cassi_fit.jaw_fit.fit_jaw``) on every
truth family (``synth.JAW_KINEMATICS``: fixed condyle, physiological eminence glide, thrust,
speech) x noise family (``NOISE_FAMILIES`` below, "xrmb" the one like a real file) x
|theta| bin (degrees from the reference frame). Per cell ``N_SUBJECTS`` subjects x
``TASKS``; each recording has its own seed, derived from its family, subject and task
(:func:`recording_seed`); a subject's geometry is the same in every family. Per frame:
angle error, pivot error (against the true motion's fixed point, Eqs 6-7), and the errors
of two points on the jaw moved by the estimated motion (lower incisor tip, chin =
gnathion), NaN in frames a method did not use, so every comparison is on the same frames.
Per cell: the pooled median (95th percentile) and a 95 % interval from ``BOOTSTRAP``
resamples of the recordings (the independent units; frames of one recording share its
noise and motion). A regime names a winner only when the paired interval of its
difference to every other method (the same resamples, the same frames) lies below 0;
otherwise it reads ``tie:`` (:func:`verdict`). Smooth-pivot's ``smoothness`` and knot
spacing are chosen first on held-out recordings (subjects ``H01`` ..., not compared;
:func:`tune_smooth_pivot`). The run takes a few minutes on two cores (compiling each
method once: every recording has ``DURATION_S`` seconds).

Writes to --out: ``jaw_comparison.csv`` (every cell), ``jaw_comparison.md`` (the winners
per regime and the full tables), ``pivot_error_vs_theta.png``, ``point_error_vs_noise.png``.
With --docs DIR the Markdown file is also written there (``make experiments`` passes
``--docs docs/generated``; docs/JAW.md and the README quote its winner tables verbatim,
checked by tests/test_experiment_jaw.py). Its first line names the command that wrote it.
Dataset part (--dataset; real data, no truth): per recording and method the median
residual, the rms angle difference to the per-frame fit and the median pivot:
``dataset_methods.csv``, ``dataset_pivots.png``.
"""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import numpy as np
from jaw_regimes import synthetic_table, trust_threshold
from jaw_truth import (
    BOOTSTRAP,
    DURATION_S,
    N_SUBJECTS,
    NOISE_FAMILIES,
    STATISTICS,
    TASKS,
    THETA_BINS_DEG,
    TRUST_PIVOT_MM,
    TUNING_NOISES,
    WINNER_STATISTICS,
    _methods,
    tune_smooth_pivot,
    tuned_methods,
)


def _bin_label(lo, hi):
    return f"{lo:g}-{hi:g}" if hi < 90 else f">={lo:g}"


def winners_markdown(rows, verdicts, metric):
    """Family x noise rows, |theta| bins as columns, each cell the clear winner or a tie."""
    bins = list(zip(THETA_BINS_DEG[:-1], THETA_BINS_DEG[1:], strict=True))
    lines = ["| truth | noise | " + " | ".join(f"{_bin_label(*b)} deg" for b in bins) + " |",
             "|---|---|" + "---|" * len(bins)]  # fmt: skip
    for family in dict.fromkeys(r["family"] for r in rows):
        for noise in NOISE_FAMILIES:
            cells = [verdicts.get((family, noise, lo, metric), ("-", None))[0]
                     for lo, _ in bins]
            if any(c != "-" for c in cells):
                lines.append(f"| {family} | {noise} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def wins_count(verdicts, metric):
    """``{method: regimes it wins clearly, "tie": regimes with no clear winner}``."""
    counts = {m: 0 for m in _methods()} | {"tie": 0}
    for (_f, _n, _lo, key), (text, best) in sorted(verdicts.items()):
        if key == metric and text != "-":
            counts[best if best is not None else "tie"] += 1
    return counts


def _value(r, key):
    m, lo, hi = r[key], r[f"{key}_lo"], r[f"{key}_hi"]
    if not np.isfinite(m):
        return "-"
    digits = 2 if m < 10 else 1
    return f"{m:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def full_markdown(rows, metric):
    """Every method x family x noise x bin: statistic [95 % interval] ``metric``."""
    bins = list(zip(THETA_BINS_DEG[:-1], THETA_BINS_DEG[1:], strict=True))
    lines = ["| truth | noise | method | " + " | ".join(f"{_bin_label(*b)} deg" for b in bins)
             + " |", "|---|---|---|" + "---|" * len(bins)]  # fmt: skip
    for family in dict.fromkeys(r["family"] for r in rows):
        for noise in NOISE_FAMILIES:
            for method in _methods():
                by_bin = {r["theta_lo_deg"]: r for r in rows if r["family"] == family
                          and r["noise"] == noise and r["method"] == method}  # fmt: skip
                if by_bin:
                    cells = [_value(by_bin[lo], metric) if lo in by_bin else "-" for lo, _ in bins]
                    lines.append(f"| {family} | {noise} | {method} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def tuning_markdown(tuning, choice) -> str:
    """The held-out tuning table (empty text without one)."""
    if not tuning:
        return ""
    from cassi_fit.tables import markdown_text

    return markdown_text(tuning, ["smoothness", "knot_spacing", "recordings",
                                  "median_chin_err_mm", "median_pivot_err_mm"],
                         digits={"smoothness": 2, "median_chin_err_mm": 3,
                                 "median_pivot_err_mm": 2})


def markdown(rows, verdicts, command: str, tuning=(), choice=(1.0, 16)) -> str:
    """The whole Markdown report; its first line names the command that wrote it."""
    parts = [
        f"<!-- written by `{command}`; do not edit: `make experiments` rewrites it -->",
        "# Jaw methods per regime (synthetic truth)",
        "",
        "Written by `experiments/jaw_comparison.py` (see its docstring and docs/JAW.md). "
        f"Per cell (truth x noise): {N_SUBJECTS} subjects x {len(TASKS)} tasks = "
        f"{N_SUBJECTS * len(TASKS)} recordings of {DURATION_S:g} s, each with its own seed "
        "(from its family, subject and task); every method on the same frames. Frames "
        "binned by the true |theta| from the reference frame. A cell names a method only "
        "when it beats every other one: the paired 95 % interval of the difference of the "
        f"two methods' statistic ({BOOTSTRAP} bootstrap resamples of the recordings, the "
        "independent units) lies below 0; otherwise it reads `tie:` and lists the best "
        "method and every method it does not beat. Intervals in the full tables: the same "
        "bootstrap over recordings. Smooth-pivot runs with smoothness "
        f"{choice[0]:g} and a knot every {choice[1]} frames, "
        + ("chosen on held-out recordings (below)" if tuning else
           "the library's defaults (not tuned in this run)")
        + ". Truth and noise families: docs/SYNTHETIC.md.",
        "",
    ]
    parts += ["## Smooth-pivot settings chosen on held-out recordings", ""]
    if tuning:
        parts += [f"Subjects H01-H{N_SUBJECTS:02d} (not in the comparison), every truth "
                  f"family, both tasks, noise {' and '.join(TUNING_NOISES)}: "
                  f"{tuning[0]['recordings']} recordings. Median chin point error over "
                  "their frames; the lowest is used below.", "",
                  tuning_markdown(tuning, choice), ""]
    else:
        parts += ["Not tuned in this run (`--small`): the library's defaults.", ""]
    for key in WINNER_STATISTICS:
        counts = ", ".join(f"{m} {c}" for m, c in wins_count(verdicts, key).items())
        parts += [f"## Winner by {STATISTICS[key][2]}", "",
                  f"Regimes won clearly, and ties: {counts}.", "",
                  winners_markdown(rows, verdicts, key), ""]
    for key, (_, _, title) in STATISTICS.items():
        parts += [f"## {title} [95 % interval]", "", full_markdown(rows, key), ""]
    return "\n".join(parts)


def section(text: str, title: str) -> str:
    """The body of section ``## title`` of a Markdown text, without its heading (to quote it
    elsewhere under a heading of the quoting document's own level)."""
    start = text.index(f"## {title}\n") + len(f"## {title}\n")
    end = text.find("\n## ", start)
    return text[start : end if end >= 0 else len(text)].strip("\n") + "\n"


# ----------------------------------------------------------------------------- figures
def _png(fig) -> bytes:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _figures(rows, out, overwrite):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cassi_fit._io import atomic_write

    families = list(dict.fromkeys(r["family"] for r in rows))
    fig, axes = plt.subplots(1, len(families), figsize=(4.2 * len(families), 3.8), sharey=True)
    for ax, family in zip(np.atleast_1d(axes), families, strict=True):
        for method in _methods():
            sel = sorted((r for r in rows if r["method"] == method and r["family"] == family
                          and r["noise"] == "white-0.25"), key=lambda r: r["theta_lo_deg"])
            mids = [np.sqrt(max(r["theta_lo_deg"], 0.25) * min(r["theta_hi_deg"], 32.0))
                    for r in sel]  # fmt: skip
            med = np.array([r["median_pivot_err_mm"] for r in sel])
            err = np.array([[m - r["median_pivot_err_mm_lo"], r["median_pivot_err_mm_hi"] - m]
                            for m, r in zip(med, sel, strict=True)]).T.reshape(2, -1)
            err = np.clip(np.nan_to_num(err), 0.0, None)  # a block-bootstrap interval
            # of a median need not contain the sample median exactly
            ax.errorbar(mids, med, yerr=err, fmt="o-", ms=3, capsize=2, label=method)
        ax.axhline(TRUST_PIVOT_MM, color="grey", ls=":")
        ax.set(xscale="log", yscale="log", xlabel="|theta| from reference (deg)",
               title=f"{family}, white 0.25 mm")
    np.atleast_1d(axes)[0].set_ylabel("median pivot error (mm), 95 % CI")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    atomic_write(out / "pivot_error_vs_theta.png", _png(fig), overwrite=overwrite)
    fig, axes = plt.subplots(1, len(families), figsize=(4.2 * len(families), 3.8), sharey=True)
    for ax, family in zip(np.atleast_1d(axes), families, strict=True):
        for method in _methods():
            med = []
            for noise in NOISE_FAMILIES:
                sel = [r for r in rows if r["method"] == method and r["family"] == family
                       and r["noise"] == noise]  # fmt: skip
                w = [r["frames"] for r in sel]
                med.append(np.average([r["median_chin_err_mm"] for r in sel], weights=w))
            ax.plot(range(len(NOISE_FAMILIES)), med, "o-", label=method)
        ax.set_xticks(range(len(NOISE_FAMILIES)), list(NOISE_FAMILIES), rotation=35, fontsize=7)
        ax.set(yscale="log", title=family)
    np.atleast_1d(axes)[0].set_ylabel("chin point error (mm; frame-weighted median)")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    atomic_write(out / "point_error_vs_noise.png", _png(fig), overwrite=overwrite)


# ---------------------------------------------------------------------------- dataset
def dataset_report(root, out, overwrite, limit):
    """Methods compared on a real dataset (no truth): table and pivot scatter."""
    import warnings

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cassi_fit._io import atomic_write
    from cassi_fit.dataset import Dataset
    from cassi_fit.jaw_fit import jaw_from_track
    from cassi_fit.status import fitted

    data = Dataset(root)
    rows, fig = [], plt.figure(figsize=(6, 5))
    ax = fig.gca()
    pairs = [(s, t) for s in data.subjects() for t in data.tasks(s)][:limit]
    for subject, task in pairs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            track = data.load(subject, task).track
        fits = {m: jaw_from_track(track, method=m) for m in _methods()}
        for m, fit in fits.items():
            use = fitted(fit.status)
            diff = np.rad2deg(fit.theta[use] - fits["frame-fit"].theta[use])
            rows.append({"subject": subject, "task": task, "method": m,
                         "median_residual_mm": float(np.median(fit.residual[use])),
                         "rms_theta_diff_to_frame_fit_deg": float(np.sqrt(np.mean(diff**2))),
                         "pivot_median_a_mm": float(np.median(fit.pivot[use, 0])),
                         "pivot_median_b_mm": float(np.median(fit.pivot[use, 1]))})  # fmt: skip
            if m in ("closed-form", "fixed-pivot"):
                ax.plot(fit.pivot[use, 0], fit.pivot[use, 1], "." if m == "closed-form" else "o",
                        ms=2 if m == "closed-form" else 6, alpha=0.4 if m == "closed-form" else 1,
                        label=f"{subject} {task} {m}")  # fmt: skip
    ax.set(xlim=(-200, 50), ylim=(-150, 100), xlabel="pivot a (mm)", ylabel="pivot b (mm)",
           title="Per-frame closed-form pivots vs the fixed-pivot fit")
    ax.legend(fontsize=6)
    atomic_write(out / "dataset_pivots.png", _png(fig), overwrite=overwrite)
    if rows:
        from cassi_fit.tables import csv_text

        atomic_write(out / "dataset_methods.csv", csv_text(rows), overwrite=overwrite)
    return rows


# -------------------------------------------------------------------------------- main
def _command(argv) -> str:
    """The command line as the Markdown header names it (paths as given)."""
    return " ".join(["python experiments/jaw_comparison.py", *argv])


def _summary(rows, verdicts) -> None:
    threshold = trust_threshold(rows)
    print(f"closed-form pivot trustworthy (median error < {TRUST_PIVOT_MM} mm, physiological "
          f"truth, white 0.25 mm) from |theta| >= {threshold} deg" if threshold is not None
          else "closed-form pivot never trustworthy at white 0.25 mm noise in this run")
    for key in WINNER_STATISTICS:
        counts = ", ".join(f"{m} {c}" for m, c in wins_count(verdicts, key).items())
        print(f"regimes won by {STATISTICS[key][2]}: {counts}")


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="folder for the tables and figures")
    parser.add_argument("--docs", help="also write jaw_comparison.md into this folder")
    parser.add_argument("--small", action="store_true", help="one subject, one task (fast)")
    parser.add_argument("--dataset", help="also compare the methods on this dataset folder")
    parser.add_argument("--limit", type=int, default=6, help="dataset recordings to use")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)
    out = Path(args.out)
    outputs = [out / n for n in ("jaw_comparison.csv", "jaw_comparison.md",
                                 "pivot_error_vs_theta.png", "point_error_vs_noise.png")]
    if args.docs:
        outputs.append(Path(args.docs) / "jaw_comparison.md")
    if args.dataset:
        outputs += [out / "dataset_methods.csv", out / "dataset_pivots.png"]
    existing = [p for p in outputs if p.exists()]
    if existing and not args.force:  # refuse before any work, as the toolkit's writers do
        print(f"jaw_comparison: {existing[0]} exists (pass --force to replace it)",
              file=sys.stderr)
        return 1

    import jax

    # Errors of a few hundredths of a mm are compared here: float32 would blur them.
    jax.config.update("jax_enable_x64", True)
    from cassi_fit._io import atomic_write
    from cassi_fit.tables import csv_text

    tuning, choice = tune_smooth_pivot(args.small)
    rows, verdicts = synthetic_table(args.small, tuned_methods(choice))
    text = markdown(rows, verdicts, _command(argv), tuning, choice)
    atomic_write(out / "jaw_comparison.csv", csv_text(rows), overwrite=args.force)
    atomic_write(out / "jaw_comparison.md", text, overwrite=args.force)
    if args.docs:
        atomic_write(Path(args.docs) / "jaw_comparison.md", text, overwrite=args.force)
    _figures(rows, out, overwrite=args.force)
    _summary(rows, verdicts)
    if args.dataset:
        dataset_report(args.dataset, out, args.force, args.limit)
    return 0


if __name__ == "__main__":
    sys.exit(main())
