"""``cassi animate``: a pellet recording to a video (MP4 with sound, GIF) or a still (PNG)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from cassi_fit._cli._corpus import add_run_arguments, finish, run_options
from cassi_fit.options import (
    ALL_JAW_METHODS,
    ANIMATION_SUFFIXES,
    COLLISION_MODES,
    GAP_POLICIES,
    JAW_SENSOR_SETS,
    JAW_WEIGHTS,
    MODES,
    TONGUE_ANCHORS,
    TONGUE_SHAPES,
    VIEWS,
)


def add_recording_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recording",
        nargs="+",
        metavar="RECORDING",
        help="a pellet file (.txy) or an articulograph file (EST Track .ema, Carstens .pos, "
        "NDI Wave .tsv, mview .mat, a .npy/.npz/.csv array; docs/EMA.md), or three words "
        "DATASET SUBJECT TASK: a dataset folder (per-subject folders or flat files) and the "
        "subject and task in it",
    )
    add_source_arguments(parser)


def add_source_arguments(parser: argparse.ArgumentParser) -> None:
    """The options an articulograph file may need (``dataset.load_recording``'s)."""
    parser.add_argument("--sensor-map", metavar="MAP", default=None,
                        help="articulograph sensor map: a built-in name (auto, mocha, mngu0, "
                        "sparc, synthetic) or a .toml file (default: sensors.toml beside the "
                        "files, else the built-in names)")
    parser.add_argument("--layout", default=None,
                        help="array files: a built-in layout (sparc, mngu0) or comma-separated "
                        "column names")
    parser.add_argument("--rate", type=float, default=None,
                        help="array files (and headerless .pos files): the sampling rate, Hz")
    parser.add_argument("--bite-plane", metavar="FILE", default=None,
                        help="articulograph files: the bite-plane recording (default: a *bite* "
                        "file beside)")


def source_options(args: argparse.Namespace) -> dict:
    """``dataset.load_recording``'s keywords from :func:`add_source_arguments`' options."""
    return {"sensor_map": args.sensor_map, "layout": args.layout, "rate": args.rate,
            "bite_plane": args.bite_plane}


def add_model_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--mode",
        choices=MODES,
        default=None,
        help="every choice at once (docs/CASSI_MODE.md): improved (default: thick tongue "
        "whose back follows T4, conformation from Headmeasures) or cassi (the paper's: "
        "flat tongue of zero thickness, back anchored behind and below T4, only the jaw "
        "shape adjusted, no collisions); the options below override it",
    )
    parser.add_argument(
        "--jaw",
        choices=ALL_JAW_METHODS,
        default=None,
        help="how the jaw moves: the paper's closed form from the two jaw pellets (the "
        "default with two jaw sensors), or a least-squares fit: per frame (frame-fit), about "
        "one pivot for the whole recording (fixed-pivot), or about a pivot that moves "
        "smoothly (smooth-pivot); with one jaw sensor (most EMA corpora) the default is "
        "coupled-rotation (the rotation coupled to the sensor's displacement, learned from "
        "two-sensor recordings; docs/JAW.md), and the pivot fits run on a stated prior",
    )
    parser.add_argument(
        "--jaw-sensors",
        choices=JAW_SENSOR_SETS,
        default=None,
        help="the jaw sensors to use (default: every jaw pellet the recording tracks); MNI "
        "alone animates as a one-sensor recording would be",
    )
    parser.add_argument(
        "--stride",
        type=int,
        default=None,
        metavar="N",
        help="use every Nth data line from the first valid one (default 1: every line; "
        "CASSI showed every 10th); video time stays real time",
    )
    parser.add_argument(
        "--tongue-anchor",
        choices=TONGUE_ANCHORS,
        default=None,
        help="the tongue's back anchor points: fixed (CASSI: they never move, hence its V "
        "shape), follow (they move with T4; default) or none",
    )
    parser.add_argument(
        "--tongue-shape",
        choices=TONGUE_SHAPES,
        default=None,
        help="thick (default) or flat (CASSI: a surface of zero thickness through the "
        "four tongue pellets)",
    )
    parser.add_argument(
        "--gap",
        choices=GAP_POLICIES,
        default=None,
        help="untracked or mistracked pellet values: hold the last good value (default) or "
        "interpolate between good ones; repaired frames are flagged in the caption",
    )
    parser.add_argument(
        "--calibration",
        metavar="PATH",
        help="the subject's calibration: a folder written by 'cassi calibrate' (the file "
        "SUBJECT.calibration.json in it is used) or one such file; default: the subject's "
        "shape straight from Headmeasures and the first valid line",
    )
    parser.add_argument(
        "--cassi",
        action="store_true",
        help="the same as --mode cassi (every choice of the paper); not with --calibration",
    )
    parser.add_argument(
        "--collisions",
        choices=COLLISION_MODES,
        default=None,
        help="off (default; as CASSI: the tongue may pass through the teeth and palate) or "
        "project (every frame, the tongue is pushed out of the teeth and the palate and "
        "the lips out of the teeth); penetration depths are measured either way",
    )
    parser.add_argument(
        "--jaw-weights",
        choices=JAW_WEIGHTS,
        default=None,
        help="region weights of the jaw rotation: CASSI's (teeth 100%%; default) or Parke's "
        "(teeth 90%%)",
    )


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "animate",
        help="animate the face from a pellet recording (video or still)",
        description="Fit the face to the recording's subject (CASSI's initialization), move it "
        "with every data line and render it (front, side, inside, top and midsagittal "
        "views) to a video "
        "or a still. An .mp4 carries the recording's sound (a .wav with the pellet file's "
        "stem), aligned to the frames for any stride.",
    )
    add_recording_argument(parser)
    add_model_arguments(parser)
    parser.add_argument(
        "--views",
        default=",".join(VIEWS),
        metavar="LIST",
        help="comma-separated views among front, side, inside, top (the paper's four) and "
        "midsagittal (the model cut at z = 0 as a 2D tracing, with the subject's palate and "
        "pharynx traces and the pellets with trails); default: all five",
    )
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
        help="for a .png: which animation frame to draw (0 = the first valid line)",
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
    parser.add_argument("--accept-mismatch", action="store_true",
                        help="use sound or labels whose length does not fit the recording "
                        "(a wrong sample rate, a cut file, labels in other units): a warning "
                        "instead of the error")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    # DATASET alone with --out DIR: every recording to DIR/SUBJECT/TASK.mp4 (run_dataset)
    add_run_arguments(parser, force=False)
    parser.add_argument("--format", choices=("mp4", "gif"), default="mp4",
                        help="DATASET form: the videos' format (default mp4)")
    parser.set_defaults(func=run)


