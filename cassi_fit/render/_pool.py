"""Frames drawn by several processes at once (issue 30): :class:`FramePool`.

Each worker is a 'spawn' process with its own :class:`~cassi_fit.render.Renderer` (its
own OpenGL context) of the same model, size, views and traces; the frames come back in
the order they were asked for, so a video is encoded exactly as the serial loop would
encode it, byte for byte (each frame depends only on its vertices and keywords, not on
the frames drawn before it). Mesa's llvmpipe draws with threads of its own, one per core
by default: each worker gets its share of the cores (``LP_NUM_THREADS``), as corpus
workers get their share of BLAS and XLA threads, so ``jobs`` workers do not fight over
the cores. A worker imports neither JAX nor the face model's code: it is sent the
model's arrays (:func:`model_arrays`).
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from types import SimpleNamespace
from typing import Any

import numpy as np

#: Frames asked of each worker ahead of the one the caller waits for.
AHEAD = 3

_RENDERER = None  # the worker's Renderer, made on its first frame
_SETUP: tuple | None = None  # (model arrays, Renderer keywords), set by _start


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


def _start(setup: tuple, threads: int) -> None:
    """A worker's start: its share of the cores for llvmpipe (read when Mesa makes the
    context, on the first frame), Ctrl-C left to the parent (which stops the pool)."""
    import signal

    global _SETUP
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ["LP_NUM_THREADS"] = str(threads)
    _SETUP = setup


def _draw(points: np.ndarray, kwargs: dict[str, Any]) -> np.ndarray:
    """One frame in a worker (``Renderer.render(points, **kwargs)``)."""
    global _RENDERER
    if _RENDERER is None:
        from ._scene import Renderer

        model, options = _SETUP
        _RENDERER = Renderer(model, **options)
    return _RENDERER.render(points, **kwargs)


class FramePool:
    """``jobs`` worker processes drawing frames of ``model`` with ``Renderer(model,
    **options)`` each; :meth:`draw` yields the frames in order. ``threads``: llvmpipe
    threads per worker (default :func:`draw_threads`). Use as a context manager, or
    :meth:`close` it; an error in a worker (no OpenGL, bad vertices) is raised by
    :meth:`draw` as the serial loop would raise it. ``LP_NUM_THREADS`` in the
    environment is respected."""

    def __init__(self, model: Any, *, jobs: int, threads: int | None = None,
                 **options: Any) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        from ._gl import ensure_headless_gl

        if int(jobs) < 1:
            raise ValueError(f"jobs must be at least 1, got {jobs}")
        ensure_headless_gl()  # once here: the workers inherit PYOPENGL_PLATFORM
        self.jobs = int(jobs)
        self.views = tuple(options.get("views", ()))
        if isinstance(options.get("views"), str):
            self.views = (options["views"],)
        threads = int(os.environ.get("LP_NUM_THREADS") or threads or draw_threads(self.jobs))
        self.threads = threads
        # concurrent.futures, not multiprocessing.Pool: a worker that dies (a crash in
        # the OpenGL driver) is an error here, not a frame waited for forever
        self._pool = ProcessPoolExecutor(
            self.jobs, mp_context=multiprocessing.get_context("spawn"), initializer=_start,
            initargs=((model_arrays(model), dict(options)), threads))

    def draw(self, work: Iterable[tuple[np.ndarray, dict[str, Any]]]
             ) -> Iterator[np.ndarray]:
        """The frames of ``work`` (``(vertices, Renderer.render keywords)`` each), drawn
        by the workers, in order; at most ``AHEAD`` frames per worker in flight."""
        pending: deque = deque()
        for points, kwargs in work:
            if len(pending) >= AHEAD * self.jobs:
                yield pending.popleft().result()
            pending.append(self._pool.submit(_draw, np.asarray(points), kwargs))
        while pending:
            yield pending.popleft().result()

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        pool, self._pool = getattr(self, "_pool", None), None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> FramePool:
        return self

    def __exit__(self, *exc: object) -> bool:
        self.close()
        return False
