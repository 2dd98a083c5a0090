"""Finding XRMB recordings on disk and loading each with its subject's data.

Two layouts are understood, case-insensitively (see ``docs/FORMATS.md``):

- folder per subject (the distribution): ``ROOT/JW11/TP005.TXY`` (or ``tp005.txy``,
  repeated trials ``tp020_2.txy``), ``ROOT/JW11/PAL.DAT``, ``ROOT/JW11/PHA.DAT``, audio
  ``ROOT/JW11/TP005.WAV``; ``Headmeasures.txt`` in the subject folder or at the root.
- flat: ``ROOT/jw11_tp005.txy``, ``ROOT/jw11_pal.dat``, ``ROOT/jw11_pha.dat``,
  ``ROOT/jw11_tp005.wav``, ``ROOT/Headmeasures.txt``.

A root that is itself one subject's folder (it holds a bare ``PAL.DAT``) also works.
Subject names are upper case (``JW11``, ``S01``), task names lower case (``tp005``).
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import DataFormatError, MissingDataError
from .headmeasures import DEFAULT_HEAD_MEASURES, HeadMeasures, read_headmeasures
from .outlines import read_outline
from .txy import PelletTrack, read_txy

PELLET_SUFFIX = ".txy"
HEADMEASURES_NAME = "headmeasures.txt"
_TRIAL = re.compile(r"[0-9]+")


class DefaultHeadMeasuresWarning(UserWarning):
    """A recording uses ``DEFAULT_HEAD_MEASURES`` because its subject has no measures."""


@dataclass(frozen=True, eq=False)
class Recording:
    """One subject performing one task, with everything the subject's folder holds.

    ``palate`` and ``pharynx`` are ``(n, 2)`` mm arrays or None when the file is absent;
    ``head`` falls back to ``DEFAULT_HEAD_MEASURES`` (``head_is_default`` True, with a
    :class:`DefaultHeadMeasuresWarning` once per subject); ``audio`` is the ``.wav`` with
    the pellet file's stem, or None.
    """

    subject: str
    task: str
    track: PelletTrack
    palate: np.ndarray | None
    pharynx: np.ndarray | None
    head: HeadMeasures
    head_is_default: bool
    audio: Path | None
    path: Path


def recording_source(recording: Recording) -> str:
    """The name of a recording in messages: its pellet file, else ``SUBJECT/TASK`` (any
    object with ``subject``, ``task``, ``track`` and optionally ``path``)."""
    path = getattr(recording, "path", None) or getattr(recording.track, "path", None)
    return str(path) if path is not None else f"{recording.subject}/{recording.task}"


def _listing(folder: Path) -> dict[str, Path]:
    """Lower-case file name -> path for the regular files in ``folder``.

    Names are matched case-insensitively, so two files whose names differ only in case
    (``TP101.TXY`` and ``tp101.txy``) would be one recording twice: a
    :class:`DataFormatError` naming both, never a silent pick.
    """
    try:
        files = sorted(p for p in folder.iterdir() if p.is_file())
    except OSError:
        return {}
    listing: dict[str, Path] = {}
    for path in files:
        other = listing.setdefault(path.name.lower(), path)
        if other is not path:
            raise DataFormatError(
                folder, None, f"{other.name} and {path.name} differ only in case: the same "
                "file name twice (names are matched case-insensitively); remove or rename one"
            )
    return listing


def _natural_key(name: str) -> list:
    return [int(s) if s.isdigit() else s for s in re.split(r"([0-9]+)", name)]


def _split_stem(stem: str, folder_name: str, names: dict[str, Path], subject_folder: bool):
    """``(subject, task)`` of a pellet file stem; subject None = the folder's subject."""
    stem = stem.lower()
    prefix, sep, rest = stem.partition("_")
    if sep and rest and prefix == folder_name.lower():
        return prefix.upper(), rest  # JW11/jw11_tp005.txy
    if sep and rest and (f"{prefix}_pal.dat" in names or f"{prefix}_pha.dat" in names):
        return prefix.upper(), rest  # flat, with the subject's palate beside it
    if subject_folder or "pal.dat" in names or "pha.dat" in names:
        return None, stem
    if sep and rest and not _TRIAL.fullmatch(rest):
        return prefix.upper(), rest  # flat: jw11_tp005 (but tp020_2 is a repeated trial)
    return None, stem


def _find(folders: list[Path], names: list[str]) -> Path | None:
    for folder in folders:
        listing = _listing(folder)
        for name in names:
            if name in listing:
                return listing[name]
    return None


_WARNED: set[tuple[str, str]] = set()


def _head_measures(subject: str, folders: list[Path]) -> tuple[HeadMeasures, bool]:
    """The subject's measures from the first ``Headmeasures.txt`` that lists it."""
    seen = []
    for folder in folders:
        path = _find([folder], [HEADMEASURES_NAME])
        if path is not None:
            seen.append(path)
            table = read_headmeasures(path)
            if subject in table:
                return table[subject], False
    where = ", ".join(map(str, seen)) if seen else "no Headmeasures.txt found"
    key = (subject, str(folders[0]))
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(
            f"{subject}: no head measures ({where}); using DEFAULT_HEAD_MEASURES",
            DefaultHeadMeasuresWarning,
            stacklevel=4,  # the caller of Dataset.load / load_recording
        )
    return DEFAULT_HEAD_MEASURES, True


