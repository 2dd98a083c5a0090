"""``cassi animate``: a pellet recording to a video (MP4 with sound, GIF) or a still (PNG)."""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

from cassi_fit.options import ANIMATION_SUFFIXES, DEFAULT_FPS, TRACT_VIEW, VIEWS

from ._options import (
    add_accept_mismatch_argument,
    add_model_arguments,
    add_recording_argument,
    add_run_arguments,
    add_speaker_argument,
    dataset_args,
    finish,
    load_recording_args,
    parse_size,
    parse_views,
    run_args,
    run_options,
    spec_from_args,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "animate",
        help="animate the face from a pellet recording (video or still)",
        description="Fit the face to the recording's subject (CASSI's initialization), move it "
        "with every data line and render it (front, side, inside, top and midsagittal "
        "views) to a video "
        "or a still. An .mp4 carries the recording's sound (a .wav with the pellet file's "
        "stem), aligned to the frames for any stride and --fps. With one recording, --jobs "
        "N draws its frames in N processes (the same video).",
    )
    add_recording_argument(parser)
    add_model_arguments(parser)
    parser.add_argument(
        "--views",
        default=",".join(VIEWS),
        metavar="LIST",
        help="comma-separated views among front, side, inside, top (the paper's four) and "
        "midsagittal (the model cut at z = 0 as a 2D tracing, with the subject's palate and "
        "pharynx traces and the pellets with trails); default: all five. Also tract: the "
        "frame's area function and the tube's spectrum with the model's F1-F3 (and the "
        "sound's, where measured), as in cassi acoustics",
    )
    add_speaker_argument(parser, "the tract view")
    parser.add_argument(
        "--size",
        default="640x480",
        metavar="WxH",
        help="size of the whole image in pixels (default 640x480); four views share it as a "
        "2x2 grid, five as a 3x2 grid",
    )
    parser.add_argument(
        "--out",
        metavar="FILE",
        help="output .mp4 (with sound when there is any), .gif or .png (one still, see "
        "--frame); default SUBJECT_TASK.mp4 in the current folder",
    )
    parser.add_argument(
        "--frame",
        type=int,
        default=0,
        metavar="K",
        help="for a .png: which animation frame to draw (0 = the first valid line; with "
        "--stride N, frame K is data line first + K*N; --fps does not change it)",
    )
    parser.add_argument(
        "--fps",
        default=str(DEFAULT_FPS),
        metavar="RATE",
        help=f"frames per second of a video (default {DEFAULT_FPS}; a number or 'native': "
        "one frame per data line, XRMB's 145.6 per second). Each video frame shows the data "
        "line nearest its time, on the file's own clock (irregular articulograph times "
        "included), with that line's status; nothing is interpolated. --stride N first keeps "
        "every Nth line; a video never has more frames than those lines (XRMB with --stride "
        "10: 14.6 fps). The penetration CSV and the reports keep every (strided) line",
    )
    parser.add_argument(
        "--markers",
        action="store_true",
        help="draw the measured pellets (red) and the model's pellet sites (green)",
    )
    parser.add_argument(
        "--penetration",
        metavar="CSV",
        help="also write the per-frame penetration depths (mm; tongue in palate, teeth, "
        "front teeth; lips in teeth), before and after any projection, to CSV",
    )
    parser.add_argument("--no-audio", action="store_true", help="leave the sound out of an .mp4")
    add_accept_mismatch_argument(parser)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    # DATASET alone with --out DIR: every recording to DIR/SUBJECT/TASK.mp4 (run_dataset)
    add_run_arguments(parser, force=False)
    parser.add_argument("--format", choices=("mp4", "gif"), default="mp4",
                        help="DATASET form: the videos' format (default mp4)")
    parser.set_defaults(func=run)














def run(args) -> int:
    from cassi_fit.errors import CassiError
    from cassi_fit.recording_video import parse_fps

    if len(args.recording) == 1 and Path(args.recording[0]).is_dir() and not (
            args.out and Path(args.out).suffix.lower() in ANIMATION_SUFFIXES):
        return run_dataset(args)  # a folder with an image or video --out: its one recording
    size, views = parse_size(args.size), parse_views(args.views)
    parse_fps(args.fps)  # a bad --fps fails before any work
    out = Path(args.out) if args.out else None
    if out is not None and out.suffix.lower() not in ANIMATION_SUFFIXES:
        raise CassiError(f"--out {out}: must end in {', '.join(ANIMATION_SUFFIXES)}")
    recording = load_recording_args(args.recording, args)
    out = out or Path(f"{recording.subject}_{recording.task}.mp4")
    csv_out = Path(args.penetration) if args.penetration else None
    from cassi_fit._io import check_outputs  # before any work: no input, no clash, no overwrite

    check_outputs([out, csv_out], overwrite=args.force)
    still = out.suffix.lower() == ".png"
    jobs = 1 if still else drawing_jobs(args)
    from cassi_fit.render import FramePool, prepare_gl

    prepare_gl()  # drawn here (too): OpenGL readied while the face is fitted and moved
    # --jobs N: the drawing workers start now, importing what they need meanwhile
    with FramePool(jobs=jobs) if jobs > 1 else contextlib.nullcontext() as pool:
        run = run_args(recording, args)
        written = write_output(out, run, size, views, args, pool=pool)
    state, animation = run.state, run.animation
    from cassi_fit.reports import penetration_summary, tongue_volume_summary, write_penetration_csv

    print(f"wrote {written} ({animation.n_frames} frames, stride {animation.stride})")
    for line in state.calibration_problems:  # said once on reading, kept beside the output
        print(f"calibration problem: {line}")
    for line in state.calibration_caveats:
        print(f"calibration: {line}")
    from cassi_fit.lips import run_closures_line

    if (line := run_closures_line(run)) is not None:  # lips apart in labelled /p b m/
        print(line)
    print(penetration_summary(animation))
    print(tongue_volume_summary(state.model, animation))
    if csv_out is not None:
        print(f"wrote {write_penetration_csv(csv_out, animation, overwrite=args.force)}")
    return 0


