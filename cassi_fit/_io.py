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
- :func:`foreign_data` lists the recording data in a folder that the synthetic corpus
  writer did not write, so that a generator never writes into a real dataset.

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


#: How the synthetic corpus writers mark what they wrote (``cassi_fit.synth``,
#: ``cassi_fit.ema.synthetic``; tests/test_hostile.py checks that a corpus they write has
#: no :func:`foreign_data`): the first line of the corpus README and of each recording's
#: ground-truth sidecar ``<task>.truth.csv``; each subject folder holds ``anatomy.json``.
SYNTHETIC_README_START = "cassi_fit synthetic"
SYNTHETIC_TRUTH_START = "# cassi_fit synthetic ground truth"
#: Recording data besides :func:`data_kind`'s: articulograph files and label files.
_RECORDING_SUFFIXES = (".ema", ".pos", ".tsv", ".mat", ".lab", ".textgrid")
_SMALL_FILE = 1 << 20  # sidecars and Headmeasures files are kilobytes; more is not ours


def _entries(folder: Path) -> list[Path]:
    """The visible entries of ``folder`` (no ``.`` names), sorted; none if unreadable."""
    try:
        return sorted(p for p in folder.iterdir() if not p.name.startswith("."))
    except OSError:
        return []


def _head_text(path: Path, size: int = 256) -> str | None:
    """The first ``size`` bytes of a regular file as text, None if it cannot be read."""
    try:
        with open(path, "rb") as fh:  # callers checked special_kind: a regular file
            return fh.read(size).decode("utf-8", errors="replace")
    except OSError:
        return None


def _small_text(path: Path) -> str | None:
    """A regular file's whole text if it is small (< 1 MiB), else None."""
    try:
        if path.stat().st_size >= _SMALL_FILE:
            return None
        return path.read_bytes().decode("utf-8", errors="replace")
    except OSError:
        return None


def _synthetic_subject(folder: Path) -> bool:
    """A subject folder the synthetic writer made: its ``anatomy.json`` names it."""
    import json

    anatomy = folder / "anatomy.json"
    if special_kind(anatomy) is not None or not anatomy.is_file():
        return False
    text = _small_text(anatomy)
    try:
        data = json.loads(text) if text is not None else None
    except ValueError:
        return False
    return isinstance(data, dict) and str(data.get("name", "")).upper() == folder.name.upper()


def _headmeasures_subjects(path: Path) -> set[str] | None:
    """The subjects a ``Headmeasures.txt`` lists (upper case), None if unreadable."""
    text = _small_text(path)
    if text is None:
        return None
    rows = [line.split("#", 1)[0].split() for line in text.splitlines()]
    rows = [r for r in rows if r]
    return {r[0].upper() for r in rows[1:]}


def _is_recording_data(path: Path) -> bool:
    return data_kind(path) is not None or path.suffix.lower() in _RECORDING_SUFFIXES


def _foreign_in_subject(folder: Path, synthetic: bool) -> list[Path]:
    """The data in one subject folder that the synthetic writer did not write."""
    entries = [p for p in _entries(folder) if not p.is_dir()]
    truths = {}
    for p in entries:
        if p.name.lower().endswith(".truth.csv") and special_kind(p) is None:
            text = _head_text(p)
            truths[p.name[:-len(".truth.csv")].lower()] = bool(
                text and text.startswith(SYNTHETIC_TRUTH_START))
    bite_ok = synthetic and (folder / "frame.json").is_file()  # an EMA corpus's bite plane
    found = []
    for p in entries:
        name = p.name.lower()
        if special_kind(p) is not None:
            found.append(p)
        elif name.endswith(".truth.csv"):
            if not truths.get(name[:-len(".truth.csv")]):
                found.append(p)
        elif not _is_recording_data(p):
            continue
        elif not synthetic or name.endswith(("headmeasures.txt", ".lab", ".textgrid")):
            found.append(p)  # synth writes no labels and no per-subject Headmeasures
        elif data_kind(p) in ("a palate trace", "a pharynx trace"):
            continue  # the subject's anatomy.json goes with them
        elif not (truths.get(p.stem.lower()) or (bite_ok and "bite" in name)):
            found.append(p)
    return found


