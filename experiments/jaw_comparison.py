"""Closed form or fit? Jaw-rotation methods compared per regime on synthetic truth.

    python experiments/jaw_comparison.py --out DIR [--docs DIR] [--small] [--force]
                                         [--dataset DIR] [--limit N]

Synthetic part (cassi_fit.synth; the true jaw motion is known). Every jaw method
(cassi_fit.options.JAW_METHODS, called through ``cassi_fit.jaw_fit.fit_jaw``) on every
truth family (``synth.JAW_KINEMATICS``: fixed condyle, physiological eminence glide, thrust)
x noise family (``NOISE_FAMILIES`` below) x |theta| bin (degrees from the reference frame).
The same subjects (geometry drawn once, ``SUBJECT_SEEDS``) and tasks are used for every
family and noise, so the cells are paired. Per frame: angle error, pivot error (against the
true motion's fixed point, Eqs 6-7), and the errors of two points on the jaw moved by the
estimated motion (lower incisor tip, chin = gnathion). Per cell: the median and a 95 %
moving-block bootstrap interval of the median (``BOOTSTRAP`` resamples of blocks of
``BLOCK_FRAMES`` consecutive frames, seeded, since neighbouring frames are correlated).

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

# name: (synth noise family, SD per coordinate in mm, unmarked jaw-pellet mistracks)
NOISE_FAMILIES = {
    "none": ("white", 0.0, False),
    "white-0.1": ("white", 0.1, False),
    "white-0.25": ("white", 0.25, False),
    "white-0.5": ("white", 0.5, False),
    "drift-0.25": ("drift", 0.25, False),
    "mistracks": ("white", 0.25, True),
}
THETA_BINS_DEG = (0.0, 1.0, 2.0, 4.0, 8.0, 16.0, 90.0)
# Per-frame errors measured (column of frame_errors) ...
METRICS = ("pivot_err_mm", "angle_err_deg", "chin_err_mm", "incisor_err_mm")
# ... and the statistics reported per cell: key -> (per-frame error, percentile, title).
# The 95th percentile shows what a median hides: rare mistracks, occasional failures.
STATISTICS = {
    "median_pivot_err_mm": ("pivot_err_mm", 50, "pivot error (mm), median"),
    "median_angle_err_deg": ("angle_err_deg", 50, "angle error (deg), median"),
    "median_chin_err_mm": ("chin_err_mm", 50, "chin point error (mm), median"),
    "median_incisor_err_mm": ("incisor_err_mm", 50, "incisor tip error (mm), median"),
    "p95_chin_err_mm": ("chin_err_mm", 95, "chin point error (mm), 95th percentile"),
}
WINNER_STATISTICS = ("median_chin_err_mm", "median_pivot_err_mm", "median_angle_err_deg",
                     "p95_chin_err_mm")
SUBJECT_SEEDS = (300, 301, 302, 303)
TASKS = ("tp106", "tp040")  # jaw wagging (wide angles), a sentence (speech angles)
DURATION_S = 6.0
SMALL = {"subjects": 1, "tasks": ("tp106",), "duration_s": 3.0}
BOOTSTRAP, BLOCK_FRAMES, BOOTSTRAP_SEED = 300, 25, 12345
TRUST_PIVOT_MM = 5.0  # a pivot is "trustworthy" when its median error is below this
MISTRACK_MM = (4.0, 10.0)  # jump size of an injected jaw-pellet mistrack


def _methods():
    from cassi_fit.options import JAW_METHODS

    return JAW_METHODS


# ------------------------------------------------------------------------ one recording
def _rotate(theta, points):
    """``R(theta) p`` (paper Eqs 4-5) for theta (n,) and points (n, 2) or (2,): (n, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    points = np.broadcast_to(points, (theta.shape[0], 2))
    return np.stack([c * points[:, 0] + s * points[:, 1], -s * points[:, 0] + c * points[:, 1]], -1)


def true_motion(truth, f0):
    """Per frame, the true motion from frame ``f0``: ``(theta (n,), t (n, 2), pivot (n, 2),
    defined (n,))``; ``current o reference^-1`` of the truth's poses from rest."""
    theta = truth.theta - truth.theta[f0]
    t = truth.translation - _rotate(theta, truth.translation[f0])
    one_minus_c, s = 1.0 - np.cos(theta), np.sin(theta)
    det = one_minus_c**2 + s**2  # det(I - R), 0 where there is no fixed point
    defined = det > 1e-18
    safe = np.where(defined, det, 1.0)
    pivot = np.stack([one_minus_c * t[:, 0] + s * t[:, 1], -s * t[:, 0] + one_minus_c * t[:, 1]],
                     -1) / safe[:, None]  # fmt: skip
    return theta, t, np.where(defined[:, None], pivot, np.nan), defined


def _with_mistracks(track, truth, rng):
    """The track with 1-3 unmarked mistracks on the jaw pellets (a jump of 4-10 mm of MNI
    or MNM for 1-5 frames), as ``rare mistracks``; the fits are not told."""
    from cassi_fit.txy import PelletTrack

    positions = track.positions.copy()
    tracked = np.flatnonzero(track.valid[:, 6:8].all(axis=(1, 2)))
    for _ in range(int(rng.integers(1, 4))):
        start = int(rng.choice(tracked[1:]))  # never the reference frame
        length = int(rng.integers(1, 6))
        angle = rng.uniform(0.0, 2 * np.pi)
        jump = rng.uniform(*MISTRACK_MM) * np.array([np.cos(angle), np.sin(angle)])
        positions[start : start + length, int(rng.integers(6, 8))] += jump
    return PelletTrack(times=track.times, positions=positions, valid=track.valid)


def frame_errors(track, truth, anatomy, method):
    """Per-frame errors of one method on one recording: dict of (n_used,) arrays."""
    from cassi_fit.jaw_fit import fit_jaw

    jaw = track.positions[:, 6:8, :]
    valid = track.valid[:, 6:8].all(axis=(1, 2))
    f0 = int(np.argmax(valid))
    fit = fit_jaw(jaw[f0], np.where(valid[:, None, None], jaw, 0.0), method=method,
                  solver="optimistix-lm", valid=valid)  # fmt: skip
    theta, t, pivot, defined = true_motion(truth, f0)
    use = valid & (fit.status <= 1) & (np.arange(len(valid)) > f0)
    out = {"theta_deg": np.rad2deg(np.abs(theta)),
           "angle_err_deg": np.rad2deg(np.abs(fit.theta - theta))}  # fmt: skip
    est_pivot = np.where(fit.pivot_defined[:, None], fit.pivot, np.nan)
    out["pivot_err_mm"] = np.linalg.norm(est_pivot - pivot, axis=1)  # NaN: undefined
    for name, rest in (("incisor", anatomy.lower_incisor_tip_rest), ("chin", anatomy.chin_rest)):
        at_f0 = _rotate(truth.theta[f0 : f0 + 1], rest)[0] + truth.translation[f0]
        err = (_rotate(fit.theta, at_f0) + fit.translation) - (_rotate(theta, at_f0) + t)
        out[f"{name}_err_mm"] = np.linalg.norm(err, axis=1)
    return {k: v[use] for k, v in out.items()}


def _recordings(small: bool):
    """Yield ``(family, noise name, track, truth, anatomy)`` for every recording."""
    from cassi_fit import synth

    n_subjects = SMALL["subjects"] if small else len(SUBJECT_SEEDS)
    tasks = SMALL["tasks"] if small else TASKS
    duration = SMALL["duration_s"] if small else DURATION_S
    for family in synth.JAW_KINEMATICS:
        for s, subject_seed in enumerate(SUBJECT_SEEDS[:n_subjects]):
            rng = np.random.default_rng(subject_seed)  # same geometry for every family
            anatomy = synth.make_subject(f"X{s + 1:02d}", rng, jaw_kinematics=family)
            for task in tasks:
                for k, (noise, (kind, sd, mistracks)) in enumerate(NOISE_FAMILIES.items()):
                    track, truth = synth.synth_recording(
                        anatomy, task, seed=(subject_seed, len(task), 7), noise_mm=sd,
                        duration_s=duration, dropouts=False, mistracks=False,
                        noise_family=kind)  # fmt: skip
                    if mistracks:
                        rng_m = np.random.default_rng((subject_seed, len(task), 8, k))
                        track = _with_mistracks(track, truth, rng_m)
                    yield family, noise, track, truth, anatomy


# ------------------------------------------------------------------------------ tables
def block_bootstrap_ci(values, rng, q=50, n_boot=BOOTSTRAP, block=BLOCK_FRAMES):
    """95 % interval of the ``q``-th percentile of ``values`` (in frame order) by a
    moving-block bootstrap: ``n_boot`` resamples made of random runs of ``block``
    consecutive values (neighbouring frames share noise drift and fit errors)."""
    n = values.shape[0]
    if n == 0:
        return float("nan"), float("nan")
    block = min(block, n)
    n_blocks = -(-n // block)
    starts = rng.integers(0, n - block + 1, size=(n_boot, n_blocks))
    index = (starts[:, :, None] + np.arange(block)).reshape(n_boot, -1)[:, :n]
    stats = np.percentile(values[index], q, axis=1)
    lo, hi = np.percentile(stats, [2.5, 97.5])
    return float(lo), float(hi)


def synthetic_table(small: bool):
    """Rows (dicts), one per method x family x noise x |theta| bin, with each of
    ``STATISTICS`` (key) and its 95 % interval (key + ``_lo``, ``_hi``)."""
    pooled = {}
    for family, noise, track, truth, anatomy in _recordings(small):
        for method in _methods():
            errs = frame_errors(track, truth, anatomy, method)
            cell = pooled.setdefault((method, family, noise), {})
            for k, v in errs.items():
                cell.setdefault(k, []).append(v)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    rows = []
    for (method, family, noise), errs in pooled.items():
        errs = {k: np.concatenate(v) for k, v in errs.items()}
        for lo, hi in zip(THETA_BINS_DEG[:-1], THETA_BINS_DEG[1:], strict=True):
            sel = (errs["theta_deg"] >= lo) & (errs["theta_deg"] < hi)
            if not sel.any():
                continue
            row = {"method": method, "family": family, "noise": noise, "theta_lo_deg": lo,
                   "theta_hi_deg": hi, "frames": int(sel.sum())}  # fmt: skip
            for key, (metric, q, _) in STATISTICS.items():
                v = errs[metric][sel]
                v = v[np.isfinite(v)]  # pivot undefined (theta = 0) in truth or estimate
                row[key] = float(np.percentile(v, q)) if v.size else float("nan")
                row[f"{key}_lo"], row[f"{key}_hi"] = block_bootstrap_ci(v, rng, q)
            rows.append(row)
    return rows


def trust_threshold(rows, method="closed-form", noise="white-0.25", family="physiological"):
    """Smallest |theta| (deg) from which every bin's median pivot error is < TRUST_PIVOT_MM."""
    bins = sorted((r for r in rows if r["method"] == method and r["noise"] == noise
                   and r.get("family", family) == family), key=lambda r: r["theta_lo_deg"])
    threshold = None
    for r in bins:
        if r["median_pivot_err_mm"] < TRUST_PIVOT_MM:
            threshold = r["theta_lo_deg"] if threshold is None else threshold
        else:
            threshold = None
    return threshold


def winner(cells, key):
    """The method with the lowest statistic ``key`` in ``cells`` (rows of one regime), and
    whether it is clear (its interval lies below every other method's) or a near tie (the
    runner-up's interval overlaps): ``(text, method)``."""
    cells = [r for r in cells if np.isfinite(r[key])]
    if not cells:
        return "-", None
    ranked = sorted(cells, key=lambda r: r[key])
    best = ranked[0]
    ties = [r["method"] for r in ranked[1:] if r[f"{key}_lo"] <= best[f"{key}_hi"]]
    text = best["method"] if not ties else f"{best['method']} ~ {ties[0]}"
    return text, best["method"]


def _bin_label(lo, hi):
    return f"{lo:g}-{hi:g}" if hi < 90 else f">={lo:g}"


def winners_markdown(rows, metric):
    """Family x noise rows, |theta| bins as columns, each cell the winning method."""
    bins = list(zip(THETA_BINS_DEG[:-1], THETA_BINS_DEG[1:], strict=True))
    lines = ["| truth | noise | " + " | ".join(f"{_bin_label(*b)} deg" for b in bins) + " |",
             "|---|---|" + "---|" * len(bins)]  # fmt: skip
    families = list(dict.fromkeys(r["family"] for r in rows))
    for family in families:
        for noise in NOISE_FAMILIES:
            cells = []
            for lo, _ in bins:
                regime = [r for r in rows if r["family"] == family and r["noise"] == noise
                          and r["theta_lo_deg"] == lo]  # fmt: skip
                cells.append(winner(regime, metric)[0])
            if any(c != "-" for c in cells):
                lines.append(f"| {family} | {noise} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def wins_count(rows, metric):
    """``{method: number of regimes it wins}`` for ``metric`` (clear or not)."""
    counts = {m: 0 for m in _methods()}
    keys = {(r["family"], r["noise"], r["theta_lo_deg"]) for r in rows}
    for key in sorted(keys):
        regime = [r for r in rows if (r["family"], r["noise"], r["theta_lo_deg"]) == key]
        best = winner(regime, metric)[1]
        if best is not None:
            counts[best] += 1
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


def markdown(rows, command: str) -> str:
    """The whole Markdown report; its first line names the command that wrote it."""
    parts = [
        f"<!-- written by `{command}`; do not edit: `make experiments` rewrites it -->",
        "# Jaw methods per regime (synthetic truth)",
        "",
        "Written by `experiments/jaw_comparison.py` (see its docstring and docs/JAW.md). "
        "Frames binned by the true |theta| from the reference frame. A cell names the "
        "method with the lowest error; `A ~ B`: B's 95 % interval overlaps A's (no clear "
        "winner). Intervals: moving-block bootstrap over frames; a fixed pivot is one value "
        "per recording, so its intervals are coarse. Truth and noise families: "
        "docs/SYNTHETIC.md.",
        "",
    ]
    for key in WINNER_STATISTICS:
        counts = ", ".join(f"{m} {c}" for m, c in wins_count(rows, key).items())
        parts += [f"## Winner by {STATISTICS[key][2]}", "", f"Regimes won: {counts}.", "",
                  winners_markdown(rows, key), ""]  # fmt: skip
    for key, (_, _, title) in STATISTICS.items():
        parts += [f"## {title} [95 % interval]", "", full_markdown(rows, key), ""]
    return "\n".join(parts)


def section(text: str, title: str) -> str:
    """The body of section ``## title`` of a Markdown text, without its heading (to quote it
    elsewhere under a heading of the quoting document's own level)."""
    start = text.index(f"## {title}\n") + len(f"## {title}\n")
    end = text.find("\n## ", start)
    return text[start : end if end >= 0 else len(text)].strip("\n") + "\n"


def _csv(rows) -> str:
    keys = list(rows[0])
    buf = io.StringIO()
    buf.write(",".join(keys) + "\n")
    for r in rows:
        buf.write(",".join(f"{r[k]:.6g}" if isinstance(r[k], float) else str(r[k])
                           for k in keys) + "\n")  # fmt: skip
    return buf.getvalue()


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
            use = fit.status <= 1
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
        atomic_write(out / "dataset_methods.csv", _csv(rows), overwrite=overwrite)
    return rows


# -------------------------------------------------------------------------------- main
def _command(argv) -> str:
    """The command line as the Markdown header names it (paths as given)."""
    return " ".join(["python experiments/jaw_comparison.py", *argv])


def _summary(rows) -> None:
    threshold = trust_threshold(rows)
    print(f"closed-form pivot trustworthy (median error < {TRUST_PIVOT_MM} mm, physiological "
          f"truth, white 0.25 mm) from |theta| >= {threshold} deg" if threshold is not None
          else "closed-form pivot never trustworthy at white 0.25 mm noise in this run")
    for key in WINNER_STATISTICS:
        counts = ", ".join(f"{m} {c}" for m, c in wins_count(rows, key).items())
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

    rows = synthetic_table(args.small)
    text = markdown(rows, _command(argv))
    atomic_write(out / "jaw_comparison.csv", _csv(rows), overwrite=args.force)
    atomic_write(out / "jaw_comparison.md", text, overwrite=args.force)
    if args.docs:
        atomic_write(Path(args.docs) / "jaw_comparison.md", text, overwrite=args.force)
    _figures(rows, out, overwrite=args.force)
    _summary(rows)
    if args.dataset:
        dataset_report(args.dataset, out, args.force, args.limit)
    return 0


if __name__ == "__main__":
    sys.exit(main())
