"""Small per-recording reports of an animation: the penetration depths as text and CSV, and
the jaw plot (closed form against the pivot fits, with the labelled segments)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import Bool, Float

from .animate import Animation

if TYPE_CHECKING:
    from .labels import Labels


def penetration_summary(animation: Animation) -> str:
    """One line per kind of penetration (``collide.REPORT_KEYS``): the 95th percentile and
    the maximum depth over the frames of ``animation`` (mm); after projection, the maximum
    left."""
    if not animation.penetration:
        return "penetration: not measured (the model has no collision chains)"
    lines = ["penetration depth, mm (95th percentile / max over frames)"
             + ("; after projection" if animation.collisions == "project" else "")]
    for key, before in animation.penetration.items():
        after = animation.penetration_after[key]
        text = f"  {key:20s} {np.percentile(before, 95):6.2f} / {before.max():6.2f}"
        if animation.collisions == "project":
            text += f"   -> {after.max():.3f}"
        lines.append(text)
    return "\n".join(lines)


def tongue_volume_summary(model: object, animation: Animation) -> str:
    """One line: the tongue's volume (mL) at rest and its least and greatest over the
    frames of ``animation``, also relative to rest (docs/TONGUE.md; CASSI's flat sheet has
    about none)."""
    from .tongue import tongue_volumes

    rest = float(tongue_volumes(model, np.asarray(model.vertices)[None])[0])
    ml = tongue_volumes(model, animation.vertices)
    text = f"tongue volume, mL: {ml.min():.2f} .. {ml.max():.2f} over the frames (rest {rest:.2f})"
    if abs(rest) > 1e-9:
        text += f"; {100 * (ml.min() / rest - 1):+.2f} % .. {100 * (ml.max() / rest - 1):+.2f} %"
    return text


def write_penetration_csv(path: str | Path, animation: Animation, *, overwrite: bool = False) -> Path:
    """A CSV, one row per frame: ``time_s``, ``line`` (1-based data line), then each depth
    (mm) before and after projection. Written atomically; an existing file only with
    ``overwrite``."""
    from .tables import write_table

    keys = list(animation.penetration)
    columns = ["time_s", "line"] + [f"{k}_mm" for k in keys] + [f"{k}_after_mm" for k in keys]
    rows = []
    for i in range(animation.n_frames):
        row = {"time_s": float(animation.times[i]), "line": int(animation.frame_index[i]) + 1}
        row.update((f"{k}_mm", float(animation.penetration[k][i])) for k in keys)
        row.update((f"{k}_after_mm", float(animation.penetration_after[k][i])) for k in keys)
        rows.append(row)
    digits = {c: 4 for c in columns if c.endswith("_mm")}
    return write_table(rows, Path(path), columns=columns, digits=digits,
                       overwrite=overwrite)[0]


def jaw_comparison_plot(
    path: str | Path,
    reference_jaw: Float[np.ndarray, "2 2"],
    current_jaw: Float[np.ndarray, "n 2 2"],
    times: Float[np.ndarray, " n"],
    *,
    labels: Labels | None = None,
    valid: Bool[np.ndarray, " n"] | None = None,
    title: str = "",
) -> Path:
    """A PNG of the jaw per frame: the paper's closed form (Eqs 1-7) against the fixed-
    and smooth-pivot least-squares fits: rotation theta (deg), pivot x and y (mm).

    reference_jaw (2, 2) mm: MNI, MNM on the reference frame; current_jaw (n, 2, 2) mm:
    MNI, MNM per frame; times (n,) s; ``valid`` (n,): frames whose jaw pellets are
    tracked (default: all; the others are left out of the fits and the plot). ``labels`` (``labels.Labels``): each labelled
    segment is shaded on every panel and named above the top one. Written atomically,
    replacing ``path``."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ._io import atomic_write
    from .jaw_fit import fit_jaw

    t = np.asarray(times, np.float64)
    reference_jaw, current_jaw = np.asarray(reference_jaw), np.asarray(current_jaw)
    if valid is not None:  # untracked frames: finite stand-ins, excluded by ``valid``
        valid = np.asarray(valid, bool)
        current_jaw = np.where(valid[:, None, None], current_jaw, reference_jaw)
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    for method, style in (
        ("closed-form", dict(lw=0.8, color="0.45")),
        ("fixed-pivot", dict(lw=1.6, color="tab:blue")),
        ("smooth-pivot", dict(lw=1.6, color="tab:orange", ls="--")),
    ):
        fit = fit_jaw(reference_jaw, current_jaw, method=method, valid=valid)
        shown = fit.pivot_defined if valid is None else fit.pivot_defined & valid
        pivot = np.where(shown[:, None], fit.pivot, np.nan)
        theta = np.where(True if valid is None else valid, np.degrees(fit.theta), np.nan)
        axes[0].plot(t, theta, label=method, **style)
        axes[1].plot(t, pivot[:, 0], **style)
        axes[2].plot(t, pivot[:, 1], **style)
    for ax, name in zip(axes, ("jaw rotation theta (deg)", "pivot x (mm)",
                               "pivot y (mm)"), strict=True):
        ax.set_ylabel(name)
    axes[2].set_xlabel("time (s)")
    for ax in axes[1:]:  # the closed-form pivot runs off at small angles (Eqs 6-7)
        ax.set_ylim(-160, 80)
    if labels is not None:
        _shade_labels(axes, labels, t)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(title or "jaw: closed form (Eqs 1-7) vs least-squares pivot fits",
                      pad=16 if labels is not None else 6)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return atomic_write(Path(path), buffer.getvalue(), overwrite=True)


def _shade_labels(axes, labels: Labels, t: np.ndarray) -> None:
    """Alternate light bands over the labelled segments inside the plotted time span,
    with the label above the top panel."""
    top = axes[0]
    for k, (start, end, name) in enumerate(labels.segments()):
        if end <= t[0] or start >= t[-1]:
            continue
        for ax in axes:
            ax.axvspan(start, end, color="0.85" if k % 2 else "0.92", lw=0, zorder=0)
        top.text((max(start, t[0]) + min(end, t[-1])) / 2, 1.01, name, ha="center",
                 va="bottom", fontsize=7, transform=top.get_xaxis_transform(), clip_on=False)