def foreign_data(folder: str | os.PathLike) -> list[Path]:
    """The recording data in ``folder`` that a synthetic corpus writer did not write.

    Looks where a dataset lives (``folder`` and its subject folders, names starting with
    ``.`` aside), reading only small sidecars, never a special file: every pipe, device,
    socket or broken link; every recording data file (pellet ``.txy``, ``.wav``,
    ``PAL.DAT``/``PHA.DAT``, ``Headmeasures.txt``, articulograph files, ``.lab`` and
    ``.TextGrid`` labels) without the synthetic writers' marks
    (:data:`SYNTHETIC_README_START`, :data:`SYNTHETIC_TRUTH_START`): a recording without
    its synthetic ``<task>.truth.csv``, an outline in a folder without the subject's
    ``anatomy.json``, a ``Headmeasures.txt`` listing a subject that is not synthetic,
    a ``README.txt`` that is not a synthetic corpus's, any label file. Sorted; empty
    for an absent or empty folder, or a corpus the writers wrote.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    entries = _entries(folder)
    subjects = [p for p in entries if p.is_dir()]
    synthetic = {p.name.upper() for p in subjects if _synthetic_subject(p)}
    found = []
    for p in entries:
        name = p.name.lower()
        if p.is_dir():
            continue
        if special_kind(p) is not None:
            found.append(p)
        elif name == "readme.txt":
            text = _head_text(p)
            if not (text and text.startswith(SYNTHETIC_README_START)):
                found.append(p)
        elif name == "headmeasures.txt":
            listed = _headmeasures_subjects(p)
            if listed is None or not listed <= synthetic:
                found.append(p)
        elif _is_recording_data(p) or name.endswith(".truth.csv"):
            found.append(p)  # the synthetic corpus has subject folders, nothing flat
    for sub in subjects:
        found += _foreign_in_subject(sub, sub.name.upper() in synthetic)
    return sorted(found)


def refuse_foreign_data(folder: str | os.PathLike, writer: str = "cassi synth") -> None:
    """One :class:`OutputExistsError` naming ``folder`` and the first of its
    :func:`foreign_data` if it holds any, whatever ``overwrite`` says (``writer`` names
    the writer in the message); nothing otherwise. For the synthetic corpus writers, before
    they write anything."""
    found = foreign_data(folder)
    if found:
        more = f" and {len(found) - 1} more" if len(found) > 1 else ""
        raise OutputExistsError(
            f"{folder}: holds data {writer} did not write ({found[0]}{more}); refusing to "
            "write into it, even with --force: choose a new or empty folder")


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


# ------------------------------------------------------------------- interruptions
# Ctrl-C (SIGINT) and SIGTERM end a command as an exception, KeyboardInterrupt, so that
# every writer's clean-up runs (``except BaseException``: temporaries removed, ffmpeg
# killed, the OpenGL context released) and the command prints one line. Python's own
# handler raises it wherever the main thread happens to be, which goes wrong in three
# places, all met in practice:
#
# * inside the initialisation of an extension module (JAX's jaxlib, while ``import jax``
#   runs): the extension fails half-built and the process aborts ("terminate called after
#   throwing an instance of 'nanobind::python_error'") or raises ImportError;
# * inside a garbage-collection callback or a ``__del__`` (JAX's ``_xla_gc_callback`` runs
#   at every collection, and collections are frequent while JAX traces): Python prints
#   "Exception ignored in ..." with a traceback and drops the interrupt, so the command
#   runs on to the end;
# * after the command, while the interpreter shuts down with JAX's and Mesa's threads
#   still running: a segmentation fault.
#
# So here the handler defers the interrupt while an extension module initialises (and in
# explicit ``defer_interrupts()`` blocks), re-delivers one that a callback swallowed
# (``sys.unraisablehook``), both through a 20 ms timer (SIGALRM), and leaves the clean-up
# of the first interrupt undisturbed by further signals (a third one ends the process at
# once). A command run as a program (``cli.main()``) ends with ``os._exit`` after its
# clean-up, so that no interpreter shutdown runs after an interrupt.

INTERRUPT_EXIT_STATUS = 130
"""The exit status of an interrupted command (128 + SIGINT, whichever signal it was)."""

_RETRY_S = 0.02  # seconds before a deferred or swallowed interrupt is delivered again
_EXTENSION_INIT = frozenset({"ExtensionFileLoader.create_module",
                             "ExtensionFileLoader.exec_module"})


class _Interrupts:
    """The process's interrupt state (signal handlers run in the main thread only)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.raised = False  # a KeyboardInterrupt is unwinding: its clean-up runs
        self.pending: int | None = None  # a signal not delivered yet
        self.last = 2  # the signal last raised as KeyboardInterrupt (SIGINT)
        self.deferred = 0  # depth of defer_interrupts() blocks
        self.signals = 0  # signals received since the handlers were installed
        self.worker = False  # a pool worker: SIGTERM between tasks ends it quietly
        self.in_task = False


