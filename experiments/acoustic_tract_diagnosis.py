"""Where the model's formant errors on the real recordings come from (issue 29's diagnosis).

    python experiments/acoustic_tract_diagnosis.py [--jw11 DIR] [--emu DIR] --docs docs/generated --force

Writes ``acoustic_tract_diagnosis.md``: three tables, each from one recording of one
speaker (the referee's recordings, read as ``acoustic_referee.py`` reads them).

1. **JW11's pharynx** (XRMB, nine /a/): for the tongue base as the template placed it
   (against ``pharynx.DEFAULT_WALL``) and as the area function carries it to JW11's wall
   (``area_function``, *the tongue base*): the narrowest pharyngeal section and the
   pharynx's mean area (mm^2, median over the scored frames), and the median signed F1-F3
   errors. Then the same with the pharynx's areas scaled down (``pharynx_scale``), to show
   how narrow the unseen pharynx of these /a/ would have to be for F1: a diagnosis, not a
   fit (nothing here is used by the model).
2. **What moves JW11's formants**: ``d log F / d log alpha`` per area-rule region
   (``jax.jacfwd`` of the formants in each region's scale, the sections' regions held),
   the mean over the scored frames: the regions whose width the formants depend on.
3. **EMU mo1 by vowel quality** (IPS Munich, one sentence, no palate or wall trace: the
   palate from its tongue sensors' upper envelope, ``palate.envelope_palate``, said in a
   line below the table; the default wall): the
   median signed F1-F3 errors per quality, front vowels first, the share of frames
   whose narrowest pharyngeal section is at most ``CLOSED_MM2`` (a pharynx pressed shut),
   and the model's lip opening (the upper lip's lowest midsagittal point above the lower
   lip's highest: negative where the lips cross) and incisor opening (mm, medians).
   JW11's /a/ has both given in a line below table 1 for comparison, with its wall's
   distance behind the template's; a line below table 3 gives mo1's upper-lip sensor's
   height above its lower-lip sensor and the model's lip opening in its bilabial closures
   /p b m/ (where the lips touch), and the one below table 1 JW11's UL above its LL.
4. **EMU mo1 with its lips touching where their sensors are nearest** (the run's
   ``lip_closure``, ``lips.lips_touching``; not the default): table 3's columns, the
   line saying what was estimated and the model's lip opening in /p b m/ again.
5. **What the lips touching does to the referee's figures**: for mo1 with the lips at rest
   on the first valid line (the default) and touching, the median over vowel segments of
   |error| with its bootstrap interval, for the sensors alone and calibrated held out
   (``acoustic_referee.py``'s method, its ``pellets`` and ``calibrated, held out``).
6. **The model's vowels beside Story (2008)'s MRI area functions** (``tube.STORY_2008``,
   one male speaker): mo1's /i:/ and /u:/ and JW11's /a/, the model's median area function
   over the quality's scored frames (per section: a summary, not one frame) with the
   tongue root as the pellets leave it and as it keeps the midsagittal area (the default),
   and Story's stretched to the model's length, as mean areas over six stretches by their
   distance from the glottis (``STRETCHES``, fractions of the tract's length: about the
   epilarynx, the hypopharynx, the pharynx, the oropharynx behind the velum, the palatal
   stretch and the front cavity with the lips); then F1-F3 (Hz) of the measured (median),
   Story's tract, the model's and the model's with each stretch replaced by Story's: which
   stretch's areas hold the error.
7. **Variants** (every variant tried, none chosen by these figures): the tongue root as the
   pellets leave it (before), keeping the rest midsagittal area (the default), keeping the
   recording's median midsagittal area (a per-speaker reference from the sensors over all
   frames), and Soquet's larynx rule confined to ``EPILARYNX_MM`` above the glottis (the
   epilaryngeal tube; above it the low-pharynx rule) with the root before and now: per
   vowel quality of mo1 and for JW11's /a/, the median signed F1-F3 errors, the root's
   shift forward and the pharynx's mean area; then the referee's median |error| over
   segments for each variant (sensors alone; for mo1 also calibrated held out where the
   variant is a geometry the calibration can take), and each variant minus the root
   before, paired by segment, with the referee's bootstrap interval.
8. **The lips' width narrowed by their protrusion** (``area_function``, *the lips' width*:
   Maeda 1990's lip model, the default): JW11's /a/ and mo1 by vowel quality with the
   lips' sections as the published labial rule gives them (before) and narrowed as the
   lips come forward (now), the columns of 7; then the referee's figures of both and now
   minus before, paired by segment (mo1 also calibrated held out). Tables 3, 4 and 7 give
   the lips' protrusion (``lips forward mm``: ``area_function.lip_protrusion``, subject mm;
   0 in table 10's rows without the narrowing, which has no rest to measure it from).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from shared_data import EMU_MO1, XRMB_JW11, real_data  # noqa: E402

FRAMES = 60  # JW11 frames analysed (an even subsample of the scored ones)
PHARYNX_SCALES = (1.0, 0.5, 0.25, 0.12, 0.06)
CLOSED_MM2 = 20.0
FRONT = ("i", "e", "E", "aI")  # German front (and fronting) vowel qualities of mo1
PHARYNX = (1, 2, 3)  # area_function.REGIONS: low, mid, upper (oro-) pharynx
#: Table 6's stretches of the tract (fractions of its length from the glottis): about the
#: epilarynx, the hypopharynx, the pharynx, the oropharynx behind the velum, the palatal
#: stretch and the front cavity with the lips (of a 169 mm tract: 0-20, 20-44, 44-74,
#: 74-98, 98-135 and 135-169 mm, where Story's /i/ has them)
STRETCHES = (("epilarynx", 0.0, 0.12), ("hypopharynx", 0.12, 0.26), ("pharynx", 0.26, 0.44),
             ("oropharynx", 0.44, 0.58), ("palatal", 0.58, 0.80), ("front and lips", 0.80, 1.0))
#: Soquet et al.'s larynx rule within this far of the glottis in table 7's larynx variant:
#: the epilaryngeal tube, about 2 cm in adult men (Story's /i/: its narrow first 15-20 mm)
EPILARYNX_MM = 20.0


def _pick(n_total: int, n: int) -> np.ndarray:
    return np.unique(np.round(np.linspace(0, n_total - 1, min(n, n_total))).astype(int))


def _tract(geometry, vertices, tract, scale):
    import jax.numpy as jnp

    from cassi_fit import area_function as af
    from cassi_fit import tube

    areas, lengths, regions = af.area_functions(geometry, jnp.asarray(vertices), tract, scale)
    f = np.asarray(tube.formants_batch(areas, lengths).frequency)[:, :3]
    return np.asarray(areas), np.asarray(regions), f


def _pharynx_stats(areas, regions):
    ph = np.isin(regions, PHARYNX)
    narrow = np.where(ph, areas, np.inf).min(1)
    mean = np.where(ph, areas, 0).sum(1) / np.maximum(ph.sum(1), 1)
    return narrow, mean


def jw11_rows(result) -> tuple[list[dict], list[dict]]:
    """Tables 1 and 2 (module docstring)."""
    import equinox as eqx

    idx = np.nonzero(result.scored)[0]
    idx = idx[_pick(len(idx), FRAMES)]
    v, meas = np.asarray(result.vertices)[idx], result.measured.frequency[idx, :3]
    g = result.geometry
    before = dataclasses.replace(g, rest_midsagittal_mm2=None)
    template = dataclasses.replace(before, base_weight=None, base_shift_x=None)
    rows = []
    for name, root, geom in (
            ("tongue base as the template placed it", "before", template),
            ("tongue base carried to JW11's wall", "before", before),
            ("tongue base carried to JW11's wall", "keeps the midsagittal area", g)):
        for ps in PHARYNX_SCALES if geom is g else (1.0,):
            tract = eqx.tree_at(lambda t: t.pharynx_scale, result.tract, ps * result.tract.pharynx_scale)
            areas, regions, f = _tract(geom, v, tract, result.scale)
            narrow, mean = _pharynx_stats(areas, regions)
            err = np.nanmedian(f / meas - 1.0, axis=0)
            rows.append({"tongue base": name, "tongue root": root, "pharynx areas x": ps,
                         "narrowest pharynx mm^2": float(np.median(narrow)),
                         "mean pharynx mm^2": float(np.median(mean)),
                         **{f"F{q + 1} signed error %": 100 * float(err[q]) for q in range(3)}})
    return rows, _elasticities(g, v, result)


def _elasticities(geometry, v, result) -> list[dict]:
    import jax
    import jax.numpy as jnp

    from cassi_fit import area_function as af
    from cassi_fit import tube

    areas, lengths, regions = (np.asarray(x) for x in af.area_functions(
        geometry, jnp.asarray(v), result.tract, result.scale))
    n_reg = len(af.REGIONS)

    def log_f(log_scale, a, ln, reg):
        return jnp.log(tube.formants(a * jnp.exp(log_scale[reg]), ln).frequency[:3])

    jac = jax.jit(jax.vmap(jax.jacfwd(log_f), in_axes=(None, 0, 0, 0)))
    e = np.asarray(jac(jnp.zeros(n_reg, areas.dtype), jnp.asarray(areas), jnp.asarray(lengths),
                       jnp.asarray(regions)))
    mean = np.nanmean(e, axis=0)  # (3, regions)
    share = np.array([(regions == r).mean() for r in range(n_reg)])
    return [{"region": af.REGIONS[r], "share of sections": float(share[r]),
             **{f"dlogF{q + 1}/dlog alpha": float(mean[q, r]) for q in range(3)}}
            for r in range(n_reg)]


def emu_rows(result) -> list[dict]:
    """Table 3 (module docstring)."""
    from cassi_fit.acoustic_fit import vowel_quality
    from cassi_fit.area_function import lip_opening

    quality = np.array([vowel_quality(str(s)) for s in result.labels])
    narrow, _ = _pharynx_stats(result.areas, np.asarray(_regions(result)))
    err = result.relative_error
    v = np.asarray(result.vertices)
    g = result.geometry
    # the lips' opening (mm): the upper lip's lowest midsagittal point above the lower lip's
    # highest (negative: the lips cross); the jaw's: the lower incisor below the upper
    lips = lip_opening(g, v)
    jaw = v[:, g.upper[0], 1] - v[:, g.lower[0], 1]
    shift = _root_shift_mm(result)
    forward = _lips_forward_mm(result)
    rows = []
    qualities = sorted(set(quality[result.scored]), key=lambda q: (q not in FRONT, q))
    for q in qualities:
        m = result.scored & (quality == q)
        med = np.nanmedian(err[m], axis=0)
        rows.append({"quality": q, "front": q in FRONT, "frames": int(m.sum()),
                     "measured F2 Hz": float(np.median(result.measured.frequency[m, 1])),
                     "model F2 Hz": float(np.median(result.model[m, 1])),
                     **{f"F{k + 1} signed error %": 100 * float(med[k]) for k in range(3)},
                     f"pharynx <= {CLOSED_MM2:.0f} mm^2": float(np.mean(narrow[m] <= CLOSED_MM2)),
                     "root forward mm": float(np.median(shift[m])),
                     "lip opening mm": float(np.median(lips[m] / result.scale)),
                     "incisors apart mm": float(np.median(jaw[m] / result.scale)),
                     "lips forward mm": float(np.median(forward[m]))})
    return rows


def lip_closure_rows(default, closed, default_held) -> list[dict]:
    """Table 5 (module docstring): ``default`` and ``closed`` mo1's acoustics results;
    ``default_held`` the default's held-out formants."""
    import acoustic_referee as ref

    from cassi_fit import acoustic_fit

    rows = []
    for lips, result in (("at rest on the first valid line (default)", default),
                         ("touching where their sensors are nearest", closed)):
        held = default_held if result is default else acoustic_fit.leave_one_quality_out(result)[0]
        conds = {"pellets": result.model[:, :3], "calibrated, held out": held}
        for r in ref.summary_rows("mo1", ref.segment_rows("mo1", result, conds), 0.0):
            rows.append({"lips": lips, "compared": r["compared"], "segments": r["segments"],
                         **{f"{q} median |error|": r[f"{q} median |error|"]
                            for q in ref.FORMANTS}})
    return rows


