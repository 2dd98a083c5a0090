"""Corpus task functions for tests/test_interrupt.py (importable by spawned workers)."""

import os

from cassi_fit._io import atomic_write
from cassi_fit.corpus import CorpusItem, TaskResult


def blocking_task(item: CorpusItem, out_dir: str, *, overwrite: bool = False) -> TaskResult:
    """Start writing ``out_dir/SUBJECT/TASK.txt``, report the worker's pid on the FIFO
    named by ``CASSI_TEST_REACHED``, then wait (for a signal) half-way through the file."""

    def write(fh):
        fh.write("half")
        fh.flush()
        with open(os.environ["CASSI_TEST_REACHED"], "w") as fifo:
            fifo.write(f"{os.getpid()}\n")
        while True:  # interrupted by the signal, never finished
            os.read(_never_ready(), 1)

    path = os.path.join(out_dir, item.subject, f"{item.task}.txt")
    atomic_write(path, write, overwrite=overwrite)
    return TaskResult({}, (path,))


def _never_ready() -> int:
    """A pipe's read end with no writer ever writing: a read blocks until a signal."""
    read, _write = os.pipe()
    _never_ready.keep = _write  # keep the write end open, so reads block
    return read
