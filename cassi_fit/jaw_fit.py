"""Least-squares jaw rotation: alternatives to, and a check on, the paper's closed form.

Data: the reference jaw ``(2, 2)`` mm (rows [MNI, MNM]) and the current jaw in ``n`` frames
``(n, 2, 2)``. Every method returns, per frame, the motion ``p' = R(theta) p + t`` taking the
reference to the frame (Eqs 4-5; :mod:`cassi_fit.rigid`), its pivot, residuals, status and
uncertainty, as a :class:`JawFit`. Methods are small objects (equinox Modules, in
optimistix's style), passed to :func:`fit_jaw` as ``method=``:

* :class:`ClosedForm` -- the paper's Eqs 1-3, 6-7 in the sound form (:func:`jaw.closed_form`).
* :class:`FrameFit` -- per frame, rotation + translation fitted to both pellets (3 parameters,
  4 residuals). Parameterised by ``(theta, t)``, never by the pivot, which is ill-conditioned
  at small theta; the pivot is derived. Its exact answer is :func:`jaw.procrustes`.
* :class:`FixedPivot` -- Parke's model: one pivot ``q`` for the recording, an angle per frame,
  ``p' = R(theta_k)(p - q) + q``. The angles are eliminated in closed form (variable
  projection: for a given ``q`` the best ``theta_k`` is one ``atan2``), so the solver sees
  2 parameters and ``4 n`` residuals; the pivot covariance is then the exact marginal.
* :class:`SmoothPivot` -- a moving pivot ``q_k`` (linear spline with a knot every
  ``knot_spacing`` frames) with a smoothness prior ``smoothness * sum |q_{k+1} - q_k|^2``
  (mm^2 per frame step, against squared pellet residuals in mm^2), angles eliminated as
  above. ``smoothness -> inf`` gives the fixed pivot; small values let the pivot follow the
  condyle's translation. Solved on its block-tridiagonal normal equations in O(n) time and
  memory (covariance too: selected inversion, never a dense matrix).

Solvers are objects too: :class:`LevenbergMarquardt` (default), :class:`GaussNewton`,
:class:`Dogleg` (optimistix), and jaxopt's ``JaxoptLevenbergMarquardt`` /
``JaxoptGaussNewton`` from :mod:`cassi_fit._jaxopt_adapter`. "smooth-pivot" uses its own
structured solver; the solver object only chooses its kind and the step budget: damped
solvers give Levenberg-Marquardt-damped Newton steps on the exact per-frame Hessians
(``JawFit.solver`` = ``"block-tridiagonal-lm"``), the Gauss-Newton solvers undamped
Gauss-Newton steps (``"block-tridiagonal-gn"``). The names users type (``"frame-fit"``,
``"optimistix-lm"``; :mod:`cassi_fit.options`) are aliases: :func:`jaw_method` and
:func:`jaw_solver` turn them into objects; :func:`fit_jaw` still accepts them.

Starts: by default the fits start from the closed form / Procrustes (the frame fit then starts
at its minimum); every fitted method takes an explicit ``start`` (documented per class), used
by the tests to start far from the answer. Uncertainty: ``s^2 (J^T J)^-1`` with ``s^2``
pooled over the recording's usable frames.
"""

from __future__ import annotations

import abc
import functools
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from . import jaw, rigid
from .errors import DegenerateGeometryError, InvalidChoiceError, MissingDataError
from .options import JAW_METHODS, SOLVERS, check_choice
from .status import STATUS_LABELS, Status

if TYPE_CHECKING:
    from .txy import PelletTrack

DEFAULT_KNOT_SPACING = 16  # frames (about 0.11 s at 145.6 Hz) between pivot-path knots
DEFAULT_MAX_STEPS = 100

ArrayLike = Array | np.ndarray


@dataclass(frozen=True)
class JawFit:
    """One recording's jaw motion, per frame (``n`` frames); numpy arrays.

    theta (n,) rad, opening positive; translation (n, 2) mm, ``p' = R(theta) p + t``
    from the reference jaw; pivot (n, 2) mm: the fixed point of the frame's motion (for
    "fixed-pivot" the recording's pivot, for "smooth-pivot" the pivot path), (0, 0) where
    undefined; pivot_defined (n,) bool; residual (n,) mm, rms pellet misfit of the frame;
    status (n,) int, a :class:`cassi_fit.status.Status` (OK, PIVOT_UNDEFINED, DEGENERATE,
    NON_FINITE, INVALID_FRAME (values interpolated), NOT_CONVERGED, MISTRACKED);
    converged: the solver reported success (all frames for "frame-fit");
    covariance (n, 3, 3) of ``(theta, tx, ty)`` (rad, mm) given the frame's data;
    pivot_covariance (n, 2, 2) mm^2 for the uncertainty ellipse (inf where undefined);
    noise_mm: the pooled pellet-noise estimate ``s``; method, solver: their alias names;
    reference_frame: the frame used as the reference by :func:`jaw_from_track` (None when
    the caller gave the reference to :func:`fit_jaw`).
    """

    theta: np.ndarray
    translation: np.ndarray
    pivot: np.ndarray
    pivot_defined: np.ndarray
    residual: np.ndarray
    status: np.ndarray
    converged: bool
    covariance: np.ndarray
    pivot_covariance: np.ndarray
    noise_mm: float
    method: str
    solver: str
    reference_frame: int | None = None

    @property
    def status_names(self) -> list[str]:
        """The status word of every frame (``"ok"``, ``"invalid-frame"``, ...)."""
        return [STATUS_LABELS.get(int(c), f"status-{int(c)}") for c in self.status]


# ------------------------------------------------------------------------- solvers
def _tolerance(dtype) -> float:
    return 1e-8 if jnp.dtype(dtype) == jnp.float64 else 1e-4


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