def parse_size(text: str) -> tuple[int, int]:
    from cassi_fit.errors import CassiError

    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise CassiError(f"--size must look like 640x480, got {text!r}") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise CassiError(f"--size {text}: each side must be between 16 and 8192 pixels")
    return width, height


def parse_views(text: str) -> tuple[str, ...]:
    from cassi_fit.errors import CassiError

    views = tuple(v.strip() for v in text.split(",") if v.strip())
    unknown = [v for v in views if v not in VIEWS]
    if unknown or not views:
        raise CassiError(
            f"--views: unknown view(s) {', '.join(unknown) or '(none)'}; use {','.join(VIEWS)}"
        )
    return views


def load_recording_args(words, args: argparse.Namespace | None = None):
    """A ``Recording`` from ``[PATH]`` or ``[DATASET, SUBJECT, TASK]``, with the
    articulograph options of :func:`add_source_arguments` in ``args``."""
    from cassi_fit.errors import CassiError

    options = source_options(args) if args is not None else {}
    if len(words) == 1:
        from cassi_fit.dataset import load_recording

        path = Path(words[0])
        if not os.path.lexists(path):  # anything else load_recording names (a pipe, ...)
            raise CassiError(f"{path}: no such recording file")
        return load_recording(path, **options)  # a pipe, device or folder: one line saying which
    if len(words) == 3:
        from cassi_fit.dataset import Dataset

        root = Path(words[0])
        if not root.is_dir():
            raise CassiError(f"{root}: no such dataset folder")
        return Dataset(root, sensor_map=options.get("sensor_map")).load(words[1], words[2])
    raise CassiError(f"RECORDING is a pellet file or DATASET SUBJECT TASK, got {len(words)} words")


def spec_from_args(args: argparse.Namespace):
    """The ``run_spec.RunSpec`` of the options of :func:`add_model_arguments`, checked once
    (for one recording and for every recording of a dataset alike)."""
    from cassi_fit.run_spec import run_spec

    mode = chosen_mode(args)
    return run_spec(mode, calibration=getattr(args, "calibration", None) or None,
                    jaw=args.jaw, stride=args.stride, jaw_weights=args.jaw_weights,
                    tongue_anchor=args.tongue_anchor, gap_policy=args.gap,
                    collisions=args.collisions, tongue_shape=args.tongue_shape,
                    jaw_sensors=getattr(args, "jaw_sensors", None))


