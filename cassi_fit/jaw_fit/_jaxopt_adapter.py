"""The one place that imports jaxopt (unmaintained upstream; kept as an alternative solver).

jaxopt warns on import that it is no longer maintained. That DeprecationWarning is caught
here, so it neither reaches users nor fails a test suite that turns warnings into errors;
jaxopt itself is imported on first use, not with this module. Everything else in the
toolkit uses optimistix; this adapter gives jaxopt's LevenbergMarquardt and GaussNewton the
same shape as the optimistix path: ``residuals(params, args) -> (m,)`` in, ``(params,
result)`` out (``result`` a :class:`cassi_fit.status.SolverResult` code), as the function
:func:`least_squares` and as the :class:`~cassi_fit.jaw_fit.Solver` subclasses
:class:`JaxoptLevenbergMarquardt` and :class:`JaxoptGaussNewton` (aliases ``"jaxopt-lm"``,
``"jaxopt-gn"``), which the jaw methods accept as ``solver=``.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any, ClassVar

import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..status import SolverResult
from ._solvers import DEFAULT_MAX_STEPS, Solver, result_code

METHODS = ("lm", "gn")


@functools.cache
def _jaxopt():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*JAXopt is no longer maintained.*")
        warnings.simplefilter("ignore", DeprecationWarning)
        import jaxopt
    return jaxopt


def least_squares(residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
                  args: Any, *, method: str = "lm", tol: float = 1e-10,
                  max_steps: int = DEFAULT_MAX_STEPS
                  ) -> tuple[Float[Array, " p"], Int[Array, ""]]:
    """Minimise ``|residuals(params, args)|^2`` from ``params0`` with jaxopt.

    method: ``"lm"`` (LevenbergMarquardt) or ``"gn"`` (GaussNewton). Traceable (jit, vmap).
    Returns ``(params, result)``: SUCCESSFUL when jaxopt's error measure (gradient norm)
    fell below ``tol``; else NON_FINITE when the parameters or the error are not finite,
    MAX_STEPS_REACHED when ``max_steps`` iterations ran. Never raises on non-convergence.
    """
    if method not in METHODS:
        raise ValueError(f"jaxopt method must be one of {METHODS}, not {method!r}")
    jaxopt = _jaxopt()

    def fun(params, data):
        return residuals(params, data)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        if method == "lm":
            solver = jaxopt.LevenbergMarquardt(
                residual_fun=fun, maxiter=max_steps, tol=tol, xtol=tol, gtol=tol,
                solver="cholesky", materialize_jac=True, implicit_diff=False, jit=True,
            )
        else:
            solver = jaxopt.GaussNewton(
                residual_fun=fun, maxiter=max_steps, tol=tol, implicit_diff=False, jit=True
            )
        params, state = solver.run(params0, args)
    finite = jnp.all(jnp.isfinite(params)) & jnp.isfinite(state.error)
    result = jnp.where(state.error <= tol, result_code(SolverResult.SUCCESSFUL),
                       jnp.where(finite, result_code(SolverResult.MAX_STEPS_REACHED),
                                 result_code(SolverResult.NON_FINITE)))
    return params, result


class _JaxoptSolver(Solver):
    """A jaxopt solver behind the :class:`~cassi_fit.jaw_fit.Solver` interface. ``rtol``:
    tolerance on jaxopt's error measure (None: 1e-8 in float64, 1e-4 in float32); ``atol``
    is accepted for symmetry and unused; ``max_steps``: iteration budget."""

    _method: ClassVar[str]

    def run(self, residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
            args: Any, gradient_stop: bool = False
            ) -> tuple[Float[Array, " p"], Int[Array, ""]]:
        """:func:`least_squares`; ``gradient_stop`` is implied (jaxopt stops on its
        gradient-norm error measure)."""
        tol = self.tolerances(params0.dtype)[0]
        return least_squares(residuals, params0, args, method=self._method, tol=tol,
                             max_steps=self.max_steps)


class JaxoptLevenbergMarquardt(_JaxoptSolver):
    """jaxopt's LevenbergMarquardt (alias ``"jaxopt-lm"``)."""

    name: ClassVar[str] = "jaxopt-lm"
    damped: ClassVar[bool] = True
    _method: ClassVar[str] = "lm"


class JaxoptGaussNewton(_JaxoptSolver):
    """jaxopt's GaussNewton (alias ``"jaxopt-gn"``)."""

    name: ClassVar[str] = "jaxopt-gn"
    damped: ClassVar[bool] = False
    _method: ClassVar[str] = "gn"