class Solver(eqx.Module):
    """A least-squares solver for the fitted jaw methods.

    ``rtol``/``atol``: tolerances (None: 1e-8 in float64, 1e-4 in float32); ``max_steps``:
    iteration budget. :meth:`run` is traceable (jit, vmap) and returns failure as a value.
    ``name`` is the command-line alias; ``damped`` tells smooth-pivot's structured solver
    to damp its steps (Levenberg-Marquardt) or to start undamped (Gauss-Newton). Any
    equinox Module with ``run``, ``name``, ``damped``, ``rtol`` and ``max_steps`` works as a
    solver (the jaxopt solvers of :mod:`cassi_fit._jaxopt_adapter` do).
    """

    rtol: float | None = None
    atol: float | None = None
    max_steps: int = DEFAULT_MAX_STEPS

    name: ClassVar[str] = "custom"
    damped: ClassVar[bool] = True

    def tolerances(self, dtype: np.dtype | type) -> tuple[float, float]:
        """``(rtol, atol)`` for parameters of ``dtype``."""
        tol = _tolerance(dtype)
        return (tol if self.rtol is None else self.rtol, tol if self.atol is None else self.atol)

    @abc.abstractmethod
    def run(self, residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"],
            args: Any,
            gradient_stop: bool = False) -> tuple[Float[Array, " p"], Bool[Array, ""]]:
        """Minimise ``|residuals(params, args)|^2`` from ``params0``: ``(params, success)``."""


class _Optimistix(Solver):
    _kinds: ClassVar[tuple[type, type]]

    def run(self, residuals, params0, args, gradient_stop=False):
        rtol, atol = self.tolerances(params0.dtype)
        solver = self._kinds[int(bool(gradient_stop))](rtol=rtol, atol=atol)
        sol = optx.least_squares(residuals, solver, params0, args, max_steps=self.max_steps,
                                 throw=False)
        return sol.value, sol.result == optx.RESULTS.successful


class LevenbergMarquardt(_Optimistix):
    """optimistix's Levenberg-Marquardt (alias ``"optimistix-lm"``; the default)."""

    name: ClassVar[str] = "optimistix-lm"
    _kinds: ClassVar[tuple[type, type]] = (optx.LevenbergMarquardt, _StoppingLM)


class GaussNewton(_Optimistix):
    """optimistix's Gauss-Newton (alias ``"optimistix-gn"``)."""

    name: ClassVar[str] = "optimistix-gn"
    damped: ClassVar[bool] = False
    _kinds: ClassVar[tuple[type, type]] = (optx.GaussNewton, _StoppingGN)


class Dogleg(_Optimistix):
    """optimistix's Dogleg trust region (alias ``"optimistix-dogleg"``)."""

    name: ClassVar[str] = "optimistix-dogleg"
    _kinds: ClassVar[tuple[type, type]] = (optx.Dogleg, _StoppingDogleg)


def jaw_solver(name: str, *, max_steps: int = DEFAULT_MAX_STEPS) -> Any:
    """The solver object for a command-line alias in :data:`cassi_fit.options.SOLVERS`."""
    check_choice("solver", name, SOLVERS)
    if name.startswith("jaxopt-"):
        from . import _jaxopt_adapter

        kind = {"jaxopt-lm": _jaxopt_adapter.JaxoptLevenbergMarquardt,
                "jaxopt-gn": _jaxopt_adapter.JaxoptGaussNewton}[name]
        return kind(max_steps=max_steps)
    kind = {"optimistix-lm": LevenbergMarquardt, "optimistix-gn": GaussNewton,
            "optimistix-dogleg": Dogleg}[name]
    return kind(max_steps=max_steps)


def _as_solver(solver: Any) -> Any:
    if isinstance(solver, str):
        return jaw_solver(solver)
    if not (isinstance(solver, eqx.Module) and callable(getattr(solver, "run", None))):
        raise InvalidChoiceError(f"solver must be a solver object or one of "
                                 f"{', '.join(SOLVERS)}, not {solver!r}")
    return solver


def _minimise(solver, residuals, params0, args, gradient_stop):
    """The solve step of every generic fit (one place, so a test can stub it out)."""
    return solver.run(residuals, params0, args, gradient_stop)


def solve(residuals: Callable[..., Float[Array, " m"]], params0: Float[Array, " p"], args: Any,
          solver: Any = "optimistix-lm", gradient_stop: bool = False
          ) -> tuple[Float[Array, " p"], Bool[Array, ""]]:
    """Minimise ``|residuals(params, args)|^2`` from ``params0`` with ``solver`` (an object or
    an alias). Traceable (jit/vmap). Returns ``(params, converged)``; failure comes back as
    a value, never as an exception from traced code.

    ``converged`` is the solver's own verdict, or a Gauss-Newton step from the answer that
    would gain less than the cost can resolve (Newton decrement ``g^T (J^T J)^+ g <=
    max(tol^2, 100 eps) (1 + |r|^2)``, scale-free in the parameters): a trust-region solver
    sitting exactly on the minimum may stop by shrinking its region without declaring
    success. ``gradient_stop`` also ends the optimistix solvers at a stationary point
    (:class:`_GradientStop`); use it only with well-scaled parameters.
    """
    solver = _as_solver(solver)
    params, converged = _minimise(solver, residuals, params0, args, gradient_stop)
    res = residuals(params, args)
    jac = jax.jacfwd(residuals)(params, args)
    grad = jac.T @ res
    normal = jac.T @ jac
    # a rounding-level ridge instead of a pseudo-inverse (an SVD per frame costs more than
    # the whole solve when vmapped); parameters without effect have zero gradient anyway
    ridge = 1e-12 * jnp.trace(normal) + jnp.finfo(normal.dtype).tiny
    eye = jnp.eye(normal.shape[0], dtype=normal.dtype)
    decrement = grad @ jnp.linalg.solve(normal + ridge * eye, grad)
    floor = jnp.maximum(_tolerance(params0.dtype) ** 2, 100 * jnp.finfo(params.dtype).eps)
    stationary = decrement <= floor * (1.0 + jnp.sum(res**2))
    return params, converged | stationary


# ------------------------------------------------------------- residual functions
def rigid_residuals(params: Float[Array, "3"], args: Any) -> Float[Array, "4"]:
    """One frame, ``params = (theta, tx, ty)``: ``R p_i + t - p_i'`` for both pellets, (4,) mm."""
    reference, current = args
    return (rigid.apply(params[0], params[1:], reference) - current).ravel()


def _frame_scale(reference):
    """Centroid ``c`` (2,) and rms radius ``ell`` (mm) of the reference jaw points."""
    centre = jnp.mean(reference, axis=0)
    return centre, jnp.sqrt(jnp.mean(jnp.sum((reference - centre) ** 2, axis=-1)))


def scaled_rigid_residuals(z: Float[Array, "3"], args: Any) -> Float[Array, "4"]:
    """One frame in scaled, centred coordinates ``z = (ell theta, s)``, (4,) mm.

    ``p' = R(theta)(p - c) + c + s`` with ``c`` the reference centroid and ``ell`` its rms
    radius. Both parameters are then in mm and decoupled: ``J^T J = 2 I`` at every ``z``
    (the rotation column sums to zero over the two pellets about their centroid), so the
    Levenberg-Marquardt damping ``lambda I`` acts evenly on all three.
    """
    reference, current = args
    centre, ell = _frame_scale(reference)
    theta = z[0] / ell
    return (rigid.apply(theta, z[1:], reference - centre) + centre - current).ravel()


