"""``cassi synth OUT_DIR``: write a synthetic XRMB (or articulograph) corpus with ground truth."""

from __future__ import annotations

import argparse

#: ``--format`` values: the XRMB corpus, or the same corpus as an articulograph records it
#: (cassi_fit.ema.synthetic.FORMATS; tests/test_ema_synthetic.py keeps the two in step).
FORMATS = ("xrmb", "est", "est-ascii", "ag501", "wave", "mview", "emu")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "synth",
        help="write a synthetic XRMB corpus with ground truth",
        description=(
            "Write a synthetic X-ray microbeam corpus in the real file formats (pellet "
            ".txy files, PAL.DAT, PHA.DAT, Headmeasures.txt, .wav for speech tasks) plus "
            "ground truth (per recording <task>.truth.csv, per subject anatomy.json). "
            "Deterministic from the seed."
        ),
    )
    parser.add_argument("out_dir", metavar="OUT_DIR", help="folder to write (created if needed)")
    parser.add_argument("--subjects", type=int, default=15, help="number of subjects (default 15)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--noise-scale",
        type=float,
        default=1.0,
        help="multiplies the default measurement noise (0.3 mm SD of the jaw pellet "
        "distance); 0 to 10",
    )
    parser.add_argument(
        "--noise-family",
        default="realistic",
        metavar="FAMILY",
        help="realistic (white plus slow drift, the default), white, or drift",
    )
    parser.add_argument(
        "--jaw-kinematics",
        default="mixed",
        metavar="FAMILIES",
        help="how the jaw moves: mixed (the default: S01 physiological, S02 fixed-condyle, "
        "S03 thrust, S04 physiological, ...), or fixed-condyle, physiological, thrust, or a "
        "comma-separated list of them cycled over the subjects (docs/SYNTHETIC.md)",
    )
    parser.add_argument(
        "--tasks",
        default=None,
        help="comma-separated task names, e.g. tp106,tp040 (default: the standard set; "
        "`--tasks list` shows the library)",
    )
    parser.add_argument(
        "--format",
        default="xrmb",
        choices=FORMATS,
        help="xrmb (the default: .txy pellet files) or an articulograph's format for the same "
        "subjects and tasks, measured in 3D with reference sensors, a known head movement and "
        "a recording frame (docs/EMA.md): est (EST Track binary, 200 Hz), est-ascii (500 Hz), "
        "ag501 (Carstens .pos, 250 Hz), wave (NDI Wave .tsv, 100 Hz), mview (.mat, 100 Hz), "
        "emu (an EMU-SDMS database: SSFF tracks padded with zeros, the sound inside, 200 Hz)",
    )
    parser.add_argument(
        "--sensors",
        default="xrmb",
        choices=("xrmb", "mocha"),
        help="articulograph formats: which sensors are recorded: xrmb (the default: one per "
        "XRMB pellet, two on the jaw, four on the tongue) or mocha (MOCHA-TIMIT's set: one "
        "jaw sensor on the lower incisor; tongue tip, blade and dorsum)",
    )
    parser.add_argument(
        "--lab-like",
        action="store_true",
        help="with --format ag501, wave or mview: recordings as labs' files look (no "
        "upper-incisor sensor, numbered and shuffled channels, unused channels, a device or "
        "lab frame whose midline is not at zero, parasagittal sensors, a loose reference, "
        "dropouts), the truth of each placement in placement.json beside them "
        "(cassi_fit.ema.lab_like)",
    )
    parser.add_argument("--no-audio", action="store_true", help="do not write .wav files")
    parser.add_argument("--force", action="store_true", help="overwrite existing files")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..synth import TASKS, generate_corpus

    if args.tasks is not None and args.tasks.strip().lower() == "list":
        for spec in TASKS.values():
            print(f"{spec.name:8s} {spec.kind:12s} {spec.prompt}")
        return 0
    if args.format == "xrmb" and args.sensors != "xrmb":
        from ..errors import CassiError

        raise CassiError("--sensors chooses an articulograph's sensors: give --format too")
    if getattr(args, "lab_like", False):
        from ..ema.lab_like import write_lab_like_corpus

        tasks = None if args.tasks is None else tuple(
            t.strip() for t in args.tasks.split(",") if t.strip())
        out = write_lab_like_corpus(args.out_dir, format=args.format, n_subjects=args.subjects,
                                    seed=args.seed, overwrite=args.force, tasks=tasks,
                                    audio=not args.no_audio)
        print(f"wrote {args.subjects} lab-like {args.format} sessions to {out} (seed "
              f"{args.seed}; the truth in each placement.json)")
        return 0
    if args.format != "xrmb":
        from ..ema.synthetic import write_ema_corpus

        out = write_ema_corpus(
            args.out_dir,
            format=args.format,
            n_subjects=args.subjects,
            seed=args.seed,
            tasks=args.tasks,
            noise_scale=args.noise_scale,
            audio=not args.no_audio,
            overwrite=args.force,
            jaw_kinematics=args.jaw_kinematics,
            noise_family=args.noise_family,
            sensors=args.sensors,
        )
        print(f"wrote a synthetic {args.format} EMA corpus of {args.subjects} subjects to {out} "
              f"(seed {args.seed})")
        return 0
    out = generate_corpus(
        args.out_dir,
        n_subjects=args.subjects,
        seed=args.seed,
        tasks=args.tasks,
        noise_scale=args.noise_scale,
        audio=not args.no_audio,
        overwrite=args.force,
        jaw_kinematics=args.jaw_kinematics,
        noise_family=args.noise_family,
    )
    print(f"wrote a synthetic corpus of {args.subjects} subjects to {out} (seed {args.seed})")
    return 0
