"""The real recordings as the vocal tract's referee: the model's formants against the sound.

    python experiments/acoustic_referee.py [--jw11 DIR] [--emu DIR] --docs docs/generated --force

Per vowel segment of each real recording, the model's relative F1/F2/F3 error (model /
measured - 1, the median over the segment's scored frames; Praat's Burg formants,
``cassi_fit.formant_track``) for:

* ``pellets``: the model driven by the pellets as it is today (default larynx, the
  published area rules unscaled);
* ``calibrated, held out``: the speaker's tract fitted to the other vowel qualities'
  frames (``cassi_fit.acoustic_fit``), scored on this quality's (leave one quality out);
  a recording with one vowel quality has none;
* ``uniform tube``: a uniform tube as long as the model's tract over the recording's
  vowels (median);
* ``tongue at rest``: the model with the jaw and lips from the pellets and the tongue held
  at rest.

JW11 (XRMB, task 5: nine /a/ segments) runs with both jaw pellets and with MNM hidden (one
jaw sensor); the EMU bundle (IPS Munich, speaker mo1, one German sentence; one jaw sensor,
three tongue sensors) with its one. Each is one recording of one speaker. The summary
rows: the median over segments of |error| with a 95 % percentile-bootstrap interval over
segments (``BOOTSTRAP`` resamples), and each method minus each baseline, paired by segment
(``better`` when the interval is below 0). Each recording is heard with the default adult
male norms (``acoustics.speaker_norms``: larynx 30 mm below the hyoid, Praat's ceiling
5000 Hz, the calibration's prior); a note gives the voice's median F0.

A second table (``--emu``): mo1 with the adult male and the adult female norms, each with
the lips at rest on the first valid line (the default) and touching where the lip sensors
are nearest (the run's ``lip_closure``): the four combinations' median |error| over
segments, sensors alone and calibrated held out; a third, by vowel quality, the signed
errors under each norm. The evidence on ``--speaker female``: why it is not the default.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import zlib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from shared_data import EMU_MO1, XRMB_JW11, real_data  # noqa: E402

BOOTSTRAP = 2000
LEVEL = 95
FORMANTS = ("F1", "F2", "F3")
METHODS = ("pellets", "calibrated, held out")
BASELINES = ("uniform tube", "tongue at rest")


def _without_mnm(recording):
    from cassi_fit.pellets import PELLET_NAMES

    track = recording.track
    valid = track.valid.copy()
    valid[:, PELLET_NAMES.index("MNM")] = False
    return dataclasses.replace(recording, track=dataclasses.replace(track, valid=valid))


def _rest_tongue_vertices(run):
    """The animation's frames with the tongue's parameters at the subject's rest."""
    import equinox as eqx
    import jax.numpy as jnp

    from cassi_fit.frames import geometry

    params = run.animation.params
    rest = jnp.broadcast_to(jnp.asarray(run.state.conformation.tongue), params.tongue.shape)
    return geometry(run.state, eqx.tree_at(lambda p: p.tongue, params, rest))[0]


def conditions(result, run) -> dict[str, np.ndarray]:
    """Each condition's F1-F3 ``(m, 3)`` Hz at the result's frames."""
    import jax.numpy as jnp

    from cassi_fit import acoustic_fit, tube
    from cassi_fit.acoustics import model_formants

    out = {"pellets": result.model[:, :3]}
    held, fits = acoustic_fit.leave_one_quality_out(result)
    out["calibrated, held out"] = held if held is not None else np.full_like(result.model[:, :3], np.nan)
    vtl = float(np.median(result.lengths[result.scored].sum(1)))
    areas, lengths = tube.uniform_tube(vtl, 300.0, 40)
    uni = np.asarray(tube.formants_batch(areas[None], lengths[None]).frequency)[0, :3]
    out["uniform tube"] = np.broadcast_to(uni, result.model[:, :3].shape)
    rest_v = _rest_tongue_vertices(run)
    out["tongue at rest"] = model_formants(result.geometry, jnp.asarray(rest_v), result.tract,
                                           result.scale)[0][:, :3]
    return out, fits, vtl


