"""Special files for tests of hostile inputs, and a guard that turns a FIFO opened for
reading into a test failure instead of a hang.

Opening a FIFO for reading blocks until a writer opens it. The toolkit must never open one
(discovery and readers look at ``os.stat`` only). :class:`FifoGuard` watches FIFOs while a
block runs: a background thread tries, again and again, to open each FIFO for writing
without blocking. That succeeds only when some reader has the FIFO open (else the kernel
says ENXIO), so a success is proof that the code under test opened it, whatever the
machine's speed; the guard then closes its end, which gives the blocked reader an end of
file (the code under test goes on, and the test fails on ``guard.opened``). Nothing here
decides pass or fail by time: the polling period only sets how soon a blocked reader is
released.
"""

from __future__ import annotations

import errno
import os
import threading
from pathlib import Path

POLL_S = 0.02


class FifoGuard:
    """``with FifoGuard(fifo, ...) as guard: ...`` then ``assert guard.opened == []``."""

    def __init__(self, *fifos: os.PathLike | str):
        self.fifos = [Path(f) for f in fifos]
        self.opened: list[Path] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        while not self._stop.wait(POLL_S):
            for fifo in self.fifos:
                try:
                    fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
                except OSError as exc:
                    if exc.errno in (errno.ENXIO, errno.ENOENT):
                        continue  # no reader (or the node is gone): nothing opened it
                    raise
                if fifo not in self.opened:
                    self.opened.append(fifo)
                os.close(fd)  # the reader sees an end of file and goes on

    def __enter__(self) -> FifoGuard:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def make_fifo(path: os.PathLike | str) -> Path:
    """A FIFO at ``path`` (its folder created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(path)
    return path


def make_socket(path: os.PathLike | str) -> Path:
    """A Unix socket node at ``path`` (bound, then closed: the node stays)."""
    import socket

    path = Path(path).absolute()
    path.parent.mkdir(parents=True, exist_ok=True)
    sock = socket.socket(socket.AF_UNIX)
    cwd = os.getcwd()
    try:  # by a relative name: a socket's path may hold at most 107 bytes
        os.chdir(path.parent)
        sock.bind(path.name)
    finally:
        os.chdir(cwd)
        sock.close()
    return path
