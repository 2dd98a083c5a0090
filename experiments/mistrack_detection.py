"""Mistrack detection: per shape, how many injected wrong values the detector flags, and
how many clean values it flags, on synthetic recordings and on the real JW11 recording.

    python experiments/mistrack_detection.py [--docs docs/generated] [--trials 60]
        [--real DIR] [--figure DIR] [--small] [--force]

Each trial takes a clean recording, injects one labelled mistrack of one shape
(:data:`SHAPES`, :func:`inject`) into a random pellet at a random place, runs the
detector (``cassi_fit.mistracks.detect``) and counts, among the injected values, those
it flags (the detection rate), and the values it flags that were clean before and are
not injected ("collateral": e.g. the other jaw pellet when one drifts, since the jaw
distance cannot tell which one moved). False alarms are the values flagged in the
untouched recordings, per pellet, over their tracked values.

The shapes are those of issue 24 (real trackers' failures), built here from their
description and not from the detector's tests: a one-frame spike; a pellet set to (0, 0)
for 20 frames (zero dropout) or to an in-range marker (9.999, 9.999) mm for 20 frames;
a pellet stuck at its value for 40 frames; a pellet offset by 5-15 mm for 20 frames
(persistent jump); 10 mm of linear drift over 100 frames, then back (drift); two pellets
trading places for 20 frames (swap: neighbouring tongue pellets, the lips or the jaw
pellets); a 2-8 mm spike on the pellet's first or last tracked line.

Synthetic part: ``cassi_fit.synth.synth_recording`` with its default noise and dropouts
and without its own mistracks, three subjects (one of each jaw family) times the speech
tasks tp011, tp020, tp040, tp069. The generator's own unmarked mistracks (one to three
jumps of 4-10 mm lasting 1-5 frames) are measured as a further row, against the truth it
writes (``JawTruth.mistracked``). Real part (when ``--real`` holds ``jw11_tp005.txy``):
the same injections into JW11 task 5 of the Wisconsin XRMB database (Westbury 1994):
one recording of one speaker. ``--figure DIR`` draws the untouched real recording's
pellets with every flagged value marked, and one example of each shape. ``--small``
(for the tests): one subject, one task.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
from shared_data import JW11_TASK5, XRMB_JW11, real_file

SEED = 0
SUBJECTS = 3
TASKS = ("tp011", "tp020", "tp040", "tp069")
MARKER_MM = (9.999, 9.999)
#: shape -> (pellets it may hit, or None for any)
SHAPES = ("spike", "zero-dropout", "marker-dropout", "stuck", "persistent-jump", "drift",
          "swap", "first-line spike", "last-line spike")
SWAP_PAIRS = ((2, 3), (3, 4), (4, 5), (0, 1), (6, 7))
#: the detection rate is also given per group of pellets (indices in PELLET_NAMES)
GROUPS = {"lips": (0, 1), "tongue": (2, 3, 4, 5), "jaw": (6, 7)}
DOCS_NAME = "mistrack_detection.md"
MAKE_COMMAND = "python experiments/mistrack_detection.py --docs docs/generated --force"


def _find_real(folder) -> Path | None:
    """JW11 task 5 in ``folder`` (``--real``), else where ``shared_data`` finds it; None if absent."""
    path = Path(folder) / JW11_TASK5 if folder else real_file(XRMB_JW11, JW11_TASK5)
    return path if path is not None and path.is_file() else None


# ------------------------------------------------------------------ injections
def _run(tracked: np.ndarray, length: int, rng: np.random.Generator) -> int | None:
    """A start frame such that ``tracked[start:start + length]`` is all True (and not
    at the track's first or last tracked frame), or None."""
    ok = np.convolve(tracked.astype(int), np.ones(length, int), "valid") == length
    ok[: int(np.argmax(tracked)) + 1] = False
    last = len(tracked) - 1 - int(np.argmax(tracked[::-1]))
    ok[max(last - length, 0):] = False
    starts = np.flatnonzero(ok)
    return int(rng.choice(starts)) if starts.size else None


def _direction(rng: np.random.Generator) -> np.ndarray:
    angle = rng.uniform(0.0, 2.0 * np.pi)
    return np.array([np.cos(angle), np.sin(angle)])


def inject(track, shape: str, rng: np.random.Generator):
    """``(track with one mistrack of ``shape``, truth (n, 8) bool, pellet names)``.

    ``shape`` one of :data:`SHAPES`; pellet and place drawn from ``rng`` among values
    tracked in x and y. Raises ``ValueError`` if the track has no room for it."""
    from cassi_fit.pellets import PELLET_NAMES
    from cassi_fit.txy import PelletTrack

    pos = np.array(track.positions, dtype=np.float64)
    tracked = np.asarray(track.valid).all(axis=-1)
    truth = np.zeros(tracked.shape, bool)
    candidates = [p for p in range(8) if tracked[:, p].sum() > 120]
    if not candidates:
        raise ValueError("no pellet is tracked long enough")
    if shape == "swap":
        pairs = [ab for ab in SWAP_PAIRS if all(q in candidates for q in ab)]
        a, b = pairs[int(rng.integers(len(pairs)))]
        start = _run(tracked[:, a] & tracked[:, b], 20, rng)
        frames = slice(start, start + 20)
        pos[frames, a], pos[frames, b] = pos[frames, b].copy(), pos[frames, a].copy()
        truth[frames, [a, b]] = True
        names = (PELLET_NAMES[a], PELLET_NAMES[b])
    else:
        p = int(rng.choice(candidates))
        names = (PELLET_NAMES[p],)
        if shape in ("first-line spike", "last-line spike"):
            k = np.flatnonzero(tracked[:, p])[0 if shape.startswith("first") else -1]
            pos[k, p] += rng.uniform(2.0, 8.0) * _direction(rng)
            truth[k, p] = True
        else:
            length = {"spike": 1, "stuck": 40, "drift": 100}.get(shape, 20)
            start = _run(tracked[:, p], length, rng)
            if start is None:
                raise ValueError(f"no room for {shape}")
            frames = slice(start, start + length)
            if shape == "spike":
                pos[frames, p] += rng.uniform(4.0, 10.0) * _direction(rng)
            elif shape == "zero-dropout":
                pos[frames, p] = 0.0
            elif shape == "marker-dropout":
                pos[frames, p] = MARKER_MM
            elif shape == "stuck":
                pos[frames, p] = pos[start, p]
                frames = slice(start + 1, start + length)  # the first value is still true
            elif shape == "persistent-jump":
                pos[frames, p] += rng.uniform(5.0, 15.0) * _direction(rng)
            elif shape == "drift":
                ramp = np.linspace(0.0, 10.0, length + 1)[1:, None]
                pos[frames, p] += ramp * _direction(rng)
            else:
                raise ValueError(f"unknown shape {shape!r}")
            truth[frames, p] = True
    pos = np.round(pos * 1e3) / 1e3  # micrometres, as the files hold them
    out = PelletTrack(times=track.times, positions=pos, valid=track.valid, path=track.path)
    return out, truth, names


# ------------------------------------------------------------------ measurement
def synthetic_recordings(subjects: int = SUBJECTS, tasks=TASKS, *, own_mistracks=False
                         ) -> list[tuple[str, object, object]]:
    """``[(name, track, truth)]``: clean synthetic recordings (dropouts, no mistracks), or
    with the generator's own mistracks (``own_mistracks``)."""
    from cassi_fit import synth

    out = []
    for index, name in enumerate(synth.subject_names(subjects)):
        anatomy = synth.make_subject(name, np.random.default_rng([SEED, 1, index]))
        for task in tasks:
            track, truth = synth.synth_recording(
                anatomy, task, seed=synth._recording_seed(SEED, index, task),
                mistracks=own_mistracks)
            out.append((f"{name} {task}", track, truth))
    return out


def measure(tracks, trials: int, rng: np.random.Generator, detect: Callable) -> list[dict]:
    """One row per shape: detection rate, collateral, main reasons, over ``trials``
    injections spread over ``tracks``."""
    from cassi_fit.mistracks import REASONS

    clean = [detect(t) for t in tracks]
    rows = []
    for shape in SHAPES:
        hit, total = np.zeros(8, int), np.zeros(8, int)
        collateral = 0
        reason_counts = dict.fromkeys((r.label for r in REASONS), 0)
        for trial in range(trials):
            k = trial % len(tracks)
            injected, truth, _ = inject(tracks[k], shape, rng)
            report = detect(injected)
            hit += (report.flags & truth).sum(axis=0)
            total += truth.sum(axis=0)
            collateral += int((report.flags & ~truth & ~clean[k].flags).sum())
            for r in REASONS:
                reason_counts[r.label] += int((report.has(r) & truth).sum())
        top = sorted((c, lab) for lab, c in reason_counts.items() if c)[::-1][:3]
        groups = {f"{g}_pct": (100.0 * hit[list(ps)].sum() / total[list(ps)].sum()
                               if total[list(ps)].sum() else None)
                  for g, ps in GROUPS.items()}
        rows.append({"shape": shape, "trials": trials, "values": int(total.sum()),
                     "detected_pct": 100.0 * hit.sum() / max(total.sum(), 1), **groups,
                     "collateral_per_trial": collateral / trials,
                     "reasons": ", ".join(f"{lab} {100.0 * c / max(total.sum(), 1):.0f}%"
                                          for c, lab in top)})
    return rows


def false_alarms(tracks, detect: Callable, truths=None) -> dict:
    """Per pellet: flagged values over tracked values (percent) on ``tracks``; with
    ``truths``, the flagged values that are not true mistracks."""
    from cassi_fit.pellets import PELLET_NAMES

    flagged = np.zeros(8, int)
    tracked = np.zeros(8, int)
    for k, track in enumerate(tracks):
        flags = detect(track).flags
        if truths is not None:
            flags = flags & ~truths[k]
        flagged += flags.sum(axis=0)
        tracked += np.asarray(track.valid).all(axis=-1).sum(axis=0)
    row = {p: 100.0 * flagged[i] / max(tracked[i], 1) for i, p in enumerate(PELLET_NAMES)}
    row["all"] = 100.0 * flagged.sum() / max(tracked.sum(), 1)
    row["flagged"] = int(flagged.sum())
    row["tracked"] = int(tracked.sum())
    return row


def own_mistracks_row(detect: Callable, subjects: int = SUBJECTS, tasks=TASKS
                      ) -> tuple[dict, dict]:
    """The generator's own mistracks: ``(shape row, false-alarm row)``."""
    recs = synthetic_recordings(subjects, tasks, own_mistracks=True)
    hit = total = 0
    for _, track, truth in recs:
        flags = detect(track).flags
        hit += int((flags & truth.mistracked).sum())
        total += int(truth.mistracked.sum())
    row = {"shape": "synthetic generator's jumps (4-10 mm, 1-5 frames)", "trials": len(recs),
           "values": total, "detected_pct": 100.0 * hit / max(total, 1),
           "collateral_per_trial": None, "reasons": ""}
    fa = false_alarms([t for _, t, _ in recs], detect, [tr.mistracked for _, _, tr in recs])
    return row, fa


# ------------------------------------------------------------------ figure
def figure(real_track, out_dir: Path, rng: np.random.Generator, detect: Callable) -> list[Path]:
    """The untouched real recording with flagged values marked, and one example per shape
    (x and y of the injected pellet over time, injected values and flagged values)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cassi_fit._io import atomic_write
    from cassi_fit.pellets import PELLET_NAMES

    written = []

    def save(fig, name):
        def write(fh):
            fig.savefig(fh, format="png", dpi=90)
        written.append(atomic_write(out_dir / name, write, overwrite=True, binary=True))
        plt.close(fig)

    report = detect(real_track)
    fig, axes = plt.subplots(8, 2, figsize=(12, 14), sharex=True)
    t = real_track.times
    for p, name in enumerate(PELLET_NAMES):
        for axis in range(2):
            ax = axes[p, axis]
            ax.plot(t, real_track.positions[:, p, axis], lw=0.8)
            bad = report.flags[:, p]
            ax.plot(t[bad], real_track.positions[bad, p, axis], "rx")
            ax.set_ylabel(f"{name} {'xy'[axis]} (mm)", fontsize=7)
    fig.suptitle(f"JW11 task 5, untouched: {int(report.flags.sum())} values flagged (red)")
    save(fig, "mistracks_real_untouched.png")
    fig, axes = plt.subplots(len(SHAPES), 2, figsize=(12, 2.2 * len(SHAPES)))
    for row, shape in enumerate(SHAPES):
        injected, truth, names = inject(real_track, shape, rng)
        flags = detect(injected).flags
        p = PELLET_NAMES.index(names[0])
        for axis in range(2):
            ax = axes[row, axis]
            ax.plot(t, real_track.positions[:, p, axis], color="0.6", lw=0.8, label="true")
            ax.plot(t, injected.positions[:, p, axis], lw=0.8, label="injected")
            ax.plot(t[truth[:, p]], injected.positions[truth[:, p], p, axis], "o", ms=3,
                    mfc="none", label="injected values")
            ax.plot(t[flags[:, p]], injected.positions[flags[:, p], p, axis], "rx", ms=3,
                    label="flagged")
            ax.set_ylabel(f"{shape}\n{names[0]} {'xy'[axis]}", fontsize=7)
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    save(fig, "mistracks_real_shapes.png")
    return written


# ------------------------------------------------------------------ the document
HEADERS = {"shape": "Shape", "trials": "Trials", "values": "Injected values",
           "detected_pct": "Detected (%)", "lips_pct": "lips UL LL (%)",
           "tongue_pct": "tongue T1-T4 (%)", "jaw_pct": "jaw MNI MNM (%)",
           "collateral_per_trial": "Other values flagged, per trial",
           "reasons": "Main reasons (% of injected values)"}


def document(synthetic_rows, real_rows, fa_rows, real_name: str | None,
             size: tuple[int, int] = (SUBJECTS, len(TASKS))) -> str:
    from cassi_fit.pellets import PELLET_NAMES
    from cassi_fit.tables import markdown_text

    fa_columns = ["data", *PELLET_NAMES, "all", "flagged", "tracked"]
    fa_headers = {p: f"{p} (%)" for p in PELLET_NAMES} | {"all": "all (%)",
                                                         "flagged": "values flagged",
                                                         "tracked": "values tracked"}
    parts = [
        f"<!-- written by `{MAKE_COMMAND}`; do not edit: `make experiments` rewrites it -->",
        "# Mistrack detection: detection and false-alarm rates",
        "",
        "Written by `experiments/mistrack_detection.py` (its docstring says how each shape "
        "is injected). Detected: flagged values among the injected ones. Other values "
        "flagged: values flagged in the injected recording that are neither injected nor "
        "flagged in the untouched one (e.g. the other jaw pellet when one drifts).",
        "",
        f"## Synthetic recordings ({size[0]} subjects x {size[1]} speech tasks)",
        "",
        markdown_text(synthetic_rows, list(HEADERS), headers=HEADERS, digits=1),
    ]
    if real_rows is not None:
        parts += [
            f"## The real recording: {real_name}, one recording of one speaker",
            "",
            markdown_text(real_rows, list(HEADERS), headers=HEADERS, digits=1),
        ]
    else:
        parts += ["The real recording (JW11 task 5) was not found: no real part.", ""]
    parts += [
        "## False alarms: values flagged in untouched recordings, per pellet",
        "",
        markdown_text(fa_rows, fa_columns, headers=fa_headers, digits=2),
    ]
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--docs", help=f"write {DOCS_NAME} into this folder")
    ap.add_argument("--trials", type=int, default=60, help="injections per shape and part")
    ap.add_argument("--real", help="folder holding jw11_tp005.txy (default: shared/data/xrmb_jw11 in a folder above)")
    ap.add_argument("--figure", help="write the real recording's figures into this folder")
    ap.add_argument("--small", action="store_true", help="one subject, one task (tests)")
    ap.add_argument("--force", action="store_true", help="replace an existing output")
    args = ap.parse_args(argv)

    from cassi_fit._io import atomic_write
    from cassi_fit.mistracks import detect
    from cassi_fit.txy import read_txy

    out = Path(args.docs) / DOCS_NAME if args.docs else None
    if out is not None and out.exists() and not args.force:
        print(f"{out} exists (use --force)", file=sys.stderr)
        return 1
    size = (1, 1) if args.small else (SUBJECTS, len(TASKS))
    tasks = TASKS[-1:] if args.small else TASKS
    recs = synthetic_recordings(size[0], tasks)
    tracks = [t for _, t, _ in recs]
    synthetic_rows = measure(tracks, args.trials, np.random.default_rng([SEED, 24, 1]), detect)
    own_row, own_fa = own_mistracks_row(detect, size[0], tasks)
    synthetic_rows.append(own_row)
    fa_rows = [{"data": f"synthetic, {len(tracks)} recordings", **false_alarms(tracks, detect)},
               {"data": "synthetic with the generator's jumps, not counting them", **own_fa}]
    real_path = _find_real(args.real)
    real_rows = None
    if real_path is not None:
        real = read_txy(real_path)
        real_rows = measure([real], args.trials, np.random.default_rng([SEED, 24, 2]), detect)
        fa_rows.append({"data": f"real: {real_path.name} (one speaker)",
                        **false_alarms([real], detect)})
        if args.figure:
            for path in figure(real, Path(args.figure), np.random.default_rng([SEED, 24, 3]),
                               detect):
                print(f"wrote {path}")
    text = document(synthetic_rows, real_rows, fa_rows,
                    None if real_path is None else f"{real_path.name} (JW11 task 5)", size)
    if out is not None:
        atomic_write(out, text, overwrite=args.force)
        print(f"wrote {out}")
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
