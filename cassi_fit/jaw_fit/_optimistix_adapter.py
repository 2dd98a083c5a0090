"""optimistix's Gauss-Newton family behind the jaw fits' solvers
(:mod:`cassi_fit.jaw_fit._solvers`), with a first-order stopping test. The one module of
the jaw fits that imports optimistix at its top; the solvers import it when they are
traced, so that a warm process, which loads the compiled fits, never imports optimistix."""

from __future__ import annotations

import jax.numpy as jnp
import optimistix as optx


class _GradientStop:
    """Mixin for optimistix's Gauss-Newton family; see :meth:`terminate`."""

    def terminate(self, fn, y, args, options, state, tags):
        """optimistix's Cauchy test (small step in ``y`` and in the residuals), or first-order
        optimality ``|J^T r|_inf <= atol (1 + |r|)`` at the last accepted point.

        The Cauchy test is only evaluated after an *accepted* step. At the minimum the
        predicted reduction is ~1e-30 and the actual one is rounding noise, so a trust-region
        solver rejects about half of its steps there; in a vmapped fit the batch then runs
        until the unluckiest frame gets an acceptance. The gradient test (MINPACK's ``gtol``)
        stops as soon as the last accepted point is stationary. Only for problems whose
        parameters are scaled so that ``J^T J`` is of order 1 (the per-frame fit: exactly
        ``2 I``), where a gradient below ``atol`` means a parameter error below ``atol``.
        """
        done, result = super().terminate(fn, y, args, options, state, tags)
        info = state.f_info
        grad = info.jac.transpose().mv(info.residual)
        norm = jnp.sqrt(jnp.sum(info.residual**2))
        stationary = (~state.first_step) & (jnp.max(jnp.abs(grad)) <= self.atol * (1.0 + norm))
        return done | stationary, result


class _StoppingLM(_GradientStop, optx.LevenbergMarquardt):
    pass


class _StoppingGN(_GradientStop, optx.GaussNewton):
    pass


class _StoppingDogleg(_GradientStop, optx.Dogleg):
    pass


_KINDS = {"LevenbergMarquardt": (optx.LevenbergMarquardt, _StoppingLM),
          "GaussNewton": (optx.GaussNewton, _StoppingGN),
          "Dogleg": (optx.Dogleg, _StoppingDogleg)}


def kinds(name: str) -> tuple[type, type]:
    """optimistix's solver class ``name`` and its subclass that also stops at a stationary
    point (:class:`_GradientStop`)."""
    return _KINDS[name]
