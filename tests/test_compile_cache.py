"""The persistent compilation cache (issue 23, part 1): where it lives, that it can be
turned off, that two processes can fill one folder at the same moment, and that a process
after them compiles nothing. Counted through JAX's own events, never timed."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cassi_fit import synth
from cassi_fit._exported import EXPORT_CACHE_ENV
from cassi_fit.corpus import _process
from cassi_fit.corpus._process import (
    CompileCacheWarning,
    default_compile_cache,
    use_compile_cache,
    worker_thread_env,
)


def test_the_folder_the_environment_chooses(tmp_path):
    home = os.path.expanduser("~")
    assert default_compile_cache({}) == Path(home) / ".cache/cassi_fit/jax"
    assert default_compile_cache({"XDG_CACHE_HOME": "/x/c"}) == Path("/x/c/cassi_fit/jax")
    assert default_compile_cache({"XDG_CACHE_HOME": "relative"}) == (
        Path(home) / ".cache/cassi_fit/jax")  # the XDG rule: relative values are ignored
    jax_dir = {"JAX_COMPILATION_CACHE_DIR": str(tmp_path / "j"), "XDG_CACHE_HOME": "/x/c"}
    assert default_compile_cache(jax_dir) == tmp_path / "j"
    ours = {**jax_dir, "CASSI_COMPILE_CACHE": str(tmp_path / "c")}
    assert default_compile_cache(ours) == tmp_path / "c"
    for off in ("off", "0", "", "None"):
        assert default_compile_cache({**ours, "CASSI_COMPILE_CACHE": off}) is None


def test_a_folder_that_cannot_be_written_is_one_warning_and_no_cache(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    for name in ("JAX_COMPILATION_CACHE_DIR", "CASSI_COMPILE_CACHE"):
        monkeypatch.setenv(name, os.environ.get(name, ""))  # restored after the test
    with pytest.warns(CompileCacheWarning, match="cannot hold the compilation cache"):
        assert use_compile_cache(blocker / "jax", inherit=False) is None


def test_a_folder_with_an_entry_missing_its_last_use_is_repaired(tmp_path, monkeypatch):
    """An entry written without the size limit (or by a process killed between JAX's two
    writes) has no last-use file; JAX's size-limited cache then fails every later write.
    Using the folder repairs it first, under JAX's own lock: JAX's cache class itself then
    writes, and the repaired entry is the first to be evicted."""
    from jax._src.lru_cache import LRUCache

    folder = tmp_path / "jax"
    folder.mkdir()
    (folder / "old-cache").write_bytes(b"x" * 10)  # no old-atime beside it
    with pytest.raises(FileNotFoundError):  # JAX as it is, on such a folder
        LRUCache(str(folder), max_size=1 << 20).put("new", b"y" * 10)
    for name in ("JAX_COMPILATION_CACHE_DIR", "CASSI_COMPILE_CACHE",
                 "JAX_COMPILATION_CACHE_MAX_SIZE", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
                 "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"):
        monkeypatch.setenv(name, os.environ.get(name, ""))  # restored after the test
    assert _process.repair_compile_cache(folder) == 1
    assert _process.repair_compile_cache(folder) == 0  # nothing left to repair
    assert int.from_bytes((folder / "old-atime").read_bytes(), "little") == 0
    cache = LRUCache(str(folder), max_size=25)
    cache.put("new", b"y" * 10)
    cache.put("newer", b"z" * 10)  # over 25 bytes: the repaired entry goes first
    assert not (folder / "old-cache").exists() and (folder / "new-cache").exists()


class LRUCache:  # named as JAX's cache class (jax._src.lru_cache): its put's frame
    def put(self):
        from cassi_fit import _signals

        return _signals._in_extension_init(sys._getframe())


def test_an_interrupt_waits_while_jax_writes_a_cache_entry():
    from jax._src import lru_cache

    from cassi_fit import _signals

    assert lru_cache.LRUCache.put.__qualname__ == "LRUCache.put"  # the name looked for
    assert LRUCache().put()
    assert not _signals._in_extension_init(sys._getframe())


def test_worker_threads_are_limited_before_jax_starts():
    given = {"XLA_FLAGS": "--xla_dump_to=/tmp/d --xla_cpu_multi_thread_eigen=true"}
    env = worker_thread_env(1, given)
    assert env["XLA_FLAGS"].split() == ["--xla_dump_to=/tmp/d",
                                        "--xla_cpu_multi_thread_eigen=false",
                                        "intra_op_parallelism_threads=1"]
    assert env["OMP_NUM_THREADS"] == env["NPROC"] == env["LP_NUM_THREADS"] == "1"
    assert worker_thread_env(3, {})["XLA_FLAGS"] == "intra_op_parallelism_threads=3"
    assert _process.threads_per_worker(2, cores=8) == 4
    assert _process.threads_per_worker(4, cores=2) == 1


# The child: `cassi jaw` as the program, counting JAX's compilation-cache events, after
# waiting at a barrier (a line on stdin) so that two children compile at the same moment.
_COUNTING = """
import json, sys
import jax.monitoring
counts = {"requests": 0, "hits": 0}
def listen(event, **kwargs):
    if event == "/jax/compilation_cache/compile_requests_use_cache":
        counts["requests"] += 1
    elif event == "/jax/compilation_cache/cache_hits":
        counts["hits"] += 1
