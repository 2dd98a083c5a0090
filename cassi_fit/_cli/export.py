"""``cassi export``: the animated face as a glTF binary (.glb), or one frame as OBJ/PLY."""

from __future__ import annotations

from pathlib import Path

from ._options import add_model_arguments, add_recording_argument, load_recording_args, run_args

SUFFIXES = (".glb", ".obj", ".ply")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "export",
        help="export the animated face as .glb (morph-target animation) or a frame as .obj/.ply",
        description="Animate the face from a recording and export it: the whole animation as "
        "one glTF binary (.glb; one morph target per keyframe, played on the recording's "
        "clock by Blender, three.js and other glTF viewers), or a single frame as .obj or "
        ".ply with per-vertex colours. Vertex data are in mm in the model frame.",
    )
    add_recording_argument(parser)
    parser.add_argument(
        "--out",
        required=True,
        metavar="FILE",
        help="output file: .glb (animation), .obj or .ply (one frame)",
    )
    parser.add_argument(
        "--frame",
        type=int,
        default=0,
        metavar="K",
        help="for .obj/.ply: which animation frame (0 = the first valid line)",
    )
    add_model_arguments(parser)
    parser.add_argument(
        "--max-keyframes",
        type=int,
        default=240,
        metavar="N",
        help="at most N keyframes in a .glb, evenly spread (default 240; 0 = every frame); "
        "viewers interpolate linearly between them",
    )
    parser.add_argument(
        "--step",
        action="store_true",
        help="in a .glb, hold each keyframe (STEP) instead of interpolating",
    )
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.set_defaults(func=run)


def run(args) -> int:
    from cassi_fit._io import check_outputs
    from cassi_fit.errors import CassiError
    from cassi_fit.export import export_frame, export_glb

    out = Path(args.out)
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise CassiError(f"--out {out}: must end in {', '.join(SUFFIXES)}")
    if args.max_keyframes < 0 or args.max_keyframes == 1:
        raise CassiError(f"--max-keyframes must be 0 or at least 2, got {args.max_keyframes}")
    recording = load_recording_args(args.recording, args)
    check_outputs([out], overwrite=args.force)  # before any work: never an input or data file
    run = run_args(recording, args)
    animation, model = run.animation, run.state.model
    if suffix == ".glb":
        written = export_glb(
            out,
            animation.vertices,
            model.faces,
            animation.times,
            face_material=model.face_material,
            max_keyframes=args.max_keyframes or None,
            interpolation="STEP" if args.step else "LINEAR",
            overwrite=args.force,
            extras={
                "subject": recording.subject,
                "task": recording.task,
                "stride": animation.stride,
                "jaw": animation.jaw_method,
            },
        )
        print(f"wrote {written} ({animation.n_frames} frames)")
        return 0
    if not 0 <= args.frame < animation.n_frames:
        raise CassiError(f"--frame {args.frame}: the animation has {animation.n_frames} frames")
    written = export_frame(
        out,
        animation.vertices[args.frame],
        model.faces,
        face_material=model.face_material,
        overwrite=args.force,
    )
    print(
        f"wrote {written} (frame {args.frame}, data line {animation.frame_index[args.frame] + 1})"
    )
    return 0