def segment_rows(name: str, result, conds: dict) -> list[dict]:
    """One row per vowel segment and condition: frames scored, median relative F1-F3 error."""
    rows = []
    labels = result.labels
    k, m = 0, len(labels)
    from cassi_fit.acoustics import is_vowel

    while k < m:
        j = k
        while j < m and labels[j] == labels[k]:
            j += 1
        s = np.arange(k, j)[result.scored[k:j]]
        if is_vowel(str(labels[k])) and len(s):
            for cond, f in conds.items():
                err = f[s] / result.measured.frequency[s, :3] - 1.0
                row = {"recording": name, "start_s": round(float(result.times[k]), 3),
                       "vowel": str(labels[k]), "frames": j - k, "scored": len(s), "condition": cond}
                for q, fq in enumerate(FORMANTS):
                    row[f"{fq}_error"] = float(np.nanmedian(err[:, q])) if np.isfinite(err[:, q]).any() else np.nan
                rows.append(row)
        k = j
    return rows


def _rng(*names) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32("/".join(map(str, names)).encode()))


def summary_rows(name: str, rows: list[dict], share: float) -> list[dict]:
    """Median |error| over segments with its bootstrap interval; methods minus baselines."""
    by = {}
    for r in rows:
        if r["recording"] == name:
            by.setdefault(r["condition"], []).append([abs(r[f"{q}_error"]) for q in FORMANTS])
    out = []
    n_seg = len(next(iter(by.values()))) if by else 0
    if not n_seg:
        return out
    idx = _rng(name).integers(0, n_seg, size=(BOOTSTRAP, n_seg))
    lo_p, hi_p = (100 - LEVEL) / 2, 100 - (100 - LEVEL) / 2
    for cond, vals in by.items():
        v = np.asarray(vals)
        if np.all(np.isnan(v)):
            continue
        row = {"recording": name, "compared": cond, "segments": n_seg, "scored share": share}
        for q, fq in enumerate(FORMANTS):
            boot = np.nanmedian(v[idx, q], axis=1)
            lo, hi = np.nanpercentile(boot, [lo_p, hi_p])
            row[f"{fq} median |error|"] = f"{100 * np.nanmedian(v[:, q]):.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"
        out.append(row)
    for meth in METHODS:
        for base in BASELINES:
            if meth not in by or base not in by or np.all(np.isnan(by[meth])):
                continue
            d = np.asarray(by[meth]) - np.asarray(by[base])
            row = {"recording": name, "compared": f"{meth} - {base}", "segments": n_seg,
                   "scored share": share}
            for q, fq in enumerate(FORMANTS):
                boot = np.nanmedian(d[idx, q], axis=1)
                lo, hi = np.nanpercentile(boot, [lo_p, hi_p])
                verdict = "better" if hi < 0 else "worse" if lo > 0 else "tie"
                row[f"{fq} median |error|"] = (f"{100 * np.nanmedian(d[:, q]):+.1f} % "
                                               f"[{100 * lo:+.1f}, {100 * hi:+.1f}] {verdict}")
            out.append(row)
    return out


def run_jw11(folder: Path, one_jaw: bool):
    from cassi_fit.acoustics import recording_acoustics
    from cassi_fit.dataset import load_recording
    from cassi_fit.pipeline import run_recording

    rec = load_recording(next(folder.glob("*.txy")))
    if one_jaw:
        rec = _without_mnm(rec)
    run = run_recording(rec)
    return run, recording_acoustics(run)


def run_emu(folder: Path, **changes):
    """The EMU bundle read as every command reads it (``dataset.load_recording``: the IPS
    Munich sensor map, the occlusal frame estimated from the recording, the sound and the
    ``Segment`` labels inside the bundle); ``changes``: fields of the run's spec."""
    from cassi_fit.acoustics import recording_acoustics
    from cassi_fit.dataset import load_recording
    from cassi_fit.pipeline import run_recording

    run = run_recording(load_recording(next(folder.glob("*_bndl.json"))), **changes)
    return run, recording_acoustics(run)


