"""Ctrl-C and SIGTERM in the toolkit's commands and pool workers: an interrupt ends a
command as ``KeyboardInterrupt`` where that is safe, so that every writer's clean-up runs
(temporaries removed, ffmpeg killed, the OpenGL context released), and the command prints
one line and exits with :data:`INTERRUPT_EXIT_STATUS`.

The commands use :func:`interruptible` (the ``cassi`` program) and
:func:`exit_on_signal`; the corpus pool uses :func:`worker_signals`, :func:`in_task`,
:func:`signals_blocked`; a writer's steps that must not stop half-way use
:func:`defer_interrupts`.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

# Ctrl-C (SIGINT) and SIGTERM end a command as an exception, KeyboardInterrupt, so that
# every writer's clean-up runs (``except BaseException``: temporaries removed, ffmpeg
# killed, the OpenGL context released) and the command prints one line. Python's own
# handler raises it wherever the main thread happens to be, which goes wrong in three
# places, all met in practice:
#
# * inside the initialisation of an extension module (JAX's jaxlib, while ``import jax``
#   runs): the extension fails half-built and the process aborts ("terminate called after
#   throwing an instance of 'nanobind::python_error'") or raises ImportError;
# * inside a garbage-collection callback or a ``__del__`` (JAX's ``_xla_gc_callback`` runs
#   at every collection, and collections are frequent while JAX traces): Python prints
#   "Exception ignored in ..." with a traceback and drops the interrupt, so the command
#   runs on to the end;
# * after the command, while the interpreter shuts down with JAX's and Mesa's threads
#   still running: a segmentation fault.
#
# So here the handler defers the interrupt while an extension module initialises or JAX
# writes a compilation cache entry (stopped half-way, it breaks the folder for every later
# process: cassi_fit.corpus._process), and in explicit ``defer_interrupts()`` blocks, re-delivers one that a callback swallowed
# (``sys.unraisablehook``), both through a 20 ms timer (SIGALRM), and leaves the clean-up
# of the first interrupt undisturbed by further signals (a third one ends the process at
# once). A command run as a program (``cli.main()``) ends with ``os._exit`` after its
# clean-up, so that no interpreter shutdown runs after an interrupt.

INTERRUPT_EXIT_STATUS = 130
"""The exit status of an interrupted command (128 + SIGINT, whichever signal it was)."""

_RETRY_S = 0.02  # seconds before a deferred or swallowed interrupt is delivered again
_EXTENSION_INIT = frozenset({"ExtensionFileLoader.create_module",
                             "ExtensionFileLoader.exec_module"})
#: Where an interrupt also waits: JAX writing a compilation cache entry and its last-use
#: file (``jax._src.lru_cache``); stopped between the two, the folder is left with an
#: entry that breaks every later write of the size-limited cache.
_NO_INTERRUPT = _EXTENSION_INIT | {"LRUCache.put", "LRUCache.get"}


class _Interrupts:
    """The process's interrupt state (signal handlers run in the main thread only)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.raised = False  # a KeyboardInterrupt is unwinding: its clean-up runs
        self.pending: int | None = None  # a signal not delivered yet
        self.last = 2  # the signal last raised as KeyboardInterrupt (SIGINT)
        self.deferred = 0  # depth of defer_interrupts() blocks
        self.signals = 0  # signals received since the handlers were installed
        self.worker = False  # a pool worker: SIGTERM between tasks ends it quietly
        self.in_task = False


_STATE = _Interrupts()


def _in_extension_init(frame: Any) -> bool:
    """Whether ``frame`` (or a caller) is no place for an interrupt: an extension module
    initialising, or JAX writing a cache entry."""
    while frame is not None:
        if getattr(frame.f_code, "co_qualname", "") in _NO_INTERRUPT:
            return True
        frame = frame.f_back
    return False


def _flush_and_exit(status: int, line: str | None = "cassi: interrupted") -> None:
    """End the process now: ``line`` on stderr, the standard streams flushed, no
    interpreter shutdown (``os._exit``)."""
    import sys

    if "multiprocessing.resource_tracker" in sys.modules:
        import gc

        gc.collect()  # a finished pool's semaphores released: no "leaked" warning at exit
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    if line:
        try:
            os.write(2, (line + "\n").encode())
        except OSError:
            pass
    os._exit(status)


def _deliver_later() -> None:
    import signal

    signal.setitimer(signal.ITIMER_REAL, _RETRY_S)


def _on_signal(signum: int, frame: Any) -> None:
    state = _STATE
    state.signals += 1
    if state.raised:  # the first interrupt's clean-up is running: leave it be
        if state.signals >= 3:
            _flush_and_exit(INTERRUPT_EXIT_STATUS)
        return
    if state.worker and not state.in_task:  # a pool worker between tasks: just end
        _flush_and_exit(128 + signum, None)
    state.pending = signum
    _deliver(frame)


