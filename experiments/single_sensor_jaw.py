"""One jaw sensor: which method predicts the other sensor best? Chosen by held-out evidence.

    python experiments/single_sensor_jaw.py [--real DIR] [--out DIR] [--docs DIR]
                                            [--subjects N] [--force]

Every recording with both jaw pellets (MNI at the lower incisors, MNM at a molar) is fitted
with one of them alone, and each single-sensor method predicts the other; the error is the
distance between the prediction and the measured pellet (mm), over the frames where both are
tracked and neither is mistracked (the same frames for every method: paired). Two sources:

* the real recordings of ``--real`` (default: shared/data/xrmb_jw11 in a folder above the
  checkout, the XRMB speaker
  JW11, task 5: one recording of one speaker; skipped when absent);
* a synthetic corpus made here in memory (``--subjects`` subjects x the speech tasks
  ``TASKS``, ``DURATION_S`` each, no dropouts or mistracks; ``cassi_fit.synth``).

Methods: the trivial baselines (the hidden sensor static at its reference position; moved
with the visible one), the pivot methods with the pivot estimated from the data alone and
with their default one-sensor prior (``jaw_fit.POPULATION_CONDYLE``), "coupled-rotation"
with couplings that never saw the recording scored (real: learned from the synthetic corpus,
or from the other half of the same recording, which is the same speaker and says so;
synthetic: learned from the other synthetic subjects, or the shipped default learned from
JW11), and, as the mark to reach, the two-pellet fixed pivot, which saw the hidden sensor.
Per row: frames, the median error with a 95 % moving-block bootstrap interval (blocks of
``BLOCK_FRAMES`` frames within each recording, ``BOOTSTRAP`` resamples, seeded), and the
95th percentile. It also derives the default couplings (``jaw_fit.DEFAULT_COUPLINGS``) from
the real recording and says whether the shipped numbers match.

Writes ``single_sensor_jaw.csv`` and ``.md`` to ``--out`` (and the Markdown to ``--docs``),
through ``cassi_fit.tables``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from shared_data import XRMB_JW11, real_data

#: shared/data/xrmb_jw11 in the first folder above the checkout that has it
REAL_DEFAULT = real_data(XRMB_JW11) or Path("../shared/data/xrmb_jw11")
TASKS = ("tp011", "tp020", "tp040")  # VCV, words, a sentence: speech
DURATION_S = 5.0  # one length for every synthetic recording: the fits compile once
BLOCK_FRAMES = 73  # 0.5 s: neighbouring frames' errors are correlated
BOOTSTRAP = 400
SENSORS = ("MNI", "MNM")
COLUMNS = ("source", "visible", "method", "prior", "recordings", "not_converged", "frames",
           "median_mm",
           "median_lo_mm", "median_hi_mm", "p95_mm")


def _tracks_real(folder: Path) -> list[tuple[str, str, object]]:
    """``[(name, speaker, track)]`` of every pellet file under ``folder``."""
    from cassi_fit.corpus import dataset_items
    from cassi_fit.txy import read_txy

    return [(f"{i.subject}/{i.task}", i.subject, read_txy(i.path))
            for i in dataset_items(folder)]


def _tracks_synthetic(n_subjects: int) -> list[tuple[str, str, object]]:
    """``[(name, speaker, track)]``: ``n_subjects`` subjects, the jaw-kinematics families of
    ``synth.JAW_KINEMATICS`` in turn (the "speech" family among them, whose parameters were
    measured on the real JW11 recording), each speaking ``TASKS``."""
    from cassi_fit import synth

    out = []
    for s in range(n_subjects):
        name = f"S{s + 1:02d}"
        family = synth.JAW_KINEMATICS[s % len(synth.JAW_KINEMATICS)]
        anatomy = synth.make_subject(name, np.random.default_rng([20, 1, s]),
                                     jaw_kinematics=family)
        for t, task in enumerate(TASKS):
            track, _ = synth.synth_recording(anatomy, task, seed=[20, 2, s, t],
                                             duration_s=DURATION_S, dropouts=False,
                                             mistracks=False)
            out.append((f"{name}/{task} ({anatomy.jaw_kinematics})", name, track))
    return out


def _rotate(theta, p):
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * p[..., 0] + s * p[..., 1], -s * p[..., 0] + c * p[..., 1]], -1)


def _jaw(track):
    from cassi_fit.pellets import pellet_index

    return track.positions[:, [pellet_index(s) for s in SENSORS]]


def _half(track, first: bool):
    """The track with the other half of its frames untracked."""
    from cassi_fit.txy import PelletTrack

    keep = (np.arange(track.n_frames) < track.n_frames // 2) == first
    return PelletTrack(times=track.times, positions=track.positions,
                       valid=track.valid & keep[:, None, None], path=track.path)


def _predictions(track, visible, couplings):
    """``{method label: (predicted hidden (n, 2), prior text, converged)}`` and the scored
    frames. A fit that did not converge is scored as it stands (and counted)."""
    from cassi_fit.jaw_fit import (
        PIVOT_FROM_DATA,
        CoupledRotation,
        FixedPivot,
        SmoothPivot,
        jaw_from_track,
    )
    from cassi_fit.status import Status, fitted

    jaw = _jaw(track)
    v, h = SENSORS.index(visible), 1 - SENSORS.index(visible)
    procrustes = jaw_from_track(track, method="frame-fit")  # both tracked, neither mistracked
    frames = fitted(procrustes.status) & np.isfinite(jaw).all(axis=(1, 2))
    ref = procrustes.reference_frame
    both = jaw_from_track(track, method="fixed-pivot")
    out = {"static (baseline)": (np.broadcast_to(jaw[ref, h], jaw[:, h].shape), "", True),
           "translate with the visible sensor (baseline)":
               (jaw[ref, h] + jaw[:, v] - jaw[ref, v], "", True),
           "two-pellet fixed pivot (saw the hidden sensor)":
               (_rotate(both.theta, jaw[ref, h]) + both.translation, both.prior,
                both.converged)}
    methods = {"fixed-pivot, pivot from the data": FixedPivot(pivot_prior=PIVOT_FROM_DATA),
               "fixed-pivot, default prior": FixedPivot(),
               "smooth-pivot, default prior": SmoothPivot()}
    for label, coupling in couplings.items():
        methods[f"coupled-rotation, {label}"] = CoupledRotation(coupling=coupling)
    for label, method in methods.items():
        fit = jaw_from_track(track, method=method, jaw_sensors=visible,
                             reference_frame=ref)
        ok = fitted(fit.status) | (fit.status == Status.NOT_CONVERGED)  # scored as it stands
        out[label] = (np.where(ok[:, None], fit.hidden_predicted, np.nan), fit.prior,
                      fit.converged)
    return out, frames


def _bootstrap_median(series: list[np.ndarray], seed: int) -> tuple[float, float]:
    """95 % moving-block bootstrap interval of the pooled median (blocks within series)."""
    rng = np.random.default_rng(seed)
    series = [e for e in series if len(e)]
    medians = []
    for _ in range(BOOTSTRAP):
        draw = []
        for e in series:
            b = min(BLOCK_FRAMES, len(e))
            starts = rng.integers(0, len(e) - b + 1, size=int(np.ceil(len(e) / b)))
            draw.append(np.concatenate([e[s:s + b] for s in starts])[:len(e)])
        medians.append(np.median(np.concatenate(draw)))
    lo, hi = np.percentile(medians, [2.5, 97.5])
    return float(lo), float(hi)


def _rows(source, recordings, visible, couplings_for):
    """Table rows of one source and visible sensor; ``couplings_for(speaker, track)`` gives
    the held-out couplings of a recording."""
    errors: dict[str, list[np.ndarray]] = {}
    priors: dict[str, str] = {}
    unconverged: dict[str, int] = {}
    h = 1 - SENSORS.index(visible)
    for _, speaker, track in recordings:
        preds, frames = _predictions(track, visible, couplings_for(speaker, track))
        measured = _jaw(track)[:, h]
        for label, (pred, prior, converged) in preds.items():
            unconverged[label] = unconverged.get(label, 0) + int(not converged)
            use = frames & np.isfinite(pred).all(axis=1)
            errors.setdefault(label, []).append(np.linalg.norm(pred[use] - measured[use], axis=1))
            priors.setdefault(label, prior)
    rows = []
    for k, (label, series) in enumerate(errors.items()):
        pooled = np.concatenate(series)
        lo, hi = _bootstrap_median(series, seed=k)
        rows.append({"source": source, "visible": visible, "method": label,
                     "prior": priors[label], "recordings": len(series),
                     "not_converged": unconverged[label],
                     "frames": int(pooled.size), "median_mm": float(np.median(pooled)),
                     "median_lo_mm": lo, "median_hi_mm": hi,
                     "p95_mm": float(np.percentile(pooled, 95))})
    return rows


def _split_rows(recordings, visible):
    """The real recordings' coupling learned from the other half of the same recording."""
    from cassi_fit.jaw_fit import CoupledRotation, jaw_from_track, learn_jaw_coupling
    from cassi_fit.status import fitted

    h = 1 - SENSORS.index(visible)
    series = []
    for name, _, track in recordings:
        measured = _jaw(track)[:, h]
        both = jaw_from_track(track, method="frame-fit")
        frames = fitted(both.status) & np.isfinite(_jaw(track)).all(axis=(1, 2))
        first = np.arange(track.n_frames) < track.n_frames // 2
        for learn_first in (True, False):
            coupling = learn_jaw_coupling([_half(track, learn_first)], visible,
                                          source=f"the other half of {name}")
            fit = jaw_from_track(track, method=CoupledRotation(coupling=coupling),
                                 jaw_sensors=visible, reference_frame=both.reference_frame)
            use = frames & fitted(fit.status) & (first != learn_first)
            series.append(np.linalg.norm(fit.hidden_predicted[use] - measured[use], axis=1))
    pooled = np.concatenate(series)
    lo, hi = _bootstrap_median(series, seed=99)
    return {"source": "real", "visible": visible,
            "method": "coupled-rotation, learned from the other half of the same recording "
                      "(same speaker)",
            "prior": "2-fold split in time", "recordings": len(recordings), "not_converged": 0,
            "frames": int(pooled.size), "median_mm": float(np.median(pooled)),
            "median_lo_mm": lo, "median_hi_mm": hi, "p95_mm": float(np.percentile(pooled, 95))}


