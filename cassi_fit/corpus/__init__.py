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
  paid once per worker, not once per recording; and by default every worker loads what
  any earlier process compiled from JAX's persistent compilation cache (``_process``:
  ``compilation_cache=`` a folder, or False for none). With ``jobs=N`` each worker
  computes on its share of the cores (XLA's threads limited before JAX starts), and
  ``scheduler=`` is checked and reached within a time limit (``_cluster``).
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

This package holds only the executor (``_executor``), the items (``_items``), the
resume markers (``_markers``), the set-up of a computing process (``_process``) and the
connection to a Dask cluster (``_cluster``). Each command's task lives beside the command:
``evaluate.evaluate_corpus``, ``calibrate.calibrate_corpus``, ``recording_video.animate_corpus``
(``cassi jaw DATASET``'s in ``jaw_corpus``);
:func:`write_table` writes a corpus table as CSV, and as Parquet when pyarrow is importable
(``cassi_fit.tables``).

The package's names are imported on first use (:func:`__getattr__`): a command that needs
one of its modules (``cassi`` sets up the compilation cache with ``_process`` before every
computing command) does not import the executor, the cluster connection and the markers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cassi_fit._lazy import lazy_names

if TYPE_CHECKING:
    from ..tables import csv_text as csv_text
    from ._cluster import DEFAULT_TIMEOUT_S as DEFAULT_TIMEOUT_S
    from ._cluster import SchedulerError as SchedulerError
    from ._cluster import check_scheduler as check_scheduler
    from ._cluster import connect_scheduler as connect_scheduler
    from ._cluster import parse_scheduler_address as parse_scheduler_address
    from ._cluster import scheduler_timeout as scheduler_timeout
    from ._executor import WORKER_DIED as WORKER_DIED
    from ._executor import CorpusResult as CorpusResult
    from ._executor import CorpusRun as CorpusRun
    from ._executor import ItemResult as ItemResult
    from ._executor import JaxSettings as JaxSettings
    from ._executor import TaskResult as TaskResult
    from ._executor import default_jobs as default_jobs
    from ._executor import model_digest as model_digest
    from ._executor import process_pool as process_pool
    from ._executor import refuse_existing as refuse_existing
    from ._executor import replaces as replaces
    from ._executor import run_corpus as run_corpus
    from ._executor import run_item as run_item
    from ._executor import use_model as use_model
    from ._executor import worker_model as worker_model
    from ._executor import write_table as write_table
    from ._items import CorpusItem as CorpusItem
    from ._items import chosen_tasks as chosen_tasks
    from ._items import dataset_items as dataset_items
    from ._items import item_rng as item_rng
    from ._items import load_item as load_item
    from ._items import require_items as require_items
    from ._markers import MARKER_DIR as MARKER_DIR
    from ._markers import completed_row as completed_row
    from ._markers import marker_path as marker_path
    from ._markers import task_fingerprint as task_fingerprint
    from ._process import COMPILE_CACHE_ENV as COMPILE_CACHE_ENV
    from ._process import default_compile_cache as default_compile_cache
    from ._process import use_compile_cache as use_compile_cache
    from ._process import worker_thread_env as worker_thread_env

#: Each public name -> the module (relative to this package) it comes from.
_NAMES = {
    "csv_text": "..tables",
    "DEFAULT_TIMEOUT_S": "._cluster",
    "SchedulerError": "._cluster",
    "check_scheduler": "._cluster",
    "connect_scheduler": "._cluster",
    "parse_scheduler_address": "._cluster",
    "scheduler_timeout": "._cluster",
    "WORKER_DIED": "._executor",
    "CorpusResult": "._executor",
    "CorpusRun": "._executor",
    "ItemResult": "._executor",
    "JaxSettings": "._executor",
    "TaskResult": "._executor",
    "default_jobs": "._executor",
    "model_digest": "._executor",
    "process_pool": "._executor",
    "refuse_existing": "._executor",
    "replaces": "._executor",
    "run_corpus": "._executor",
    "run_item": "._executor",
    "use_model": "._executor",
    "worker_model": "._executor",
    "write_table": "._executor",
    "CorpusItem": "._items",
    "chosen_tasks": "._items",
    "dataset_items": "._items",
    "item_rng": "._items",
    "load_item": "._items",
    "require_items": "._items",
    "MARKER_DIR": "._markers",
    "completed_row": "._markers",
    "marker_path": "._markers",
    "task_fingerprint": "._markers",
    "COMPILE_CACHE_ENV": "._process",
    "default_compile_cache": "._process",
    "use_compile_cache": "._process",
    "worker_thread_env": "._process",
}

__all__ = sorted(_NAMES)


__getattr__, __dir__ = lazy_names(__name__, _NAMES, globals())
