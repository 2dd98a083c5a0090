"""``cassi jaw``'s tables and its corpus task: one recording's jaw fit as a frame table and a
summary row, and ``cassi jaw DATASET`` (the task run on every recording by the corpus
executor, :func:`cassi_fit.corpus.run_corpus`).

Every table goes through :mod:`cassi_fit.tables` (one writer, one way to print a cell).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from ._io import atomic_write
from .status import Status, fitted
from .tables import csv_text

if TYPE_CHECKING:
    import numpy as np
    from jaxtyping import Float

    from .corpus import CorpusItem, CorpusResult, TaskResult
    from .dataset import Dataset
    from .jaw_fit import JawFit
    from .labels import Labels
    from .pipeline import RecordingRun
    from .run_spec import RunSpec

JAW_FRAME_COLUMNS = ("time_s", "theta_deg", "pivot_a_mm", "pivot_b_mm", "tx_mm", "ty_mm",
                     "residual_mm", "status")
#: the jaw statuses counted per recording (Status values 0-5)
JAW_STATUSES = (Status.OK, Status.PIVOT_UNDEFINED, Status.DEGENERATE, Status.NON_FINITE,
                Status.INVALID_FRAME, Status.NOT_CONVERGED)


def jaw_frame_rows(times: Float[np.ndarray, " n"], fit: JawFit, labels: Labels | None = None,
                   mistracks: list[str] | None = None) -> tuple[list[dict], list[str]]:
    """One recording's jaw table as ``(rows, columns)``: one row per frame,
    :data:`JAW_FRAME_COLUMNS` (times s, theta deg, pivot and translation mm, rms residual
    mm, the status word; the pivot blank where it is undefined (``pivot-undefined``, and in
    frames whose own data were not used), the residual blank where nothing was fitted);
    with one jaw sensor and the other's reference known, the hidden sensor's predicted position (``MNM_pred_x_mm``, ``MNM_pred_y_mm`` or ``MNI_...``, mm,
    in the pellet frame; blank in frames whose own data were not used: invalid-frame,
    mistracked, ...); a ``mistrack`` column when ``mistracks`` are given (one string
    per frame, ``MistrackReport.frame_labels``: which pellet the detector flagged and
    why, e.g. ``"MNI:dropout"``); a ``label`` column when ``labels`` are given
    (``labels.Labels``; ``""`` between labelled intervals)."""
    import numpy as np

    predicted = fit.hidden_predicted
    pred_columns = ([f"{fit.hidden_sensor}_pred_x_mm", f"{fit.hidden_sensor}_pred_y_mm"]
                    if predicted is not None else [])
    columns = (list(JAW_FRAME_COLUMNS) + (["mistrack"] if mistracks is not None else [])
               + pred_columns + (["label"] if labels is not None else []))
    theta_deg = np.rad2deg(fit.theta)
    predicted_here = fitted(fit.status) | (fit.status == int(Status.NOT_CONVERGED))
    current = labels.at(times) if labels is not None else None
    rows = []
    for k in range(len(times)):
        pivot = fit.pivot[k] if fit.pivot_defined[k] else (None, None)
        row = {"time_s": float(times[k]), "theta_deg": float(theta_deg[k]),
               "pivot_a_mm": _number(pivot[0]), "pivot_b_mm": _number(pivot[1]),
               "tx_mm": float(fit.translation[k, 0]), "ty_mm": float(fit.translation[k, 1]),
               "residual_mm": float(fit.residual[k]) if predicted_here[k] else None,
               "status": Status(int(fit.status[k])).label}
        if predicted is not None:  # blank where the frame's own data were not used
            row[pred_columns[0]], row[pred_columns[1]] = (
                (float(v) for v in predicted[k]) if predicted_here[k] else (None, None))
        if mistracks is not None:
            row["mistrack"] = mistracks[k]
        if current is not None:
            row["label"] = str(current[k])
        rows.append(row)
    return rows, columns


def _number(value) -> float | None:
    return None if value is None else float(value)


def jaw_frame_csv(times: Float[np.ndarray, " n"], fit: JawFit, labels: Labels | None = None,
                  mistracks: list[str] | None = None) -> str:
    """:func:`jaw_frame_rows` as CSV text, as ``cassi jaw RECORDING`` writes it."""
    rows, columns = jaw_frame_rows(times, fit, labels, mistracks)
    return csv_text(rows, columns)


def _iqr(x: np.ndarray) -> float | None:
    import numpy as np

    if x.size == 0:
        return None
    q1, q3 = np.percentile(x, [25, 75])
    return float(q3 - q1)


def jaw_summary_row(fit: JawFit, *, label_file: str = "",
                    current: Float[np.ndarray, "n 2 2"] | None = None) -> dict:
    """The corpus-table row of one jaw fit: method, the jaw sensors used and the prior,
    frames, angle range (deg) over the fitted frames, pivot spread (interquartile range of
    the pivot's a and b over frames with a defined pivot, mm), residuals (rms and max over
    fitted frames, mm), the noise estimate, convergence (and how the solve failed,
    ``solver_failure``, empty when it converged), the number of frames per status, and,
    given the recording's jaw pellets ``current`` (n, 2, 2) mm, the hidden sensor's
    prediction error (median and 95th percentile, mm; empty with both sensors)."""
    import numpy as np

    fitted = fit.status == int(Status.OK)
    theta_deg = np.rad2deg(fit.theta[fitted])
    pivots = fit.pivot[fitted & fit.pivot_defined]
    residual = fit.residual[fitted]
    failure = fit.failure
    row = {
        "method": fit.method, "solver": fit.solver, "jaw_sensors": ",".join(fit.jaw_sensors),
        "prior": fit.prior, "frames": int(fit.status.size),
        "theta_min_deg": float(theta_deg.min()) if theta_deg.size else None,
        "theta_max_deg": float(theta_deg.max()) if theta_deg.size else None,
        "theta_range_deg": float(np.ptp(theta_deg)) if theta_deg.size else None,
        "pivot_iqr_a_mm": _iqr(pivots[:, 0]), "pivot_iqr_b_mm": _iqr(pivots[:, 1]),
        "residual_rms_mm": float(np.sqrt(np.mean(residual**2))) if residual.size else None,
        "residual_max_mm": float(residual.max()) if residual.size else None,
        "noise_mm": float(fit.noise_mm), "converged": bool(fit.converged),
        "solver_failure": "" if failure is None else failure.label,
    }
    for s in JAW_STATUSES:
        row[f"frames_{s.label.replace('-', '_')}"] = int(np.sum(fit.status == int(s)))
    hidden = (None, None)
    if current is not None and fit.hidden_predicted is not None:
        from .jaw_fit import jaw_diagnostics

        d = jaw_diagnostics(fit, current)
        hidden = tuple(None if np.isnan(v) else v
                       for v in (d.hidden_error_median_mm, d.hidden_error_p95_mm))
    row["hidden_error_median_mm"], row["hidden_error_p95_mm"] = hidden
    row["label_file"] = label_file
    return row


def jaw_output_path(out_dir: str | os.PathLike, item: CorpusItem) -> Path:
    """``out_dir/SUBJECT/TASK.jaw.csv``."""
    return Path(out_dir) / item.subject / f"{item.task}.jaw.csv"


def segments_output_path(out_dir: str | os.PathLike, item: CorpusItem) -> Path:
    """``out_dir/SUBJECT/TASK.segments.csv``."""
    return Path(out_dir) / item.subject / f"{item.task}.segments.csv"


class JawTables(NamedTuple):
    """What :func:`write_jaw_tables` wrote: the ``outputs`` (the frame table, and the
    segments table when there are labels), the ``labels`` used (None: none found or
    asked for) and the ``segments`` rows."""

    outputs: tuple[Path, ...]
    labels: Labels | None
    segments: list[dict]


def write_jaw_tables(run: RecordingRun, out: str | os.PathLike,
                     segments_out: str | os.PathLike, *, labels: bool = True,
                     overwrite: bool = False) -> JawTables:
    """One recording's jaw tables (``cassi jaw``, one recording or a corpus's): the frame
    table (:func:`jaw_frame_csv`, with the mistrack column) to ``out`` and, when
    ``labels`` and labels beside the recording or inside it (``labels.recording_labels``), a
    ``label`` column and one row per labelled segment (``labels.segment_summary``: peak
    jaw opening, lip aperture range, ...) to ``segments_out``. ``run``: a
    ``pipeline.RecordingRun`` with the jaw stage run."""
    from .labels import SEGMENT_COLUMNS, recording_labels, segment_summary

    recording, fit = run.recording, run.jaw
    track = recording.track
    found = recording_labels(recording) if labels else None  # beside the file or inside it
    outputs = [atomic_write(out, jaw_frame_csv(track.times, fit, found,
                                               track.mistracks.frame_labels()),
                            overwrite=overwrite)]
    segments: list[dict] = []
    if found is not None:
        segments = segment_summary(track.times, fit.theta, track.positions, found,
                                   usable=fit.status == int(Status.OK))
        outputs.append(atomic_write(segments_out, csv_text(segments, SEGMENT_COLUMNS),
                                    overwrite=overwrite))
    return JawTables(tuple(outputs), found, segments)


def jaw_task(item: CorpusItem, out_dir: str, *, spec: RunSpec, labels: bool = True,
             overwrite: bool = False) -> TaskResult:
    """``cassi jaw DATASET``'s task: the jaw stage of one recording
    (``pipeline.run_recording(..., stages=pipeline.JAW)``, as ``spec`` says), its tables
    (:func:`write_jaw_tables`: ``out_dir/SUBJECT/TASK.jaw.csv``, and
    ``TASK.segments.csv`` with labels) and the summary row (:func:`jaw_summary_row`; with
    one jaw sensor, the other's prediction error where the file has it). Any recording
    the toolkit reads (``corpus.load_item``)."""
    from .corpus import TaskResult, load_item
    from .pellets import JAW_PELLETS, pellet_index
    from .pipeline import JAW, run_recording

    recording = load_item(item, quiet=True)
    run = run_recording(recording, spec, stages=JAW)
    written = write_jaw_tables(run, jaw_output_path(out_dir, item),
                               segments_output_path(out_dir, item), labels=labels,
                               overwrite=overwrite)
    found = written.labels
    label_file = found.path.name if found is not None and found.path is not None else ""
    current = recording.track.positions[:, [pellet_index(p) for p in JAW_PELLETS]]
    return TaskResult(jaw_summary_row(run.jaw, label_file=label_file, current=current),
                      tuple(str(p) for p in written.outputs))


def jaw_spec(spec: RunSpec | str | None = None, **changes: Any) -> RunSpec:
    """The run spec of ``cassi jaw``: ``spec`` with ``changes`` (``jaw=``, a method object
    or name, ``jaw_sensors=``), computed in float64 (``x64``: the pivots to a micrometre
    are quotients by ``sin(theta / 2)``)."""
    from .run_spec import run_spec

    return run_spec(spec, **changes).replace(x64=True)


def jaw_corpus_path(out_dir: str | os.PathLike) -> Path:
    """``out_dir/jaw_corpus.csv`` (and ``.parquet`` beside it)."""
    return Path(out_dir) / "jaw_corpus.csv"


def jaw_corpus(
    dataset: Dataset | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None,
    run_options: Mapping[str, Any] | None = None,
    spec: RunSpec | str | None = None,
    labels: bool = True,
    **changes: Any,
) -> CorpusResult:
    """``cassi jaw DATASET --out DIR``: :func:`jaw_task` on every recording (the jaw
    method and sensors of ``spec`` with ``changes``, :func:`jaw_spec`: float64, checked
    before the run), then the corpus table ``DIR/jaw_corpus.csv`` (and ``.parquet``).
    ``spec.jaw`` None: the closed form with two jaw sensors, coupled-rotation with one;
    ``spec.jaw_sensors`` None: the jaw pellets each recording has. ``run_options`` go to
    :func:`cassi_fit.corpus.run_corpus` (``jobs``, ``scheduler``, ``executor``,
    ``resume``, ``overwrite``, ``progress``, ``compilation_cache``). Returns a
    ``corpus.CorpusResult`` (``value`` None)."""
    from .corpus import (
        CorpusResult,
        dataset_items,
        refuse_existing,
        replaces,
        require_items,
        run_corpus,
        write_table,
    )

    spec = jaw_spec(spec, **changes)
    run_options = dict(run_options or {})
    table = jaw_corpus_path(out_dir)
    refuse_existing([table], run_options)  # before the run, not after it
    run_options.setdefault("desc", "jaw")
    items = require_items(dataset_items(dataset, subjects=subjects, tasks=tasks), dataset,
                          subjects, tasks)
    run = run_corpus(jaw_task, items, out_dir, options={"spec": spec, "labels": bool(labels)},
                     **run_options)
    return CorpusResult(run, write_table(run.rows(), table, overwrite=replaces(run_options)))
