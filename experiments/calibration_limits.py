"""Where calibration meets its limits: the jaw shape's anatomical bound (S09's stall) and
the lower lip's unobserved incisor tip (issue 20, part 6).

    python experiments/calibration_limits.py [--out experiments/output] [--docs DIR] [--force]

On the corpus of ``subject_fitting.py`` (seed ``SEED``, ``FULL``: 15 subjects, tasks
tp106, tp040, tp020_2; written to a temporary folder and removed afterwards), method
``separate``:

1. The jaw-shape stage, per subject: how much longer than the model's its Headmeasures ask
   the jaw to be (the skin gonion's distance behind the model's lower incisor tip, times
   p/d, over the model's own, along x: a rough reading of ``jaw_scale_x``); the stage
   solved once, as the calibration did before (converged or not, the raw unknown ``u`` of
   the jaw's x scale and the scale it reached); the stage as ``calibrate`` solves it now
   (a bound the cost still pushes against is held and the rest solved again); the stage's
   cost (model mm^2) and its slope along the jaw's log x scale at the answer (negative:
   the cost would fall further beyond the bound): ``calibration_jaw_stage.csv``.
2. For every subject whose single solve did not converge: the raw unknown, the scale and
   the cost against the solver's step budget (``TRACE_STEPS``): ``calibration_stall.csv``.
3. The lower lip: per subject the calibration's error against the synthetic truth, the
   true tip-offset difference (how much further ahead of MNI the subject's incisor tip
   lies than the model's), and the range ``calibrate.lower_lip_bias`` reports:
   ``calibration_lower_lip.csv``. The synthetic subjects are drawn from the same dental
   norms as the range, so this checks the range's geometry, not its width on real
   speakers.

4. A real dataset (``--real DIR``; by default the shared JW11 recording when it is
   present): each subject calibrated, its convergence, bounds, lips and lower-lip range:
   ``calibration_real.csv``.

``--docs DIR`` also writes ``calibration_limits.md`` (the three tables), ``calibration_real.md``
(step 4, when it ran) and
``calibration_schema.md`` (the calibration file's entries and plausible ranges, from
``cassi_fit.calibration.SCHEMA`` and ``PARAMS``), each headed by the command that wrote
it. Nothing is overwritten without ``--force``.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import subject_rows as sf
from shared_data import XRMB_JW11, real_data

#: Step budgets at which a stalled stage is shown (the calibration's is 100).
TRACE_STEPS = (5, 10, 20, 50, 100, 200, 400)
DOCS_COMMAND = ("python experiments/calibration_limits.py --out experiments/output "
                "--docs docs/generated --force")
OUTPUTS = ("calibration_jaw_stage.csv", "calibration_stall.csv", "calibration_lower_lip.csv")
DOC_TABLES = ("calibration_limits.md", "calibration_schema.md")
JAW_FREE = ("jaw_theta", "log_jaw_scale")
#: The real recordings' folder used when present (``--real``).
REAL = real_data(XRMB_JW11)
JAW_HEADERS = {"scale": "p/d", "asked_x": "asked x", "once_converged": "once: converged",
               "once_u": "once: u", "once_x_scale": "once: x scale",
               "once_cost_mm2": "once: cost mm^2", "now_converged": "now: converged",
               "now_bounds_hit": "now: bounds hit", "now_x_scale": "now: x scale",
               "now_cost_mm2": "now: cost mm^2", "now_slope_mm2": "now: slope mm^2"}
LOWER_HEADERS = {"lower_lip_mm": "lower lip mm", "error_mm": "error mm",
                 "tip_offset_difference_mm": "tip offset difference mm",
                 "bias_low_mm": "range low mm", "bias_high_mm": "range high mm",
                 "error_inside": "error inside", "offset_inside": "offset inside"}


# ------------------------------------------------------------------ the jaw-shape stage


def _stage(model, recordings):
    """``(problem, x0, mask, weights, flat0, unravel)`` of the subject's jaw-shape stage."""
    from jax.flatten_util import ravel_pytree

    from cassi_fit import calibrate as c
    from cassi_fit.calibrate_residuals import Problem, Unknowns

    data, measured, x0, _ = c._prepare(recordings, model)
    dtype = x0.log_scale.dtype
    mask = Unknowns.mask(JAW_FREE, dtype)
    weights = c._stage_weights(("jaw_shape",), True, dtype)
    flat0, unravel = ravel_pytree(x0)
    return Problem(model, data, measured), x0, mask, weights, flat0, unravel


