"""The jaw comparison experiment: per-regime errors with intervals, regenerable docs.

The notebook and the small run (``--small --docs``) share one notebook kernel (``runs``):
the notebook runs the same small run first, so the second run in that process finds the
jaw fits and the statistics traced and compiled, instead of tracing them all again here."""

import csv
import os
import sys
from pathlib import Path

import nbformat
import numpy as np
import pytest
from experiment_kernel import main_cell, setup_cell
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import jaw_comparison  # noqa: E402
import jaw_regimes  # noqa: E402
import jaw_truth  # noqa: E402

# What `make experiments` runs; the generated docs file must name exactly this command.
MAKE_COMMAND = ("python experiments/jaw_comparison.py --out experiments/output "
                "--docs docs/generated --force")  # fmt: skip
GENERATED = ROOT / "docs" / "generated" / "jaw_comparison.md"
QUOTED = ("Winner by chin point error (mm), median", "Winner by pivot error (mm), median",
          "Winner by chin point error (mm), 95th percentile",
          "Winner by angle error (deg), median")  # fmt: skip


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One kernel runs the notebook top to bottom, then ``main`` of the small run with
    ``--docs``. Returns ``part -> (result or None, error or None)``: for ``"notebook"`` the
    notebook's executed cells, for ``"small"`` the small run's output folder; each test
    raises its own part's error. The notebook's one recording (subject S01's sentence of
    the default synthetic corpus) comes from a corpus of that recording alone, the same
    file (a recording depends only on its seed, subject and task): the kernel is not left
    to write the whole default corpus (15 subjects, every task) into the user's cache."""
    from cassi_fit import synth

    out = tmp_path_factory.mktemp("jaw_small")
    sentence = synth.generate_corpus(tmp_path_factory.mktemp("synth") / "corpus", n_subjects=1,
                                     tasks=[synth.SENTENCE_TASK], audio=False)
    argv = ["--small", "--out", str(out), "--docs", str(out / "docs")]
    nb = nbformat.read(ROOT / "notebooks" / "jaw_comparison.ipynb", as_version=4)
    notebook = list(nb.cells)
    setup = setup_cell("jaw_comparison")  # this process's settings, then the experiment
    small = main_cell("jaw_comparison", argv)
    nb.cells = [*notebook, setup, small]
    client = NotebookClient(nb, timeout=None, kernel_name="python3",
                            resources={"metadata": {"path": str(ROOT / "notebooks")}})
    result = {}
    with client.setup_kernel(env={**os.environ, "CASSI_SYNTH_DIR": str(sentence)}):
        try:
            for i, cell in enumerate(notebook):
                client.execute_cell(cell, i)
            result["notebook"] = (notebook, None)
        except Exception as exc:  # noqa: BLE001 -- raised by its test
            result["notebook"] = (None, exc)
        try:
            client.execute_cell(setup, len(notebook))
            client.execute_cell(small, len(notebook) + 1)
            text = "".join(o.get("text", "") for o in small.outputs if o.get("name") == "stdout")
            assert text.rstrip().splitlines()[-1] == "exit status 0", text[-2000:]
            result["small"] = (out, None)
        except Exception as exc:  # noqa: BLE001
            result["small"] = (None, exc)
    return result


def _part(runs, name):
    value, error = runs[name]
    if error is not None:
        raise error
    return value


@pytest.fixture(scope="module")
def small_run(runs):
    return _part(runs, "small")


def test_trust_threshold_finds_the_first_trustworthy_bin():
    rows = [{"method": "closed-form", "noise": "white-0.25", "family": "physiological",
             "theta_lo_deg": lo, "median_pivot_err_mm": e}
            for lo, e in ((0, 40.0), (2, 9.0), (4, 3.0), (8, 1.0))]  # fmt: skip
    assert jaw_regimes.trust_threshold(rows) == 4
    rows[1]["median_pivot_err_mm"] = 1.0
    assert jaw_regimes.trust_threshold(rows) == 2
    rows[3]["median_pivot_err_mm"] = 50.0
    assert jaw_regimes.trust_threshold(rows) is None


def _recs(values_per_recording):
    return [{"m": np.asarray(v, float)} for v in values_per_recording]


def test_the_weighted_percentile_is_numpys_on_unit_counts_and_resamples_recordings():
    rng = np.random.default_rng(0)
    recs = _recs([rng.normal(size=k) for k in (30, 7, 12)])
    values, owner = jaw_regimes._stack(recs, "m")
    for q in (50, 95):
        got = jaw_regimes.weighted_percentile(values, owner, np.ones((1, 3), int), q)
        assert got[0] == np.percentile(values, q, method="inverted_cdf")
    # a resample holding recording 1 twice and no other is recording 1's own percentile
    got = jaw_regimes.weighted_percentile(values, owner, np.array([[0, 2, 0]]), 50)
    assert got[0] == np.percentile(recs[1]["m"], 50, method="inverted_cdf")


