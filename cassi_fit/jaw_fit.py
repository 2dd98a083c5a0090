"""Least-squares jaw rotation: alternatives to, and a check on, the paper's closed form.

Data: the reference jaw ``(2, 2)`` mm (rows [MNI, MNM]) and the current jaw in ``n`` frames
``(n, 2, 2)``. Every method returns, per frame, the motion ``p' = R(theta) p + t`` taking the
reference to the frame (Eqs 4-5; :mod:`cassi_fit.rigid`), its pivot, residuals, status and
uncertainty, as a :class:`JawFit`. Methods:

* ``"closed-form"`` -- the paper's Eqs 1-3, 6-7 in the sound form (:func:`jaw.closed_form`).
* ``"frame-fit"`` -- per frame, rotation + translation fitted to both pellets (3 parameters,
  4 residuals). Parameterised by ``(theta, t)``, never by the pivot, which is ill-conditioned
  at small theta; the pivot is derived. Its exact reference is :func:`jaw.procrustes`.
* ``"fixed-pivot"`` -- Parke's model: one pivot ``q`` for the recording, an angle per frame,
  ``p' = R(theta_k)(p - q) + q``. The angles are eliminated in closed form (variable
  projection: for a given ``q`` the best ``theta_k`` is one ``atan2``), so the solver sees
  2 parameters and ``4 n`` residuals; the pivot covariance is then the exact marginal.
* ``"smooth-pivot"`` -- a moving pivot ``q_k`` (linear spline with a knot every
  ``knot_spacing`` frames) with a smoothness prior ``smoothness * sum |q_{k+1} - q_k|^2``
  (mm^2 per frame step, against squared pellet residuals in mm^2), angles eliminated as
  above. ``smoothness -> inf`` gives the fixed pivot; small values let the pivot follow the
  condyle's translation, the model the jaw literature supports.

Solvers (``solver=``): ``"optimistix-lm"`` (default), ``"optimistix-gn"``,
``"optimistix-dogleg"``, ``"jaxopt-lm"``, ``"jaxopt-gn"`` (the last two through
:mod:`cassi_fit._jaxopt_adapter`). "smooth-pivot" has its own structured solver instead
(normal equations assembled from per-frame 2x2 blocks, block-tridiagonal solve; the
solver name only picks Gauss-Newton for ``*-gn`` and Levenberg-Marquardt otherwise;
``JawFit.solver`` says ``"block-tridiagonal-lm"`` / ``"-gn"``). Initial guesses come from
the closed form / Procrustes.
Uncertainty: ``s^2 (J^T J)^-1`` with ``s^2`` pooled over the recording's usable frames.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from . import jaw, rigid
from .errors import DegenerateGeometryError, MissingDataError

METHODS = ("closed-form", "frame-fit", "fixed-pivot", "smooth-pivot")
SOLVERS = ("optimistix-lm", "optimistix-gn", "optimistix-dogleg", "jaxopt-lm", "jaxopt-gn")
DEFAULT_KNOT_SPACING = 16  # frames (about 0.11 s at 145.6 Hz) between pivot-path knots
_MAX_STEPS = 100


@dataclass(frozen=True)
class JawFit:
    """One recording's jaw motion, per frame (``n`` frames); numpy arrays.

    theta (n,) rad, opening positive; translation (n, 2) mm, ``p' = R(theta) p + t``
    from the reference jaw; pivot (n, 2) mm: the fixed point of the frame's motion (for
    "fixed-pivot" the recording's pivot, for "smooth-pivot" the pivot path), (0, 0) where
    undefined; pivot_defined (n,) bool; residual (n,) mm, rms pellet misfit of the frame;
    status (n,) int, see :data:`cassi_fit.jaw.STATUS_NAMES` (0 ok, 1 pivot undefined,
    2 degenerate, 3 non-finite, 4 invalid frame (values interpolated), 5 not converged);
    converged: the solver reported success (all frames for "frame-fit");
    covariance (n, 3, 3) of ``(theta, tx, ty)`` (rad, mm) given the frame's data;
    pivot_covariance (n, 2, 2) mm^2 for the uncertainty ellipse (inf where undefined);
    noise_mm: the pooled pellet-noise estimate ``s``.
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

    @property
    def status_names(self) -> list[str]:
        return [jaw.status_name(c) for c in self.status]