def _assemble(path: Path, subject: str, task: str, own: Path | None, shared: list[Path]):
    """Load a recording; ``own`` is the subject's folder (bare PAL.DAT allowed) or None."""
    prefixed = lambda kind: [f"{subject.lower()}_{kind}.dat"]  # noqa: E731
    bare = lambda kind: [f"{kind}.dat"]  # noqa: E731
    own_l = [own] if own is not None else []

    def outline(kind: str, name: str):
        found = _find(own_l, prefixed(kind) + bare(kind)) or _find(shared, prefixed(kind))
        return None if found is None else read_outline(found, kind=name)

    track = read_txy(path)
    head, is_default = _head_measures(subject, own_l + shared)
    audio = _find([path.parent], [f"{path.stem.lower()}.wav"])
    return Recording(
        subject=subject,
        task=task,
        track=track,
        palate=outline("pal", "palate"),
        pharynx=outline("pha", "pharynx"),
        head=head,
        head_is_default=is_default,
        audio=audio,
        path=path,
    )


def load_recording(path: str | os.PathLike) -> Recording:
    """Load a single pellet file with the subject data found beside it or one folder up.

    The subject is taken from a flat name (``jw11_tp005.txy``) or else from the name of
    the file's folder (``JW11/TP005.TXY``).
    """
    path = Path(path)
    if path.exists() and not path.is_dir() and not path.is_file():
        raise DataFormatError(path, None, "not a regular file (a pipe, device or socket)")
    if not path.is_file():
        raise MissingDataError(f"{path}: no such pellet file")
    folder = path.parent.resolve()
    names = _listing(folder)
    subject, task = _split_stem(path.stem, folder.name, names, subject_folder=False)
    if subject is None or subject == folder.name.upper():
        subject = folder.name.upper()
        return _assemble(path, subject, task, own=folder, shared=[folder.parent])
    return _assemble(path, subject, task, own=None, shared=[folder, folder.parent])


class Dataset:
    """The recordings under ``root`` (either layout, case-insensitive).

    ``subjects()`` and ``tasks(subject)`` list canonical names (natural order);
    ``load(subject, task)`` returns a :class:`Recording`; ``pellet_path`` the file.
    Discovery reads only folder listings; files are read by ``load``.
    """

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)
        if not self.root.is_dir():
            raise MissingDataError(f"{self.root}: not a folder")
        # (SUBJECT, task) -> (pellet path, the subject's own folder or None)
        self._index: dict[tuple[str, str], tuple[Path, Path | None]] = {}
        self._scan_folder(self.root, subject_folder=False)
        for sub in sorted(p for p in self.root.iterdir() if p.is_dir()):
            if not sub.name.startswith("."):
                self._scan_folder(sub, subject_folder=True)

    def _scan_folder(self, folder: Path, subject_folder: bool) -> None:
        names = _listing(folder)
        for lower in sorted(names):
            if not lower.endswith(PELLET_SUFFIX) or lower.startswith("."):
                continue
            path = names[lower]
            subject, task = _split_stem(path.stem, folder.name, names, subject_folder)
            own = folder if subject is None or subject == folder.name.upper() else None
            subject = subject or folder.name.upper()
            key = (subject, task)
            if key in self._index:
                warnings.warn(
                    f"{path}: ignored, {subject} {task} is already {self._index[key][0]}",
                    stacklevel=3,
                )
                continue
            self._index[key] = (path, own)

    def subjects(self) -> list[str]:
        return sorted({s for s, _ in self._index}, key=_natural_key)

    def tasks(self, subject: str) -> list[str]:
        subject = self._subject(subject)
        return sorted((t for s, t in self._index if s == subject), key=_natural_key)

    def _subject(self, subject: str) -> str:
        key = str(subject).upper()
        if key not in self.subjects():
            known = ", ".join(self.subjects()) or "none"
            raise MissingDataError(f"{self.root}: no subject {subject!r} (subjects: {known})")
        return key

    def pellet_path(self, subject: str, task: str) -> Path:
        key = (self._subject(subject), str(task).lower())
        if key not in self._index:
            known = ", ".join(self.tasks(key[0]))
            raise MissingDataError(f"{self.root}: {key[0]} has no task {task!r} (tasks: {known})")
        return self._index[key][0]

    def load(self, subject: str, task: str) -> Recording:
        """Read one recording with its subject's palate, pharynx, head measures, audio."""
        path = self.pellet_path(subject, task)
        subject, task = self._subject(subject), str(task).lower()
        own = self._index[(subject, task)][1]
        # a root that is itself a subject folder: look one folder up, as load_recording does
        shared = [self.root, self.root.parent] if own == self.root else [self.root]
        return _assemble(path, subject, task, own=own, shared=shared)

    def __len__(self) -> int:
        return len(self._index)

    def __repr__(self) -> str:
        return (
            f"Dataset({str(self.root)!r}, subjects={len(self.subjects())}, recordings={len(self)})"
        )
