"""The synthetic corpus's task library, under its old name.

The library now lives in the synth package (``cassi_fit.synth._tasks``, its public names
re-exported from :mod:`cassi_fit.synth`); this module keeps ``from cassi_fit.synth_tasks
import TASKS`` working for code written before the split.
"""

from __future__ import annotations

from .synth._tasks import (
    CONTROLS,
    DEFAULT_TASKS,
    JAW_WAGGING_TASK,
    SENTENCE_TASK,
    TASKS,
    TaskSpec,
    UnknownTaskError,
    control_trajectories,
    get_task,
    task_duration,
)

__all__ = [
    "CONTROLS",
    "DEFAULT_TASKS",
    "JAW_WAGGING_TASK",
    "SENTENCE_TASK",
    "TASKS",
    "TaskSpec",
    "UnknownTaskError",
    "control_trajectories",
    "get_task",
    "task_duration",
]
