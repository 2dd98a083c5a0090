"""Compiled kernels that a new process loads instead of tracing them again (issue 30).

JAX's persistent compilation cache (:mod:`cassi_fit.corpus._process`) spares a new
process the compiling of a function, not its tracing: every process still runs the
function's Python once per shape to find what to compile, seconds for the calibration's
solver. :func:`exported` wraps a module-level kernel as ``eqx.filter_jit`` does (its
arguments may be pytrees mixing arrays and hashable non-array leaves, such as the face
model's ``Topology``, which select the computation) and keeps each traced computation
serialized with ``jax.export``; a later process deserializes it and calls it, untraced.
The results are those of ``eqx.filter_jit`` to the bit (the same computation, compiled by
the same XLA).

An entry holds the compiled executable too (``jax.experimental.serialize_executable``), so
a warm process neither traces nor lowers the kernel, nor hashes its module for JAX's cache:
it loads the machine code (``jax.jit(exported.call)`` lowered the exported module again in
every process, 0.3 s a kernel). Executables are keyed by this machine's processor too (its
instruction set flags); an entry whose executable cannot be loaded here is called through
its exported computation instead. A computation that calls LAPACK (``jnp.linalg`` on the
CPU) readies JAX's LAPACK kernels before its executable is loaded, as lowering it would
(without that the loaded executable would call uninitialized kernels). An executable that
JAX's compilation cache answered with cannot be stored, so a kernel's computation is
compiled without that cache when its entry is made (see :func:`_compile`): after a change
of the code that leaves the computation as it was, the first process compiles it once
more, and the later ones load it (they lowered it again, each of them, before).

An entry is keyed by the function's qualified name, a digest of the cassi_fit package's
source files (any change of the code invalidates every entry), the versions of JAX and of
the libraries the kernels trace through, the platform, the JAX settings that change a
trace (float64, the promotion rules, the matmul precision), the non-array arguments
(pickled) and the arrays' shapes, dtypes and places in the arguments. It is looked up in
this process, then on disk, and only then traced. (A kernel's code changed while a process
runs, as a test's monkeypatch changes it, is not seen: turn the folder off there.)

The folder, first match wins:

1. ``CASSI_EXPORT_CACHE=DIR`` (``off``, ``0``, ``none`` or empty: no exported kernels,
   every kernel traced as by ``eqx.filter_jit``);
2. ``exported/`` in JAX's compilation cache folder when that cache is on (the command line
   and the corpus workers turn it on: ``CASSI_COMPILE_CACHE``; ``--no-compile-cache``
   turns both off);
3. none: every kernel traced as by ``eqx.filter_jit``.

A file is written whole or not at all (a temporary file renamed into place); a file that
cannot be read, or is not a complete entry, is traced again and replaced; a folder that
cannot be created or written leaves the kernels traced in every process, never an error.
The folder is held under :data:`EXPORT_CACHE_MAX_BYTES`, the least recently used entries
removed first. Entries are pickles, trusted as JAX trusts the executables of its own
cache folder beside them.

A kernel called inside another transformation (``jax.grad``, ``jax.vmap``, an enclosing
``jit``: its arguments are tracers) is traced as by ``eqx.filter_jit``: an exported
computation carries no derivative here.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .options import CACHE_OFF

#: The environment variable naming the exported kernels' folder (or ``off``).
EXPORT_CACHE_ENV = "CASSI_EXPORT_CACHE"
#: The folder's size limit: past it the least recently used entries are removed. An entry
#: is 0.01-1 MB (one kernel at one set of shapes).
EXPORT_CACHE_MAX_BYTES = 256 * 1024**2
#: The subfolder of JAX's compilation cache folder that holds the exported kernels.
SUBFOLDER = "exported"
#: The file name ending of an entry.
SUFFIX = ".exported"
#: Changes when an entry's content changes form.
_FORMAT = 2
#: The libraries whose code a kernel's tracing runs through (their versions are keyed).
_TRACED_LIBRARIES = ("jax", "jaxlib", "equinox", "optimistix", "lineax", "jaxopt")
#: The JAX settings that change what a trace makes, or whether it fails (keyed).
_TRACE_SETTINGS = ("jax_enable_x64", "jax_numpy_rank_promotion", "jax_numpy_dtype_promotion",
                   "jax_default_matmul_precision")


def _settings() -> tuple[str, ...]:
    import jax

    return tuple(str(getattr(jax.config, name)) for name in _TRACE_SETTINGS)


def export_folder() -> Path | None:
    """The folder of the exported kernels for this process now, or None (none: every
    kernel traced); see the module's doc for the order."""
    chosen = os.environ.get(EXPORT_CACHE_ENV)
    if chosen is not None:
        if chosen.strip().lower() in CACHE_OFF:
            return None
        return Path(chosen).expanduser().absolute()
    import jax

    base = jax.config.jax_compilation_cache_dir
    if not base or not jax.config.jax_enable_compilation_cache or "://" in str(base):
        return None
    return Path(base).expanduser().absolute() / SUBFOLDER


