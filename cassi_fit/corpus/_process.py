"""What a process that computes sets up before JAX starts: the persistent compilation cache
and, for one worker among several, its share of the cores.

**The compilation cache.** JAX compiles every function a run needs (seconds per
function); without a persistent cache every process pays that again. The command line and
the corpus workers keep what they compile in one folder per user, and a later process
(the next file of a shell loop, a worker of the next run) loads it instead of compiling.
The folder, first match wins:

1. ``CASSI_COMPILE_CACHE=DIR`` (``off``, ``0``, ``none`` or empty: no cache);
2. ``JAX_COMPILATION_CACHE_DIR`` (JAX's own variable; the test suite sets it to a
   temporary folder);
3. ``$XDG_CACHE_HOME/cassi_fit/jax``, else ``~/.cache/cassi_fit/jax``.

``cassi ... --no-compile-cache`` turns it off for one command. The kernels that a process
would otherwise trace again are kept in its subfolder ``exported/`` (``cassi_fit._exported``;
``CASSI_EXPORT_CACHE=DIR|off`` moves or turns off that part alone). Every compiled function is
kept (JAX's default keeps only those that took a second to compile), and the folder is
held under :data:`COMPILE_CACHE_MAX_BYTES`, the least recently used entries evicted
first.

*Several processes at once.* JAX writes a cache entry with a plain file write and reads
whatever file it finds under the entry's name; only when the cache has a size limit does
it take a file lock (``filelock``, a dependency) around each read, write and eviction. So
the limit is always set here: a process never reads an entry that another one is half-way
through writing. (A failed read is not fatal in JAX either: it warns and compiles.)
Entries are keyed by the function, the shapes, the JAX version and the flags (float64 or
not), so a run with other settings adds entries beside the old ones.

*A folder written without the limit.* With the limit, JAX keeps beside every entry
(``KEY-cache``) its last use (``KEY-atime``) and, at every write, reads them all; one
entry without it (written by a process without the limit, or by one killed between the
two writes) makes every later write fail with a warning. So each process, before it uses
the folder, gives such entries a last use of 0 (the first to be evicted) under JAX's own
lock (:func:`repair_compile_cache`); and an interrupt waits while JAX writes an entry
(``cassi_fit._signals``).

**Threads.** XLA runs one computation on as many threads as the process may use. With
``--jobs N`` on C cores each worker is limited to ``C // N`` of them
(:func:`worker_thread_env`: XLA's Eigen thread pool off or to that size, and the
OpenMP/MKL/OpenBLAS thread counts), set in the worker before JAX starts, so that N
workers do not fight over the same cores.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Mapping
from pathlib import Path

from ..options import CACHE_OFF

#: The environment variable naming the cache folder (or ``off``).
COMPILE_CACHE_ENV = "CASSI_COMPILE_CACHE"
#: The cache's size limit: past it JAX evicts the least recently used entries. A full
#: run of every command on a few recording lengths takes about a tenth of it.
COMPILE_CACHE_MAX_BYTES = 2 * 1024**3
#: Functions that compile faster than this are not written (JAX's default is 1 s; most of
#: this toolkit's functions compile in 0.1-1 s, and together they are the start-up cost).
COMPILE_CACHE_MIN_SECONDS = 0.0


class CompileCacheWarning(UserWarning):
    """The compilation cache folder cannot be used; the process compiles without it."""


def default_compile_cache(environ: Mapping[str, str] | None = None) -> Path | None:
    """The compilation cache folder this process should use, or None (off); see the
    module's doc for the order (``CASSI_COMPILE_CACHE``, ``JAX_COMPILATION_CACHE_DIR``,
    the user's cache folder). Nothing is created or changed."""
    environ = os.environ if environ is None else environ
    chosen = environ.get(COMPILE_CACHE_ENV)
    if chosen is not None:
        if chosen.strip().lower() in CACHE_OFF:
            return None
        return Path(chosen).expanduser().absolute()
    if environ.get("JAX_COMPILATION_CACHE_DIR"):
        return Path(environ["JAX_COMPILATION_CACHE_DIR"]).expanduser().absolute()
    base = environ.get("XDG_CACHE_HOME", "")
    if not base or not os.path.isabs(base):  # the XDG rule: a relative value is ignored
        base = os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "cassi_fit" / "jax"


