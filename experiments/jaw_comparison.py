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

# name: (synth noise family, SD per coordinate in mm, unmarked jaw-pellet mistracks)
# ("xrmb": band-limited noise and the molar pellet's out-of-plane yaw at noise scale 1,
# docs/SYNTHETIC.md; its SD argument is the default noise, which it rescales itself)
NOISE_FAMILIES = {
    "none": ("white", 0.0, False),
    "white-0.25": ("white", 0.25, False),
    "drift-0.25": ("drift", 0.25, False),
    "xrmb": ("xrmb", 0.3 / np.sqrt(2.0), False),
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
N_SUBJECTS = 6  # per cell, each with its own geometry; x 2 tasks = 12 recordings per cell
BASE_SEED = 2026
TASKS = ("tp106", "tp040")  # jaw wagging (wide angles), a sentence (speech angles)
DURATION_S = 4.0
SMALL = {"subjects": 1, "tasks": ("tp106",), "duration_s": 3.0}
BOOTSTRAP, BOOTSTRAP_SEED = 400, 12345
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


def frame_errors(track, truth, anatomy, method):  # method: an alias or a method object
    """Per-frame errors of one method on one recording: dict of (n,) arrays, NaN in the
    frames the method did not use (so methods are compared on the same frames)."""
    from cassi_fit.jaw_fit import fit_jaw

    jaw = track.positions[:, 6:8, :]
    valid = track.valid[:, 6:8].all(axis=(1, 2))
    f0 = int(np.argmax(valid))
    options = {"solver": "optimistix-lm"} if isinstance(method, str) else {}
    fit = fit_jaw(jaw[f0], np.where(valid[:, None, None], jaw, 0.0), method=method,
                  valid=valid, **options)
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
    return {k: v if k == "theta_deg" else np.where(use, v, np.nan) for k, v in out.items()}


def recording_seed(*names: str) -> tuple[int, int]:
    """A seed of its own for every recording, from its full names (e.g. family, subject,
    task): no two recordings share their noise or their task's random draws."""
    import zlib

    return BASE_SEED, zlib.crc32("|".join(names).encode())


def _recordings(small: bool, *, prefix: str = "X", tasks=None, noises=None, families=None):
    """Yield ``(family, noise name, recording id, track, truth, anatomy)`` for every
    recording. A subject's geometry is the same in every family (paired families); its
    motion and noise are drawn from the recording's own seed, shared by the noise levels
    of one recording (paired noise levels). ``prefix`` names the subjects (``X01`` ... for
    the comparison, ``H01`` ... for the held-out tuning set: other seeds, other people)."""
    from cassi_fit import synth

    n_subjects = SMALL["subjects"] if small else N_SUBJECTS
    tasks = tasks or (SMALL["tasks"] if small else TASKS)
    duration = SMALL["duration_s"] if small else DURATION_S
    for family in families or synth.JAW_KINEMATICS:
        for s in range(n_subjects):
            subject = f"{prefix}{s + 1:02d}"
            rng = np.random.default_rng(recording_seed(subject))
            anatomy = synth.make_subject(subject, rng, jaw_kinematics=family)
            for task in tasks:
                seed = recording_seed(family, subject, task)
                for noise, (kind, sd, mistracks) in NOISE_FAMILIES.items():
                    if noises is not None and noise not in noises:
                        continue
                    track, truth = synth.synth_recording(
                        anatomy, task, seed=seed, noise_mm=sd, duration_s=duration,
                        dropouts=False, mistracks=False, noise_family=kind)
                    if mistracks:
                        rng_m = np.random.default_rng((*seed, 8))
                        track = _with_mistracks(track, truth, rng_m)
                    yield family, noise, f"{subject}/{task}", track, truth, anatomy


# ------------------------------------------------------------------------------ tables
SMOOTHNESS_GRID = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0)
KNOT_SPACING_GRID = (4, 8, 16, 32)  # frames
TUNING_NOISES = ("white-0.25", "xrmb")


