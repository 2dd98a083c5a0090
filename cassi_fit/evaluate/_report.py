"""Writing the evaluation: CSV and Markdown in Table 2's layout, comparisons, a figure."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .._io import OutputGroup, atomic_outputs
from ..errors import OutputExistsError
from ..tables import csv_text
from ._measures import MEASURES
from ._ratings import (
    CASSI_TOTALS,
    COMPONENTS,
    LIP_APART_LARGE_MM,
    LIP_APART_MM,
    LIP_TIGHT_MM,
    RATINGS,
    SLOPE_STEEP_DEG,
    SLOPE_UP_DEG,
    SLOPE_VERY_STEEP_DEG,
    TONGUE_POKE_DEEP_MM,
    TONGUE_POKE_MM,
    describe,
)
from ._rows import EvaluationResult, RecordingRow, SubjectRow

# ----------------------------------------------------------------------------- writing
_META = ("subject", "task", "status", "error", "frames", "stride", "jaw", "calibration",
         "collisions")
_SUBJECT_META = ("subject", "tasks", "recordings", "failed", "status", "error", "stride", "jaw",
                 "calibration", "collisions")



def _subjects(n: int) -> str:
    return f"{n} subject" if n == 1 else f"{n} subjects"

def _meta_value(row: RecordingRow | SubjectRow, name: str) -> object:
    return row.status.label if name == "status" else getattr(row, name)


def _csv_text(rows: Sequence[RecordingRow | SubjectRow], meta: tuple[str, ...]) -> str:
    """The rows as CSV (``tables.csv_text``; measures to 4 decimals)."""
    columns = [*meta, *MEASURES]
    for c in COMPONENTS:
        columns += [f"{c}_rating", f"{c}_problems_n", f"{c}_problems"]
    columns.append("not_counted")
    table = []
    for r in rows:
        line = {k: _meta_value(r, k) for k in meta}
        line.update((k, float(r.measures[k])) for k in MEASURES if k in r.measures)
        for c in COMPONENTS:
            found = r.problems.get(c)
            if found is not None:
                line.update({f"{c}_rating": r.ratings[c], f"{c}_problems_n": len(found),
                             f"{c}_problems": describe(found)})
        line["not_counted"] = describe(r.problems.get("not_counted", []))
        table.append(line)
    return csv_text(table, columns, digits=4)


def _cell(row: SubjectRow, component: str) -> str:
    if not row.rated:
        return "not rated"
    found = row.problems[component]
    text = row.ratings[component]
    return f"{text} ({describe(found)})" if found else text


def _totals_text(totals: tuple[int, ...]) -> str:
    return "/".join(str(n) for n in totals)


def markdown_table(result: EvaluationResult) -> str:
    """Table 2's layout: Subject | Tasks | Teeth | Lips | Tongue, each cell the rating and
    the problems counted; a totals row (EXCELLENT/VERY GOOD/GOOD/FAIR per column); then
    the problems reported but not counted, and any recording not evaluated."""
    s = result.settings
    lines = [
        "| Subject | Tasks | Teeth | Lips | Tongue |",
        "|---|---|---|---|---|",
    ]
    for row in result.subjects:
        lines.append(f"| {row.subject} | {row.tasks} | "
                     + " | ".join(_cell(row, c) for c in COMPONENTS) + " |")
    totals = result.totals()
    lines.append("| **Total** (EXCELLENT/VERY GOOD/GOOD/FAIR) | | "
                 + " | ".join(_totals_text(totals[c]) for c in COMPONENTS) + " |")
    head = (f"Calibration: {s.get('calibration', '?')}; collisions: {s.get('collisions', '?')}; "
            f"jaw: {s.get('jaw', '?')}; stride {s.get('stride', '?')}. "
            "Problems counted as in CASSI's Table 2 (thresholds: docs/EVALUATION.md); "
            "xN = a problem counted N times.")
    out = [head, "", *lines]
    noted = [f"{r.subject}: {describe(r.problems['not_counted'])}"
             for r in result.subjects if r.problems.get("not_counted")]
    if noted:
        out += ["", "Seen but not counted (as in CASSI): " + "; ".join(noted) + "."]
    if result.failed:
        out += ["", "Not evaluated: " + "; ".join(
            f"{r.subject} {r.task} ({r.error})" for r in result.failed) + "."]
    return "\n".join(out) + "\n"


OUTPUT_NAMES = ("evaluation_subjects.csv", "evaluation_recordings.csv", "evaluation.md")


def write_table(
    result: EvaluationResult, out_dir: str | os.PathLike, *, overwrite: bool = False,
    group: OutputGroup | None = None,
) -> list[Path]:
    """Write ``evaluation_subjects.csv``, ``evaluation_recordings.csv`` and
    ``evaluation.md`` into ``out_dir``, all or nothing (``_io.atomic_outputs``: an error
    or Ctrl-C leaves none of them). Refuses (``OutputExistsError``) before writing
    anything if one exists and ``overwrite`` is false. ``group``: stage the files in a
    caller's ``atomic_outputs`` group instead (they appear when it ends)."""
    out_dir = Path(out_dir)
    paths = [out_dir / name for name in OUTPUT_NAMES]
    existing = [str(p) for p in paths if p.exists()]
    if existing and not overwrite:
        raise OutputExistsError(
            f"{', '.join(existing)}: file exists (pass overwrite=True / --force to replace it)")
    if group is None:
        with atomic_outputs(overwrite=overwrite) as own:
            return write_table(result, out_dir, overwrite=overwrite, group=own)
    md = "# Objective evaluation (CASSI Table 2)\n\n" + markdown_table(result)
    texts = (_csv_text(result.subjects, _SUBJECT_META), _csv_text(result.recordings, _META), md)
    return [group.write(p, t) for p, t in zip(paths, texts, strict=True)]


