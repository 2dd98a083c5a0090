"""The jaw comparison experiment and its notebook run, and they say what they must."""

import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import jaw_comparison  # noqa: E402


def test_trust_threshold_finds_the_first_trustworthy_bin():
    rows = [{"method": "closed-form", "noise_mm": 0.3, "theta_lo_deg": lo,
             "median_pivot_err_mm": e} for lo, e in ((0, 40.0), (2, 9.0), (4, 3.0), (8, 1.0))]
    assert jaw_comparison.trust_threshold(rows) == 4
    rows[1]["median_pivot_err_mm"] = 1.0
    assert jaw_comparison.trust_threshold(rows) == 2
    rows[3]["median_pivot_err_mm"] = 50.0
    assert jaw_comparison.trust_threshold(rows) is None


@pytest.mark.slow
def test_notebook_runs_and_shows_figures(tmp_path):
    nb = nbformat.read(ROOT / "notebooks" / "jaw_comparison.ipynb", as_version=4)
    NotebookClient(nb, timeout=120, kernel_name="python3",
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
