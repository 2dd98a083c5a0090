"""``cassi view``: one recording as one self-contained web page (``cassi_fit.viewer``)."""

from __future__ import annotations

from pathlib import Path

from ._options import (
    add_accept_mismatch_argument,
    add_model_arguments,
    add_recording_argument,
    load_recording_args,
    run_args,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "view",
        help="write one self-contained web page of a recording (face, sound, labels)",
        description="Animate the face from a recording and write one HTML file that opens "
        "offline in a browser, with nothing to install: the face at every data line, the "
        "measured pellets and the model's sites, the paper's four views as camera presets "
        "(orbit and zoom), part toggles, the midsagittal section, the phone/word labels "
        "(click one to go there), the jaw opening and lip aperture, and the recording's "
        "sound (slowed with the picture at speed 0.5 and 0.25).",
    )
    add_recording_argument(parser)
    parser.add_argument("--out", required=True, metavar="FILE",
                        help="the page to write (.html)")
    add_model_arguments(parser)
    parser.add_argument("--no-sound", action="store_true",
                        help="leave the recording's sound out of the page")
    parser.add_argument("--no-labels", action="store_true",
                        help="leave the labels beside the recording out of the page")
    add_accept_mismatch_argument(parser)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.set_defaults(func=run)


def run(args) -> int:
    from cassi_fit._io import check_outputs
    from cassi_fit.errors import CassiError
    from cassi_fit.viewer import view

    out = Path(args.out)
    if out.suffix.lower() not in (".html", ".htm"):
        raise CassiError(f"--out {out}: the page is written as .html")
    recording = load_recording_args(args.recording, args)
    check_outputs([out], overwrite=args.force)  # before any work: never an input or data file
    if args.stride is None:
        args.stride = 1  # the page holds every data line unless told otherwise
    page = view(run_args(recording, args), labels=not args.no_labels or None,
                sound=not args.no_sound, accept_mismatch=args.accept_mismatch)
    written = page.save(out, overwrite=args.force)
    meta = page.meta
    print(f"wrote {written} ({meta['frames']} frames, {page.size_bytes / 1e6:.1f} MB)")
    return 0
