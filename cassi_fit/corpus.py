"""Whole corpora: one runner for every per-recording command, on any Executor.

A corpus run applies one **task function** to many :class:`CorpusItem` s (a recording, or a
subject for per-subject work such as calibration) and collects one summary row per item.

* **Where it runs.** Items are independent tasks submitted to a
  :class:`concurrent.futures.Executor`: ``jobs=N`` starts a local process pool ('spawn'
  start method: JAX is not fork-safe), ``scheduler=ADDRESS`` sends the same tasks to a
  running ``dask.distributed`` cluster (through ``Client.get_executor()``), ``executor=``
  takes any Executor (or a Dask ``Client``), and ``jobs=1`` runs in this process with no
  pool. Workers live for the whole run, so what JAX compiles (cached by ``jax.jit`` /
  ``eqx.filter_jit`` in the worker process) and the face model (:func:`worker_model`) are
  paid once per worker, not once per recording; ``compilation_cache=DIR`` lets workers
  and later runs load compiled code from JAX's persistent cache instead.
* **Task functions** are module-level (picklable) functions
  ``task(item, out_dir, *, overwrite, **options) -> TaskResult`` taking plain arguments:
  they read the item's files, write their outputs under ``out_dir`` atomically, and return
  the summary row (a flat dict of numbers and strings) and the outputs' paths.
* **Failure isolation.** An item whose task raises becomes a row with status ``FAILED``
  and its one-line error; the run goes on. An item that kills its worker process (a
  crash, the OOM killer) is found by rerunning the items that were in flight one by one,
  and is FAILED alone (on a Dask cluster the nanny restarts workers and Dask reports the
  item as lost). ``CorpusRun.failed`` lists the failures, ``failure_summary()`` describes
  them; callers exit non-zero.
* **Resumable.** After an item's outputs are written, a completion marker
  ``out_dir/.cassi-corpus/SUBJECT/TASK.json`` is written last, atomically; it holds the
  row, a fingerprint of the task and its options, and each output's size and SHA-256.
  ``resume=True`` skips items whose marker matches and whose outputs are all present and
  unchanged, and takes their rows from the markers. Failed items get no marker.
* **Deterministic.** Results are sorted by (subject, task) in natural order; floats are
  written with fixed precision; workers compute with the calling process's float64
  setting; :func:`item_rng` seeds per item. Tables are byte-identical whatever the number
  of workers, the scheduler or the completion order.

``cassi jaw DATASET``'s task lives beside its command, in :mod:`cassi_fit.jaw_table`;
:func:`write_table` writes a corpus table as CSV, and as Parquet when pyarrow is importable
(``cassi_fit.tables``).
"""

# jaxtyping's shape strings (" n") are not Python expressions:
from __future__ import annotations

import concurrent.futures as cf
import hashlib
import json
import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._io import atomic_write
from .errors import CassiError, OutputExistsError
from .status import Status
from .tables import FLOAT_DIGITS, ID_COLUMNS, csv_text, parquet_available, table_columns  # noqa: F401
from .tables import write_table as _write_table

if TYPE_CHECKING:
    import numpy as np

    from .dataset import Dataset, Recording
    from .evaluate import EvaluationResult
    from .face_model import FaceModel

MARKER_DIR = ".cassi-corpus"


# ------------------------------------------------------------------------ items
@dataclass(frozen=True, order=False)
class CorpusItem:
    """One unit of work: ``subject`` (upper case), ``task`` (lower case; ``""`` for
    per-subject work), ``path``: the pellet file (or, per subject, the dataset folder),
    and ``root``: the dataset folder it came from (``""`` for a lone file)."""

    subject: str
    task: str
    path: str
    root: str = ""


def load_item(item: CorpusItem) -> Recording:
    """The item's ``dataset.Recording`` (pellets with the subject's palate, pharynx, head
    measures and audio), found as ``Dataset(root).load`` does, or beside a lone file."""
    from .dataset import Dataset, load_recording

    if item.root:
        return Dataset(item.root).load(item.subject, item.task)
    return load_recording(item.path)


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


