"""Safe file writing shared by every writer in the toolkit.

Promises:

- whatever the toolkit writes is written atomically: a hidden temporary file in the same
  folder, removed on any failure or interrupt (``except BaseException``), then moved into
  place by ``os.replace``; a partial file never appears under the final name;
- outputs get the user's normal mode (``0666`` less the process umask, as ``open()``
  gives), not the ``0600`` of ``tempfile.mkstemp``;
- a file read as input in this process is never replaced (readers call
  :func:`register_input`), and neither is an existing data file of the toolkit's input
  kinds (a pellet ``.txy``, ``PAL.DAT``/``PHA.DAT``, ``Headmeasures.txt``, a ``.wav``),
  even with ``overwrite``, unless the writer writes that kind of file itself
  (``data_file=True``: ``write_txy``, ``write_outline``, ...);
- an existing path that is not a regular file (a pipe, a device, a socket, a broken or
  looping link: :func:`special_kind`) is never written over, even with ``overwrite``:
  ``os.replace`` would swap the node for a regular file (a disk's device node included);
- :func:`check_outputs` lets a command check all its outputs at once, before any work:
  the rules above, plus no two outputs on one path; :func:`atomic_outputs` writes several
  files all or nothing (none appears unless all were written);

Every refusal is one line naming the file.
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from .errors import CassiError, OutputExistsError

_INPUT_FILES: set[str] = set()

#: Data files of a recording, by name (lower case): what no other output may replace.
_DATA_SUFFIXES = {".txy": "a pellet file", ".wav": "a sound file"}
_DATA_NAMES = {
    "pal.dat": "a palate trace",
    "pha.dat": "a pharynx trace",
    "headmeasures.txt": "a Headmeasures file",
}


def _key(path: str | os.PathLike) -> str:
    return os.path.realpath(os.fspath(path))


def register_input(path: str | os.PathLike) -> None:
    """Remember that ``path`` was read as input, so that no writer may replace it."""
    _INPUT_FILES.add(_key(path))


def is_input(path: str | os.PathLike) -> bool:
    """Whether ``path`` (after resolving links) was registered as an input file."""
    return _key(path) in _INPUT_FILES


def data_kind(path: str | os.PathLike) -> str | None:
    """The kind of recording data file ``path`` names (``"a pellet file"``, ...), or None.

    By name, case-insensitively: ``*.txy``, ``*.wav``, ``PAL.DAT``/``PHA.DAT`` (also the
    flat layout's ``jw11_pal.dat``), ``Headmeasures.txt``.
    """
    name = Path(path).name.lower()
    for ending, kind in _DATA_NAMES.items():
        if name == ending or name.endswith("_" + ending):
            return kind
    return _DATA_SUFFIXES.get(Path(name).suffix)


def special_kind(path: str | os.PathLike) -> str | None:
    """What ``path`` is when it exists but is neither a regular file (nor a link to one)
    nor a folder: ``"a named pipe (FIFO)"``, ``"a character device"``, ``"a block
    device"``, ``"a socket"``, ``"a broken link"``, ``"a link that loops"``; else None
    (absent, a regular file, a folder). Never opens ``path``: ``os.stat`` only (opening a
    FIFO for reading blocks until a writer comes)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "a broken link" if os.path.islink(path) else None
    except OSError:  # ELOOP, a name too long, ...
        return "a link that loops" if os.path.islink(path) else None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    for test, kind in ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character "
                       "device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "a special file"


def check_output(
    path: str | os.PathLike, *, overwrite: bool = False, data_file: bool = False
) -> Path:
    """``path`` as a ``Path`` if a writer may create or replace it; else one clear error.

    Refused (:class:`OutputExistsError`): a registered input; an existing path that is
    not a regular file or a link to one (:func:`special_kind`: a pipe, device, socket,
    broken link), whatever ``overwrite`` says; an existing data file (:func:`data_kind`)
    unless ``data_file`` (the writer writes that kind of file) and ``overwrite``; any
    other existing file unless ``overwrite``. :class:`CassiError`: a folder, or a path
    under a file.
    """
    path = Path(path)
    if is_input(path):
        raise OutputExistsError(f"{path}: refusing to overwrite an input file")
    special = special_kind(path)
    if special is not None:
        raise OutputExistsError(f"{path}: is {special}, not a regular file; refusing to "
                                "write over it (even with --force); choose another name")
    if path.is_dir():
        raise CassiError(f"{path}: is a folder, not a file name")
    if any(parent.exists() and not parent.is_dir() for parent in path.parents):
        raise CassiError(f"{path}: cannot be written, a parent is a file, not a folder")
    if not os.path.lexists(path):
        return path
    kind = data_kind(path)
    if kind is not None and not data_file:
        raise OutputExistsError(f"{path}: refusing to replace {kind} (recording data)")
    if not overwrite:
        raise OutputExistsError(
            f"{path}: file exists (pass overwrite=True / --force to replace it)"
        )
    return path


def check_output_folder(path: str | os.PathLike) -> Path:
    """``path`` as a ``Path`` if it is a folder or absent (a writer may create it), else
    one :class:`CassiError` saying what it is (a file, a pipe, a device, a broken link, a
    path under a file): for commands whose output is a folder (``--out DIR``), before
    any work, not once per file at the end."""
    path = Path(path)
    special = special_kind(path)
    if special is not None:
        raise CassiError(f"{path}: is {special}, not a folder; give a folder for the outputs")
    if path.exists() and not path.is_dir():
        raise CassiError(f"{path}: is a file, not a folder; give a folder for the outputs")
    if any(parent.exists() and not parent.is_dir() for parent in path.parents):
        raise CassiError(f"{path}: cannot be a folder, a parent is a file, not a folder")
    return path


def check_outputs(
    paths: Iterable[str | os.PathLike | None], *, overwrite: bool = False
) -> list[Path]:
    """Check all the outputs of one command before it does any work.

    ``paths``: the command's output files (``None`` entries, unused options, are
    skipped). Each must pass :func:`check_output` (no input, no recording data file, no
    existing file unless ``overwrite``), and no two may be the same file (after resolving
    links), e.g. ``--penetration`` equal to ``--out``. Returns the paths as ``Path``.
    """
    out: list[Path] = []
    seen: dict[str, Path] = {}
    for given in paths:
        if given is None:
            continue
        path = check_output(given, overwrite=overwrite)
        first = seen.setdefault(_key(path), path)
        if first is not path:
            raise OutputExistsError(f"{path}: given twice as an output (also as {first})")
        out.append(path)
    return out


def _umask() -> int:
    """The process umask (read from /proc where possible, so that it is never changed)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)  # no other way to read it; put it back at once
    os.umask(mask)
    return mask


def default_mode() -> int:
    """The mode ``open()`` gives a new file: ``0o666`` less the process umask."""
    return 0o666 & ~_umask()


def _temporary(final: Path) -> tuple[int, Path]:
    """A new hidden file next to ``final``, same suffix, mode ``0666 & ~umask``: (fd, path)."""
    for _ in range(100):
        # The real suffix stays last: ffmpeg, trimesh and matplotlib go by it.
        tmp = final.with_name(f".{final.stem}.{secrets.token_hex(4)}.part{final.suffix}")
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), tmp
        except FileExistsError:
            continue
    raise OutputExistsError(f"{final}: could not create a temporary file next to it")


def _prepare(path: str | os.PathLike, overwrite: bool, data_file: bool) -> Path:
    final = check_output(path, overwrite=overwrite, data_file=data_file)
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CassiError(f"{final}: cannot create its folder ({exc.strerror})") from None
    return final


def remove_quietly(path: str | os.PathLike | None) -> None:
    """Delete ``path`` if it exists (clean-up on a failure path: never raises OSError)."""
    if path is None:
        return
    try:
        os.unlink(path)
    except OSError:
        pass


def atomic_write(
    path: str | os.PathLike,
    write: Callable[[IO[Any]], None] | bytes | str,
    *,
    overwrite: bool = False,
    binary: bool | None = None,
    data_file: bool = False,
) -> Path:
    """Write ``path`` atomically; returns the path written.

    ``write`` is either the content (``bytes`` or ``str``, text as UTF-8 with newlines
    kept) or a callable that receives an open file object. The refusals are those of
    :func:`check_output`; parent folders are created; the file gets the user's normal
    mode. On any failure, ``KeyboardInterrupt`` included, nothing is left behind.
    """
    final = _prepare(path, overwrite, data_file)
    if binary is None:
        binary = isinstance(write, bytes)
    fd, tmp = _temporary(final)
    try:
        kwargs = {} if binary else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, "wb" if binary else "w", **kwargs) as fh:
            if callable(write):
                write(fh)
            else:
                fh.write(write)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, final)
    except BaseException:
        remove_quietly(tmp)
        raise
    return final


def atomic_output_path(
    path: str | os.PathLike, *, overwrite: bool = False, data_file: bool = False
) -> tuple[Path, Path]:
    """For writers that need a file name (ffmpeg, trimesh, matplotlib): ``(tmp, final)``.

    ``tmp`` exists (empty, the user's normal mode), is hidden, in the same folder, with
    the same suffix. Write to it, then call :func:`commit_output`; on failure call
    :func:`remove_quietly` (``tmp``). The same refusals as :func:`atomic_write` apply.
    """
    final = _prepare(path, overwrite, data_file)
    fd, tmp = _temporary(final)
    os.close(fd)
    return tmp, final


def commit_output(tmp: str | os.PathLike, final: str | os.PathLike) -> Path:
    """Move a finished temporary output into place (atomic on one file system), with the
    user's normal mode whatever created ``tmp``."""
    os.chmod(tmp, default_mode())
    os.replace(tmp, final)
    return Path(final)


class OutputGroup:
    """Several outputs written all or nothing; made by :func:`atomic_outputs`."""

    def __init__(self, overwrite: bool):
        self.overwrite = overwrite
        self._pending: dict[str, tuple[Path, Path]] = {}  # key -> (tmp, final)

    def path(self, path: str | os.PathLike, *, data_file: bool = False) -> Path:
        """A temporary file to write ``path``'s content to (for writers that need a
        name, e.g. matplotlib); it is moved to ``path`` when the group ends well."""
        final = _prepare(path, self.overwrite, data_file)
        if _key(final) in self._pending:
            raise OutputExistsError(f"{final}: given twice as an output")
        fd, tmp = _temporary(final)
        os.close(fd)
        self._pending[_key(final)] = (tmp, final)
        return tmp

    def write(
        self,
        path: str | os.PathLike,
        content: bytes | str,
        *,
        data_file: bool = False,
    ) -> Path:
        """Stage ``content`` (bytes, or text written as UTF-8) for ``path``; returns ``path``."""
        tmp = self.path(path, data_file=data_file)
        if isinstance(content, bytes):
            tmp.write_bytes(content)
        else:
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                fh.write(content)
        return self._pending[_key(path)][1]

    def _commit(self) -> list[Path]:
        for tmp, _ in self._pending.values():
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
        return [commit_output(tmp, final) for tmp, final in self._pending.values()]

    def _discard(self) -> None:
        for tmp, _ in self._pending.values():
            remove_quietly(tmp)


@contextmanager
def atomic_outputs(*, overwrite: bool = False) -> Iterator[OutputGroup]:
    """Write several files all or nothing: ``with atomic_outputs(overwrite=f) as group:``
    then ``group.write(path, text)`` or ``group.path(path)`` (a temporary to write to).

    Each path is checked as :func:`check_output` says (and none twice) when it is staged.
    Only when the block ends without error are the files moved into place, one
    ``os.replace`` each; on any error or interrupt every temporary is removed and no
    output appears (e.g. an evaluation's table, report and figures).
    """
    group = OutputGroup(overwrite)
    try:
        yield group
        group._commit()
    except BaseException:
        group._discard()
        raise


def decode_text(path: str | os.PathLike, raw: bytes) -> str:
    """A text file's bytes as a text editor may have written them: UTF-8 with or without
    a byte-order mark, or UTF-16 with one (little- or big-endian). ``DataFormatError``
    naming the file and the line of the first byte that is not such text (UTF-16
    without a byte-order mark, Latin-1 ...)."""
    import codecs

    from .errors import DataFormatError

    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        encoding, body = "utf-16", raw  # the codec reads the mark and the byte order
    else:
        encoding, body = "utf-8", raw.removeprefix(codecs.BOM_UTF8)
    try:
        text = body.decode(encoding)
    except UnicodeDecodeError as exc:
        line = body[: exc.start].decode(encoding, errors="replace").count("\n") + 1
        raise DataFormatError(path, line, f"not a text file in UTF-8, or UTF-16 with a "
                              f"byte-order mark (byte {body[exc.start]:#04x}); save it as "
                              "UTF-8") from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise DataFormatError(path, line, "a NUL character: UTF-16 without a byte-order mark? "
                              "save it as UTF-8")
    return text


def read_text(path: str | os.PathLike, what: str = "file") -> str:
    """The text of ``path`` (:func:`decode_text`), registered as an input; the one reader
    of the toolkit's text input. ``MissingDataError`` if there is no such file (``what``
    names it), ``DataFormatError`` if it is a folder, not a regular file (a FIFO would
    block) or not text."""
    import stat

    from .errors import DataFormatError, MissingDataError

    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise MissingDataError(f"{path}: no such file ({what} not found)") from None
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise DataFormatError(path, None, f"is a folder, not a file ({what} expected)")
    if not stat.S_ISREG(mode):
        raise DataFormatError(path, None, f"not a regular file (a pipe, device or socket; "
                              f"{what} expected)")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read: {exc.strerror or exc}") from None
    register_input(path)
    return decode_text(path, raw)


def read_lines(path: str | os.PathLike, what: str = "file") -> tuple[Path, list[tuple[int, str]]]:
    """A text data file (:func:`read_text`) as ``(lineno, line)`` pairs: CRLF, CR or LF
    line ends, blank (white-space only) lines dropped, line numbers 1-based as stored.
    Shared by the toolkit's line-based readers (pellet files, outlines, Headmeasures,
    labels, articulograph text files)."""
    text = read_text(path, what).replace("\r\n", "\n").replace("\r", "\n")
    return Path(path), [(i + 1, s) for i, s in enumerate(text.split("\n")) if s.strip()]


def parse_json(path: str | os.PathLike, text: str) -> Any:
    """The JSON document ``text`` (read from ``path``): ``DataFormatError`` naming the
    file and the line if it is not valid JSON."""
    import json

    from .errors import DataFormatError

    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataFormatError(path, exc.lineno, f"invalid JSON: {exc.msg}") from None


def read_json(path: str | os.PathLike, what: str) -> Any:
    """The JSON document in ``path`` (:func:`read_text`, :func:`parse_json`), registered
    as an input: ``MissingDataError`` if there is no such file (``what`` names it),
    ``DataFormatError`` naming the file and the line if it is not valid JSON."""
    return parse_json(path, read_text(path, what))