def _openings(result) -> str:
    """JW11's lip and incisor openings over its scored frames, in words."""
    from cassi_fit.area_function import lip_opening

    v, g = np.asarray(result.vertices)[result.scored], result.geometry
    lips = lip_opening(g, v)
    jaw = v[:, g.upper[0], 1] - v[:, g.lower[0], 1]
    return (f"JW11's wall lies {-float(g.base_shift_x):.1f} mm behind the template's at the "
            "hyoid end's height (the tongue base's carry, model mm). JW11's /a/ (scored frames, "
            f"medians): lip opening {np.median(lips) / result.scale:.1f} mm, incisors "
            f"{np.median(jaw) / result.scale:.1f} mm apart.")


def _bilabials(result) -> str:
    """The model's lip opening in the recording's bilabial closures /p b m/ (where the lips
    touch), in words: a check on the lips' rest that no formant enters."""
    from cassi_fit.area_function import lip_opening

    v, g = np.asarray(result.vertices), result.geometry
    lips = lip_opening(g, v)
    m = np.isin(np.asarray([str(s) for s in result.labels]), ("p", "b", "m"))
    if not m.any():
        return "No bilabial closure /p b m/ is labelled."
    mm = lips[m] / result.scale
    return (f"In its bilabial closures /p b m/ ({int(m.sum())} frames), where the lips touch, "
            f"the model's lips are {np.median(mm):.1f} mm apart (median; least "
            f"{np.min(mm):.1f} mm).")


