"""The notebooks are stored executed (``make notebooks``, notebooks/store_outputs.py), with
outputs that are those of their sources as they are and no machine's absolute paths in them.

Cheap: nothing is executed here (tests/test_notebook_*.py execute them); the stored hash of
each notebook's sources must be the hash of its sources now."""

import importlib.util
from pathlib import Path

import nbformat
import pytest

HERE = Path(__file__).resolve().parents[1] / "notebooks"
_spec = importlib.util.spec_from_file_location("store_outputs", HERE / "store_outputs.py")
store_outputs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(store_outputs)


def test_every_notebook_here_is_one_make_notebooks_stores():
    assert sorted(p.stem for p in HERE.glob("*.ipynb")) == sorted(store_outputs.NOTEBOOKS)


@pytest.mark.parametrize("name", store_outputs.NOTEBOOKS)
def test_stored_outputs_are_current_and_clean(name):
    notebook = nbformat.read(HERE / f"{name}.ipynb", as_version=4)
    stored = notebook.metadata.get("cassi_fit", {}).get("source_sha256")
    assert stored == store_outputs.source_sha256(notebook), (
        f"notebooks/{name}.ipynb changed since its outputs were stored: run make notebooks")
    code = [c for c in notebook.cells if c.cell_type == "code"]
    assert all(c.execution_count is not None for c in code)
    outputs = [o for c in code for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs)  # a figure, at least one
    leaks = [t for t in store_outputs.outputs_text(notebook)
             if store_outputs.ABSOLUTE_PATH.search(t)]
    assert not leaks, [store_outputs.ABSOLUTE_PATH.search(t).group(0) for t in leaks][:3]


def test_the_cleaner_replaces_paths_but_not_base64():
    blob = "A/tmp/" * 100  # a base64-looking run that happens to hold '/tmp/'
    text = f"wrote /tmp/tmpab12/S01.mp4 and {store_outputs.ROOT}/docs/x.md {blob}"
    clean = store_outputs._clean_text(text)
    assert clean.startswith("wrote <tmp>/S01.mp4 and <repo>/docs/x.md ")
    assert clean.endswith(blob)
    assert not store_outputs.ABSOLUTE_PATH.search(store_outputs.BASE64_RUN.sub("", clean))
