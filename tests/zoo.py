"""The shared zoo of synthetic subjects for every test file.

Import it from a test module (``tests/`` is on ``sys.path`` under pytest)::

    import zoo

    def test_something():
        track, truth = zoo.recording("tp106")          # in memory, cached
        anatomy = zoo.subject(0)

    @pytest.fixture(scope="session")
    def corpus(tmp_path_factory):
        return zoo.small_corpus(tmp_path_factory)       # written once per session

Everything is deterministic (fixed seeds) and cheap; results are cached per process, so
treat the returned arrays as read-only.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from cassi_fit import synth

JAW_WAGGING = synth.JAW_WAGGING_TASK  # "tp106", wide rotations (about 20-25 degrees)
SENTENCE = synth.SENTENCE_TASK  # "tp040", speech-sized rotations (about 2-8 degrees)
SMALL_CORPUS_TASKS = ("tp106", "tp040", "tp020_2")


@functools.cache
def subject(index: int = 0, seed: int = 0) -> synth.SubjectAnatomy:
    """The anatomy of subject ``S{index + 1:02d}`` exactly as in a corpus of that seed."""
    name = synth.subject_names(index + 1)[index]
    return synth.make_subject(name, np.random.default_rng([seed, 1, index]))


@functools.cache
def recording(
    task: str = SENTENCE,
    subject_index: int = 0,
    seed: int = 0,
    *,
    noise_mm: float = synth.DEFAULT_NOISE_MM,
    clean: bool = False,
):
    """``(PelletTrack, JawTruth)`` of one synthetic recording, in memory.

    With the defaults it is the same recording a corpus of ``seed`` holds. ``clean=True``
    drops the dropouts and mistracks (leading untracked rows stay, as in every real
    file); ``noise_mm=0`` gives noise-free pellets (rounded to 1 um).
    """
    seed_seq = synth._recording_seed(seed, subject_index, task)
    return synth.synth_recording(
        subject(subject_index, seed),
        task,
        seed=seed_seq,
        noise_mm=noise_mm,
        dropouts=not clean,
        mistracks=not clean,
    )


def jaw_wagging(subject_index: int = 0, **kwargs):
    """``(track, truth)`` of the jaw-wagging task (large rotations)."""
    return recording(JAW_WAGGING, subject_index, **kwargs)


def sentence(subject_index: int = 0, **kwargs):
    """``(track, truth)`` of the sentence task (speech-sized rotations)."""
    return recording(SENTENCE, subject_index, **kwargs)


def true_jaw_pellets(truth) -> np.ndarray:
    """``(n, 2, 2)`` mm, noise-free MNI and MNM (jaw point order of the jaw code)."""
    return truth.pellets_true[:, 6:8, :]


_CORPORA: dict[tuple, Path] = {}


def small_corpus(tmp_path_factory, n_subjects: int = 2, tasks=SMALL_CORPUS_TASKS, seed: int = 0):
    """A corpus folder written once per test session (per argument set): ``Path``.

    Subject S01 has upper-case file names, S02 lower-case; every task has its truth
    sidecar, speech tasks a ``.wav``. Do not write into it.
    """
    key = (n_subjects, tuple(tasks), seed)
    if key not in _CORPORA:
        out = tmp_path_factory.mktemp("synthetic_corpus")
        _CORPORA[key] = synth.generate_corpus(out, n_subjects=n_subjects, seed=seed, tasks=tasks)
    return _CORPORA[key]


def synthetic_mview(tmp_path_factory, sensors: str | None = "mocha"):
    """One synthetic mview recording (task tp040, seed 3, no sound), read back with the
    reader's warnings silenced: ``sensors="mocha"`` one jaw sensor and three tongue
    sensors, ``None`` the X-ray microbeam set. An articulograph recording without a palate
    trace or a calibration."""
    import warnings

    from cassi_fit.dataset import load_recording
    from cassi_fit.ema.synthetic import write_ema_corpus

    more = {} if sensors is None else {"sensors": sensors}
    root = write_ema_corpus(tmp_path_factory.mktemp("ema") / "c", format="mview", n_subjects=1,
                            tasks="tp040", seed=3, audio=False, **more)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_recording(next(p for p in root.rglob("*.mat") if "bite" not in p.name))
