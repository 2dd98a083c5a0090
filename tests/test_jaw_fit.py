"""Least-squares jaw fits (cassi_fit.jaw_fit): exact recovery, independent references from far
starts, noise, bad data, mistracks, the method and solver objects."""

import jax
import numpy as np
import pytest
from scipy.optimize import least_squares

from cassi_fit import jaw_fit, rigid
from cassi_fit.errors import DegenerateGeometryError, InvalidChoiceError, MissingDataError
from cassi_fit.jaw_fit import (
    ClosedForm,
    Dogleg,
    FixedPivot,
    FrameFit,
    GaussNewton,
    JaxoptGaussNewton,
    JaxoptLevenbergMarquardt,
    LevenbergMarquardt,
    SmoothPivot,
    fit_jaw,
    jaw_method,
)
from cassi_fit.options import JAW_METHODS
from cassi_fit.status import SolverResult, Status

REFERENCE = np.array([[-2.0, -18.0], [-35.0, -24.0]])
PIVOT = np.array([-88.0, -8.0])  # near the condyle
N = 120
THETA = 0.2 * np.sin(np.linspace(0.0, 3 * np.pi, N)) ** 2  # up to 11.5 degrees, speech-like
_move = jax.jit(jax.vmap(lambda th, q, p: rigid.apply(*rigid.from_pivot(th, q), p),
                         in_axes=(0, None, None)))
CURRENT = np.asarray(_move(THETA, PIVOT, REFERENCE))
TRANSLATION = np.asarray(jax.vmap(lambda th: rigid.from_pivot(th, PIVOT)[1])(THETA))
SOLVERS = {"optimistix-lm": LevenbergMarquardt(), "optimistix-gn": GaussNewton(),
           "optimistix-dogleg": Dogleg(), "jaxopt-lm": JaxoptLevenbergMarquardt(),
           "jaxopt-gn": JaxoptGaussNewton()}
# far starts: 10 degrees and 20 mm away from the answer
FAR_MOTION = np.array([np.deg2rad(10.0), 14.0, -14.0])
FAR_PIVOT = PIVOT + np.array([14.0, -14.0])
SMOOTHNESS, SPACING = 1.0, 16


def noisy(noise, seed=1):
    return CURRENT + np.random.default_rng(seed).normal(0.0, noise, CURRENT.shape)


def far_method(kind, solver):
    """``kind`` from the far start with ``solver`` (None: the method's own default,
    Levenberg-Marquardt with the method's step budget)."""
    if kind == "frame-fit":
        return FrameFit(solver=solver, start=np.column_stack([THETA, TRANSLATION]) + FAR_MOTION)
    if kind == "fixed-pivot":
        return FixedPivot(solver=solver, start=FAR_PIVOT)
    return SmoothPivot(smoothness=SMOOTHNESS, knot_spacing=SPACING, solver=solver,
                       start=FAR_PIVOT)


