"""Least-squares jaw rotation: alternatives to, and a check on, the paper's closed form.

Data: the reference jaw ``(2, 2)`` mm (rows [MNI, MNM]) and the current jaw in ``n`` frames
``(n, 2, 2)``. Every method returns, per frame, the motion ``p' = R(theta) p + t`` taking the
reference to the frame (Eqs 4-5; :mod:`cassi_fit.rigid`), its pivot, residuals, status,
solver result and uncertainty, as a :class:`JawFit`. Methods are small objects (equinox
Modules, in optimistix's style), passed to :func:`fit_jaw` as ``method=``:

* :class:`ClosedForm` -- the paper's Eqs 1-3, 6-7 in the sound form (:func:`jaw.closed_form`).
* :class:`FrameFit` -- per frame, rotation + translation fitted to both pellets (3 parameters,
  4 residuals): the two-point rigid problem, solved in closed form (2D Procrustes,
  :func:`jaw.procrustes`) with its Gauss-Newton covariance; given a solver it iterates
  instead (the solver comparison). Parameterised by ``(theta, t)``, never by the pivot,
  which is ill-conditioned at small theta; the pivot is derived.
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
* :class:`CoupledRotation` -- one jaw sensor: the rotation from a :class:`JawCoupling`
  (theta linear in the sensor's displacement, learned from two-sensor recordings by
  :func:`learn_jaw_coupling`), the translation that maps the sensor exactly.

One jaw sensor (``jaw_sensors="MNI"`` or ``"MNM"``): the data then fix only two of the
motion's three parameters. "closed-form" and "frame-fit" refuse with that reason
(:func:`check_sensors`); the pivot methods rest on a :class:`PivotPrior` (default
:data:`POPULATION_CONDYLE`); "coupled-rotation" on its coupling. The fit predicts the
hidden sensor (``JawFit.hidden_predicted``) and states its prior (``JawFit.prior``).

Solvers are objects too, behind one interface (:class:`Solver`: ``run`` returns the
parameters and a :class:`cassi_fit.status.SolverResult`): :class:`LevenbergMarquardt`
(default), :class:`GaussNewton`, :class:`Dogleg` (optimistix), and jaxopt's
:class:`JaxoptLevenbergMarquardt` / :class:`JaxoptGaussNewton` (the only module importing
jaxopt is ``_jaxopt_adapter``). "smooth-pivot" uses its own structured solver; the solver
object only chooses its kind and the step budget: damped solvers give
Levenberg-Marquardt-damped Newton steps on the exact per-frame Hessians (``JawFit.solver`` =
``"block-tridiagonal-lm"``), the Gauss-Newton solvers undamped Gauss-Newton steps
(``"block-tridiagonal-gn"``). The names users type (``"frame-fit"``, ``"optimistix-lm"``;
:mod:`cassi_fit.options`) are aliases: :func:`jaw_method` and :func:`jaw_solver` turn them
into objects; :func:`fit_jaw` still accepts them.

Starts: by default the fits start from the closed form / Procrustes (the frame fit then starts
at its minimum); every fitted method takes an explicit ``start`` (documented per class), used
by the tests to start far from the answer. Uncertainty: ``s^2 (J^T J)^-1`` with ``s^2``
pooled over the recording's usable frames.

Modules: ``_solvers`` (the interface, optimistix's solvers, the structured solver),
``_optimistix_adapter`` (optimistix's solver classes, imported when a solver is traced),
``_jaxopt_adapter``, ``_solve`` (aliases and the generic solve step), ``_residuals``,
``_linalg`` (block-tridiagonal algebra), ``_kernels`` (the compiled kernels), ``_priors``
(pivot priors, couplings), ``_methods`` (the method objects), ``_fit`` (``fit_jaw``,
``JawFit``), ``_track`` (``jaw_from_track``, ``learn_jaw_coupling``), ``_diagnostics``.
This file only re-exports (jaxopt's solvers on first use).
"""

from typing import TYPE_CHECKING

from ._diagnostics import (
    PLAUSIBLE_PIVOT_X_MM,
    PLAUSIBLE_PIVOT_Y_MM,
    JawDiagnostics,
    jaw_diagnostics,
)
from ._fit import JAW_FRAME_BUCKET, JAW_SENSORS, JawFit, fit_jaw, jaw_bucket, jaw_sensor_set
from ._linalg import block_tridiagonal_inverse_blocks, block_tridiagonal_solve
from ._methods import (
    DEFAULT_KNOT_SPACING,
    ClosedForm,
    CoupledRotation,
    FixedPivot,
    FrameFit,
    JawMethod,
    SmoothPivot,
    check_sensors,
    jaw_method,
    method_for_sensors,
    tracked_jaw_sensors,
)
from ._priors import (
    DEFAULT_COUPLINGS,
    PIVOT_FROM_DATA,
    POPULATION_CONDYLE,
    PRIOR_NOISE_MM,
    JawCoupling,
    PivotPrior,
)
from ._residuals import (
    best_angle_about,
    fixed_pivot_residuals,
    rigid_residuals,
    scaled_rigid_residuals,
    smooth_pivot_residuals,
)
from ._solve import jaw_solver, least_squares, solve
from ._solvers import DEFAULT_MAX_STEPS, Dogleg, GaussNewton, LevenbergMarquardt, Solver
from ._track import jaw_from_track, learn_jaw_coupling

if TYPE_CHECKING:
    from ._jaxopt_adapter import JaxoptGaussNewton, JaxoptLevenbergMarquardt

__all__ = [
    "DEFAULT_COUPLINGS", "DEFAULT_KNOT_SPACING", "DEFAULT_MAX_STEPS", "JAW_FRAME_BUCKET", "JAW_SENSORS",
    "PIVOT_FROM_DATA", "PLAUSIBLE_PIVOT_X_MM", "PLAUSIBLE_PIVOT_Y_MM", "POPULATION_CONDYLE",
    "PRIOR_NOISE_MM", "ClosedForm", "CoupledRotation", "Dogleg", "JawCoupling", "PivotPrior", "FixedPivot", "FrameFit", "GaussNewton", "JawDiagnostics",
    "JawFit", "JawMethod", "JaxoptGaussNewton", "JaxoptLevenbergMarquardt",
    "LevenbergMarquardt", "SmoothPivot", "Solver", "best_angle_about",
    "block_tridiagonal_inverse_blocks", "block_tridiagonal_solve", "check_sensors", "method_for_sensors", "tracked_jaw_sensors", "fit_jaw", "jaw_bucket",
    "fixed_pivot_residuals", "jaw_diagnostics", "jaw_from_track", "jaw_method", "jaw_sensor_set", "jaw_solver",
    "learn_jaw_coupling", "least_squares", "rigid_residuals", "scaled_rigid_residuals", "smooth_pivot_residuals",
    "solve",
]

#: jaxopt's solvers, imported when named (their equinox classes cost every fit's start).
_JAXOPT = ("JaxoptGaussNewton", "JaxoptLevenbergMarquardt")


def __getattr__(name: str) -> object:
    if name in _JAXOPT:
        from . import _jaxopt_adapter

        return getattr(_jaxopt_adapter, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
