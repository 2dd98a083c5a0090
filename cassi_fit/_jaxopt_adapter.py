"""The one place that imports jaxopt (unmaintained upstream; kept as an alternative solver).

jaxopt warns on import that it is no longer maintained. That DeprecationWarning is caught
here, so it neither reaches users nor fails a test suite that turns warnings into errors.
Everything else in the toolkit uses optimistix; this adapter gives jaxopt's
LevenbergMarquardt and GaussNewton the same call shape as the optimistix path in
:mod:`cassi_fit.jaw_fit`: ``residuals(params, args) -> (m,)`` in, ``(params, converged)`` out.
"""

from __future__ import annotations

import functools
import warnings

METHODS = ("lm", "gn")


@functools.cache
def _jaxopt():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*JAXopt is no longer maintained.*")
        warnings.simplefilter("ignore", DeprecationWarning)
        import jaxopt
    return jaxopt


def least_squares(residuals, params0, args, *, method="lm", tol=1e-10, max_steps=100):
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