def _norms_note(norms) -> str:
    f0 = "no voiced frame" if norms.f0_hz is None else f"the voice's median F0 {norms.f0_hz:.0f} Hz"
    return (f"heard with the adult {norms.speaker} norms ({norms.why}: larynx "
            f"{norms.larynx_drop_mm:.0f} mm below the hyoid, formant ceiling "
            f"{norms.ceiling_hz:.0f} Hz); {f0}")


def speaker_rows(runs: dict, computed: dict | None = None) -> tuple[list[dict], dict]:
    """The second table (module docstring): ``runs`` {lips in words: run}; for each, mo1
    heard with the male and the female norms, sensors alone and calibrated held out. Also
    the segments' rows {(lips, speaker): rows} (the third table's). ``computed``
    {(lips, speaker): (acoustics, held-out F1-F3)}: the combinations already computed
    (the first table's mo1: lips at rest, male norms), not computed again."""
    from cassi_fit import acoustic_fit
    from cassi_fit.acoustics import recording_acoustics

    out, segments, computed = [], {}, computed or {}
    for lips, run in runs.items():
        for speaker in ("male", "female"):
            if (lips, speaker) in computed:
                result, held = computed[lips, speaker]
            else:
                result = recording_acoustics(run, speaker=speaker)
                held = acoustic_fit.leave_one_quality_out(result)[0]
            name = f"mo1, {speaker} norms, {lips}"
            conds = {"pellets": result.model[:, :3], "calibrated, held out": held}
            segments[lips, speaker] = segment_rows(name, result, conds)
            for row in summary_rows(name, segments[lips, speaker], round(result.share_scored, 3)):
                out.append({"norms": f"adult {speaker} (larynx {result.norms.larynx_drop_mm:.0f} mm, "
                                     f"ceiling {result.norms.ceiling_hz:.0f} Hz)", "lips": lips,
                            **{k: v for k, v in row.items() if k != "recording"}})
    return out, segments


def quality_rows(male: list[dict], female: list[dict]) -> list[dict]:
    """The third table: per vowel quality, the median over its segments of the signed
    F1-F3 error (%) of the sensors alone (``pellets``) with the male and the female norms."""
    from cassi_fit.acoustic_fit import vowel_quality

    def by_quality(rows):
        out = {}
        for r in rows:
            if r["condition"] == "pellets":
                out.setdefault(vowel_quality(r["vowel"]), []).append([r[f"{q}_error"] for q in FORMANTS])
        return out

    m, f = by_quality(male), by_quality(female)
    rows = []
    for q in sorted(m):
        row = {"quality": q, "segments": len(m[q])}
        for k, fq in enumerate(FORMANTS):
            for name, d in (("male", m), ("female", f)):
                row[f"{fq} {name} %"] = round(100 * float(np.nanmedian(np.asarray(d[q])[:, k])), 1)
        rows.append(row)
    return rows


def speaker_section(args, emu) -> list[str]:
    """The second table's section of the page (empty without the EMU recording); ``emu``
    the first table's ``(run, acoustics, held-out F1-F3)`` of mo1 (lips at rest, the
    default male norms: its row of the second table, not computed again)."""
    from cassi_fit.tables import markdown_text

    if emu is None:
        return []
    closed_run, _ = run_emu(args.emu, lip_closure=True)
    rows, segments = speaker_rows({"lips at rest": emu[0], "lip_closure": closed_run},
                                  {("lips at rest", "male"): emu[1:]})
    rest = quality_rows(segments["lips at rest", "male"], segments["lips at rest", "female"])
    return ["## EMU mo1 with the adult male and female norms, lips at rest and touching", "",
            f"mo1's voice: median F0 {emu[1].norms.f0_hz:.0f} Hz (`--speaker auto` would choose "
            "the female norms). Each row: the sensors drive the model (`pellets`) "
            "or the tract is fitted to the other vowel qualities (`calibrated, held out`); "
            "the median over vowel segments of |error| with its bootstrap interval, as above "
            "(the intervals' resamples differ from the first table's). The default is the male "
            "norms with the lips at rest (the first table's rows).", "",
            markdown_text(rows), "",
            "By vowel quality (lips at rest, sensors alone): the median over the quality's "
            "segments of the signed error (model / measured - 1) with each norm.", "",
            markdown_text(rest, digits=1), ""]


