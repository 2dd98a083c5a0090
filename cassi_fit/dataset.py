"""Finding recordings on disk (XRMB and articulographs) and loading each with its subject's data.

Two layouts are understood, case-insensitively (see ``docs/FORMATS.md``):

- folder per subject (the distribution): ``ROOT/JW11/TP005.TXY`` (or ``tp005.txy``,
  repeated trials ``tp020_2.txy``), ``ROOT/JW11/PAL.DAT``, ``ROOT/JW11/PHA.DAT``, audio
  ``ROOT/JW11/TP005.WAV``; ``Headmeasures.txt`` in the subject folder or at the root.
- flat: ``ROOT/jw11_tp005.txy``, ``ROOT/jw11_pal.dat``, ``ROOT/jw11_pha.dat``,
  ``ROOT/jw11_tp005.wav``, ``ROOT/Headmeasures.txt``.

A root that is itself one subject's folder (it holds a bare ``PAL.DAT``) also works.
Subject names are upper case (``JW11``, ``S01``), task names lower case (``tp005``).

Articulograph (EMA) recordings are found beside them (docs/EMA.md): files ending
``.ema`` (EST Track), ``.pos`` (Carstens), ``.tsv`` (NDI Wave) and ``.mat`` (mview), in a
subject's folder (``S01/tp005.pos``) or flat with the speaker first (MOCHA-TIMIT's
``fsew0_001.ema``, mngu0's ``mngu0_s1_0001.ema``; a suffix of one or two digits is a
repeated trial, as in ``tp020_2``). A file whose name holds ``bite`` is the folder's
bite-plane recording, not a task. The sensor map is the first of ``<stem>.sensors.toml``,
``sensors.toml`` in the file's folder or the one above, else the built-in names; a map
given to :func:`load_recording` or :class:`Dataset` wins. Other names (an EST file called
``.txt``, arrays) are read by :func:`load_recording` alone, which detects the format by
content. :func:`recording_from_array` makes a recording from a numpy array.

An emuDB (:mod:`cassi_fit.ema.emu`: a folder with ``<name>_DBconfig.json``, the root or
one in it) gives a recording per bundle ``<session>_ses/<bundle>_bndl/`` (session =
subject, bundle = task); ``<bundle>_bndl.json`` files are found like other recordings.
Sound and labels inside a file: :attr:`Recording.sound`, :attr:`Recording.labels`.

Special files (named pipes, devices, sockets, broken links) are never opened: discovery
skips them with a :class:`SpecialFileWarning` naming them (opening a FIFO for reading
blocks until a writer comes), and loading one is a :class:`DataFormatError`. A folder in
which nothing is found is not an error for :class:`Dataset` (``len(dataset) == 0``);
:meth:`Dataset.check_selection` turns it, and subjects or tasks asked for that are not
there, into one :class:`MissingDataError` naming the folder and what was looked for.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import Float

from ._io import special_kind
from .errors import DataFormatError, MissingDataError
from .headmeasures import DEFAULT_HEAD_MEASURES, HeadMeasures, read_headmeasures
from .outlines import outlines_problem, read_outline
from .txy import PelletTrack, read_txy

# The articulograph side (cassi_fit.ema: every format's reader, sensor maps, head
# correction) and the sound are imported where they are used: a pellet file needs none.
if TYPE_CHECKING:
    from .ema import RawEma, SensorMap, SensorReport
    from .sound import Sound

PELLET_SUFFIX = ".txy"
#: Articulograph files a :class:`Dataset` discovers (by suffix; read by content).
EMA_SUFFIXES = (".ema", ".pos", ".tsv", ".mat")
SENSOR_MAP_NAME = "sensors.toml"
HEADMEASURES_NAME = "headmeasures.txt"
_TRIAL = re.compile(r"[0-9]+")
_SHORT_TRIAL = re.compile(r"[0-9]{1,2}")
_BITE = re.compile(r"bite|occlusal", re.IGNORECASE)
#: What discovery looks for, in messages.
LOOKED_FOR = ("pellet files (.txy) or articulograph recordings (.ema, .pos, .tsv, .mat, "
              "EMU bundles), in the folder or its subject folders")
_MAX_NAMES = 12  # names listed in a message before "..."

#: What a sensor map can be given as (:func:`cassi_fit.ema.sensor_map.sensor_map`).
SensorMapLike = "SensorMap | str | os.PathLike | None"


class DefaultHeadMeasuresWarning(UserWarning):
    """A recording uses ``DEFAULT_HEAD_MEASURES`` because its subject has no measures."""


class CompanionFileWarning(UserWarning):
    """A file beside an articulograph recording (a palate trace in another format) could
    not be read and is not used; the recording is."""


class SpecialFileWarning(UserWarning):
    """Discovery skipped special files (pipes, devices, sockets, broken links) in a
    dataset's folder: they are never opened, so they are never a recording, an outline or
    a ``Headmeasures.txt``."""


@dataclass(frozen=True, eq=False)
class Recording:
    """One subject performing one task, with everything the subject's folder holds.

    ``palate`` and ``pharynx`` are ``(n, 2)`` mm arrays or None when the file is absent;
    ``head`` falls back to ``DEFAULT_HEAD_MEASURES`` (``head_is_default`` True, with a
    :class:`DefaultHeadMeasuresWarning` once per subject); ``audio`` is the ``.wav`` with
    the pellet file's stem, or None. ``sensors`` is None for XRMB files; for an
    articulograph recording it says how its track was made (format, rate, units, the
    roles of its sensors, the head correction and its per-frame residual, the occlusal
    frame, each sensor's distance from the midsagittal plane:
    :class:`~cassi_fit.ema.report.SensorReport`). The pipeline needs nothing else: the
    track is in the toolkit's frame, mm, at the file's own rate (``track.frame_step_s``).
    ``file_sound``: the sound stored inside the recording file (mview ``AUDIO``, an EMU
    bundle's media), or None; ``labels``: the label tiers stored inside it (mview
    ``WORDS``/``PHONES``/``LABELS``, EMU levels), ``()`` if none; ``label_tier``: the tier
    its labels come from (a TextGrid's beside it, or one inside it), None for the default
    (``labels.tier_name``: phones, then words, then the first).
    """

    subject: str
    task: str
    track: PelletTrack
    palate: np.ndarray | None
    pharynx: np.ndarray | None
    head: HeadMeasures
    head_is_default: bool
    audio: Path | None
    path: Path | None
    sensors: SensorReport | None = None
    file_sound: Sound | None = None
    labels: tuple = ()
    label_tier: str | None = None

    @property
    def sound(self) -> Sound | None:
        """The recording's sound: the ``.wav`` beside its file (``audio``), else the sound
        stored inside the file (``file_sound``), else None."""
        if self.audio is not None:
            from .sound import Sound

            return Sound.from_file(self.audio)
        return self.file_sound

    @property
    def source(self) -> str:
        """The recording's name in messages: its pellet file, else ``SUBJECT/TASK``."""
        path = self.path or self.track.path
        return str(path) if path is not None else f"{self.subject}/{self.task}"

    @property
    def format(self) -> str:
        """``"xrmb"``, or the articulograph file's format (``est``, ``ag501``...)."""
        return "xrmb" if self.sensors is None else self.sensors.format


def _names(names: Sequence[str]) -> str:
    """``a, b, c`` (at most ``_MAX_NAMES``, then ``...``), or ``none``."""
    names = list(names)
    if not names:
        return "none"
    more = f", ... ({len(names)} in all)" if len(names) > _MAX_NAMES else ""
    return ", ".join(names[:_MAX_NAMES]) + more


def _special_files(folder: Path) -> list[tuple[Path, str]]:
    """``(path, what it is)`` of the special files in ``folder`` (``os.stat`` only)."""
    try:
        entries = sorted(folder.iterdir())
    except OSError:
        return []
    found = [(p, special_kind(p)) for p in entries]
    return [(p, kind) for p, kind in found if kind is not None]


_WARNED_SPECIAL: set[tuple[str, tuple[str, ...]]] = set()


def _warn_special(folder: Path, stacklevel: int) -> list[tuple[Path, str]]:
    """The special files in ``folder``, with one :class:`SpecialFileWarning` naming them
    (once per process for the same folder and files: a dataset is scanned by every
    command stage that opens it)."""
    found = _special_files(folder)
    key = (os.path.realpath(folder), tuple(p.name for p, _ in found))
    if found and key not in _WARNED_SPECIAL:
        _WARNED_SPECIAL.add(key)
        what = _names([f"{p.name} ({kind})" for p, kind in found])
        warnings.warn(f"{folder}: skipped {len(found)} special file(s), never opened: {what}",
                      SpecialFileWarning, stacklevel=stacklevel + 1)
    return found


def _regular(path: Path) -> None:
    """A :class:`DataFormatError` naming ``path`` unless it is a regular file (or a link to
    one); :class:`MissingDataError` if it does not exist. Never opens it."""
    kind = special_kind(path)
    if kind is not None:
        raise DataFormatError(path, None, f"not a regular file but {kind}; not read")
    if path.is_dir():
        raise DataFormatError(path, None, "is a folder, not a recording file")
    if not path.is_file():
        raise MissingDataError(f"{path}: no such recording file")


def _not_a_folder(path: Path) -> str:
    """Why ``path`` is no dataset folder, for a message."""
    kind = special_kind(path)
    if kind is not None:
        return f"is {kind}, not a dataset folder"
    if path.is_file():
        return ("is a file, not a dataset folder (give the folder that holds it, or load "
                "one recording with load_recording)")
    return "no such dataset folder"


def _listing(folder: Path) -> dict[str, Path]:
    """Lower-case file name -> path for the regular files in ``folder`` (special files
    are left out: :func:`_warn_special` says which).

    Names are matched case-insensitively, so two files whose names differ only in case
    (``TP101.TXY`` and ``tp101.txy``) would be one recording twice: a
    :class:`DataFormatError` naming both, never a silent pick.
    """
    try:
        files = sorted(p for p in folder.iterdir() if p.is_file())  # stat only, never open
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


def _emu():
    """:mod:`cassi_fit.ema.emu` (imported on first use)."""
    from .ema import emu

    return emu


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


def _assemble(path: Path, subject: str, task: str, own: Path | None, shared: list[Path],
              ema: dict | None = None):
    """Load a recording; ``own`` is the subject's folder (bare PAL.DAT allowed) or None;
    ``ema``: None for an XRMB file, else the articulograph options (format, sensor map,
    layout, rate, bite plane)."""
    prefixed = lambda kind: [f"{subject.lower()}_{kind}.dat"]  # noqa: E731
    bare = lambda kind: [f"{kind}.dat"]  # noqa: E731
    own_l = [own] if own is not None else []

    def outline(kind: str, name: str):
        found = _find(own_l, prefixed(kind) + bare(kind)) or _find(shared, prefixed(kind))
        if found is None:
            return None
        try:
            return read_outline(found, kind=name)
        except DataFormatError as exc:
            if ema is None:  # an XRMB subject's own PAL.DAT/PHA.DAT: its errors stand
                raise
            # beside an articulograph file (MOCHA-TIMIT's fsew0_pal.dat, decimal numbers in
            # its own units): a companion never refuses the recording
            warnings.warn(f"{exc}; not an XRMB {name} trace (whole micrometres): not used",
                          CompanionFileWarning, stacklevel=4)
            return None

    inside: dict = {}
    if ema is None:
        track, report = read_txy(path), None
    else:
        track, report, raw = _ema_track(path, **ema)
        inside = {"file_sound": raw.sound, "labels": raw.labels}
    head, is_default = _head_measures(subject, own_l + shared)
    audio = None if path.is_dir() else _find([path.parent], [f"{path.stem.lower()}.wav"])
    palate, pharynx = outline("pal", "palate"), outline("pha", "pharynx")
    if palate is not None and pharynx is not None:
        problem = outlines_problem(palate, pharynx)
        if problem is not None:
            pha = _find(own_l, prefixed("pha") + bare("pha")) or _find(shared, prefixed("pha"))
            raise DataFormatError(pha, None, problem)
    return Recording(
        subject=subject,
        task=task,
        track=track,
        palate=palate,
        pharynx=pharynx,
        head=head,
        head_is_default=is_default,
        audio=audio,
        path=path,
        sensors=report,
        **inside,
    )


def _is_bite(path: Path) -> bool:
    return bool(_BITE.search(path.stem))


def _sensor_map_for(path: Path, given: SensorMapLike) -> SensorMap:
    """The map given, else ``<stem>.sensors.toml``, ``sensors.toml`` beside or one folder
    up, else the built-in names."""
    from .ema.sensor_map import PROPOSED
    from .ema.sensor_map import sensor_map as _sensor_map

    if given is not None and str(given) != PROPOSED:
        return _sensor_map(given)
    found = (_find([path.parent], [f"{path.stem.lower()}.{SENSOR_MAP_NAME}", SENSOR_MAP_NAME])
             or _find([path.parent.parent], [SENSOR_MAP_NAME]))
    return _sensor_map(found if found is not None else given)  # a map beside wins over proposed


def _bite_for(path: Path, given: str | os.PathLike | None) -> Path | None:
    """The bite-plane recording given, else the one file of the same suffix named
    ``*bite*`` in the recording's folder (two are an error naming them)."""
    if given is not None:
        return Path(given)
    if _is_bite(path):
        return None
    found = sorted(p for p in _listing(path.parent).values()
                   if _is_bite(p) and p.suffix.lower() == path.suffix.lower())
    if _emu().is_bundle_folder(path):  # a bite-plane bundle of the session
        found = sorted(p for p in path.parent.iterdir() if _emu().is_bundle_folder(p)
                       and _is_bite(p))
    if len(found) > 1:
        raise DataFormatError(path.parent, None, f"{len(found)} bite-plane recordings "
                              f"({', '.join(p.name for p in found)}): give one (bite_plane=)")
    return found[0] if found else None


def _ema_track(path: Path, *, fmt: str | None = None, sensor_map: SensorMapLike = None,
               layout=None, rate: float | None = None, bite_plane=None, session=None
               ) -> tuple[PelletTrack, SensorReport, RawEma]:
    from .ema import ema_to_track, read_ema

    raw = read_ema(path, format=fmt, layout=layout, rate=rate)
    smap = _sensor_map_for(path, sensor_map)
    if smap.name == "auto" and sensor_map is None:
        smap = _emu().sensor_map_for(raw) or smap  # the IPS Munich set has a built-in map
    bite_path = _bite_for(path, bite_plane)
    if bite_path is None:
        placed = None
        if session is not None:  # a Dataset: the subject's session (its map, its frame)
            smap, placed = session(smap)
        return (*ema_to_track(raw, smap, placement=placed), raw)
    bite = read_ema(bite_path, rate=rate)
    return (*ema_to_track(raw, smap, bite=bite,
                          bite_map=_sensor_map_for(bite_path, sensor_map)), raw)


def _split_ema_stem(stem: str, folder_name: str, subject_folder: bool):
    """``(subject, task)`` of an articulograph file stem; subject None = the folder's.
    ``fsew0_001`` is speaker FSEW0's utterance 001; ``tp020_2`` (one or two digits after
    the ``_``) is a repeated trial in a subject's folder."""
    stem = stem.lower()
    prefix, sep, rest = stem.partition("_")
    if sep and rest and prefix == folder_name.lower():
        return prefix.upper(), rest
    if subject_folder or not (sep and rest) or _SHORT_TRIAL.fullmatch(rest):
        return None, stem
    if re.search("[a-z]", prefix):
        return prefix.upper(), rest
    return None, stem


def load_recording(path: str | os.PathLike, *, sensor_map: SensorMapLike = None,
                   layout: str | Sequence[str] | None = None, rate: float | None = None,
                   bite_plane: str | os.PathLike | None = None,
                   tier: str | None = None) -> Recording:
    """Load a single recording with the subject data found beside it or one folder up.

    The format is detected by content (:func:`cassi_fit.ema.detect.detect_format`): an
    XRMB pellet file, or an articulograph file (EST Track, Carstens ``.pos``, NDI Wave,
    mview ``.mat``, a ``.npy``/``.npz``/CSV array). The subject is taken from a flat name
    (``jw11_tp005.txy``, ``fsew0_001.ema``) or else from the name of the file's folder
    (``JW11/TP005.TXY``). For articulograph files: ``sensor_map`` (a
    :class:`~cassi_fit.ema.sensor_map.SensorMap`, a built-in name or a ``.toml`` file;
    default the one beside the file, else the built-in names), ``layout`` and ``rate``
    (arrays; ``rate`` also for a headerless ``.pos``), ``bite_plane`` (a bite-plane
    recording; default a ``*bite*`` file beside). ``tier``: the label tier to use
    (``Recording.label_tier``; default phones, then words).

    ``path`` must be a regular file (or a link to one): a pipe, device or socket is a
    :class:`DataFormatError` and is never opened; special files beside it are skipped
    with a :class:`SpecialFileWarning`.
    """
    path = Path(path)
    pellet_file = path.suffix.lower() == PELLET_SUFFIX  # (never an EMU ``*_bndl`` folder)
    if pellet_file or not _emu().is_bundle_folder(path):
        _regular(path)
    if pellet_file:
        fmt = "xrmb"
    else:
        from .ema.detect import detect_format

        fmt = detect_format(path)
    folder = path.parent.resolve()
    _warn_special(folder, stacklevel=2)  # the subject's files are looked for here
    names = _listing(folder)
    if fmt == "xrmb":
        ema = None
        subject, task = _split_stem(path.stem, folder.name, names, subject_folder=False)
    else:
        ema = {"fmt": fmt, "sensor_map": sensor_map, "layout": layout, "rate": rate,
               "bite_plane": bite_plane}
        subject, task = _split_ema_stem(path.stem, folder.name, subject_folder=False)
        if fmt == "emu":
            subject, task = _emu().recording_names(path, folder)
            if _emu().session_of(path) is not None:  # a database: the session folder
                return _with_tier(_assemble(path, subject, task, own=folder,
                                            shared=[folder.parent], ema=ema), tier)
    if subject is None or subject == folder.name.upper():
        subject = folder.name.upper()
        return _with_tier(_assemble(path, subject, task, own=folder, shared=[folder.parent],
                                    ema=ema), tier)
    return _with_tier(_assemble(path, subject, task, own=None, shared=[folder, folder.parent],
                                ema=ema), tier)


def _with_tier(recording: Recording, tier: str | None) -> Recording:
    """The recording with its label tier chosen (``Recording.label_tier``), or as it is.
    (Called on ``_assemble``'s result: its warnings keep their stack levels.)"""
    return recording if tier is None else replace(recording, label_tier=tier)


def recording_from_array(
    ema: Float[np.ndarray, "n c"],
    layout: str | Sequence[str] = "sparc",
    rate: float = 50.0,
    audio: str | os.PathLike | None = None,
    *,
    units: str | None = None,
    mean_mm: Float[np.ndarray, " c"] | None = None,
    sd_mm: Float[np.ndarray, " c"] | None = None,
    sensor_map: SensorMapLike = None,
    subject: str = "ARRAY",
    task: str = "array",
) -> Recording:
    """A :class:`Recording` from a ``(frames, columns)`` array, e.g. an inversion model's
    output, so that a notebook can animate it.

    ``layout``: a built-in name (``"sparc"``: SPARC's 12 columns ``TDX TDY ... LLX LLY``
    at 50 Hz; ``"mngu0"``) or the column names (``["UL_x", "UL_y", ...]``); ``rate`` Hz;
    ``audio``: a ``.wav`` to play with it. Units: millimetres (``units``: ``"mm"``,
    ``"cm"``, ``"m"``); SPARC's output is normalised, not millimetres (docs/EMA.md): give
    ``mean_mm`` and ``sd_mm`` (per column, mm) or ``units="mm"`` if the values are mm.
    The array's x and y are the midsagittal plane's; which way is forward and up comes
    from the anatomy (the report says so). Head measures, palate and pharynx are the
    defaults (``head_is_default``).
    """
    from .ema import ema_to_track
    from .ema.arrays import raw_from_array
    from .ema.sensor_map import sensor_map as _sensor_map

    raw: RawEma = raw_from_array(ema, layout=layout, rate=rate, units=units,
                                 mean_mm=mean_mm, sd_mm=sd_mm)
    track, report = ema_to_track(raw, _sensor_map(sensor_map))
    audio_path = None if audio is None else Path(audio)
    if audio_path is not None and not audio_path.is_file():
        raise MissingDataError(f"{audio_path}: no such audio file")
    return Recording(subject=subject, task=task, track=track, palate=None, pharynx=None,
                     head=DEFAULT_HEAD_MEASURES, head_is_default=True, audio=audio_path,
                     path=None, sensors=report)


class Dataset:
    """The recordings under ``root`` (either layout, case-insensitive; XRMB and
    articulograph files, see the module docstring; ``sensor_map`` for every
    articulograph file, else each file's own; ``tier`` the label tier of every recording,
    ``Recording.label_tier``).

    ``subjects()`` and ``tasks(subject)`` list canonical names (natural order);
    ``load(subject, task)`` returns a :class:`Recording`; ``pellet_path`` the file.
    Discovery reads only folder listings (``os.stat``, never ``open``); files are read by
    ``load``. Special files are skipped with a :class:`SpecialFileWarning` and listed in
    ``skipped`` (``(path, what it is)``). A ``root`` that is not a folder (a file, a pipe,
    nothing) is a :class:`MissingDataError` naming it; a folder with no recordings gives
    an empty dataset, which :meth:`check_selection` refuses.
    """

    def __init__(self, root: str | os.PathLike, *, sensor_map: SensorMapLike = None,
                 tier: str | None = None):
        self.root = Path(root)
        if not self.root.is_dir():
            raise MissingDataError(f"{self.root}: {_not_a_folder(self.root)}")
        try:
            entries = sorted(self.root.iterdir())
        except OSError as exc:
            raise MissingDataError(f"{self.root}: cannot list the dataset folder "
                                   f"({exc.strerror or exc})") from None
        self.sensor_map = sensor_map
        self.tier = tier
        # (SUBJECT, task) -> (pellet path, the subject's own folder or None)
        self._index: dict[tuple[str, str], tuple[Path, Path | None]] = {}
        self.skipped: list[tuple[Path, str]] = []
        self._scan_folder(self.root, subject_folder=False)
        self._scan_emu(self.root)
        for sub in (p for p in entries if p.is_dir()):
            if not sub.name.startswith(".") and not sub.name.endswith(_emu().SESSION_SUFFIX):
                self._scan_folder(sub, subject_folder=True)
                self._scan_emu(sub)

    def _scan_emu(self, folder: Path) -> None:
        """The bundles of an emuDB at ``folder`` (one holding a ``*_DBconfig.json``)."""
        if _emu().find_dbconfig(folder) is None:
            return
        for session, bundle, path in _emu().database_bundles(folder):
            if not _is_bite(path):
                self._add((session.upper(), bundle.lower()), path, path.parent)

    def _scan_folder(self, folder: Path, subject_folder: bool) -> None:
        # stacklevel: warn -> _warn_special -> _scan_folder -> __init__ -> the caller
        self.skipped += _warn_special(folder, stacklevel=3)
        names = _listing(folder)
        for lower in sorted(names):
            if lower.startswith("."):
                continue
            path = names[lower]
            if lower.endswith(PELLET_SUFFIX):
                subject, task = _split_stem(path.stem, folder.name, names, subject_folder)
            elif lower.endswith(_emu().BUNDLE_SUFFIX + ".json"):
                subject, task = _emu().recording_names(path, folder)
            elif path.suffix.lower() in EMA_SUFFIXES and not _is_bite(path):
                subject, task = _split_ema_stem(path.stem, folder.name, subject_folder)
            else:
                continue
            own = folder if subject is None or subject == folder.name.upper() else None
            subject = subject or folder.name.upper()
            self._add((subject, task), path, own)

    def _add(self, key: tuple[str, str], path: Path, own: Path | None) -> None:
        if key in self._index:
            warnings.warn(f"{path}: ignored, {key[0]} {key[1]} is already "
                          f"{self._index[key][0]}", stacklevel=4)
            return
        self._index[key] = (path, own)

    def subjects(self) -> list[str]:
        return sorted({s for s, _ in self._index}, key=_natural_key)

    def tasks(self, subject: str) -> list[str]:
        subject = self._subject(subject)
        return sorted((t for s, t in self._index if s == subject), key=_natural_key)

    def _subject(self, subject: str) -> str:
        key = str(subject).upper()
        if key not in self.subjects():
            raise MissingDataError(f"{self.root}: no subject {subject!r} (subjects: "
                                   f"{_names(self.subjects())}){self._nothing_found()}")
        return key

    def _nothing_found(self) -> str:
        """`` ; found no ...`` for messages about an empty dataset, else ``""``."""
        return "" if self._index else f"; found no recordings: looked for {LOOKED_FOR}"

    def _skipped_note(self) -> str:
        """``; skipped 1 special file(s): S01/TP040.TXY (a named pipe (FIFO))`` or ``""``."""
        if not self.skipped:
            return ""
        names = [f"{p.relative_to(self.root)} ({kind})" for p, kind in self.skipped]
        return f"; skipped {len(names)} special file(s), never opened: {_names(names)}"

    def _skipped_as(self, subject: str, task: str) -> str:
        """``; S01/TP999.TXY is a named pipe ...`` if a skipped special file would have
        been ``subject``'s ``task``, else ``""``."""
        for path, kind in self.skipped:
            stem = path.name.split(".")[0].lower()
            if stem in (task, f"{subject.lower()}_{task}"):
                return f"; {path} is {kind}, skipped"
        return ""

    def pellet_path(self, subject: str, task: str) -> Path:
        """The recording file of ``subject``'s ``task`` (names in any case); a
        :class:`MissingDataError` naming the folder, the subject or task not found and
        those there are."""
        key = (self._subject(subject), str(task).lower())
        if key not in self._index:
            raise MissingDataError(
                f"{self.root}: {key[0]} has no task {task!r} (tasks: "
                f"{_names(self.tasks(key[0]))}){self._skipped_as(key[0], key[1])}")
        return self._index[key][0]

    def check_selection(self, subjects: Sequence[str] | None = None,
                        tasks: Sequence[str] | None = None) -> None:
        """Refuse a choice that finds nothing, before any work: one
        :class:`MissingDataError` naming the folder and what was looked for, if the
        dataset holds no recordings, if a subject asked for is not there, or if a task
        asked for is held by none of the chosen subjects (all subjects when ``subjects``
        is None). Names in any case; None means all."""
        if not self._index:
            raise MissingDataError(f"{self.root}: found no recordings: looked for "
                                   f"{LOOKED_FOR}{self._skipped_note()}")
        chosen = self.subjects() if subjects is None else [self._subject(s) for s in subjects]
        if not chosen:
            raise MissingDataError(f"{self.root}: no subject chosen (an empty list); "
                                   f"subjects: {_names(self.subjects())}")
        if tasks is None:
            return
        held = {t for s in chosen for t in self.tasks(s)}
        wanted = [str(t) for t in tasks]
        missing = [t for t in wanted if t.lower() not in held]
        if not wanted or missing:
            whose = "any subject" if subjects is None else f"subject(s) {_names(chosen)}"
            what = f"no task {_names(missing)}" if missing else "no task chosen (an empty list)"
            raise MissingDataError(
                f"{self.root}: {what} for {whose} (tasks: "
                f"{_names(sorted(held, key=_natural_key))})"
                f"{''.join(self._skipped_as(s, t.lower()) for s in chosen for t in missing)}")

    def load(self, subject: str, task: str) -> Recording:
        """Read one recording with its subject's palate, pharynx, head measures, audio.
        The file must still be a regular file (never opened otherwise); its format is
        detected by content, as :func:`load_recording` does (a pellet file named ``.ema``
        is read as the pellet file it is)."""
        path = self.pellet_path(subject, task)
        if not _emu().is_bundle_folder(path):
            _regular(path)
        subject, task = self._subject(subject), str(task).lower()
        own = self._index[(subject, task)][1]
        # a root that is itself a subject folder: look one folder up, as load_recording does
        shared = [self.root, self.root.parent] if own == self.root else [self.root]
        if _emu().is_bundle_folder(path):
            shared = [path.parent.parent, self.root]
        from .ema.detect import detect_format

        xrmb = path.suffix.lower() == PELLET_SUFFIX or detect_format(path) == "xrmb"
        ema = None if xrmb else {"sensor_map": self.sensor_map,
                                 "session": partial(self._session_frame, subject)}
        return _with_tier(_assemble(path, subject, task, own=own, shared=shared, ema=ema),
                          self.tier)

    def _session_frame(self, subject: str, smap: SensorMap):
        """``(map, frame)`` shared by ``subject``'s articulograph files, found once from
        all of them (:func:`cassi_fit.ema.track.session_of`)."""
        from .ema.track import session_of

        cache = self.__dict__.setdefault("_sessions", {})
        if subject not in cache:
            cache[subject] = session_of(
                [p for (s, _), (p, _) in sorted(self._index.items())
                 if s == subject and p.suffix.lower() != PELLET_SUFFIX and not _is_bite(p)], smap)
        return cache[subject]

    def __len__(self) -> int:
        return len(self._index)

    def __repr__(self) -> str:
        return (
            f"Dataset({str(self.root)!r}, subjects={len(self.subjects())}, recordings={len(self)})"
        )
