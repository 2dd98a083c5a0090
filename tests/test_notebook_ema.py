"""notebooks/ema.ipynb runs top to bottom: an EST Track file (MOCHA-TIMIT's sensor set) to a
video, and an inversion model's array to an animation."""

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from cassi_fit.ema.synthetic import write_ema_corpus

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "ema.ipynb"


@pytest.mark.slow
def test_notebook_executes(tmp_path, monkeypatch):
    corpus = write_ema_corpus(tmp_path / "ema", format="est", n_subjects=1, tasks=["tp040"],
                              sensors="mocha")
    monkeypatch.setenv("CASSI_EMA_FILE", str(corpus / "S01" / "tp040.ema"))
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(notebook, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs)
    assert "EST_File Track" in text and "MNI  <- LI" in text and "T4   <- (no sensor)" in text
    assert "jaw: coupled-rotation from MNI" in text
    # the toolkit's frame: the upper lip above the lower lip, the tongue behind the incisors
    assert "upper lip above the lower lip in 100% of frames" in text
    assert "tongue tip behind the incisors in 100%" in text
    html = [o["data"]["text/html"] for o in outputs if "text/html" in o.get("data", {})]
    assert any("<video" in h and "base64" in h for h in html)
    assert sum("image/png" in o.get("data", {}) for o in outputs) == 1  # the midsagittal view
    # the inversion model's array: 12 columns at 50 Hz, animated with its one jaw sensor
    assert re.search(r"\(\d+, 12\) -> \d+ frames, jaw: coupled-rotation", text)
