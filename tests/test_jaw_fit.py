"""Least-squares jaw fits (cassi_fit.jaw_fit): exact recovery, Procrustes, noise, bad data."""

import jax
import numpy as np
import pytest

from cassi_fit import jaw, jaw_fit, rigid
from cassi_fit.errors import DegenerateGeometryError, MissingDataError

REFERENCE = np.array([[-2.0, -18.0], [-35.0, -24.0]])
PIVOT = np.array([-88.0, -8.0])  # near the condyle
N = 120
THETA = 0.2 * np.sin(np.linspace(0.0, 3 * np.pi, N)) ** 2  # up to 11.5 degrees, speech-like
_move = jax.jit(jax.vmap(lambda th, q, p: rigid.apply(*rigid.from_pivot(th, q), p),
                         in_axes=(0, None, None)))
CURRENT = np.asarray(_move(THETA, PIVOT, REFERENCE))
TRANSLATION = np.asarray(jax.vmap(lambda th: rigid.from_pivot(th, PIVOT)[1])(THETA))
# every solver on the cheap models; the smooth pivot (slower to compile) with two of them
ALL_FITS = [(m, s) for m in ("frame-fit", "fixed-pivot") for s in jaw_fit.SOLVERS] + [
    ("smooth-pivot", "optimistix-lm"), ("smooth-pivot", "jaxopt-gn")]


@pytest.mark.parametrize("method, solver", [("closed-form", "optimistix-lm")] + ALL_FITS)
def test_noise_free_motion_recovered_exactly(method, solver):
    fit = jaw_fit.fit_jaw(REFERENCE, CURRENT, method=method, solver=solver)
    assert fit.converged and fit.method == method
    np.testing.assert_allclose(fit.theta, THETA, atol=1e-9)
    np.testing.assert_allclose(fit.translation, TRANSLATION, atol=1e-7)
    rotating = THETA > 1e-3
    np.testing.assert_allclose(fit.pivot[rotating], np.broadcast_to(PIVOT, (rotating.sum(), 2)),
                               atol=1e-5)
    assert np.all(fit.residual < 1e-7)
    assert fit.covariance.shape == (N, 3, 3) and fit.pivot_covariance.shape == (N, 2, 2)


def noisy(noise, seed=1):
    return CURRENT + np.random.default_rng(seed).normal(0.0, noise, CURRENT.shape)


def test_frame_fit_equals_procrustes():
    current = noisy(0.3)
    fit = jaw_fit.fit_jaw(REFERENCE, current, method="frame-fit")
    ref = jax.vmap(jaw.procrustes, in_axes=(None, 0))(REFERENCE, current)
    np.testing.assert_allclose(fit.theta, ref.theta, atol=1e-9)
    np.testing.assert_allclose(fit.translation, ref.translation, atol=1e-8)


def _point_error(fit, point):
    true = np.asarray(jax.vmap(rigid.apply, in_axes=(0, 0, None))(THETA, TRANSLATION, point))
    est = np.asarray(jax.vmap(rigid.apply, in_axes=(0, 0, None))(fit.theta, fit.translation, point))
    return np.linalg.norm(est - true, axis=-1)


def test_fits_beat_the_closed_form_under_noise():
    chin = np.array([5.0, -45.0])
    errors = {m: [] for m in jaw_fit.METHODS}
    pivot_errors = {m: [] for m in jaw_fit.METHODS}
    for seed in range(4):
        current = noisy(0.3, seed)
        for m in jaw_fit.METHODS:
            fit = jaw_fit.fit_jaw(REFERENCE, current, method=m, smoothness=100.0)
            errors[m].append(np.mean(_point_error(fit, chin)))
            pivot_errors[m].append(np.median(np.linalg.norm(fit.pivot - PIVOT, axis=1)))
    closed = np.mean(errors["closed-form"])
    for m in jaw_fit.METHODS[1:]:
        assert np.mean(errors[m]) < closed, m
    for m in ("fixed-pivot", "smooth-pivot"):
        assert np.mean(pivot_errors[m]) < 0.2 * np.mean(pivot_errors["closed-form"]), m
    # the closed-form pivot at speech angles scatters by many mm at 0.3 mm noise
    assert np.mean(pivot_errors["closed-form"]) > 5.0