def tune_smooth_pivot(small: bool):
    """Choose smooth-pivot's ``smoothness`` and ``knot_spacing`` on held-out recordings.

    The held-out set: subjects ``H01`` ... (``N_SUBJECTS`` of them, not in the comparison),
    every truth family, both tasks, noises ``TUNING_NOISES``. Each pair of the grid
    ``SMOOTHNESS_GRID`` x ``KNOT_SPACING_GRID`` is scored by the median chin point error
    over all their frames; the lowest wins. Returns ``(rows, (smoothness, knot_spacing))``.
    With ``small`` nothing is tuned: the library's defaults, and no rows.
    """
    from cassi_fit.jaw_fit import DEFAULT_KNOT_SPACING, jaw_method

    if small:
        return [], (1.0, DEFAULT_KNOT_SPACING)
    recordings = list(_recordings(False, prefix="H", noises=TUNING_NOISES))
    rows = []
    for spacing in KNOT_SPACING_GRID:
        for smoothness in SMOOTHNESS_GRID:
            method = jaw_method("smooth-pivot", solver="optimistix-lm",
                                smoothness=smoothness, knot_spacing=spacing)
            chin, pivot = [], []
            for *_, track, truth, anatomy in recordings:
                errs = frame_errors(track, truth, anatomy, method)
                chin.append(errs["chin_err_mm"])
                pivot.append(errs["pivot_err_mm"])
            chin, pivot = np.concatenate(chin), np.concatenate(pivot)
            rows.append({"smoothness": smoothness, "knot_spacing": spacing,
                         "recordings": len(recordings),
                         "median_chin_err_mm": float(np.nanmedian(chin)),
                         "median_pivot_err_mm": float(np.nanmedian(pivot))})
    best = min(rows, key=lambda r: r["median_chin_err_mm"])
    return rows, (best["smoothness"], best["knot_spacing"])


def tuned_methods(choice):
    """name -> method object: smooth-pivot with the tuned ``(smoothness, knot_spacing)``."""
    from cassi_fit.jaw_fit import jaw_method

    smoothness, spacing = choice
    methods = default_methods()
    methods["smooth-pivot"] = jaw_method("smooth-pivot", solver="optimistix-lm",
                                         smoothness=smoothness, knot_spacing=spacing)
    return methods


def default_methods():
    """name -> method object, every alias with the library's defaults."""
    from cassi_fit.jaw_fit import jaw_method

    return {m: jaw_method(m, solver="optimistix-lm") for m in _methods()}


def _regimes(small: bool, methods=None):
    """``{(family, noise, bin lo): {method: [per-recording dict of (n_bin,) arrays]}}``,
    every method's arrays on the same frames of the same recordings."""
    methods = methods or default_methods()
    regimes: dict = {}
    for family, noise, _rec, track, truth, anatomy in _recordings(small):
        errs = {m: frame_errors(track, truth, anatomy, obj) for m, obj in methods.items()}
        theta = errs["closed-form"]["theta_deg"]  # the truth's, the same for every method
        for lo, hi in zip(THETA_BINS_DEG[:-1], THETA_BINS_DEG[1:], strict=True):
            sel = (theta >= lo) & (theta < hi)
            if not sel.any():
                continue
            cell = regimes.setdefault((family, noise, lo), {})
            for m, e in errs.items():
                cell.setdefault(m, []).append({k: v[sel] for k, v in e.items()})
    return regimes


def _stack(recs, metric, mask=None):
    """``(values, recording index)`` of ``metric`` pooled over the recordings ``recs``
    (finite values, and where ``mask`` (a list like ``recs``) is True)."""
    values, owner = [], []
    for i, r in enumerate(recs):
        keep = np.isfinite(r[metric]) if mask is None else mask[i]
        values.append(r[metric][keep])
        owner.append(np.full(int(keep.sum()), i))
    return np.concatenate(values), np.concatenate(owner)