def _cost(problem, x) -> float:
    """The jaw-shape stage's cost: sum of its squared residuals, model mm^2."""
    r = np.asarray(problem.residual_groups(x, False)["jaw_shape"], np.float64)
    return float(r @ r)


def _slope_log_kx(problem, x) -> float:
    """d cost / d log(jaw x scale) at ``x`` (model mm^2): the u-gradient over du/dlog k."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from cassi_fit.calibration import JAW_SCALE_BOUND

    def cost(u):
        y = eqx.tree_at(lambda z: z.log_jaw_scale, x, x.log_jaw_scale.at[0].set(u))
        r = problem.residual_groups(y, False)["jaw_shape"]
        return jnp.sum(r * r)

    u = x.log_jaw_scale[0]
    b = math.log(JAW_SCALE_BOUND)
    dlogk_du = 1.0 / math.cosh(float(u) / b) ** 2
    return float(jax.grad(cost)(u)) / dlogk_du


def _x_scale(x) -> tuple[float, float]:
    """``(u, jaw x scale)`` of the unknowns ``x``."""
    from cassi_fit.calibrate_residuals import bounded_jaw

    return float(x.log_jaw_scale[0]), float(np.exp(bounded_jaw(x)[1][0]))


def _asked_x(model, recordings, scale) -> float:
    """The subject's skin gonion behind the model's lower incisor tip (x), times p/d, over
    the model's gonion's: the jaw x scale the gonion alone asks for."""
    from cassi_fit.conformation import skin_landmarks

    v = np.asarray(model.vertices, np.float64)[:, :2]
    tip, gonion = v[model.landmarks["lower_incisor_tip"]], v[model.landmarks["gonion"]]
    skin = skin_landmarks(model, recordings[0].head)[0]
    return float((scale * skin[0] - tip[0]) / (gonion[0] - tip[0]))


def jaw_stage_rows(root, model) -> tuple[list[dict], list[dict]]:
    """Steps 1 and 2: per-subject rows, and the stall trace of the subjects whose single
    solve did not converge."""
    import optimistix as optx
    from jax.flatten_util import ravel_pytree

    from cassi_fit import calibrate as c
    from cassi_fit.calibrate_residuals import stage_kernel
    from cassi_fit.dataset import Dataset
    from cassi_fit.jaw_fit import LevenbergMarquardt

    ds = Dataset(root)
    rows, trace = [], []
    for subject in ds.subjects():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            recs = [ds.load(subject, t) for t in ds.tasks(subject)]
        problem, x0, mask, weights, flat0, unravel = _stage(model, recs)
        once, ok_once, _ = stage_kernel(model, problem.data, True, x0, mask, weights)
        now, ok_now = c._solve_stage(model, problem.data, True, x0, JAW_FREE, ("jaw_shape",),
                                     True)
        scale = float(np.exp(x0.log_scale))
        u_once, k_once = _x_scale(once)
        _, k_now = _x_scale(now)
        rows.append({
            "subject": subject, "scale": scale, "asked_x": _asked_x(model, recs, scale),
            "once_converged": bool(ok_once), "once_u": u_once, "once_x_scale": k_once,
            "once_cost_mm2": _cost(problem, once),
            "now_converged": bool(ok_now), "now_bounds_hit": ";".join(c.bounds_hit(now)),
            "now_x_scale": k_now, "now_cost_mm2": _cost(problem, now),
            "now_slope_mm2": _slope_log_kx(problem, now)})
        if bool(ok_once):
            continue
        free = np.asarray(ravel_pytree(mask)[0])

        def residuals(y, base, problem=problem, free=free, unravel=unravel):
            return problem.residual_groups(unravel(base + free * (y - base)), False)["jaw_shape"]

        rtol, atol = LevenbergMarquardt().tolerances(np.float64)
        for steps in TRACE_STEPS:
            sol = optx.least_squares(residuals, optx.LevenbergMarquardt(rtol=rtol, atol=atol),
                                     flat0, flat0, max_steps=steps, throw=False)
            y = unravel(flat0 + free * (sol.value - flat0))
            u, k = _x_scale(y)
            trace.append({"subject": subject, "steps": steps,
                          "converged": bool(sol.result == optx.RESULTS.successful),
                          "u": u, "x_scale": k, "cost_mm2": _cost(problem, y)})
    return rows, trace


# ------------------------------------------------------------------ the lower lip


def lower_lip_rows(root, model) -> list[dict]:
    """Step 3: the lower lip's error, the true tip-offset difference and the reported
    range, per subject (method separate)."""
    from cassi_fit.calibrate import calibrate_dataset
    from cassi_fit.calibration import CalibrationWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        cals = calibrate_dataset(root, method="separate", model=model)
    truths = sf.true_values(root, cals, model)
    rows = []
    for subject, cal in cals.items():
        t = truths[subject]
        low, high = cal.lower_lip_bias
        error = cal.lower_lip_thickness - t["lower_lip_thickness"]
        offset = t["tip_offset_difference_mm"]
        rows.append({"subject": subject, "lower_lip_mm": cal.lower_lip_thickness,
                     "error_mm": error, "tip_offset_difference_mm": offset,
                     "bias_low_mm": low, "bias_high_mm": high,
                     "error_inside": bool(low <= error <= high),
                     "offset_inside": bool(low <= offset <= high)})
    return rows


# ------------------------------------------------------------------ real recordings


def real_rows(folder, model) -> list[dict]:
    """Step 4: every subject of a real dataset folder calibrated (method separate): its
    convergence, bounds, the lower lip and the range of its possible bias, its problems."""
    from cassi_fit.calibrate import calibrate_dataset
    from cassi_fit.calibration import CalibrationWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        cals = calibrate_dataset(folder, method="separate", model=model)
    rows = []
    for subject, cal in cals.items():
        low, high = cal.lower_lip_bias
        rows.append({"subject": subject, "recordings": ";".join(cal.recordings),
                     "head_is_default": cal.head_is_default, "converged": cal.converged,
                     "bounds_hit": ";".join(cal.bounds_hit), "scale": cal.scale,
                     "upper_lip_mm": cal.upper_lip_thickness,
                     "lower_lip_mm": cal.lower_lip_thickness, "bias_low_mm": low,
                     "bias_high_mm": high, "problems": len(cal.problems())})
    return rows


def real_markdown(folder, rows: list[dict]) -> str:
    from cassi_fit.tables import markdown_text

    text = _header("Calibration of a real recording", (
        f"Every subject of `{Path(folder).name}/` calibrated (method separate): "
        f"{len(rows)} subject(s), one speaker each; a number from one recording of one "
        "speaker says only that. Without Headmeasures (XRMB ships none) only the scale and "
        "the lips are fitted; the lower lip's range is what the unobserved incisor tip may "
        "add (95 % of the dental norms)."))
    digits = {"scale": 4, "upper_lip_mm": 2, "lower_lip_mm": 2, "bias_low_mm": 2,
              "bias_high_mm": 2}
    return text + markdown_text(rows, digits=digits, headers={
        "upper_lip_mm": "upper lip mm", "lower_lip_mm": "lower lip mm",
        "bias_low_mm": "range low mm", "bias_high_mm": "range high mm"})


# ------------------------------------------------------------------ the documents


def schema_rows() -> list[dict]:
    """The calibration file's entries: name, kind, plausible range and unit, the format
    version from which it is required (``calibration.SCHEMA``, ``PARAMS``)."""
    from cassi_fit.calibration import PARAMS, SCHEMA

    def span(low, high):
        lows = low if isinstance(low, tuple) else (low,)
        highs = high if isinstance(high, tuple) else (high,)
        if all(math.isinf(v) for v in (*lows, *highs)):
            return ""
        return ", ".join(f"{lo:.4g} to {hi:.4g}" for lo, hi in zip(lows, highs, strict=True))

    rows = []
    for name, f in SCHEMA.items():
        if f.kind == "params":
            continue
        kind = f.kind + (f" ({', '.join(f.choices)})" if f.choices else "")
        rows.append({"entry": name, "kind": kind, "range": span(f.low, f.high),
                     "unit": f.unit, "required from format": f.since})
    for name, (shape, low, high, unit) in PARAMS.items():
        kind = "number" if not shape else f"{shape[0]} numbers"
        rows.append({"entry": f"params.{name}", "kind": kind, "range": span(low, high),
                     "unit": unit, "required from format": 1})
    return rows


def _header(title: str, text: str) -> str:
    return (f"<!-- written by `{DOCS_COMMAND}`; do not edit: `make experiments` rewrites it "
            f"-->\n# {title}\n\n{text}\n\n")


def limits_markdown(jaw: list[dict], trace: list[dict], lower: list[dict]) -> str:
    from cassi_fit.tables import markdown_text

    n = len(lower)
    inside = sum(r["error_inside"] for r in lower)
    offsets = sum(r["offset_inside"] for r in lower)
    text = _header("Calibration at its limits (synthetic truth)", (
        f"The default synthetic corpus ({n} subjects, tasks {', '.join(sf.FULL.tasks)}, seed "
        f"{sf.SEED}), method separate. The jaw-shape stage solved once (as the calibration "
        "did before) and as it is solved now (a jaw-shape unknown at its bound, with the cost "
        "still falling outward, held there and the rest solved again). \"asked x\": the skin "
        "gonion's distance behind the model's lower incisor tip, times p/d, over the "
        "model's own: roughly the jaw x scale the gonion alone asks for (bound "
        "1.30). u: the raw unknown of the jaw's log x scale (the scale is "
        "exp(B tanh(u/B)), B = log 1.30). Cost: the stage's squared residuals, model mm^2; "
        "slope: its derivative along the log x scale at the answer (negative: it would "
        "fall further beyond the bound)."))
    text += markdown_text(jaw, digits={"scale": 4, "asked_x": 3, "once_u": 3,
                                       "once_x_scale": 7, "once_cost_mm2": 4,
                                       "now_x_scale": 7, "now_cost_mm2": 4,
                                       "now_slope_mm2": 2}, headers=JAW_HEADERS)
    if trace:
        text += ("\nThe single solve of each subject that did not converge, against the step "
                 "budget (the calibration's is 100): u walks out along tanh's flat tail while "
                 "the scale creeps to the bound and the cost barely moves.\n\n")
        text += markdown_text(trace, digits={"u": 3, "x_scale": 7, "cost_mm2": 6},
                              headers={"x_scale": "x scale", "cost_mm2": "cost mm^2"})
    else:
        text += ("\nEvery subject's single solve converged: no stall to trace (one is made "
                 "on purpose in tests/test_calibrate.py: S01 with its gonion moved back to "
                 "x = -110 mm).\n")
    text += (f"\nThe lower lip: the calibration's error (estimate minus truth, mm), the true "
             "tip-offset difference that predicts it (how much further ahead of MNI, along "
             "the jaw line, the subject's incisor tip lies than the model's), and the range "
             "`Calibration.lower_lip_bias` reports (95 % of the dental norms, to first "
             f"order). Error inside the range: {inside} of {n}; the offset alone: {offsets} "
             f"of {n}. The synthetic subjects are drawn from the same norms as the range: this "
             "checks its geometry, not its width on real speakers.\n\n")
    text += markdown_text(lower, digits=2, headers=LOWER_HEADERS)
    return text


def schema_markdown() -> str:
    from cassi_fit.tables import markdown_text

    text = _header("The calibration file's entries", (
        "`SUBJECT.calibration.json`, format `cassi_fit calibration 2` "
        "(`cassi_fit.calibration.SCHEMA`, `PARAMS`): every entry, its kind and plausible "
        "range; a file outside them is refused in one line naming the file, the line and "
        "the entry. Subject measures in mm (Headmeasures' plausible ranges); `params` in "
        "model units (what the face is drawn from)."))
    return text + markdown_text(schema_rows(), digits=4)


# ------------------------------------------------------------------ main


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="experiments/output", help="folder for the CSVs")
    parser.add_argument("--docs", metavar="DIR", help="also write the documentation's "
                        "Markdown tables (DOC_TABLES) into DIR")
    parser.add_argument("--real", metavar="DIR", default=None if REAL is None else str(REAL),
                        help="a real dataset folder to calibrate too (default: the shared "
                        "JW11 recording when present); writes calibration_real.csv (and "
                        "calibration_real.md with --docs)")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)  # as the calibration runs (cassi calibrate)
    from cassi_fit._io import atomic_write, check_outputs
    from cassi_fit.face_model import load_model
    from cassi_fit.tables import write_table

    out = Path(args.out)
    docs = list(DOC_TABLES) + (["calibration_real.md"] if args.real else [])
    paths = [out / n for n in OUTPUTS] + ([Path(args.docs) / n for n in docs]
                                          if args.docs else [])
    paths += [out / "calibration_real.csv"] if args.real else []
    check_outputs(paths, overwrite=args.force)
    model = load_model()
    with tempfile.TemporaryDirectory(prefix="cassi_calibration_limits_") as workdir:
        root = sf.make_corpus(Path(workdir) / "corpus", sf.FULL)
        jaw, trace = jaw_stage_rows(root, model)
        lower = lower_lip_rows(root, model)
    real = real_rows(args.real, model) if args.real else None
    for name, rows in zip(OUTPUTS, (jaw, trace, lower), strict=True):
        write_table(rows, out / name, overwrite=args.force)
    if real is not None:
        write_table(real, out / "calibration_real.csv", overwrite=args.force)
    if args.docs:
        atomic_write(Path(args.docs) / "calibration_limits.md",
                     limits_markdown(jaw, trace, lower), overwrite=args.force)
        atomic_write(Path(args.docs) / "calibration_schema.md", schema_markdown(),
                     overwrite=args.force)
        if real is not None:
            atomic_write(Path(args.docs) / "calibration_real.md", real_markdown(args.real, real),
                         overwrite=args.force)
    stalled = [r["subject"] for r in jaw if not r["once_converged"]]
    print(f"single solve not converged: {', '.join(stalled) or 'none'}; now converged "
          f"{sum(r['now_converged'] for r in jaw)}/{len(jaw)}, at a bound: "
          f"{', '.join(r['subject'] for r in jaw if r['now_bounds_hit']) or 'none'}")
    print(f"lower lip error inside the reported range: {sum(r['error_inside'] for r in lower)}"
          f"/{len(lower)}; tip offset inside: {sum(r['offset_inside'] for r in lower)}"
          f"/{len(lower)}")
    for r in real or ():
        print(f"real {r['subject']}: converged {r['converged']}, problems {r['problems']}, "
              f"lower lip {r['lower_lip_mm']:.2f} mm ({r['bias_low_mm']:+.2f}.."
              f"{r['bias_high_mm']:+.2f} mm)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