def test_pivot_uncertainty_tracks_the_real_scatter():
    fit = jaw_fit.fit_jaw(REFERENCE, noisy(0.3), method="fixed-pivot")
    sd = np.sqrt(np.diag(fit.pivot_covariance[0]))
    assert 0.05 < sd[0] < 5.0 and fit.noise_mm == pytest.approx(0.3, rel=0.3)
    closed = jaw_fit.fit_jaw(REFERENCE, noisy(0.3), method="closed-form")
    small = (THETA > 1e-3) & (THETA < 0.02)
    assert np.median(np.sqrt(closed.pivot_covariance[small, 0, 0])) > 10 * sd[0]


def test_invalid_and_untracked_frames_are_flagged_and_interpolated():
    current = CURRENT.copy()
    current[10, 0] = np.nan  # untracked MNI
    current[20, 1] = current[20, 0]  # coincident pellets
    valid = np.ones(N, bool)
    valid[30] = False
    for method in ("closed-form", "fixed-pivot"):
        fit = jaw_fit.fit_jaw(REFERENCE, current, method=method, valid=valid)
        assert fit.status[10] == jaw.STATUS_NON_FINITE
        assert fit.status[20] == jaw.STATUS_DEGENERATE
        assert fit.status[30] == jaw.STATUS_INVALID_FRAME
        assert fit.status_names[30] == "invalid-frame"
        for leaf in (fit.theta, fit.translation, fit.pivot, fit.residual, fit.covariance):
            assert np.all(np.isfinite(leaf))
        for k in (10, 20, 30):
            assert fit.theta[k] == pytest.approx(0.5 * (fit.theta[k - 1] + fit.theta[k + 1]))


def test_unusable_recordings_raise_clear_errors():
    with pytest.raises(MissingDataError, match="reference"):
        jaw_fit.fit_jaw(np.full((2, 2), np.nan), CURRENT)
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        jaw_fit.fit_jaw(np.zeros((2, 2)), CURRENT)
    with pytest.raises(MissingDataError, match="no frame"):
        jaw_fit.fit_jaw(REFERENCE, CURRENT, valid=np.zeros(N, bool))
    with pytest.raises(DegenerateGeometryError, match="never rotates"):
        jaw_fit.fit_jaw(REFERENCE, np.broadcast_to(REFERENCE + 1.0, (5, 2, 2)),
                        method="fixed-pivot")
    with pytest.raises(ValueError, match="solver"):
        jaw_fit.fit_jaw(REFERENCE, CURRENT, method="frame-fit", solver="scipy")
    with pytest.raises(ValueError, match="method"):
        jaw_fit.fit_jaw(REFERENCE, CURRENT, method="magic")


def test_smoothness_interpolates_between_frame_fit_and_fixed_pivot():
    current = noisy(0.3)
    fixed = jaw_fit.fit_jaw(REFERENCE, current, method="fixed-pivot")
    stiff = jaw_fit.fit_jaw(REFERENCE, current, method="smooth-pivot", smoothness=1e8)
    loose = jaw_fit.fit_jaw(REFERENCE, current, method="smooth-pivot", smoothness=1e-2)
    np.testing.assert_allclose(stiff.pivot, fixed.pivot, atol=0.05)
    assert np.ptp(loose.pivot[:, 0]) > 10 * np.ptp(stiff.pivot[:, 0])
    assert np.mean(loose.residual) <= np.mean(stiff.residual)


