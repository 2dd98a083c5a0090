"""``make notebooks``: run every notebook here top to bottom and store it with its outputs.

A reader on a code host's web page sees the figures, tables and printed numbers without
running anything. Each notebook is executed in this folder with the default synthetic corpus
(``$CASSI_SYNTH_DIR`` overrides), its outputs cleaned of this machine's absolute paths (the
checkout, temporary folders and the home folder become ``<repo>``, ``<tmp>`` and ``~``), and
the hash of its cells' sources stored in its metadata (``cassi_fit.source_sha256``), so that
tests/test_notebooks_stored.py can tell, without running anything, that the stored outputs
are those of the sources as they are.

    python notebooks/store_outputs.py [NAME ...]     # default: every notebook here
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
NOTEBOOKS = ("animate", "ema", "jaw_comparison", "labels", "subject_fitting")
#: Long base64 runs (images, sound, the viewer's data) are never rewritten nor searched.
BASE64_RUN = re.compile(r"[A-Za-z0-9+/=]{200,}")
TEMP_FOLDER = re.compile(r"(?:/private)?(?:/var/folders/[\w.-]+/[\w.-]+/T|/tmp|/var/tmp)/[\w.-]+")
#: What an absolute path of a machine looks like in an output (for the test).
ABSOLUTE_PATH = re.compile(r"(?<![\w.~<>-])/(?:work|tmp|root|home|Users|var|opt|usr|mnt|private)/")


def source_sha256(notebook: dict) -> str:
    """The hash of a notebook's cells (type and source, in order) and its kernel."""
    cells = [(c["cell_type"], "".join(c["source"]) if isinstance(c["source"], list)
              else c["source"]) for c in notebook["cells"]]  # fmt: skip
    kernel = notebook.get("metadata", {}).get("kernelspec", {}).get("name", "")
    text = json.dumps([kernel, cells], ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _clean_text(text: str) -> str:
    """``text`` with this machine's paths replaced, base64 runs left as they are."""
    home = str(Path.home())

    def clean(part: str) -> str:
        part = part.replace(str(ROOT), "<repo>")
        part = TEMP_FOLDER.sub("<tmp>", part)
        return part.replace(home + "/", "~/") if home not in ("/", "") else part

    pieces, at = [], 0
    for match in BASE64_RUN.finditer(text):
        pieces += [clean(text[at : match.start()]), match.group(0)]
        at = match.end()
    return "".join([*pieces, clean(text[at:])])


def outputs_text(notebook) -> list[str]:
    """Every text of every output (stream, plain text, HTML, Markdown), base64 runs out."""
    out = []
    for cell in notebook.cells:
        for output in cell.get("outputs", []):
            texts = [output.get("text", "")]
            texts += [v for k, v in output.get("data", {}).items()
                      if k.startswith("text/") or k == "application/json"]  # fmt: skip
            for t in texts:
                t = t if isinstance(t, str) else json.dumps(t)
                out.append(BASE64_RUN.sub("", t))
    return out


def clean_outputs(notebook) -> None:
    """This machine's paths out of every output's text (in place)."""
    for cell in notebook.cells:
        for output in cell.get("outputs", []):
            if "text" in output:
                output["text"] = _clean_text(output["text"])
            for key, value in output.get("data", {}).items():
                if key.startswith("text/") and isinstance(value, str):
                    output["data"][key] = _clean_text(value)


def store(name: str) -> float:
    """Execute ``name``.ipynb here and write it back with its outputs; seconds taken."""
    import nbformat
    from nbclient import NotebookClient

    path = HERE / f"{name}.ipynb"
    notebook = nbformat.read(path, as_version=4)
    start = time.perf_counter()
    NotebookClient(notebook, timeout=None, kernel_name="python3",
                   resources={"metadata": {"path": str(HERE)}}).execute()  # fmt: skip
    clean_outputs(notebook)
    notebook.metadata["cassi_fit"] = {"source_sha256": source_sha256(notebook)}
    for cell in notebook.cells:  # no machine's timing or ids in the stored file
        cell.get("metadata", {}).pop("execution", None)
    nbformat.write(notebook, path)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(NOTEBOOKS))
    args = parser.parse_args(argv)
    for name in args.names:
        if name not in NOTEBOOKS:
            print(f"store_outputs: no notebook {name!r} (one of {', '.join(NOTEBOOKS)})",
                  file=sys.stderr)  # fmt: skip
            return 2
    for name in args.names:
        seconds = store(name)
        size = (HERE / f"{name}.ipynb").stat().st_size
        print(f"stored notebooks/{name}.ipynb ({seconds:.0f} s, {size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