def _deliver(frame: Any) -> None:
    """Raise the pending interrupt here, unless this is no place for it (then later)."""
    state = _STATE
    if state.pending is None or state.raised:
        return
    if state.deferred:
        return  # raised when the outermost defer_interrupts() block ends
    if _in_extension_init(frame):
        _deliver_later()
        return
    signum, state.pending, state.raised, state.last = state.pending, None, True, state.pending
    raise KeyboardInterrupt(f"signal {signum}")


def _on_retry(signum: int, frame: Any) -> None:
    _deliver(frame)


def _on_unraisable(hook: Any) -> None:
    """A KeyboardInterrupt that a callback or ``__del__`` swallowed: delivered again."""
    if isinstance(hook.exc_value, KeyboardInterrupt) and _STATE.raised:
        _STATE.raised = False
        _STATE.pending = _STATE.last
        _deliver_later()
        return
    _PREVIOUS_HOOK[-1](hook)


_PREVIOUS_HOOK: list = []


@contextmanager
def defer_interrupts() -> Iterator[None]:
    """Within the block, an interrupt (SIGINT, SIGTERM) waits until the block ends: for
    short steps that must not stop half-way (moving a group of outputs into place,
    releasing an OpenGL context). Only under :func:`interruptible` (elsewhere a plain
    block)."""
    _STATE.deferred += 1
    try:
        yield
    finally:
        _STATE.deferred -= 1
    if not _STATE.deferred and _STATE.pending is not None:
        import sys

        _deliver(sys._getframe())


@contextmanager
def interruptible() -> Iterator[None]:
    """Within the block (a command's main function, in the main thread), SIGINT and
    SIGTERM raise ``KeyboardInterrupt`` where it is safe to (see the comment above), so
    that the writers' clean-up runs and no temporary file stays. Outside the main thread
    it does nothing (Python delivers signals there only). The previous handlers are
    restored when the block ends; a signal the process was started to ignore stays
    ignored."""
    import signal
    import sys
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    previous_alarm = signal.getsignal(signal.SIGALRM)
    _STATE.reset()
    _PREVIOUS_HOOK.append(sys.unraisablehook)
    sys.unraisablehook = _on_unraisable
    signal.signal(signal.SIGALRM, _on_retry)
    for signum, handler in previous.items():
        if handler is not signal.SIG_IGN:  # ignored (a background job's Ctrl-C): kept so
            signal.signal(signum, _on_signal)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        signal.signal(signal.SIGALRM, previous_alarm)
        sys.unraisablehook = _PREVIOUS_HOOK.pop()
        _STATE.reset()


#: The name the toolkit's commands used first: SIGTERM (and SIGINT) as KeyboardInterrupt.
terminate_as_interrupt = interruptible


def exit_on_signal() -> None:
    """From now on, SIGINT or SIGTERM end the process at once with one line and the
    interrupted status (:data:`INTERRUPT_EXIT_STATUS`), without interpreter shutdown: for
    a program whose work is done (or was interrupted) while it exits."""
    import signal

    def leave(signum: int, frame: Any) -> None:
        _flush_and_exit(INTERRUPT_EXIT_STATUS)

    for signum in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, leave)


def worker_signals() -> None:
    """Signals in a pool's worker process (before its first task): Ctrl-C is ignored (the
    terminal sends it to the whole process group; the parent process decides and stops
    its workers), SIGTERM raises ``KeyboardInterrupt`` in a task (its writers clean up;
    :func:`in_task` marks a task) and ends the worker quietly between tasks. Signals that
    the parent blocked while starting the worker (:func:`signals_blocked`) are let in
    after the handlers are set."""
    import signal
    import sys

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _STATE.reset()
    _STATE.worker = True
    if not _PREVIOUS_HOOK:
        _PREVIOUS_HOOK.append(sys.unraisablehook)
        sys.unraisablehook = _on_unraisable
    signal.signal(signal.SIGALRM, _on_retry)
    signal.signal(signal.SIGTERM, _on_signal)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def end_worker() -> None:
    """End this pool worker now, quietly, with SIGTERM's status (after an interrupted
    task's clean-up)."""
    _flush_and_exit(128 + 15, None)


def is_worker() -> bool:
    """Whether this process is a pool worker set up by :func:`worker_signals`."""
    return _STATE.worker


@contextmanager
def in_task() -> Iterator[None]:
    """Marks a task running in a pool worker (SIGTERM interrupts it rather than ending
    the worker outright)."""
    _STATE.in_task = True
    try:
        yield
    finally:
        _STATE.in_task = False


@contextmanager
def signals_blocked() -> Iterator[None]:
    """Within the block SIGINT and SIGTERM wait (blocked, not lost: delivered when it
    ends), and the processes started in it begin with them blocked, so that a worker is
    not interrupted before it has set its handlers (:func:`worker_signals`)."""
    import signal
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()  # it unblocks both signals when it starts
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
