"""The solver interface of the jaw fits, optimistix's solvers behind it, and the structured
Levenberg-Marquardt of the smooth pivot.

A :class:`Solver` is an equinox Module; :meth:`Solver.run` minimises ``|r(params, args)|^2``
from a start and returns ``(params, result)``, ``result`` a
:class:`cassi_fit.status.SolverResult` code (an int32 array: traceable, vmappable; failure
comes back as a value, never as an exception from traced code). jaxopt's solvers implement
the same interface in :mod:`cassi_fit.jaw_fit._jaxopt_adapter`.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..status import SolverResult
from ._linalg import block_quadratic, block_tridiagonal_solve

DEFAULT_MAX_STEPS = 100


def default_tolerance(dtype: np.dtype | type) -> float:
    """The solvers' default tolerance: 1e-8 in float64, 1e-4 in float32."""
    return 1e-8 if jnp.dtype(dtype) == jnp.float64 else 1e-4


def result_code(value: int | SolverResult) -> Int[Array, ""]:
    """A :class:`SolverResult` as the int32 array the solvers return."""
    return jnp.asarray(int(value), jnp.int32)


def from_optimistix(result: Any) -> Int[Array, ""]:
    """optimistix's ``RESULTS`` (lineax's included) -> a :class:`SolverResult` code."""
    import optimistix as optx

    R = optx.RESULTS
    code = result_code(SolverResult.SINGULAR)  # singular, breakdown, stagnation, conlim
    for item, ours in ((R.nonfinite_input, SolverResult.NON_FINITE),
                       (R.nonfinite, SolverResult.NON_FINITE),
                       (R.nonlinear_divergence, SolverResult.NONLINEAR_DIVERGENCE),
                       (R.max_steps_reached, SolverResult.MAX_STEPS_REACHED),
                       (R.nonlinear_max_steps_reached, SolverResult.MAX_STEPS_REACHED),
                       (R.successful, SolverResult.SUCCESSFUL)):
        code = jnp.where(result == item, result_code(ours), code)
    return code


class Solver(eqx.Module):
    """A least-squares solver for the fitted jaw methods (the interface every solver,
    jaxopt's included, implements).

    ``rtol``/``atol``: tolerances (None: 1e-8 in float64, 1e-4 in float32); ``max_steps``:
    iteration budget. :meth:`run` is traceable (jit, vmap) and returns failure as a value.
    ``name`` is the command-line alias; ``damped`` tells smooth-pivot's structured solver
    to damp its steps (Levenberg-Marquardt) or to start undamped (Gauss-Newton).
    """

    rtol: float | None = None
    atol: float | None = None
    max_steps: int = DEFAULT_MAX_STEPS

    name: ClassVar[str] = "custom"
    damped: ClassVar[bool] = True

    def tolerances(self, dtype: np.dtype | type) -> tuple[float, float]:
        """``(rtol, atol)`` for parameters of ``dtype``."""
        tol = default_tolerance(dtype)
        return (tol if self.rtol is None else self.rtol, tol if self.atol is None else self.atol)

    @abc.abstractmethod
    def run(self, residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
            args: Any, gradient_stop: bool = False
            ) -> tuple[Float[Array, " p"], Int[Array, ""]]:
        """Minimise ``|residuals(params, args)|^2`` from ``params0``: ``(params, result)``,
        ``result`` a :class:`cassi_fit.status.SolverResult` code (int32). ``gradient_stop``
        also ends the iteration at a stationary point (for well-scaled parameters only)."""


class _Optimistix(Solver):
    #: The optimistix solver's class name (``_optimistix_adapter.kinds``).
    _kind: ClassVar[str]

    def kinds(self) -> tuple[type, type]:
        """optimistix's solver class and the one that also stops at a stationary point
        (``gradient_stop``): optimistix is imported here, when a solver is traced, not
        with the toolkit (a warm process loads the compiled fits without it)."""
        from ._optimistix_adapter import kinds

        return kinds(self._kind)

    def run(self, residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
            args: Any, gradient_stop: bool = False
            ) -> tuple[Float[Array, " p"], Int[Array, ""]]:
        """optimistix's ``least_squares`` (``throw=False``); its ``RESULTS`` mapped by
        :func:`from_optimistix`."""
        import optimistix as optx

        rtol, atol = self.tolerances(params0.dtype)
        solver = self.kinds()[int(bool(gradient_stop))](rtol=rtol, atol=atol)
        sol = optx.least_squares(residuals, solver, params0, args, max_steps=self.max_steps,
                                 throw=False)
        return sol.value, from_optimistix(sol.result)


class LevenbergMarquardt(_Optimistix):
    """optimistix's Levenberg-Marquardt (alias ``"optimistix-lm"``; the default)."""

    name: ClassVar[str] = "optimistix-lm"
    _kind: ClassVar[str] = "LevenbergMarquardt"


