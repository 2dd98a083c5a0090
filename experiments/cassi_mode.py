"""CASSI mode against the improved mode on the synthetic corpus: the tongue's V and the
tongue through the palate, per recording (docs/CASSI_MODE.md quotes the table).

    python experiments/cassi_mode.py [--subjects 5] [--tasks tp011 tp040] [--stride 1]
        [--out docs/generated/cassi_mode.md]

Writes a synthetic corpus into a temporary folder (seed 0), evaluates every recording in
both modes (``cassi_fit.evaluate.evaluate_dataset(..., mode=...)``) and writes a Markdown
table: per recording, the sharpest sustained concave bend of the tongue's back
(``tongue_back_v_deg``; a V beyond ``TONGUE_V_DEG``) and the deepest sustained tongue
point in the palate (``tongue_palate_mm``; through beyond ``TONGUE_PALATE_MM``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")


def table(results: dict, v_limit: float, palate_limit: float) -> str:
    """The Markdown table of ``results`` (mode -> ``EvaluationResult``)."""
    improved, cassi = results["improved"].recordings, results["cassi"].recordings
    lines = ["| Recording | V (deg), improved | V (deg), CASSI | palate (mm), improved "
             "| palate (mm), CASSI |", "|---|---:|---:|---:|---:|"]
    count = {"iv": 0, "cv": 0, "ip": 0, "cp": 0}
    for a, b in zip(improved, cassi, strict=True):
        if not (a.rated and b.rated):
            lines.append(f"| {a.subject} {a.task} | {a.error or a.status.label} | {b.error or b.status.label} | | |")
            continue
        va, vb = a.measures["tongue_back_v_deg"], b.measures["tongue_back_v_deg"]
        pa, pb = a.measures["tongue_palate_mm"], b.measures["tongue_palate_mm"]
        count["iv"] += va > v_limit
        count["cv"] += vb > v_limit
        count["ip"] += pa > palate_limit
        count["cp"] += pb > palate_limit
        mark = lambda x, limit: f"**{x:.1f}**" if x > limit else f"{x:.1f}"  # noqa: E731
        lines.append(f"| {a.subject} {a.task} | {mark(va, v_limit)} | {mark(vb, v_limit)} | "
                     f"{mark(pa, palate_limit)} | {mark(pb, palate_limit)} |")
    n = sum(1 for a, b in zip(improved, cassi, strict=True) if a.rated and b.rated)
    lines.append(f"| **beyond the threshold** | {count['iv']} of {n} | {count['cv']} of {n} | "
                 f"{count['ip']} of {n} | {count['cp']} of {n} |")
    return "\n".join(lines) + "\n"


BEGIN, END = "<!-- BEGIN experiments/cassi_mode.py -->", "<!-- END experiments/cassi_mode.py -->"


def quote(doc: Path, text: str) -> None:
    """Put ``text`` between the ``BEGIN``/``END`` markers of ``doc`` (if it has them)."""
    if not doc.exists():
        return
    body = doc.read_text()
    if BEGIN in body and END in body:
        head, rest = body.split(BEGIN, 1)
        doc.write_text(head + BEGIN + "\n" + text + END + rest.split(END, 1)[1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subjects", type=int, default=5)
    parser.add_argument("--tasks", nargs="+", default=["tp011", "tp040"])
    parser.add_argument("--stride", type=int, default=1)
    parser.add_argument("--out", default="docs/generated/cassi_mode.md")
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    from cassi_fit import synth
    from cassi_fit.evaluate import TONGUE_PALATE_MM, TONGUE_V_DEG, evaluate_dataset

    with tempfile.TemporaryDirectory() as tmp:
        root = synth.generate_corpus(Path(tmp) / "corpus", n_subjects=args.subjects, seed=0,
                                     tasks=tuple(args.tasks))
        results = {m: evaluate_dataset(root, mode=m, progress=False, stride=args.stride)
                   for m in ("improved", "cassi")}
    text = (f"<!-- written by experiments/cassi_mode.py --subjects {args.subjects} --tasks "
            f"{' '.join(args.tasks)} --stride {args.stride}; do not edit -->\n"
            f"Synthetic corpus (seed 0), {args.subjects} subjects, tasks "
            f"{', '.join(args.tasks)}, stride {args.stride}. V: `tongue_back_v_deg`, bold "
            f"beyond {TONGUE_V_DEG:g} deg; palate: `tongue_palate_mm`, bold beyond "
            f"{TONGUE_PALATE_MM:g} mm (both sustained 50 ms).\n\n"
            + table(results, TONGUE_V_DEG, TONGUE_PALATE_MM))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    quote(Path(__file__).resolve().parents[1] / "docs" / "CASSI_MODE.md", text)
    print(text, end="")
    print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