def test_a_winner_is_named_only_when_the_paired_interval_excludes_zero():
    rng = np.random.default_rng(1)
    base = [rng.gamma(2.0, 1.0, size=200) for _ in range(12)]
    counts = jaw_regimes._resamples(12, rng)
    # b is a's error plus 0.5 mm on every frame: a wins clearly
    clear = {"a": _recs(base), "b": _recs([v + 0.5 for v in base])}
    assert jaw_regimes.verdict(clear, "m", 50, counts) == ("a", "a")
    # b differs from a by recording-level noise that averages out: no winner
    shift = rng.normal(0.0, 0.5, size=12)
    shift -= shift.mean()
    tie = {"a": _recs(base), "b": _recs([v + d for v, d in zip(base, shift, strict=True)])}
    text, best = jaw_regimes.verdict(tie, "m", 50, counts)
    assert best is None and text.startswith("tie: ") and set(text[5:].split(", ")) == {"a", "b"}
    # frames a method did not use (NaN) are left out of both sides of the pair
    gaps = {"a": _recs([np.where(np.arange(200) < 100, v, np.nan) for v in base]),
            "b": _recs([v + 0.5 for v in base])}
    assert jaw_regimes.verdict(gaps, "m", 50, counts)[1] == "a"


def test_every_recording_has_its_own_seed():
    """The old seed ``(subject_seed, len(task), 7)`` gave tp106 and tp040 the same noise."""
    seeds = {jaw_truth.recording_seed(f, s, t) for f in ("speech", "thrust")
             for s in ("X01", "X02") for t in ("tp106", "tp040")}
    assert len(seeds) == 8
    recs = list(jaw_truth._recordings(True, tasks=("tp106", "tp040"), noises=("white-0.25",),
                                           families=("fixed-condyle",)))
    (_, _, _, a, ta, _), (_, _, _, b, tb, _) = recs
    n = min(a.n_frames, b.n_frames)
    noise_a = (a.positions - ta.pellets_true)[20:n, 6, 0]
    noise_b = (b.positions - tb.pellets_true)[20:n, 6, 0]
    assert abs(np.corrcoef(noise_a, noise_b)[0, 1]) < 0.2


def test_the_errors_are_measured_against_the_true_motion():
    """Noise-free fixed-condyle truth: the fixed pivot is the condyle and the closed-form angle
    is exact, so the per-frame errors the tables pool must be ~0 (a wrong true motion, a
    wrong reference frame or a sign error in the jaw points would show here). Recordings as
    long as the small run's: the fits compiled here are the ones it uses."""
    from cassi_fit import synth

    duration = jaw_truth.SMALL["duration_s"]
    anatomy = synth.make_subject("X01", np.random.default_rng(300), jaw_kinematics="fixed-condyle")
    track, truth = synth.synth_recording(anatomy, "tp106", seed=1, noise_mm=0.0,
                                         duration_s=duration, dropouts=False,
                                         mistracks=False)  # fmt: skip
    fixed = jaw_truth.frame_errors(track, truth, anatomy, "fixed-pivot")
    assert fixed["theta_deg"].max() > 8.0
    pivot_err = fixed["pivot_err_mm"]  # NaN where the true motion has no pivot (theta 0)
    assert np.isfinite(pivot_err).sum() > 100 and np.nanmax(pivot_err) < 0.05
    assert np.isfinite(fixed["chin_err_mm"]).sum() > 100  # NaN: frames the fit did not use
    assert np.nanmax(fixed["chin_err_mm"]) < 0.05 and np.nanmax(fixed["angle_err_deg"]) < 0.01
    closed = jaw_truth.frame_errors(track, truth, anatomy, "closed-form")
    assert np.nanmax(closed["angle_err_deg"]) < 0.01
    assert np.nanmax(closed["incisor_err_mm"]) < 0.05
    # The physiological truth moves its pivot: Parke's fixed pivot then misses the chin.
    anatomy = synth.make_subject("X01", np.random.default_rng(300), jaw_kinematics="physiological")
    track, truth = synth.synth_recording(anatomy, "tp106", seed=1, noise_mm=0.0,
                                         duration_s=duration, dropouts=False,
                                         mistracks=False)  # fmt: skip
    biased = jaw_truth.frame_errors(track, truth, anatomy, "fixed-pivot")
    assert np.nanpercentile(biased["chin_err_mm"], 90) > 0.3


