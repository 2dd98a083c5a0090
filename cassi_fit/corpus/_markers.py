"""Completion markers: what makes a corpus run resumable (see the package docstring)."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from .._io import atomic_write
from ._items import CorpusItem, TaskResult

MARKER_DIR = ".cassi-corpus"


def marker_path(out_dir: str | os.PathLike, item: CorpusItem) -> Path:
    """Where ``item``'s completion marker lives."""
    return Path(out_dir) / MARKER_DIR / item.subject / f"{item.task or '_subject'}.json"


def task_fingerprint(task: Callable, options: Mapping[str, Any]) -> str:
    """SHA-256 of the task's qualified name and its options: a marker written with other
    settings does not count as done."""
    text = json.dumps([task.__module__, task.__qualname__, dict(sorted(options.items()))],
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _file_digest(path: Path) -> dict:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return {"bytes": path.stat().st_size, "sha256": h.hexdigest()}


def _write_marker(out_dir: str, item: CorpusItem, fingerprint: str, result: TaskResult):
    root = Path(out_dir)
    outputs = {}
    for p in result.outputs:
        p = Path(p)
        rel = os.path.relpath(p, root) if p.is_absolute() else str(p)
        outputs[rel] = _file_digest(root / rel)
    # the keys are sorted in the file: "columns" keeps the row's own order, which is the
    # table's column order (a resumed row must give the same table as a computed one)
    doc = {"subject": item.subject, "task": item.task, "fingerprint": fingerprint,
           "row": result.row, "columns": list(result.row), "outputs": outputs}
    text = json.dumps(doc, indent=1, sort_keys=True, default=_json_scalar) + "\n"
    atomic_write(marker_path(out_dir, item), text, overwrite=True)


def _json_scalar(value):
    """numpy scalars in rows (``np.int64``, ``np.bool_``) as Python numbers."""
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"a row value of type {type(value).__name__} cannot be stored")


def completed_row(out_dir: str | os.PathLike, item: CorpusItem, fingerprint: str) -> dict | None:
    """The row stored for ``item`` if its marker exists, was written with ``fingerprint``
    and every output it lists is present with the recorded size and SHA-256; else None."""
    path = marker_path(out_dir, item)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if doc.get("fingerprint") != fingerprint:
        return None
    for rel, want in doc.get("outputs", {}).items():
        out = Path(out_dir) / rel
        if not out.is_file() or out.stat().st_size != want["bytes"] or _file_digest(out) != want:
            return None
    row = doc["row"]
    return {k: row[k] for k in doc.get("columns", row)}
