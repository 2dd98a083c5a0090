"""The command-line options several commands share, in one place: where a recording comes
from (:func:`add_recording_argument`, :func:`add_source_arguments`), how the model runs
(:func:`add_model_arguments` -> ``run_spec.RunSpec``), the image options (``--size``,
``--views``) and where a corpus runs (:func:`add_run_arguments` -> ``corpus.run_corpus``'s
keywords, :func:`finish`). Each command module adds only its own options."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from cassi_fit.options import (
    ALL_JAW_METHODS,
    ALL_VIEWS,
    COLLISION_MODES,
    GAP_POLICIES,
    JAW_SENSOR_SETS,
    JAW_WEIGHTS,
    MODES,
    TONGUE_ANCHORS,
    TONGUE_SHAPES,
)

# ------------------------------------------------------------------ where a recording comes from


def add_recording_argument(parser: argparse.ArgumentParser) -> None:
    """``RECORDING`` (a file, or DATASET SUBJECT TASK) and :func:`add_source_arguments`."""
    parser.add_argument(
        "recording",
        nargs="+",
        metavar="RECORDING",
        help="a pellet file (.txy) or an articulograph file (EST Track .ema, Carstens .pos, "
        "NDI Wave .tsv, mview .mat, a .npy/.npz/.csv array, an EMU bundle folder or "
        "_bndl.json; docs/EMA.md), or three words DATASET SUBJECT TASK: a dataset folder "
        "(per-subject folders, flat files or an emuDB) and the subject and task in it; a "
        "dataset folder alone stands for its recording when it holds one",
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
    parser.add_argument("--accept-proposed-map", action="store_true",
                        help="articulograph files with numbered channels and no sensor map: "
                        "use the map proposed from the data (`cassi info --write-sensor-map "
                        "FILE` shows it); the channels it is not sure of get no role")
    parser.add_argument("--tier", metavar="NAME", default=None,
                        help="the label tier to use: a TextGrid's beside the file or one "
                        "inside it (default: phones, then words, WebMAUS's MAU, one "
                        "speaker's 'NAME - phones', else the first; `cassi info` lists them)")


def add_accept_mismatch_argument(parser: argparse.ArgumentParser, also: str = "") -> None:
    """``--accept-mismatch``: sound or labels whose length does not fit the recording
    used with a warning (``sound.check_sound``, ``labels.check_labels``); ``also``: what
    it means for this command, appended to the help."""
    parser.add_argument("--accept-mismatch", action="store_true",
                        help="use sound or labels whose length does not fit the recording "
                        "(a wrong sample rate, a cut file, labels in other units): a warning "
                        "instead of the error" + (f"; {also}" if also else ""))


def add_selection_arguments(parser: argparse.ArgumentParser, when: str = "") -> None:
    """A dataset command's ``--subjects`` and ``--tasks`` (names or comma-separated
    lists, :func:`names_option`); ``when``: the condition they apply under, e.g. "with
    --out"."""
    prefix = f"{when}: " if when else ""
    parser.add_argument("--subjects", nargs="+", metavar="SUBJECT",
                        help=f"{prefix}only these subjects (default: all)")
    parser.add_argument("--tasks", nargs="+", metavar="TASK",
                        help=f"{prefix}only these tasks (names or comma-separated lists, e.g. "
                        "tp040 tp106); default: every task of every subject")


def source_options(args: argparse.Namespace) -> dict:
    """``dataset.load_recording``'s keywords from :func:`add_source_arguments`' options."""
    smap = args.sensor_map
    if smap is None and getattr(args, "accept_proposed_map", False):
        smap = "proposed"  # cassi_fit.ema.sensor_map.PROPOSED; a map beside the files wins
    return {"sensor_map": smap, "layout": args.layout, "rate": args.rate,
            "bite_plane": args.bite_plane, "tier": getattr(args, "tier", None)}


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
        if path.is_dir():
            from cassi_fit.ema.emu import is_bundle_folder

            if not is_bundle_folder(path):  # a dataset folder: its one recording
                return _only_recording(path, options)
        return load_recording(path, **options)  # a pipe or device: one line saying which
    if len(words) == 3:
        from cassi_fit.dataset import Dataset

        root = Path(words[0])
        if not root.is_dir():
            raise CassiError(f"{root}: no such dataset folder")
        return Dataset(root, sensor_map=options.get("sensor_map"),
                       tier=options.get("tier")).load(words[1], words[2])
    raise CassiError(f"RECORDING is a pellet file or DATASET SUBJECT TASK, got {len(words)} words")


def _only_recording(root: Path, options: dict):
    """The one recording of the dataset folder ``root``, said in one line on stderr; a
    folder with several is refused in one line naming how to choose (or with none)."""
    from cassi_fit.dataset import Dataset
    from cassi_fit.errors import CassiError

    dataset = Dataset(root, sensor_map=options.get("sensor_map"), tier=options.get("tier"))
    pairs = [(s, t) for s in dataset.subjects() for t in dataset.tasks(s)]
    if len(pairs) != 1:
        example = f" (e.g. {root} {pairs[0][0]} {pairs[0][1]})" if pairs else ""
        raise CassiError(f"{root}: a dataset folder with {len(pairs)} recordings: name one "
                         f"as DATASET SUBJECT TASK{example}")
    (subject, task), = pairs
    print(f"{root}: a dataset of one recording: {subject} {task}", file=sys.stderr)
    return dataset.load(subject, task)


