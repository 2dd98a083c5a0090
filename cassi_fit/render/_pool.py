"""Frames drawn by several processes at once (issue 30): :class:`FramePool`.

``jobs`` drawing processes: this one and ``jobs - 1`` 'spawn' workers, each with its own
:class:`~cassi_fit.render.Renderer` (its own OpenGL context) of the same model, size,
views and traces. The frames are handed out in batches of consecutive frames (each
batch drawn pipelined, ``Renderer.render_frames``) and come back in the order they were
asked for, so a video is encoded exactly as the serial loop would encode it, byte for
byte (each frame depends only on its vertices and keywords, not on the frames drawn
before it).

A worker's start-up (a fresh interpreter importing pyrender, OpenGL, Pillow; over a
second of CPU) is hidden twice over: the workers are started, and import, when the pool
is made, before the model is known (``FramePool(jobs=N)``, then :meth:`FramePool.set_model`;
``cassi animate --jobs N`` makes its pool before fitting and animating), and this
process draws the first batches itself until a worker is ready, then goes on drawing
its share. Mesa's llvmpipe draws with threads of its own, one per core by default:
each worker gets its share of the cores (``LP_NUM_THREADS``), as corpus workers get
their share of BLAS and XLA threads. A worker imports neither JAX nor the face model's
code: it is sent the model's arrays (:func:`model_arrays`).
"""

from __future__ import annotations

import itertools
import os
import pickle
import threading
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from itertools import islice
from types import SimpleNamespace
from typing import Any

import numpy as np

#: Batches asked of each worker ahead of the one the caller waits for.
AHEAD = 2
#: Consecutive frames in a batch: drawn pipelined by one process, sent back at once.
BATCH = 12

_RENDERER: tuple | None = None  # the worker's (setup key, Renderer), made on first use
_KEYS = itertools.count()  # set_model's keys (with the process id: unique among pools)


