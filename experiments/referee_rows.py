"""The rows of experiments/real_referee.py: per recording and pooled over a dataset, the
median and 95th percentile of each predictor's error with block-bootstrap intervals
and verdicts; running a dataset's recordings; reading the rows back.
"""

from __future__ import annotations

import warnings
import zlib
from collections.abc import Callable, Sequence

import numpy as np
from referee_parts import (
    BOOTSTRAP,
    LEVEL,
    STATISTICS,
    Couplings,
    PartResult,
    recording_parts,
    single_sensor_predictor,
)


# --------------------------------------------------------------------------- bootstrap
def _rng(*names: object) -> np.random.Generator:
    """A generator seeded from names (stable across runs and processes)."""
    return np.random.default_rng(zlib.crc32("/".join(map(str, names)).encode()))


def block_starts(n: int, rng: np.random.Generator, block: int,
                 n_boot: int = BOOTSTRAP) -> np.ndarray:
    """Start indices (n_boot, ceil(n / block)) of a moving-block bootstrap of n frames."""
    block = max(1, min(block, n))
    return rng.integers(0, n - block + 1, size=(n_boot, -(-n // block)))


def resample_index(starts: np.ndarray, n: int, block: int) -> np.ndarray:
    """Frame indices (..., n) of resamples given by their block starts (..., n_blocks)."""
    block = max(1, min(block, n))
    index = starts[..., None] + np.arange(block)
    return index.reshape(*starts.shape[:-1], -1)[..., :n]


def _interval(stats: np.ndarray) -> tuple[float, float]:
    lo, hi = np.percentile(stats, [(100 - LEVEL) / 2, 100 - (100 - LEVEL) / 2])
    return float(lo), float(hi)


def _verdict(lo: float, hi: float) -> str:
    return "better" if hi < 0 else "worse" if lo > 0 else "tie"


def _stat_rows(base: dict, values: dict[str, np.ndarray], boot: dict[str, np.ndarray],
               roles: dict[str, str], frames: int) -> list[dict]:
    """Rows of every predictor and of every method-minus-baseline pair.

    values: predictor -> {statistic: value}; boot: predictor -> (n_stats, B) resampled."""
    rows = []
    for name, role in roles.items():
        row = dict(base, predictor=name, role=role, versus="", frames=frames)
        for k, key in enumerate(STATISTICS):
            lo, hi = _interval(boot[name][k])
            row |= {f"{key}_mm": values[name][k], f"{key}_lo_mm": lo, f"{key}_hi_mm": hi,
                    f"{key}_verdict": ""}
        rows.append(row)
    for name, role in roles.items():  # methods against baselines and references;
        if role == "baseline":  # references against baselines
            continue
        for other, other_role in roles.items():
            if other_role == role or (role != "method" and other_role != "baseline"):
                continue
            row = dict(base, predictor=name, role=f"{role} - {other_role}", versus=other,
                       frames=frames)
            for k, key in enumerate(STATISTICS):
                lo, hi = _interval(boot[name][k] - boot[other][k])
                row |= {f"{key}_mm": values[name][k] - values[other][k], f"{key}_lo_mm": lo,
                        f"{key}_hi_mm": hi, f"{key}_verdict": _verdict(lo, hi)}
            rows.append(row)
    return rows


def _percentiles(values: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.percentile(values, list(STATISTICS.values()), axis=axis)


def recording_rows(dataset: str, subject: str, task: str, result: PartResult) -> list[dict]:
    """Per-recording rows of one part: every predictor's median and 95th percentile with
    their block-bootstrap intervals, and the paired differences."""
    n = len(result.frames)
    base = {"dataset": dataset, "subject": subject, "task": task, "part": result.part,
            "metric": result.metric, "recordings": 1, "subjects": 1}
    if n == 0:
        return []
    starts = block_starts(n, _rng(dataset, subject, task, result.part), result.block)
    index = resample_index(starts, n, result.block)
    values = {k: _percentiles(v) for k, v in result.errors.items()}
    boot = {k: _percentiles(v[index]) for k, v in result.errors.items()}
    return _stat_rows(base, values, boot, result.roles, n)


def pooled_rows(dataset: str, results: Sequence[tuple[str, str, PartResult]]) -> list[dict]:
    """Pooled rows of one part over recordings ``(subject, task, result)``: frames pooled;
    the bootstrap resamples subjects (with all their recordings), then blocks of frames
    within each recording (the same blocks as the per-recording rows)."""
    results = [r for r in results if len(r[2].frames)]
    if not results:
        return []
    first = results[0][2]
    subjects = sorted({s for s, _, _ in results})
    starts = [block_starts(len(r.frames), _rng(dataset, s, t, r.part), r.block)
              for s, t, r in results]
    by_subject = {s: [k for k, (sub, _, _) in enumerate(results) if sub == s] for s in subjects}
    rng = _rng(dataset, "pooled", first.part)
    names = list(first.roles)
    values = {k: _percentiles(np.concatenate([r.errors[k] for _, _, r in results])) for k in names}
    boot = {k: np.empty((len(STATISTICS), BOOTSTRAP)) for k in names}
    for b in range(BOOTSTRAP):
        chosen = rng.choice(len(subjects), size=len(subjects), replace=True)
        picks = [k for c in chosen for k in by_subject[subjects[c]]]
        index = [resample_index(starts[k][b], len(results[k][2].frames), results[k][2].block)
                 for k in picks]
        for name in names:
            sample = np.concatenate([results[k][2].errors[name][i] for k, i in zip(picks, index,
                                                                                  strict=True)])
            boot[name][:, b] = _percentiles(sample)
    base = {"dataset": dataset, "subject": "pooled", "task": "pooled", "part": first.part,
            "metric": first.metric, "recordings": len(results), "subjects": len(subjects)}
    frames = sum(len(r.frames) for _, _, r in results)
    return _stat_rows(base, values, boot, first.roles, frames)


# ------------------------------------------------------------------------------- runs
def dataset_recordings(root, subjects=None, tasks=None):
    """Yield ``(subject, task, recording)`` of every recording of the folder ``root``
    (restricted to ``subjects`` / ``tasks`` when given)."""
    from cassi_fit.dataset import Dataset

    data = Dataset(root)
    for subject in data.subjects():
        if subjects and subject not in {s.upper() for s in subjects}:
            continue
        for task in data.tasks(subject):
            if tasks and task not in {t.lower() for t in tasks}:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # default head measures
                recording = data.load(subject, task)
            yield subject, task, recording


def run(datasets: Sequence[tuple[str, object, object, object]], model=None,
        progress: Callable[[str], None] | None = None) -> tuple[list[dict], list[dict]]:
    """Every recording's rows and each part's pooled rows of every dataset, and the
    couplings learned. ``datasets``: ``(label, folder, subjects or None, tasks or None)``."""
    from cassi_fit.face_model import load_model

    model = load_model() if model is None else model
    loaded = {label: list(dataset_recordings(root, subjects, tasks))
              for label, root, subjects, tasks in datasets}
    tracks: dict[tuple[str, str], list] = {}
    for label, recordings in loaded.items():
        for subject, _, recording in recordings:
            tracks.setdefault((label, subject), []).append(recording.track)
    couplings = Couplings(tracks)
    rows = []
    for label, recordings in loaded.items():
        by_part = {}
        for subject, task, recording in recordings:
            if progress:
                progress(f"{label} {subject} {task}")
            single = single_sensor_predictor(
                lambda sensor, label=label, subject=subject: couplings.get(label, subject, sensor))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                parts = recording_parts(recording, model, single)
            for result in parts:
                rows += recording_rows(label, subject, task, result)
                by_part.setdefault((result.part, result.metric), []).append(
                    (subject, task, result))
        for results in by_part.values():
            rows += pooled_rows(label, results)
    return rows, couplings.rows()


# ---------------------------------------------------------------------------- tables
INTEGER_COLUMNS = ("frames", "recordings", "subjects")


TEXT_COLUMNS = ("dataset", "subject", "task", "part", "metric", "predictor", "role", "versus",
                "median_verdict", "p95_verdict", "sensor", "source")


def parse_rows(text: str) -> list[dict]:
    """Rows of ``real_referee.csv`` (or ``real_referee_couplings.csv``) text, numbers as
    numbers (the inverse of ``tables.csv_text`` up to its 6 decimals)."""
    import csv
    import io

    rows = []
    for raw in csv.DictReader(io.StringIO(text)):
        rows.append({k: v if k in TEXT_COLUMNS else int(v) if k in INTEGER_COLUMNS
                     else float(v) for k, v in raw.items()})
    return rows


def _cell(row: dict | None, key: str, verdict: bool = False) -> str:
    if row is None or not np.isfinite(row[f"{key}_mm"]):
        return "-"
    text = f"{row[f'{key}_mm']:.2f} [{row[f'{key}_lo_mm']:.2f}, {row[f'{key}_hi_mm']:.2f}]"
    return f"{text} {row[f'{key}_verdict']}" if verdict else text
