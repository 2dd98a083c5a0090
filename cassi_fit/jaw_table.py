"""``cassi jaw``'s tables and its corpus task: one recording's jaw fit as a frame table and a
summary row, and ``cassi jaw DATASET`` (the task run on every recording by the corpus
executor, :func:`cassi_fit.corpus.run_corpus`).

Every table goes through :mod:`cassi_fit.tables` (one writer, one way to print a cell).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._io import atomic_write
from .corpus import (
    CorpusItem,
    CorpusRun,
    TaskResult,
    dataset_items,
    require_items,
    run_corpus,
    write_table,
)
from .errors import OutputExistsError
from .status import Status
from .tables import csv_text

if TYPE_CHECKING:
    import numpy as np
    from jaxtyping import Float

    from .dataset import Dataset
    from .jaw_fit import JawFit
    from .labels import Labels
    from .txy import PelletTrack

JAW_FRAME_COLUMNS = ("time_s", "theta_deg", "pivot_a_mm", "pivot_b_mm", "tx_mm", "ty_mm",
                     "residual_mm", "status")
#: the jaw statuses counted per recording (Status values 0-5)
JAW_STATUSES = (Status.OK, Status.PIVOT_UNDEFINED, Status.DEGENERATE, Status.NON_FINITE,
                Status.INVALID_FRAME, Status.NOT_CONVERGED)


def jaw_frame_rows(times: Float[np.ndarray, " n"], fit: JawFit, labels: Labels | None = None,
                   mistracks: list[str] | None = None) -> tuple[list[dict], list[str]]:
    """One recording's jaw table as ``(rows, columns)``: one row per frame,
    :data:`JAW_FRAME_COLUMNS` (times s, theta deg, pivot and translation mm, rms residual
    mm, the status word); with one jaw sensor and the other's reference known, the hidden
    sensor's predicted position (``MNM_pred_x_mm``, ``MNM_pred_y_mm`` or ``MNI_...``, mm,
    in the pellet frame); a ``mistrack`` column when ``mistracks`` are given (one string
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
    current = labels.at(times) if labels is not None else None
    rows = []
    for k in range(len(times)):
        row = {"time_s": float(times[k]), "theta_deg": float(theta_deg[k]),
               "pivot_a_mm": float(fit.pivot[k, 0]), "pivot_b_mm": float(fit.pivot[k, 1]),
               "tx_mm": float(fit.translation[k, 0]), "ty_mm": float(fit.translation[k, 1]),
               "residual_mm": float(fit.residual[k]), "status": Status(int(fit.status[k])).label}
        if predicted is not None:
            row[pred_columns[0]], row[pred_columns[1]] = (float(v) for v in predicted[k])
        if mistracks is not None:
            row["mistrack"] = mistracks[k]
        if current is not None:
            row["label"] = str(current[k])
        rows.append(row)
    return rows, columns


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


#: frames per padding bucket of the jaw fits: one compilation covers every recording up to
#: 7 s; the padding's cost is nothing for the closed form, and up to 3x a short recording's
#: fitting time for "frame-fit" (still far below one compilation)
JAW_FRAME_BUCKET = 1024


def fit_jaw_bucketed(track: PelletTrack, *, method: str | None = None,
                     solver: str | None = None, smoothness: float = 1.0,
                     jaw_sensors: str | None = None) -> JawFit:
    """``jaw_fit.jaw_from_track`` with the frames padded to a multiple of
    :data:`JAW_FRAME_BUCKET` (1024 frames, 7 s), so that a worker compiles the fit once per
    bucket instead of once per recording length (the XRMB lengths all differ; compiling
    costs about 2-3 s a length, fitting a recording tens of ms). The padding is untracked
    frames after the last: the per-frame methods give the real frames the values of an
    unpadded fit (they are fitted frame by frame and the noise is pooled over usable frames
    only), and "fixed-pivot" gets zero weight for them. "smooth-pivot" is not padded: its
    pivot-path knots depend on the length. ``jaw_sensors``: both, or one (``"MNI"``,
    ``"MNM"``; ``jaw_fit.fit_jaw``), or None for the jaw pellets the track has; ``method``
    None: the closed form with two, coupled-rotation with one
    (``jaw_fit.method_for_sensors``)."""
    import dataclasses

    import numpy as np

    from .jaw_fit import jaw_from_track, jaw_sensor_set, method_for_sensors, tracked_jaw_sensors
    from .txy import PelletTrack

    sensors = (tracked_jaw_sensors(track.valid, track.path) if jaw_sensors is None
               else jaw_sensor_set(jaw_sensors))
    method = method_for_sensors(method, sensors).name
    jaw_sensors = ",".join(sensors)

    if method == "smooth-pivot":
        return jaw_from_track(track, method=method, solver=solver, smoothness=float(smoothness),
                              jaw_sensors=jaw_sensors)
    n = track.n_frames
    extra = -n % JAW_FRAME_BUCKET
    step = track.frame_step_s
    padded = PelletTrack(
        times=np.concatenate([track.times, track.times[-1] + step * np.arange(1, extra + 1)]),
        positions=np.concatenate([track.positions, np.full((extra, 8, 2), np.nan)]),
        valid=np.concatenate([track.valid, np.zeros((extra, 8, 2), bool)]),
        path=track.path,
    )
    fit = jaw_from_track(padded, method=method, solver=solver, jaw_sensors=jaw_sensors)
    per_frame = {f.name: getattr(fit, f.name)[:n] for f in dataclasses.fields(fit)
                 if isinstance(getattr(fit, f.name), np.ndarray)
                 and getattr(fit, f.name).shape[:1] == (n + extra,)}
    return dataclasses.replace(fit, **per_frame)


def jaw_output_path(out_dir: str | os.PathLike, item: CorpusItem) -> Path:
    """``out_dir/SUBJECT/TASK.jaw.csv``."""
    return Path(out_dir) / item.subject / f"{item.task}.jaw.csv"


def segments_output_path(out_dir: str | os.PathLike, item: CorpusItem) -> Path:
    """``out_dir/SUBJECT/TASK.segments.csv``."""
    return Path(out_dir) / item.subject / f"{item.task}.segments.csv"


def jaw_task(item: CorpusItem, out_dir: str, *, method: str | None = None,
             solver: str | None = None, smoothness: float = 1.0,
             jaw_sensors: str | None = None, labels: bool = True,
             overwrite: bool = False) -> TaskResult:
    """``cassi jaw DATASET``'s task: fit the jaw of one pellet file
    (:func:`fit_jaw_bucketed`), write ``out_dir/SUBJECT/TASK.jaw.csv`` (one row per frame)
    and return the summary row (:func:`jaw_summary_row`). When ``labels`` and a label
    file lies beside the pellet file or labels are inside it (``labels.recording_labels``),
    the frame table gets a
    ``label`` column and ``TASK.segments.csv`` holds one row per labelled segment
    (``labels.segment_summary``: peak jaw opening, lip aperture range, ...). With one jaw
    sensor (``jaw_sensors``), the other's prediction is in the frame table and its error,
    where the file has it, in the row. Any recording the toolkit reads (XRMB or an
    articulograph's, ``corpus.load_item``); ``method``/``jaw_sensors`` None: as
    :func:`fit_jaw_bucketed`, per recording."""
    from .corpus import load_item
    from .labels import SEGMENT_COLUMNS, recording_labels, segment_summary
    from .pellets import JAW_PELLETS, pellet_index

    recording = load_item(item, quiet=True)
    track = recording.track
    fit = fit_jaw_bucketed(track, method=method, solver=solver, smoothness=smoothness,
                           jaw_sensors=jaw_sensors)
    found = recording_labels(recording) if labels else None  # beside the file or inside it
    out = jaw_output_path(out_dir, item)
    outputs = [atomic_write(out, jaw_frame_csv(track.times, fit, found,
                                               track.mistracks.frame_labels()),
                            overwrite=overwrite)]
    label_file = ""
    if found is not None:
        label_file = found.path.name if found.path is not None else ""
        rows = segment_summary(track.times, fit.theta, track.positions, found,
                               usable=fit.status == int(Status.OK))
        outputs.append(atomic_write(segments_output_path(out_dir, item),
                                    csv_text(rows, SEGMENT_COLUMNS), overwrite=overwrite))
    current = track.positions[:, [pellet_index(p) for p in JAW_PELLETS]]
    return TaskResult(jaw_summary_row(fit, label_file=label_file, current=current),
                      tuple(str(p) for p in outputs))


def jaw_corpus_path(out_dir: str | os.PathLike) -> Path:
    """``out_dir/jaw_corpus.csv`` (and ``.parquet`` beside it)."""
    return Path(out_dir) / "jaw_corpus.csv"


def jaw_corpus(
    dataset: Dataset | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    method: str | None = None,
    solver: str | None = None,
    smoothness: float = 1.0,
    jaw_sensors: str | None = None,
    labels: bool = True,
    subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None,
    **run_options: Any,
) -> tuple[CorpusRun, list[Path]]:
    """``cassi jaw DATASET --out DIR``: :func:`jaw_task` on every recording (float64, as
    the single-recording command), then the corpus table ``DIR/jaw_corpus.csv`` (and
    ``.parquet``). ``run_options`` go to :func:`cassi_fit.corpus.run_corpus` (``jobs``,
    ``scheduler``, ``executor``, ``resume``, ``overwrite``, ``progress``,
    ``compilation_cache``). ``solver``: None for the method's own; ``jaw_sensors``: both,
    or one (``"MNI"``, ``"MNM"``), or None (the default) for the jaw pellets each recording
    has; ``method`` None: the closed form with two jaw sensors, coupled-rotation with one.
    Returns the run (``run.failed``: exit non-zero) and the table files written. A method
    that cannot run with the sensors given is refused before the run."""
    replace = bool(run_options.get("overwrite") or run_options.get("resume"))
    table = jaw_corpus_path(out_dir)
    if table.exists() and not replace:  # refuse before the run, not after it
        raise OutputExistsError(f"{table}: file exists (pass overwrite=True / --force, or "
                                "resume=True / --resume)")
    from .jaw_fit import check_sensors, jaw_method, jaw_sensor_set

    sensors = None if jaw_sensors is None else ",".join(jaw_sensor_set(jaw_sensors))
    if method is not None:  # checked here (the name, its options) rather than per recording
        chosen = jaw_method(method, solver=solver, smoothness=smoothness)
        if sensors is not None:
            check_sensors(chosen, jaw_sensor_set(sensors))
    run_options.setdefault("x64", True)  # pivots to a micrometre need float64 (cassi jaw)
    run_options.setdefault("desc", "jaw")
    options = {"method": method, "solver": solver, "labels": bool(labels),
               "jaw_sensors": sensors}
    if method == "smooth-pivot":
        options["smoothness"] = float(smoothness)
    items = require_items(dataset_items(dataset, subjects=subjects, tasks=tasks), dataset,
                          subjects, tasks)
    run = run_corpus(jaw_task, items, out_dir, options=options, **run_options)
    written = write_table(run.rows(), table, overwrite=replace)
    return run, written
