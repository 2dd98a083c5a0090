"""``cassi demo``: the whole pipeline on the synthetic corpus, in one command."""

from __future__ import annotations

import sys
from pathlib import Path

from cassi_fit.options import MODES


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "demo",
        help="animate a jaw-wagging task and a sentence of the synthetic corpus",
        description="Create the synthetic corpus if it is absent, calibrate one subject's "
        "face (lip thickness, face width, jaw shape), animate its jaw-wagging task and a "
        "spoken sentence with the tongue and lips kept out of the teeth and palate, and "
        "write to --out: the two videos (the sentence with its sound), the five views "
        "(the paper's four and the midsagittal section) as stills, the sentence as a .glb, a plot of the paper's closed-form jaw rotation "
        "against least-squares pivot fits, and a still of CASSI-like against calibrated "
        "with collisions. Re-running replaces the demo's own files in --out.",
    )
    parser.add_argument(
        "--out", default="demo_output", metavar="DIR", help="output folder (default demo_output)"
    )
    parser.add_argument(
        "--size",
        default="640x480",
        metavar="WxH",
        help="video size in pixels, the five views as a 3x2 grid (default 640x480)",
    )
    parser.add_argument(
        "--stride",
        type=int,
        default=1,
        metavar="N",
        help="use every Nth data line (default 1: every line)",
    )
    parser.add_argument(
        "--subject", metavar="NAME", help="which synthetic subject (default: the first)"
    )
    parser.add_argument(
        "--mode", choices=MODES, default="improved",
        help="how the videos are made: improved (default: calibrated, collisions projected) "
        "or cassi (every choice of the paper: flat tongue, anchored back, no collisions; "
        "docs/CASSI_MODE.md); the comparison still is CASSI mode against the calibrated face",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)


def _corpus_recordings(subject):
    from cassi_fit import synth
    from cassi_fit.dataset import Dataset
    from cassi_fit.errors import CassiError

    dataset = Dataset(synth.ensure_default_corpus())
    subjects = dataset.subjects()
    subject = subject or subjects[0]
    if subject.upper() not in [s.upper() for s in subjects]:
        raise CassiError(f"--subject {subject}: the synthetic corpus has {', '.join(subjects)}")
    tasks = {t.lower() for t in dataset.tasks(subject)}
    wanted = (synth.JAW_WAGGING_TASK, synth.SENTENCE_TASK)
    missing = [t for t in wanted if t.lower() not in tasks]
    if missing:
        raise CassiError(
            f"{dataset.root if hasattr(dataset, 'root') else 'corpus'}: subject "
            f"{subject} has no task {', '.join(missing)}"
        )
    return [dataset.load(subject, task) for task in wanted]


def jaw_plot(path, state, animation, *, title="", labels=None):
    """Closed-form jaw (theta, pivot) per frame against the fixed- and smooth-pivot fits,
    the labelled segments shaded (``reports.jaw_comparison_plot``)."""
    import numpy as np

    from cassi_fit.reports import jaw_comparison_plot

    return jaw_comparison_plot(path, np.asarray(state.reference_jaw),
                               np.asarray(animation.pellets_measured)[:, 6:8],
                               np.asarray(animation.times), labels=labels, title=title)