def _usable(folder: Path) -> str | None:
    """None if ``folder`` exists (created if needed) and is writable; else the reason."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return exc.strerror or type(exc).__name__
    if not os.access(folder, os.W_OK | os.X_OK):
        return "not writable"
    return None


#: JAX's names in a size-limited cache folder: an entry and its last use
#: (``jax._src.lru_cache``).
_ENTRY_SUFFIX, _LAST_USE_SUFFIX = "-cache", "-atime"


def repair_compile_cache(folder: str | os.PathLike, timeout_s: float = 10.0) -> int:
    """Give every entry of the cache ``folder`` that has no last-use file one (time 0:
    evicted first), under JAX's lock on the folder, so that JAX's size limit can work on
    it (see the module's doc); returns how many were given one. A folder that cannot be
    locked or written is left as it is (0): JAX then warns and compiles, as before."""
    try:
        import filelock
    except ImportError:  # no limit without it (compile_cache_settings), so nothing to do
        return 0
    folder = Path(folder)
    repaired = 0
    try:
        with filelock.FileLock(os.fspath(folder / ".lockfile"), timeout=timeout_s):
            for entry in folder.glob(f"*{_ENTRY_SUFFIX}"):
                key = entry.name[: -len(_ENTRY_SUFFIX)]
                last_use = folder / f"{key}{_LAST_USE_SUFFIX}"
                if not last_use.exists():
                    last_use.write_bytes((0).to_bytes(8, "little"))
                    repaired += 1
    except (OSError, filelock.Timeout):
        pass
    return repaired


def compile_cache_settings(folder: str | os.PathLike) -> dict[str, str]:
    """JAX's settings (as environment variables) for a compilation cache in ``folder``:
    the folder, every entry kept, the size limit that makes JAX lock the folder."""
    import importlib.util

    settings = {
        "JAX_COMPILATION_CACHE_DIR": os.fspath(folder),
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": str(COMPILE_CACHE_MIN_SECONDS),
        "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",  # no size floor either
    }
    if importlib.util.find_spec("filelock") is not None:  # JAX needs it for the limit
        settings["JAX_COMPILATION_CACHE_MAX_SIZE"] = str(COMPILE_CACHE_MAX_BYTES)
    return settings


def use_compile_cache(folder: str | os.PathLike | None, *, inherit: bool = True
                      ) -> Path | None:
    """Make this process use the compilation cache in ``folder`` (None: no cache);
    returns the folder used, or None.

    ``inherit`` (the command line, a pool's worker): through JAX's environment variables,
    which JAX reads when it is imported and the processes this one starts inherit; and
    through ``jax.config`` if JAX is imported already. ``inherit=False`` (a library call
    in the caller's process): ``jax.config`` only, the environment left alone. Either
    takes effect if JAX has compiled nothing yet. A folder that cannot be created or
    written is a :class:`CompileCacheWarning` (one line) and no cache, never an error.
    """
    if folder is not None:
        folder = Path(folder).expanduser().absolute()
        reason = _usable(folder)
        if reason is not None:
            warnings.warn(f"{folder}: cannot hold the compilation cache ({reason}); "
                          "compiling without it", CompileCacheWarning, stacklevel=2)
            folder = None
    settings = {} if folder is None else compile_cache_settings(folder)
    if "JAX_COMPILATION_CACHE_MAX_SIZE" in settings:
        repair_compile_cache(folder)
    if inherit and folder is None:
        os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
        os.environ[COMPILE_CACHE_ENV] = "off"  # for the processes this one starts
    elif inherit:
        os.environ.update(settings)
    jax = sys.modules.get("jax")
    if jax is None and not inherit:
        import jax
    if jax is not None:
        _update_config(jax, folder, settings)
    return folder


def _update_config(jax, folder: Path | None, settings: Mapping[str, str]) -> None:
    if folder is None:
        jax.config.update("jax_enable_compilation_cache", False)
        return
    jax.config.update("jax_enable_compilation_cache", True)
    if jax.config.jax_compilation_cache_dir != os.fspath(folder):
        jax.config.update("jax_compilation_cache_dir", os.fspath(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", COMPILE_CACHE_MIN_SECONDS)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    if "JAX_COMPILATION_CACHE_MAX_SIZE" in settings:
        jax.config.update("jax_compilation_cache_max_size", COMPILE_CACHE_MAX_BYTES)


# --------------------------------------------------------------------------- threads
#: Thread-count variables of the numerical libraries a worker may load (and of Mesa's
#: llvmpipe, which draws a video's frames with one thread per core by default).
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                     "NPROC", "LP_NUM_THREADS")


def worker_thread_env(threads: int, environ: Mapping[str, str] | None = None
                      ) -> dict[str, str]:
    """The environment variables that limit a process to ``threads`` threads of
    computation: XLA's CPU client thread pool (``NPROC``), its Eigen intra-op pool
    (``XLA_FLAGS``: ``--xla_cpu_multi_thread_eigen=false`` for one thread, else
    ``intra_op_parallelism_threads=N``; flags already in ``XLA_FLAGS`` are kept) and
    OpenMP, MKL and OpenBLAS. Must be in the environment before JAX starts."""
    environ = os.environ if environ is None else environ
    threads = max(int(threads), 1)
    flags = [f for f in environ.get("XLA_FLAGS", "").split()
             if not f.lstrip("-").startswith(("xla_cpu_multi_thread_eigen",
                                              "intra_op_parallelism_threads"))]
    if threads == 1:
        flags.append("--xla_cpu_multi_thread_eigen=false")
    flags.append(f"intra_op_parallelism_threads={threads}")
    out = {name: str(threads) for name in _THREAD_VARIABLES}
    out["XLA_FLAGS"] = " ".join(flags)
    return out


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """Each of ``workers`` processes' share of ``cores`` (default: the cores this process
    may use), at least 1."""
    if cores is None:
        try:
            cores = len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            cores = os.cpu_count() or 1
    return max(cores // max(int(workers), 1), 1)


def limit_threads(threads: int) -> bool:
    """Limit this process to ``threads`` threads of computation (:func:`worker_thread_env`)
    if JAX has not started yet; returns whether the limit could still be set."""
    if "jax" in sys.modules:
        return False
    os.environ.update(worker_thread_env(threads))
    return True
