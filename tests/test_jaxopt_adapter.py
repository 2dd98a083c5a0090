"""The jaxopt adapter: solves, vmaps, and keeps jaxopt's unmaintained warning to itself."""

import importlib
import subprocess
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cassi_fit.jaw_fit import _jaxopt_adapter
from cassi_fit.status import SolverResult


def rosenbrock(p, a):
    return jnp.array([p[0] - a, 10.0 * (p[1] - p[0] ** 2)])


@pytest.mark.parametrize("method", _jaxopt_adapter.METHODS)
def test_solves_and_vmaps_without_warnings(method):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        importlib.reload(_jaxopt_adapter)
        run = jax.vmap(lambda a: _jaxopt_adapter.least_squares(
            rosenbrock, jnp.array([-1.2, 1.0]), a, method=method))
        params, result = run(jnp.array([1.0, 2.0]))
    np.testing.assert_allclose(params, [[1.0, 1.0], [2.0, 4.0]], atol=1e-7)
    assert np.all(result == SolverResult.SUCCESSFUL)
    assert not [w for w in caught if "jaxopt" in str(w.message).lower()
                or "maintained" in str(w.message).lower()]


def test_import_warning_never_reaches_users():
    code = ("import jax.numpy as jnp\nfrom cassi_fit.jaw_fit import _jaxopt_adapter as a\n"
            "print(int(a.least_squares(lambda p, x: p - x, jnp.zeros(2), 1.0)[1]) == 0)")
    out = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stderr
    assert "maintained" not in out.stderr and "True" in out.stdout


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="lm"):
        _jaxopt_adapter.least_squares(rosenbrock, jnp.zeros(2), 1.0, method="bfgs")


@pytest.mark.parametrize("solver", [_jaxopt_adapter.JaxoptLevenbergMarquardt(),
                                    _jaxopt_adapter.JaxoptGaussNewton()])
def test_solver_objects_solve_and_respect_their_step_budget(solver):
    from cassi_fit.jaw_fit import Solver

    assert isinstance(solver, Solver)  # the one typed interface
    run = jax.vmap(lambda a: solver.run(rosenbrock, jnp.array([-1.2, 1.0]), a))
    params, result = run(jnp.array([1.0, 2.0]))
    np.testing.assert_allclose(params, [[1.0, 1.0], [2.0, 4.0]], atol=1e-7)
    assert np.all(result == SolverResult.SUCCESSFUL) and solver.name.startswith("jaxopt-")
    stopped = type(solver)(max_steps=1)
    params, result = stopped.run(rosenbrock, jnp.array([-1.2, 1.0]), 1.0)
    assert int(result) == SolverResult.MAX_STEPS_REACHED
    assert np.linalg.norm(np.asarray(params) - 1.0) > 1e-3