def _unscale(z, reference):
    """``(ell theta, s)`` -> ``(theta, t)`` with ``t = c + s - R(theta) c``."""
    centre, ell = _frame_scale(reference)
    theta = z[0] / ell
    return jnp.concatenate([theta[None], centre + z[1:] - rigid.apply(theta, jnp.zeros(2), centre)])


def _scale(y, reference):
    """``(theta, t)`` -> ``(ell theta, s)``, the inverse of :func:`_unscale`."""
    centre, ell = _frame_scale(reference)
    s = y[1:] + rigid.apply(y[0], jnp.zeros(2), centre) - centre
    return jnp.concatenate([(ell * y[0])[None], s])


def best_angle_about(pivot: Float[Array, "2"], reference: Float[Array, "2 2"],
                     current: Float[Array, "2 2"]) -> Float[Array, ""]:
    """The theta minimising ``sum_i |R(theta)(p_i - q) + q - p_i'|^2``, one frame, rad.

    ``argmax_theta sum_i v_i . R u_i`` with ``u = p - q``, ``v = p' - q``: one atan2.
    Where both sums vanish (pellets on the pivot) theta is 0, gradient 0 (double-where).
    """
    u, v = reference - pivot, current - pivot
    cross = jnp.sum(v[:, 0] * u[:, 1] - v[:, 1] * u[:, 0])
    dot = jnp.sum(u * v)
    ok = (cross != 0.0) | (dot != 0.0)
    return jnp.where(ok, jnp.arctan2(jnp.where(ok, cross, 0.0), jnp.where(ok, dot, 1.0)), 0.0)


def _about_pivot(pivot, reference, current, weight):
    """Weighted residuals (4,) of one frame turned about ``pivot`` by its best angle."""
    theta = best_angle_about(pivot, reference, current)
    moved = rigid.apply(*rigid.from_pivot(theta, pivot), reference)
    return weight * (moved - current).ravel()


_about_pivot_frames = jax.vmap(_about_pivot, in_axes=(None, None, 0, 0))
_about_pivots_frames = jax.vmap(_about_pivot, in_axes=(0, None, 0, 0))


def fixed_pivot_residuals(pivot: Float[Array, "2"], args: Any) -> Float[Array, " 4n"]:
    """Parke's fixed pivot, angles projected out: ``pivot`` (2,) mm -> residuals (4 n,) mm."""
    reference, current, weight = args
    return _about_pivot_frames(pivot, reference, current, weight).ravel()


def _spline(knots, n, spacing):
    """Piecewise-linear path (n, 2) through ``knots`` (m, 2) placed every ``spacing`` frames."""
    k = jnp.arange(n)
    j = k // spacing
    f = (k % spacing / spacing)[:, None]
    return (1.0 - f) * knots[j] + f * knots[jnp.minimum(j + 1, knots.shape[0] - 1)]


def smooth_pivot_residuals(knots: Float[Array, " 2m"], args: Any) -> Float[Array, " r"]:
    """Moving pivot: knots (2 m,) mm, flattened (m, 2) -> data residuals (4 n,) and prior
    residuals (2 (m-1),). For reference and tests on small problems (the fit itself never
    forms this vector's Jacobian).

    The prior is ``sqrt(smoothness) * (q_{k+1} - q_k)`` summed exactly over the frames of
    each knot interval: ``|dQ|^2 / spacing`` per interval.
    """
    reference, current, weight, smoothness, spacing = args
    knots = knots.reshape(-1, 2)
    path = _spline(knots, current.shape[0], spacing)
    data = _about_pivots_frames(path, reference, current, weight).ravel()
    prior = jnp.sqrt(smoothness / spacing) * (knots[1:] - knots[:-1]).ravel()
    return jnp.concatenate([data, prior])


# ------------------------------------------------ block-tridiagonal linear algebra
def block_tridiagonal_solve(diag: Float[Array, "m 2 2"], upper: Float[Array, "m-1 2 2"],
                            rhs: Float[Array, "m 2"]) -> Float[Array, "m 2"]:
    """Solve ``N x = rhs`` for a symmetric block-tridiagonal ``N`` with 2x2 blocks.

    diag (m, 2, 2) = ``N_jj``, upper (m - 1, 2, 2) = ``N_j,j+1`` (``N_j+1,j`` is its
    transpose), rhs (m, 2). Block Thomas algorithm (block LDL^T; stable for positive
    definite ``N``): O(m) time and memory in one forward and one backward ``lax.scan``.
    """
    zero = jnp.zeros_like(diag[0])
    upper_pad = jnp.concatenate([upper, zero[None]])
    lower_prev = jnp.concatenate([zero[None], upper])  # N_j,j-1 = upper[j-1]^T

    def forward(carry, blocks):
        c_prev, d_prev = carry
        dj, uj, lj, bj = blocks
        lt = lj.T
        pivot = dj - lt @ c_prev
        c = jnp.linalg.solve(pivot, uj)
        d = jnp.linalg.solve(pivot, bj - lt @ d_prev)
        return (c, d), (c, d)

    _, (c, d) = jax.lax.scan(forward, (zero, jnp.zeros_like(rhs[0])),
                             (diag, upper_pad, lower_prev, rhs))

    def backward(x_next, blocks):
        cj, dj = blocks
        x = dj - cj @ x_next
        return x, x

    _, x = jax.lax.scan(backward, jnp.zeros_like(rhs[0]), (c, d), reverse=True)
    return x


