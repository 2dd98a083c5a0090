"""Small per-recording reports of an animation: the penetration depths as text and CSV."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .animate import Animation


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


def write_penetration_csv(path: str | Path, animation: Animation, *, overwrite: bool = False) -> Path:
    """A CSV, one row per frame: ``time_s``, ``line`` (1-based data line), then each depth
    (mm) before and after projection. Written atomically; an existing file only with
    ``overwrite``."""
    from ._io import atomic_write

    keys = list(animation.penetration)
    header = ["time_s", "line"] + [f"{k}_mm" for k in keys] + [f"{k}_after_mm" for k in keys]
    rows = [",".join(header)]
    for i in range(animation.n_frames):
        values = [f"{animation.times[i]:.6f}", str(int(animation.frame_index[i]) + 1)]
        values += [f"{animation.penetration[k][i]:.4f}" for k in keys]
        values += [f"{animation.penetration_after[k][i]:.4f}" for k in keys]
        rows.append(",".join(values))
    return atomic_write(Path(path), "\n".join(rows) + "\n", overwrite=overwrite)
