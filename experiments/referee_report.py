"""The Markdown of experiments/real_referee.py: per part the tables of the pooled rows,
the headline, the issue's hand measurements against the rows, the couplings.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from referee_parts import BLOCK_S, BOOTSTRAP, ISSUE_JW11, SYNTHETIC_LABEL
from referee_rows import _cell


def _pooled(rows, dataset, part, metric):
    return [r for r in rows if r["dataset"] == dataset and r["subject"] == "pooled"
            and r["part"] == part and r["metric"] == metric]


def _datasets(rows) -> list[str]:
    return list(dict.fromkeys(r["dataset"] for r in rows))


def _dataset_title(rows, dataset) -> str:
    pooled = [r for r in rows if r["dataset"] == dataset and r["subject"] == "pooled"]
    n_rec = max((r["recordings"] for r in pooled), default=0)
    n_sub = max((r["subjects"] for r in pooled), default=0)
    return f"{dataset} ({n_rec} rec., {n_sub} subj.)"


def part_tables(rows, part: str, metric: str) -> str:
    """Two Markdown tables of one part and metric, the datasets side by side: every
    predictor's pooled median and 95th percentile [95 % interval]; the paired differences
    (method minus baseline or reference, on the same frames) with their verdicts."""
    from cassi_fit.tables import markdown_text

    datasets = _datasets(rows)
    by_dataset = {d: _pooled(rows, d, part, metric) for d in datasets}
    names = list(dict.fromkeys(r["predictor"] for d in datasets for r in by_dataset[d]
                               if not r["versus"]))
    errors, paired, headers = [], [], {}
    for name in names:
        role = next(r["role"] for d in datasets for r in by_dataset[d]
                    if r["predictor"] == name and not r["versus"])
        row = {"predictor": name, "role": role}
        for d in datasets:
            found = next((r for r in by_dataset[d] if r["predictor"] == name and not r["versus"]),
                         None)
            row[f"{d} median"], row[f"{d} p95"] = _cell(found, "median"), _cell(found, "p95")
            row[f"{d} frames"] = "-" if found is None else found["frames"]
        errors.append(row)
    pairs = list(dict.fromkeys((r["predictor"], r["versus"]) for d in datasets
                               for r in by_dataset[d] if r["versus"]))
    for name, other in pairs:
        row = {"comparison": f"{name} - {other}"}
        for d in datasets:
            found = next((r for r in by_dataset[d] if (r["predictor"], r["versus"])
                          == (name, other)), None)
            row[f"{d} median"] = _cell(found, "median", verdict=True)
            row[f"{d} p95"] = _cell(found, "p95", verdict=True)
        paired.append(row)
    for d in datasets:
        title = _dataset_title(rows, d)
        headers |= {f"{d} median": f"{title}: median [95 % CI]",
                    f"{d} p95": f"{title}: 95th pct [95 % CI]", f"{d} frames": f"{d}: frames"}
    text = markdown_text(errors, headers=headers)
    if paired:
        text += "\nPaired, on the same frames (mm; negative: the first predicts better):\n\n"
        text += markdown_text(paired, headers=headers)
    return text


def headline(rows) -> str:
    """One Markdown table: per part (and metric) and dataset, the method and the baseline
    with the lowest pooled median, and their paired difference with its verdict (a
    lowest point estimate names no winner: the verdict says whether the interval does)."""
    from cassi_fit.tables import markdown_text

    table = []
    for part, metric in dict.fromkeys((r["part"], r["metric"]) for r in rows):
        if metric == "along":
            continue
        for d in _datasets(rows):
            pooled = _pooled(rows, d, part, metric)
            plain = [r for r in pooled if not r["versus"]]
            best = {role: min((r for r in plain if r["role"] == role), default=None,
                              key=lambda r: r["median_mm"]) for role in ("method", "baseline")}
            if best["method"] is None or best["baseline"] is None:
                continue
            paired = next(r for r in pooled if (r["predictor"], r["versus"])
                          == (best["method"]["predictor"], best["baseline"]["predictor"]))
            table.append({
                "part": f"{part} ({metric})", "dataset": d,
                "lowest method: median [95 % CI]":
                    f"{best['method']['predictor']}: {_cell(best['method'], 'median')}",
                "lowest baseline: median [95 % CI]":
                    f"{best['baseline']['predictor']}: {_cell(best['baseline'], 'median')}",
                "method - baseline: median": _cell(paired, "median", verdict=True),
                "method - baseline: 95th pct": _cell(paired, "p95", verdict=True)})
    return markdown_text(table) if table else "No part has both a method and a baseline.\n"


def issue_check(rows, dataset: str) -> str:
    """The issue's hand measurements on JW11 beside this run's (MNM from MNI)."""
    from cassi_fit.tables import markdown_text

    pooled = _pooled(rows, dataset, "jaw: MNM from MNI", "position")
    table = []
    for name, (words, median, p95, differs) in ISSUE_JW11.items():
        found = next((r for r in pooled if r["predictor"] == name and not r["versus"]), None)
        table.append({"issue 20": words, "by hand": f"{median:.1f} ({p95:.1f})",
                      "predictor here": name,
                      "this run": "not run" if found is None
                      else f"{found['median_mm']:.2f} ({found['p95_mm']:.2f})",
                      "what differs": differs or "nothing"})
    return markdown_text(table)


PART_TEXT = {
    ("jaw", "position"): "Distance (mm) between the predicted and the measured hidden jaw "
    "sensor. Methods see one jaw sensor (`jaw_from_track(..., jaw_sensors=SEEN)`: the "
    "coupled rotation with a coupling learned on other speakers, below; the fixed and "
    "smooth pivots with the library's one-sensor prior, a population condyle with an SD of "
    "15 mm; a fixed pivot held at that condyle; a fixed pivot fitted freely); the "
    "baselines need nothing but that sensor; the references saw both sensors (the goal a "
    "single-sensor method would like to reach).",
    ("tongue", "surface"): "Distance (mm) from the measured hidden pellet to the tongue's "
    "upper midsagittal contour (methods: the model's tongue posed by the pipeline without "
    "the pellet; baseline: the chord between the neighbouring pellets).",
    ("tongue", "site"): "Distance (mm) from the measured hidden pellet to where the model "
    "puts it (its pellet site; baseline: the point on the chord at the model's rest "
    "arc-length fraction).",
    ("tongue", "along"): "The tangential part of the site error: distance (mm) along the "
    "contour (chord) from the predicted site to the foot of the perpendicular from the "
    "measured pellet.",
    ("lips", "position"): "Distance (mm) between the predicted and the measured lower lip. "
    "Held out: LL. Not held out: both jaw pellets (the jaw motion, by the pipeline's jaw "
    "method). The lip's own motion (#65/#66) has no predictor in the model: this error is "
    "what the model needs the LL pellet for.",
}


def _dataset_note(rows, dataset) -> str:
    recordings = sorted({(r["subject"], r["task"]) for r in rows
                         if r["dataset"] == dataset and r["subject"] != "pooled"})
    subjects = sorted({s for s, _ in recordings})
    if dataset == SYNTHETIC_LABEL:
        tasks = sorted({t for _, t in recordings})
        return (f"`{dataset}`: the toolkit's synthetic corpus, {len(recordings)} recordings of "
                f"{len(subjects)} subjects (tasks {', '.join(tasks)}). Its generator shares "
                "assumptions with the models scored here: it is no referee, only a comparison "
                "of how the two behave.")
    if len(recordings) == 1:
        (subject, task), = recordings
        return (f"`{dataset}`: real, one recording of one speaker ({subject}, task {task}). "
                "Its numbers say what this speaker did in this task, not what speakers do.")
    return (f"`{dataset}`: real, {len(recordings)} recordings of {len(subjects)} speakers "
            f"({', '.join(subjects)}).")


def couplings_markdown(couplings: Sequence[dict]) -> str:
    """The couplings used, per dataset and sensor: one speaker's as they are, several
    speakers' as the median [min, max] of their coefficients (deg of jaw rotation per mm
    of the sensor's displacement, x forward and y up)."""
    from cassi_fit.tables import markdown_text

    def spread(values):
        values = np.rad2deg(values)
        if len(values) == 1:
            return f"{values[0]:.3f}"
        return f"{np.median(values):.3f} [{values.min():.3f}, {values.max():.3f}]"

    table = []
    for d, sensor in dict.fromkeys((c["dataset"], c["sensor"]) for c in couplings):
        group = [c for c in couplings if (c["dataset"], c["sensor"]) == (d, sensor)]
        table.append({
            "dataset": d, "sensor": sensor, "speakers": len(group),
            "deg per mm, x": spread(np.array([c["rad_per_mm_x"] for c in group])),
            "deg per mm, y": spread(np.array([c["rad_per_mm_y"] for c in group])),
            "scatter (deg)": spread(np.array([c["theta_sd_rad"] for c in group])),
            "learned from": group[0]["source"] if len(group) == 1
            else "for each speaker, the others of its dataset"})
    return markdown_text(table) if table else "No coupling was learned.\n"