def write_output(out: Path, run, size, views, args, pool=None) -> Path:
    """The run's still (``.png``, frame ``--frame``) or video (``recording_video.write_recording_video``;
    ``pool``: a started ``render.FramePool`` drawing it, for ``--jobs N``)."""
    from cassi_fit import recording_video as video
    from cassi_fit.errors import CassiError

    recording, animation = run.recording, run.animation
    panels = None
    if TRACT_VIEW in views:  # the area function and the tube's spectrum beside the face
        from cassi_fit.acoustics import tract_panels

        panels = tract_panels(run, calibration=getattr(args, "calibration", None),
                              speaker=getattr(args, "speaker", None))
        if panels:  # which vocal tract: the fitted one or which speaker's norms, and why
            print(panels[0]["tract"])
    if out.suffix.lower() == ".png":
        from cassi_fit.render import Renderer, save_png

        if not 0 <= args.frame < animation.n_frames:
            raise CassiError(f"--frame {args.frame}: the animation has {animation.n_frames} frames")
        with Renderer(run.state.model, size=size, views=views, grid=len(views) > 1,
                      traces=video.subject_traces(recording, run.state.scale)) as renderer:
            (image,) = video.animation_frames(
                animation, renderer, subject=recording.subject, task=recording.task,
                markers=args.markers, progress=False, indices=[args.frame], panels=panels)
        return save_png(out, image, overwrite=args.force)
    sound = getattr(recording, "sound", None)  # beside the file or inside it
    if not args.no_audio and out.suffix.lower() == ".mp4" and sound is not None:
        print(f"sound: {sound.source}", file=sys.stderr)
    return video.write_recording_video(out, run, size=size, views=views, markers=args.markers,
                                       audio=not args.no_audio, progress=not args.quiet,
                                       accept_mismatch=args.accept_mismatch,
                                       overwrite=args.force, fps=args.fps,
                                       jobs=drawing_jobs(args), panels=panels, pool=pool)


def drawing_jobs(args) -> int:
    """``--jobs`` for one recording: the frames drawn by N processes (default 1)."""
    from cassi_fit.errors import CassiError

    if args.scheduler:
        raise CassiError("--scheduler is for a DATASET; one recording's frames are drawn "
                         "here (--jobs N: in N local processes)")
    if args.jobs is not None and args.jobs < 1:
        raise CassiError(f"--jobs must be at least 1, got {args.jobs}")
    return args.jobs or 1


def run_dataset(args) -> int:
    """``cassi animate DATASET --out DIR``: one video per recording
    (``recording_video.animate_corpus``) with the same run spec as one recording, in parallel; exit
    1 if any failed."""
    from cassi_fit.errors import CassiError
    from cassi_fit.recording_video import animate_corpus

    if not args.out or Path(args.out).suffix.lower() in ANIMATION_SUFFIXES:
        raise CassiError(f"{args.recording[0]}: a dataset folder; give --out DIR for its "
                         "videos (or --out FILE.mp4/.png for a folder of one recording)")
    video_options = {"suffix": f".{args.format}", "size": parse_size(args.size),
                     "views": parse_views(args.views), "audio": not args.no_audio,
                     "markers": args.markers, "fps": args.fps}
    if TRACT_VIEW in video_options["views"]:
        from functools import partial

        from cassi_fit.acoustics import tract_panels

        # a worker is sent the function and the folder: each subject's own vocal tract
        video_options["tract_panels"] = partial(tract_panels, calibration=args.calibration,
                                                speaker=args.speaker)
    run, written, _ = animate_corpus(dataset_args(args.recording[0], args), args.out, spec=spec_from_args(args),
                                     video_options=video_options,
                                     run_options=run_options(args))
    print(f"{len(run.results) - len(run.failed)} of {len(run.results)} videos written to "
          f"{args.out} on {run.workers} worker(s); table {written[0]}")
    return finish(run)
