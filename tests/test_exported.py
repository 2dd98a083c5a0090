"""Exported kernels (cassi_fit._exported): the same results as ``eqx.filter_jit`` to the
bit, loaded by a new process without tracing, and never an error from the folder: a broken
entry is traced again and replaced, an unusable folder leaves the kernel traced."""

import os
import subprocess
import sys
from pathlib import Path

import equinox as eqx
import exported_kernels as ek
import jax
import numpy as np
import pytest

from cassi_fit import _exported
from cassi_fit._exported import EXPORT_CACHE_ENV, SUFFIX, Exported, export_folder

HERE = Path(__file__).resolve().parent


def _same(out, ref):
    assert jax.tree.structure(out) == jax.tree.structure(ref)
    for a, b in zip(jax.tree.leaves(out), jax.tree.leaves(ref), strict=True):
        if eqx.is_array(b):
            assert np.asarray(a).dtype == np.asarray(b).dtype
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        else:
            assert a == b


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setenv(EXPORT_CACHE_ENV, str(tmp_path / "exported"))
    return tmp_path / "exported"


def test_the_exported_kernel_gives_filter_jits_results_and_traces_once(folder):
    kernel = Exported(ek.kernel.fn)
    args = ek.inputs()
    before = len(ek.TRACES)
    out = kernel(*args)
    assert len(ek.TRACES) == before + 1
    _same(out, kernel.jitted(*args))
    assert (kernel.traces, kernel.loads) == (1, 0)
    assert len(list(folder.glob(f"*{SUFFIX}"))) == 1
    traced = len(ek.TRACES)
    _same(kernel(*args), out)  # the second call: this process's own entry, no trace
    assert (kernel.traces, kernel.loads, len(ek.TRACES)) == (1, 0, traced)
    kernel(*ek.inputs(5))  # other shapes: another entry
    assert kernel.traces == 2 and len(list(folder.glob(f"*{SUFFIX}"))) == 2
    fresh = Exported(ek.kernel.fn)  # as a new process: from the folder
    _same(fresh(*args), out)
    assert (fresh.traces, fresh.loads) == (0, 1)