SUMMARY_NAME = "evaluation_summary.png"


def write_report(
    result: EvaluationResult, out_dir: str | os.PathLike, *, overwrite: bool = False,
    summary_name: str = SUMMARY_NAME,
) -> list[Path]:
    """The whole evaluation output, all or nothing: :func:`write_table`'s three files and
    :func:`plot_summary`'s figure (``summary_name``) in ``out_dir``; an error or Ctrl-C
    while writing any of them leaves none. Returns the four paths."""
    out_dir = Path(out_dir)
    with atomic_outputs(overwrite=overwrite) as group:
        written = write_table(result, out_dir, overwrite=overwrite, group=group)
        written.append(plot_summary(result, out_dir / summary_name, overwrite=overwrite,
                                    group=group))
    return written


def compare(a: EvaluationResult, b: EvaluationResult, *,
            labels: tuple[str, str] = ("a", "b"), paper: bool = True) -> str:
    """A small Markdown table of the two results' rating totals side by side (and CASSI's
    own Table 2 totals when ``paper``), with the mean number of problems per subject."""
    lines = ["| | Teeth | Lips | Tongue | problems per subject (teeth/lips/tongue) |",
             "|---|---|---|---|---|"]
    if paper:  # its mean counts follow from the totals, FAIR taken as 3 problems
        mean = "/".join(f"{np.dot(CASSI_TOTALS[c], np.arange(4)) / 15:.1f}" for c in COMPONENTS)
        lines.append("| CASSI (paper, 15 subjects; FAIR as 3) | "
                     + " | ".join(_totals_text(CASSI_TOTALS[c]) for c in COMPONENTS)
                     + f" | {mean} |")
    for label, result in zip(labels, (a, b), strict=True):
        rated = [s for s in result.subjects if s.rated]
        mean = "/".join(
            f"{np.mean([len(s.problems[c]) for s in rated]):.1f}" if rated else "-"
            for c in COMPONENTS)
        totals = result.totals()
        lines.append(f"| {label} ({_subjects(len(rated))}) | "
                     + " | ".join(_totals_text(totals[c]) for c in COMPONENTS)
                     + f" | {mean} |")
    return "Counts are EXCELLENT/VERY GOOD/GOOD/FAIR.\n\n" + "\n".join(lines) + "\n"


# Measures drawn per subject in the summary figure, per component: (names, thresholds).
_PLOTTED = {
    "teeth": (("lower_slope_deg",), (SLOPE_UP_DEG, SLOPE_STEEP_DEG, SLOPE_VERY_STEEP_DEG)),
    "lips": (("lip_gap_min_mm", "lip_gap_median_mm"),
             (-LIP_TIGHT_MM, LIP_APART_MM, LIP_APART_LARGE_MM)),
    "tongue": (("tongue_upper_front_mm", "tongue_lower_front_mm"),
               (TONGUE_POKE_MM, TONGUE_POKE_DEEP_MM)),
}


def plot_summary(
    result: EvaluationResult, path: str | os.PathLike, *, overwrite: bool = False,
    group: OutputGroup | None = None,
) -> Path:
    """A PNG: top row, subjects per rating for teeth, lips, tongue (beside CASSI's Table 2
    counts); bottom row, the key measures per subject against their thresholds (dashed).
    Written atomically; ``group``: staged in a caller's ``atomic_outputs`` group."""
    if group is None:
        with atomic_outputs(overwrite=overwrite) as own:
            return plot_summary(result, path, overwrite=overwrite, group=own)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tmp = group.path(path)
    rated = [s for s in result.subjects if s.rated]
    totals = result.totals()
    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5), constrained_layout=True)
    x = np.arange(len(RATINGS))
    for k, c in enumerate(COMPONENTS):
        ax = axes[0, k]
        ax.bar(x - 0.2, totals[c], 0.4, label=f"measured ({_subjects(len(rated))})")
        ax.bar(x + 0.2, CASSI_TOTALS[c], 0.4, label="CASSI Table 2 (15)", alpha=0.5,
               hatch="//")
        ax.set_xticks(x, RATINGS, fontsize=9)
        ax.set_ylim(0, 1.3 * max(max(totals[c]), max(CASSI_TOTALS[c]), 1))
        ax.set_title(f"{c}: subjects per rating")
        ax.set_ylabel("subjects")
        ax.legend(fontsize=8, loc="upper left")
        names, limits = _PLOTTED[c]
        ax = axes[1, k]
        width = 0.8 / len(names)
        where = np.arange(len(rated))
        for j, name in enumerate(names):
            values = [s.measures.get(name, np.nan) for s in rated]
            ax.bar(where + (j - (len(names) - 1) / 2) * width, values, width,
                   label=f"{name} ({MEASURES[name].unit})")
        for limit in limits:
            ax.axhline(limit, color="tab:red", lw=1, ls="--")
        ax.axhline(0.0, color="black", lw=0.5)
        ax.set_xticks(where, [s.subject for s in rated], rotation=90, fontsize=8)
        ax.set_title(f"{c}: key measures per subject (dashed: thresholds)", fontsize=10)
        ax.legend(fontsize=8)
    s = result.settings
    fig.suptitle(f"Objective evaluation: calibration {s.get('calibration', '?')}, "
                 f"collisions {s.get('collisions', '?')}")
    try:
        fig.savefig(tmp, dpi=100)  # the group removes tmp on any failure
    finally:
        plt.close(fig)
    return Path(path)