_STATE = _Interrupts()


def _in_extension_init(frame: Any) -> bool:
    while frame is not None:
        if getattr(frame.f_code, "co_qualname", "") in _EXTENSION_INIT:
            return True
        frame = frame.f_back
    return False


def _flush_and_exit(status: int, line: str | None = "cassi: interrupted") -> None:
    """End the process now: ``line`` on stderr, the standard streams flushed, no
    interpreter shutdown (``os._exit``)."""
    import sys

    if "multiprocessing.resource_tracker" in sys.modules:
        import gc

        gc.collect()  # a finished pool's semaphores released: no "leaked" warning at exit
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    if line:
        try:
            os.write(2, (line + "\n").encode())
        except OSError:
            pass
    os._exit(status)


def _deliver_later() -> None:
    import signal

    signal.setitimer(signal.ITIMER_REAL, _RETRY_S)


def _on_signal(signum: int, frame: Any) -> None:
    state = _STATE
    state.signals += 1
    if state.raised:  # the first interrupt's clean-up is running: leave it be
        if state.signals >= 3:
            _flush_and_exit(INTERRUPT_EXIT_STATUS)
        return
    if state.worker and not state.in_task:  # a pool worker between tasks: just end
        _flush_and_exit(128 + signum, None)
    state.pending = signum
    _deliver(frame)


def _deliver(frame: Any) -> None:
    """Raise the pending interrupt here, unless this is no place for it (then later)."""
    state = _STATE
    if state.pending is None or state.raised:
        return
    if state.deferred:
        return  # raised when the outermost defer_interrupts() block ends
    if _in_extension_init(frame):
        _deliver_later()
        return
    signum, state.pending, state.raised, state.last = state.pending, None, True, state.pending
    raise KeyboardInterrupt(f"signal {signum}")


def _on_retry(signum: int, frame: Any) -> None:
    _deliver(frame)


def _on_unraisable(hook: Any) -> None:
    """A KeyboardInterrupt that a callback or ``__del__`` swallowed: delivered again."""
    if isinstance(hook.exc_value, KeyboardInterrupt) and _STATE.raised:
        _STATE.raised = False
        _STATE.pending = _STATE.last
        _deliver_later()
        return
    _PREVIOUS_HOOK[-1](hook)


_PREVIOUS_HOOK: list = []


@contextmanager
def defer_interrupts() -> Iterator[None]:
    """Within the block, an interrupt (SIGINT, SIGTERM) waits until the block ends: for
    short steps that must not stop half-way (moving a group of outputs into place,
    releasing an OpenGL context). Only under :func:`interruptible` (elsewhere a plain
    block)."""
    _STATE.deferred += 1
    try:
        yield
    finally:
        _STATE.deferred -= 1
    if not _STATE.deferred and _STATE.pending is not None:
        import sys

        _deliver(sys._getframe())