def block_tridiagonal_inverse_blocks(
    diag: Float[Array, "m 2 2"], upper: Float[Array, "m-1 2 2"]
) -> tuple[Float[Array, "m 2 2"], Float[Array, "m-1 2 2"]]:
    """The blocks ``(C_jj, C_j,j+1)`` of ``C = N^-1`` for the symmetric positive definite
    block-tridiagonal ``N`` of :func:`block_tridiagonal_solve` (selected inversion).

    Forward: Schur complements ``S_0 = N_00``, ``S_j = N_jj - U_j-1^T S_j-1^-1 U_j-1``.
    Backward (as in a Rauch-Tung-Striebel smoother): ``C_m-1 = S_m-1^-1``,
    ``G_j = S_j^-1 U_j``, ``C_jj = S_j^-1 + G_j C_j+1,j+1 G_j^T``,
    ``C_j,j+1 = -G_j C_j+1,j+1``. O(m) time and memory; the dense inverse is never formed.
    """
    zero = jnp.zeros_like(diag[0])
    lower_prev = jnp.concatenate([zero[None], upper])

    def forward(s_inv_prev, blocks):
        dj, uprev = blocks
        s_inv = jnp.linalg.inv(dj - uprev.T @ s_inv_prev @ uprev)
        return s_inv, s_inv

    _, s_inv = jax.lax.scan(forward, zero, (diag, lower_prev))

    def backward(c_next, blocks):
        s_inv_j, uj = blocks
        g = s_inv_j @ uj
        c = s_inv_j + g @ c_next @ g.T
        return c, (c, -g @ c_next)

    last = s_inv[-1]
    _, (head, up) = jax.lax.scan(backward, last, (s_inv[:-1], upper), reverse=True)
    return jnp.concatenate([head, last[None]]), up


def _block_quadratic(diag, upper, x):
    """``x^T N x`` for the block-tridiagonal ``N`` of :func:`block_tridiagonal_solve`."""
    return (jnp.einsum("ji,jik,jk->", x, diag, x)
            + 2.0 * jnp.einsum("ji,jik,jk->", x[:-1], upper, x[1:]))


# ----------------------------------------------------- smooth pivot: structured solver
def _smooth_pivot_system(knots, reference, current, weight, smoothness, spacing, newton):
    """Cost, gradient (m, 2), the step matrix and the Gauss-Newton normal matrix of
    :func:`smooth_pivot_residuals` at ``knots`` (m, 2); each matrix block-tridiagonal as
    ``(diag (m, 2, 2), upper (m-1, 2, 2))``.

    Assembled from per-frame blocks: frame ``k`` depends on its pivot ``q_k = (1-f) Q_j + f
    Q_j+1`` only, through a (4, 2) Jacobian ``J_k`` (angle projected out), so it adds
    ``w w' A_k`` to blocks (j, j), (j, j+1), (j+1, j+1) with ``A_k = J_k^T J_k`` (Gauss-Newton)
    or, for the step matrix when ``newton``, the exact 2x2 Hessian of the frame's cost
    ``|r_k|^2 / 2``. The Gauss-Newton matrix of the projected residuals misses the
    curvature the eliminated angle brings in; where the data hold little pivot information
    (slow movement) Gauss-Newton then converges only linearly (rate 0.8 on a 200,000-line
    recording with one opening per 5 s), Newton in 6-7 steps. The prior adds
    ``smoothness / spacing`` times the difference operator. O(n) memory: never forms the
    (4 n, 2 m) Jacobian nor the (n, m) spline weights.
    """
    n, m = current.shape[0], knots.shape[0]
    k = jnp.arange(n)
    j = k // spacing
    f = (k % spacing) / spacing
    path = (1.0 - f)[:, None] * knots[j] + f[:, None] * knots[j + 1]

    def frame(q, cur, w):
        def r(p):
            return _about_pivot(p, reference, cur, w)

        jac, res = jax.jacfwd(r)(q), r(q)
        gn = jac.T @ jac
        hess = jax.hessian(lambda p: 0.5 * jnp.sum(r(p) ** 2))(q) if newton else gn
        return gn, hess, jac.T @ res, res

    a_gn, a_step, g, res = jax.vmap(frame)(path, current, weight)
    w0, w1 = 1.0 - f, f
    lam = smoothness / spacing
    eye = jnp.eye(2, dtype=a_gn.dtype)
    ends = jnp.zeros(m, a_gn.dtype).at[:-1].add(1.0).at[1:].add(1.0)

    def blocks(a):
        diag = jnp.zeros((m, 2, 2), a.dtype).at[j].add(w0[:, None, None] ** 2 * a)
        diag = diag.at[j + 1].add(w1[:, None, None] ** 2 * a)
        upper = jnp.zeros((m - 1, 2, 2), a.dtype).at[j].add((w0 * w1)[:, None, None] * a)
        return diag + lam * ends[:, None, None] * eye, upper - lam * eye

    step = knots[1:] - knots[:-1]
    grad = jnp.zeros((m, 2), g.dtype).at[j].add(w0[:, None] * g).at[j + 1].add(w1[:, None] * g)
    grad = grad.at[:-1].add(-lam * step).at[1:].add(lam * step)
    cost = 0.5 * (jnp.sum(res**2) + lam * jnp.sum(step**2))
    gn = blocks(a_gn)
    return cost, grad, (blocks(a_step) if newton else gn), gn


def _minimise_block_tridiagonal(system, knots0, *, damped, max_steps, tol):
    """Levenberg-Marquardt-damped steps on block-tridiagonal systems: ``system(knots) ->
    (cost, grad, step matrix, Gauss-Newton matrix)`` (matrices as ``(diag, upper)``).
    ``damped``: ``lambda I`` added from the start, Nielsen's update of ``lambda``; else
    ``lambda = 0`` until a step fails to reduce the cost, then damped the same way.
    Returns ``(knots, converged)``. Converged: at an accepted point the Gauss-Newton step
    (always positive semi-definite, so a safe test even where the step matrix is not) is
    below ``tol (1 + max |Q|)`` mm, or its predicted reduction ``g^T N^-1 g`` is below
    ``max(tol^2, 100 eps) (1 + 2 cost)`` mm^2: a gain that the cost (a sum over thousands
    of frames) cannot resolve in floating point.
    """

    def stationary(knots, cost, grad, gn):
        # a rounding-level ridge keeps knots without data finite
        newton = block_tridiagonal_solve(gn[0] + ridge * jnp.eye(2), gn[1], -grad)
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
        delta = block_tridiagonal_solve(diag + s["lam"] * jnp.eye(2), upper, -s["grad"])
        trial = s["knots"] + delta
        t_cost, t_grad, t_mat, t_gn = system(trial)
        predicted = -(jnp.sum(s["grad"] * delta) + 0.5 * _block_quadratic(diag, upper, delta))
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
    return out["knots"], out["done"]


