"""The one runner: a recording and a :class:`~cassi_fit.run_spec.RunSpec` in, the fitted
subject and its animation out.

A recording's path through the toolkit, stage by stage, each stage one module entered
once (docs/ARCHITECTURE.md): load (:mod:`cassi_fit.dataset`, with the data layer's readers
and the mistrack detector), :func:`cassi_fit.initialize.initialize` (the subject's model,
CASSI's initialization), :func:`cassi_fit.animate.animate` (every frame; the jaw method of
:mod:`cassi_fit.jaw_fit` inside), then an output stage: a video
(:func:`cassi_fit.recording_video.write_recording_video`), an export (:mod:`cassi_fit.export`) or the
evaluation's measures (:mod:`cassi_fit.evaluate`). :func:`run_recording` runs the two
pipeline stages; every command (``cassi animate``, ``export``, ``evaluate``, ``demo``), the
corpus tasks and the Python API call it, so they cannot drift apart.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

from .animate import Animation, animate
from .initialize import SubjectState, initialize
from .run_spec import RunSpec, run_spec

if TYPE_CHECKING:
    from .dataset import Recording
    from .face_model import FaceModel


class RecordingRun(NamedTuple):
    """One recording run: the ``recording``, its ``spec`` (the calibration resolved for the
    subject is ``state.calibration``), the fitted subject ``state`` and the ``animation``."""

    recording: Recording
    spec: RunSpec
    state: SubjectState
    animation: Animation


def run_recording(
    recording: Recording,
    spec: RunSpec | str | None = None,
    *,
    model: FaceModel | None = None,
    **changes: Any,
) -> RecordingRun:
    """Initialize the face to ``recording``'s subject and animate it over every
    ``stride``-th data line, as ``spec`` says (a :class:`RunSpec`, a preset's name
    ``"improved"``/``"cassi"``, or None for ``"improved"``; ``changes``: fields to change,
    e.g. ``calibration="calibration/"``, ``collisions="project"``, ``jaw=SmoothPivot()``,
    ``stride=5``). The spec is checked once, here. ``model``: the face model (default
    ``load_model()``). Returns a :class:`RecordingRun`."""
    spec = run_spec(spec, **changes)
    state = initialize(recording, model, spec=spec)
    return RecordingRun(recording, spec, state, animate(state, recording))
