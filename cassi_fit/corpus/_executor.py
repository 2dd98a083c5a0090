"""The executor: one task function over many items, on any Executor (see the package
docstring): failure isolation, resuming, the run's table."""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from .._io import check_output_folder, check_outputs
from .._signals import defer_interrupts, end_worker, in_task, is_worker, signals_blocked
from ..errors import CassiError, OutputExistsError
from ..status import Status
from ..tables import ID_COLUMNS
from ..tables import write_table as _write_table
from ._cluster import connect_scheduler
from ._items import CorpusItem, ItemResult, TaskResult, _order
from ._markers import MARKER_DIR, _write_marker, completed_row, marker_path, task_fingerprint
from ._process import default_compile_cache, limit_threads, threads_per_worker, use_compile_cache

if TYPE_CHECKING:
    from ..face_model import FaceModel


def _one_line(exc: BaseException) -> str:
    """The error as one line: the message of a CassiError, else ``Type: message``."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    if not isinstance(exc, CassiError):
        text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= 300 else text[:297] + "..."


@dataclass(frozen=True)
class JaxSettings:
    """What every worker sets before a task: ``x64`` (float64; None leaves JAX's
    default); the persistent compilation cache: ``compilation_cache`` (a folder, shared
    by the workers and by later runs, so that a worker loads what another one or an
    earlier run compiled) or, with ``default_cache``, the worker's own default folder
    (``_process.default_compile_cache``: a Dask worker on another machine uses its own);
    neither: no cache. ``threads``: the worker's share of the cores (set before JAX
    starts, in a process pool's workers only; None: no limit). ``rank_promotion``: JAX's
    rank promotion rule (``allow``, ``warn``, ``raise``; None leaves JAX's), the
    starting process's: its workers trace as it does (a worker that allowed what the
    caller refuses would hide it), and a kernel it exported (``cassi_fit._exported``,
    keyed by that rule) is theirs to load instead of tracing it again."""

    x64: bool | None = None
    compilation_cache: str | None = None
    default_cache: bool = False
    threads: int | None = None
    rank_promotion: str | None = None

    def cache_folder(self) -> str | None:
        """The cache folder to use in this process, or None."""
        if self.compilation_cache is not None:
            return self.compilation_cache
        if self.default_cache:
            folder = default_compile_cache()
            return None if folder is None else os.fspath(folder)
        return None


def _configure_jax(settings: JaxSettings, *, inherit: bool = False) -> None:
    """Apply ``settings`` in this process; ``inherit``: through the environment too (a
    pool's worker before JAX starts), else through ``jax.config`` only (this process's
    environment, which the caller owns, is left alone)."""
    cache = settings.cache_folder()
    if settings.x64 is None and cache is None and settings.rank_promotion is None:
        return
    if cache is not None and _CONFIGURED.get("cache") != cache:
        use_compile_cache(cache, inherit=inherit)
        _CONFIGURED["cache"] = cache
    if settings.x64 is not None:
        import jax

        if bool(jax.config.jax_enable_x64) != settings.x64:
            jax.config.update("jax_enable_x64", settings.x64)
    if settings.rank_promotion is not None:
        import jax

        if jax.config.jax_numpy_rank_promotion != settings.rank_promotion:
            jax.config.update("jax_numpy_rank_promotion", settings.rank_promotion)


_CONFIGURED: dict[str, str] = {}  # what _configure_jax last set in this process


def run_item(task: Callable[..., TaskResult], item: CorpusItem, out_dir: str | None,
             options: Mapping[str, Any], fingerprint: str, jax_settings: JaxSettings
             ) -> ItemResult:
    """Run ``task`` on one item (in a worker): ``ItemResult`` OK with the row after the
    marker is written, or FAILED with the one-line error. KeyboardInterrupt and SystemExit
    pass through: an interrupted run stops, and its finished items stay marked (in a pool
    worker, SIGTERM interrupts the task, its writers clean up, and the worker ends)."""
    try:
        with in_task():
            # a marker says the latest attempt succeeded: an attempt that fails leaves none
            if out_dir is not None:
                marker_path(out_dir, item).unlink(missing_ok=True)
            _configure_jax(jax_settings)  # a Dask worker is long-lived and shared: every task
            result = task(item, out_dir, **options)
            if not isinstance(result, TaskResult):
                raise TypeError(f"{task.__qualname__} returned {type(result).__name__}, "
                                "not a TaskResult")
            if out_dir is not None:
                _write_marker(out_dir, item, fingerprint, result)
    except Exception as exc:  # noqa: BLE001 -- isolation: one bad recording, one FAILED row
        return ItemResult(item, Status.FAILED, _one_line(exc))
    except KeyboardInterrupt:
        if is_worker():  # its clean-up has run; the pool sees a worker that ended
            end_worker()
        raise
    return ItemResult(item, Status.OK, "", result.row)


def _init_worker(jax_settings: JaxSettings) -> None:
    """A local pool's worker, before any task (and before JAX starts): its share of the
    threads, the signals (:func:`cassi_fit._signals.worker_signals`: Ctrl-C is the parent's to
    handle; SIGTERM ends a task as an interrupt, with its clean-up, and the worker
    quietly), the compilation cache and float64."""
    from .._signals import worker_signals

    if jax_settings.threads is not None:
        limit_threads(jax_settings.threads)
    worker_signals()
    _configure_jax(jax_settings, inherit=True)


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

    def close(self, *, interrupted: bool = False) -> None:
        """Shut our own pool down (``interrupted``: its workers told to stop now, by
        SIGTERM, rather than after their current item) and close our Dask client."""
        if self.settings is not None and self.executor is not None:
            if interrupted:
                for process in list(getattr(self.executor, "_processes", {}).values()):
                    if process.is_alive():
                        process.terminate()
            # interrupted: the pool breaks and fails every pending future itself (Python
            # 3.11 raises in its manager thread if one of them was cancelled first)
            self.executor.shutdown(wait=True, cancel_futures=not interrupted)
        if self.client is not None:
            self.client.close()


def _dask_pool(client, own: bool) -> _Pool:
    workers = client.scheduler_info().get("workers", {})
    threads = sum(int(w.get("nthreads", 1)) for w in workers.values()) or 1
    return _Pool(client.get_executor(pure=False), threads, client=client if own else None)


def _open_pool(executor, jobs, scheduler, n_items: int, jax_settings,
               scheduler_timeout=None) -> _Pool:
    if executor is not None:
        if hasattr(executor, "get_executor"):  # a dask.distributed.Client
            return _dask_pool(executor, own=False)
        workers = getattr(executor, "_max_workers", None) or 0
        return _Pool(executor, int(workers))
    if scheduler is not None:
        return _dask_pool(connect_scheduler(scheduler, scheduler_timeout), own=True)
    jobs = default_jobs() if jobs is None else int(jobs)
    if jobs < 1:
        raise CassiError(f"jobs must be at least 1, got {jobs}")
    jobs = min(jobs, max(n_items, 1))
    if jobs == 1:
        return _Pool(None, 1)
    pool = _Pool(None, jobs, settings=replace(jax_settings, threads=threads_per_worker(jobs)))
    pool.executor = pool.new_executor(jobs)
    return pool


def process_pool(jobs: int, *, x64: bool | None = None,
                 compilation_cache: str | os.PathLike | bool | None = True
                 ) -> cf.ProcessPoolExecutor:
    """The pool ``run_corpus(jobs=N)`` makes, to keep between runs (its workers stay warm:
    what they compiled and loaded is kept): ``jobs`` 'spawn' worker processes, each on its
    share of the cores, with ``x64`` and the ``compilation_cache`` as :func:`run_corpus`
    takes them. Pass it as ``run_corpus(executor=...)``; shut it down when done."""
    own_cache = compilation_cache not in (None, True, False)
    settings = JaxSettings(x64, os.path.abspath(compilation_cache) if own_cache else None,
                           default_cache=compilation_cache is True,
                           threads=threads_per_worker(jobs),
                           rank_promotion=_current("jax_numpy_rank_promotion"))
    return _Pool(None, jobs, settings=settings).new_executor(jobs)


def _current(name: str) -> bool | str | None:
    """This process's JAX setting ``name`` (``jax_enable_x64``: float64, a bool;
    ``jax_numpy_rank_promotion``: the rank promotion rule, a str), None before JAX starts
    (read without importing JAX: a process that has not started it has no setting)."""
    import sys

    jax = sys.modules.get("jax")
    return None if jax is None else getattr(jax.config, name)


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


class CorpusResult(NamedTuple):
    """What every corpus entry point returns (``animate_corpus``, ``evaluate_corpus``,
    ``jaw_corpus``, ``calibrate_corpus``): the ``run`` (``run.failed``: exit non-zero),
    the ``tables`` written (paths; none when the caller writes them), and the command's
    ``value`` (the evaluation, the calibrations; None when the tables are all)."""

    run: CorpusRun
    tables: list[Path]
    value: Any = None


def run_corpus(
    task: Callable[..., TaskResult],
    items: Sequence[CorpusItem],
    out_dir: str | os.PathLike | None,
    *,
    options: Mapping[str, Any] | None = None,
    executor: cf.Executor | Any | None = None,
    jobs: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    overwrite: bool = False,
    x64: bool | None = None,
    compilation_cache: str | os.PathLike | bool | None = True,
    scheduler_timeout: float | None = None,
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
    JAX's persistent compilation cache in every worker (and in this process with
    ``jobs=1``): True (default) the worker's default folder
    (``corpus._process.default_compile_cache``: ``CASSI_COMPILE_CACHE``, else
    ``JAX_COMPILATION_CACHE_DIR``, else the user's cache folder), a folder, or
    False/None for none (:class:`JaxSettings`). With ``jobs`` > 1 each worker computes
    on its share of the cores. ``scheduler_timeout``: seconds allowed to reach
    ``scheduler`` (default ``CASSI_SCHEDULER_TIMEOUT`` or 10; ``corpus._cluster``).
    Returns every item's result, failed ones included; raises only for the run itself
    (bad arguments, an interruption). ``out_dir`` None: a run that writes no files and
    keeps no markers (the library's in-memory forms, e.g. ``evaluate_dataset``; no
    ``resume``).
    """
    if out_dir is None and resume:
        raise CassiError("resume needs an output folder (its completion markers)")
    out = None if out_dir is None else Path(out_dir).absolute()  # workers: another folder
    if out is not None:
        check_output_folder(out)  # a file or a pipe: one line now, not a failure per item
    markers = None if out is None else out / MARKER_DIR
    if (markers is not None and not (resume or overwrite) and markers.is_dir()
            and any(markers.iterdir())):
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
    own_cache = compilation_cache not in (None, True, False)
    jax_settings = JaxSettings(
        _current("jax_enable_x64") if x64 is None else bool(x64),
        os.path.abspath(compilation_cache) if own_cache else None,
        default_cache=compilation_cache is True,
        rank_promotion=_current("jax_numpy_rank_promotion"))
    pool = (_open_pool(executor, jobs, scheduler, len(todo), jax_settings, scheduler_timeout)
            if todo else _Pool(None, 1))
    try:
        results = _collect(pool, task, todo, None if out is None else str(out), options,
                           fingerprint, jax_settings, progress, desc, len(items), len(done))
    except BaseException:
        with defer_interrupts():
            pool.close(interrupted=True)
        raise
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
        # our own pool: a worker started here sets its handlers before any signal
        with signals_blocked() if pool.settings is not None else nullcontext():
            return executor.submit(run_item, task, item, out, options, fingerprint,
                                   jax_settings)

    try:
        if pool.executor is None:  # in this process: its own float64 setting comes back
            before = _current("jax_enable_x64")
            try:
                for item in todo:
                    record(run_item(task, item, out, options, fingerprint, jax_settings))
            finally:
                if before is not None and _current("jax_enable_x64") != before:
                    import jax

                    jax.config.update("jax_enable_x64", before)
        else:
            _run_on_pool(pool, submit, todo, record)
        return results
    finally:
        bar.close()


