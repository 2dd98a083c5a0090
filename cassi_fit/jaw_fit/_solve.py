"""Solver choice (objects, or the aliases users type) and the one generic solve step.

:func:`least_squares` is the solve of every generic fit (it goes through :func:`_minimise`,
one place, so that a test can stub the solver out); :func:`solve` is its boolean form for
callers that only need "converged" (the calibration).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ..errors import InvalidChoiceError
from ..options import SOLVERS, check_choice
from ..status import SolverResult
from ._solvers import (
    DEFAULT_MAX_STEPS,
    Dogleg,
    GaussNewton,
    LevenbergMarquardt,
    Solver,
    default_tolerance,
    result_code,
)

#: The solver class of each alias; jaxopt's by name in ``_jaxopt_adapter``, imported when
#: chosen (their equinox classes cost every process that fits a jaw).
_BY_NAME: dict[str, type[Solver] | str] = {
    "optimistix-lm": LevenbergMarquardt, "optimistix-gn": GaussNewton,
    "optimistix-dogleg": Dogleg, "jaxopt-lm": "JaxoptLevenbergMarquardt",
    "jaxopt-gn": "JaxoptGaussNewton",
}


def jaw_solver(name: str, *, max_steps: int = DEFAULT_MAX_STEPS) -> Solver:
    """The solver object for a command-line alias in :data:`cassi_fit.options.SOLVERS`."""
    check_choice("solver", name, SOLVERS)
    cls = _BY_NAME[name]
    if isinstance(cls, str):
        from . import _jaxopt_adapter

        cls = getattr(_jaxopt_adapter, cls)
    return cls(max_steps=max_steps)


def as_solver(solver: Solver | str) -> Solver:
    """``solver`` if it is a :class:`Solver`, the object for an alias, else one clear error."""
    if isinstance(solver, str):
        return jaw_solver(solver)
    if not isinstance(solver, Solver):
        raise InvalidChoiceError(f"solver must be a solver object or one of "
                                 f"{', '.join(SOLVERS)}, not {solver!r}")
    return solver


def _minimise(solver, residuals, params0, args, gradient_stop):
    """The solve step of every generic fit (one place, so a test can stub it out)."""
    return solver.run(residuals, params0, args, gradient_stop)


def least_squares(residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
                  args: Any, solver: Solver | str = "optimistix-lm",
                  gradient_stop: bool = False) -> tuple[Float[Array, " p"], Int[Array, ""]]:
    """Minimise ``|residuals(params, args)|^2`` from ``params0`` with ``solver`` (an object or
    an alias). Traceable (jit/vmap). Returns ``(params, result)``, ``result`` a
    :class:`cassi_fit.status.SolverResult` code; failure comes back as a value, never as an
    exception from traced code.

    SUCCESSFUL is the solver's own verdict, or a Gauss-Newton step from the answer that
    would gain less than the cost can resolve (Newton decrement ``g^T (J^T J)^+ g <=
    max(tol^2, 100 eps) (1 + |r|^2)``, scale-free in the parameters): a trust-region solver
    sitting exactly on the minimum may stop by shrinking its region without declaring
    success. ``gradient_stop`` also ends the optimistix solvers at a stationary point
    (``_solvers._GradientStop``); use it only with well-scaled parameters.
    """
    solver = as_solver(solver)
    params, result = _minimise(solver, residuals, params0, args, gradient_stop)
    res = residuals(params, args)
    jac = jax.jacfwd(residuals)(params, args)
    grad = jac.T @ res
    normal = jac.T @ jac
    # a rounding-level ridge instead of a pseudo-inverse (an SVD per frame costs more than
    # the whole solve when vmapped); parameters without effect have zero gradient anyway
    ridge = 1e-12 * jnp.trace(normal) + jnp.finfo(normal.dtype).tiny
    eye = jnp.eye(normal.shape[0], dtype=normal.dtype)
    decrement = grad @ jnp.linalg.solve(normal + ridge * eye, grad)
    floor = jnp.maximum(default_tolerance(params0.dtype) ** 2, 100 * jnp.finfo(params.dtype).eps)
    stationary = jnp.isfinite(decrement) & (decrement <= floor * (1.0 + jnp.sum(res**2)))
    return params, jnp.where(stationary, result_code(SolverResult.SUCCESSFUL), result)


def solve(residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"], args: Any,
          solver: Solver | str = "optimistix-lm", gradient_stop: bool = False
          ) -> tuple[Float[Array, " p"], Bool[Array, ""]]:
    """:func:`least_squares` with the result as one bool, ``(params, converged)``."""
    params, result = least_squares(residuals, params0, args, solver, gradient_stop)
    return params, result == int(SolverResult.SUCCESSFUL)