def dataset_items(dataset: Dataset | str | os.PathLike, *, subjects: Iterable[str] | None = None,
                  tasks: Iterable[str] | None = None,
                  per_subject: bool = False) -> list[CorpusItem]:
    """The items of a ``dataset.Dataset`` (or its folder), in natural order: one per
    recording, or with ``per_subject`` one per subject (``task=""``, ``path`` = the
    dataset folder). ``subjects``/``tasks`` restrict the choice (names, any case)."""
    from .dataset import Dataset

    # absolute paths: a Dask worker may run in another folder (or on another machine
    # that mounts the same file system)
    ds = dataset if isinstance(dataset, Dataset) else Dataset(os.path.abspath(dataset))
    names = ds.subjects() if subjects is None else [str(s).upper() for s in subjects]
    wanted = None if tasks is None else {str(t).lower() for t in tasks}
    items, root = [], os.path.abspath(ds.root)
    for subject in names:
        chosen = [t for t in ds.tasks(subject) if wanted is None or t in wanted]
        if per_subject and chosen:
            items.append(CorpusItem(subject, "", root, root))
        elif not per_subject:
            items += [CorpusItem(subject, t, os.path.abspath(ds.pellet_path(subject, t)), root)
                      for t in chosen]
    return items


def item_rng(item: CorpusItem, seed: int = 0) -> np.random.Generator:
    """A numpy Generator that depends only on ``(seed, subject, task)``, for tasks that
    draw random numbers: the same on every worker and in every order."""
    import numpy as np

    digest = hashlib.sha256(f"{item.subject}\0{item.task}".encode()).digest()
    return np.random.default_rng([int(seed), *(int.from_bytes(digest[i:i + 4], "little")
                                               for i in range(0, 16, 4))])


# --------------------------------------------------------- markers and resuming
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


