"""The one place that imports jaxopt (unmaintained upstream; kept as an alternative solver).

jaxopt warns on import that it is no longer maintained. That DeprecationWarning is caught
here, so it neither reaches users nor fails a test suite that turns warnings into errors.
Everything else in the toolkit uses optimistix; this adapter gives jaxopt's
LevenbergMarquardt and GaussNewton the same call shape as the optimistix path in
:mod:`cassi_fit.jaw_fit`: ``residuals(params, args) -> (m,)`` in, ``(params, converged)`` out,
as the function :func:`least_squares` and as the solver objects
:class:`JaxoptLevenbergMarquardt` and :class:`JaxoptGaussNewton` (aliases ``"jaxopt-lm"``,
``"jaxopt-gn"``), which the jaw methods of :mod:`cassi_fit.jaw_fit` accept as ``solver=``.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

METHODS = ("lm", "gn")
DEFAULT_MAX_STEPS = 100


@functools.cache
def _jaxopt():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*JAXopt is no longer maintained.*")
        warnings.simplefilter("ignore", DeprecationWarning)
        import jaxopt
    return jaxopt


def least_squares(residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
                  args: Any, *, method: str = "lm", tol: float = 1e-10,
                  max_steps: int = DEFAULT_MAX_STEPS) -> tuple[Float[Array, " p"], Bool[Array, ""]]:
    """Minimise ``|residuals(params, args)|^2`` from ``params0`` with jaxopt.

    method: ``"lm"`` (LevenbergMarquardt) or ``"gn"`` (GaussNewton). Traceable (jit, vmap).
    Returns ``(params, converged)``; converged is True when jaxopt's error measure (gradient
    norm) fell below ``tol`` within ``max_steps`` iterations. Never raises on non-convergence.
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
    return params, state.error <= tol


class _JaxoptSolver(eqx.Module):
    """A jaxopt solver as a jaw-fit solver object (see :class:`cassi_fit.jaw_fit.Solver`).

    ``rtol``: tolerance on jaxopt's error measure (None: 1e-8 in float64, 1e-4 in float32;
    ``atol`` is accepted for symmetry and unused); ``max_steps``: iteration budget.
    """

    rtol: float | None = None
    atol: float | None = None
    max_steps: int = DEFAULT_MAX_STEPS

    name: ClassVar[str]
    damped: ClassVar[bool]
    _method: ClassVar[str]

    def tolerances(self, dtype) -> tuple[float, float]:
        tol = 1e-8 if jnp.dtype(dtype) == jnp.float64 else 1e-4
        return (tol if self.rtol is None else self.rtol, tol if self.atol is None else self.atol)

    def run(self, residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
            args: Any, gradient_stop: bool = False) -> tuple[Float[Array, " p"], Bool[Array, ""]]:
        """Minimise ``|residuals(params, args)|^2`` from ``params0``; ``gradient_stop`` is
        implied (jaxopt stops on its gradient-norm error measure)."""
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