@functools.cache
def _serializable() -> bool:
    """Whether ``jax.export`` can serialize here (it needs the ``flatbuffers`` package, a
    dependency of the toolkit; without it every kernel is traced)."""
    import importlib.util

    return importlib.util.find_spec("flatbuffers") is not None


@functools.cache
def _fingerprint() -> bytes:
    """What every key of this process shares: the package's source files and the traced
    libraries' versions (computed once)."""
    from importlib import metadata

    h = hashlib.sha256(f"format {_FORMAT}\n".encode())
    package = Path(__file__).resolve().parent
    for path in sorted(package.rglob("*.py")):
        h.update(path.relative_to(package).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    for name in _TRACED_LIBRARIES:
        try:
            version = metadata.version(name)
        except metadata.PackageNotFoundError:
            version = "-"
        h.update(f"{name} {version}\n".encode())
    h.update(_processor().encode())
    return h.digest()


def _processor() -> str:
    """This machine's processor as its executables depend on it: the architecture and the
    instruction set flags (Linux's ``/proc/cpuinfo``; elsewhere the platform's name).
    ``platform.processor()`` runs ``uname -p`` in a new process on Linux (milliseconds of
    every command that loads a kernel): it is asked only where there are no flags."""
    import platform

    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith(("flags", "Features", "isa")):
                    return f"{platform.machine()} {line.split(':', 1)[-1].strip()}"
    except OSError:
        pass
    return f"{platform.machine()} {platform.processor()}"


class _Slot:
    """The place of the ``index``-th array among a kernel's outputs (in a stored skeleton
    of the outputs; everything else in the skeleton is the outputs' static part)."""

    __slots__ = ("index",)

    def __init__(self, index: int):
        self.index = index

    def __reduce__(self):
        return (_Slot, (self.index,))


class _Entry:
    """One exported computation, ready to call: ``(arrays) -> outputs``. ``call`` is its
    compiled executable (loaded, or compiled by this process), else ``jax.jit`` of the
    exported computation."""

    def __init__(self, call, skeleton):
        import jax

        self.call = call
        self.device = jax.devices()[0]
        self.leaves, self.treedef = jax.tree.flatten(skeleton)

    def __call__(self, arrays):
        import jax

        # every input committed to the one device: jit compiles a computation again for
        # each mix of committed arrays (a kernel's own outputs, fed back: the calibration's
        # next stage) and uncommitted ones (made by jnp), although it is the same
        # computation; that was a second 18 s compilation of the calibration's solver
        outs = self.call(*jax.device_put(list(arrays), self.device))
        return self.treedef.unflatten(
            [outs[leaf.index] if isinstance(leaf, _Slot) else leaf for leaf in self.leaves])


def _compile(exported, avals):
    """``(compiled, serialized executable or None)``: the exported computation compiled for
    the one device. An executable JAX's compilation cache answered with cannot be stored
    (XLA's CPU client serializes such an executable without its machine code: loaded
    again, it fails to find its functions), and the cache holds the computation whenever
    a change of the code left it as it was: so one that will be stored is compiled
    without the cache (:func:`_without_compilation_cache`; once, after such a change),
    and every later process loads it instead of lowering it again. An entry whose
    executable another process could not load (:func:`_executable_is_portable`), or one
    the cache answered for all the same, is called through its exported computation."""
    import jax

    specs = [jax.ShapeDtypeStruct(s, d, weak_type=w) for s, d, w in avals]
    portable = _executable_is_portable(exported)
    hits = []

    def listen(event, **kwargs):
        if event == "/jax/compilation_cache/cache_hits":
            hits.append(event)

    jax.monitoring.register_event_listener(listen)
    try:
        with _without_compilation_cache() if portable else contextlib.nullcontext():
            compiled = jax.jit(exported.call).lower(*specs).compile()
    finally:
        jax.monitoring.unregister_event_listener(listen)
    if hits or not portable:
        return compiled, None
    try:
        from jax.experimental import serialize_executable

        return compiled, serialize_executable.serialize(compiled)
    except Exception:  # a backend that cannot serialize executables: the exported form
        return compiled, None


@contextlib.contextmanager
def _without_compilation_cache():
    """JAX's persistent compilation cache neither read nor written by the compilations
    within (JAX's own switch, ``jax_enable_compilation_cache``, is read once a process).
    JAX's internals: where they are not as expected, the cache stays on (and an executable
    it answers with is not stored, :func:`_compile`)."""
    import jax

    try:
        from jax._src import compilation_cache as cache

        cache.is_cache_used(jax.devices()[0].client)  # settled now, restored after
        before = cache._cache_checked, cache._cache_used
    except Exception:
        yield
        return
    cache._cache_checked, cache._cache_used = True, False
    try:
        yield
    finally:
        cache._cache_checked, cache._cache_used = before


def _custom_calls(exported) -> set[str]:
    """The targets of the computation's custom calls (``lapack_dgetrf_ffi``, ...)."""
    import re

    text = exported.mlir_module()
    return set(re.findall(r'custom_call @(\w+)', text)) | set(
        re.findall(r'call_target_name = "([^"]+)"', text))


def _calls_lapack(exported) -> bool:
    """Whether the computation calls JAX's LAPACK kernels (custom calls ``lapack_...``)."""
    return any(t.startswith("lapack_") for t in _custom_calls(exported))


def _executable_is_portable(exported) -> bool:
    """Whether a stored executable of the computation can be loaded by another process: its
    custom calls are LAPACK's alone, whose kernels :func:`_load` readies. Any other (a host
    callback holds a pointer into the process that compiled it; an FFT's kernels are
    registered elsewhere) keeps the exported computation only."""
    return all(t.startswith("lapack_") for t in _custom_calls(exported))


#: The modules whose C functions JAX's LAPACK kernels call (jaxlib imports them by name).
_LAPACK_MODULES = ("scipy.linalg.cython_blas", "scipy.linalg.cython_lapack")


def _lapack_modules() -> None:
    """Import SciPy's BLAS and LAPACK function tables (:data:`_LAPACK_MODULES`) without
    the ``scipy.linalg`` package around them, for :func:`_initialize_lapack`.

    jaxlib finds its LAPACK kernels' functions by importing these two compiled modules
    (their ``__pyx_capi__``), and importing a submodule runs its package first:
    ``scipy.linalg``'s Python API (and, through ``scipy._lib``, ``numpy.f2py``), 0.2-0.4 s
    of a warm ``cassi jaw`` that uses none of it. The two modules import nothing of
    ``scipy.linalg``, so they are loaded from their files under their own names; a later
    ``import scipy.linalg`` runs the package as ever and finds them in ``sys.modules``.
    Anything unexpected (no SciPy file found, the package already imported) leaves the
    ordinary import to jaxlib."""
    import importlib.machinery
    import importlib.util
    import sys

    if "scipy.linalg" in sys.modules or all(m in sys.modules for m in _LAPACK_MODULES):
        return
    scipy = importlib.util.find_spec("scipy")
    if scipy is None or not scipy.submodule_search_locations:
        return
    folders = [os.path.join(p, "linalg") for p in scipy.submodule_search_locations]
    specs = [importlib.machinery.PathFinder.find_spec(name, folders)
             for name in _LAPACK_MODULES]
    if any(s is None or not isinstance(s.loader, importlib.machinery.ExtensionFileLoader)
           for s in specs):
        return
    for name, spec in zip(_LAPACK_MODULES, specs, strict=True):
        if name in sys.modules:
            continue
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise


def _initialize_lapack() -> None:
    """Ready JAX's LAPACK kernels as lowering a LAPACK call does (jaxlib's
    ``initialize_lapack``), SciPy's function tables found by :func:`_lapack_modules`."""
    from jax._src.lax.linalg import initialize_lapack

    try:
        _lapack_modules()
    except Exception:  # jaxlib's own import then (and the error, if any, is its)
        pass
    initialize_lapack()


def _load(executable, lapack: bool):
    """The stored executable loaded on this process's one device, or None."""
    import jax
    from jax.experimental import serialize_executable

    if lapack:  # as lowering a LAPACK call does: its kernels' BLAS/LAPACK functions found
        _initialize_lapack()
    payload, in_tree, out_tree = executable
    device = jax.devices()[0]
    return serialize_executable.deserialize_and_load(
        payload, in_tree, out_tree, backend=device.client, execution_devices=[device])


def _value_pickle(obj) -> bytes:
    """``obj`` pickled by its values alone, the same bytes in every process: pickle's memo
    writes an object met twice as a reference to the first, so two equal structures whose
    equal strings are one object in one process (the model's dict keys) and two in another
    (a corpus worker's unpickled run spec) would give two digests, and the worker would
    trace again what the folder holds. Without the memo (``Pickler.fast``) every object is
    written in full; a structure that refers to itself cannot be, and keeps the plain
    pickle (its digest is then this process's only)."""
    import io

    buffer = io.BytesIO()
    pickler = pickle.Pickler(buffer, protocol=4)
    pickler.fast = True
    try:
        pickler.dump(obj)
    except (RecursionError, ValueError):
        return pickle.dumps(obj, protocol=4)
    return buffer.getvalue()


class Exported:
    """A kernel wrapped by :func:`exported`. ``traces`` and ``loads`` count, in this
    process, the computations traced and those loaded from the folder; ``jitted`` is the
    kernel under ``eqx.filter_jit`` (what runs when there is no folder)."""

    def __init__(self, fn: Callable):
        import equinox as eqx

        functools.update_wrapper(self, fn)
        self.fn = fn
        self.jitted = eqx.filter_jit(fn)
        self.name = f"{fn.__module__}.{fn.__qualname__}"
        self.traces = 0
        self.loads = 0
        self._entries: dict[Any, _Entry | None] = {}

    def __call__(self, *args, **kwargs):
        import equinox as eqx
        import jax

        folder = export_folder()
        if folder is None or not _serializable():
            return self.jitted(*args, **kwargs)
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        arrays, in_tree = jax.tree.flatten(dynamic)
        if any(isinstance(a, jax.core.Tracer) for a in arrays):
            return self.jitted(*args, **kwargs)
        avals = tuple((np.shape(a), jax.dtypes.canonicalize_dtype(a.dtype),
                       bool(getattr(a, "weak_type", False))) for a in arrays)
        static_leaves, static_tree = jax.tree.flatten(static)
        key = (in_tree, avals, static_tree, tuple(static_leaves), _settings())
        try:
            entry = self._entries[key]
        except KeyError:
            entry = self._entries[key] = self._entry(folder, in_tree, avals, static)
        except TypeError:  # an unhashable static argument: eqx.filter_jit says so
            return self.jitted(*args, **kwargs)
        if entry is None:  # this computation cannot be exported: traced as always
            return self.jitted(*args, **kwargs)
        return entry(arrays)

    def _entry(self, folder: Path, in_tree, avals, static) -> _Entry | None:
        """The computation at these arguments: from the folder, else traced (and stored);
        None if it cannot be exported."""
        try:
            digest = self._digest(in_tree, avals, static)
        except (pickle.PicklingError, TypeError, AttributeError):
            return None  # a static argument that does not pickle: no stable key
        path = folder / f"{self.fn.__qualname__}-{digest}{SUFFIX}"
        entry = _read(path, digest)
        if entry is not None:
            self.loads += 1
            return entry
        try:
            exported, skeleton = self._trace(in_tree, avals, static)
            compiled, executable = _compile(exported, avals)
        except Exception:  # eqx.filter_jit then traces it (and raises what it raises)
            return None
        self.traces += 1
        _write(path, digest, exported, skeleton, executable)
        return _Entry(compiled, skeleton)

    def _digest(self, in_tree, avals, static) -> str:
        import jax

        skeleton = jax.tree.unflatten(in_tree, [_Slot(i) for i in range(in_tree.num_leaves)])
        spec = (self.name, jax.default_backend(), _settings(),
                [(tuple(s), str(d), bool(w)) for s, d, w in avals], skeleton, static)
        h = hashlib.sha256(_fingerprint())
        h.update(_value_pickle(spec))
        return h.hexdigest()[:40]

    def _trace(self, in_tree, avals, static):
        """``(jax.export.Exported, skeleton of the outputs)``: the kernel traced at these
        arguments, its outputs flattened (an exported computation takes and returns
        standard pytrees only)."""
        import equinox as eqx
        import jax
        from jax import export

        out = {}

        def flat(*arrays):
            args, kwargs = eqx.combine(jax.tree.unflatten(in_tree, arrays), static)
            leaves, tree = jax.tree.flatten(self.fn(*args, **kwargs))
            slots, outs = [], []
            for leaf in leaves:
                if eqx.is_array(leaf):
                    slots.append(_Slot(len(outs)))
                    outs.append(leaf)
                else:
                    slots.append(leaf)
            out["skeleton"] = jax.tree.unflatten(tree, slots)
            return tuple(outs)

        specs = [jax.ShapeDtypeStruct(s, d, weak_type=w) for s, d, w in avals]
        # the entry is read only by this JAX (its version is keyed): custom calls without
        # a compatibility guarantee (LAPACK's) are safe here
        exported = export.export(jax.jit(flat), disabled_checks=[
            export.DisabledSafetyCheck.custom_call("ALL")])(*specs)
        return exported, out["skeleton"]


def exported(fn: Callable) -> Exported:
    """Decorate a module-level kernel: ``eqx.filter_jit`` that a new process loads from
    the folder of exported kernels instead of tracing again (see the module's doc)."""
    return Exported(fn)


def _read(path: Path, digest: str) -> _Entry | None:
    """The entry stored at ``path``, or None (absent, unreadable or not an entry)."""
    from jax import export

    try:
        with open(path, "rb") as fh:
            form, stored, skeleton, blob, executable, lapack = pickle.load(fh)
        if form != _FORMAT or stored != digest:
            return None
        call = None
        if executable is not None:
            try:
                call = _load(executable, lapack)
            except Exception:  # not loadable here: the exported computation, compiled
                call = None
        if call is None:
            import jax

            call = jax.jit(export.deserialize(bytearray(blob)).call)
        entry = _Entry(call, skeleton)
    except Exception:  # a broken entry is traced again and replaced
        return None
    try:
        os.utime(path)  # its last use, for the size limit
    except OSError:
        pass
    return entry


def _write(path: Path, digest: str, exported, skeleton, executable) -> None:
    """Store an entry (whole or not at all); a folder that cannot be written is left."""
    from ._io import atomic_write
    from .errors import CassiError

    try:
        content = pickle.dumps((_FORMAT, digest, skeleton, exported.serialize(), executable,
                                _calls_lapack(exported)), protocol=4)
    except Exception:  # an output that does not pickle, a computation JAX cannot serialize
        return
    try:
        atomic_write(path, content, overwrite=True)
    except (OSError, CassiError):
        return
    _evict(path.parent, EXPORT_CACHE_MAX_BYTES, keep=path)


def _evict(folder: Path, max_bytes: int, keep: Path) -> None:
    """Remove the least recently used entries of ``folder`` but ``keep`` until it holds
    ``max_bytes`` at most (another process removing the same ones at once is harmless)."""
    entries = []
    try:
        for path in folder.glob(f"*{SUFFIX}"):
            if path.name.startswith("."):  # another process's temporary file
                continue
            try:
                st = path.stat()
            except OSError:
                continue
            entries.append((st.st_mtime, st.st_size, path))
    except OSError:
        return
    total = sum(size for _, size, _ in entries)
    for _, size, path in sorted(entries, key=lambda e: e[0]):
        if total <= max_bytes:
            break
        if path == keep:
            continue
        try:
            path.unlink()
        except OSError:
            pass
        total -= size