def run_args(recording, args):
    """``pipeline.run_recording`` of one recording with the options of
    :func:`add_model_arguments`."""
    from cassi_fit.pipeline import run_recording

    return run_recording(recording, spec_from_args(args))


def chosen_mode(args: argparse.Namespace) -> str | None:
    """The mode of ``--mode`` and ``--cassi`` (the same as ``--mode cassi``); a
    ``CassiError`` if they disagree."""
    from cassi_fit.errors import CassiError

    mode, cassi = getattr(args, "mode", None), getattr(args, "cassi", False)
    if cassi and mode not in (None, "cassi"):
        raise CassiError(f"--cassi and --mode {mode} disagree")
    return "cassi" if cassi else mode


def run(args) -> int:
    from cassi_fit.errors import CassiError

    if len(args.recording) == 1 and Path(args.recording[0]).is_dir():
        return run_dataset(args)
    size, views = parse_size(args.size), parse_views(args.views)
    out = Path(args.out) if args.out else None
    if out is not None and out.suffix.lower() not in ANIMATION_SUFFIXES:
        raise CassiError(f"--out {out}: must end in {', '.join(ANIMATION_SUFFIXES)}")
    recording = load_recording_args(args.recording, args)
    out = out or Path(f"{recording.subject}_{recording.task}.mp4")
    csv_out = Path(args.penetration) if args.penetration else None
    from cassi_fit._io import check_outputs  # before any work: no input, no clash, no overwrite

    check_outputs([out, csv_out], overwrite=args.force)
    run = run_args(recording, args)
    state, animation = run.state, run.animation
    from cassi_fit.reports import penetration_summary, tongue_volume_summary, write_penetration_csv

    written = write_output(out, run, size, views, args)
    print(f"wrote {written} ({animation.n_frames} frames, stride {animation.stride})")
    for line in state.calibration_problems:  # said once on reading, kept beside the output
        print(f"calibration problem: {line}")
    for line in state.calibration_caveats:
        print(f"calibration: {line}")
    print(penetration_summary(animation))
    print(tongue_volume_summary(state.model, animation))
    if csv_out is not None:
        print(f"wrote {write_penetration_csv(csv_out, animation, overwrite=args.force)}")
    return 0


def write_output(out: Path, run, size, views, args) -> Path:
    """The run's still (``.png``, frame ``--frame``) or video (``recording_video.write_recording_video``)."""
    from cassi_fit import recording_video as video
    from cassi_fit.errors import CassiError

    recording, animation = run.recording, run.animation
    if out.suffix.lower() == ".png":
        from cassi_fit.render import Renderer, save_png

        if not 0 <= args.frame < animation.n_frames:
            raise CassiError(f"--frame {args.frame}: the animation has {animation.n_frames} frames")
        with Renderer(run.state.model, size=size, views=views, grid=len(views) > 1,
                      traces=video.subject_traces(recording, run.state.scale)) as renderer:
            (image,) = video.animation_frames(
                animation, renderer, subject=recording.subject, task=recording.task,
                markers=args.markers, progress=False, indices=[args.frame])
        return save_png(out, image, overwrite=args.force)
    if not args.no_audio and out.suffix.lower() == ".mp4" and recording.audio is not None:
        print(f"sound: {recording.audio}", file=sys.stderr)
    return video.write_recording_video(out, run, size=size, views=views, markers=args.markers,
                                       audio=not args.no_audio, progress=not args.quiet,
                                       accept_mismatch=args.accept_mismatch,
                                       overwrite=args.force)


def run_dataset(args) -> int:
    """``cassi animate DATASET --out DIR``: one video per recording
    (``recording_video.animate_corpus``) with the same run spec as one recording, in parallel; exit
    1 if any failed."""
    from cassi_fit.errors import CassiError
    from cassi_fit.recording_video import animate_corpus

    if not args.out or Path(args.out).suffix.lower() in ANIMATION_SUFFIXES:
        raise CassiError(f"{args.recording[0]}: a dataset folder; give --out DIR for its videos")
    video_options = {"suffix": f".{args.format}", "size": parse_size(args.size),
                     "views": parse_views(args.views), "audio": not args.no_audio,
                     "markers": args.markers}
    run, written = animate_corpus(args.recording[0], args.out, spec=spec_from_args(args),
                                  video_options=video_options, run_options=run_options(args))
    print(f"{len(run.results) - len(run.failed)} of {len(run.results)} videos written to "
          f"{args.out} on {run.workers} worker(s); table {written[0]}")
    return finish(run)
