"""The one runner: a recording and a :class:`~cassi_fit.run_spec.RunSpec` in, the fitted
subject and its animation out.

A recording's path through the toolkit, stage by stage, each stage one module entered
once (docs/ARCHITECTURE.md): load (:mod:`cassi_fit.dataset`, with the data layer's readers
and the mistrack detector), :func:`cassi_fit.initialize.initialize` (the subject's model,
CASSI's initialization), :func:`cassi_fit.animate.animate` (every frame; the jaw method of
:mod:`cassi_fit.jaw_fit` inside), then an output stage: a video
(:func:`cassi_fit.recording_video.write_recording_video`), an export (:mod:`cassi_fit.export`) or the
evaluation's measures (:mod:`cassi_fit.evaluate`). :func:`run_recording` runs the stages a
command needs (:data:`ANIMATE`: initialize and animate; :data:`JAW`: the jaw fit alone);
every command (``cassi animate``, ``export``, ``evaluate``, ``demo``, ``jaw``), the corpus
tasks and the Python API call it, so they cannot drift apart.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

from .errors import InvalidChoiceError
from .run_spec import RunSpec, run_spec

if TYPE_CHECKING:  # the stages' modules are imported by the stages run (cassi jaw: no model)
    from .animate import Animation
    from .dataset import Recording
    from .face_model import FaceModel
    from .initialize import SubjectState
    from .jaw_fit import JawFit


#: The stages :func:`run_recording` can run: ``"initialize"`` (the subject's model),
#: ``"animate"`` (every frame; needs ``"initialize"``) and ``"jaw"`` (the jaw fit on the
#: recording's own pellets, ``cassi jaw``'s: no model).
STAGES = ("initialize", "animate", "jaw")
#: What a command that draws or measures the face runs (the default).
ANIMATE = ("initialize", "animate")
#: What ``cassi jaw`` runs.
JAW = ("jaw",)


class RecordingRun(NamedTuple):
    """One recording run: the ``recording``, its ``spec`` (the calibration resolved for the
    subject is ``state.calibration``), the fitted subject ``state``, the ``animation`` and
    the ``jaw`` fit (a ``jaw_fit.JawFit`` on the recording's pellets); a stage not run
    leaves its field None."""

    recording: Recording
    spec: RunSpec
    state: SubjectState | None = None
    animation: Animation | None = None
    jaw: JawFit | None = None


def fit_recording_jaw(recording: Recording, spec: RunSpec) -> JawFit:
    """The ``"jaw"`` stage: ``jaw_fit.jaw_from_track`` on the recording's pellet track
    (the reference: its first line with the jaw sensors tracked and not mistracked), by
    the spec's jaw method on the spec's jaw sensors (default: those the recording
    tracks, and the method ``RunSpec.jaw_method_for`` them), padded to a frame bucket
    as every jaw fit is (``jaw_fit.jaw_bucket``: recordings of different lengths share one
    compilation)."""
    from .jaw_fit import jaw_from_track, tracked_jaw_sensors

    track = recording.track
    sensors = spec.jaw_sensors or tracked_jaw_sensors(track.valid, track.path)
    return jaw_from_track(track, method=spec.jaw_method_for(sensors), jaw_sensors=sensors)


def run_recording(
    recording: Recording,
    spec: RunSpec | str | None = None,
    *,
    stages: tuple[str, ...] = ANIMATE,
    model: FaceModel | None = None,
    **changes: Any,
) -> RecordingRun:
    """Run ``stages`` (:data:`STAGES`; default :data:`ANIMATE`) of ``recording`` as
    ``spec`` says (a :class:`RunSpec`, a preset's name ``"improved"``/``"cassi"``, or
    None for ``"improved"``; ``changes``: fields to change, e.g.
    ``calibration="calibration/"``, ``collisions="project"``, ``jaw=SmoothPivot()``,
    ``stride=5``): initialize the face to the recording's subject, animate it over every
    ``stride``-th data line, fit the jaw on the pellets. The spec is checked once, here;
    with ``spec.x64`` the stages compute in float64 (``jax.enable_x64``, for this call
    only; without, JAX's setting stays as it is). ``model``: the face model (default ``load_model()``). Returns a
    :class:`RecordingRun`."""
    import contextlib

    import jax

    spec = run_spec(spec, **changes)
    unknown = [s for s in stages if s not in STAGES]
    if unknown or ("animate" in stages and "initialize" not in stages):
        raise InvalidChoiceError(f"stages must be among {', '.join(STAGES)}, animate with "
                                 f"initialize; got {', '.join(stages)}")
    state = animation = jaw = None
    with jax.enable_x64(True) if spec.x64 else contextlib.nullcontext():
        if "initialize" in stages:
            from .initialize import initialize

            state = initialize(recording, model, spec=spec)
        if "animate" in stages:
            from .animate import animate

            animation = animate(state, recording)
        if "jaw" in stages:
            jaw = fit_recording_jaw(recording, spec)
    return RecordingRun(recording, spec, state, animation, jaw)
