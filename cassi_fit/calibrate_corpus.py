"""``cassi calibrate DATASET``: the calibration of every subject, on the corpus executor.

:func:`calibrate_task` calibrates one subject (``calibrate.calibrate_subject``) and writes
its ``SUBJECT.calibration.json``; :func:`calibrate_corpus` runs it over a dataset's
subjects (in this process, local processes or a Dask cluster; resumable) and writes the
summary and corpus tables. Tasks are chosen by ``corpus.chosen_tasks``, the one rule of
every dataset run.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from .calibrate import calibrate_subject, write_summary
from .calibration import (
    CalibrationWarning,
    calibration_path,
    read_calibration,
    write_calibration,
)
from .corpus import (
    CorpusItem,
    CorpusResult,
    TaskResult,
    chosen_tasks,
    dataset_items,
    refuse_existing,
    replaces,
    require_items,
    run_corpus,
    worker_model,
    write_table,
)
from .dataset import Dataset
from .errors import MissingDataError
from .options import CALIBRATION_METHODS, check_choice
from .status import Status


def calibrate_task(item: CorpusItem, out_dir: str, *, tasks: Sequence[str] | None = None,
                   method: str = "separate", collisions: bool = True,
                   overwrite: bool = False) -> TaskResult:
    """``cassi calibrate``'s task, per subject (``item.task == ""``): calibrate the
    subject from ``tasks`` (default: all its recordings) with the worker's model and write
    ``out_dir/SUBJECT.calibration.json``. Row: method, scale, lip thicknesses, face width
    (mm), convergence."""
    ds = item.dataset()
    wanted = chosen_tasks(ds, item.subject, tasks)
    if not wanted:
        raise MissingDataError(f"{ds.root}: subject {item.subject} has none of the tasks "
                               f"{', '.join(tasks or [])}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        recordings = [ds.load(item.subject, t) for t in wanted]
    with warnings.catch_warnings():  # the row carries the problems; a worker's raw warning
        warnings.simplefilter("ignore", CalibrationWarning)  # would only repeat them
        cal = calibrate_subject(recordings, worker_model(), method=method,
                                collisions=collisions)
    path = write_calibration(calibration_path(out_dir, item.subject), cal, overwrite=overwrite)
    row = {"method": cal.method, "recordings": len(recordings), "scale": float(cal.scale),
           "upper_lip_thickness_mm": float(cal.upper_lip_thickness),
           "lower_lip_thickness_mm": float(cal.lower_lip_thickness),
           "face_width_mm": float(cal.face_width), "converged": bool(cal.converged),
           "problems": "; ".join(cal.problems())}
    return TaskResult(row, (str(path),))


def calibrate_corpus(
    dataset: Dataset | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None,
    run_options: Mapping[str, Any] | None = None,
    method: str = "separate",
    collisions: bool = True,
) -> CorpusResult:
    """``cassi calibrate DATASET``: :func:`calibrate_task` per subject (float64), then
    ``out_dir/calibration_summary.csv`` (the calibrated subjects, read back from their
    files in sorted order) and ``out_dir/calibration_corpus.csv`` (every subject, failed
    ones with their error; and ``.parquet``). ``run_options`` go to
    ``corpus.run_corpus``. Returns a ``corpus.CorpusResult`` whose ``value`` is
    ``{subject: Calibration}``."""
    run_options = dict(run_options or {})
    check_choice("calibration method", method, CALIBRATION_METHODS)
    out = Path(out_dir)
    summary, table = out / "calibration_summary.csv", out / "calibration_corpus.csv"
    refuse_existing([summary, table], run_options)
    run_options.setdefault("x64", True)  # calibration residuals are sub-millimetre
    run_options.setdefault("desc", "calibrate")
    options = {"tasks": None if tasks is None else tuple(sorted(str(t).lower() for t in tasks)),
               "method": method, "collisions": bool(collisions)}
    items = dataset_items(dataset, subjects=subjects, per_subject=True)
    require_items(items, dataset, subjects, tasks)
    run = run_corpus(calibrate_task, items, out, options=options, **run_options)
    cals = {r.item.subject: read_calibration(calibration_path(out, r.item.subject))
            for r in run.results if r.status == Status.OK}
    written = [write_summary(summary, cals, overwrite=replaces(run_options))]
    written += write_table(run.rows(), table, overwrite=replaces(run_options))
    return CorpusResult(run, written, cals)