def test_small_run_reports_every_method_per_regime_with_intervals(small_run):
    with open(small_run / "jaw_comparison.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    from cassi_fit import synth
    from cassi_fit.options import JAW_METHODS

    regimes = {(r["family"], r["noise"], r["method"]) for r in rows}
    assert regimes == {(f, n, m) for f in synth.JAW_KINEMATICS
                       for n in jaw_truth.NOISE_FAMILIES for m in JAW_METHODS}
    inside = []
    for r in rows:
        for key in jaw_truth.STATISTICS:
            value, lo, hi = float(r[key]), float(r[f"{key}_lo"]), float(r[f"{key}_hi"])
            if np.isfinite(value):
                assert lo <= hi, (r, key)
                inside.append(lo <= value <= hi)
    assert np.mean(inside) > 0.95
    bins = {(r["family"], r["noise"], r["method"]): set() for r in rows}
    for r in rows:
        bins[(r["family"], r["noise"], r["method"])].add(float(r["theta_lo_deg"]))
    assert all(len(b) >= 3 for b in bins.values())  # per angle bin, not pooled
    text = (small_run / "jaw_comparison.md").read_text()
    assert text == (small_run / "docs" / "jaw_comparison.md").read_text()
    for title in QUOTED:
        body = jaw_comparison.section(text, title)
        assert body.count("\n| ") >= len(synth.JAW_KINEMATICS) * len(jaw_truth.NOISE_FAMILIES)
    assert "] |" in text and "[" in text  # medians with [lo, hi] intervals
    for name in ("pivot_error_vs_theta.png", "point_error_vs_noise.png"):
        assert (small_run / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _skeleton(text):
    """Headings and the result tables' header rows: the format, without the numbers (the
    held-out tuning table is in the full run only)."""
    lines = text.splitlines()
    return [line for i, line in enumerate(lines) if line.startswith(("#", "| truth"))
            or (line.startswith("|---") and lines[i - 1].startswith("| truth"))]


def test_the_docs_table_is_the_one_make_experiments_writes(small_run):
    text = GENERATED.read_text()
    assert text.splitlines()[0] == jaw_comparison.markdown([], {}, MAKE_COMMAND).splitlines()[0]
    assert _skeleton(text) == _skeleton((small_run / "jaw_comparison.md").read_text())
    for doc, titles in ((ROOT / "README.md", QUOTED[:2]), (ROOT / "docs" / "JAW.md", QUOTED)):
        quoted = doc.read_text()
        for title in titles:
            assert jaw_comparison.section(text, title) in quoted, (doc.name, title)


def _full_table_row(text, title, family, noise, method):
    """The cells of one row of a full table of the generated report (by bin)."""
    for line in jaw_comparison.section(text, title).splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[:3] == [family, noise, method]:
            return cells[3:]
    raise AssertionError(f"no row {family} {noise} {method} in {title!r}")


def test_the_generated_numbers_are_this_codes():
    """Re-runs one whole cell of the published table (speech truth, xrmb noise: its 12
    recordings) for the two methods that compile fastest, and compares every bin's median
    chin error with docs/generated/jaw_comparison.md as printed: a change to the generator,
    the fits or the statistics without regenerating the table fails here."""
    from cassi_fit.jaw_fit import jaw_method

    text = GENERATED.read_text()
    recordings = list(jaw_truth._recordings(False, noises=("xrmb",), families=("speech",)))
    assert len(recordings) == jaw_truth.N_SUBJECTS * len(jaw_truth.TASKS)
    title = "chin point error (mm), median [95 % interval]"
    for name in ("closed-form", "frame-fit"):
        method = jaw_method(name, solver="optimistix-lm")
        errs = [jaw_truth.frame_errors(track, truth, anatomy, method)
                for *_, track, truth, anatomy in recordings]
        theta = np.concatenate([e["theta_deg"] for e in errs])
        chin = np.concatenate([e["chin_err_mm"] for e in errs])
        printed = _full_table_row(text, title, "speech", "xrmb", name)
        bins = list(zip(jaw_truth.THETA_BINS_DEG[:-1], jaw_truth.THETA_BINS_DEG[1:],
                        strict=True))
        checked = 0
        for (lo, hi), cell in zip(bins, printed, strict=True):
            v = chin[(theta >= lo) & (theta < hi)]
            v = v[np.isfinite(v)]
            if cell == "-":
                assert v.size == 0
                continue
            median = np.percentile(v, 50, method="inverted_cdf")
            digits = 2 if median < 10 else 1
            assert cell.split(" [")[0] == f"{median:.{digits}f}", (name, lo, cell, median)
            checked += 1
        assert checked >= 3


@pytest.mark.slow
def test_notebook_runs_and_shows_figures(runs):
    cells = _part(runs, "notebook")
    outputs = [o for cell in cells if cell.cell_type == "code" for o in cell.outputs]
    # the experiment's two figures and one recording's jaw plot
    assert sum("image/png" in o.get("data", {}) for o in outputs) == 3
    text = "".join(o.get("text", "") for o in outputs)
    assert "closed-form pivot" in text and "smooth-pivot" in text
    assert "angle error (deg): median" in text  # the methods against the generator's truth
    assert any("| fixed-pivot |" in o.get("data", {}).get("text/markdown", "") for o in outputs)


def test_existing_outputs_are_kept_unless_forced(tmp_path, capsys):
    (tmp_path / "jaw_comparison.csv").write_text("mine\n")
    assert jaw_comparison.main(["--small", "--out", str(tmp_path)]) == 1
    assert "exists" in capsys.readouterr().err
    assert (tmp_path / "jaw_comparison.csv").read_text() == "mine\n"