def _lip_sensors(run) -> float:
    """The recording's upper-lip sensor above its lower-lip sensor (mm, median over the
    frames where both are tracked, the recording's own frame)."""
    track = run.recording.track
    p, ok = np.asarray(track.positions, float), np.asarray(track.valid)
    both = ok[:, 0].all(-1) & ok[:, 1].all(-1) if ok.ndim == 3 else ok[:, 0] & ok[:, 1]
    return float(np.median(p[both, 0, 1] - p[both, 1, 1]))


def _variant_geometries(result) -> dict:
    """Table 7's geometry variants of a result's subject (module docstring)."""
    import jax
    import jax.numpy as jnp

    from cassi_fit import area_function as af

    g = result.geometry
    v = jnp.asarray(result.vertices)
    median = float(np.median(np.asarray(jax.vmap(lambda x: af.midsagittal_area(g, x))(v))))
    return {"root before": dataclasses.replace(g, rest_midsagittal_mm2=None),
            "root keeps the rest area (default)": g,
            "root keeps the recording's median area": dataclasses.replace(
                g, rest_midsagittal_mm2=np.asarray(median, np.float64))}


def _epilarynx_areas(areas, lengths, regions):
    """Soquet et al.'s larynx rule kept within ``EPILARYNX_MM`` of the glottis; the larynx
    sections above it take the low-pharynx rule at their distance (table 7's variant)."""
    from cassi_fit import area_function as af

    areas, lengths, regions = (np.asarray(x) for x in (areas, lengths, regions))
    x = np.cumsum(lengths, -1) - lengths / 2
    a0, b0, a1, b1 = af.ALPHA[0], af.BETA[0], af.ALPHA[1], af.BETA[1]
    d_cm = (areas / 100.0 / a0) ** (1.0 / b0)  # the larynx rule inverted: the distance
    above = (regions == 0) & (x > EPILARYNX_MM) & (areas > af.MIN_AREA_MM2)
    return np.where(above, 100.0 * a1 * d_cm ** b1, areas)


