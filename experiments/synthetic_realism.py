"""Does the synthetic corpus look like real speech? Truth-free diagnostics, side by side.

    python experiments/synthetic_realism.py [--docs DIR] [--out DIR] [--subjects N] [--force]

Computes, on the real XRMB recording JW11 task 5 (``../shared/data/xrmb_jw11``; one
recording of one speaker, repeated /sa/) and on synthetic recordings of the same length of
the synthetic task tp005 (slow /sa/ repetition) for every jaw-kinematics family x noise
family ("realistic", the default corpus's, and "xrmb"), the diagnostics that tell jaw
motions apart without a truth (:func:`diagnostics`):

- each jaw method's median residual (closed form, frame fit, fixed pivot, smooth pivot),
  the share of closed-form and smooth-pivot pivots in the plausible region, the fixed
  pivot's location and the closed-form pivots' spread (IQR);
- translation versus rotation: MNI's displacement regressed on the per-frame angle (mm per
  degree, x and y) and the SD of what the angle does not explain (x);
- the MNI-MNM distance (constant for a rigid jaw in its plane): SD, slope against the
  angle, high-pass SD (what a Gaussian of 10 ms does not keep) and autocorrelation at one
  frame and at 50 ms: the noise spectrum;
- movement: the angle's 1st-99th percentile range, MNI's vertical range (5th-95th), the
  99th percentile speed of MNI, LL and T1, and the tongue pellets' median spacing.

Writes ``synthetic_realism.md`` (a table of measure x source: the real value, and per
synthetic cell the median and the range over subjects; a column says whether the real
value falls inside each cell's range) to --docs (``docs/generated``) and the per-recording
rows as ``synthetic_realism.csv`` to --out. Every fit uses the same 730 frames as the real
file, so each method compiles once. Without the real recording the real column is empty
and the script says so.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from shared_data import JW11_TASK5, XRMB_JW11, real_file

from cassi_fit.txy import FRAME_STEP_US

TASK = "tp005"
N_FRAMES = 730  # as the real file
SEED = 20
METHODS = ("closed-form", "frame-fit", "fixed-pivot", "smooth-pivot")
NOISES = ("realistic", "xrmb")
DT = FRAME_STEP_US * 1e-6  # XRMB's frame step, as the real file


def real_path() -> Path | None:
    """The real JW11 task 5 (``shared_data``), or None when it is not on this machine."""
    return real_file(XRMB_JW11, JW11_TASK5)


def _speed_p99(xy: np.ndarray) -> float:
    """99th percentile speed (mm/s) of ``(n, 2)`` positions, lightly smoothed (2 frames)."""
    from scipy.ndimage import gaussian_filter1d

    smooth = gaussian_filter1d(xy, 2.0, axis=0)
    return float(np.percentile(np.linalg.norm(np.diff(smooth, axis=0), axis=1) / DT, 99))


def diagnostics(track) -> dict[str, float]:
    """The truth-free diagnostics of one pellet track (see the module docstring)."""
    from scipy.ndimage import gaussian_filter1d

    from cassi_fit.jaw_fit import jaw_diagnostics, jaw_from_track
    from cassi_fit.status import fitted

    pos = track.positions
    out: dict[str, float] = {}
    fits = {}
    for method in METHODS:
        fit = jaw_from_track(track, method=method)
        diag = jaw_diagnostics(fit, pos[:, 6:8])
        key = method.replace("-", "_")
        out[f"{key}_residual_mm"] = diag.residual_median_mm
        fits[method] = fit
        if method in ("closed-form", "smooth-pivot"):
            out[f"{key}_plausible"] = diag.pivot_plausible_fraction
        if method == "closed-form":
            out["closed_form_pivot_iqr_x_mm"] = diag.pivot_iqr_x_mm
            out["closed_form_pivot_iqr_y_mm"] = diag.pivot_iqr_y_mm
        if method == "fixed-pivot":
            used = fitted(fit.status)
            out["fixed_pivot_x_mm"], out["fixed_pivot_y_mm"] = np.median(fit.pivot[used], axis=0)
    fit = fits["frame-fit"]
    used = np.asarray(fit.status) <= 1
    theta = np.rad2deg(fit.theta[used])
    mni = pos[used, 6] - pos[fit.reference_frame, 6]
    design = np.stack([theta, np.ones_like(theta)], axis=1)
    coef, *_ = np.linalg.lstsq(design, mni, rcond=None)
    out["mni_x_mm_per_deg"], out["mni_y_mm_per_deg"] = coef[0]
    out["mni_x_unexplained_sd_mm"] = float(np.std(mni[:, 0] - design @ coef[:, 0]))
    distance = np.linalg.norm(pos[used, 6] - pos[used, 7], axis=1)
    dev = distance - distance.mean()
    out["distance_sd_mm"] = float(np.std(dev))
    out["distance_mm_per_deg"] = float(np.polyfit(theta, distance, 1)[0])
    out["distance_highpass_sd_mm"] = float(np.std(dev - gaussian_filter1d(dev, 0.010 / DT)))
    lag = round(0.05 / DT)
    out["distance_autocorr_1"] = float(np.corrcoef(dev[:-1], dev[1:])[0, 1])
    out["distance_autocorr_50ms"] = float(np.corrcoef(dev[:-lag], dev[lag:])[0, 1])
    out["theta_range_deg"] = float(np.subtract(*np.percentile(theta, [99, 1])))
    ok = track.valid.all(axis=2)
    both = ok[:, 6] & ok[:, 7]
    out["mni_y_range_mm"] = float(np.subtract(*np.percentile(pos[both, 6, 1], [95, 5])))
    for name, i in (("mni", 6), ("ll", 1), ("t1", 2)):
        out[f"{name}_speed_p99_mm_s"] = _speed_p99(pos[ok[:, i], i])
    tongue = ok[:, 2:6].all(axis=1)
    gaps = np.linalg.norm(np.diff(pos[tongue, 2:6], axis=1), axis=2)
    for k, value in enumerate(np.median(gaps, axis=0)):
        out[f"t{k + 1}_t{k + 2}_spacing_mm"] = float(value)
    return out


def synthetic_rows(n_subjects: int) -> list[dict]:
    """One row per synthetic recording: family x noise x subject, tp005, 730 frames."""
    from cassi_fit import synth

    rows = []
    for family in synth.JAW_KINEMATICS:
        for noise in NOISES:
            for i in range(n_subjects):
                name = f"S{i + 1:02d}"
                anatomy = synth.make_subject(name, np.random.default_rng([SEED, 1, i]),
                                             jaw_kinematics=family)
                track, _ = synth.synth_recording(
                    anatomy, TASK, seed=[SEED, 2, i, 5], noise_family=noise,
                    duration_s=N_FRAMES * DT, mistracks=False)
                rows.append({"source": f"{family} / {noise}", "subject": name,
                             **diagnostics(track)})
    return rows


def real_rows() -> list[dict]:
    from cassi_fit.txy import read_txy

    path = real_path()
    if path is None:
        return []
    return [{"source": "JW11 tp005 (real)", "subject": "JW11", **diagnostics(read_txy(path))}]


def summary(rows: list[dict]) -> list[dict]:
    """measure x source: the real value; per synthetic cell ``median [min, max]``; and
    which cells' ranges hold the real value."""
    measures = [k for k in rows[0] if k not in ("source", "subject")]
    real = {r["source"]: r for r in rows if r["subject"] == "JW11"}
    real_row = next(iter(real.values()), None)
    sources = list(dict.fromkeys(r["source"] for r in rows if r["subject"] != "JW11"))
    out = []
    for m in measures:
        row: dict[str, object] = {"measure": m}
        row["JW11 (real)"] = None if real_row is None else f"{real_row[m]:.3g}"
        inside = []
        for s in sources:
            values = np.array([r[m] for r in rows if r["source"] == s], float)
            row[s] = f"{np.median(values):.3g} [{values.min():.3g}, {values.max():.3g}]"
            if real_row is not None and values.min() <= real_row[m] <= values.max():
                inside.append(s)
        row["real inside"] = ", ".join(inside) if real_row is not None else "no real file"
        out.append(row)
    return out