# ------------------------------------------------ independent references (numpy, scipy)
def np_rotate(theta, p):
    """``R(theta) p`` for theta (n,) and p (n, 2) or (2,), written out in numpy."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * p[..., 0] + s * p[..., 1], -s * p[..., 0] + c * p[..., 1]], -1)


def np_procrustes(reference, current):
    """Two-point least-squares rigid motion, analytic: (theta (n,), t (n, 2))."""
    c_ref, c_cur = reference.mean(0), current.mean(1)
    u, v = reference[0] - c_ref, current[:, 0] - c_cur
    theta = np.arctan2(u[1] * v[:, 0] - u[0] * v[:, 1], u[0] * v[:, 0] + u[1] * v[:, 1])
    return theta, c_cur - np_rotate(theta, np.broadcast_to(c_ref, c_cur.shape))


def np_pivot_residuals(path, theta, current):
    """Pellets turned by theta (n,) about path (n, 2): residuals (4 n,)."""
    moved = np.stack([np_rotate(theta, REFERENCE[i] - path) + path for i in range(2)], 1)
    return (moved - current).ravel()


def scipy_fixed_pivot(current):
    def res(x):
        return np_pivot_residuals(np.broadcast_to(x[:2], (N, 2)), x[2:], current)

    x = least_squares(res, np.concatenate([PIVOT, THETA]), xtol=1e-15, ftol=1e-15, gtol=1e-15,
                      jac="3-point").x
    return x[:2], x[2:]


def np_spline(knots, n, spacing):
    k = np.arange(n)
    j, f = k // spacing, (k % spacing / spacing)[:, None]
    return (1 - f) * knots[j] + f * knots[j + 1]


def scipy_smooth_pivot(current):
    m = (N - 1) // SPACING + 2

    def res(x):
        knots = x[:2 * m].reshape(m, 2)
        prior = np.sqrt(SMOOTHNESS / SPACING) * np.diff(knots, axis=0).ravel()
        return np.concatenate([np_pivot_residuals(np_spline(knots, N, SPACING), x[2 * m:],
                                                  current), prior])

    x0 = np.concatenate([np.tile(PIVOT, m), THETA])
    sol = least_squares(res, x0, xtol=1e-15, ftol=1e-15, gtol=1e-15, jac="3-point")
    return np_spline(sol.x[:2 * m].reshape(m, 2), N, SPACING), sol.x[2 * m:], sol.jac


# Levenberg-Marquardt from the far start as each method runs it by default (None): for
# "frame-fit" that is SOLVERS' LevenbergMarquardt(), for the pivot methods with their own
# step budget (PIVOT_MAX_STEPS, not DEFAULT_MAX_STEPS: the only difference), the solver
# the other tests here run them with, so these compile no kernel of their own
FAR_SOLVERS = dict(SOLVERS, **{"optimistix-lm": None})
FAR_CASES = [(kind, name) for kind in ("frame-fit", "fixed-pivot", "smooth-pivot")
             for name in FAR_SOLVERS]


@pytest.fixture(scope="module")
def references():
    current = noisy(0.3)
    return current, np_procrustes(REFERENCE, current), scipy_fixed_pivot(current), \
        scipy_smooth_pivot(current)


def check_far_start(kind, name, refs):
    """The fit from 10 degrees / 20 mm away converges to the independent reference."""
    current, procrustes, fixed, smooth = refs
    fit = fit_jaw(REFERENCE, current, method=far_method(kind, FAR_SOLVERS[name]))
    assert fit.converged, (kind, name)
    if kind == "frame-fit":
        np.testing.assert_allclose(fit.theta, procrustes[0], atol=1e-9)
        np.testing.assert_allclose(fit.translation, procrustes[1], atol=1e-7)
    elif kind == "fixed-pivot":
        np.testing.assert_allclose(fit.pivot, np.broadcast_to(fixed[0], (N, 2)), atol=1e-5)
        np.testing.assert_allclose(fit.theta, fixed[1], atol=1e-8)
    else:
        np.testing.assert_allclose(fit.pivot, smooth[0], atol=1e-4)
        np.testing.assert_allclose(fit.theta, smooth[1], atol=1e-7)


@pytest.mark.parametrize("kind, name", FAR_CASES)
def test_far_start_converges_to_independent_reference(kind, name, references):
    check_far_start(kind, name, references)


@pytest.mark.parametrize("method", [ClosedForm(), far_method("frame-fit", None),
                                    far_method("fixed-pivot", None),
                                    far_method("smooth-pivot", None)],
                         ids=JAW_METHODS)
def test_noise_free_motion_recovered_exactly(method):
    fit = fit_jaw(REFERENCE, CURRENT, method=method)
    assert fit.converged and fit.method == method.name
    np.testing.assert_allclose(fit.theta, THETA, atol=1e-9)
    np.testing.assert_allclose(fit.translation, TRANSLATION, atol=1e-7)
    rotating = THETA > 1e-3
    np.testing.assert_allclose(fit.pivot[rotating], np.broadcast_to(PIVOT, (rotating.sum(), 2)),
                               atol=1e-5)
    assert np.all(fit.residual < 1e-7)
    assert fit.covariance.shape == (N, 3, 3) and fit.pivot_covariance.shape == (N, 2, 2)


def test_frame_fit_equals_procrustes(references):
    current, (theta, t), _, _ = references
    fit = fit_jaw(REFERENCE, current, method=FrameFit(start=FAR_MOTION))  # far from most frames
    np.testing.assert_allclose(fit.theta, theta, atol=1e-9)
    np.testing.assert_allclose(fit.translation, t, atol=1e-8)


def _point_error(fit, point):
    true = np.asarray(jax.vmap(rigid.apply, in_axes=(0, 0, None))(THETA, TRANSLATION, point))
    est = np.asarray(jax.vmap(rigid.apply, in_axes=(0, 0, None))(fit.theta, fit.translation, point))
    return np.linalg.norm(est - true, axis=-1)


def test_fits_beat_the_closed_form_under_noise():
    chin = np.array([5.0, -45.0])
    methods = {"closed-form": ClosedForm(), "frame-fit": FrameFit(start=FAR_MOTION),
               "fixed-pivot": FixedPivot(start=FAR_PIVOT),
               "smooth-pivot": SmoothPivot(smoothness=100.0, start=FAR_PIVOT)}
    errors = {m: [] for m in methods}
    pivot_errors = {m: [] for m in methods}
    for seed in range(3):
        current = noisy(0.3, seed)
        for m, method in methods.items():
            fit = fit_jaw(REFERENCE, current, method=method)
            assert fit.converged, m
            errors[m].append(np.mean(_point_error(fit, chin)))
            pivot_errors[m].append(np.median(np.linalg.norm(fit.pivot - PIVOT, axis=1)))
    closed = np.mean(errors["closed-form"])
    for m in ("frame-fit", "fixed-pivot", "smooth-pivot"):
        assert np.mean(errors[m]) < closed, m
    for m in ("fixed-pivot", "smooth-pivot"):
        assert np.mean(pivot_errors[m]) < 0.2 * np.mean(pivot_errors["closed-form"]), m
    # the closed-form pivot at speech angles scatters by many mm at 0.3 mm noise
    assert np.mean(pivot_errors["closed-form"]) > 5.0


def test_frame_fit_is_the_closed_form_and_agrees_with_the_iterative_fit(references):
    """By default frame-fit solves the two-point problem in closed form (no solver); given a
    solver it iterates, from 10 degrees / 20 mm away, to the same motion, residuals,
    covariance (s^2 (J^T J)^-1 at the solution) and noise estimate."""
    current = references[0]
    closed = fit_jaw(REFERENCE, current, method=FrameFit())
    iterated = fit_jaw(REFERENCE, current, method=far_method("frame-fit", LevenbergMarquardt()))
    assert closed.solver == "procrustes" and iterated.solver == "optimistix-lm"
    assert jaw_method("frame-fit") == FrameFit() and not FrameFit().iterative
    assert closed.converged and iterated.converged
    np.testing.assert_allclose(closed.theta, iterated.theta, atol=1e-9)
    np.testing.assert_allclose(closed.translation, iterated.translation, atol=1e-7)
    np.testing.assert_allclose(closed.residual, iterated.residual, atol=1e-7)
    np.testing.assert_allclose(closed.covariance, iterated.covariance, rtol=1e-6, atol=1e-14)
    assert closed.noise_mm == pytest.approx(iterated.noise_mm, rel=1e-6)
    # the covariance is the Gauss-Newton one: s^2 (J^T J)^-1 of the rigid residuals
    k = 40
    jac = np.asarray(jax.jit(jax.jacfwd(jaw_fit.rigid_residuals))(  # compiled, not op by op
        np.r_[closed.theta[k], closed.translation[k]], (REFERENCE, current[k])))
    np.testing.assert_allclose(closed.covariance[k],
                               closed.noise_mm**2 * np.linalg.inv(jac.T @ jac), rtol=1e-9)


def test_frame_fit_lm_confirms_the_procrustes_start_at_once():
    """From its default start (the minimum) LM must stop within 2 steps for every frame
    (the vmapped loop runs until the slowest frame stops)."""
    fit = fit_jaw(REFERENCE, noisy(0.3), method=FrameFit(solver=LevenbergMarquardt(max_steps=2)))
    assert fit.converged


def test_smooth_pivot_covariance_is_the_marginal_of_the_full_problem(references):
    """s^2 (J^T J)^-1 of the knots (selected inversion, no dense matrix) mapped to the path
    equals the knot block of the full (knots + angles) problem's covariance."""
    current, _, _, (path, _, jac) = references
    fit = fit_jaw(REFERENCE, current, method=SmoothPivot(smoothness=SMOOTHNESS,
                                                         knot_spacing=SPACING))
    m = (N - 1) // SPACING + 2
    knot_cov = (fit.noise_mm**2 * np.linalg.inv(jac.T @ jac))[:2 * m, :2 * m]
    knot_cov = knot_cov.reshape(m, 2, m, 2)
    k = np.arange(N)
    weights = np.zeros((N, m))
    weights[k, k // SPACING] = 1 - k % SPACING / SPACING
    weights[k, k // SPACING + 1] = k % SPACING / SPACING
    dense = np.einsum("kj,kl,jalb->kab", weights, weights, knot_cov)
    np.testing.assert_allclose(fit.pivot_covariance, dense, rtol=0.05)


@pytest.mark.parametrize("sensors", [("MNI", "MNM"), ("MNI",)])
def test_untracked_frames_at_the_ends_change_no_fit(sensors):
    """A recording whose first and last frames are untracked is fitted as the recording of
    its tracked stretch alone by the pivot methods (the per-frame ones fit each frame on
    its own): the smooth pivot's knots that no usable frame reaches follow its smoothness
    and carry neither its prior (informative with one sensor) nor a parameter's count. So
    the smooth pivot, too, is padded to the frame bucket (the default: one compilation
    for every length up to 1024 frames; both fits below are padded to it)."""
    current = noisy(0.1, seed=4)
    head, tail = SPACING, 13  # the cut's knots fall on the whole's
    valid = np.ones(N, bool)
    valid[:head] = valid[N - tail:] = False
    valid[50:53] = False  # a gap inside stays a gap
    inner = slice(head, N - tail)
    for name in ("fixed-pivot", "smooth-pivot"):
        cut = fit_jaw(current[head], current[inner], method=name, valid=valid[inner],
                      jaw_sensors=sensors)
        whole = fit_jaw(current[head], current, method=name, valid=valid, jaw_sensors=sensors)
        np.testing.assert_allclose(whole.theta[inner], cut.theta, atol=1e-8, err_msg=name)
        np.testing.assert_allclose(whole.pivot[inner], cut.pivot, atol=1e-5, err_msg=name)
        np.testing.assert_allclose(whole.pivot_covariance[inner], cut.pivot_covariance,
                                   rtol=1e-5, atol=1e-9, err_msg=name)
        np.testing.assert_array_equal(whole.status[inner], cut.status, err_msg=name)
        np.testing.assert_allclose(whole.noise_mm, cut.noise_mm, rtol=1e-6, err_msg=name)


def test_block_tridiagonal_solve_and_selected_inverse_match_dense_numpy():
    rng = np.random.default_rng(3)
    m = 7
    a = rng.normal(size=(2 * m, 2 * m))
    band = np.abs(np.subtract.outer(np.arange(2 * m) // 2, np.arange(2 * m) // 2)) <= 1
    dense = (a @ a.T + 2 * m * np.eye(2 * m)) * band
    blocks = dense.reshape(m, 2, m, 2)
    diag = blocks[np.arange(m), :, np.arange(m), :]
    upper = blocks[np.arange(m - 1), :, np.arange(1, m), :]
    rhs = rng.normal(size=(m, 2))
    # compiled, as the smooth pivot's kernel runs them (op by op, each step compiles its own)
    x = jax.jit(jaw_fit.block_tridiagonal_solve)(diag, upper, rhs)
    np.testing.assert_allclose(np.asarray(x).ravel(), np.linalg.solve(dense, rhs.ravel()),
                               rtol=1e-10)
    inv = np.linalg.inv(dense).reshape(m, 2, m, 2)
    c_diag, c_up = jax.jit(jaw_fit.block_tridiagonal_inverse_blocks)(diag, upper)
    np.testing.assert_allclose(c_diag, inv[np.arange(m), :, np.arange(m), :], rtol=1e-10)
    np.testing.assert_allclose(c_up, inv[np.arange(m - 1), :, np.arange(1, m), :], rtol=1e-9,
                               atol=1e-14)


def test_pivot_uncertainty_tracks_the_real_scatter():
    """The reported pivot SD matches the pivot's scatter over 40 independent noise draws
    (the SD of 40 draws is itself uncertain by about 11 %: 25 % is over 2 of those), and
    the pooled noise estimate the noise that was added (358 degrees of freedom: 4 %)."""
    fits = [fit_jaw(REFERENCE, noisy(0.3, seed), method="fixed-pivot") for seed in range(40)]
    scatter = np.std([f.pivot[0] for f in fits], axis=0, ddof=1)
    reported = np.sqrt(np.median([np.diag(f.pivot_covariance[0]) for f in fits], axis=0))
    np.testing.assert_allclose(reported, scatter, rtol=0.25)
    assert np.median([f.noise_mm for f in fits]) == pytest.approx(0.3, rel=0.05)
    fit = fits[0]
    sd = np.sqrt(np.diag(fit.pivot_covariance[0]))
    closed = fit_jaw(REFERENCE, noisy(0.3), method="closed-form")
    small = (THETA > 1e-3) & (THETA < 0.02)
    assert np.median(np.sqrt(closed.pivot_covariance[small, 0, 0])) > 10 * sd[0]


def test_invalid_and_untracked_frames_are_flagged_and_interpolated():
    current = CURRENT.copy()
    current[10, 0] = np.nan  # untracked MNI
    current[20, 1] = current[20, 0]  # coincident pellets
    valid = np.ones(N, bool)
    valid[30] = False
    for method in (ClosedForm(), FixedPivot()):
        fit = fit_jaw(REFERENCE, current, method=method, valid=valid)
        assert fit.status[10] == Status.NON_FINITE
        assert fit.status[20] == Status.DEGENERATE
        assert fit.status[30] == Status.INVALID_FRAME
        assert Status(int(fit.status[30])).label == "invalid-frame"
        for leaf in (fit.theta, fit.translation, fit.pivot, fit.residual, fit.covariance):
            assert np.all(np.isfinite(leaf))
        for k in (10, 20, 30):
            assert fit.theta[k] == pytest.approx(0.5 * (fit.theta[k - 1] + fit.theta[k + 1]))


def test_unusable_recordings_raise_clear_errors():
    with pytest.raises(MissingDataError, match="reference"):
        fit_jaw(np.full((2, 2), np.nan), CURRENT)
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        fit_jaw(np.zeros((2, 2)), CURRENT)
    with pytest.raises(MissingDataError, match="no frame"):
        fit_jaw(REFERENCE, CURRENT, valid=np.zeros(N, bool))
    with pytest.raises(DegenerateGeometryError, match="never rotates"):  # N: no new shape
        fit_jaw(REFERENCE, np.broadcast_to(REFERENCE + 1.0, (N, 2, 2)), method=FixedPivot())


def test_options_are_objects_and_aliases_are_checked():
    assert jaw_method("closed-form") == ClosedForm()
    assert jaw_method("frame-fit", solver="optimistix-gn") == FrameFit(solver=GaussNewton())
    smooth = jaw_method("smooth-pivot", solver="jaxopt-gn", smoothness=3.0)
    assert smooth == SmoothPivot(smoothness=3.0, solver=JaxoptGaussNewton())
    assert smooth.solver_name == "block-tridiagonal-gn"
    with pytest.raises(InvalidChoiceError, match="solver"):
        fit_jaw(REFERENCE, CURRENT, method="frame-fit", solver="scipy")
    with pytest.raises(InvalidChoiceError, match="method"):
        fit_jaw(REFERENCE, CURRENT, method="magic")
    with pytest.raises(InvalidChoiceError, match="method object"):
        fit_jaw(REFERENCE, CURRENT, method=FixedPivot(), solver="optimistix-gn")
    for bad in (-1.0, 0.0, float("nan"), float("inf"), "x"):
        with pytest.raises(InvalidChoiceError, match="smoothness"):
            SmoothPivot(smoothness=bad)
        with pytest.raises(InvalidChoiceError, match="smoothness"):
            fit_jaw(REFERENCE, CURRENT, method="smooth-pivot", smoothness=bad)
    with pytest.raises(InvalidChoiceError, match="knot_spacing"):
        SmoothPivot(knot_spacing=0)


def test_smoothness_interpolates_between_frame_fit_and_fixed_pivot():
    current = noisy(0.3)
    fixed = fit_jaw(REFERENCE, current, method=FixedPivot())
    stiff = fit_jaw(REFERENCE, current, method=SmoothPivot(smoothness=1e8))
    loose = fit_jaw(REFERENCE, current, method=SmoothPivot(smoothness=1e-2))
    np.testing.assert_allclose(stiff.pivot, fixed.pivot, atol=0.05)
    assert np.ptp(loose.pivot[:, 0]) > 10 * np.ptp(stiff.pivot[:, 0])
    assert np.mean(loose.residual) <= np.mean(stiff.residual)


@pytest.mark.parametrize("kind", ["fixed-pivot", "smooth-pivot"])
def test_unconverged_recording_fit_flags_every_frame(kind):
    """A whole-recording fit stopped before convergence: NOT_CONVERGED on its frames."""
    current = noisy(0.3).copy()
    current[5, 0] = np.nan
    fit = fit_jaw(REFERENCE, current, method=far_method(kind, LevenbergMarquardt(max_steps=0)))
    assert not fit.converged and fit.failure == SolverResult.MAX_STEPS_REACHED
    assert fit.status[5] == Status.NON_FINITE
    assert np.all(np.delete(fit.status, 5) == Status.NOT_CONVERGED)
    assert np.all(np.delete(fit.solver_result, 5) == SolverResult.MAX_STEPS_REACHED)


def test_a_stopped_frame_fit_says_which_frames_and_why():
    fit = fit_jaw(REFERENCE, noisy(0.3), method=far_method("frame-fit", GaussNewton(max_steps=1)))
    stopped = fit.solver_result != SolverResult.SUCCESSFUL
    assert stopped.any() and not fit.converged
    assert np.all(fit.solver_result[stopped] == SolverResult.MAX_STEPS_REACHED)
    assert np.all((fit.status == Status.NOT_CONVERGED) == stopped)
    assert fit.failure == SolverResult.MAX_STEPS_REACHED


# ------------------------------------------------------------------ jaw_from_track
def _track(n=N, spike=None):
    """The synthetic motion as a pellet track (jaw pellets MNI, MNM; the others still). Its
    N frames are the length of the fits above, whose compiled kernels the track's fits
    reuse (the pivot methods' are compiled per length)."""
    from cassi_fit.txy import PelletTrack

    positions = np.zeros((n, 8, 2))
    positions[:, :6] = np.arange(12).reshape(6, 2) - 20.0
    positions[:, 6:] = CURRENT[:n]
    valid = np.ones((n, 8, 2), bool)
    valid[:3] = False
    valid[17, 7] = False
    if spike is not None:
        positions[spike, 6] += np.array([0.0, -30.0])  # a 30 mm MNI mistrack
    return PelletTrack(times=np.arange(n) * 0.006866, positions=positions, valid=valid)


def test_jaw_from_track_uses_first_valid_jaw_frame():
    fit = jaw_fit.jaw_from_track(_track(), method="frame-fit")
    expected = fit_jaw(CURRENT[3], CURRENT, method="frame-fit")
    np.testing.assert_allclose(fit.theta[3:17], expected.theta[3:17], atol=1e-12)
    assert abs(fit.theta[3]) < 1e-12 and list(fit.status[:3]) == [Status.INVALID_FRAME] * 3
    assert fit.status[17] == Status.INVALID_FRAME


@pytest.mark.parametrize("method", JAW_METHODS)
def test_mistracked_values_are_not_used(method):
    fit = jaw_fit.jaw_from_track(_track(spike=25), method=method)
    assert fit.status[25] == Status.MISTRACKED
    assert Status(int(fit.status[25])).label == "mistracked"
    assert np.all(fit.status[20:30][np.arange(10) != 5] <= Status.PIVOT_UNDEFINED)
    # the frame is interpolated from its neighbours, not fitted to the 30 mm spike
    assert abs(np.rad2deg(fit.theta[25] - (THETA[25] - THETA[3]))) < 0.5


def test_a_mistracked_first_line_is_not_the_reference():
    fit = jaw_fit.jaw_from_track(_track(spike=3), method="closed-form")
    assert fit.status[3] == Status.MISTRACKED and fit.reference_frame == 4
    expected = fit_jaw(CURRENT[4], CURRENT)
    np.testing.assert_allclose(fit.theta[5:17], expected.theta[5:17], atol=1e-12)
    # relative to line 4, not to the spike (which would add ~30 degrees to every frame)
    np.testing.assert_allclose(fit.theta[4:17], THETA[4:17] - THETA[4], atol=1e-9)


def test_reference_frame_must_be_a_usable_index():
    track = _track(spike=25)
    for bad in (-1, N, 2.0, True):
        with pytest.raises(InvalidChoiceError, match="reference_frame"):
            jaw_fit.jaw_from_track(track, reference_frame=bad)
    with pytest.raises(MissingDataError, match="untracked in reference frame 1"):
        jaw_fit.jaw_from_track(track, reference_frame=1)
    with pytest.raises(MissingDataError, match="mistracked in reference frame 25"):
        jaw_fit.jaw_from_track(track, reference_frame=25)
    fit = jaw_fit.jaw_from_track(track, reference_frame=10)
    assert abs(fit.theta[10]) < 1e-12


# --------------------------------------------------------------------- diagnostics
def test_diagnostics_tell_a_rigid_fixed_pivot_from_a_scattered_closed_form():
    current = noisy(0.3)
    closed = jaw_fit.jaw_diagnostics(fit_jaw(REFERENCE, current), current)
    fixed = jaw_fit.jaw_diagnostics(fit_jaw(REFERENCE, current, method=FixedPivot()), current)
    # distance noise of two pellets each with 0.3 mm per coordinate: about 0.3 * sqrt(2)
    assert closed.jaw_distance_sd_mm == pytest.approx(0.3 * np.sqrt(2), rel=0.25)
    assert closed.jaw_distance_sd_mm == fixed.jaw_distance_sd_mm
    assert fixed.pivot_iqr_x_mm == 0.0 and fixed.pivot_plausible_fraction == 1.0
    assert closed.pivot_iqr_x_mm > 10.0 and closed.pivot_plausible_fraction < 0.8
    assert fixed.frames_used == N and fixed.method == "fixed-pivot"
    assert set(fixed.to_dict()) >= {"pivot_iqr_y_mm", "residual_median_mm"}
    # a pivot in front of the face is implausible
    ahead = jaw_fit.jaw_diagnostics(fit_jaw(REFERENCE, np.asarray(_move(
        THETA + 0.05, np.array([40.0, -8.0]), REFERENCE)), method=FixedPivot()), CURRENT)
    assert ahead.pivot_plausible_fraction == 0.0


# ------------------------------------------------------------------------ meta-test
def test_far_start_tests_fail_when_the_solver_returns_its_start(references,
                                                               solvers_return_their_start):
    """The far-start tests above can fail: with the solve step replaced by one that returns
    its start, every one of them raises AssertionError."""
    for kind, name in FAR_CASES:
        with pytest.raises(AssertionError):
            check_far_start(kind, name, references)


def test_a_file_whose_every_line_looks_mistracked_says_why():
    from cassi_fit.txy import PelletTrack

    track = _track()
    fast = PelletTrack(times=np.arange(N) * 1e-6, positions=track.positions, valid=track.valid)
    with pytest.raises(MissingDataError, match="mistracked.*times and units"):
        jaw_fit.jaw_from_track(fast)