def main(argv=None) -> int:
    from cassi_fit.tables import markdown_text, write_table

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jw11", type=Path, default=real_data(XRMB_JW11))
    ap.add_argument("--emu", type=Path, default=real_data(EMU_MO1))
    ap.add_argument("--docs", type=Path, default=ROOT / "docs" / "generated")
    ap.add_argument("--force", action="store_true")
    args = ap.parse_args(argv)
    jobs = []
    if args.jw11:
        jobs += [("JW11 (two jaw pellets)", lambda: run_jw11(args.jw11, False)),
                 ("JW11 (one jaw sensor: MNM hidden)", lambda: run_jw11(args.jw11, True))]
    if args.emu:
        jobs.append(("EMU mo1 (one jaw sensor)", lambda: run_emu(args.emu)))
    if not jobs:
        print("acoustic_referee: skipped, no real recording (../shared/data absent)")
        return 0
    seg_rows, summ, notes, emu = [], [], [], None
    for name, job in jobs:
        run, result = job()
        conds, fits, vtl = conditions(result, run)
        if name.startswith("EMU"):  # the default norms (male), the lips at rest
            emu = (run, result, conds["calibrated, held out"])
        rows = segment_rows(name, result, conds)
        seg_rows += rows
        summ += summary_rows(name, rows, round(result.share_scored, 3))
        qualities = sorted({str(s) for s in result.labels[result.scored]})
        notes.append(f"- {name}: {len(qualities)} vowel quality(ies) scored ({', '.join(qualities)}); "
                     f"{100 * result.share_scored:.0f} % of the vowels' frames scored; the model's tract "
                     f"{vtl:.0f} mm long (median over scored frames)"
                     + ("; one vowel quality: no held-out calibrated figure" if not fits else
                        "; held-out fits converged: "
                        + ", ".join(f"{q} {'yes' if f.converged else 'no'}" for q, f in fits.items()))
                     + f"; {_norms_note(result.norms)}")
        print(name, "done", flush=True)
    args.docs.mkdir(parents=True, exist_ok=True)
    write_table(seg_rows, args.docs / "acoustic_referee_segments.csv", overwrite=args.force,
                digits=3)
    text = ["<!-- written by `python experiments/acoustic_referee.py --docs docs/generated "
            "--force`; do not edit: `make experiments` rewrites it -->",
            "# The vocal tract's referee: model formants against the real recordings' sound", "",
            "Written by `experiments/acoustic_referee.py` (docstring: the method). Each line is "
            "one recording of one speaker (JW11: XRMB, Westbury et al. 1994; EMU mo1: IPS Munich "
            "EMA demo): no figure here generalises to other speakers. Relative error = model / "
            "measured - 1 (Praat's Burg formants, ceiling 5000 Hz: the adult male norms, the default; "
            "the female norms in the section below); per segment the median over its "
            "scored frames; below, the median over segments of |error| with a 95 % bootstrap "
            "interval over segments, and paired differences (method minus baseline).", "",
            markdown_text(summ), "", "Notes:", "", *notes, "", *speaker_section(args, emu),
            "Per segment and condition: `acoustic_referee_segments.csv` beside this file.", ""]
    out = args.docs / "acoustic_referee.md"
    if out.exists() and not args.force:
        print(f"{out} exists (use --force)")
        return 1
    out.write_text("\n".join(text))
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