def inside_counts(rows: list[dict]) -> dict[str, int]:
    """source -> how many measures hold the real value inside its range over subjects."""
    table = summary(rows)
    sources = [k for k in table[0] if k not in ("measure", "JW11 (real)", "real inside")]
    return {s: sum(s in str(r["real inside"]).split(", ") for r in table) for s in sources}


def markdown(rows: list[dict], n_subjects: int) -> str:
    from cassi_fit.tables import markdown_text

    table = summary(rows)
    counts = inside_counts(rows) if any(r["subject"] == "JW11" for r in rows) else {}
    n_measures = len(table)
    lines = [
        "<!-- written by `python experiments/synthetic_realism.py --docs docs/generated "
        "--force`; do not edit: `make experiments` rewrites it -->",
        "# Synthetic recordings beside a real one: truth-free diagnostics",
        "",
        f"Real: JW11 task 5 (repeated /sa/), {N_FRAMES} frames: **one recording of one "
        "speaker**. Synthetic: task tp005 (slow /sa/ repetition), the same number of "
        f"frames, {n_subjects} subjects per cell (seed {SEED}), no mistracks. A cell is "
        "`median [min, max]` over the subjects. Measures: experiments/synthetic_realism.py; "
        "what changed in the generator and why: docs/SYNTHETIC.md.",
        "",
        "Measures (of " + str(n_measures) + ") whose real value lies inside the cell's range: "
        + (", ".join(f"{s} {c}" for s, c in counts.items()) if counts else "no real file")
        + ".",
        "",
        markdown_text(table, digits=3).rstrip("\n"),
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--docs", type=Path, help="write synthetic_realism.md here")
    parser.add_argument("--out", type=Path, help="write synthetic_realism.csv here")
    parser.add_argument("--subjects", type=int, default=5, help="subjects per cell")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_platforms", "cpu")
    jax.config.update("jax_enable_x64", True)
    from cassi_fit._io import atomic_write
    from cassi_fit.tables import write_table

    rows = real_rows()
    if not rows:
        print("synthetic_realism: the real recording is absent; synthetic columns only",
              file=sys.stderr)
    rows += synthetic_rows(args.subjects)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        write_table(rows, args.out / "synthetic_realism.csv", overwrite=args.force)
    text = markdown(rows, args.subjects)
    if args.docs:
        args.docs.mkdir(parents=True, exist_ok=True)
        atomic_write(args.docs / "synthetic_realism.md", text, overwrite=args.force)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