def dataset_args(root, args: argparse.Namespace):
    """The dataset folder ``root`` as a corpus command reads it: a ``dataset.Dataset``
    with ``--sensor-map`` (or ``--accept-proposed-map``) when given, else the folder.
    The options that describe one file (``--layout``, ``--rate``, ``--bite-plane``) are
    refused for a dataset in one line, never silently ignored."""
    from cassi_fit.errors import CassiError

    options = source_options(args)
    per_file = [f"--{k.replace('_', '-')}" for k in ("layout", "rate", "bite_plane")
                if options.get(k) is not None]
    if per_file:
        raise CassiError(f"{root}: {', '.join(per_file)} describe one file, not a dataset; "
                         f"give them with one recording (or put a sensor map beside the files)")
    smap = options.get("sensor_map")
    if smap is None and options.get("tier") is None:
        return root
    from cassi_fit.dataset import Dataset

    if isinstance(smap, str) and os.path.lexists(smap):
        smap = os.path.abspath(smap)  # a worker may run in another folder
    return Dataset(os.path.abspath(root), sensor_map=smap, tier=options.get("tier"))


def add_speaker_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """``--speaker {male,female,auto}``: the adult norms the sound is heard with
    (``acoustics.speaker_norms``); ``what`` says where they apply."""
    parser.add_argument(
        "--speaker", choices=("male", "female", "auto"), default=None,
        help=f"the adult norms for {what}: the larynx's drop below the hyoid (30 mm male, 15 "
        "mm female), Praat's formant ceiling (5000 / 5500 Hz) and the acoustic calibration's "
        "prior; male (default, the norms the toolkit has always used), female, or auto: from "
        "the recording's voice, a median F0 of its voiced frames of 160 Hz or more a female "
        "voice (male without a voiced sound). The female norms rest on one MRI abstract and "
        "made one female voice's formants worse overall (docs/ACOUSTICS.md)")


# ------------------------------------------------------------------ how the model runs


def add_model_arguments(parser: argparse.ArgumentParser) -> None:
    """The run spec's options (:func:`spec_from_args`): the mode, the jaw, the tongue, the
    gaps, the calibration and the collisions."""
    parser.add_argument(
        "--mode",
        choices=MODES,
        default=None,
        help="every choice at once (docs/CASSI_MODE.md): improved (default: thick tongue "
        "whose back follows T4, conformation from Headmeasures) or cassi (the paper's: "
        "flat tongue of zero thickness, back anchored behind and below T4, only the jaw "
        "shape adjusted, no collisions); the options below override it",
    )
    add_jaw_arguments(parser)
    add_shape_arguments(parser)


def add_jaw_arguments(parser: argparse.ArgumentParser) -> None:
    """``--jaw``, ``--jaw-sensors``, ``--jaw-weights`` and ``--stride``."""
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
        "--jaw-weights",
        choices=JAW_WEIGHTS,
        default=None,
        help="region weights of the jaw rotation: CASSI's (teeth 100%%; default) or Parke's "
        "(teeth 90%%)",
    )
    parser.add_argument(
        "--stride",
        type=int,
        default=None,
        metavar="N",
        help="use every Nth data line from the first valid one (default 1: every line; "
        "CASSI showed every 10th); video time stays real time",
    )


def add_shape_arguments(parser: argparse.ArgumentParser) -> None:
    """The tongue, the gaps, the calibration, ``--cassi`` and the collisions."""
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
        "--lip-closure",
        action="store_true",
        default=None,
        help="an articulograph recording without a calibration: the model's lips touch "
        "where the lip sensors are nearest (lips sealed in /p b m/) instead of resting where "
        "the first valid line has them; not the default (docs/ACOUSTICS.md)",
    )


def chosen_mode(args: argparse.Namespace) -> str | None:
    """The mode of ``--mode`` and ``--cassi`` (the same as ``--mode cassi``); a
    ``CassiError`` if they disagree."""
    from cassi_fit.errors import CassiError

    mode, cassi = getattr(args, "mode", None), getattr(args, "cassi", False)
    if cassi and mode not in (None, "cassi"):
        raise CassiError(f"--cassi and --mode {mode} disagree")
    return "cassi" if cassi else mode


def spec_from_args(args: argparse.Namespace):
    """The ``run_spec.RunSpec`` of the options of :func:`add_model_arguments`, checked once
    (for one recording and for every recording of a dataset alike)."""
    from cassi_fit.run_spec import run_spec

    mode = chosen_mode(args)
    return run_spec(mode, calibration=getattr(args, "calibration", None) or None,
                    jaw=args.jaw, stride=args.stride, jaw_weights=args.jaw_weights,
                    tongue_anchor=args.tongue_anchor, gap_policy=args.gap,
                    collisions=args.collisions, tongue_shape=args.tongue_shape,
                    jaw_sensors=getattr(args, "jaw_sensors", None),
                    lip_closure=getattr(args, "lip_closure", None))