def _with_geometry(result, geometry):
    """``result`` with the model's formants, areas and lengths of another geometry."""
    import jax.numpy as jnp

    from cassi_fit.acoustics import model_formants

    f, bw, a, ln = model_formants(geometry, jnp.asarray(result.vertices), result.tract, result.scale)
    return dataclasses.replace(result, model=f, model_bandwidth=bw, areas=a, lengths=ln,
                               geometry=geometry)


def _with_epilarynx(result):
    from cassi_fit import tube

    a = _epilarynx_areas(result.areas, result.lengths, _regions(result))
    f = np.asarray(tube.formants_batch(a, result.lengths).frequency)
    return dataclasses.replace(result, model=f, areas=a)


def variant_results(result) -> dict:
    """Table 7's variants of one recording's result (module docstring)."""
    out = {name: _with_geometry(result, g) for name, g in _variant_geometries(result).items()}
    out[f"larynx rule within {EPILARYNX_MM:.0f} mm of the glottis, root before"] = _with_epilarynx(
        out["root before"])
    out[f"larynx rule within {EPILARYNX_MM:.0f} mm of the glottis, root keeps the rest area"] = (
        _with_epilarynx(out["root keeps the rest area (default)"]))
    return out


def _lips_forward_mm(result):
    """The lips' protrusion of every frame (subject mm; ``area_function.lip_protrusion``)."""
    import jax
    import jax.numpy as jnp

    from cassi_fit import area_function as af

    g = result.geometry
    v = jnp.asarray(result.vertices)
    return np.asarray(jax.vmap(lambda x: af.lip_protrusion(g, x))(v)) / result.scale