@eqx.filter_jit
def _smooth_pivot_kernel(config, reference, current, weight, smoothness, knots0):
    """Compiled smooth-pivot fit. ``config = (damped, max_steps, tol, spacing)`` (static).
    Returns the pivot path (n, 2), its unit covariance (n, 2, 2) (``(J^T J)^-1`` blocks
    mapped through the spline, selected inversion) and the convergence verdict."""
    damped, max_steps, tol, spacing = config
    n = current.shape[0]

    def system(knots):
        return _smooth_pivot_system(knots, reference, current, weight, smoothness, spacing,
                                    newton=damped)

    knots, converged = _minimise_block_tridiagonal(system, knots0, damped=damped,
                                                   max_steps=max_steps, tol=tol)
    _, _, _, (diag, upper) = system(knots)
    ridge = 1e-12 * jnp.max(jnp.abs(jnp.diagonal(diag, axis1=1, axis2=2)))
    c_diag, c_up = block_tridiagonal_inverse_blocks(diag + ridge * jnp.eye(2), upper)
    k = jnp.arange(n)
    j = k // spacing
    f = ((k % spacing) / spacing)[:, None, None]
    c01 = c_up[j]
    # pivot q_k = (1 - f) Q_j + f Q_j+1: only blocks (j, j), (j, j+1), (j+1, j+1) matter
    unit_cov = ((1 - f) ** 2 * c_diag[j] + (1 - f) * f * (c01 + jnp.swapaxes(c01, 1, 2))
                + f**2 * c_diag[j + 1])
    return _spline(knots, n, spacing), unit_cov, converged


# ---------------------------------------------------------------- compiled kernels
def _motion_params(motion):
    return jnp.concatenate([motion.theta[None], motion.translation])


def _unit_covariance(params, reference, current):
    """``(J^T J)^-1`` (3, 3) of the frame's rigid residuals at ``params``."""
    jac = jax.jacfwd(rigid_residuals)(params, (reference, current))
    return jnp.linalg.inv(jac.T @ jac)


@eqx.filter_jit
def _closed_form_kernel(reference, current):
    """Per frame: the closed form, and noise propagated through it: ``G G^T`` with
    ``G = d(theta, t)/d(current)``."""

    def one(cur):
        y = _motion_params(jaw.closed_form(reference, cur))
        g = jax.jacfwd(lambda c: _motion_params(jaw.closed_form(reference, c)))(cur)
        g = g.reshape(3, 4)
        return y, rigid_residuals(y, (reference, cur)), jnp.array(True), g @ g.T

    return jax.vmap(one)(current)


@eqx.filter_jit
def _frame_fit_kernel(solver, reference, current, start):
    """Per frame least squares from ``start`` (n, 3) motions (None: each frame's Procrustes
    motion): ``(params, residuals, converged, unit covariance)``."""
    if start is None:
        start = jax.vmap(lambda c: _motion_params(jaw.procrustes(reference, c)))(current)

    def one(cur, y0):
        z, converged = solve(scaled_rigid_residuals, _scale(y0, reference), (reference, cur),
                             solver, gradient_stop=True)
        y = _unscale(z, reference)
        return y, rigid_residuals(y, (reference, cur)), converged, _unit_covariance(
            y, reference, cur)

    return jax.vmap(one)(current, start)


@eqx.filter_jit
def _fixed_pivot_kernel(solver, reference, current, weight, pivot0):
    """Compiled fixed-pivot fit: ``-> (q, converged, J)``."""
    args = (reference, current, weight)
    pivot, converged = solve(fixed_pivot_residuals, pivot0, args, solver)
    return pivot, converged, jax.jacfwd(fixed_pivot_residuals)(pivot, args)


@jax.jit
@functools.partial(jax.vmap, in_axes=(None, 0, 0))
def _about_pivot_params(reference, current, pivot):
    """Per frame: best angle about ``pivot`` -> params (theta, tx, ty), unit covariance."""
    theta, t = rigid.from_pivot(best_angle_about(pivot, reference, current), pivot)
    y = jnp.concatenate([theta[None], t])
    return y, _unit_covariance(y, reference, current)


@jax.jit
@jax.vmap
def _pivot_with_covariance(params, covariance):
    """The fixed point of ``params = (theta, tx, ty)`` and its (2, 2) covariance."""

    def fixed_point(y):
        return rigid.pivot((y[0], y[1:]))[0]

    point, defined = rigid.pivot((params[0], params[1:]))
    jac = jax.jacfwd(fixed_point)(params)
    cov = jnp.where(defined, jac @ covariance @ jac.T, jnp.diag(jnp.full(2, jnp.inf)))
    return point, defined, cov


_closed_form_frames = jax.jit(jax.vmap(jaw.closed_form, in_axes=(None, 0)))
_procrustes_frames = jax.jit(jax.vmap(jaw.procrustes, in_axes=(None, 0)))
_frame_residuals = jax.jit(jax.vmap(rigid_residuals, in_axes=(0, (None, 0))))
_translation_about = jax.jit(jax.vmap(lambda theta, q: rigid.from_pivot(theta, q)[1]))


# ---------------------------------------------------------------------- helpers
def _interpolate(values, usable):
    """Fill unusable frames of ``values`` (n, ...) by linear interpolation over frame index
    (held constant beyond the ends)."""
    frames = np.arange(values.shape[0])
    flat = values.reshape(values.shape[0], -1).copy()
    for col in range(flat.shape[1]):
        flat[:, col] = np.interp(frames, frames[usable], flat[usable, col])
    return flat.reshape(values.shape)


def _check_reference(reference):
    if not np.all(np.isfinite(reference)):
        raise MissingDataError("jaw reference: MNI or MNM untracked (non-finite) in the reference")
    if np.all(reference[0] == reference[1]):
        raise DegenerateGeometryError(
            f"jaw reference: MNI and MNM coincide at {reference[0].tolist()} mm"
        )


def _prepare(reference, current, valid):
    """Validate; returns (reference, safe current, usable mask, base status)."""
    reference = np.asarray(reference, dtype=float)
    current = np.asarray(current, dtype=float)
    if reference.shape != (2, 2) or current.ndim != 3 or current.shape[1:] != (2, 2):
        raise ValueError(
            f"jaw data: expected reference (2, 2) and current (n, 2, 2), got "
            f"{reference.shape} and {current.shape}"
        )
    _check_reference(reference)
    n = current.shape[0]
    valid = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
    if valid.shape != (n,):
        raise ValueError(f"jaw data: valid must have shape ({n},), got {valid.shape}")
    status = np.asarray(_closed_form_frames(reference, current).status).astype(np.int32)
    status = np.where(valid, status, Status.INVALID_FRAME)
    usable = status <= Status.PIVOT_UNDEFINED
    if not usable.any():
        raise MissingDataError("jaw data: no frame where both jaw pellets are tracked")
    safe = np.where(usable[:, None, None], current, reference[None])
    return reference, safe, usable, np.where(usable, 0, status).astype(np.int32)


