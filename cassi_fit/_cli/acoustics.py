"""``cassi acoustics RECORDING [--csv OUT.csv] [--plot OUT.png]``: the model's formants of
every frame against the recording's sound (``cassi_fit.acoustics``); ``cassi acoustics
DATASET --out DIR``: every recording of a dataset and its tables
(``cassi_fit.acoustics_corpus``)."""

from __future__ import annotations

from pathlib import Path

from ._options import (
    add_accept_mismatch_argument,
    add_model_arguments,
    add_recording_argument,
    add_run_arguments,
    add_selection_arguments,
    add_speaker_argument,
    dataset_args,
    finish,
    load_recording_args,
    names_option,
    run_options,
    spec_from_args,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "acoustics",
        help="the model's formants F1-F3 per frame against the sound's (Praat), per vowel segment",
        description="The area function of every animated frame (the midsagittal airway from a "
        "glottis placed below the hyoid to the lips, areas by Soquet et al.'s rules), its "
        "formants through a lossy tube (Sondhi & Schroeter), and the sound's formants measured "
        "by Praat's Burg method at the same times. Prints one line per vowel segment (labels "
        "beside the pellet file: X.lab or X.TextGrid) with the median model and measured F1-F3 "
        "and the share of the vowels' frames scored (silent, unvoiced and wide-bandwidth frames "
        "are never scored). --csv writes the per-frame table (and OUT.segments.csv), --plot "
        "the formant tracks over the spectrogram. --calibration FILE with an acoustic "
        "calibration (cassi calibrate --acoustic) uses its vocal tract. One line says which "
        "speaker's norms (--speaker) the sound is heard with.",
    )
    add_recording_argument(parser)
    add_model_arguments(parser)
    add_speaker_argument(parser, "the vocal tract and the sound's formants")
    parser.add_argument("--ceiling", type=float, default=None, metavar="HZ",
                        help="Praat's formant ceiling (default the speaker's: 5000 for an adult "
                        "male, 5500 for an adult female); given, it wins over --speaker's")
    parser.add_argument("--csv", metavar="OUT.csv", help="per-frame table to write")
    parser.add_argument("--plot", metavar="OUT.png", help="figure to write")
    add_accept_mismatch_argument(parser, "frames the sound does not cover are not scored")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="a dataset folder as RECORDING: every recording heard (in "
                        "parallel) into DIR/SUBJECT/TASK.acoustics.csv and "
                        ".acoustics.segments.csv, and the dataset's tables "
                        "acoustics_recordings.csv, acoustics_segments.csv and "
                        "acoustics_summary.csv/.md (per subject and vowel quality)")
    add_selection_arguments(parser, "with --out")
    add_run_arguments(parser)  # with --out: --jobs, --scheduler, --resume, --force
    parser.add_argument("--quiet", action="store_true", help="with --out: no progress bar")
    parser.set_defaults(func=run)


def run(args) -> int:
    words = args.recording
    if len(words) == 1 and Path(words[0]).is_dir() and args.out is not None:
        return run_dataset(args)
    if args.out is not None:
        from cassi_fit.errors import CassiError

        raise CassiError(f"--out DIR is for a dataset folder's recordings, not {' '.join(words)}"
                         " (one recording: --csv and --plot)")
    from cassi_fit.acoustics import plot_acoustics, recording_sound, unscored_line
    from cassi_fit.acoustics_corpus import hear
    from cassi_fit.errors import OutputExistsError
    from cassi_fit.labels import recording_labels
    from cassi_fit.tables import markdown_text, write_table

    for out in (args.csv, args.plot):
        if out and Path(out).exists() and not args.force:
            raise OutputExistsError(f"{out}: exists (use --force to replace it)")
    recording = load_recording_args(words, args)
    # none, or one that does not fit the recording: said before the model is run
    samples, rate = recording_sound(recording, accept_mismatch=args.accept_mismatch)
    labels = recording_labels(recording, accept_mismatch=args.accept_mismatch)
    # what the calibration folder lacked and what the model took without knowing it (a
    # palate estimated, the lips' rest), as animate says: printed before the acoustics
    heard = hear(recording, spec_from_args(args), labels=labels, samples=samples,
                 rate_hz=rate, speaker=args.speaker, ceiling_hz=args.ceiling, say=print)
    run_, result = heard.run, heard.acoustics
    print(result.norms.line(ceiling_hz=args.ceiling, larynx=heard.larynx))
    from cassi_fit.lips import closures_line

    if (line := closures_line(result.lips_in_closures, run_.spec.lip_closure)) is not None:
        print(line)  # the lips' rest is wrong where they stay apart in labelled closures
    segments = result.segment_rows()
    if (why := unscored_line(labels)) is not None:
        print(why)
    else:
        print(markdown_text(segments, digits=3) if segments else "no vowel segments labelled")
        print(result.scored_line())
    if args.csv:
        write_table(result.frame_rows(), args.csv, overwrite=args.force, digits=3)
        seg_path = Path(args.csv).with_suffix(".segments.csv")
        if segments:
            write_table(segments, seg_path, overwrite=args.force, digits=3)
        print(f"wrote {args.csv}")
    if args.plot:
        plot_acoustics(result, samples, rate, args.plot)
        print(f"wrote {args.plot}")
    return 0