# ------------------------------------------------------------------ solvers, by name
def _tolerance(dtype):
    return 1e-8 if jnp.dtype(dtype) == jnp.float64 else 1e-4


class _GradientStop:
    """Mixin for optimistix's Gauss-Newton family; see :meth:`terminate`."""

    def terminate(self, fn, y, args, options, state, tags):
        """optimistix's Cauchy test (small step in ``y`` and in the residuals), or first-order
        optimality ``|J^T r|_inf <= atol (1 + |r|)`` at the last accepted point.

        The Cauchy test is only evaluated after an *accepted* step. At the minimum the
        predicted reduction is ~1e-30 and the actual one is rounding noise, so a trust-region
        solver rejects about half of its steps there, shrinks its region and tries again; in
        a vmapped fit the batch then runs until the unluckiest frame gets an acceptance
        (6-7 steps for the per-frame fit started at its minimum). The gradient test (MINPACK's
        ``gtol``) stops as soon as the last accepted point is stationary: for a start at the
        minimum, after the first evaluation. Only for problems whose parameters are scaled so
        that ``J^T J`` is of order 1 (the per-frame fit: exactly ``2 I``), where a gradient
        below ``atol`` means a parameter error below ``atol``.
        """
        done, result = super().terminate(fn, y, args, options, state, tags)
        info = state.f_info
        grad = info.jac.transpose().mv(info.residual)
        norm = jnp.sqrt(jnp.sum(info.residual**2))
        stationary = (~state.first_step) & (jnp.max(jnp.abs(grad)) <= self.atol * (1.0 + norm))
        return done | stationary, result


class _LevenbergMarquardt(_GradientStop, optx.LevenbergMarquardt):
    pass


class _GaussNewton(_GradientStop, optx.GaussNewton):
    pass


class _Dogleg(_GradientStop, optx.Dogleg):
    pass


def solve(residuals, params0, args, solver="optimistix-lm", gradient_stop=False):
    """Minimise ``|residuals(params, args)|^2`` from ``params0`` with the named solver.

    Traceable (jit/vmap). Returns ``(params, converged)``. Failure comes back as a value
    (optimistix ``throw=False``), never as an exception from traced code. ``converged`` is
    the solver's own verdict, or a Gauss-Newton step from the answer that would gain less
    than the cost can resolve (Newton decrement ``g^T (J^T J)^+ g <= max(tol^2, 100 eps)
    (1 + |r|^2)``, scale-free in the parameters): a trust-region solver sitting exactly on
    the minimum may stop by shrinking its region without declaring success. (An earlier
    ``|J^T r|_inf <= 100 tol (1 + |r|^2)`` passed unconverged recordings: in float32 a
    fixed pivot 0.8 mm = 1.5 sd from the minimum, after 0 steps.) ``gradient_stop``
    also ends the optimistix solvers at a stationary point (:class:`_GradientStop`); use it
    only with well-scaled parameters.
    """
    params, converged = _solve_raw(residuals, params0, args, solver, gradient_stop)
    res = residuals(params, args)
    jac = jax.jacfwd(residuals)(params, args)
    grad = jac.T @ res
    decrement = grad @ jnp.linalg.pinv(jac.T @ jac) @ grad
    floor = jnp.maximum(_tolerance(params0.dtype) ** 2, 100 * jnp.finfo(params.dtype).eps)
    stationary = decrement <= floor * (1.0 + jnp.sum(res**2))
    return params, converged | stationary


def _solve_raw(residuals, params0, args, solver, gradient_stop=False):
    tol = _tolerance(params0.dtype)
    if solver.startswith("jaxopt-"):
        from . import _jaxopt_adapter

        return _jaxopt_adapter.least_squares(
            residuals, params0, args, method=solver.removeprefix("jaxopt-"), tol=tol,
            max_steps=_MAX_STEPS,
        )
    kinds = {
        "optimistix-lm": (optx.LevenbergMarquardt, _LevenbergMarquardt),
        "optimistix-gn": (optx.GaussNewton, _GaussNewton),
        "optimistix-dogleg": (optx.Dogleg, _Dogleg),
    }
    sol = optx.least_squares(
        residuals, kinds[solver][int(gradient_stop)](rtol=tol, atol=tol), params0, args,
        max_steps=_MAX_STEPS, throw=False,
    )
    return sol.value, sol.result == optx.RESULTS.successful