#: How often (s) the main thread wakes while it waits for a pool's work: a signal the
#: system hands to another of this process's threads (the pool's manager, tqdm's monitor)
#: reaches Python's handler only when the main thread runs again, and a wait without a
#: timeout never does: Ctrl-C was left unanswered, the run waiting for ever
WAKE_S = 0.25


def _wait(futures, return_when=cf.ALL_COMPLETED):
    """``concurrent.futures.wait``, woken every :data:`WAKE_S` so that an interrupt is
    answered (the signal's handler runs between two waits)."""
    while True:
        done, pending = cf.wait(futures, timeout=WAKE_S, return_when=return_when)
        if not pending or (done and return_when == cf.FIRST_COMPLETED):
            return done, pending


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
            done, _ = _wait(in_flight, return_when=cf.FIRST_COMPLETED)
            crashed = _settle(done, in_flight, record, BrokenProcessPool)
            if crashed and pool.settings is not None:
                done, _ = _wait(in_flight)  # a broken pool fails all it holds at once
                crashed += _settle(done, in_flight, record, BrokenProcessPool)
                pool.executor.shutdown(wait=True)
                for item in crashed:
                    record(_alone(pool, submit, item, BrokenProcessPool))
                pool.executor = pool.new_executor(pool.workers)
            else:
                for item in crashed:
                    record(ItemResult(item, Status.FAILED, WORKER_DIED))
    except BaseException:
        if pool.settings is None:  # our own pool is stopped whole by _Pool.close
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
        future = submit(single, item)
        _wait([future])
        return future.result()
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