def _root_shift_mm(result):
    import jax
    import jax.numpy as jnp

    from cassi_fit import area_function as af

    g = result.geometry
    return np.asarray(jax.vmap(lambda v: af.root_shift(g, v))(jnp.asarray(result.vertices))) / result.scale


def variant_quality_rows(name: str, variants: dict) -> list[dict]:
    """Table 7 (module docstring): per variant and vowel quality."""
    from cassi_fit.acoustic_fit import vowel_quality

    rows = []
    for variant, r in variants.items():
        quality = np.array([vowel_quality(str(s)) for s in r.labels])
        shift = _root_shift_mm(r)
        forward = _lips_forward_mm(r)
        _, mean = _pharynx_stats(np.asarray(r.areas), np.asarray(_regions(r)))
        err = r.relative_error
        for q in sorted(set(quality[r.scored]), key=lambda q: (q not in FRONT, q)):
            m = r.scored & (quality == q)
            med = np.nanmedian(err[m], axis=0)
            rows.append({"recording": name, "variant": variant, "quality": q, "frames": int(m.sum()),
                         "root forward mm": float(np.median(shift[m])),
                         "mean pharynx mm^2": float(np.median(mean[m])),
                         **{f"F{k + 1} signed error %": 100 * float(med[k]) for k in range(3)},
                         "lips forward mm": float(np.median(forward[m]))})
    return rows


def variant_referee_rows(name: str, variants: dict, held_out: dict,
                         base_name: str = "root before") -> list[dict]:
    """Table 8 (module docstring): the referee's figures per variant; ``held_out``
    {variant: (m, 3) Hz} where computed; each variant paired with ``base_name``'s."""
    import acoustic_referee as ref

    rows, per_segment = [], {}
    for variant, r in variants.items():
        conds = {"pellets": r.model[:, :3]}
        if held_out.get(variant) is not None:
            conds["calibrated, held out"] = held_out[variant]
        seg = ref.segment_rows(name, r, conds)
        per_segment[variant] = seg
        for row in ref.summary_rows(name, seg, 0.0):
            rows.append({"recording": name, "variant": variant, "compared": row["compared"],
                         "segments": row["segments"],
                         **{f"{q} median |error|": row[f"{q} median |error|"] for q in ref.FORMANTS}})
    # each variant minus the baseline, paired by segment (the referee's bootstrap)
    base = per_segment.get(base_name)
    for variant, seg in per_segment.items():
        if base is None or variant == base_name:
            continue
        for cond in ("pellets", "calibrated, held out"):
            a = [r for r in seg if r["condition"] == cond]
            b = [r for r in base if r["condition"] == cond]
            if not a or len(a) != len(b):
                continue
            idx = ref._rng(name, variant, cond).integers(0, len(a), size=(ref.BOOTSTRAP, len(a)))
            row = {"recording": name, "variant": f"{variant} - {base_name}", "compared": cond,
                   "segments": len(a)}
            for q in ref.FORMANTS:
                d = np.array([abs(x[f"{q}_error"]) - abs(y[f"{q}_error"]) for x, y in zip(a, b, strict=True)])
                boot = np.nanmedian(d[idx], axis=1)
                lo, hi = np.nanpercentile(boot, [(100 - ref.LEVEL) / 2, 100 - (100 - ref.LEVEL) / 2])
                verdict = "better" if hi < 0 else "worse" if lo > 0 else "tie"
                row[f"{q} median |error|"] = (f"{100 * np.nanmedian(d):+.1f} % [{100 * lo:+.1f}, "
                                              f"{100 * hi:+.1f}] {verdict}")
            rows.append(row)
    return rows


def _median_tract(r, m):
    a = np.median(np.asarray(r.areas)[m], 0)
    ln = np.median(np.asarray(r.lengths)[m], 0)
    return a, ln


