"""Running the evaluation: animate each recording, measure and rate it, combine per subject."""

from __future__ import annotations

import numbers
import os
import warnings
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Union

from ..errors import CassiError, MissingDataError
from ..options import COLLISION_MODES, CONFORMATIONS, JAW_METHODS, MODES, check_choice
from ._measures import measure
from ._rows import EvaluationResult, RecordingRow, SubjectRow

if TYPE_CHECKING:
    from ..calibrate import Calibration
    from ..dataset import Dataset, Recording
    from ..face_model import FaceModel

#: What a recording is animated with: ``None`` (the toolkit's conformation from
#: Headmeasures), a conformation name (``"cassi"``: only what the paper did) or a fitted
#: ``Calibration``.
CalibrationChoice = Union[None, str, "Calibration"]


def _calibration_label(calibration: CalibrationChoice, mode: str = "improved") -> str:
    """The word the tables print for ``calibration`` (``"cassi mode"`` in that mode)."""
    if mode == "cassi":
        return "cassi mode"
    if calibration is None:
        return "default"
    if isinstance(calibration, str):
        return calibration
    return "calibrated"


def _check_settings(collisions: str, jaw: str, stride: int) -> None:
    check_choice("collisions", collisions, COLLISION_MODES)
    check_choice("jaw method", jaw, JAW_METHODS)
    if isinstance(stride, bool) or not isinstance(stride, numbers.Integral) or stride < 1:
        raise CassiError(f"stride must be an integer of at least 1, got {stride!r}")


def evaluate_recording(
    recording: Recording,
    *,
    calibration: CalibrationChoice = None,
    collisions: str = "off",
    jaw: str = "closed-form",
    stride: int = 1,
    model: FaceModel | None = None,
    mode: str = "improved",
) -> RecordingRow:
    """Animate one recording and rate it: an OK :class:`RecordingRow`.

    ``calibration``: None (the toolkit's conformation from Headmeasures), ``"cassi"``
    (only what the paper did) or a ``calibrate.Calibration``; ``collisions``: ``"off"``
    or ``"project"`` (``options.COLLISION_MODES``); ``jaw`` (``options.JAW_METHODS``),
    ``stride``: as ``animate.animate``; ``mode``: ``options.MODES`` (``"cassi"``: every
    choice of the paper, ``initialize.CASSI``: flat tongue, fixed back anchors, no lip
    rounding, the paper's conformation; then ``calibration`` must be None and
    ``collisions`` ``"off"``). Errors propagate (``CassiError``).
    """
    from ..animate import animate
    from ..initialize import initialize

    _check_settings(collisions, jaw, stride)
    _check_mode(mode, calibration, collisions)
    if isinstance(calibration, str):
        check_choice("calibration", calibration, CONFORMATIONS)
    state = initialize(recording, model, calibration=calibration, mode=mode)
    anim = animate(state, recording, jaw=jaw, stride=stride, collisions=collisions)
    return RecordingRow.evaluated(
        recording.subject, recording.task, measure(state, anim), frames=int(anim.n_frames),
        stride=int(stride), jaw=jaw, calibration=_calibration_label(calibration, mode),
        collisions=collisions)


def _check_mode(mode: str, calibration: object, collisions: str) -> None:
    check_choice("mode", mode, MODES)
    if mode == "cassi" and (calibration not in (None, "cassi") or collisions != "off"):
        raise CassiError("the cassi mode is the paper's: no calibration and no collision "
                         "handling")


def _calibration_for(
    calibrations: None | str | Mapping[str, Calibration], subject: str
) -> CalibrationChoice:
    if calibrations is None or isinstance(calibrations, str):
        return calibrations
    if subject in calibrations:
        return calibrations[subject]
    warnings.warn(f"{subject}: no calibration given; using the default conformation",
                  stacklevel=3)
    return None


def _plan(dataset: Dataset, subjects: Iterable[str] | None,
          tasks: Iterable[str] | None) -> list[tuple[str, str]]:
    """``(subject, task)`` pairs to evaluate, in the dataset's order."""
    names = dataset.subjects() if subjects is None else [str(s).upper() for s in subjects]
    if not names:
        raise MissingDataError(f"{dataset.root}: no recordings found")
    wanted = None if tasks is None else {str(t).lower() for t in tasks}
    plan = []
    for subject in names:
        chosen = [t for t in dataset.tasks(subject) if wanted is None or t in wanted]
        plan += [(subject, t) for t in chosen]
    if not plan:
        raise MissingDataError(
            f"{dataset.root}: none of the tasks {', '.join(sorted(wanted or []))} found for "
            f"{', '.join(names)}"
        )
    return plan


def evaluate_dataset(
    dataset_or_path: Dataset | str | os.PathLike,
    *,
    calibrations: None | str | Mapping[str, Calibration] = None,
    collisions: str = "off",
    tasks: Iterable[str] | None = None,
    subjects: Iterable[str] | None = None,
    progress: bool = True,
    jaw: str = "closed-form",
    stride: int = 1,
    model: FaceModel | None = None,
    mode: str = "improved",
) -> EvaluationResult:
    """Evaluate every recording of a dataset (or the chosen ``subjects``/``tasks``) and
    rate each subject.

    ``calibrations``: None (the default conformation), ``"cassi"`` (CASSI-like, for
    everyone) or a dict subject (upper case) -> ``Calibration`` (a subject missing from it
    gets the default, with a warning). A recording that fails (a ``CassiError``: bad data,
    non-finite geometry) is kept as a ``FAILED`` row with its message and not rated; its
    subject is rated from the others. ``collisions``, ``jaw`` and ``stride`` are checked
    before anything is animated; ``mode``: as :func:`evaluate_recording`. Progress bar
    over the files on stderr (tqdm).
    """
    from tqdm import tqdm

    from ..dataset import Dataset, DefaultHeadMeasuresWarning

    _check_settings(collisions, jaw, stride)
    _check_mode(mode, None if isinstance(calibrations, (str, type(None))) else {}, collisions)
    if isinstance(calibrations, str):
        check_choice("calibrations", calibrations, CONFORMATIONS)
    dataset = dataset_or_path if isinstance(dataset_or_path, Dataset) else Dataset(
        dataset_or_path)
    plan = _plan(dataset, subjects, tasks)
    settings = {"stride": int(stride), "jaw": jaw, "collisions": collisions}
    rows = []
    bar = tqdm(plan, desc="evaluate", unit="file", disable=not progress)
    for subject, task in bar:
        bar.set_postfix_str(f"{subject} {task}")
        calibration = _calibration_for(calibrations, subject)
        try:
            with warnings.catch_warnings():  # the rows name the calibration used
                warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
                recording = dataset.load(subject, task)
            rows.append(evaluate_recording(recording, calibration=calibration,
                                           collisions=collisions, jaw=jaw, stride=stride,
                                           model=model, mode=mode))
        except CassiError as exc:
            rows.append(RecordingRow.not_evaluated(
                subject, task, str(exc), calibration=_calibration_label(calibration, mode),
                **settings))
    planned = list(dict.fromkeys(subject for subject, _ in plan))  # those with chosen tasks
    per_subject = [SubjectRow.of_recordings(s, [r for r in rows if r.subject == s], **settings)
                   for s in planned]
    label = "calibrated" if isinstance(calibrations, Mapping) else _calibration_label(
        calibrations, mode)
    return EvaluationResult(rows, per_subject, {**settings, "calibration": label})