def markdown(rows, command: str, couplings: Sequence[dict] = ()) -> str:
    """The whole Markdown report; its first line names the command that wrote it.
    ``couplings``: the rows of ``real_referee_couplings.csv``."""
    datasets = _datasets(rows)
    real = [d for d in datasets if d != SYNTHETIC_LABEL]
    parts = [
        f"<!-- written by `{command}`; do not edit: `make experiments` rewrites it -->",
        "# Real recordings as the referee: held-out sensors",
        "",
        "Written by `experiments/real_referee.py` (its docstring says exactly what is held "
        "out and how each error is measured). Each model predicts a pellet it never saw, "
        "and the measured pellet is the referee. Datasets side by side: "
        + ", ".join(f"`{d}`" for d in datasets) + ".",
        "",
        *(f"- {_dataset_note(rows, d)}" for d in datasets),
        "",
        f"Statistics: the median and 95th percentile of the per-frame errors, frames pooled "
        f"over a dataset's recordings, with 95 % percentile-bootstrap intervals ({BOOTSTRAP} "
        f"resamples: subjects resampled with all their recordings, then blocks of "
        f"{BLOCK_S} s of consecutive frames within each recording; with one subject "
        "the interval reflects only the frames of its recordings). Paired rows: a predictor's "
        "statistic minus another's on the same resampled frames; `better`/`worse` only where "
        "the interval excludes 0, else `tie`. Per-recording rows are in `real_referee.csv`.",
        "",
    ]
    parts += ["## Headline", "", "Per held-out test, the method and the baseline with the "
              "lowest pooled median (mm), and the method minus the baseline on the same "
              "frames; the sections below give every predictor.", "", headline(rows), ""]
    seen = list(dict.fromkeys((r["part"], r["metric"]) for r in rows))
    for part, metric in seen:
        kind = part.split(":")[0]
        parts += [f"## {part[0].upper() + part[1:]} ({metric})", "", PART_TEXT[(kind, metric)],
                  "", part_tables(rows, part, metric), ""]
    parts += ["## Couplings of the coupled rotation", "",
              "Learned (`jaw_fit.learn_jaw_coupling`: the two-sensor frame fit's angle "
              "regressed on the seen sensor's displacement) for each speaker from other "
              "speakers only, never from the recording scored: from the other subjects of "
              "its dataset, or, where its dataset has none, from the other datasets. Every "
              "coupling is in `real_referee_couplings.csv`.", "", couplings_markdown(couplings),
              ""]
    for d in real:
        parts += [f"## Check against the issue's hand measurements ({d})", "",
                  "Issue 20 measured these by hand on JW11 task 5 (MNM from MNI, median "
                  "(95th percentile), mm); the rows above reproduce them where the library "
                  "has the method.", "", issue_check(rows, d), ""]
    return "\n".join(parts)