def _noise_variance(residuals, usable, n_params):
    dof = 4 * int(usable.sum()) - n_params
    return float(np.sum(residuals[usable] ** 2) / dof) if dof > 0 else 0.0


def _initial_pivot(reference, current, usable):
    """Linear least squares for ``q`` in ``t_k = (I - R_k) q`` from Procrustes motions.

    ``(I - R)^T (I - R) = (2 - 2 cos theta) I``, so frames weigh in by their rotation.
    """
    m = _procrustes_frames(reference, current)
    theta, t = np.asarray(m.theta)[usable], np.asarray(m.translation)[usable]
    gain = np.sum(2.0 - 2.0 * np.cos(theta))
    if gain == 0.0:
        raise DegenerateGeometryError("jaw data: the jaw never rotates, so no pivot exists")
    c, s = np.cos(theta), np.sin(theta)
    # (I - R)^T t with R = [[c, s], [-s, c]]
    rhs = np.stack([(1 - c) * t[:, 0] + s * t[:, 1], -s * t[:, 0] + (1 - c) * t[:, 1]], -1)
    return rhs.sum(axis=0) / gain


def _optional_array(shape_doc):
    def convert(value):
        return None if value is None else np.asarray(value, dtype=float)

    convert.__doc__ = shape_doc
    return convert


# ---------------------------------------------------------------------- methods
class _Estimate(NamedTuple):
    params: np.ndarray  # (n, 3) theta, tx, ty
    residuals: np.ndarray  # (n, 4) mm
    unit_cov: np.ndarray  # (n, 3, 3)
    frame_ok: np.ndarray  # (n,) bool: converged
    n_params: int
    path: np.ndarray | None = None  # (n, 2) pivot path of the pivot models
    unit_pivot_cov: np.ndarray | None = None  # (n, 2, 2)


class JawMethod(eqx.Module):
    """A jaw-motion method: an object passed to :func:`fit_jaw` as ``method=``; ``name`` is
    its command-line alias (:data:`cassi_fit.options.JAW_METHODS`)."""

    name: ClassVar[str]

    @abc.abstractmethod
    def _estimate(self, reference, current, usable) -> _Estimate:
        """Per-frame motion of ``current`` (usable frames filled with the reference)."""

    @property
    def solver_name(self) -> str:
        """What ``JawFit.solver`` reports."""
        return self.solver.name


class ClosedForm(JawMethod):
    """The paper's Eqs 1-3, 6-7 in the numerically sound form, per frame; no solver."""

    name: ClassVar[str] = "closed-form"

    @property
    def solver_name(self) -> str:
        return "closed-form"

    def _estimate(self, reference, current, usable):
        params, res, ok, unit_cov = (np.asarray(a) for a in _closed_form_kernel(reference,
                                                                                 current))
        return _Estimate(params, res, unit_cov, ok | ~usable, 3 * int(usable.sum()))


class FrameFit(JawMethod):
    """Rotation + translation fitted to both pellets, per frame (vmapped).

    solver: a solver object (default :class:`LevenbergMarquardt`) or an alias.
    start: None (the Procrustes motion, i.e. the minimum: the solver confirms it), or the
    initial motion ``(theta rad, tx mm, ty mm)``, shape (3,) for every frame or (n, 3).
    """

    solver: Any = eqx.field(default=LevenbergMarquardt(), converter=_as_solver)
    start: Float[np.ndarray, "*n 3"] | None = eqx.field(
        default=None, converter=_optional_array("(3,) or (n, 3)"))

    name: ClassVar[str] = "frame-fit"

    def _estimate(self, reference, current, usable):
        n = current.shape[0]
        start = None if self.start is None else jnp.asarray(
            np.broadcast_to(self.start, (n, 3)), jnp.asarray(reference).dtype)
        params, res, converged, unit_cov = (np.asarray(a) for a in _frame_fit_kernel(
            self.solver, reference, current, start))
        return _Estimate(params, res, unit_cov, converged | ~usable, 3 * int(usable.sum()))


class FixedPivot(JawMethod):
    """Parke's fixed pivot: one pivot for the recording, one angle per frame (projected out).

    solver: a solver object or an alias. start: None (linear least squares on the
    Procrustes motions, ``t_k = (I - R_k) q``) or the initial pivot (2,) mm.
    """

    solver: Any = eqx.field(default=LevenbergMarquardt(), converter=_as_solver)
    start: Float[np.ndarray, "2"] | None = eqx.field(
        default=None, converter=_optional_array("(2,) mm"))

    name: ClassVar[str] = "fixed-pivot"

    def _estimate(self, reference, current, usable):
        pivot0 = _initial_pivot(reference, current, usable) if self.start is None else self.start
        pivot, converged, jac = _fixed_pivot_kernel(
            self.solver, reference, current, usable.astype(float),
            jnp.asarray(pivot0, jnp.asarray(reference).dtype))
        jac = np.asarray(jac)
        n = current.shape[0]
        path = np.broadcast_to(np.asarray(pivot), (n, 2))
        unit = np.broadcast_to(np.linalg.pinv(jac.T @ jac), (n, 2, 2))
        return _pivot_estimate(reference, current, usable, path, unit, bool(converged), 2)


