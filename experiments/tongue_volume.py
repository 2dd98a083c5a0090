"""The tongue's volume over every synthetic task (docs/TONGUE.md quotes the table).

    python experiments/tongue_volume.py [--subjects 2] [--stride 1]
        [--out docs/generated/tongue_volume.md]

Animates every task of the first synthetic subjects (seed 0, in memory) through the real
pipeline (``pipeline.run_recording``) three ways: the improved mode (tongue back
following T4, no collisions), CASSI's fixed anchors on the thick tongue, and the improved
mode with the collision projection; per recording the least and greatest tongue volume
over the frames (mL, ``tongue.tongue_volumes``) and the largest departure from the model's
rest volume (%).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
ROOT = Path(__file__).resolve().parents[1]
RUNS = {"improved": {}, "fixed anchors": {"tongue_anchor": "fixed"},
        "collisions projected": {"collisions": "project"}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subjects", type=int, default=2)
    ap.add_argument("--stride", type=int, default=1)
    ap.add_argument("--out", default=str(ROOT / "docs/generated/tongue_volume.md"))
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from cassi_fit import synth
    from cassi_fit.dataset import Recording
    from cassi_fit.pipeline import run_recording
    from cassi_fit.synth import TASKS
    from cassi_fit.tongue import tongue_volumes

    rest = None
    lines = ["| Recording | " + " | ".join(f"{r}: min-max (mL)" for r in RUNS)
             + " | largest departure from rest (%) |", "|---|" + "---:|" * (len(RUNS) + 1)]
    worst_all = 0.0
    for index, name in enumerate(synth.subject_names(args.subjects)):
        anatomy = synth.make_subject(name, np.random.default_rng([0, 1, index]))
        for task in TASKS:
            track, _ = synth.synth_recording(anatomy, task, seed=synth._recording_seed(0, index, task))
            recording = Recording(subject=name, task=task, track=track, palate=anatomy.palate,
                                  pharynx=anatomy.pharynx, head=anatomy.head,
                                  head_is_default=False, audio=None,
                                  path=Path(f"/synthetic/{name}/{task}.txy"))
            cells, worst = [], 0.0
            for options in RUNS.values():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    _, _, state, animation, _ = run_recording(recording, stride=args.stride,
                                                           **options)
                ml = tongue_volumes(state.model, animation.vertices)
                if rest is None:
                    rest = float(tongue_volumes(state.model, np.asarray(state.model.vertices)[None])[0])
                cells.append(f"{ml.min():.2f}-{ml.max():.2f}")
                worst = max(worst, float(np.abs(ml / rest - 1).max()) * 100)
            worst_all = max(worst_all, worst)
            lines.append(f"| {name} {task} | " + " | ".join(cells) + f" | {worst:.2f} |")
            print(lines[-1], flush=True)
    command = "python experiments/tongue_volume.py" + "".join(
        f" --{k} {v}" for k, v in (("subjects", args.subjects), ("stride", args.stride)))
    text = (f"<!-- written by `{command}`; do not edit: `make experiments` rewrites it -->\n"
            "# Tongue volume over the synthetic tasks\n\n"
            f"Rest volume of the model's tongue: {rest:.2f} mL. Per recording (every "
            f"{args.stride}. data line), the least and greatest volume over the frames; the "
            f"largest departure from rest over the three runs is {worst_all:.2f} %.\n\n"
            + "\n".join(lines) + "\n")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