def _coupling_rows(real, synthetic):
    """The couplings learned from each source, and whether the shipped ones match."""
    from cassi_fit.jaw_fit import DEFAULT_COUPLINGS, learn_jaw_coupling

    rows, learned = [], {}
    for sensor in SENSORS:
        syn = learn_jaw_coupling([t for _, _, t in synthetic], sensor,
                                 source="the synthetic corpus")
        mechanical = learn_jaw_coupling([t for name, _, t in synthetic if "(speech)" not in name],
                                        sensor, source="the synthetic corpus, no speech family")
        learned[("synthetic", sensor)] = syn
        learned[("synthetic, mechanical", sensor)] = mechanical
        sources = [("synthetic", syn), ("synthetic, no speech family", mechanical)]
        if real:
            rl = learn_jaw_coupling([t for _, _, t in real], sensor, source="real")
            learned[("real", sensor)] = rl
            sources.append(("real", rl))
        for name, c in sources:
            shipped = DEFAULT_COUPLINGS[sensor]
            same = bool(np.allclose(c.rad_per_mm, shipped.rad_per_mm, rtol=1e-5, atol=1e-9))
            rows.append({"source": name, "sensor": sensor, "rad_per_mm_x": c.rad_per_mm[0],
                         "rad_per_mm_y": c.rad_per_mm[1], "theta_sd_rad": c.theta_sd_rad,
                         "frames": c.frames, "shipped_default": same})
    return rows, learned