class SmoothPivot(JawMethod):
    """A pivot moving along a linear spline (a knot every ``knot_spacing`` frames) with the
    smoothness prior ``smoothness * sum_k |q_k+1 - q_k|^2`` (mm^2 per frame step).

    smoothness: finite and > 0 (``inf`` is :class:`FixedPivot`). solver: chooses damping
    (``damped`` solvers: Levenberg-Marquardt; Gauss-Newton ones: undamped first) and the
    step budget of the structured block-tridiagonal solver (damped: Newton steps on the
    exact per-frame Hessians; Gauss-Newton solvers: Gauss-Newton steps). start: None (as
    :class:`FixedPivot`) or an initial pivot (2,) mm for every knot.
    """

    smoothness: float = 1.0
    knot_spacing: int = DEFAULT_KNOT_SPACING
    solver: Any = eqx.field(default=LevenbergMarquardt(), converter=_as_solver)
    start: Float[np.ndarray, "2"] | None = eqx.field(
        default=None, converter=_optional_array("(2,) mm"))

    name: ClassVar[str] = "smooth-pivot"

    def __check_init__(self):
        try:
            value = float(self.smoothness)
        except (TypeError, ValueError):
            value = float("nan")
        if not (np.isfinite(value) and value > 0.0):
            raise InvalidChoiceError(
                f"smoothness must be a finite number > 0, got {self.smoothness!r}")
        if int(self.knot_spacing) != self.knot_spacing or self.knot_spacing < 1:
            raise InvalidChoiceError(
                f"knot_spacing must be a whole number of frames >= 1, got {self.knot_spacing!r}")

    @property
    def solver_name(self) -> str:
        return "block-tridiagonal-" + ("lm" if self.solver.damped else "gn")

    def _estimate(self, reference, current, usable):
        n, spacing = current.shape[0], int(self.knot_spacing)
        m = (n - 1) // spacing + 2
        pivot0 = _initial_pivot(reference, current, usable) if self.start is None else self.start
        dtype = jnp.asarray(reference).dtype
        tol = self.solver.tolerances(dtype)[0]
        config = (bool(self.solver.damped), int(self.solver.max_steps), float(tol), spacing)
        path, unit, converged = _smooth_pivot_kernel(
            config, reference, current, usable.astype(float),
            jnp.asarray(float(self.smoothness), dtype),
            jnp.asarray(np.tile(pivot0, (m, 1)), dtype))
        return _pivot_estimate(reference, current, usable, np.asarray(path), np.asarray(unit),
                               bool(converged), 2 * m)


def _pivot_estimate(reference, current, usable, path, unit_pivot_cov, converged, n_extra):
    params, unit_cov = (np.asarray(a) for a in _about_pivot_params(reference, current, path))
    res = np.asarray(_frame_residuals(params, (reference, current)))
    return _Estimate(params, res, unit_cov, np.full(len(usable), converged),
                     int(usable.sum()) + n_extra, path, unit_pivot_cov)


def jaw_method(name: str, *, solver: Any = "optimistix-lm", smoothness: float = 1.0,
               knot_spacing: int = DEFAULT_KNOT_SPACING) -> JawMethod:
    """The method object for a command-line alias (:data:`cassi_fit.options.JAW_METHODS`).

    ``solver`` (object or alias in :data:`cassi_fit.options.SOLVERS`; checked even for
    "closed-form", which does not use it), ``smoothness`` and ``knot_spacing`` (frames)
    for "smooth-pivot". Raises :class:`~cassi_fit.errors.InvalidChoiceError` on a bad name,
    solver or smoothness.
    """
    check_choice("jaw method", name, JAW_METHODS)
    solver = _as_solver(solver)
    if name == "closed-form":
        return ClosedForm()
    if name == "frame-fit":
        return FrameFit(solver=solver)
    if name == "fixed-pivot":
        return FixedPivot(solver=solver)
    return SmoothPivot(smoothness=smoothness, knot_spacing=knot_spacing, solver=solver)


def _as_method(method, solver, smoothness, knot_spacing) -> JawMethod:
    if isinstance(method, str):
        options = {k: v for k, v in (("solver", solver), ("smoothness", smoothness),
                                      ("knot_spacing", knot_spacing)) if v is not None}
        return jaw_method(method, **options)
    if not isinstance(method, JawMethod):
        raise InvalidChoiceError(f"method must be a jaw method object or one of "
                                 f"{', '.join(JAW_METHODS)}, not {method!r}")
    if any(v is not None for v in (solver, smoothness, knot_spacing)):
        raise InvalidChoiceError("solver, smoothness and knot_spacing belong to the method "
                                 "object (e.g. SmoothPivot(smoothness=...)), not to fit_jaw")
    return method


def fit_jaw(
    reference: Float[ArrayLike, "2 2"],
    current: Float[ArrayLike, "n 2 2"],
    *,
    method: JawMethod | str = "closed-form",
    valid: Bool[ArrayLike, " n"] | None = None,
    solver: Any = None,
    smoothness: float | None = None,
    knot_spacing: int | None = None,
) -> JawFit:
    """Jaw motion from ``reference`` (2, 2) mm [MNI, MNM] to each frame of ``current``
    (n, 2, 2) mm, by ``method``: an object (:class:`ClosedForm`, :class:`FrameFit`,
    :class:`FixedPivot`, :class:`SmoothPivot`) or its alias; with an alias, ``solver``,
    ``smoothness`` and ``knot_spacing`` are passed on to :func:`jaw_method` (the old call
    form). ``valid`` (n,) bool marks frames to use; the others, and frames with an
    untracked or coincident jaw pellet, get a status and interpolated values.
    Raises :class:`MissingDataError` / :class:`DegenerateGeometryError` when no motion
    can be computed at all (untracked or coincident reference, no usable frame, no rotation
    for a pivot model), :class:`InvalidChoiceError` for a bad method or option.
    """
    method = _as_method(method, solver, smoothness, knot_spacing)
    reference, current, usable, base_status = _prepare(reference, current, valid)
    est = method._estimate(reference, current, usable)
    s2 = _noise_variance(est.residuals, usable, est.n_params)
    covariance = np.where(usable[:, None, None], s2 * est.unit_cov, 0.0)
    params = _interpolate(est.params, usable)
    if est.path is None:
        pivot, defined, pivot_cov = (
            np.asarray(a) for a in _pivot_with_covariance(params, covariance)
        )
        pivot = np.where(defined[:, None], pivot, 0.0)
    else:
        pivot, defined = np.asarray(est.path, float), np.ones(len(usable), bool)
        pivot_cov = s2 * np.asarray(est.unit_pivot_cov)
        params[:, 1:] = np.asarray(_translation_about(params[:, 0], pivot))
    status = np.where(defined, Status.OK, Status.PIVOT_UNDEFINED)
    status = np.where(est.frame_ok, status, Status.NOT_CONVERGED)
    status = np.where(usable, status, base_status).astype(np.int32)
    residual = np.sqrt(np.sum(est.residuals**2, axis=1) / 2.0)  # rms over the two pellets
    return JawFit(
        theta=params[:, 0], translation=params[:, 1:], pivot=pivot,
        pivot_defined=defined & usable, residual=np.where(usable, residual, 0.0),
        status=status, converged=bool(est.frame_ok.all()), covariance=covariance,
        pivot_covariance=pivot_cov, noise_mm=float(np.sqrt(s2)), method=method.name,
        solver=method.solver_name,
    )