def test_jaw_from_track_uses_first_valid_jaw_frame():
    from cassi_fit.txy import PelletTrack

    n = 40
    positions = np.zeros((n, 8, 2))
    positions[:, :6] = np.arange(12).reshape(6, 2)
    positions[:, 6:] = CURRENT[:n]
    valid = np.ones((n, 8, 2), bool)
    valid[:3] = False
    valid[17, 7] = False
    track = PelletTrack(times=np.arange(n) * 0.006866, positions=positions, valid=valid)
    fit = jaw_fit.jaw_from_track(track, method="frame-fit")
    expected = jaw_fit.fit_jaw(CURRENT[3], CURRENT[:n], method="frame-fit")
    np.testing.assert_allclose(fit.theta[3:17], expected.theta[3:17], atol=1e-12)
    assert abs(fit.theta[3]) < 1e-12 and list(fit.status[:3]) == [jaw.STATUS_INVALID_FRAME] * 3
    assert fit.status[17] == jaw.STATUS_INVALID_FRAME


def test_frame_fit_lm_stops_at_once_from_procrustes_start():
    """The scaled per-frame problem starts at its minimum; LM must confirm it in one
    evaluation for every frame (the vmapped loop runs until the slowest frame stops)."""
    import optimistix as optx

    current = noisy(0.3)

    def steps(c):
        sol = optx.least_squares(
            jaw_fit.scaled_rigid_residuals, jaw_fit._LevenbergMarquardt(rtol=1e-8, atol=1e-8),
            jaw_fit._scaled_start(REFERENCE, c), (REFERENCE, c), max_steps=100, throw=False)
        return sol.stats["num_steps"]

    assert int(np.max(jax.vmap(steps)(current))) <= 2


def test_smooth_pivot_equals_the_dense_least_squares_fit():
    """The block-tridiagonal solver minimises the same objective as a dense LM on
    :func:`smooth_pivot_residuals`, with the same covariance s^2 (J^T J)^-1."""
    import optimistix as optx

    current, spacing, smoothness = noisy(0.3), 16, 1.0
    fit = jaw_fit.fit_jaw(REFERENCE, current, method="smooth-pivot", smoothness=smoothness,
                          knot_spacing=spacing)
    assert fit.converged and fit.solver == "block-tridiagonal-lm"
    m = (N - 1) // spacing + 2
    knots0 = np.tile(jaw_fit._initial_pivot(REFERENCE, current, np.ones(N, bool)), m)
    args = (REFERENCE, current, np.ones(N), smoothness, spacing)
    sol = optx.least_squares(jaw_fit.smooth_pivot_residuals,
                             optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10), knots0, args)
    weights = jaw_fit._spline_weights(N, spacing, m)
    np.testing.assert_allclose(fit.pivot, weights @ np.asarray(sol.value).reshape(m, 2),
                               atol=1e-5)
    jac = np.asarray(jax.jacfwd(jaw_fit.smooth_pivot_residuals)(sol.value, args))
    knot_cov = (fit.noise_mm**2 * np.linalg.inv(jac.T @ jac)).reshape(m, 2, m, 2)
    dense = np.einsum("kj,kl,jalb->kab", weights, weights, knot_cov)
    np.testing.assert_allclose(fit.pivot_covariance, dense, rtol=1e-5)


@pytest.mark.parametrize("method", ["fixed-pivot", "smooth-pivot"])
def test_unconverged_recording_fit_flags_every_frame(method, monkeypatch):
    """A whole-recording fit stopped before convergence: status 5 on its frames, not ok."""
    monkeypatch.setattr(jaw_fit, "_MAX_STEPS", 0)
    for kernel in (jaw_fit._fixed_pivot_kernel, jaw_fit._smooth_pivot_kernel):
        kernel.cache_clear()
    try:
        current = noisy(0.3).copy()
        current[5, 0] = np.nan
        fit = jaw_fit.fit_jaw(REFERENCE, current, method=method)
    finally:
        for kernel in (jaw_fit._fixed_pivot_kernel, jaw_fit._smooth_pivot_kernel):
            kernel.cache_clear()
    assert not fit.converged
    assert fit.status[5] == jaw.STATUS_NON_FINITE
    assert np.all(np.delete(fit.status, 5) == jaw.STATUS_NOT_CONVERGED)