def run(real_dir: Path | None, n_subjects: int) -> tuple[list[dict], list[dict]]:
    """The method table and the coupling table."""
    from cassi_fit.jaw_fit import DEFAULT_COUPLINGS, learn_jaw_coupling

    real = _tracks_real(real_dir) if real_dir is not None and real_dir.is_dir() else []
    synthetic = _tracks_synthetic(n_subjects)
    couplings, learned = _coupling_rows(real, synthetic)
    rows = []
    for visible in SENSORS:
        if real:
            def real_couplings(speaker, track, visible=visible):
                return {"learned from the synthetic corpus": learned[("synthetic", visible)],
                        "learned from the synthetic families not tuned to JW11":
                            learned[("synthetic, mechanical", visible)]}

            rows += _rows("real", real, visible, real_couplings)
            rows.append(_split_rows(real, visible))

        def synthetic_couplings(speaker, track, visible=visible):
            others = [t for _, s, t in synthetic if s != speaker]
            loso = learn_jaw_coupling(others, visible, source="the other synthetic subjects")
            return {"learned from the other synthetic subjects": loso,
                    "the shipped default (learned from JW11)": DEFAULT_COUPLINGS[visible]}

        rows += _rows("synthetic", synthetic, visible, synthetic_couplings)
    return rows, couplings


