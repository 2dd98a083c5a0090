"""Safe file writing shared by every writer in the toolkit.

Two promises: whatever the toolkit writes is written atomically (a temporary file in the
same folder, then ``os.replace``), and it never overwrites a file that it has read as
input in this process. Readers call :func:`register_input` on every path they open.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO

from .errors import OutputExistsError

_INPUT_FILES: set[str] = set()


def _key(path: str | os.PathLike) -> str:
    return os.path.realpath(os.fspath(path))


def register_input(path: str | os.PathLike) -> None:
    """Remember that ``path`` was read as input, so that no writer may replace it."""
    _INPUT_FILES.add(_key(path))


def is_input(path: str | os.PathLike) -> bool:
    return _key(path) in _INPUT_FILES


def atomic_write(
    path: str | os.PathLike,
    write: Callable[[IO], None] | bytes | str,
    *,
    overwrite: bool = False,
    binary: bool | None = None,
) -> Path:
    """Write ``path`` atomically.

    ``write`` is either the content (``bytes`` or ``str``) or a callable that receives an
    open file object. Refuses (``OutputExistsError``) to replace a file read as input in
    this process, and to replace any existing file unless ``overwrite`` is true. Parent
    folders are created. Returns the path written.
    """
    path = Path(path)
    if is_input(path):
        raise OutputExistsError(f"{path}: refusing to overwrite an input file")
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: file exists (pass overwrite=True / --force to replace it)")
    path.parent.mkdir(parents=True, exist_ok=True)
    if binary is None:
        binary = isinstance(write, bytes)
    mode = "wb" if binary else "w"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        kwargs = {} if binary else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, mode, **kwargs) as fh:
            if callable(write):
                write(fh)
            else:
                fh.write(write)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_output_path(path: str | os.PathLike, *, overwrite: bool = False) -> tuple[Path, Path]:
    """For writers that need a file name (ffmpeg, trimesh): returns ``(tmp, final)``.

    Write to ``tmp`` (same folder, same suffix), then call :func:`commit_output`.
    The same refusals as :func:`atomic_write` apply.
    """
    final = Path(path)
    if is_input(final):
        raise OutputExistsError(f"{final}: refusing to overwrite an input file")
    if final.exists() and not overwrite:
        raise OutputExistsError(f"{final}: file exists (pass overwrite=True / --force to replace it)")
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=final.suffix, dir=final.parent)
    os.close(fd)
    return Path(tmp), final


def commit_output(tmp: str | os.PathLike, final: str | os.PathLike) -> Path:
    """Move a finished temporary output into place (atomic on one file system)."""
    os.replace(tmp, final)
    return Path(final)


def read_json(path: str | os.PathLike, what: str):
    """The JSON document in ``path``, registered as an input: ``MissingDataError`` if
    there is no such file (``what`` names it), ``DataFormatError`` naming the file and
    the line if it is not valid JSON."""
    import json

    from .errors import DataFormatError, MissingDataError

    path = Path(path)
    if not path.is_file():
        raise MissingDataError(f"{path}: {what} not found")
    register_input(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise DataFormatError(path, exc.lineno, f"invalid JSON: {exc.msg}") from None