def _check_solver(solver):
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")


# ------------------------------------------------------------- residual functions
def rigid_residuals(params, args):
    """One frame, ``params = (theta, tx, ty)``: ``R p_i + t - p_i'`` for both pellets, (4,) mm."""
    reference, current = args
    return (rigid.apply(params[0], params[1:], reference) - current).ravel()


def _frame_scale(reference):
    """Centroid ``c`` (2,) and rms radius ``ell`` (mm) of the reference jaw points."""
    centre = jnp.mean(reference, axis=0)
    return centre, jnp.sqrt(jnp.mean(jnp.sum((reference - centre) ** 2, axis=-1)))


def scaled_rigid_residuals(z, args):
    """One frame in scaled, centred coordinates ``z = (ell theta, s)``, (4,) mm.

    ``p' = R(theta)(p - c) + c + s`` with ``c`` the reference centroid and ``ell`` its rms
    radius. Both parameters are then in mm and decoupled: ``J^T J = 2 I`` at every ``z``
    (the rotation column sums to zero over the two pellets about their centroid), so the
    Levenberg-Marquardt damping ``lambda I`` acts evenly on all three, and one Gauss-Newton
    step solves the problem up to its (small) curvature in theta.
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


def _scaled_start(reference, current):
    """Initial ``z``: the closed-form angle (the two-point least-squares angle) and the
    centroid translation -- together the Procrustes motion, so well-posed frames start at
    the minimum and the solver only confirms it."""
    centre, ell = _frame_scale(reference)
    theta = jaw.closed_form(reference, current).theta
    return jnp.concatenate([(ell * theta)[None], jnp.mean(current, axis=0) - centre])


def best_angle_about(pivot, reference, current):
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


def fixed_pivot_residuals(pivot, args):
    """Parke's fixed pivot, angles projected out: ``pivot`` (2,) mm -> residuals (4 n,) mm."""
    reference, current, weight = args
    return _about_pivot_frames(pivot, reference, current, weight).ravel()


def _spline(knots, n, spacing):
    """Piecewise-linear path (n, 2) through ``knots`` (m, 2) placed every ``spacing`` frames."""
    k = jnp.arange(n)
    j = k // spacing
    f = (k % spacing / spacing)[:, None]
    return (1.0 - f) * knots[j] + f * knots[jnp.minimum(j + 1, knots.shape[0] - 1)]


def smooth_pivot_residuals(knots, args):
    """Moving pivot: knots (2 m,) mm, flattened (m, 2) -> data residuals (4 n,) and prior residuals (2 (m-1),).

    The prior is ``sqrt(smoothness) * (q_{k+1} - q_k)`` summed exactly over the frames of
    each knot interval: ``|dQ|^2 / spacing`` per interval.
    """
    reference, current, weight, smoothness, spacing = args
    knots = knots.reshape(-1, 2)
    path = _spline(knots, current.shape[0], spacing)
    data = _about_pivots_frames(path, reference, current, weight).ravel()
    prior = jnp.sqrt(smoothness / spacing) * (knots[1:] - knots[:-1]).ravel()
    return jnp.concatenate([data, prior])


# ---------------------------------------------------------------- compiled kernels
def _motion_params(motion):
    return jnp.concatenate([motion.theta[None], motion.translation])


def _unit_covariance(params, reference, current):
    """``(J^T J)^-1`` (3, 3) of the frame's rigid residuals at ``params``."""
    jac = jax.jacfwd(rigid_residuals)(params, (reference, current))
    return jnp.linalg.inv(jac.T @ jac)


@functools.cache
def _frame_kernel(method, solver):
    """Compiled, vmapped per-frame estimate: closed form or per-frame least squares."""

    def one(reference, current):
        y0 = _motion_params(jaw.closed_form(reference, current))
        if method == "closed-form":
            # noise propagated through the closed form itself: G G^T, G = d(theta, t)/d(current)
            g = jax.jacfwd(lambda c: _motion_params(jaw.closed_form(reference, c)))(current)
            g = g.reshape(3, 4)
            y, converged, unit_cov = y0, jnp.array(True), g @ g.T
        else:
            z, converged = solve(scaled_rigid_residuals, _scaled_start(reference, current),
                                 (reference, current), solver, gradient_stop=True)
            y = _unscale(z, reference)
            unit_cov = _unit_covariance(y, reference, current)
        return y, rigid_residuals(y, (reference, current)), converged, unit_cov

    return jax.jit(jax.vmap(one, in_axes=(None, 0)))