def _comparison(path: Path, run, size, caption="calibrated + collisions"):
    """Side by side at the frame where the CASSI-mode tongue is deepest in the front
    teeth: the CASSI mode (``run_spec.CASSI``) and the demo's run."""
    import numpy as np

    from cassi_fit.pipeline import run_recording
    from cassi_fit.render import Renderer, save_png

    animation = run.animation
    cassi_run = run_recording(run.recording, "cassi", stride=run.spec.stride)
    state, cassi = cassi_run.state, cassi_run.animation
    depth = np.maximum(cassi.penetration["tongue_upper_front"],
                       cassi.penetration["tongue_lower_front"])
    k = int(np.argmax(depth))
    width, height = size
    renderer = Renderer(state.model, size=(width // 2 * 2, height), views=("inside", "front"))
    t = float(cassi.times[k])
    left = renderer.render(cassi.vertices[k], caption=(
        f"CASSI mode, t={t:.2f} s: tongue {depth[k]:.1f} mm into the front teeth"))
    after = max(float(animation.penetration_after["tongue_upper_front"][k]),
                float(animation.penetration_after["tongue_lower_front"][k]))
    right = renderer.render(animation.vertices[k], caption=(
        f"{caption}: {after:.1f} mm"))
    return save_png(path, np.concatenate([left, right], axis=0), overwrite=True)


def _stills(out: Path, renderer, recording, animation):
    """The five views alone and the grid, at the frame of widest jaw opening (the
    midsagittal view with the pellets' trails of the last ``recording_video.TRAIL_S``)."""
    import numpy as np

    from cassi_fit import recording_video as video
    from cassi_fit.render import save_png

    k = int(np.argmax(np.asarray(animation.params.jaw_theta)))
    stem = f"{recording.subject}_{recording.task}"
    written = []
    markers = {
        "measured": np.asarray(animation.pellets_measured[k]),
        "model": np.asarray(animation.pellets_model[k]),
    }
    back = video.trail_frames(animation)
    trails = {"measured": np.asarray(animation.pellets_measured[max(k - back, 0) : k + 1])}
    views = renderer.render_views(animation.vertices[k], markers=markers, trails=trails,
                                  time=float(animation.times[k]))  # fmt: skip
    for view, image in views.items():
        written.append(save_png(out / f"{stem}_{view}.png", image, overwrite=True))
    (grid,) = video.animation_frames(
        animation,
        renderer,
        subject=recording.subject,
        task=recording.task,
        markers=True,
        progress=False,
        indices=[k],
    )
    written.append(save_png(out / f"{stem}_grid.png", grid, overwrite=True))
    return written


def run(args) -> int:
    from cassi_fit import recording_video as video
    from cassi_fit.export import export_glb
    from cassi_fit.labels import labels_for
    from cassi_fit.options import VIEWS
    from cassi_fit.pipeline import run_recording
    from cassi_fit.render import Renderer
    from cassi_fit.run_spec import run_spec

    from ._options import parse_size

    size = parse_size(args.size)
    cassi = args.mode == "cassi"
    # the demo's run: calibrated with collisions projected, or every choice of the paper
    spec = run_spec(args.mode, stride=args.stride, collisions=None if cassi else "project")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    renderer = None
    recordings = _corpus_recordings(args.subject)  # [jaw wagging, sentence]
    if not cassi:
        import warnings

        from cassi_fit.calibrate import calibrate_subject, calibration_path, write_calibration
        from cassi_fit.calibration import CalibrationWarning

        print(f"calibrating {recordings[0].subject} ...", file=sys.stderr)
        with warnings.catch_warnings():  # said once below, beside the outputs
            warnings.simplefilter("ignore", CalibrationWarning)
            calibration = calibrate_subject(recordings)
        for line in calibration.problems():
            print(f"cassi: warning: {calibration.subject}: calibration: {line}",
                  file=sys.stderr)
        written.append(write_calibration(calibration_path(out, calibration.subject),
                                         calibration, overwrite=True))
        spec = spec.replace(calibration=calibration)
    try:
        for recording in recordings:
            print(f"animating {recording.subject} {recording.task} ({args.mode} mode) ...",
                  file=sys.stderr)
            run = run_recording(recording, spec)
            renderer = renderer or Renderer(run.state.model, size=size, views=VIEWS)
            stem = f"{recording.subject}_{recording.task}"
            written.append(video.write_recording_video(
                out / f"{stem}.mp4", run, renderer=renderer, progress=not args.quiet,
                overwrite=True))
            written += _stills(out, renderer, recording, run.animation)
            if recording is recordings[-1]:  # the sentence: CASSI-like against this, and glTF
                written.append(_comparison(
                    out / f"{stem}_cassi_vs_{args.mode if cassi else 'calibrated'}.png", run,
                    size, "CASSI mode" if cassi else "calibrated + collisions"))
                written.append(export_glb(
                    out / f"{stem}.glb", run.animation.vertices, run.state.model.faces,
                    run.animation.times, face_material=run.state.model.face_material,
                    overwrite=True, extras={"subject": recording.subject, "task": recording.task}))
            else:  # jaw wagging: the closed form against the fits
                written.append(jaw_plot(out / f"{stem}_jaw.png", run.state, run.animation,
                                        title=f"{stem}: closed form vs pivot fits",
                                        labels=labels_for(recording.path)))
    finally:
        if renderer is not None:
            renderer.close()
    print(f"demo written to {out.resolve()}:")
    for path in written:
        print(f"  {path}")
    return 0