def _child(out, environ):
    env = {**os.environ, **environ, "JAX_PLATFORMS": "cpu",
           "PYTHONPATH": os.pathsep.join([str(HERE), str(HERE.parent),
                                          os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, str(HERE / "exported_kernels.py"), str(out)],
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    with np.load(out) as z:
        return {k: z[k] for k in z.files}


def test_a_new_process_loads_the_kernel_without_tracing(tmp_path):
    # a compilation cache of its own, empty: the first process compiles the kernel itself
    # and stores its executable (one JAX's cache answered with is not stored)
    environ = {EXPORT_CACHE_ENV: str(tmp_path / "exported"),
               "JAX_COMPILATION_CACHE_DIR": str(tmp_path / "jax")}
    first = _child(tmp_path / "first.npz", environ)
    second = _child(tmp_path / "second.npz", environ)
    assert list(first["counts"]) == [1, 1, 0, 1]  # traced once (its Python ran once), stored
    # loaded, its executable too: the kernel's Python never ran, nothing was lowered
    assert list(second["counts"]) == [0, 0, 1, 1]
    again = _child(tmp_path / "again.npz", {**environ,
                                              "JAX_COMPILATION_CACHE_DIR": str(tmp_path / "j2")})
    assert list(again["counts"]) == [0, 0, 1, 1]  # the executable needs no compilation cache
    # its LAPACK calls readied from SciPy's two function tables, not the scipy.linalg package
    assert not second["scipy_linalg"] and not again["scipy_linalg"]
    off = _child(tmp_path / "off.npz", {EXPORT_CACHE_ENV: "off"})
    assert list(off["counts"]) == [1, 0, 0, 0]  # eqx.filter_jit's own trace
    for name in ("a", "b", "trace"):
        np.testing.assert_array_equal(second[name], first[name])
        np.testing.assert_array_equal(again[name], first[name])
        np.testing.assert_array_equal(off[name], first[name])


def test_a_computation_the_compilation_cache_holds_is_stored_with_its_executable(tmp_path):
    """XLA's CPU client serializes an executable loaded from JAX's compilation cache
    without its machine code: a kernel whose computation the cache holds already (the
    code changed elsewhere, every entry traced again) is compiled without the cache when
    its entry is made, so that later processes load its executable instead of lowering
    it again, each of them."""
    cache = {"JAX_COMPILATION_CACHE_DIR": str(tmp_path / "jax"),
             "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0"}
    # the kernel's computation compiled into the cache (the entry beside it elsewhere)
    fill = _child(tmp_path / "fill.npz", {**cache, EXPORT_CACHE_ENV: str(tmp_path / "elsewhere")})
    environ = {**cache, EXPORT_CACHE_ENV: str(tmp_path / "exported")}
    first = _child(tmp_path / "first.npz", environ)  # traced again, compiled again
    second = _child(tmp_path / "second.npz", environ)
    assert list(first["counts"]) == [1, 1, 0, 1]  # this process's compiled kernel
    assert list(second["counts"]) == [0, 0, 1, 1]  # loaded, its executable too
    for name in ("a", "b", "trace"):
        np.testing.assert_array_equal(first[name], fill[name])
        np.testing.assert_array_equal(second[name], first[name])


def test_only_an_executable_another_process_can_load_is_stored(monkeypatch):
    """LAPACK's custom calls are readied before an executable is loaded; any other custom
    call keeps the entry to its exported computation (called, never loaded as machine code)."""
    import jax
    import jax.numpy as jnp
    from jax import export

    from cassi_fit import _exported

    spec = jax.ShapeDtypeStruct((3, 3), jnp.float64)
    inverse = export.export(jax.jit(jnp.linalg.inv), disabled_checks=[
        export.DisabledSafetyCheck.custom_call("ALL")])(spec)
    avals = [((3, 3), jnp.float64, False)]
    assert any(t.startswith("lapack_") for t in _exported._custom_calls(inverse))
    assert _exported._executable_is_portable(inverse)
    with jax.enable_x64(True):
        monkeypatch.setattr(_exported, "_custom_calls", lambda e: {"lapack_dgetrf_ffi", "other"})
        compiled, executable = _exported._compile(inverse, avals)
        assert executable is None
        a = jnp.asarray(np.eye(3) * 2.0)
        np.testing.assert_array_equal(compiled(a), np.eye(3) / 2.0)


def test_a_broken_entry_is_traced_again_and_replaced(folder):
    args = ek.inputs()
    out = Exported(ek.kernel.fn)(*args)
    (entry,) = folder.glob(f"*{SUFFIX}")
    for broken in (b"", entry.read_bytes()[:1000], b"not a pickle at all"):
        entry.write_bytes(broken)
        kernel = Exported(ek.kernel.fn)
        _same(kernel(*args), out)
        assert (kernel.traces, kernel.loads) == (1, 0)
        assert entry.stat().st_size > 1000  # written again, whole
        again = Exported(ek.kernel.fn)
        _same(again(*args), out)
        assert (again.traces, again.loads) == (0, 1)
    assert [p.name for p in folder.iterdir()] == [entry.name]  # no temporary file left


def test_an_unusable_folder_leaves_the_kernel_traced_without_error(tmp_path, monkeypatch):
    (tmp_path / "a_file").write_text("not a folder")
    monkeypatch.setenv(EXPORT_CACHE_ENV, str(tmp_path / "a_file" / "exported"))
    args = ek.inputs()
    kernel = Exported(ek.kernel.fn)
    _same(kernel(*args), kernel.jitted(*args))
    assert (kernel.traces, kernel.loads) == (1, 0)
    _same(kernel(*args), kernel.jitted(*args))
    assert kernel.traces == 1  # this process keeps its own


def test_the_folder_follows_the_compilation_cache_and_can_be_turned_off(tmp_path, monkeypatch):
    monkeypatch.delenv(EXPORT_CACHE_ENV, raising=False)
    previous = jax.config.jax_compilation_cache_dir
    jax.config.update("jax_compilation_cache_dir", str(tmp_path / "jax"))
    try:  # nothing compiled meanwhile: JAX's own cache would start in that folder
        assert export_folder() == tmp_path / "jax" / _exported.SUBFOLDER
        jax.config.update("jax_enable_compilation_cache", False)  # --no-compile-cache
        assert export_folder() is None
    finally:
        jax.config.update("jax_compilation_cache_dir", previous)
        jax.config.update("jax_enable_compilation_cache", True)
    for off in ("off", "0", "none", ""):
        monkeypatch.setenv(EXPORT_CACHE_ENV, off)
        assert export_folder() is None
    kernel = Exported(ek.kernel.fn)
    _same(kernel(*ek.inputs()), kernel.jitted(*ek.inputs()))
    assert (kernel.traces, kernel.loads) == (0, 0)


def test_under_a_transformation_the_kernel_is_traced_as_by_filter_jit(folder):
    pair, power, offset = ek.inputs()
    kernel = Exported(ek.kernel.fn)

    def loss(f, b):
        return f(eqx.tree_at(lambda p: p.b, pair, b), power, offset)[0].b.sum()

    grad = jax.grad(lambda b: loss(kernel, b))(pair.b)
    np.testing.assert_array_equal(grad, jax.grad(lambda b: loss(kernel.jitted, b))(pair.b))
    assert (kernel.traces, kernel.loads) == (0, 0) and not folder.exists()


def test_the_folder_is_held_under_its_size_limit(folder, monkeypatch):
    monkeypatch.setattr(_exported, "EXPORT_CACHE_MAX_BYTES", 1)  # room for the newest only
    kernel = Exported(ek.kernel.fn)
    kernel(*ek.inputs(4))
    kernel(*ek.inputs(5))
    (kept,) = folder.glob(f"*{SUFFIX}")
    fresh = Exported(ek.kernel.fn)
    fresh(*ek.inputs(5))
    assert (fresh.traces, fresh.loads) == (0, 1)  # the newest one stayed


def test_the_jaw_kernels_give_filter_jits_results(folder):
    """Two of the toolkit's exported kernels, each against its own ``eqx.filter_jit``."""
    import zoo

    from cassi_fit.jaw_fit._kernels import closed_form_kernel, fixed_pivot_kernel
    from cassi_fit.jaw_fit._solve import as_solver

    track, _ = zoo.jaw_wagging(clean=True)
    jaw = np.asarray(track.positions)[:, 6:8]
    jaw = jaw[np.isfinite(jaw).all(axis=(1, 2))]
    reference, current = jaw[0], jaw[1:]
    weight = np.ones(len(current))
    prior = (np.zeros(2), np.zeros(2))
    for wrapped, args in ((closed_form_kernel, (reference, current)),
                          (fixed_pivot_kernel, (as_solver("optimistix-lm"), reference, current,
                                                weight, np.array([-80.0, 10.0]), prior))):
        kernel = Exported(wrapped.fn)
        _same(kernel(*args), kernel.jitted(*args))
        assert kernel.traces == 1


def test_lapack_is_readied_without_the_scipy_linalg_package():
    """A loaded LAPACK kernel needs SciPy's two BLAS/LAPACK function tables, not the
    ``scipy.linalg`` package (0.2-0.4 s): they are loaded alone, and the package imports
    as ever afterwards, the tables in it."""
    code = (
        "import sys\n"
        "import jax, numpy as np\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "from cassi_fit import _exported\n"
        "_exported._initialize_lapack()\n"
        "assert 'scipy.linalg' not in sys.modules, 'scipy.linalg imported'\n"
        "assert all(m in sys.modules for m in _exported._LAPACK_MODULES)\n"
        "a = np.array([[4.0, 1.0], [1.0, 3.0]])\n"
        "np.testing.assert_allclose(np.asarray(jax.numpy.linalg.inv(a)) @ a, np.eye(2), atol=1e-12)\n"
        "import scipy.linalg\n"
        "from scipy.linalg import cython_blas, cython_lapack\n"
        "assert cython_blas is sys.modules['scipy.linalg.cython_blas']\n"
        "np.testing.assert_allclose(scipy.linalg.inv(a) @ a, np.eye(2), atol=1e-12)\n"
        "print('ok')\n")
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


def test_equal_static_arguments_give_one_digest_whichever_objects_hold_them():
    """The folder's key reads the static arguments' values, not which objects hold them: a
    corpus worker's unpickled run spec holds its strings in objects of its own where the
    starting process shares one (pickle's memo wrote the two apart), and the worker traced
    again what the folder held. A structure that refers to itself still gets a key."""
    kernel = Exported(ek.kernel.fn)
    args = ek.inputs()
    dynamic, _ = eqx.partition((args, {}), eqx.is_array)
    arrays, in_tree = jax.tree.flatten(dynamic)
    avals = tuple((np.shape(a), np.asarray(a).dtype, False) for a in arrays)
    name = "cassi"
    shared = {"mode": name, "jaw": name}  # one object, twice
    apart = {"mode": "".join(["cas", "si"]), "jaw": "".join(["ca", "ssi"])}  # equal, two objects
    assert shared == apart and apart["mode"] is not apart["jaw"]
    assert kernel._digest(in_tree, avals, shared) == kernel._digest(in_tree, avals, apart)
    assert kernel._digest(in_tree, avals, shared) != kernel._digest(in_tree, avals, {"mode": "x"})
    loop = []
    loop.append(loop)
    assert len(kernel._digest(in_tree, avals, loop)) == 40