def draw_threads(jobs: int, cores: int | None = None) -> int:
    """llvmpipe threads for each of ``jobs`` drawing processes: their share of ``cores``
    (default: the cores this process may use), at least 1."""
    if cores is None:
        try:
            cores = len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            cores = os.cpu_count() or 1
    return max(int(cores) // max(int(jobs), 1), 1)


def model_arrays(model: Any) -> SimpleNamespace:
    """What a Renderer reads of ``model`` (``render.MeshModel``), as numpy arrays and
    plain dicts: cheap to send to a worker, which then needs no JAX."""

    def plain(value):
        if isinstance(value, Mapping):
            return {k: plain(v) for k, v in value.items()}
        if hasattr(value, "shape") and not isinstance(value, np.ndarray):
            return np.asarray(value)
        return value

    out = SimpleNamespace(vertices=np.asarray(model.vertices), faces=np.asarray(model.faces),
                          face_material=np.asarray(model.face_material))
    for name in ("fields", "regions", "landmarks", "measures"):
        value = getattr(model, name, None)
        if value is not None:
            setattr(out, name, plain(value))
    return out


def _start(threads: int) -> None:
    """A worker's start: its share of the cores for llvmpipe (read when Mesa makes the
    context), Ctrl-C left to the parent (which stops the pool)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ["LP_NUM_THREADS"] = str(threads)


def _warm_up() -> int:
    """A worker's first task, given when the pool is made: import what drawing needs
    (pyrender, OpenGL, the renderer's modules) while the caller does other work."""
    from ._gl import ensure_headless_gl

    ensure_headless_gl()  # the parent's choice, inherited in PYOPENGL_PLATFORM
    import pyrender  # noqa: F401

    from . import _draw, _scene  # noqa: F401

    return os.getpid()


def _draw_batch(key: tuple, setup: bytes, batch: list) -> list[np.ndarray]:
    """A batch of frames in a worker (``Renderer.render_frames(batch)``); ``setup``: the
    pickled (model arrays, Renderer keywords), read when ``key`` is new here."""
    global _RENDERER
    if _RENDERER is None or _RENDERER[0] != key:
        from ._scene import Renderer

        if _RENDERER is not None:
            _RENDERER[1].close()
            _RENDERER = None
        model, options = pickle.loads(setup)
        _RENDERER = (key, Renderer(model, **options))
    return list(_RENDERER[1].render_frames(batch))


class FramePool:
    """``jobs`` drawing processes (this one and ``jobs - 1`` workers) drawing frames of
    ``model`` with ``Renderer(model, **options)`` each; :meth:`draw` yields the frames in
    order. ``model`` may be given later (:meth:`set_model`): the workers start, and
    import, meanwhile. ``threads``: llvmpipe threads per worker (default
    :func:`draw_threads`; ``LP_NUM_THREADS`` in the environment is respected); this
    process keeps its own. Use as a context manager, or :meth:`close` it; an error in a
    worker (no OpenGL, bad vertices) is raised by :meth:`draw` as the serial loop would
    raise it."""

    def __init__(self, model: Any = None, *, jobs: int, threads: int | None = None,
                 **options: Any) -> None:
        if int(jobs) < 1:
            raise ValueError(f"jobs must be at least 1, got {jobs}")
        self.jobs = int(jobs)
        self.threads = int(os.environ.get("LP_NUM_THREADS") or threads
                           or draw_threads(self.jobs))
        self._pool = self._local = None
        self._warm: list = []
        self._setup: tuple | None = None
        self._error: BaseException | None = None
        # the platform's probe and the workers' spawning off this thread: the caller
        # goes on (cassi animate: fitting, animating) while they start
        self._starting = threading.Thread(target=self._open, name="cassi-frame-pool",
                                          daemon=True)
        self._starting.start()
        if model is not None:
            self.set_model(model, **options)

    @property
    def views(self) -> tuple[str, ...]:
        """The views drawn (``Renderer``'s ``views`` keyword; empty before a model)."""
        views = (self._setup or (None, {}))[1].get("views", ())
        return (views,) if isinstance(views, str) else tuple(views)

    def _open(self) -> None:
        try:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            from ._gl import ensure_headless_gl

            ensure_headless_gl(imports=False)  # the workers inherit PYOPENGL_PLATFORM
            if self.jobs > 1:
                # concurrent.futures, not multiprocessing.Pool: a worker that dies (a
                # crash in the OpenGL driver) is an error here, not a frame waited for
                self._pool = ProcessPoolExecutor(
                    self.jobs - 1, mp_context=multiprocessing.get_context("spawn"),
                    initializer=_start, initargs=(self.threads,))
                self._warm = [self._pool.submit(_warm_up) for _ in range(self.jobs - 1)]
        except BaseException as exc:  # noqa: BLE001 -- raised by draw()
            self._error = exc

    def set_model(self, model: Any, **options: Any) -> None:
        """The model and ``Renderer`` keywords of the frames :meth:`draw` will draw."""
        data = (model_arrays(model), dict(options))
        key = (os.getpid(), next(_KEYS))
        self._setup = (key, dict(options), model, pickle.dumps(data))
        if self._local is not None:
            self._local.close()
            self._local = None

    def _ready(self) -> int:
        """Workers that have started (their imports done)."""
        return sum(f.done() for f in self._warm)

    def _renderer(self):
        """This process's Renderer, made on first use."""
        if self._local is None:
            from ._scene import Renderer

            _, options, model, _ = self._setup
            self._local = Renderer(model, **options)
        return self._local

    def draw(self, work: Iterable[tuple[np.ndarray, dict[str, Any]]]
             ) -> Iterator[np.ndarray]:
        """The frames of ``work`` (``(vertices, Renderer.render keywords)`` each), drawn
        in batches of :data:`BATCH` by this process and the workers that have started
        (at most :data:`AHEAD` batches each in flight), in order."""
        if self._setup is None:
            raise ValueError("FramePool.draw: no model (set_model)")
        self._starting.join()
        if self._error is not None:
            raise self._error
        key, _, _, setup = self._setup
        batches = ((np.asarray(p), kw) for p, kw in work)
        queue: deque = deque()  # each a worker's future, or a batch drawn here, in order
        exhausted = False

        def take() -> list | None:
            nonlocal exhausted
            batch = None if exhausted else list(islice(batches, BATCH))
            exhausted = exhausted or not batch
            return batch or None

        try:
            while True:
                remote = sum(not isinstance(q, list) for q in queue)
                if self._pool is not None and remote < AHEAD * self._ready():
                    batch = take()
                    if batch is not None:
                        queue.append(self._pool.submit(_draw_batch, key, setup, batch))
                        continue
                if not queue:
                    batch = take()
                    if batch is None:
                        return
                    yield from self._renderer().render_frames(batch)  # streamed
                    continue
                head = queue[0]
                if isinstance(head, list) or head.done():
                    queue.popleft()
                    yield from head if isinstance(head, list) else head.result()
                    continue
                # a worker's batch first: draw the next one here meanwhile (one ahead)
                if not any(isinstance(q, list) for q in queue):
                    batch = take()
                    if batch is not None:
                        queue.append(list(self._renderer().render_frames(batch)))
                        continue
                yield from queue.popleft().result()
        finally:
            for future in queue:
                if not isinstance(future, list):
                    future.cancel()

    def close(self) -> None:
        """Stop the workers and release this process's renderer (idempotent)."""
        starting = getattr(self, "_starting", None)
        if starting is not None:
            starting.join()
        pool, self._pool = getattr(self, "_pool", None), None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        local, self._local = getattr(self, "_local", None), None
        if local is not None:
            local.close()

    def __enter__(self) -> FramePool:
        return self

    def __exit__(self, *exc: object) -> bool:
        self.close()
        return False