jax.monitoring.register_event_listener(listen)
print("ready", flush=True)
sys.stdin.readline()
from cassi_fit.cli import main
status = main(sys.argv[1:])
print(json.dumps(counts), flush=True)
sys.exit(status)
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    root = synth.generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=1,
                                 tasks=[synth.JAW_WAGGING_TASK])
    return next(Path(root).rglob("*.[tT][xX][yY]"))


def _start(recording, out: Path, cache: Path, *more: str) -> subprocess.Popen:
    # the exported kernels off: a warm process would load their compiled executables and
    # ask the compilation cache for nothing (tests/test_exported.py tests that path)
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), EXPORT_CACHE_ENV: "off"}
    proc = subprocess.Popen(
        [sys.executable, "-c", _COUNTING, "jaw", str(recording), "--csv", str(out),
         "--method", "closed-form", *more],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=env)
    assert proc.stdout.readline().strip() == "ready"
    return proc


def _finish(proc: subprocess.Popen) -> tuple[dict, str]:
    out, err = proc.communicate()
    assert proc.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1]), err


@pytest.mark.slow
def test_two_processes_fill_one_cache_and_the_next_compiles_nothing(recording, tmp_path):
    cache = tmp_path / "cache"
    first = [_start(recording, tmp_path / f"{k}.csv", cache) for k in range(2)]
    for proc in first:  # both start compiling at once
        proc.stdin.write("go\n")
        proc.stdin.flush()
    results = [_finish(proc) for proc in first]
    for counts, err in results:
        assert counts["requests"] > 0
        assert "compilation cache" not in err  # no failed read or write of an entry
    assert (tmp_path / "0.csv").read_bytes() == (tmp_path / "1.csv").read_bytes()
    assert any(p.name.endswith("-cache") for p in cache.iterdir())

    warm = _start(recording, tmp_path / "2.csv", cache)
    warm.stdin.write("go\n")
    warm.stdin.flush()
    counts, err = _finish(warm)
    assert counts["requests"] > 0 and counts["hits"] == counts["requests"], counts
    assert (tmp_path / "2.csv").read_bytes() == (tmp_path / "0.csv").read_bytes()


@pytest.mark.slow
def test_no_compile_cache_keeps_nothing(recording, tmp_path):
    cache = tmp_path / "cache"
    proc = _start(recording, tmp_path / "o.csv", cache, "--no-compile-cache")
    proc.stdin.write("go\n")
    proc.stdin.flush()
    counts, _ = _finish(proc)
    assert counts["requests"] == 0  # no compilation went through a cache
    assert not cache.exists() or not any(cache.iterdir())