@functools.cache
def _fixed_pivot_kernel(solver):
    """Compiled fixed-pivot fit: ``(reference, current, weight, q0) -> (q, converged, J)``."""

    def run(reference, current, weight, pivot0):
        args = (reference, current, weight)
        pivot, converged = solve(fixed_pivot_residuals, pivot0, args, solver)
        return pivot, converged, jax.jacfwd(fixed_pivot_residuals)(pivot, args)

    return jax.jit(run)


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


def _spline_weights(n, spacing, n_knots):
    """(n, m) weights of the linear spline :func:`_spline`: ``path = weights @ knots``."""
    k = np.arange(n)
    j, f = k // spacing, (k % spacing) / spacing
    weights = np.zeros((n, n_knots))
    weights[k, j] += 1.0 - f
    weights[k, np.minimum(j + 1, n_knots - 1)] += f
    return weights


# ------------------------------------------------ smooth pivot: block-tridiagonal solver
def _block_tridiagonal_solve(diag, upper, rhs):
    """Solve ``N x = rhs`` for a symmetric block-tridiagonal ``N`` with 2x2 blocks.

    diag (m, 2, 2) = ``N_jj``, upper (m - 1, 2, 2) = ``N_j,j+1`` (``N_j+1,j`` is its
    transpose), rhs (m, 2). Block Thomas algorithm (block LDL^T; stable for positive
    definite ``N``): O(m) work in one forward and one backward ``lax.scan``.
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


def _smooth_pivot_system(knots, reference, current, weight, smoothness, spacing):
    """Cost, gradient (m, 2) and Gauss-Newton normal matrix (block-tridiagonal: diagonal
    (m, 2, 2), upper (m-1, 2, 2)) of :func:`smooth_pivot_residuals` at ``knots`` (m, 2).

    Assembled from per-frame blocks: frame ``k`` depends on its pivot ``q_k = (1-f) Q_j + f
    Q_j+1`` only, through a (4, 2) Jacobian ``J_k`` (angle projected out), so it adds
    ``w w' J_k^T J_k`` to blocks (j, j), (j, j+1), (j+1, j+1); the prior adds
    ``smoothness / spacing`` times the difference operator. Never forms the (4 n, 2 m)
    Jacobian.
    """
    n, m = current.shape[0], knots.shape[0]
    k = jnp.arange(n)
    j = k // spacing
    f = (k % spacing) / spacing
    path = (1.0 - f)[:, None] * knots[j] + f[:, None] * knots[j + 1]

    def value_and_jac(q, cur, w):
        r = _about_pivot(q, reference, cur, w)
        return jax.jacfwd(lambda p: _about_pivot(p, reference, cur, w))(q), r

    jac, res = jax.vmap(value_and_jac)(path, current, weight)  # (n, 4, 2), (n, 4)
    a = jnp.einsum("kri,krj->kij", jac, jac)
    g = jnp.einsum("kri,kr->ki", jac, res)
    w0, w1 = 1.0 - f, f
    diag = jnp.zeros((m, 2, 2)).at[j].add(w0[:, None, None] ** 2 * a)
    diag = diag.at[j + 1].add(w1[:, None, None] ** 2 * a)
    upper = jnp.zeros((m - 1, 2, 2)).at[j].add((w0 * w1)[:, None, None] * a)
    grad = jnp.zeros((m, 2)).at[j].add(w0[:, None] * g).at[j + 1].add(w1[:, None] * g)
    lam = smoothness / spacing
    step = knots[1:] - knots[:-1]
    eye = jnp.eye(2)
    ends = jnp.zeros(m).at[:-1].add(1.0).at[1:].add(1.0)
    diag = diag + lam * ends[:, None, None] * eye
    upper = upper - lam * eye
    grad = grad.at[:-1].add(-lam * step).at[1:].add(lam * step)
    cost = 0.5 * (jnp.sum(res**2) + lam * jnp.sum(step**2))
    return cost, grad, diag, upper


@functools.cache
def _smooth_pivot_kernel(damped, spacing):
    """Compiled smooth-pivot fit on the block-tridiagonal normal equations.

    ``(reference, current, weight, smoothness, knots0 (m, 2)) -> (knots, converged, steps,
    diag, upper)`` (the last two: the Gauss-Newton normal matrix at the answer, for the
    covariance). Levenberg-Marquardt (``damped``: ``lambda I`` added, Nielsen's update of
    ``lambda``) or Gauss-Newton (``lambda = 0`` until a step fails to reduce the cost, then
    damped like LM). Converged: at an accepted point the Gauss-Newton step is below
    ``tol (1 + max |Q|)`` mm, or its predicted reduction ``g^T N^-1 g`` is below
    ``max(tol^2, 100 eps) (1 + 2 cost)`` mm^2: a gain that the cost (a sum over thousands
    of frames) cannot resolve in floating point, so no step could be verified anyway.
    """

    def run(reference, current, weight, smoothness, knots0):
        tol = _tolerance(knots0.dtype)
        system = functools.partial(_smooth_pivot_system, reference=reference, current=current,
                                   weight=weight, smoothness=smoothness, spacing=spacing)

        def stationary(knots, cost, grad, diag, upper):
            # a rounding-level ridge keeps knots without data and prior (smoothness 0) finite
            newton = _block_tridiagonal_solve(diag + ridge * jnp.eye(2), upper, -grad)
            small = jnp.max(jnp.abs(newton)) <= tol * (1.0 + jnp.max(jnp.abs(knots)))
            decrement = -jnp.sum(grad * newton)
            floor = jnp.maximum(tol**2, 100 * jnp.finfo(knots.dtype).eps)
            return small | (decrement <= floor * (1.0 + 2.0 * cost))

        cost, grad, diag, upper = system(knots0)
        scale = jnp.max(jnp.abs(jnp.diagonal(diag, axis1=1, axis2=2)))
        lam0 = 1e-3 * scale
        ridge = 1e-12 * scale
        state = dict(knots=knots0, cost=cost, grad=grad, diag=diag, upper=upper,
                     lam=lam0 if damped else jnp.zeros_like(lam0), nu=jnp.array(2.0),
                     steps=jnp.array(0), done=stationary(knots0, cost, grad, diag, upper))

        def body(s):
            eye = jnp.eye(2)
            delta = _block_tridiagonal_solve(s["diag"] + s["lam"] * eye, s["upper"], -s["grad"])
            trial = s["knots"] + delta
            t_cost, t_grad, t_diag, t_upper = system(trial)
            predicted = -(jnp.sum(s["grad"] * delta) + 0.5 * _block_quadratic(
                s["diag"], s["upper"], delta))
            rho = (s["cost"] - t_cost) / jnp.where(predicted > 0, predicted, 1.0)
            accept = jnp.isfinite(t_cost) & (t_cost <= s["cost"]) & (rho > 1e-4)
            lam_ok = s["lam"] * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            lam_bad = jnp.maximum(s["lam"] * s["nu"], lam0)
            new = dict(
                knots=jnp.where(accept, trial, s["knots"]),
                cost=jnp.where(accept, t_cost, s["cost"]),
                grad=jnp.where(accept, t_grad, s["grad"]),
                diag=jnp.where(accept, t_diag, s["diag"]),
                upper=jnp.where(accept, t_upper, s["upper"]),
                lam=jnp.where(accept, lam_ok, lam_bad),
                nu=jnp.where(accept, 2.0, 2.0 * s["nu"]),
                steps=s["steps"] + 1,
            )
            new["done"] = accept & stationary(new["knots"], new["cost"], new["grad"],
                                              new["diag"], new["upper"])
            return new

        out = jax.lax.while_loop(lambda s: ~s["done"] & (s["steps"] < _MAX_STEPS), body, state)
        return out["knots"], out["done"], out["steps"], out["diag"], out["upper"]

    return jax.jit(run)


def _block_quadratic(diag, upper, x):
    """``x^T N x`` for the block-tridiagonal ``N`` of :func:`_block_tridiagonal_solve`."""
    return (jnp.einsum("ji,jik,jk->", x, diag, x)
            + 2.0 * jnp.einsum("ji,jik,jk->", x[:-1], upper, x[1:]))


def _block_tridiagonal_dense(diag, upper):
    m = diag.shape[0]
    dense = np.zeros((m, 2, m, 2))
    idx = np.arange(m)
    dense[idx, :, idx, :] = diag
    dense[idx[:-1], :, idx[1:], :] = upper
    dense[idx[1:], :, idx[:-1], :] = np.swapaxes(upper, 1, 2)
    return dense.reshape(2 * m, 2 * m)


# --------------------------------------------------------------------- helpers
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
    status = np.asarray(_closed_form_frames(reference, current).status).astype(np.int32)
    status = np.where(valid, status, jaw.STATUS_INVALID_FRAME)
    usable = status <= jaw.STATUS_PIVOT_UNDEFINED
    if not usable.any():
        raise MissingDataError("jaw data: no frame where both jaw pellets are tracked")
    safe = np.where(usable[:, None, None], current, reference[None])
    return reference, safe, usable, np.where(usable, 0, status).astype(np.int32)


def _noise_variance(residuals, usable, n_params):
    dof = 4 * int(usable.sum()) - n_params
    return float(np.sum(residuals[usable] ** 2) / dof) if dof > 0 else 0.0


# ---------------------------------------------------------------------- methods
def _per_frame(reference, current, usable, method, solver):
    params, res, converged, unit_cov = (
        np.asarray(a) for a in _frame_kernel(method, solver)(reference, current)
    )
    converged = converged | ~usable
    return params, res, unit_cov, None, converged, 3 * int(usable.sum())


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


def _fixed_pivot(reference, current, usable, solver):
    pivot0 = _initial_pivot(reference, current, usable)
    pivot, converged, jac = _fixed_pivot_kernel(solver)(
        reference, current, usable.astype(float), pivot0
    )
    path = np.broadcast_to(np.asarray(pivot), current.shape[:1] + (2,))
    jac = np.asarray(jac)
    return path, lambda s2: np.broadcast_to(s2 * np.linalg.pinv(jac.T @ jac), (len(path), 2, 2)), bool(converged), 2


def _smooth_pivot(reference, current, usable, solver, smoothness, spacing):
    n = current.shape[0]
    n_knots = (n - 1) // spacing + 2
    pivot0 = _initial_pivot(reference, current, usable)
    knots0 = np.tile(pivot0, (n_knots, 1))
    knots, converged, _, diag, upper = _smooth_pivot_kernel(not solver.endswith("-gn"), spacing)(
        reference, current, usable.astype(float), float(smoothness), knots0
    )
    normal = _block_tridiagonal_dense(np.asarray(diag), np.asarray(upper))
    unit_knot_cov = np.linalg.pinv(normal).reshape(n_knots, 2, n_knots, 2)
    k = np.arange(n)
    j, f = k // spacing, ((k % spacing) / spacing)[:, None, None]
    # pivot q_k = (1 - f) Q_j + f Q_j+1: only blocks (j, j), (j, j+1), (j+1, j+1) matter
    c00, c01 = unit_knot_cov[j, :, j, :], unit_knot_cov[j, :, j + 1, :]
    c11 = unit_knot_cov[j + 1, :, j + 1, :]
    unit_path_cov = ((1 - f) ** 2 * c00 + (1 - f) * f * (c01 + np.swapaxes(c01, 1, 2))
                     + f**2 * c11)
    path = _spline_weights(n, spacing, n_knots) @ np.asarray(knots)
    return path, lambda s2: s2 * unit_path_cov, bool(converged), 2 * n_knots


def _solver_used(method, solver):
    if method == "closed-form":
        return "closed-form"
    if method == "smooth-pivot":
        return "block-tridiagonal-" + ("gn" if solver.endswith("-gn") else "lm")
    return solver


def fit_jaw(
    reference,
    current,
    *,
    method="closed-form",
    solver="optimistix-lm",
    valid=None,
    smoothness=1.0,
    knot_spacing=DEFAULT_KNOT_SPACING,
) -> JawFit:
    """Jaw motion from ``reference`` (2, 2) mm [MNI, MNM] to each frame of ``current``
    (n, 2, 2) mm. ``valid`` (n,) bool marks frames to use; the others, and frames with an
    untracked or coincident jaw pellet, get a status code and interpolated values.
    ``method`` in :data:`METHODS`, ``solver`` in :data:`SOLVERS` (unused by
    "closed-form"), ``smoothness`` and ``knot_spacing`` (frames) for "smooth-pivot".
    Raises :class:`MissingDataError` / :class:`DegenerateGeometryError` when no motion
    can be computed at all (untracked or coincident reference, no usable frame, no rotation
    for a pivot model).
    """
    if method not in METHODS:
        raise ValueError(f"unknown jaw method {method!r}; choose one of {', '.join(METHODS)}")
    _check_solver(solver)
    reference, current, usable, base_status = _prepare(reference, current, valid)
    if method in ("closed-form", "frame-fit"):
        params, res, unit_cov, _, frame_ok, n_params = _per_frame(
            reference, current, usable, method, solver
        )
        converged = bool(frame_ok.all())
        pivot_cov_of = None
    else:
        if method == "fixed-pivot":
            path, pivot_cov_of, converged, n_extra = _fixed_pivot(
                reference, current, usable, solver
            )
        else:
            path, pivot_cov_of, converged, n_extra = _smooth_pivot(
                reference, current, usable, solver, smoothness, int(knot_spacing)
            )
        params, unit_cov = (np.asarray(a) for a in _about_pivot_params(reference, current, path))
        frame_ok = np.full(len(usable), converged)
        res = np.asarray(_frame_residuals(params, (reference, current)))
        n_params = int(usable.sum()) + n_extra
    s2 = _noise_variance(res, usable, n_params)
    covariance = np.where(usable[:, None, None], s2 * unit_cov, 0.0)
    params = _interpolate(params, usable)
    if pivot_cov_of is None:
        pivot, defined, pivot_cov = (
            np.asarray(a) for a in _pivot_with_covariance(params, covariance)
        )
        pivot = np.where(defined[:, None], pivot, 0.0)
    else:
        pivot, defined = np.asarray(path, float), np.ones(len(usable), bool)
        pivot_cov = np.asarray(pivot_cov_of(s2))
        params[:, 1:] = np.asarray(_translation_about(params[:, 0], pivot))
    status = np.where(defined, jaw.STATUS_OK, jaw.STATUS_PIVOT_UNDEFINED)
    status = np.where(frame_ok, status, jaw.STATUS_NOT_CONVERGED)
    status = np.where(usable, status, base_status).astype(np.int32)
    residual = np.sqrt(np.sum(res**2, axis=1) / 2.0)  # rms over the two pellets, mm
    return JawFit(
        theta=params[:, 0], translation=params[:, 1:], pivot=pivot,
        pivot_defined=defined & usable, residual=np.where(usable, residual, 0.0),
        status=status, converged=converged, covariance=covariance,
        pivot_covariance=pivot_cov, noise_mm=float(np.sqrt(s2)), method=method,
        solver=_solver_used(method, solver),
    )


def jaw_from_track(track, *, method="closed-form", solver="optimistix-lm", reference_frame=None,
                   **options) -> JawFit:
    """:func:`fit_jaw` on a :class:`cassi_fit.txy.PelletTrack`'s MNI and MNM pellets.

    The reference is ``reference_frame`` or the first frame in which both jaw pellets are
    tracked (CASSI's first valid line for the jaw); frames with an untracked jaw pellet
    get status "invalid-frame". Errors name the file.
    """
    from .txy import JAW_PELLETS, first_valid_frame, pellet_index

    if reference_frame is None:
        reference_frame = first_valid_frame(track, JAW_PELLETS)
    jaw_points = track.positions[:, [pellet_index("MNI"), pellet_index("MNM")], :]
    valid = track.frame_valid(JAW_PELLETS)
    where = str(track.path) if track.path is not None else "<pellet track>"
    if not valid[reference_frame]:
        raise MissingDataError(f"{where}: jaw pellets untracked in reference frame {reference_frame}")
    try:
        return fit_jaw(jaw_points[reference_frame], jaw_points, method=method, solver=solver,
                       valid=valid, **options)
    except (MissingDataError, DegenerateGeometryError) as exc:
        raise type(exc)(f"{where}: {exc}") from None