def jaw_from_track(track: PelletTrack, *, method: JawMethod | str = "closed-form",
                   reference_frame: int | None = None, **options: Any) -> JawFit:
    """:func:`fit_jaw` on a :class:`cassi_fit.txy.PelletTrack`'s MNI and MNM pellets.

    Values flagged by the mistrack detector (:func:`cassi_fit.mistracks.detect_mistracks`)
    are not used: their frames get status MISTRACKED (values interpolated, as for
    untracked frames, which get INVALID_FRAME). The reference is ``reference_frame`` (an
    index in ``[0, n)`` whose jaw pellets are tracked and not mistracked) or, by default,
    the first frame in which both jaw pellets are tracked and neither is mistracked:
    CASSI's first valid line for the jaw, moved past a mistracked line so that one bad
    value cannot tilt every frame. ``options`` (``solver``, ``smoothness``, ...) go to
    :func:`fit_jaw` with a method alias. Errors name the file.
    """
    from .mistracks import detect_mistracks
    from .pellets import JAW_PELLETS, first_valid_line, pellet_index

    where = str(track.path) if track.path is not None else "<pellet track>"
    cols = [pellet_index(p) for p in JAW_PELLETS]
    tracked = track.frame_valid(JAW_PELLETS)
    flags = detect_mistracks(track)
    mistracked = flags[:, cols].any(axis=1) & tracked
    usable = tracked & ~mistracked
    n = track.n_frames
    if reference_frame is None:  # the one first-valid-line rule (pellets), for the jaw pellets
        reference_frame = first_valid_line(track, where, pellets=JAW_PELLETS, mistracked=flags).index
    elif (isinstance(reference_frame, bool) or not isinstance(reference_frame, (int, np.integer))
          or not 0 <= reference_frame < n):
        raise InvalidChoiceError(f"{where}: reference_frame must be a frame index in "
                                 f"[0, {n}), got {reference_frame!r}")
    elif not usable[reference_frame]:
        why = "mistracked" if mistracked[reference_frame] else "untracked"
        raise MissingDataError(f"{where}: jaw pellets {why} in reference frame {reference_frame}")
    jaw_points = track.positions[:, cols, :]
    try:
        fit = fit_jaw(jaw_points[reference_frame], jaw_points, method=method, valid=usable,
                      **options)
    except (MissingDataError, DegenerateGeometryError) as exc:
        raise type(exc)(f"{where}: {exc}") from None
    return replace(fit, status=np.where(mistracked, Status.MISTRACKED, fit.status).astype(
        np.int32), reference_frame=reference_frame)


# ------------------------------------------------------------------- diagnostics
#: The anatomically plausible region for a jaw pivot, in the pellet frame (origin at the
#: upper incisor tip, +x forward, +y up; mm). The mandibular condyle sits about 90-100 mm
#: behind and 20-30 mm above the incisor tip (docs/JAW.md; /work/shared/FACE_MODEL_NOTES.md;
#: the synthetic subjects draw it there too); the margin of 30 mm on every side covers
#: speakers' sizes, the condyle's forward-downward slide along the articular eminence
#: during opening (up to 10-20 mm), and effective rotation centres found in speech data
#: below and in front of the condyle (Edwards & Harris 1990, J Speech Hear Res 33:550-562;
#: Ostry, Vatikiotis-Bateson & Gribble 1997, JSLHR 40:1341-1351).
PLAUSIBLE_PIVOT_X_MM = (-100.0 - 30.0, -90.0 + 30.0)
PLAUSIBLE_PIVOT_Y_MM = (20.0 - 30.0, 30.0 + 30.0)


@dataclass(frozen=True)
class JawDiagnostics:
    """Truth-free checks of one jaw fit on a real recording (mm; fractions in [0, 1]).

    frames_used: frames with status OK or PIVOT_UNDEFINED. jaw_distance_sd_mm /
    jaw_distance_range_mm: SD and range (max - min) of the MNI-MNM distance over those
    frames: the rigid-body residual of the data (a rigid jaw keeps it constant; pellet
    noise of ``s`` mm gives an SD of about ``s``). residual_median_mm: the median rms
    pellet misfit of the method. pivot_iqr_x_mm / pivot_iqr_y_mm: interquartile range of
    the pivot over frames where it is defined (0 for "fixed-pivot"; many mm for the
    closed form at small angles). pivot_plausible_fraction: fraction of used frames whose
    pivot is defined and inside ``PLAUSIBLE_PIVOT_X_MM`` x ``PLAUSIBLE_PIVOT_Y_MM``.
    """

    method: str
    frames_used: int
    jaw_distance_sd_mm: float
    jaw_distance_range_mm: float
    residual_median_mm: float
    pivot_iqr_x_mm: float
    pivot_iqr_y_mm: float
    pivot_plausible_fraction: float

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def jaw_diagnostics(fit: JawFit, current: Float[ArrayLike, "n 2 2"]) -> JawDiagnostics:
    """:class:`JawDiagnostics` of ``fit`` on its data ``current`` (n, 2, 2) mm [MNI, MNM]."""
    current = np.asarray(current, float)
    used = np.asarray(fit.status) <= Status.PIVOT_UNDEFINED
    if current.shape != (len(used), 2, 2):
        raise ValueError(f"jaw diagnostics: current must be ({len(used)}, 2, 2), "
                         f"got {current.shape}")
    distance = np.linalg.norm(current[used, 0] - current[used, 1], axis=-1)
    defined = used & fit.pivot_defined
    pivot = fit.pivot[defined]

    def iqr(x):
        return float(np.subtract(*np.percentile(x, [75, 25]))) if x.size else float("nan")

    inside = ((pivot[:, 0] >= PLAUSIBLE_PIVOT_X_MM[0]) & (pivot[:, 0] <= PLAUSIBLE_PIVOT_X_MM[1])
              & (pivot[:, 1] >= PLAUSIBLE_PIVOT_Y_MM[0]) & (pivot[:, 1] <= PLAUSIBLE_PIVOT_Y_MM[1]))
    n_used = int(used.sum())
    return JawDiagnostics(
        method=fit.method, frames_used=n_used,
        jaw_distance_sd_mm=float(np.std(distance)) if n_used else float("nan"),
        jaw_distance_range_mm=float(np.ptp(distance)) if n_used else float("nan"),
        residual_median_mm=float(np.median(fit.residual[used])) if n_used else float("nan"),
        pivot_iqr_x_mm=iqr(pivot[:, 0]), pivot_iqr_y_mm=iqr(pivot[:, 1]),
        pivot_plausible_fraction=float(inside.sum() / n_used) if n_used else 0.0,
    )