def run_dataset(args) -> int:
    """``cassi acoustics DATASET --out DIR``: every recording heard, in parallel, and the
    dataset's tables (``acoustics_corpus``); exit 1 if any recording failed."""
    from cassi_fit.acoustics_corpus import acoustics_corpus
    from cassi_fit.errors import CassiError
    from cassi_fit.tables import markdown_text

    if args.csv or args.plot:
        raise CassiError("--csv and --plot are for one recording; a dataset's tables go to "
                         "--out DIR")
    run, written, summary = acoustics_corpus(
        dataset_args(args.recording[0], args), args.out, spec=spec_from_args(args),
        subjects=names_option(args.subjects), tasks=names_option(args.tasks), speaker=args.speaker,
        ceiling_hz=args.ceiling, accept_mismatch=args.accept_mismatch,
        run_options=run_options(args))
    overall = [r for r in summary if r["quality"] == "all"]
    if overall:
        print(markdown_text(overall, digits=1))
    print(f"{len(run.results) - len(run.failed)} of {len(run.results)} recordings heard on "
          f"{run.workers} worker(s); tables {', '.join(str(p) for p in written)}")
    return finish(run)


def calibrate_acoustic(args) -> int:
    """``cassi calibrate DATASET --acoustic``: each subject's vocal tract fitted to the
    vowels of its recordings that have sound and labels, written to
    ``OUT/SUBJECT.acoustic.json``; a fit that does not converge is reported (status 3 unless
    ``--accept-unconverged``)."""
    import sys

    import numpy as np

    from cassi_fit.acoustic_fit import (
        acoustic_calibration_path,
        fit_tract,
        vowel_quality,
        write_acoustic_calibration,
    )
    from cassi_fit.acoustics import recording_acoustics
    from cassi_fit.area_function import default_tract
    from cassi_fit.dataset import Dataset
    from cassi_fit.errors import CassiError, OutputExistsError
    from cassi_fit.pipeline import run_recording

    root, out = Path(args.dataset), Path(args.out)
    if not root.is_dir():
        raise CassiError(f"{root}: no such dataset folder")
    from ._options import dataset_args

    source = dataset_args(root, args)  # with --sensor-map when given
    dataset = source if isinstance(source, Dataset) else Dataset(root)
    subjects = [w.strip() for w in (args.subjects or "").split(",") if w.strip()] or dataset.subjects()
    status = 0
    for subject in subjects:
        target = acoustic_calibration_path(out, subject)
        if target.exists() and not args.force:
            raise OutputExistsError(f"{target}: file exists (pass --force to replace it)")
        results, names = [], []
        for task in dataset.tasks(subject):
            recording = dataset.load(subject, task)
            if recording.sound is None:
                continue
            result = recording_acoustics(run_recording(recording),
                                         speaker=getattr(args, "speaker", None))
            if result.scored.any():
                results.append(result)
                names.append(task)
        if not results:
            print(f"{subject}: no recording with sound and scored vowel frames: no acoustic "
                  "calibration")
            continue
        # one subject, one model: the frames of every recording pooled
        import jax.numpy as jnp

        vertices = jnp.concatenate([r.vertices[r.scored] for r in results])
        measured = np.concatenate([r.measured.frequency[r.scored] for r in results])
        norms = _subject_norms(subject, results)
        fit = fit_tract(results[0].geometry, vertices, measured, results[0].scale,
                        base=default_tract(vertices.dtype, norms.speaker))
        qualities = sorted({vowel_quality(str(s)) for r in results for s in r.labels[r.scored]})
        write_acoustic_calibration(target, subject, fit, recordings=names, frames=len(measured),
                                   qualities=qualities, overwrite=args.force)
        flag = "" if fit.converged else "  NOT CONVERGED"
        print(f"{subject}: {len(measured)} vowel frames ({', '.join(qualities)}); median F1-F3 "
              f"error {', '.join(f'{100 * e:.0f}' for e in fit.before)} % -> "
              f"{', '.join(f'{100 * e:.0f}' for e in fit.after)} % (on the fitted frames){flag}; "
              f"wrote {target}")
        if len(qualities) < 2:
            print(f"{subject}: one vowel quality: the fit cannot be checked on held-out vowels")
        if not fit.converged and not args.accept_unconverged:
            print(f"cassi: {subject}: the acoustic calibration did not converge (recorded in "
                  "its file); pass --accept-unconverged to accept it", file=sys.stderr)
            status = 3
    return status


def _subject_norms(subject, results):
    """The norms of most of a subject's recordings (the first's on a tie), said in a line:
    one speaker, one prior for the fit."""
    speakers = [r.norms.speaker for r in results]
    norms = next(r.norms for r in results if r.norms.speaker == max(speakers, key=speakers.count))
    mixed = "" if len(set(speakers)) == 1 else (
        f" ({speakers.count(norms.speaker)} of its {len(speakers)} recordings)")
    print(f"{subject}: {norms.line()}{mixed}")
    return norms