_MODELS: dict[str, Any] = {}


def model_digest(model_dir: str | os.PathLike | None = None) -> str:
    """SHA-256 over the files of a model folder (default: the package's model)."""
    from ..face_model import default_model_dir

    folder = Path(model_dir) if model_dir is not None else default_model_dir()
    h = hashlib.sha256()
    for p in sorted(q for q in folder.iterdir() if q.is_file()):
        h.update(p.name.encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


_OVERRIDES: list = []


@contextmanager
def use_model(model: FaceModel) -> Iterator[FaceModel]:
    """Within the block, :func:`worker_model` (no folder given) is ``model`` in this
    process: an in-process run (``jobs=1``) of a model the caller made."""
    _OVERRIDES.append(model)
    try:
        yield model
    finally:
        _OVERRIDES.pop()


def worker_model(model_dir: str | os.PathLike | None = None) -> FaceModel:
    """The face model, loaded once per worker process and kept by content digest, so
    that task functions can take a plain folder name and still reuse what the worker
    compiled for it (``eqx.filter_jit`` caches on the model's static topology)."""
    from ..face_model import load_model

    if model_dir is None and _OVERRIDES:
        return _OVERRIDES[-1]
    key = model_digest(model_dir)
    if key not in _MODELS:
        _MODELS[key] = load_model(model_dir)
    return _MODELS[key]


def refuse_existing(paths: Sequence[str | os.PathLike], run_options: Mapping[str, Any]) -> None:
    """Before a run: an ``OutputExistsError`` naming the first of ``paths`` that exists,
    unless ``run_options`` say ``overwrite`` or ``resume`` (a table is refused before the
    run, not after it)."""
    check_outputs(paths, overwrite=True)  # never a pipe, device, input or folder, even forced
    if run_options.get("overwrite") or run_options.get("resume"):
        return
    existing = [str(p) for p in paths if Path(p).exists()]
    if existing:
        raise OutputExistsError(f"{existing[0]}: file exists (pass overwrite=True / --force, "
                                "or resume=True / --resume)")


def replaces(run_options: Mapping[str, Any]) -> bool:
    """Whether a run with ``run_options`` may replace its tables (``overwrite`` or
    ``resume``)."""
    return bool(run_options.get("overwrite") or run_options.get("resume"))
