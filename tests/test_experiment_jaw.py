"""The jaw comparison experiment: per-regime errors with intervals, regenerable docs."""

import csv
import sys
from pathlib import Path

import nbformat
import numpy as np
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import jaw_comparison  # noqa: E402

# What `make experiments` runs; the generated docs file must name exactly this command.
MAKE_COMMAND = ("python experiments/jaw_comparison.py --out experiments/output "
                "--docs docs/generated --force")  # fmt: skip
GENERATED = ROOT / "docs" / "generated" / "jaw_comparison.md"
QUOTED = ("Winner by chin point error (mm), median", "Winner by pivot error (mm), median",
          "Winner by chin point error (mm), 95th percentile",
          "Winner by angle error (deg), median")  # fmt: skip


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("jaw_small")
    assert jaw_comparison.main(["--small", "--out", str(out), "--docs", str(out / "docs")]) == 0
    return out


def test_trust_threshold_finds_the_first_trustworthy_bin():
    rows = [{"method": "closed-form", "noise": "white-0.25", "family": "physiological",
             "theta_lo_deg": lo, "median_pivot_err_mm": e}
            for lo, e in ((0, 40.0), (2, 9.0), (4, 3.0), (8, 1.0))]  # fmt: skip
    assert jaw_comparison.trust_threshold(rows) == 4
    rows[1]["median_pivot_err_mm"] = 1.0
    assert jaw_comparison.trust_threshold(rows) == 2
    rows[3]["median_pivot_err_mm"] = 50.0
    assert jaw_comparison.trust_threshold(rows) is None


def test_winner_is_clear_only_when_the_intervals_part():
    def row(method, median, lo, hi):
        return {"method": method, "m": median, "m_lo": lo, "m_hi": hi}

    assert jaw_comparison.winner([row("a", 1.0, 0.9, 1.1), row("b", 2.0, 1.8, 2.2)], "m") == (
        "a", "a")
    assert jaw_comparison.winner([row("b", 1.2, 1.0, 1.4), row("a", 1.0, 0.9, 1.1)], "m") == (
        "a ~ b", "a")


def test_the_errors_are_measured_against_the_true_motion():
    """Noise-free fixed-condyle truth: the fixed pivot is the condyle and the closed-form angle
    is exact, so the per-frame errors the tables pool must be ~0 (a wrong true motion, a
    wrong reference frame or a sign error in the jaw points would show here)."""
    from cassi_fit import synth

    anatomy = synth.make_subject("X01", np.random.default_rng(300), jaw_kinematics="fixed-condyle")
    track, truth = synth.synth_recording(anatomy, "tp106", seed=1, noise_mm=0.0, duration_s=2.0,
                                         dropouts=False, mistracks=False)  # fmt: skip
    fixed = jaw_comparison.frame_errors(track, truth, anatomy, "fixed-pivot")
    assert fixed["theta_deg"].max() > 8.0
    pivot_err = fixed["pivot_err_mm"]  # NaN where the true motion has no pivot (theta 0)
    assert np.isfinite(pivot_err).sum() > 100 and np.nanmax(pivot_err) < 0.05
    assert fixed["chin_err_mm"].max() < 0.05 and fixed["angle_err_deg"].max() < 0.01
    closed = jaw_comparison.frame_errors(track, truth, anatomy, "closed-form")
    assert closed["angle_err_deg"].max() < 0.01 and closed["incisor_err_mm"].max() < 0.05
    # The physiological truth moves its pivot: Parke's fixed pivot then misses the chin.
    anatomy = synth.make_subject("X01", np.random.default_rng(300), jaw_kinematics="physiological")
    track, truth = synth.synth_recording(anatomy, "tp106", seed=1, noise_mm=0.0, duration_s=2.0,
                                         dropouts=False, mistracks=False)  # fmt: skip
    biased = jaw_comparison.frame_errors(track, truth, anatomy, "fixed-pivot")
    assert np.percentile(biased["chin_err_mm"], 90) > 0.3


def test_small_run_reports_every_method_per_regime_with_intervals(small_run):
    with open(small_run / "jaw_comparison.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    from cassi_fit import synth
    from cassi_fit.options import JAW_METHODS

    regimes = {(r["family"], r["noise"], r["method"]) for r in rows}
    assert regimes == {(f, n, m) for f in synth.JAW_KINEMATICS
                       for n in jaw_comparison.NOISE_FAMILIES for m in JAW_METHODS}
    inside = []
    for r in rows:
        for key in jaw_comparison.STATISTICS:
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
        assert body.count("\n| ") >= len(synth.JAW_KINEMATICS) * len(jaw_comparison.NOISE_FAMILIES)
    assert "] |" in text and "[" in text  # medians with [lo, hi] intervals
    for name in ("pivot_error_vs_theta.png", "point_error_vs_noise.png"):
        assert (small_run / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _skeleton(text):
    """Headings and table header rows: the format, without the numbers."""
    return [line for line in text.splitlines() if line.startswith(("#", "| truth", "|---"))]


def test_the_docs_table_is_the_one_make_experiments_writes(small_run):
    text = GENERATED.read_text()
    assert text.splitlines()[0] == jaw_comparison.markdown([], MAKE_COMMAND).splitlines()[0]
    assert _skeleton(text) == _skeleton((small_run / "jaw_comparison.md").read_text())
    for doc, titles in ((ROOT / "README.md", QUOTED[:2]), (ROOT / "docs" / "JAW.md", QUOTED)):
        quoted = doc.read_text()
        for title in titles:
            assert jaw_comparison.section(text, title) in quoted, (doc.name, title)


@pytest.mark.slow
def test_notebook_runs_and_shows_figures(tmp_path):
    nb = nbformat.read(ROOT / "notebooks" / "jaw_comparison.ipynb", as_version=4)
    NotebookClient(nb, timeout=None, kernel_name="python3",
                   resources={"metadata": {"path": str(ROOT / "notebooks")}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.outputs]
    assert sum("image/png" in o.get("data", {}) for o in outputs) == 2
    text = "".join(o.get("text", "") for o in outputs)
    assert "closed-form pivot" in text and "smooth-pivot" in text


def test_existing_outputs_are_kept_unless_forced(tmp_path, capsys):
    (tmp_path / "jaw_comparison.csv").write_text("mine\n")
    assert jaw_comparison.main(["--small", "--out", str(tmp_path)]) == 1
    assert "exists" in capsys.readouterr().err
    assert (tmp_path / "jaw_comparison.csv").read_text() == "mine\n"
