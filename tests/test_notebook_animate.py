"""notebooks/animate.ipynb runs top to bottom and shows the views and the video."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from cassi_fit import synth

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "animate.ipynb"


@pytest.mark.slow
def test_notebook_executes(tmp_path, monkeypatch):
    corpus = synth.generate_corpus(
        tmp_path / "corpus", n_subjects=1, tasks=[synth.SENTENCE_TASK], audio=True
    )
    monkeypatch.setenv("CASSI_SYNTH_DIR", str(corpus))  # the kernel inherits it
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(
        notebook,
        timeout=None,  # no cell time limit: a loaded machine is slow, not wrong
        kernel_name="python3",
        resources={"metadata": {"path": str(tmp_path)}},
    ).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 5  # front, side, inside, top; the midsagittal figure
    html = [o["data"]["text/html"] for o in outputs if "text/html" in o.get("data", {})]
    assert any("<video" in h and "base64" in h for h in html)
    text = "".join(o.get("text", "") for o in outputs)
    assert "model MNI site vs scaled MNI pellet" in text
