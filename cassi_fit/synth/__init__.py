"""A synthetic XRMB corpus with ground truth: subjects, kinematics, measurement, files.

The real X-ray microbeam database is distributed on request only; this package makes a
stand-in whose truth is known. One module per stage, each a plain function:

1. anatomy (``_anatomy``, :func:`make_subject`): a subject's palate, jaw pellet spacing,
   condyle, lips, tongue rest positions, head measures, all in the pellet frame (mm),
   drawn from anthropometric norms (``NORMS``), never from the face model's numbers;
2. tasks (``_tasks``, :data:`TASKS`): what each task asks the articulators to do, as
   control curves on the frame grid;
3. kinematics (``_kinematics``): the control curves move a rigid mandible,
   ``p' = R p + t`` (paper Eqs 4-5), as the subject's jaw-kinematics family says
   (:data:`JAW_KINEMATICS`: rotation about a fixed condyle; the physiological glide of the
   condyle along a curved eminence, coupled to the rotation; rotation plus an independent,
   jumping protrusion); the lower lip and tongue partly carried by it and partly on their
   own, the tongue kept below the palate;
4. measurement (``_measurement``, :func:`synth_recording`): noise of one of
   :data:`NOISE_FAMILIES` per pellet, all-untracked leading rows, dropouts (1000000) and a
   few unmarked mistracks, all recorded in the truth;
5. audio (``_audio``, :func:`synth_audio`): a buzz that follows the articulators;
6. truth files (``_truth``): the ground-truth sidecar per recording and ``anatomy.json``
   per subject;
7. files and the cache (``_corpus``, :func:`generate_corpus`,
   :func:`ensure_default_corpus`): the real formats through the toolkit's writers, plus
   the truth files; :func:`load_truth` and :func:`load_anatomy` read them back.

Everything is deterministic from the seed. See ``docs/SYNTHETIC.md``.
"""

from __future__ import annotations

from ._anatomy import (
    DEFAULT_JAW_KINEMATICS_CYCLE,
    JAW_KINEMATICS,
    NORMS,
    PELLETS,
    SubjectAnatomy,
    default_jaw_kinematics,
    make_subject,
)
from ._audio import AUDIO_RATE_HZ, synth_audio
from ._corpus import (
    COMPLETE_LINE,
    DEFAULT_CORPUS_SEED,
    GENERATOR_VERSION,
    corpus_status,
    default_corpus_dir,
    ensure_default_corpus,
    generate_corpus,
    load_anatomy,
    load_truth,
    subject_names,
)
from ._corpus import _recording_seed as _recording_seed
from ._foreign import foreign_data, refuse_foreign_data
from ._kinematics import (
    FRAME_STEP_S,
    JawTruth,
    condyle_offset,
    condyle_slide_mm,
    eminence_path,
    speech_protrusion_mm,
    thrust_protrusion_mm,
)
from ._kinematics import _jaw_motion as _jaw_motion
from ._measurement import (
    DEFAULT_NOISE_MM,
    MAX_NOISE_SCALE,
    NOISE_FAMILIES,
    XRMB_NOISE_MM,
    synth_recording,
)
from ._tasks import (
    CONTROLS,
    DEFAULT_TASKS,
    JAW_WAGGING_TASK,
    SENTENCE_TASK,
    TASKS,
    TaskSpec,
    UnknownTaskError,
    get_task,
)
from ._truth import TRUTH_COLUMNS

__all__ = [
    "SubjectAnatomy",
    "JawTruth",
    "TASKS",
    "TaskSpec",
    "DEFAULT_TASKS",
    "JAW_WAGGING_TASK",
    "SENTENCE_TASK",
    "DEFAULT_NOISE_MM",
    "GENERATOR_VERSION",
    "make_subject",
    "synth_recording",
    "synth_audio",
    "generate_corpus",
    "foreign_data",
    "refuse_foreign_data",
    "load_truth",
    "load_anatomy",
    "JAW_KINEMATICS",
    "DEFAULT_JAW_KINEMATICS_CYCLE",
    "NOISE_FAMILIES",
    "MAX_NOISE_SCALE",
    "XRMB_NOISE_MM",
    "NORMS",
    "COMPLETE_LINE",
    "default_jaw_kinematics",
    "eminence_path",
    "condyle_slide_mm",
    "thrust_protrusion_mm",
    "speech_protrusion_mm",
    "condyle_offset",
    "corpus_status",
    "default_corpus_dir",
    "ensure_default_corpus",
    # importable before the split too, though not listed then
    "PELLETS",
    "FRAME_STEP_S",
    "AUDIO_RATE_HZ",
    "CONTROLS",
    "TRUTH_COLUMNS",
    "DEFAULT_CORPUS_SEED",
    "subject_names",
    "get_task",
    "UnknownTaskError",
]
# ``_recording_seed`` and ``_jaw_motion`` stay importable for the tests that reuse them.