def story_rows(cases) -> tuple[list[dict], list[dict]]:
    """Table 6 (module docstring). ``cases``: ``(name, story vowel, before result, now
    result, frame mask)``."""
    import jax.numpy as jnp

    from cassi_fit import tube

    def formants(a, ln):
        return np.asarray(tube.formants(jnp.asarray(a, float), jnp.asarray(ln, float)).frequency)[:3]

    areas_rows, formant_rows = [], []
    for name, vowel, before, now, m in cases:
        step_cm, cm2 = tube.STORY_2008[vowel]
        story = np.asarray(cm2) * 100.0
        xs = (np.arange(len(story)) + 0.5) * step_cm * 10.0
        a0, l0 = _median_tract(before, m)
        a1, l1 = _median_tract(now, m)
        total = float(l1.sum())
        x = np.cumsum(l1) - l1 / 2
        s1 = np.interp(x / total * len(story) * step_cm * 10.0, xs, story)  # stretched
        x0 = np.cumsum(l0) - l0 / 2
        for stretch, lo, hi in STRETCHES:
            sel1 = (x >= lo * total) & (x < hi * total)
            sel0 = (x0 >= lo * l0.sum()) & (x0 < hi * l0.sum())
            areas_rows.append({"vowel": name, "stretch": stretch,
                               "from-to mm": f"{lo * total:.0f}-{hi * total:.0f}",
                               "model root before mm^2": float(a0[sel0].mean()),
                               "model now mm^2": float(a1[sel1].mean()),
                               "Story (2008) mm^2": float(s1[sel1].mean())})
        meas = np.median(now.measured.frequency[m, :3], 0)
        tracts = [("measured (Praat, median)", meas),
                  (f"Story's /{vowel}/ ({len(story) * step_cm * 10:.0f} mm)",
                   formants(story, np.full(len(story), step_cm * 10.0))),
                  ("model, root before", formants(a0, l0)), ("model now", formants(a1, l1))]
        for stretch, lo, hi in STRETCHES:
            sel = (x >= lo * total) & (x < hi * total)
            tracts.append((f"model now with Story's {stretch}", formants(np.where(sel, s1, a1), l1)))
        for tract, f in tracts:
            formant_rows.append({"vowel": name, "tract": tract,
                                 **{f"F{k + 1} Hz": float(f[k]) for k in range(3)}})
    return areas_rows, formant_rows


def _regions(result):
    import jax.numpy as jnp

    from cassi_fit import area_function as af

    return af.area_functions(result.geometry, jnp.asarray(result.vertices), result.tract,
                             result.scale)[2]


#: Table 10's two tracts: the lips' width narrowed by their protrusion (the default) or not
LIPS_NOW = "lips' width from their protrusion (default)"
LIPS_BEFORE = "lips' width as at rest (before)"


def lip_width_variants(result) -> dict:
    """Table 10's variants of one recording's result: the default and the lips' sections
    as the published labial rule gives them whatever the protrusion."""
    before = dataclasses.replace(result.geometry, lip_rest_x=None)
    return {LIPS_BEFORE: _with_geometry(result, before), LIPS_NOW: result}


def _jw11_section(args, acc) -> list[str]:
    import acoustic_referee as ref

    from cassi_fit.tables import markdown_text

    run, result = ref.run_jw11(args.jw11, False)
    jw_variants = variant_results(result)
    acc["variant_rows"] += variant_quality_rows("JW11", jw_variants)
    acc["variant_ref"] += variant_referee_rows("JW11", jw_variants, {})
    lips = lip_width_variants(result)
    acc["lip_rows"] += variant_quality_rows("JW11", lips)
    acc["lip_ref"] += variant_referee_rows("JW11", lips, {}, LIPS_BEFORE)
    acc["story_cases"].append(("JW11 /a/", "a", jw_variants["root before"], result, result.scored))
    pharynx, elastic = jw11_rows(result)
    print("JW11 done", flush=True)
    return ["## JW11 (XRMB, two jaw pellets, nine /a/): the pharynx", "",
            markdown_text(pharynx, digits=2), "",
            _openings(result) + f" Its UL pellet lies {_lip_sensors(run):.1f} mm above "
            "its LL pellet (median over the recording).", "",
            "## JW11: what moves the formants (tongue base carried to JW11's wall)", "",
            markdown_text(elastic, digits=3), ""]