# ------------------------------------------------------------ running one item
def _one_line(exc: BaseException) -> str:
    """The error as one line: the message of a CassiError, else ``Type: message``."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    if not isinstance(exc, CassiError):
        text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= 300 else text[:297] + "..."


@dataclass(frozen=True)
class JaxSettings:
    """What every worker sets before a task: ``x64`` (float64; None leaves JAX's
    default) and ``compilation_cache`` (a folder for JAX's persistent compilation cache,
    shared by the workers and by later runs, so that a worker loads what another one or
    an earlier run compiled; None: no cache)."""

    x64: bool | None = None
    compilation_cache: str | None = None


def _configure_jax(settings: JaxSettings) -> None:
    if settings.x64 is None and settings.compilation_cache is None:
        return
    import jax

    if settings.x64 is not None and bool(jax.config.jax_enable_x64) != settings.x64:
        jax.config.update("jax_enable_x64", settings.x64)
    cache = settings.compilation_cache
    if cache is not None and jax.config.jax_compilation_cache_dir != cache:
        jax.config.update("jax_compilation_cache_dir", cache)
        # the jaw fits compile in seconds: keep every entry, not only slow ones
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


def run_item(task: Callable[..., TaskResult], item: CorpusItem, out_dir: str,
             options: Mapping[str, Any], fingerprint: str, jax_settings: JaxSettings
             ) -> ItemResult:
    """Run ``task`` on one item (in a worker): ``ItemResult`` OK with the row after the
    marker is written, or FAILED with the one-line error. KeyboardInterrupt and SystemExit
    pass through: an interrupted run stops, and its finished items stay marked."""
    try:
        # a marker says the latest attempt succeeded: an attempt that fails leaves none
        marker_path(out_dir, item).unlink(missing_ok=True)
        _configure_jax(jax_settings)  # a Dask worker is long-lived and shared: every task
        result = task(item, out_dir, **options)
        if not isinstance(result, TaskResult):
            raise TypeError(f"{task.__qualname__} returned {type(result).__name__}, "
                            "not a TaskResult")
        _write_marker(out_dir, item, fingerprint, result)
    except Exception as exc:  # noqa: BLE001 -- isolation: one bad recording, one FAILED row
        return ItemResult(item, Status.FAILED, _one_line(exc))
    return ItemResult(item, Status.OK, "", result.row)


def _init_worker(jax_settings: JaxSettings) -> None:
    _configure_jax(jax_settings)


# ---------------------------------------------------------------- the executor
def default_jobs() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@dataclass
class _Pool:
    """Where items run: ``executor`` (None: in this process), ``workers`` for the bar;
    ``settings`` set when the pool is our own local process pool (then shut down at the
    end, and rebuilt after a worker dies); ``client``: a Dask client we opened."""

    executor: cf.Executor | None
    workers: int
    settings: JaxSettings | None = None
    client: Any = None

    def new_executor(self, n: int) -> cf.ProcessPoolExecutor:
        import multiprocessing

        return cf.ProcessPoolExecutor(
            max_workers=n, mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker, initargs=(self.settings,))

    def close(self) -> None:
        if self.settings is not None and self.executor is not None:
            self.executor.shutdown(wait=True, cancel_futures=True)
        if self.client is not None:
            self.client.close()


def _dask_pool(client, own: bool) -> _Pool:
    workers = client.scheduler_info().get("workers", {})
    threads = sum(int(w.get("nthreads", 1)) for w in workers.values()) or 1
    return _Pool(client.get_executor(pure=False), threads, client=client if own else None)


def _open_pool(executor, jobs, scheduler, n_items: int, jax_settings) -> _Pool:
    if executor is not None:
        if hasattr(executor, "get_executor"):  # a dask.distributed.Client
            return _dask_pool(executor, own=False)
        workers = getattr(executor, "_max_workers", None) or 0
        return _Pool(executor, int(workers))
    if scheduler is not None:
        from distributed import Client

        return _dask_pool(Client(scheduler), own=True)
    jobs = default_jobs() if jobs is None else int(jobs)
    if jobs < 1:
        raise CassiError(f"jobs must be at least 1, got {jobs}")
    jobs = min(jobs, max(n_items, 1))
    if jobs == 1:
        return _Pool(None, 1)
    pool = _Pool(None, jobs, settings=jax_settings)
    pool.executor = pool.new_executor(jobs)
    return pool


def _current_x64() -> bool | None:
    import sys

    if "jax" not in sys.modules:
        return None
    return bool(sys.modules["jax"].config.jax_enable_x64)


# ------------------------------------------------------------------- the runner
@dataclass
class CorpusRun:
    """A finished run: ``results`` sorted by (subject, task), ``workers`` used."""

    results: list[ItemResult]
    workers: int

    @property
    def failed(self) -> list[ItemResult]:
        return [r for r in self.results if r.status == Status.FAILED]

    @property
    def resumed(self) -> int:
        return sum(r.resumed for r in self.results)

    def rows(self) -> list[dict]:
        """The corpus table: ``subject, task, status, error`` (the runner's, whatever the
        task's row says under those names) then the task's columns."""
        out = []
        for r in self.results:
            row = {"subject": r.item.subject, "task": r.item.task, "status": r.status.label,
                   "error": r.error}
            row.update((k, v) for k, v in r.row.items() if k not in ID_COLUMNS)
            out.append(row)
        return out

    def failure_summary(self) -> str:
        """``"k of n failed:"`` and one line per failed item; ``""`` if none failed."""
        if not self.failed:
            return ""
        lines = [f"{len(self.failed)} of {len(self.results)} failed:"]
        lines += [f"  {r.item.subject} {r.item.task}: {r.error}".rstrip() for r in self.failed]
        return "\n".join(lines)


def run_corpus(
    task: Callable[..., TaskResult],
    items: Sequence[CorpusItem],
    out_dir: str | os.PathLike,
    *,
    options: Mapping[str, Any] | None = None,
    executor: cf.Executor | Any | None = None,
    jobs: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    overwrite: bool = False,
    x64: bool | None = None,
    compilation_cache: str | os.PathLike | None = None,
    progress: bool = True,
    desc: str = "corpus",
) -> CorpusRun:
    """Run ``task(item, out_dir, overwrite=..., **options)`` on every item; see the
    module doc. Where: ``executor`` (any Executor or a Dask Client), else ``scheduler``
    (a Dask scheduler address), else ``jobs`` processes (default: all cores; 1 = this
    process). ``resume`` skips items already done with the same task and options;
    without ``resume`` or ``overwrite`` a folder holding markers of an earlier run is
    refused (OutputExistsError). ``x64``: float64 in the workers (default: as in this
    process; with ``jobs=1`` the setting is made in this process); ``compilation_cache``:
    a folder for JAX's persistent compilation cache in every worker (:class:`JaxSettings`).
    Returns every item's result, failed ones included; raises only for the run itself
    (bad arguments, an interruption).
    """
    out = Path(out_dir).absolute()  # workers may run in another folder
    markers = out / MARKER_DIR
    if not (resume or overwrite) and markers.is_dir() and any(markers.iterdir()):
        raise OutputExistsError(f"{out}: holds an earlier corpus run (pass resume=True / "
                                "--resume to continue it, or overwrite=True / --force)")
    options = {**(options or {}), "overwrite": bool(overwrite or resume)}
    fingerprint = task_fingerprint(task, {k: v for k, v in options.items() if k != "overwrite"})
    items = sorted(dict.fromkeys(items), key=_order)
    done, todo = [], []
    for item in items:
        row = completed_row(out, item, fingerprint) if resume else None
        if row is None:
            todo.append(item)
        else:
            done.append(ItemResult(item, Status.OK, "", row, resumed=True))
    jax_settings = JaxSettings(
        _current_x64() if x64 is None else bool(x64),
        None if compilation_cache is None else os.path.abspath(compilation_cache))
    pool = (_open_pool(executor, jobs, scheduler, len(todo), jax_settings) if todo
            else _Pool(None, 1))
    try:
        results = _collect(pool, task, todo, str(out), options, fingerprint, jax_settings,
                           progress, desc, len(items), len(done))
    finally:
        pool.close()
    return CorpusRun(sorted(done + results, key=lambda r: _order(r.item)), pool.workers)


def _progress_bar(progress, desc, workers, total, initial):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, disable=not progress, unit="rec",
                desc=f"{desc} ({workers} worker{'s' if workers != 1 else ''})")


def _collect(pool, task, todo, out, options, fingerprint, jax_settings, progress, desc, total,
             initial):
    bar = _progress_bar(progress, desc, pool.workers, total, initial)
    results, failed = [], 0

    def record(result):
        nonlocal failed
        results.append(result)
        failed += result.status == Status.FAILED
        bar.update(1)
        if failed:
            bar.set_postfix_str(f"{failed} failed")

    def submit(executor, item):
        return executor.submit(run_item, task, item, out, options, fingerprint, jax_settings)

    try:
        if pool.executor is None:
            for item in todo:
                record(run_item(task, item, out, options, fingerprint, jax_settings))
        else:
            _run_on_pool(pool, submit, todo, record)
        return results
    finally:
        bar.close()


WORKER_DIED = "its worker process died while running it (killed, out of memory or crashed)"


def _run_on_pool(pool, submit, todo, record) -> None:
    """Submit ``todo`` keeping at most two items per worker in flight (so a dying worker
    takes down only those, and Ctrl-C has little to cancel). When a worker of our own
    pool dies, the items in flight are rerun one by one, each in a fresh one-worker
    pool, so the item that kills its worker is found and FAILED, and the rest of the run
    goes on in a new pool."""
    from concurrent.futures.process import BrokenProcessPool

    queue, in_flight = list(reversed(todo)), {}
    limit = 2 * max(pool.workers, 1) + 2
    try:
        while queue or in_flight:
            while queue and len(in_flight) < limit:
                item = queue.pop()
                try:
                    in_flight[submit(pool.executor, item)] = item
                except Exception as exc:  # noqa: BLE001 -- a broken pool we cannot rebuild
                    record(ItemResult(item, Status.FAILED, _one_line(exc)))
            if not in_flight:
                continue
            done, _ = cf.wait(in_flight, return_when=cf.FIRST_COMPLETED)
            crashed = _settle(done, in_flight, record, BrokenProcessPool)
            if crashed and pool.settings is not None:
                done, _ = cf.wait(in_flight)  # a broken pool fails all it holds at once
                crashed += _settle(done, in_flight, record, BrokenProcessPool)
                pool.executor.shutdown(wait=True)
                for item in crashed:
                    record(_alone(pool, submit, item, BrokenProcessPool))
                pool.executor = pool.new_executor(pool.workers)
            else:
                for item in crashed:
                    record(ItemResult(item, Status.FAILED, WORKER_DIED))
    except BaseException:
        for future in in_flight:
            future.cancel()
        raise


def _settle(done, in_flight, record, broken) -> list[CorpusItem]:
    """Record finished futures; return the items whose worker died."""
    crashed = []
    for future in done:
        item = in_flight.pop(future)
        try:
            record(future.result())
        except broken:
            crashed.append(item)
        except Exception as exc:  # noqa: BLE001 -- e.g. a Dask worker lost, an unpicklable row
            record(ItemResult(item, Status.FAILED, _one_line(exc)))
    return crashed


def _alone(pool, submit, item, broken) -> ItemResult:
    """Run one item in a fresh one-worker pool: its result, or FAILED if it kills it."""
    single = pool.new_executor(1)
    try:
        return submit(single, item).result()
    except broken:
        return ItemResult(item, Status.FAILED, WORKER_DIED)
    except Exception as exc:  # noqa: BLE001
        return ItemResult(item, Status.FAILED, _one_line(exc))
    finally:
        single.shutdown(wait=True)


def write_table(rows: Sequence[Mapping], path: str | os.PathLike, *,
                columns: Sequence[str] | None = None, overwrite: bool = False) -> list[Path]:
    """A corpus table: ``tables.write_table`` as CSV, and as Parquet beside it when pyarrow
    is importable."""
    return _write_table(rows, path, columns=columns, overwrite=overwrite, parquet=None)


# ------------------------------------------------------------- per-worker model
_MODELS: dict[str, Any] = {}


def model_digest(model_dir: str | os.PathLike | None = None) -> str:
    """SHA-256 over the files of a model folder (default: the package's model)."""
    from .face_model import default_model_dir

    folder = Path(model_dir) if model_dir is not None else default_model_dir()
    h = hashlib.sha256()
    for p in sorted(q for q in folder.iterdir() if q.is_file()):
        h.update(p.name.encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def worker_model(model_dir: str | os.PathLike | None = None) -> FaceModel:
    """The face model, loaded once per worker process and kept by content digest, so
    that task functions can take a plain folder name and still reuse what the worker
    compiled for it (``eqx.filter_jit`` caches on the model's static topology)."""
    from .face_model import load_model

    key = model_digest(model_dir)
    if key not in _MODELS:
        _MODELS[key] = load_model(model_dir)
    return _MODELS[key]


# ------------------------------------------------------ shared by the commands below
def _calibration_for(item: CorpusItem, conformation: str | None, calibration_dir: str | None):
    """``initialize``'s calibration for one item: ``conformation`` (e.g. "cassi"), else
    ``calibration_dir/SUBJECT.calibration.json`` when that file exists, else None (the
    default conformation; the rows say "default")."""
    if conformation is not None:
        return conformation
    if calibration_dir is None:
        return None
    from .calibrate import calibration_path, read_calibration

    path = calibration_path(calibration_dir, item.subject)
    return read_calibration(path) if path.is_file() else None


def _load_quietly(item: CorpusItem) -> Recording:
    """:func:`load_item` without the default-head-measures warning (the rows say which
    conformation was used; a warning per worker would only repeat it)."""
    import warnings

    from .dataset import DefaultHeadMeasuresWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return load_item(item)


def _refuse_existing(paths: Sequence[Path], replace: bool) -> None:
    existing = [str(p) for p in paths if p.exists()]
    if existing and not replace:  # refuse before the run, not after it
        raise OutputExistsError(f"{existing[0]}: file exists (pass overwrite=True / --force, "
                                "or resume=True / --resume)")


def _replace(run_options: Mapping[str, Any]) -> bool:
    return bool(run_options.get("overwrite") or run_options.get("resume"))


# ------------------------------------------------------------ `cassi evaluate`
MEASURE_PREFIX = "measure."


def evaluate_task(item: CorpusItem, out_dir: str, *, conformation: str | None = None,
                  calibration_dir: str | None = None, collisions: str = "off",
                  jaw: str = "closed-form", stride: int = 1, mode: str = "improved",
                  overwrite: bool = False) -> TaskResult:
    """``cassi evaluate``'s task: animate one recording and measure it
    (``evaluate.evaluate_recording`` with the worker's model). The row holds ``frames``,
    ``calibration`` (its label) and every measure as ``measure.NAME``; ratings are derived
    from the measures afterwards (:func:`evaluation_result`). Writes no file."""
    from .evaluate import evaluate_recording

    recording = _load_quietly(item)
    row = evaluate_recording(recording, calibration=_calibration_for(item, conformation,
                                                                     calibration_dir),
                             collisions=collisions, jaw=jaw, stride=stride,
                             model=worker_model(), mode=mode)
    out = {"frames": row.frames, "calibration": row.calibration}
    out.update((MEASURE_PREFIX + k, float(v)) for k, v in sorted(row.measures.items()))
    return TaskResult(out)


def evaluation_result(run: CorpusRun, settings: Mapping[str, Any]) -> EvaluationResult:
    """The ``evaluate.EvaluationResult`` of a run of :func:`evaluate_task`: one
    ``RecordingRow`` per item in the run's sorted order (FAILED ones with their error),
    then each subject's row combined from its recordings in that order. ``settings``:
    ``stride``, ``jaw``, ``collisions`` and the ``calibration`` label."""
    from .evaluate import EvaluationResult, RecordingRow, SubjectRow

    common = {k: settings[k] for k in ("stride", "jaw", "collisions")}
    rows = []
    for r in run.results:
        s, t = r.item.subject, r.item.task
        if r.status == Status.FAILED:
            rows.append(RecordingRow.not_evaluated(s, t, r.error,
                                                   calibration=settings["calibration"], **common))
            continue
        measures = {k[len(MEASURE_PREFIX):]: float(v) for k, v in r.row.items()
                    if k.startswith(MEASURE_PREFIX)}
        rows.append(RecordingRow.evaluated(s, t, measures, frames=int(r.row["frames"]),
                                           calibration=r.row["calibration"], **common))
    subjects = list(dict.fromkeys(r.subject for r in rows))
    per_subject = [SubjectRow.of_recordings(s, [r for r in rows if r.subject == s], **common)
                   for s in subjects]
    return EvaluationResult(rows, per_subject, dict(settings))


def evaluate_corpus(
    dataset: Dataset | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    calibrations: str | os.PathLike | None = None,
    collisions: str = "off",
    jaw: str = "closed-form",
    stride: int = 1,
    subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None,
    mode: str = "improved",
    **run_options: Any,
) -> tuple[CorpusRun, EvaluationResult]:
    """``cassi evaluate DATASET``: :func:`evaluate_task` on every recording, combined per
    subject (:func:`evaluation_result`). ``calibrations``: None (default conformation),
    ``"cassi"`` or a folder of ``cassi calibrate`` files (a subject without one gets the
    default); ``mode``: ``options.MODES`` (``"cassi"``: the paper's every choice, no
    calibration folder, no collisions). Completion markers go to ``out_dir``; the tables are the caller's
    (``evaluate.write_table``). Returns ``(run, EvaluationResult)``."""
    from .errors import MissingDataError
    from .options import COLLISION_MODES, CONFORMATIONS, JAW_METHODS, MODES, check_choice

    check_choice("collisions", collisions, COLLISION_MODES)
    check_choice("jaw method", jaw, JAW_METHODS)
    check_choice("mode", mode, MODES)
    if isinstance(stride, bool) or int(stride) != stride or stride < 1:
        raise CassiError(f"stride must be an integer of at least 1, got {stride!r}")
    folder = None if calibrations is None or str(calibrations) in CONFORMATIONS else str(
        Path(calibrations).absolute())
    conformation = str(calibrations) if calibrations is not None and folder is None else None
    items = dataset_items(dataset, subjects=subjects, tasks=tasks)
    if not items:
        raise MissingDataError(f"{dataset}: no recordings found (for the subjects and tasks "
                               "chosen)")
    if folder is not None:
        _check_calibrations(folder, items)
    options = {"conformation": conformation, "calibration_dir": folder,
               "collisions": collisions, "jaw": jaw, "stride": int(stride), "mode": mode}
    run_options.setdefault("desc", "evaluate")
    run = run_corpus(evaluate_task, items, out_dir, options=options, **run_options)
    label = ("cassi mode" if mode == "cassi" else "calibrated" if folder is not None
             else (conformation or "default"))
    settings = {"stride": int(stride), "jaw": jaw, "collisions": collisions,
                "calibration": label}
    return run, evaluation_result(run, settings)


def _check_calibrations(folder: str, items: Sequence[CorpusItem]) -> None:
    """Read the folder's calibration files once here, so that a broken one stops the run
    before it starts (instead of failing every recording of its subject), and warn for
    each subject that has none (its recordings get the default conformation)."""
    import warnings

    from . import calibrate

    have = calibrate.load_calibrations(Path(folder))
    for subject in dict.fromkeys(item.subject for item in items):
        if subject not in have:
            warnings.warn(f"{subject}: no calibration given; using the default conformation",
                          stacklevel=3)


# ------------------------------------------------------------ `cassi calibrate`
def calibrate_task(item: CorpusItem, out_dir: str, *, tasks: Sequence[str] | None = None,
                   method: str = "separate", collisions: bool = True,
                   overwrite: bool = False) -> TaskResult:
    """``cassi calibrate``'s task, per subject (``item.task == ""``): calibrate the
    subject from ``tasks`` (default: all its recordings) with the worker's model and write
    ``out_dir/SUBJECT.calibration.json``. Row: method, scale, lip thicknesses, face width
    (mm), convergence."""
    import warnings

    from .calibrate import calibrate_subject, calibration_path, write_calibration
    from .dataset import Dataset
    from .errors import MissingDataError

    ds = Dataset(item.root)
    have = ds.tasks(item.subject)
    wanted = have if tasks is None else [t for t in have if t in {x.lower() for x in tasks}]
    if not wanted:
        raise MissingDataError(f"{ds.root}: subject {item.subject} has none of the tasks "
                               f"{', '.join(tasks or [])}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        recordings = [ds.load(item.subject, t) for t in wanted]
    cal = calibrate_subject(recordings, worker_model(), method=method, collisions=collisions)
    path = write_calibration(calibration_path(out_dir, item.subject), cal, overwrite=overwrite)
    row = {"method": cal.method, "recordings": len(recordings), "scale": float(cal.scale),
           "upper_lip_thickness_mm": float(cal.upper_lip_thickness),
           "lower_lip_thickness_mm": float(cal.lower_lip_thickness),
           "face_width_mm": float(cal.face_width), "converged": bool(cal.converged)}
    return TaskResult(row, (str(path),))


def calibrate_corpus(
    dataset: Dataset | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    subjects: Iterable[str] | None = None,
    tasks: Iterable[str] | None = None,
    method: str = "separate",
    collisions: bool = True,
    **run_options: Any,
) -> tuple[CorpusRun, dict]:
    """``cassi calibrate DATASET``: :func:`calibrate_task` per subject (float64), then
    ``out_dir/calibration_summary.csv`` (the calibrated subjects, read back from their
    files in sorted order) and ``out_dir/calibration_corpus.csv`` (every subject, failed
    ones with their error; and ``.parquet``). Returns ``(run, {subject: Calibration})``."""
    from .calibrate import calibration_path, read_calibration, write_summary
    from .options import CALIBRATION_METHODS, check_choice

    check_choice("calibration method", method, CALIBRATION_METHODS)
    out = Path(out_dir)
    summary, table = out / "calibration_summary.csv", out / "calibration_corpus.csv"
    _refuse_existing([summary, table], _replace(run_options))
    run_options.setdefault("x64", True)  # calibration residuals are sub-millimetre
    run_options.setdefault("desc", "calibrate")
    options = {"tasks": None if tasks is None else tuple(sorted(str(t).lower() for t in tasks)),
               "method": method, "collisions": bool(collisions)}
    items = dataset_items(dataset, subjects=subjects, per_subject=True)
    if not items:
        from .errors import MissingDataError

        raise MissingDataError(f"{dataset}: no recordings found (for the subjects chosen)")
    run = run_corpus(calibrate_task, items, out, options=options, **run_options)
    cals = {r.item.subject: read_calibration(calibration_path(out, r.item.subject))
            for r in run.results if r.status == Status.OK}
    write_summary(summary, cals, overwrite=_replace(run_options))
    write_table(run.rows(), table, overwrite=_replace(run_options))
    return run, cals


# ------------------------------------------------------------ `cassi animate DATASET`
def video_output_path(out_dir: str | os.PathLike, item: CorpusItem, suffix: str = ".mp4"
                      ) -> Path:
    """``out_dir/SUBJECT/TASK.mp4`` (or the given suffix)."""
    return Path(out_dir) / item.subject / f"{item.task}{suffix}"


def animate_task(item: CorpusItem, out_dir: str, *, suffix: str = ".mp4",
                 size: tuple[int, int] = (640, 480), views: Sequence[str] | None = None,
                 conformation: str | None = None, calibration_dir: str | None = None,
                 audio: bool = True, markers: bool = False, labels: bool = True,
                 overwrite: bool = False, **animate_options: Any) -> TaskResult:
    """``cassi animate DATASET``'s task: animate one recording
    (``initialize.animate_recording`` with ``animate_options``: jaw, stride, jaw_weights,
    tongue_anchor, gap_policy, collisions) and write ``out_dir/SUBJECT/TASK.mp4`` (or
    ``.gif``), the current label (``labels.labels_for``) in each frame's caption."""
    from .initialize import animate_recording
    from .labels import labels_for
    from .render import Renderer
    from .video import subject_traces, write_animation

    recording = _load_quietly(item)
    state, animation = animate_recording(
        recording, worker_model(), calibration=_calibration_for(item, conformation,
                                                                calibration_dir),
        **animate_options)
    views = tuple(views) if views else None
    renderer = Renderer(state.model, size=tuple(size), traces=subject_traces(
        recording, state.scale), **({"views": views, "grid": len(views) > 1} if views else {}))
    found = labels_for(recording.path) if labels else None
    path = write_animation(
        video_output_path(out_dir, item, suffix), animation, renderer, subject=item.subject,
        task=item.task, audio=recording.audio if audio and suffix == ".mp4" else None,
        markers=markers, progress=False, overwrite=overwrite, labels=found)
    from .tongue import tongue_volumes

    volume = tongue_volumes(state.model, animation.vertices)
    row = {"frames": int(animation.n_frames), "stride": int(animation.stride),
           "video": str(Path(path).relative_to(Path(out_dir))),
           "label_file": found.path.name if found is not None and found.path else "",
           "tongue_volume_min_ml": round(float(volume.min()), 3),
           "tongue_volume_max_ml": round(float(volume.max()), 3)}
    return TaskResult(row, (str(path),))


def animate_corpus(dataset: Dataset | str | os.PathLike, out_dir: str | os.PathLike, *,
                   subjects: Iterable[str] | None = None, tasks: Iterable[str] | None = None,
                   task_options: Mapping[str, Any] | None = None, **run_options: Any
                   ) -> tuple[CorpusRun, list[Path]]:
    """``cassi animate DATASET --out DIR``: :func:`animate_task` (``task_options``) on
    every recording, then ``DIR/animate_corpus.csv`` (and ``.parquet``): one row per
    recording, failed ones with their error."""
    table = Path(out_dir) / "animate_corpus.csv"
    _refuse_existing([table], _replace(run_options))
    run_options.setdefault("desc", "animate")
    run = run_corpus(animate_task, dataset_items(dataset, subjects=subjects, tasks=tasks),
                     out_dir, options=dict(task_options or {}), **run_options)
    return run, write_table(run.rows(), table, overwrite=_replace(run_options))
