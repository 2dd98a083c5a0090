"""notebooks/labels.ipynb runs top to bottom: the label column and the per-segment table."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from cassi_fit import synth

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "labels.ipynb"


@pytest.mark.slow
def test_notebook_executes(tmp_path, monkeypatch):
    corpus = synth.generate_corpus(tmp_path / "corpus", n_subjects=1,
                                   tasks=[synth.SENTENCE_TASK], audio=False)
    monkeypatch.setenv("CASSI_SYNTH_DIR", str(corpus))  # the kernel inherits it
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(notebook, timeout=None, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    html = "".join(o["data"].get("text/html", "") for o in outputs if "data" in o)
    # the frame table around the first segment's start, and the per-segment table
    assert "<td>ba</td>" in html and "jaw_peak_opening_deg" in html
    assert html.count("<td>ok</td>") >= 5  # every segment has jaw and lip values
