"""What a folder holds that the synthetic corpus writers did not write
(:func:`foreign_data`), so that a generator never writes into a real dataset
(:func:`refuse_foreign_data`, called by ``synth.generate_corpus`` and
``ema.synthetic`` before they write anything), and how a finished corpus moves into its
folder (:func:`move_into_place`, both writers). Reads only small sidecars, never a
special file.
"""

from __future__ import annotations

import os
from pathlib import Path

from .._io import data_kind, special_kind
from ..errors import OutputExistsError

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
    """The subjects a ``Headmeasures.txt`` lists (upper case; ``headmeasures``' one
    parser, not registered as an input), None if unreadable."""
    from ..errors import CassiError
    from ..headmeasures import parse_headmeasures

    text = _small_text(path)
    if text is None:
        return None
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip()]
    try:
        return set(parse_headmeasures(path, lines, check=False))
    except CassiError:
        return None


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


def move_into_place(tmp: Path, out_dir: Path) -> None:
    """Rename the finished ``tmp`` to ``out_dir`` (one atomic rename if ``out_dir`` is
    absent or empty); else move file by file into it, its old README.txt removed first and
    the new one moved last, so an interruption leaves a corpus marked incomplete."""
    if out_dir.is_dir() and not any(out_dir.iterdir()):
        out_dir.rmdir()
    if not out_dir.exists():
        os.replace(tmp, out_dir)
        return
    (out_dir / "README.txt").unlink(missing_ok=True)
    for path in sorted(p for p in tmp.rglob("*") if p.is_file() and p.name != "README.txt"):
        target = out_dir / path.relative_to(tmp)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(path, target)
    os.replace(tmp / "README.txt", out_dir / "README.txt")
