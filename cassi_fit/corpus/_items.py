"""Corpus items: one recording (or one subject) as a unit of work, found in a dataset."""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..status import Status

if TYPE_CHECKING:
    import numpy as np

    from ..dataset import Dataset, Recording

@dataclass(frozen=True, order=False)
class CorpusItem:
    """One unit of work: ``subject`` (upper case), ``task`` (lower case; ``""`` for
    per-subject work), ``path``: the pellet file (or, per subject, the dataset folder),
    ``root``: the dataset folder it came from (``""`` for a lone file), and
    ``sensor_map``: the dataset's articulograph sensor map as it was given
    (``dataset.Dataset``'s; None: a map beside the files, else the built-in names) and
    ``tier`` its label tier (None: the default), so a worker reads the recording as the
    dataset does."""

    subject: str
    task: str
    path: str
    root: str = ""
    sensor_map: Any = field(default=None, compare=False)
    tier: str | None = field(default=None, compare=False)

    def dataset(self) -> Dataset:
        """The item's ``dataset.Dataset`` (its folder, with its sensor map)."""
        from ..dataset import Dataset

        return Dataset(self.root, sensor_map=self.sensor_map, tier=self.tier)


def load_item(item: CorpusItem, *, quiet: bool = False) -> Recording:
    """The item's ``dataset.Recording`` (pellets with the subject's palate, pharynx, head
    measures and audio), found as ``Dataset(root).load`` does, or beside a lone file.
    ``quiet``: without the default-head-measures warning (a corpus table says which
    conformation each row used; a warning per worker would only repeat it)."""
    import warnings

    from ..dataset import DefaultHeadMeasuresWarning, load_recording

    with warnings.catch_warnings():
        if quiet:
            warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        if item.root:
            return item.dataset().load(item.subject, item.task)
        return load_recording(item.path, sensor_map=item.sensor_map, tier=item.tier)


@dataclass(frozen=True)
class TaskResult:
    """What a task function returns: its summary ``row`` (flat dict: str, int, float,
    bool, None) and the ``outputs`` it wrote (paths)."""

    row: dict
    outputs: tuple[str, ...] = ()


@dataclass(frozen=True)
class ItemResult:
    """One item's outcome: ``status`` OK or FAILED, ``error`` (one line, ``""`` if OK),
    the task's ``row`` (empty if failed), ``resumed`` if taken from a completion marker."""

    item: CorpusItem
    status: Status
    error: str = ""
    row: dict = field(default_factory=dict)
    resumed: bool = False


def _natural(text: str) -> list:
    return [int(s) if s.isdigit() else s for s in re.split(r"([0-9]+)", text)]


def _order(item: CorpusItem) -> tuple:
    return (_natural(item.subject), _natural(item.task))


def chosen_tasks(dataset: Dataset, subject: str, tasks: Iterable[str] | None = None
                 ) -> list[str]:
    """The tasks of ``subject`` in ``dataset`` (its order) that are among ``tasks`` (names
    in any case; None: all): the one rule every dataset run chooses tasks by."""
    wanted = None if tasks is None else {str(t).lower() for t in tasks}
    return [t for t in dataset.tasks(subject) if wanted is None or t.lower() in wanted]


def dataset_items(dataset: Dataset | str | os.PathLike, *, subjects: Iterable[str] | None = None,
                  tasks: Iterable[str] | None = None,
                  per_subject: bool = False) -> list[CorpusItem]:
    """The items of a ``dataset.Dataset`` (or its folder), in natural order: one per
    recording, or with ``per_subject`` one per subject (``task=""``, ``path`` = the
    dataset folder). ``subjects``/``tasks`` restrict the choice (names, any case)."""
    from ..dataset import Dataset

    # absolute paths: a Dask worker may run in another folder (or on another machine
    # that mounts the same file system)
    ds = dataset if isinstance(dataset, Dataset) else Dataset(os.path.abspath(dataset))
    names = ds.subjects() if subjects is None else [str(s).upper() for s in subjects]
    items, root = [], os.path.abspath(ds.root)
    for subject in names:
        chosen = chosen_tasks(ds, subject, tasks)
        if per_subject and chosen:
            items.append(CorpusItem(subject, "", root, root, ds.sensor_map, ds.tier))
        elif not per_subject:
            items += [CorpusItem(subject, t, os.path.abspath(ds.pellet_path(subject, t)), root,
                                 ds.sensor_map, ds.tier) for t in chosen]
    return items


def require_items(items: list[CorpusItem], dataset: object,
                  subjects: Iterable[str] | None = None, tasks: Iterable[str] | None = None
                  ) -> list[CorpusItem]:
    """``items`` if there are any and every subject and task asked for is there
    (``dataset.Dataset.check_selection``); else a ``MissingDataError`` naming the folder
    and what was looked for: no recordings at all (and the special files skipped), a
    subject or task that is not there, or none of the subjects and tasks asked for."""
    from ..dataset import Dataset
    from ..errors import MissingDataError

    ds = dataset if isinstance(dataset, Dataset) else Dataset(os.path.abspath(dataset))
    ds.check_selection(None if subjects is None else list(subjects),
                       None if tasks is None else list(tasks))
    if items:
        return items
    wanted = []
    if tasks is not None:
        wanted.append("the task(s) " + ", ".join(str(t) for t in tasks))
    if subjects is not None:
        wanted.append("the subject(s) " + ", ".join(str(s) for s in subjects))
    raise MissingDataError(f"{ds.root}: found none of {' for '.join(wanted)} (it has "
                           f"{', '.join(ds.subjects())})")


def item_rng(item: CorpusItem, seed: int = 0) -> np.random.Generator:
    """A numpy Generator that depends only on ``(seed, subject, task)``, for tasks that
    draw random numbers: the same on every worker and in every order."""
    import numpy as np

    digest = hashlib.sha256(f"{item.subject}\0{item.task}".encode()).digest()
    return np.random.default_rng([int(seed), *(int.from_bytes(digest[i:i + 4], "little")
                                               for i in range(0, 16, 4))])
