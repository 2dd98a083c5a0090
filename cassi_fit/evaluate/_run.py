"""Running the evaluation: animate each recording, measure and rate it, combine per subject.

One recording: :func:`evaluate_recording` (``pipeline.run_recording``, then the measures).
A dataset: :func:`evaluate_corpus` runs :func:`evaluate_task` on every recording through
the corpus executor (``cassi evaluate``; one process, many, or a Dask cluster; resumable
with an output folder), and :func:`evaluate_dataset` is the same run in memory with no
output folder: the two differ only in where they run, never in what they choose.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from ..corpus import (
    CorpusItem,
    CorpusResult,
    CorpusRun,
    TaskResult,
    dataset_items,
    load_item,
    require_items,
    run_corpus,
    worker_model,
)
from ..run_spec import CalibrationFiles, RunSpec, run_spec
from ..status import Status
from ._measures import measure
from ._rows import EvaluationResult, RecordingRow, SubjectRow

if TYPE_CHECKING:
    from ..dataset import Dataset, Recording
    from ..face_model import FaceModel

#: The per-recording table's measure columns are ``measure.NAME``.
MEASURE_PREFIX = "measure."


def _spec(spec: RunSpec | None, changes: Mapping[str, Any]) -> RunSpec:
    mode = changes.pop("mode", None) if isinstance(changes, dict) else None
    if spec is not None and mode is not None:
        spec = spec.replace(mode=mode)
    return run_spec(spec if spec is not None else mode, **changes)


def _settings(spec: RunSpec) -> dict:
    return {"stride": spec.stride, "jaw": spec.jaw_name, "collisions": spec.collisions}


def evaluate_recording(
    recording: Recording,
    *,
    spec: RunSpec | None = None,
    model: FaceModel | None = None,
    **changes: Any,
) -> RecordingRow:
    """Animate one recording (``pipeline.run_recording``) and rate it: an OK
    :class:`RecordingRow`.

    ``spec``: the run's ``RunSpec`` (default the ``"improved"`` preset); ``changes``:
    fields of it to change (``calibration=None | "cassi" | Calibration | path``,
    ``collisions="project"``, ``jaw=``, ``stride=``, ``mode="cassi"`` ...). Errors
    propagate (``CassiError``).
    """
    return _evaluate(recording, _spec(spec, dict(changes)), model)[0]


def _evaluate(recording, spec, model):
    """``(RecordingRow, SubjectState)`` of one recording run with ``spec``."""
    from ..pipeline import run_recording

    run = run_recording(recording, spec, model=model)
    settings = {**_settings(spec), "jaw": run.animation.jaw_method}  # the method used
    row = RecordingRow.evaluated(
        recording.subject, recording.task, measure(run.state, run.animation),
        frames=int(run.animation.n_frames),
        calibration=spec.calibration_label(run.state.calibration), **settings)
    return row, run.state


def evaluate_task(item: CorpusItem, out_dir: str | None, *, spec: RunSpec,
                  overwrite: bool = False) -> TaskResult:
    """``cassi evaluate``'s task: animate one recording and measure it
    (:func:`evaluate_recording` with the worker's model). The row holds ``frames``,
    ``calibration`` (its label) and every measure as ``measure.NAME``; ratings are
    derived from the measures afterwards (:func:`evaluation_result`). Writes no file."""
    recording = load_item(item, quiet=True)
    row, state = _evaluate(recording, spec, worker_model())
    out = {"frames": row.frames, "calibration": row.calibration, "jaw": row.jaw,
           "calibration_problems": "; ".join(state.calibration_problems)}
    out.update((MEASURE_PREFIX + k, float(v)) for k, v in sorted(row.measures.items()))
    return TaskResult(out)


def evaluation_result(run: CorpusRun, spec: RunSpec) -> EvaluationResult:
    """The :class:`EvaluationResult` of a run of :func:`evaluate_task`: one
    ``RecordingRow`` per item in the run's sorted order (FAILED ones with their error),
    then each subject's row combined from its recordings in that order."""
    common = _settings(spec)
    rows = []
    for r in run.results:
        s, t = r.item.subject, r.item.task
        if r.status == Status.FAILED:
            rows.append(RecordingRow.not_evaluated(s, t, r.error,
                                                   calibration=spec.calibration_label(),
                                                   **common))
            continue
        measures = {k[len(MEASURE_PREFIX):]: float(v) for k, v in r.row.items()
                    if k.startswith(MEASURE_PREFIX)}
        rows.append(RecordingRow.evaluated(s, t, measures, frames=int(r.row["frames"]),
                                           calibration=r.row["calibration"],
                                           **{**common, "jaw": r.row["jaw"]}))
    subjects = list(dict.fromkeys(r.subject for r in rows))
    per_subject = [SubjectRow.of_recordings(s, [r for r in rows if r.subject == s],
                                            **{**common, "jaw": _jaw_used(rows, s, spec)})
                   for s in subjects]
    return EvaluationResult(rows, per_subject, {**common, "jaw": _jaw_used(rows, None, spec),
                                                "calibration": spec.calibration_label()})


def _jaw_used(rows: Sequence[RecordingRow], subject: str | None, spec: RunSpec) -> str:
    """The jaw methods the evaluated rows (of ``subject``, or all) used, in order of first
    use (the default picks by each recording's jaw sensors); the spec's name if none ran."""
    used = dict.fromkeys(r.jaw for r in rows if r.status != Status.FAILED
                         and (subject is None or r.subject == subject))
    return ", ".join(used) or spec.jaw_name


def _check_calibrations(spec: RunSpec) -> None:
    """Read a folder's calibration files once here, so that a broken one stops the run
    before it starts (instead of failing every recording of its subject); a subject
    without one fails its rows (``RunSpec.calibration_for``)."""
    cal = spec.calibration
    if isinstance(cal, CalibrationFiles) and cal.path.is_dir():
        from ..calibration import load_calibrations

        load_calibrations(cal.path)


def evaluate_corpus(
    dataset: Dataset | str | os.PathLike,
    out_dir: str | os.PathLike | None,
    *,
    spec: RunSpec | None = None,
    subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None,
    run_options: Mapping[str, Any] | None = None,
    **changes: Any,
) -> CorpusResult:
    """``cassi evaluate DATASET``: :func:`evaluate_task` on every recording (the chosen
    ``subjects``/``tasks``, names in any case), combined per subject
    (:func:`evaluation_result`). ``spec``/``changes``: the run (as
    :func:`evaluate_recording`; ``calibration`` may be a folder of ``cassi calibrate``'s
    files or a dict subject -> ``Calibration``: the recordings of a subject without one
    fail, each a row with its one-line error). ``run_options`` go to ``corpus.run_corpus`` (``jobs``,
    ``scheduler``, ``executor``, ``resume``, ``overwrite``, ``progress``, ...).
    Completion markers go to ``out_dir`` (None: none, nothing written); the tables are the
    caller's (``evaluate.write_report``). Returns a ``corpus.CorpusResult`` whose
    ``value`` is the :class:`EvaluationResult` (``tables`` empty)."""
    spec = _spec(spec, dict(changes))
    items = require_items(dataset_items(dataset, subjects=subjects, tasks=tasks), dataset,
                          subjects, tasks)
    _check_calibrations(spec)
    options = dict(run_options or {})
    options.setdefault("desc", "evaluate")
    run = run_corpus(evaluate_task, items, out_dir, options={"spec": spec}, **options)
    return CorpusResult(run, [], evaluation_result(run, spec))


def evaluate_dataset(
    dataset: Dataset | str | os.PathLike,
    *,
    spec: RunSpec | None = None,
    subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None,
    progress: bool = True,
    model: FaceModel | None = None,
    **changes: Any,
) -> EvaluationResult:
    """:func:`evaluate_corpus` in this process with no output folder: every recording of
    a dataset (or the chosen ``subjects``/``tasks``) evaluated and each subject rated. A
    recording that fails is kept as a ``FAILED`` row with its one-line error and not
    rated; its subject is rated from the others. ``model``: the face model to use
    (default the worker's, ``load_model()``)."""
    if model is not None:
        from ..corpus import use_model

        with use_model(model):
            return evaluate_dataset(dataset, spec=spec, subjects=subjects, tasks=tasks,
                                    progress=progress, **changes)
    return evaluate_corpus(dataset, None, spec=spec, subjects=subjects, tasks=tasks,
                           run_options={"jobs": 1, "progress": progress}, **changes).value