def markdown(rows, couplings, command: str, real_dir) -> str:
    from cassi_fit.tables import markdown_text

    n_synthetic = max((r["recordings"] for r in rows if r["source"] == "synthetic"), default=0)
    digits = {"median_mm": 2, "median_lo_mm": 2, "median_hi_mm": 2, "p95_mm": 2}
    shown = [dict(r, median=f"{r['median_mm']:.2f} [{r['median_lo_mm']:.2f}, "
                            f"{r['median_hi_mm']:.2f}]") for r in rows]
    parts = [f"<!-- written by `{command}`; do not edit -->",
             "# One jaw sensor: predicting the other",
             "",
             "Error of the hidden jaw sensor's predicted position (mm) over the frames where both "
             "are tracked (the same frames for every method). Median with a 95 % moving-block "
             f"bootstrap interval (blocks of {BLOCK_FRAMES} frames), and the 95th percentile. "
             "No coupling is learned from the recording it is scored on, except in the row "
             "that says so (the other half of the same recording). Real: "
             + (f"`{Path(real_dir).name}` (the XRMB speaker JW11, task 5: one recording of one "
                "speaker; what it shows holds for that speaker)."
                if any(r["source"] == "real" for r in rows) else "absent in this run.")
             + f" Synthetic: {n_synthetic} recordings ({', '.join(TASKS)}, {DURATION_S:g} s "
             "each, no dropouts or mistracks) of the subjects made by the script, their jaw "
             "kinematics cycling over the generator's four families; the \"speech\" family's "
             "parameters were measured on JW11 (experiments/synthetic_realism.py), so the "
             "strictly held-out coupling for the real rows is the one learned without it.",
             ""]
    for source in ("real", "synthetic"):
        for visible in SENSORS:
            sel = [r for r in shown if r["source"] == source and r["visible"] == visible]
            if not sel:
                continue
            hidden = SENSORS[1 - SENSORS.index(visible)]
            parts += [f"## {source}: {hidden} predicted from {visible}", "",
                      markdown_text(sel, ["method", "recordings", "not_converged", "frames",
                                          "median", "p95_mm"],
                                    digits=digits, headers={"median": "median [95 % CI]",
                                                            "p95_mm": "95th pct",
                                                            "not_converged": "not converged"}),
                      ""]
    parts += ["## Couplings learned (theta = a . displacement, rad per mm)", "",
              markdown_text(couplings, ["source", "sensor", "rad_per_mm_x", "rad_per_mm_y",
                                        "theta_sd_rad", "frames", "shipped_default"],
                            digits={"rad_per_mm_x": 6, "rad_per_mm_y": 6, "theta_sd_rad": 5}),
              ""]
    return "\n".join(parts)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", default=str(REAL_DEFAULT),
                        help="folder of real recordings with both jaw pellets (skipped if absent)")
    parser.add_argument("--out", default="experiments/output", help="folder for the tables")
    parser.add_argument("--docs", help="also write single_sensor_jaw.md into this folder")
    parser.add_argument("--subjects", type=int, default=8, help="synthetic subjects")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)
    out = Path(args.out)
    targets = [out / "single_sensor_jaw.csv", out / "single_sensor_jaw.md"]
    if args.docs:
        targets.append(Path(args.docs) / "single_sensor_jaw.md")
    existing = [p for p in targets if p.exists()]
    if existing and not args.force:
        print(f"single_sensor_jaw: {existing[0]} exists (pass --force to replace it)",
              file=sys.stderr)
        return 1

    import warnings

    import jax

    jax.config.update("jax_enable_x64", True)  # pivots and sub-mm errors
    from cassi_fit._io import atomic_write
    from cassi_fit.tables import write_table

    real_dir = Path(args.real) if args.real else None
    with warnings.catch_warnings():  # moved first lines are expected in real files
        warnings.simplefilter("ignore", UserWarning)
        rows, couplings = run(real_dir, args.subjects)
    command = "python experiments/single_sensor_jaw.py " + " ".join(argv)
    text = markdown(rows, couplings, command.strip(), real_dir)
    write_table(rows, targets[0], columns=COLUMNS, overwrite=args.force)
    atomic_write(targets[1], text, overwrite=args.force)
    if args.docs:
        atomic_write(targets[2], text, overwrite=args.force)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
