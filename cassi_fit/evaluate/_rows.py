"""Evaluation rows as typed records: one per recording, one per subject, and the result.

A row's ``status`` is a :class:`cassi_fit.status.Status`: ``OK`` (measured and rated) or
``FAILED`` (not rated; the one-line reason in ``error``: for a recording its error, for a
subject :data:`NO_RECORDING`). Tables print the status word (``Status.label``) and the
error in a column of its own.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from ..errors import CassiError
from ..status import Status
from ._measures import combine
from ._ratings import COMPONENTS, RATINGS, rate

#: The reason a subject is not rated when none of its recordings could be evaluated.
NO_RECORDING = "no recording evaluated"


def _check_status(status: Status, error: str) -> None:
    """OK rows carry no error; FAILED rows carry their one-line reason."""
    if status is Status.OK and error:
        raise CassiError(f"an evaluated row carries an error: {error!r}")
    if status is Status.FAILED and not error:
        raise CassiError("a failed row needs its one-line error")
    if status not in (Status.OK, Status.FAILED):
        raise CassiError(f"an evaluation row is OK or FAILED, not {status.label}")


@dataclass(frozen=True)
class RecordingRow:
    """One recording's evaluation. ``frames``: animated frames (0 if it failed);
    ``stride``, ``jaw``, ``collisions``: the animation's settings; ``calibration``: its label
    (``"default"``, ``"cassi"``, ``"calibrated"``); ``measures``: name -> value (units in
    ``MEASURES``); ``problems``: component (and ``"not_counted"``) -> problem names;
    ``ratings``: component -> word. The dicts are empty when the row failed; treat them as
    read-only."""

    subject: str
    task: str
    status: Status
    frames: int
    stride: int
    jaw: str
    calibration: str
    collisions: str
    measures: dict[str, float] = field(default_factory=dict)
    problems: dict[str, list[str]] = field(default_factory=dict)
    ratings: dict[str, str] = field(default_factory=dict)
    error: str = ""

    def __post_init__(self) -> None:
        _check_status(self.status, self.error)

    @classmethod
    def evaluated(
        cls, subject: str, task: str, measures: Mapping[str, float], *, frames: int,
        stride: int, jaw: str, calibration: str, collisions: str,
    ) -> RecordingRow:
        """An OK row: ``measures`` counted and rated (``rate``)."""
        found, ratings = rate(measures)
        return cls(subject, task, Status.OK, frames, stride, jaw, calibration, collisions,
                   dict(measures), found, ratings)

    @classmethod
    def not_evaluated(
        cls, subject: str, task: str, error: str, *, stride: int, jaw: str, calibration: str,
        collisions: str,
    ) -> RecordingRow:
        """A FAILED row (0 frames, not rated) with its one-line ``error``."""
        return cls(subject, task, Status.FAILED, 0, stride, jaw, calibration, collisions,
                   error=error)

    @property
    def rated(self) -> bool:
        return self.status is Status.OK


@dataclass(frozen=True)
class SubjectRow:
    """One subject: its recordings' measures combined (``combine``), counted and rated.
    ``tasks``: the evaluated tasks, space-separated; ``recordings``/``failed``: how many
    were evaluated / not; ``calibration``: the evaluated recordings' labels joined by
    ``/`` (empty when none was evaluated); other fields as :class:`RecordingRow`."""

    subject: str
    tasks: str
    recordings: int
    failed: int
    status: Status
    stride: int
    jaw: str
    calibration: str
    collisions: str
    measures: dict[str, float] = field(default_factory=dict)
    problems: dict[str, list[str]] = field(default_factory=dict)
    ratings: dict[str, str] = field(default_factory=dict)
    error: str = ""

    def __post_init__(self) -> None:
        _check_status(self.status, self.error)

    @classmethod
    def of_recordings(
        cls, subject: str, rows: Sequence[RecordingRow], *, stride: int, jaw: str,
        collisions: str,
    ) -> SubjectRow:
        """The subject's row from its recordings' (FAILED, ``NO_RECORDING``, if none of
        them was evaluated)."""
        ok = [r for r in rows if r.rated]
        common = dict(subject=subject, tasks=" ".join(r.task for r in ok), recordings=len(ok),
                      failed=len(rows) - len(ok), stride=stride, jaw=jaw,
                      collisions=collisions)
        if not ok:
            return cls(**common, status=Status.FAILED, calibration="", error=NO_RECORDING)
        measures = combine([r.measures for r in ok])
        found, ratings = rate(measures)
        return cls(**common, status=Status.OK,
                   calibration="/".join(sorted({r.calibration for r in ok})),
                   measures=measures, problems=found, ratings=ratings)

    @property
    def rated(self) -> bool:
        return self.status is Status.OK


@dataclass
class EvaluationResult:
    """Rows of ``evaluate_dataset``: ``recordings`` (one per file, failed ones with status
    ``FAILED`` and no ratings) and ``subjects`` (combined measures, problems and ratings per
    subject), plus the ``settings`` used (``calibration``, ``collisions``, ``jaw``,
    ``stride``)."""

    recordings: list[RecordingRow]
    subjects: list[SubjectRow]
    settings: dict[str, object] = field(default_factory=dict)

    def totals(self) -> dict[str, tuple[int, ...]]:
        """Per component, the number of rated subjects per rating (``RATINGS`` order)."""
        rated = [s for s in self.subjects if s.rated]
        return {c: tuple(sum(s.ratings[c] == r for s in rated) for r in RATINGS)
                for c in COMPONENTS}

    @property
    def failed(self) -> list[RecordingRow]:
        """The recordings not evaluated."""
        return [r for r in self.recordings if not r.rated]
