"""The API reference (issue 22 part 5): ``make docs`` builds it from the docstrings with
mkdocs and mkdocstrings (mkdocs.yml, docs/api/, docs/api_hooks.py, docs/griffe_roles.py).
It must build with ``--strict`` (any warning fails), document every name of
``cassi_fit.__all__`` where it lives, and show the docstrings as Markdown."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

import cassi_fit

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The reference built with ``mkdocs build --strict`` into a temporary folder:
    ``(folder, the build's log)``."""
    assert importlib.util.find_spec("mkdocs") and importlib.util.find_spec("mkdocstrings"), (
        "the docs extra is not installed: `make venv` (or pip install -e '.[docs]')")
    out = tmp_path_factory.mktemp("docs_site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                           str(out)], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    return out, done.stdout + done.stderr


def _anchors(out: Path) -> set[str]:
    return {a for page in (out / "reference").glob("*.html")
            for a in re.findall(r'id="(cassi_fit[^"]*)"', page.read_text(encoding="utf-8"))}


def test_the_reference_builds_without_warnings(site):
    _, log = site
    assert "WARNING" not in log and "ERROR" not in log, log


def test_every_public_name_is_documented_where_it_lives(site):
    out, _ = site
    anchors = _anchors(out)
    missing = [name for name in cassi_fit.__all__
               if (f"cassi_fit.{name}" if name in cassi_fit._MODULES
                   else f"cassi_fit.{cassi_fit._PUBLIC[name]}.{name}") not in anchors]
    assert not missing, missing


def test_docstrings_are_shown_as_markdown(site):
    """run_recording's docstring is on its page, and Sphinx roles in docstrings appear as
    code (``:class:`RecordingRun``` -> ``RecordingRun``), not as ``:class:`` text."""
    out, _ = site
    page = (out / "reference" / "pipeline.html").read_text(encoding="utf-8")
    assert "The spec is checked once, here;" in page
    assert "<code>RecordingRun</code>" in page
    for name in ("pipeline", "run_spec", "jaw_fit", "dataset"):
        text = (out / "reference" / f"{name}.html").read_text(encoding="utf-8")
        assert not re.search(r":(func|class|mod|meth|attr):", text), name