def _emu_section(args, acc) -> list[str]:
    import acoustic_referee as ref

    from cassi_fit import acoustic_fit
    from cassi_fit.acoustic_fit import vowel_quality
    from cassi_fit.tables import markdown_text

    run, result = ref.run_emu(args.emu)
    emu_variants = variant_results(result)
    held = {}
    for name in ("root before", "root keeps the rest area (default)",
                 "root keeps the recording's median area"):
        held[name] = acoustic_fit.leave_one_quality_out(emu_variants[name])[0]
    acc["variant_rows"] += variant_quality_rows("mo1", emu_variants)
    acc["variant_ref"] += variant_referee_rows("mo1", emu_variants, held)
    lips = lip_width_variants(result)
    lips_held = {LIPS_NOW: held["root keeps the rest area (default)"],
                 LIPS_BEFORE: acoustic_fit.leave_one_quality_out(lips[LIPS_BEFORE])[0]}
    acc["lip_rows"] += variant_quality_rows("mo1", lips)
    acc["lip_ref"] += variant_referee_rows("mo1", lips, lips_held, LIPS_BEFORE)
    quality = np.array([vowel_quality(str(s)) for s in result.labels])
    for q in ("i", "u"):
        acc["story_cases"].append((f"mo1 /{q}:/", q, emu_variants["root before"], result,
                                   result.scored & (quality == q)))
    text = ["## EMU mo1 (IPS Munich, one jaw sensor, palate from the tongue sensors, "
            "default wall): by vowel quality", "", markdown_text(emu_rows(result), digits=1),
            "", f"The {run.state.palate_note}.", "",
            f"Its upper-lip sensor lies {_lip_sensors(run):.1f} mm above its lower-lip "
            "sensor (median over the recording); the model's lips are fitted to XRMB's "
            "UL and LL pellet sites. " + _bilabials(result), ""]
    closed_run, closed = ref.run_emu(args.emu, lip_closure=True)
    return text + [
        "## EMU mo1 with its lips touching where their sensors are nearest "
        "(`lip_closure`, not the default): by vowel quality", "",
        markdown_text(emu_rows(closed), digits=1), "",
        f"With `lip_closure`: {closed_run.state.lip_note}. " + _bilabials(closed), "",
        "## EMU mo1: the referee's figures with the lips at rest and touching", "",
        markdown_text(lip_closure_rows(result, closed,
                                       held["root keeps the rest area (default)"])), ""]


def main(argv=None) -> int:
    from cassi_fit.tables import markdown_text

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jw11", type=Path, default=real_data(XRMB_JW11))
    ap.add_argument("--emu", type=Path, default=real_data(EMU_MO1))
    ap.add_argument("--docs", type=Path, default=ROOT / "docs" / "generated")
    ap.add_argument("--force", action="store_true")
    args = ap.parse_args(argv)
    if not args.jw11 and not args.emu:
        print("acoustic_tract_diagnosis: skipped, no real recording (../shared/data absent)")
        return 0
    out = args.docs / "acoustic_tract_diagnosis.md"
    if out.exists() and not args.force:
        print(f"{out} exists (use --force)")
        return 1
    text = ["<!-- written by `python experiments/acoustic_tract_diagnosis.py --docs "
            "docs/generated --force`; do not edit -->",
            "# Where the model's formant errors come from: JW11's pharynx, EMU's vowels", "",
            "Written by `experiments/acoustic_tract_diagnosis.py` (docstring: the method). One "
            "recording of one speaker per table: no figure generalises to other speakers. "
            "Signed error = model / measured - 1 (Praat's Burg formants).", ""]
    acc = {k: [] for k in ("story_cases", "variant_rows", "variant_ref", "lip_rows", "lip_ref")}
    if args.jw11:
        text += _jw11_section(args, acc)
    if args.emu:
        text += _emu_section(args, acc)
    if acc["story_cases"]:
        areas_rows, formant_rows = story_rows(acc["story_cases"])
        text += ["## The model's vowels beside Story (2008)'s MRI area functions: mean areas",
                 "", markdown_text(areas_rows, digits=0), "",
                 "## The same: F1-F3 of each tract, and of the model's with one stretch of "
                 "Story's", "", markdown_text(formant_rows, digits=0), "",
                 "## Variants tried: by vowel quality (none chosen by these figures)", "",
                 markdown_text(acc["variant_rows"], digits=1), "",
                 "## Variants tried: the referee's figures", "",
                 markdown_text(acc["variant_ref"]), "",
                 "## The lips' width narrowed by their protrusion (Maeda 1990): by vowel "
                 "quality and the referee's figures", "",
                 markdown_text(acc["lip_rows"], digits=1), "", markdown_text(acc["lip_ref"]), ""]
    args.docs.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(text))
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