def run_args(recording, args):
    """``pipeline.run_recording`` of one recording with the options of
    :func:`add_model_arguments` (:func:`face_spec`)."""
    from cassi_fit.pipeline import run_recording

    return run_recording(recording, face_spec(recording, args))


def face_spec(recording, args):
    """The ``RunSpec`` of the face's run for ``recording``: :func:`spec_from_args`, without
    the calibration where ``--calibration`` names a folder holding the subject's vocal
    tract but not its face (``acoustic_fit.face_calibration``: ``cassi calibrate
    --acoustic`` writes only the former; said in one line): the face keeps its defaults
    and the folder serves the vocal tract alone (``cassi animate --views ...,tract``)."""
    spec = spec_from_args(args)
    if not (getattr(args, "calibration", None) and Path(args.calibration).is_dir()):
        return spec
    # Imported only for a folder: the acoustic fit's module (optimistix with it) costs
    # a run without a calibration over a second.
    from cassi_fit.acoustic_fit import face_calibration

    spec, note = face_calibration(spec, recording.subject)
    if note is not None:
        print(note)
    return spec


def parse_size(text: str) -> tuple[int, int]:
    """``--size WxH`` -> ``(width, height)`` pixels, each 16..8192."""
    from cassi_fit.errors import CassiError

    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise CassiError(f"--size must look like 640x480, got {text!r}") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise CassiError(f"--size {text}: each side must be between 16 and 8192 pixels")
    return width, height


def parse_views(text: str) -> tuple[str, ...]:
    """``--views a,b`` -> the views, each one of ``options.ALL_VIEWS``."""
    from cassi_fit.errors import CassiError

    views = tuple(v.strip() for v in text.split(",") if v.strip())
    unknown = [v for v in views if v not in ALL_VIEWS]
    if unknown or not views:
        raise CassiError(
            f"--views: unknown view(s) {', '.join(unknown) or '(none)'}; use {','.join(ALL_VIEWS)}"
        )
    return views


# ------------------------------------------------------------------ where a corpus runs


def add_run_arguments(parser: argparse.ArgumentParser, *, force: bool = True) -> None:
    """``--jobs``, ``--scheduler``, ``--resume`` (and ``--force`` unless the command has
    its own)."""
    parser.add_argument("--jobs", type=int, metavar="N",
                        help="recordings run in N local worker processes (default: all "
                        "cores; 1: in this process)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="send the recordings to a running dask.distributed cluster "
                        "(e.g. tcp://host:8786) instead of local processes (needs the "
                        "'corpus' extra)")
    parser.add_argument("--scheduler-timeout", type=float, metavar="SECONDS",
                        help="time allowed to reach the --scheduler (default: "
                        "$CASSI_SCHEDULER_TIMEOUT or 10 s)")
    parser.add_argument("--resume", action="store_true",
                        help="skip recordings whose outputs an earlier run of the same "
                        "settings completed (checked by their markers), run the rest")
    if force:
        parser.add_argument("--force", action="store_true",
                            help="replace existing outputs (and rerun every recording)")


def names_option(values: str | list[str] | None) -> list[str] | None:
    """``--subjects``/``--tasks`` as names: ``"a,b"`` or ``["a,b", "c"]`` -> ``["a", "b",
    "c"]``; None (or an empty string) stays None (every one)."""
    if not values:
        return None
    values = [values] if isinstance(values, str) else values
    return [w.strip() for v in values for w in v.split(",") if w.strip()]


def run_options(args: argparse.Namespace) -> dict:
    """``corpus.run_corpus`` keywords from the parsed options."""
    from cassi_fit.errors import CassiError

    if args.jobs is not None and args.jobs < 1:
        raise CassiError(f"--jobs must be at least 1, got {args.jobs}")
    if args.jobs is not None and args.scheduler:
        raise CassiError("--jobs and --scheduler exclude each other (the cluster decides "
                         "its workers)")
    timeout = getattr(args, "scheduler_timeout", None)
    if args.scheduler is not None:  # a malformed address fails before any work
        from cassi_fit.corpus import parse_scheduler_address, scheduler_timeout

        parse_scheduler_address(args.scheduler)
        scheduler_timeout(timeout)
    elif timeout is not None:
        raise CassiError("--scheduler-timeout is for --scheduler")
    return {"jobs": args.jobs, "scheduler": args.scheduler, "scheduler_timeout": timeout,
            "resume": args.resume, "overwrite": args.force,
            "progress": not getattr(args, "quiet", False)}


def finish(run) -> int:
    """Print what was resumed and the failures (stderr); 1 if any recording failed."""
    if run.resumed:
        print(f"resumed: {run.resumed} of {len(run.results)} already done", file=sys.stderr)
    summary = run.failure_summary()
    if summary:
        print(summary, file=sys.stderr)
        return 1
    return 0
