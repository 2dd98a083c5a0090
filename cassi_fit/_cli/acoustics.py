"""``cassi acoustics RECORDING [--csv OUT.csv] [--plot OUT.png]``: the model's formants of
every frame against the recording's sound (``cassi_fit.acoustics``)."""

from __future__ import annotations

from pathlib import Path

from ._options import add_model_arguments, add_recording_argument, load_recording_args, run_args


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
        "calibration (cassi calibrate --acoustic) uses its vocal tract.",
    )
    add_recording_argument(parser)
    add_model_arguments(parser)
    parser.add_argument("--ceiling", type=float, default=5000.0, metavar="HZ",
                        help="Praat's formant ceiling: 5000 for an adult male (default), 5500 "
                        "for an adult female")
    parser.add_argument("--csv", metavar="OUT.csv", help="per-frame table to write")
    parser.add_argument("--plot", metavar="OUT.png", help="figure to write")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    parser.set_defaults(func=run)


def run(args) -> int:
    from cassi_fit.acoustics import plot_acoustics, recording_acoustics
    from cassi_fit.errors import OutputExistsError
    from cassi_fit.formant_track import read_wav
    from cassi_fit.tables import markdown_text, write_table

    for out in (args.csv, args.plot):
        if out and Path(out).exists() and not args.force:
            raise OutputExistsError(f"{out}: exists (use --force to replace it)")
    recording = load_recording_args(args.recording, args)
    run_ = run_args(recording, args)
    tract = _calibrated_tract(run_)
    result = recording_acoustics(run_, ceiling_hz=args.ceiling, tract=tract)
    segments = result.segment_rows()
    print(markdown_text(segments, digits=3) if segments else "no vowel segments labelled")
    print(f"{100 * result.share_scored:.0f} % of the vowels' frames scored")
    if args.csv:
        write_table(result.frame_rows(), args.csv, overwrite=args.force, digits=3)
        seg_path = Path(args.csv).with_suffix(".segments.csv")
        if segments:
            write_table(segments, seg_path, overwrite=args.force, digits=3)
        print(f"wrote {args.csv}")
    if args.plot:
        samples, rate = read_wav(recording.audio)
        plot_acoustics(result, samples, rate, args.plot)
        print(f"wrote {args.plot}")
    return 0


def _calibrated_tract(run_):
    """The vocal tract of the subject's acoustic calibration, or None (the norms)."""
    calibration = getattr(run_.state, "calibration", None)
    record = getattr(calibration, "acoustic", None)
    if not record:
        return None
    from cassi_fit.acoustic_fit import tract_from_record

    return tract_from_record(record)