@contextmanager
def interruptible() -> Iterator[None]:
    """Within the block (a command's main function, in the main thread), SIGINT and
    SIGTERM raise ``KeyboardInterrupt`` where it is safe to (see the comment above), so
    that the writers' clean-up runs and no temporary file stays. Outside the main thread
    it does nothing (Python delivers signals there only). The previous handlers are
    restored when the block ends; a signal the process was started to ignore stays
    ignored."""
    import signal
    import sys
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    previous_alarm = signal.getsignal(signal.SIGALRM)
    _STATE.reset()
    _PREVIOUS_HOOK.append(sys.unraisablehook)
    sys.unraisablehook = _on_unraisable
    signal.signal(signal.SIGALRM, _on_retry)
    for signum, handler in previous.items():
        if handler is not signal.SIG_IGN:  # ignored (a background job's Ctrl-C): kept so
            signal.signal(signum, _on_signal)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        signal.signal(signal.SIGALRM, previous_alarm)
        sys.unraisablehook = _PREVIOUS_HOOK.pop()
        _STATE.reset()


#: The name the toolkit's commands used first: SIGTERM (and SIGINT) as KeyboardInterrupt.
terminate_as_interrupt = interruptible


def exit_on_signal() -> None:
    """From now on, SIGINT or SIGTERM end the process at once with one line and the
    interrupted status (:data:`INTERRUPT_EXIT_STATUS`), without interpreter shutdown: for
    a program whose work is done (or was interrupted) while it exits."""
    import signal

    def leave(signum: int, frame: Any) -> None:
        _flush_and_exit(INTERRUPT_EXIT_STATUS)

    for signum in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, leave)


def worker_signals() -> None:
    """Signals in a pool's worker process (before its first task): Ctrl-C is ignored (the
    terminal sends it to the whole process group; the parent process decides and stops
    its workers), SIGTERM raises ``KeyboardInterrupt`` in a task (its writers clean up;
    :func:`in_task` marks a task) and ends the worker quietly between tasks. Signals that
    the parent blocked while starting the worker (:func:`signals_blocked`) are let in
    after the handlers are set."""
    import signal
    import sys

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _STATE.reset()
    _STATE.worker = True
    if not _PREVIOUS_HOOK:
        _PREVIOUS_HOOK.append(sys.unraisablehook)
        sys.unraisablehook = _on_unraisable
    signal.signal(signal.SIGALRM, _on_retry)
    signal.signal(signal.SIGTERM, _on_signal)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def end_worker() -> None:
    """End this pool worker now, quietly, with SIGTERM's status (after an interrupted
    task's clean-up)."""
    _flush_and_exit(128 + 15, None)


def is_worker() -> bool:
    """Whether this process is a pool worker set up by :func:`worker_signals`."""
    return _STATE.worker


@contextmanager
def in_task() -> Iterator[None]:
    """Marks a task running in a pool worker (SIGTERM interrupts it rather than ending
    the worker outright)."""
    _STATE.in_task = True
    try:
        yield
    finally:
        _STATE.in_task = False


@contextmanager
def signals_blocked() -> Iterator[None]:
    """Within the block SIGINT and SIGTERM wait (blocked, not lost: delivered when it
    ends), and the processes started in it begin with them blocked, so that a worker is
    not interrupted before it has set its handlers (:func:`worker_signals`)."""
    import signal
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()  # it unblocks both signals when it starts
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


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
        raise DataFormatError(path, line, f"not text in UTF-8 or UTF-16 with a byte-order "
                              f"mark (byte {body[exc.start]:#04x}); save it as UTF-8") from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise DataFormatError(path, line, "a NUL character: UTF-16 without a byte-order mark? "
                              "save it as UTF-8")
    return text


def read_text(path: str | os.PathLike, what: str) -> str:
    """The text of ``path`` (:func:`decode_text`), registered as an input:
    ``MissingDataError`` if there is no such file (``what`` names it),
    ``DataFormatError`` if it is not a regular file (a FIFO would block) or not text."""
    import stat

    from .errors import DataFormatError, MissingDataError

    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise MissingDataError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        kind = "a folder" if stat.S_ISDIR(mode) else "a pipe, device or socket"
        raise DataFormatError(path, None, f"{what} expected, found {kind}")
    register_input(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read: {exc.strerror or exc}") from None
    return decode_text(path, raw)


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
