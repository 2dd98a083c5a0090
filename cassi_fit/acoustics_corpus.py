"""``cassi acoustics DATASET --out DIR``: the model's formants against the sound over a
whole dataset, in parallel, and the tables a researcher reads across its speakers.

Every recording is heard as ``cassi acoustics RECORDING`` hears it (:func:`hear`, the one
path of both): the pellets drive the model (``pipeline.run_recording`` with the run's
spec), the subject's acoustic calibration gives the vocal tract where ``--calibration``
holds one (``SUBJECT.acoustic.json``; a folder holding only that keeps the face's default
calibration, as one recording does), and the labels beside the file or inside it say which
frames are vowels (:func:`~cassi_fit.acoustics.is_vowel`). Per recording,
``DIR/SUBJECT/TASK.acoustics.csv`` (every frame) and ``TASK.acoustics.segments.csv`` (every
vowel segment, when there is one); over the dataset:

* ``acoustics_recordings.csv``: one row per recording (failed ones with their one-line
  error; a recording with nothing to score says why in ``note``): frames, vowel frames,
  the share of them scored, the norms heard with, and the median over its vowel segments
  of |F1-F3 error|;
* ``acoustics_segments.csv``: every vowel segment of every recording, with its subject,
  task and vowel quality (the label without length marks and stress digits);
* ``acoustics_summary.csv`` (and ``.md``): per subject and vowel quality, then per subject
  over all its qualities (quality ``all``): segments, scored frames, and the median over
  the segments of the signed and of the absolute relative error (model / measured - 1) of
  F1-F3. Each subject's figures come from its own recordings: one speaker's, say so.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

RECORDINGS_NAME = "acoustics_recordings.csv"
SEGMENTS_NAME = "acoustics_segments.csv"
SUMMARY_NAME = "acoustics_summary.csv"
#: The per-recording tables' suffixes, beside each other in ``DIR/SUBJECT/``.
FRAMES_SUFFIX = ".acoustics.csv"
SEGMENTS_SUFFIX = ".acoustics.segments.csv"
FORMANTS = ("F1", "F2", "F3")
#: Decimals in the segment tables: 3 (Hz, s), 4 for the relative errors (0.01 %), so the
#: dataset's medians, read back from them, are not moved by the rounding.
ERROR_DIGITS = {"start_s": 3, "end_s": 3, **{f"{f}_{c}": 3 for f in FORMANTS
                                             for c in ("model_hz", "measured_hz")},
                **{f"{f}_error": 4 for f in FORMANTS}}


class Heard(NamedTuple):
    """:func:`hear`'s answer: the ``run`` (``pipeline.RecordingRun``), its ``acoustics``
    (``acoustics.Acoustics``), the calibrated ``larynx`` in words (None: the norms) and the
    ``notes`` a command prints (what the calibration folder lacked)."""

    run: Any
    acoustics: Any
    larynx: str | None
    notes: tuple[str, ...]


def hear(recording: Any, spec: Any, *, labels: Any = None, samples=None, rate_hz=None,
         speaker: str | None = None, ceiling_hz: float | None = None,
         model: Any = None, say: Callable[[str], Any] | None = None) -> Heard:
    """One recording heard as ``cassi acoustics`` hears it: run with ``spec`` (a
    ``run_spec.RunSpec``; where its calibration names a folder or a file in it, the
    subject's acoustic calibration there, ``SUBJECT.acoustic.json``, gives the vocal
    tract, and a folder without the subject's face calibration runs the face with the
    default one, said in a note), heard with ``speaker``'s norms and Praat's
    ``ceiling_hz`` (``acoustics.recording_acoustics``); ``labels`` and the sound default to
    the recording's own. ``notes``: what the calibration folder lacked and what the model
    took without knowing it (``calibration: ...``, the run's caveats: a palate estimated,
    the lips' rest), each also given to ``say`` as soon as it is known (before the
    acoustics, which may fail)."""
    from .acoustic_fit import calibrated_tract, face_calibration
    from .acoustics import recording_acoustics
    from .pipeline import run_recording
    from .run_spec import CalibrationFiles

    notes, found = [], None
    if isinstance(spec.calibration, CalibrationFiles):
        found = calibrated_tract(spec.calibration.path, recording.subject)
        spec, note = face_calibration(spec, recording.subject)
        notes += [line for line in (found.missing(recording.subject), note) if line]
    run = run_recording(recording, spec, **({} if model is None else {"model": model}))
    notes += [f"calibration: {line}" for line in run.state.calibration_caveats]
    for line in notes if say is not None else ():
        say(line)
    tract = None if found is None else found.tract
    result = recording_acoustics(run, samples=samples, rate_hz=rate_hz, labels=labels,
                                 ceiling_hz=ceiling_hz, tract=tract, speaker=speaker)
    return Heard(run, result, None if found is None else found.larynx(), tuple(notes))


def _median_abs_pct(rows: list[dict], key: str) -> float | None:
    """The median over ``rows`` of ``|row[key]|`` in %, to 0.1 (None for none)."""
    values = [abs(r[key]) for r in rows if r.get(key) is not None]
    return round(100 * float(np.median(values)), 1) if values else None


def acoustics_task(item: Any, out_dir: str, *, spec: Any, speaker: str | None = None,
                   ceiling_hz: float | None = None, accept_mismatch: bool = False,
                   overwrite: bool = False) -> Any:
    """``cassi acoustics DATASET``'s task: :func:`hear` one recording (the worker's model)
    and write its frame and segment tables to ``out_dir/SUBJECT/TASK``
    (:data:`FRAMES_SUFFIX`, :data:`SEGMENTS_SUFFIX`). Row: frames, vowel frames, the share
    scored, segments, the norms, the notes (the run's caveats, why nothing is scored), and
    the median over segments of each |F error| in %."""
    from .acoustics import recording_sound, unscored_line
    from .corpus import TaskResult, load_item, worker_model
    from .labels import recording_labels
    from .tables import write_table

    recording = load_item(item, quiet=True)
    samples, rate = recording_sound(recording, accept_mismatch=accept_mismatch)
    labels = recording_labels(recording, accept_mismatch=accept_mismatch)
    heard = hear(recording, spec, labels=labels, samples=samples, rate_hz=rate,
                 speaker=speaker, ceiling_hz=ceiling_hz, model=worker_model())
    result = heard.acoustics
    stem = Path(out_dir) / item.subject / item.task
    stem.parent.mkdir(parents=True, exist_ok=True)
    outputs = write_table(result.frame_rows(), stem.with_name(stem.name + FRAMES_SUFFIX),
                          overwrite=overwrite, digits=3)
    segments = result.segment_rows()
    if segments:
        outputs += write_table(segments, stem.with_name(stem.name + SEGMENTS_SUFFIX),
                               overwrite=overwrite, digits=ERROR_DIGITS)
    vowel = result.vowel
    row = {"frames": len(result.times), "vowel_frames": int(vowel.sum()),
           "scored_frames": int(result.scored.sum()),
           "share_scored": round(result.share_scored, 3), "segments": len(segments),
           "norms": result.norms.speaker, "larynx": heard.larynx or "the norms",
           "note": "; ".join([*heard.notes, unscored_line(labels) or ""]).strip("; ")}
    for f in FORMANTS:
        row[f"{f}_median_abs_error_pct"] = _median_abs_pct(segments, f"{f}_error")
    return TaskResult(row, tuple(str(p) for p in outputs))


def dataset_segments(run: Any, out_dir: str | os.PathLike) -> list[dict]:
    """Every vowel segment of the run's recordings that were heard (their segment tables
    under ``out_dir``), with subject, task and vowel quality first."""
    import csv

    from .acoustic_fit import vowel_quality
    from .status import Status

    rows = []
    for r in run.results:
        if r.status == Status.FAILED or not r.row.get("segments"):
            continue
        path = Path(out_dir) / r.item.subject / (r.item.task + SEGMENTS_SUFFIX)
        with open(path, newline="") as fh:
            for seg in csv.DictReader(fh):
                values = {k: _number(k, v) for k, v in seg.items()}
                rows.append({"subject": r.item.subject, "task": r.item.task,
                             "quality": vowel_quality(seg["vowel"]), **values})
    return rows


def _number(column: str, text: str | None) -> Any:
    """A segment table's cell read back: the vowel as written, counts as int, blank as
    None, the rest float."""
    if column == "vowel" or not text:
        return text or None
    return int(text) if column in ("frames", "scored") else float(text)


def summary_rows(segments: list[dict]) -> list[dict]:
    """Per subject and vowel quality, then per subject over all (quality ``all``): the
    segments, the frames scored, and the median over the segments with a scored frame of
    the signed and the absolute F1-F3 errors (%)."""
    def row(subject: str, quality: str, group: list[dict]) -> dict:
        scored = [g for g in group if (g.get("scored") or 0) > 0]
        out = {"subject": subject, "quality": quality, "segments": len(group),
               "segments_scored": len(scored),
               "scored_frames": int(sum(g.get("scored") or 0 for g in group))}
        for f in FORMANTS:
            errors = np.array([g[f"{f}_error"] for g in scored
                               if g.get(f"{f}_error") is not None], float)
            out[f"{f}_median_error_pct"] = (round(100 * float(np.median(errors)), 1)
                                            if errors.size else None)
            out[f"{f}_median_abs_error_pct"] = (round(100 * float(np.median(np.abs(errors))), 1)
                                                if errors.size else None)
        return out

    out = []
    for subject in dict.fromkeys(s["subject"] for s in segments):
        mine = [s for s in segments if s["subject"] == subject]
        for quality in sorted({s["quality"] for s in mine}):
            out.append(row(subject, quality, [s for s in mine if s["quality"] == quality]))
        out.append(row(subject, "all", mine))
    return out


def acoustics_corpus(dataset: Any, out_dir: str | os.PathLike, *, spec: Any = None,
                     subjects: Iterable[str] | None = None, tasks: Iterable[str] | None = None,
                     speaker: str | None = None, ceiling_hz: float | None = None,
                     accept_mismatch: bool = False,
                     run_options: Mapping[str, Any] | None = None, **changes: Any) -> Any:
    """:func:`acoustics_task` on every recording of ``dataset`` (the chosen ``subjects`` /
    ``tasks``), then the dataset's three tables in ``out_dir`` (module docstring);
    ``accept_mismatch``: sound or labels that do not fit a recording's length are used
    (with a warning) instead of failing it.
    ``run_options`` go to ``corpus.run_corpus`` (``jobs``, ``resume``, ``overwrite``...).
    Returns a ``corpus.CorpusResult``: the run, the tables written and the summary rows."""
    from .corpus import (
        CorpusResult,
        dataset_items,
        refuse_existing,
        replaces,
        require_items,
        run_corpus,
    )
    from .run_spec import run_spec
    from .tables import write_table

    spec = run_spec(spec, **changes)
    out = Path(out_dir)
    run_options = dict(run_options or {})
    tables = [out / RECORDINGS_NAME, out / SEGMENTS_NAME, out / SUMMARY_NAME]
    refuse_existing(tables, run_options)
    run_options.setdefault("desc", "acoustics")
    items = require_items(dataset_items(dataset, subjects=subjects, tasks=tasks), dataset,
                          subjects, tasks)
    options = {"spec": spec, "speaker": speaker, "ceiling_hz": ceiling_hz,
               "accept_mismatch": accept_mismatch}
    run = run_corpus(acoustics_task, items, out_dir, options=options, **run_options)
    overwrite = replaces(run_options)
    segments = dataset_segments(run, out)
    summary = summary_rows(segments)
    written = write_table(run.rows(), tables[0], overwrite=overwrite, digits=3)
    written += write_table(segments, tables[1], overwrite=overwrite, digits=ERROR_DIGITS)
    written += write_table(summary, tables[2], overwrite=overwrite, digits=1,
                           markdown="Formants over the dataset: model / measured - 1 per vowel "
                           "segment, medians per subject and vowel quality (one speaker's "
                           "figures each)")
    return CorpusResult(run, written, summary)


__all__ = ["Heard", "acoustics_corpus", "acoustics_task", "hear", "summary_rows"]