class GaussNewton(_Optimistix):
    """optimistix's Gauss-Newton (alias ``"optimistix-gn"``)."""

    name: ClassVar[str] = "optimistix-gn"
    damped: ClassVar[bool] = False
    _kind: ClassVar[str] = "GaussNewton"


class Dogleg(_Optimistix):
    """optimistix's Dogleg trust region (alias ``"optimistix-dogleg"``)."""

    name: ClassVar[str] = "optimistix-dogleg"
    _kind: ClassVar[str] = "Dogleg"


# ---------------------------------------------- structured (block-tridiagonal) solver
def minimise_block_tridiagonal(
    system: Callable[[Float[Array, "m 2"]], tuple], knots0: Float[Array, "m 2"], *,
    damped: bool, max_steps: int, tol: float,
) -> tuple[Float[Array, "m 2"], Int[Array, ""]]:
    """Levenberg-Marquardt-damped steps on block-tridiagonal systems: ``system(knots) ->
    (cost, grad, step matrix, Gauss-Newton matrix)`` (matrices as ``(diag, upper)``).
    ``damped``: ``lambda I`` added from the start, Nielsen's update of ``lambda``; else
    ``lambda = 0`` until a step fails to reduce the cost, then damped the same way.
    Returns ``(knots, result)`` (a :class:`SolverResult` code). Converged: at an accepted
    point the Gauss-Newton step (always positive semi-definite, so a safe test even where
    the step matrix is not) is below ``tol (1 + max |Q|)`` mm, or its predicted reduction
    ``g^T N^-1 g`` is below ``max(tol^2, 100 eps) (1 + 2 cost)`` mm^2: a gain that the cost
    (a sum over thousands of frames) cannot resolve in floating point.
    """

    def stationary(knots, cost, grad, gn):
        # a rounding-level ridge keeps knots without data finite
        newton = block_tridiagonal_solve(gn[0] + ridge * jnp.eye(2)[None], gn[1], -grad)
        small = jnp.max(jnp.abs(newton)) <= tol * (1.0 + jnp.max(jnp.abs(knots)))
        decrement = -jnp.sum(grad * newton)
        floor = jnp.maximum(tol**2, 100 * jnp.finfo(knots.dtype).eps)
        return small | (decrement <= floor * (1.0 + 2.0 * cost))

    cost, grad, mat, gn = system(knots0)
    scale = jnp.max(jnp.abs(jnp.diagonal(gn[0], axis1=1, axis2=2)))
    lam0 = 1e-3 * scale
    ridge = 1e-12 * scale
    state = dict(knots=knots0, cost=cost, grad=grad, mat=mat, gn=gn,
                 lam=lam0 if damped else jnp.zeros_like(lam0), nu=jnp.array(2.0, cost.dtype),
                 steps=jnp.array(0), done=stationary(knots0, cost, grad, gn))

    def body(s):
        diag, upper = s["mat"]
        delta = block_tridiagonal_solve(diag + s["lam"] * jnp.eye(2)[None], upper, -s["grad"])
        trial = s["knots"] + delta
        t_cost, t_grad, t_mat, t_gn = system(trial)
        predicted = -(jnp.sum(s["grad"] * delta) + 0.5 * block_quadratic(diag, upper, delta))
        rho = (s["cost"] - t_cost) / jnp.where(predicted > 0, predicted, 1.0)
        accept = jnp.isfinite(t_cost) & (t_cost <= s["cost"]) & (rho > 1e-4)
        lam_ok = s["lam"] * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        lam_bad = jnp.maximum(s["lam"] * s["nu"], lam0)

        def pick(new, old):
            return jax.tree_util.tree_map(lambda a, b: jnp.where(accept, a, b), new, old)

        new = dict(knots=pick(trial, s["knots"]), cost=pick(t_cost, s["cost"]),
                   grad=pick(t_grad, s["grad"]), mat=pick(t_mat, s["mat"]),
                   gn=pick(t_gn, s["gn"]), lam=pick(lam_ok, lam_bad),
                   nu=pick(jnp.array(2.0, s["nu"].dtype), 2.0 * s["nu"]), steps=s["steps"] + 1)
        new["done"] = accept & stationary(new["knots"], new["cost"], new["grad"], new["gn"])
        return new

    out = jax.lax.while_loop(lambda s: ~s["done"] & (s["steps"] < max_steps), body, state)
    finite = jnp.isfinite(out["cost"]) & jnp.all(jnp.isfinite(out["knots"]))
    result = jnp.where(out["done"], result_code(SolverResult.SUCCESSFUL),
                       jnp.where(finite, result_code(SolverResult.MAX_STEPS_REACHED),
                                 result_code(SolverResult.NON_FINITE)))
    return out["knots"], result