def weighted_percentile(values, owner, counts, q):
    """The ``q``-th percentile (inverted CDF, as numpy's ``method="inverted_cdf"``) of the
    pooled ``values`` with each value weighted by ``counts[:, owner]``: one statistic per
    row of ``counts`` ``(B, n_recordings)`` (a bootstrap resample of the recordings is a
    count per recording). ``(B,)``; NaN where a resample holds no value."""
    order = np.argsort(values, kind="stable")
    v, w = values[order], counts[:, owner[order]].astype(float)  # (N,), (B, N)
    cum = np.cumsum(w, axis=1)
    total = cum[:, -1:] if cum.shape[1] else np.zeros((counts.shape[0], 1))
    target = q / 100.0 * total
    index = np.minimum((cum < target).sum(axis=1), max(v.shape[0] - 1, 0))
    out = v[index] if v.size else np.full(counts.shape[0], np.nan)
    return np.where(total[:, 0] > 0, out, np.nan)


def _resamples(n, rng):
    """``(BOOTSTRAP, n)`` counts: how often each of ``n`` recordings is drawn."""
    draws = rng.integers(0, n, size=(BOOTSTRAP, n))
    return np.stack([np.bincount(d, minlength=n) for d in draws])


def _interval(stats):
    stats = stats[np.isfinite(stats)]
    if not stats.size:
        return float("nan"), float("nan")
    lo, hi = np.percentile(stats, [2.5, 97.5])
    return float(lo), float(hi)


def synthetic_table(small: bool, methods=None):
    """``(rows, verdicts)``. Rows (dicts), one per method x family x noise x |theta| bin,
    with each of ``STATISTICS`` (key), its 95 % interval (key + ``_lo``, ``_hi``: a
    bootstrap over recordings, the independent units; frames of one recording share its
    noise and motion) and the recordings behind it. Verdicts:
    ``{(family, noise, bin lo, key): (text, clear winner or None)}`` (:func:`verdict`).
    ``methods``: name -> method object (default: the aliases with library defaults)."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    rows, verdicts = [], {}
    for (family, noise, lo), by_method in _regimes(small, methods).items():
        hi = THETA_BINS_DEG[THETA_BINS_DEG.index(lo) + 1]
        n = len(next(iter(by_method.values())))
        counts = _resamples(n, rng)
        for method, recs in by_method.items():
            row = {"method": method, "family": family, "noise": noise, "theta_lo_deg": lo,
                   "theta_hi_deg": hi, "recordings": n,
                   "frames": int(sum(np.isfinite(r["chin_err_mm"]).sum() for r in recs))}
            for key, (metric, q, _) in STATISTICS.items():
                values, owner = _stack(recs, metric)
                row[key] = (float(np.percentile(values, q, method="inverted_cdf"))
                            if values.size else float("nan"))
                row[f"{key}_lo"], row[f"{key}_hi"] = _interval(
                    weighted_percentile(values, owner, counts, q))
            rows.append(row)
        for key in WINNER_STATISTICS:
            metric, q, _ = STATISTICS[key]
            verdicts[(family, noise, lo, key)] = verdict(by_method, metric, q, counts)
    return rows, verdicts


def verdict(by_method, metric, q, counts):
    """``(text, winner)`` of one regime. The method with the lowest statistic wins only if,
    paired with every other method on the same frames, the 95 % interval of the difference
    of their statistics over the bootstrap resamples ``counts`` (recordings) lies below 0;
    otherwise the cell reads ``tie: A, B ...`` (the best and every method it does not
    beat) and the winner is None."""
    stats = {}
    for m, recs in by_method.items():
        values, _ = _stack(recs, metric)
        if values.size:
            stats[m] = float(np.percentile(values, q, method="inverted_cdf"))
    if not stats:
        return "-", None
    ranked = sorted(stats, key=stats.get)
    best = ranked[0]
    tied = []
    for m in ranked[1:]:
        a, b = by_method[best], by_method[m]
        both = [np.isfinite(x[metric]) & np.isfinite(y[metric]) for x, y in zip(a, b,
                                                                               strict=True)]
        va, oa = _stack(a, metric, both)
        vb, ob = _stack(b, metric, both)
        diff = weighted_percentile(va, oa, counts, q) - weighted_percentile(vb, ob, counts, q)
        if not _interval(diff)[1] < 0:
            tied.append(m)
    if tied:
        return "tie: " + ", ".join([best, *tied]), None
    return best, best


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
