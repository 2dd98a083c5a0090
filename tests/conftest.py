"""Shared test set-up: float64 on (precision is asserted), rank promotion raising (an
array of one rank is never silently broadcast against another: write ``x[None]`` or
``jnp.broadcast_to``), and the synthetic subject zoo. The library's default, float32, is
run by tests/test_float32.py in a process of its own.

One JAX compilation cache for the whole session, shared with every process the tests start
(the CLI in subprocesses, notebook kernels, corpus workers): the same functions are compiled
once instead of once per process. It lives in a fresh temporary folder, removed at exit, so
no run ever reads another run's executables. ``CASSI_TEST_JAX_CACHE=0`` turns it off. The
exported kernels (``cassi_fit._exported``) are kept in it too, so a kernel is traced once
in the session, not once in every process.
"""

import atexit
import os
import shutil
import tempfile

os.environ.setdefault("JAX_PLATFORMS", "cpu")
if os.environ.get("CASSI_TEST_JAX_CACHE", "1") != "0" and "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _cache = tempfile.mkdtemp(prefix="cassi-test-jax-cache-")
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _cache
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
    # every process on this folder keeps JAX's size-capped (locked, LRU) layout, as the
    # command line's does: a folder written both ways breaks the eviction's bookkeeping
    # (2 GiB: cassi_fit.corpus._process.COMPILE_CACHE_MAX_BYTES; set before JAX is imported)
    os.environ.setdefault("JAX_COMPILATION_CACHE_MAX_SIZE", str(2 * 1024**3))
# The command line and corpus workers use the same folder (cassi_fit.corpus._process), or
# none: never the user's own cache (~/.cache/cassi_fit/jax), whatever the environment says.
os.environ["CASSI_COMPILE_CACHE"] = os.environ.get("JAX_COMPILATION_CACHE_DIR") or "off"

# Under pytest-xdist (`make test` runs two workers), each worker computes on its share of
# the cores, as a corpus run's workers do: two XLA thread pools each as wide as the machine
# only fight over it. Set before JAX starts; the processes a test starts inherit it.
if os.environ.get("PYTEST_XDIST_WORKER"):
    from cassi_fit.corpus._process import limit_threads, threads_per_worker

    limit_threads(threads_per_worker(int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))))

# Every process the tests start (the command line in subprocesses, notebook kernels, corpus
# workers) computes as this one does, float64 with rank promotion raising: it is held to
# the same rule, and it loads the kernels this process and the others compiled (the
# exported kernels and JAX's cache are keyed by these settings) instead of compiling a
# float32 set of its own. The library's default, float32, has its own test
# (tests/test_float32.py), which sets its process's precision itself.
os.environ["JAX_ENABLE_X64"] = "1"
os.environ["JAX_NUMPY_RANK_PROMOTION"] = "raise"

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture
def solvers_return_their_start(monkeypatch):
    """Every jaw solver's solve step replaced by one that returns its start and reports
    success (the least-squares step and the block-tridiagonal one), for the meta-tests that
    show a far-start test fails without its solver. Every exported kernel
    (``cassi_fit._exported``; the jaw methods' kernels are) gets a fresh ``eqx.filter_jit``
    for the test, so it is traced again with the stub in it, and its own compilations (which
    hold the real solver) come back untouched afterwards: the process's other compiled
    functions are kept, not dropped with ``jax.clear_caches()`` for every later test file
    to trace again. The stub refuses to be traced anywhere else (a RuntimeError, not the
    AssertionError the meta-tests expect), so no other compiled function can keep it. No
    kernel is loaded exported (it would hold the real solver) nor exported with the stub
    in it."""
    import functools
    import sys

    import equinox as eqx

    from cassi_fit._exported import EXPORT_CACHE_ENV, Exported
    from cassi_fit.jaw_fit import _solve, _solvers
    from cassi_fit.status import SolverResult

    success = np.int32(SolverResult.SUCCESSFUL)
    depth = [0]  # inside a fresh kernel's trace

    def fresh(fn):
        @functools.wraps(fn)
        def traced(*args, **kwargs):
            depth[0] += 1
            try:
                return fn(*args, **kwargs)
            finally:
                depth[0] -= 1
        return eqx.filter_jit(traced)

    def stub(result):
        if not depth[0]:
            raise RuntimeError("the stubbed solver traced outside a fresh exported kernel: "
                               "a compiled function could keep it")
        return result, success

    monkeypatch.setattr(_solve, "_minimise",
                        lambda solver, residuals, params0, args, gradient_stop: stub(params0))
    monkeypatch.setattr(_solvers, "minimise_block_tridiagonal",
                        lambda system, knots0, **kw: stub(knots0))
    monkeypatch.setenv(EXPORT_CACHE_ENV, "off")
    kernels = {id(k): k for name, module in list(sys.modules.items())
               if name.startswith("cassi_fit") and module is not None
               for k in vars(module).values() if isinstance(k, Exported)}
    assert kernels  # the jaw methods' kernels at least
    for kernel in kernels.values():
        monkeypatch.setattr(kernel, "jitted", fresh(kernel.fn))
    yield
