"""One jaw sensor (cassi_fit.jaw_fit with ``jaw_sensors="MNI"`` or ``"MNM"``): refusals with a
reason, the pivot methods from far starts (failing against a stubbed solver), the coupled
rotation and its learning on exactly coupled data, the hidden sensor's prediction, and the
real XRMB recording JW11 when it is present."""

import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from real_data import XRMB_JW11, missing, real_data

from cassi_fit import rigid
from cassi_fit.errors import InvalidChoiceError
from cassi_fit.jaw_fit import (
    DEFAULT_COUPLINGS,
    PIVOT_FROM_DATA,
    ClosedForm,
    CoupledRotation,
    FixedPivot,
    FrameFit,
    JawCoupling,
    PivotPrior,
    SmoothPivot,
    fit_jaw,
    jaw_from_track,
    jaw_sensor_set,
    learn_jaw_coupling,
)
from cassi_fit.status import Status

REFERENCE = np.array([[-2.0, -18.0], [-35.0, -24.0]])  # [MNI, MNM], mm
PIVOT = np.array([-88.0, -8.0])
N = 120
# jaw wagging: up to 23 degrees, so that one sensor's arc holds its pivot's curvature
THETA = 0.4 * np.sin(np.linspace(0.0, 3 * np.pi, N)) ** 2
_move = jax.jit(jax.vmap(lambda th, q, p: rigid.apply(*rigid.from_pivot(th, q), p),
                         in_axes=(0, None, None)))
CURRENT = np.asarray(_move(THETA, PIVOT, REFERENCE))
FAR = PIVOT + np.array([25.0, 20.0])  # 32 mm from the answer


def _rotate(theta, p):
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * p[..., 0] + s * p[..., 1], -s * p[..., 0] + c * p[..., 1]], -1)


_JW11 = real_data(XRMB_JW11)
REAL = None if _JW11 is None else _JW11 / "jw11_tp005.txy"  # task 5
needs_real = pytest.mark.skipif(REAL is None, reason=missing(XRMB_JW11))


# ------------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("method", [ClosedForm(), FrameFit(), "closed-form", "frame-fit"])
@pytest.mark.parametrize("sensor", ["MNI", "MNM"])
def test_two_sensor_methods_refuse_one_sensor_with_the_reason(method, sensor):
    with pytest.raises(InvalidChoiceError, match="needs both jaw sensors.*not determined"):
        fit_jaw(REFERENCE, CURRENT, method=method, jaw_sensors=sensor)


def test_coupled_rotation_refuses_both_sensors_and_a_coupling_of_the_other_sensor():
    with pytest.raises(InvalidChoiceError, match="is for one jaw sensor"):
        fit_jaw(REFERENCE, CURRENT, method="coupled-rotation")
    with pytest.raises(InvalidChoiceError, match="coupling is for MNI"):
        fit_jaw(REFERENCE, CURRENT, method=CoupledRotation(coupling=DEFAULT_COUPLINGS["MNI"]),
                jaw_sensors="MNM")


def test_sensor_sets_are_checked():
    assert jaw_sensor_set("mnm, MNI") == ("MNI", "MNM") and jaw_sensor_set(["MNM"]) == ("MNM",)
    for bad in ("", "MNI,MNI", "T1", "MNI,T1", ()):
        with pytest.raises(InvalidChoiceError, match="jaw sensors"):
            jaw_sensor_set(bad)


# ------------------------------------------------------- pivot methods from a far start
def far_cases():
    """(name, method, sensor, expected pivot): one sensor, 32 mm away from the answer."""
    at_truth = PivotPrior(tuple(PIVOT), (5.0, 5.0), "the truth, for the test")
    return [("fixed, from the data", FixedPivot(start=FAR, pivot_prior=PIVOT_FROM_DATA), "MNI"),
            ("fixed, from the data, MNM", FixedPivot(start=FAR, pivot_prior=PIVOT_FROM_DATA),
             "MNM"),
            ("fixed, prior", FixedPivot(start=FAR, pivot_prior=at_truth), "MNI"),
            ("smooth, prior", SmoothPivot(smoothness=100.0, start=FAR, pivot_prior=at_truth),
             "MNI")]


def check_far_start(method, sensor):
    """The one-sensor fit from 32 mm away finds the pivot that made the data (noise-free;
    the prior, where there is one, agrees with the data) and predicts the hidden sensor."""
    fit = fit_jaw(REFERENCE, CURRENT, method=method, jaw_sensors=sensor)
    assert fit.converged
    np.testing.assert_allclose(fit.pivot, np.broadcast_to(PIVOT, (N, 2)), atol=1e-3)
    np.testing.assert_allclose(fit.theta, THETA, atol=1e-6)
    hidden = 1 - ("MNI", "MNM").index(sensor)
    assert fit.hidden_sensor == ("MNI", "MNM")[hidden] and fit.jaw_sensors == (sensor,)
    np.testing.assert_allclose(fit.hidden_predicted, CURRENT[:, hidden], atol=1e-3)


@pytest.mark.parametrize("name, method, sensor", far_cases(), ids=[c[0] for c in far_cases()])
def test_one_sensor_pivot_methods_converge_from_a_far_start(name, method, sensor):
    check_far_start(method, sensor)


def test_one_sensor_far_start_tests_fail_when_the_solver_returns_its_start(
        solvers_return_their_start):
    for _, method, sensor in far_cases():
        with pytest.raises(AssertionError):
            check_far_start(method, sensor)


def test_a_prior_pulls_a_pivot_the_data_cannot_place_and_is_stated():
    """Speech-sized angles and noise: one sensor's arc hardly places the pivot; with the
    default prior the fit stays near it, says so, and is far better than without."""
    theta = 0.12 * np.sin(np.linspace(0.0, 3 * np.pi, N)) ** 2
    current = np.asarray(_move(theta, PIVOT, REFERENCE))
    current = current + np.random.default_rng(4).normal(0.0, 0.3, current.shape)
    free = fit_jaw(REFERENCE, current, method=FixedPivot(pivot_prior=PIVOT_FROM_DATA),
                   jaw_sensors="MNI")
    prior = fit_jaw(REFERENCE, current, method="fixed-pivot", jaw_sensors="MNI")
    assert prior.prior.startswith("pivot prior (-95, 25) mm, SD (15, 15) mm: population condyle")
    assert "SD from the prior" in prior.prior and free.prior == "pivot estimated from the data"
    error = {k: np.median(np.linalg.norm(f.hidden_predicted - current[:, 1], axis=1))
             for k, f in (("free", free), ("prior", prior))}
    assert np.linalg.norm(prior.pivot[0] - PIVOT) < 20.0
    assert error["prior"] < 0.5 * error["free"], error


# --------------------------------------------------------------------- coupled rotation
A = np.array([-0.006, -0.0075])  # rad per mm of MNI displacement


def coupled_track(n=N, a=A, seed=0):
    """A two-sensor track whose rotation is exactly ``a . d`` (d: MNI's displacement)."""
    from cassi_fit.txy import PelletTrack

    rng = np.random.default_rng(seed)
    s = np.sin(np.linspace(0.0, 4 * np.pi, n)) ** 2
    d = np.column_stack([-2.0 * s + 0.3 * rng.standard_normal(n), -18.0 * s])
    d[0] = 0.0
    theta = d @ a
    mni = REFERENCE[0] + d
    mnm = mni + _rotate(theta, REFERENCE[1] - REFERENCE[0])
    positions = np.zeros((n, 8, 2))
    positions[:, :6] = [[15.0, 18.0], [9.0, -21.0], [-17.0, 1.0], [-28.0, 8.0], [-39.0, 15.0],
                        [-53.0, 17.0]]
    positions[:, 6], positions[:, 7] = mni, mnm
    track = PelletTrack(times=np.arange(n) * 0.006866, positions=positions,
                        valid=np.ones((n, 8, 2), bool))
    return track, theta


def test_coupling_is_learned_and_predicts_the_hidden_sensor_exactly():
    track, theta = coupled_track()
    coupling = learn_jaw_coupling([track], "MNI", source="exact test data")
    np.testing.assert_allclose(coupling.rad_per_mm, A, atol=1e-9)
    assert coupling.theta_sd_rad < 1e-9 and coupling.frames == N
    fit = jaw_from_track(track, method=CoupledRotation(coupling=coupling), jaw_sensors="MNI")
    np.testing.assert_allclose(fit.theta, theta, atol=1e-9)
    np.testing.assert_allclose(fit.hidden_predicted, track.positions[:, 7], atol=1e-9)
    assert fit.solver == "coupled" and "exact test data" in fit.prior
    assert np.isnan(fit.noise_mm) and np.all(fit.residual == 0.0)


def test_a_wrong_coupling_scores_its_known_error():
    """20 % too much rotation: the hidden sensor is off by |R(1.2 theta) - R(theta)| r, by hand."""
    track, theta = coupled_track()
    wrong = JawCoupling("MNI", tuple(1.2 * A), 0.0, (0.0, 0.0), 1, "wrong by 20 %")
    fit = jaw_from_track(track, method=CoupledRotation(coupling=wrong), jaw_sensors="MNI")
    r = np.linalg.norm(REFERENCE[1] - REFERENCE[0])
    expected = 2.0 * r * np.abs(np.sin(0.2 * theta / 2.0))  # chord of the extra 0.2 theta
    error = np.linalg.norm(fit.hidden_predicted - track.positions[:, 7], axis=1)
    np.testing.assert_allclose(error, expected, atol=1e-9)


def test_coupled_uncertainty_grows_with_the_displacement():
    track, _ = coupled_track()
    fit = jaw_from_track(track, method="coupled-rotation", jaw_sensors="MNI")
    d = np.linalg.norm(track.positions[:, 6] - track.positions[0, 6], axis=1)
    sd = np.sqrt(fit.covariance[:, 0, 0])
    c = DEFAULT_COUPLINGS["MNI"]
    assert sd[0] == pytest.approx(c.theta_sd_rad)
    assert sd[np.argmax(d)] > 2 * c.theta_sd_rad


def test_one_sensor_ignores_the_other_sensors_gaps():
    """With MNI alone, frames where only MNM is untracked are fitted, and its prediction is
    there all the same."""
    track, _ = coupled_track()
    valid = track.valid.copy()
    valid[50:60, 7] = False
    from cassi_fit.txy import PelletTrack

    gappy = PelletTrack(times=track.times, positions=track.positions, valid=valid)
    fit = jaw_from_track(gappy, method="coupled-rotation", jaw_sensors="MNI")
    assert np.all(fit.status[50:60] == Status.OK)
    both = jaw_from_track(gappy, method="closed-form")
    assert np.all(both.status[50:60] == Status.INVALID_FRAME)
    assert np.isfinite(fit.hidden_predicted).all()


# ------------------------------------------------------------------ the real recording
@needs_real
def test_real_coupling_learned_on_one_half_predicts_mnm_on_the_other():
    """JW11 (one recording of one speaker): a coupling learned from the first half of the
    recording predicts MNM from MNI on the second half with a median error of 0.59 mm and a
    95th percentile of 1.00 mm (measured; experiments/single_sensor_jaw.py), better than
    the two-pellet fixed pivot that saw MNM (0.92, 2.37) and than translating MNM with MNI."""
    from cassi_fit.txy import PelletTrack, read_txy

    track = read_txy(REAL)
    n = track.n_frames
    first = np.arange(n) < n // 2
    half = PelletTrack(times=track.times, positions=track.positions,
                       valid=track.valid & first[:, None, None], path=track.path)
    coupling = learn_jaw_coupling([half], "MNI", source="JW11's first half")
    fit = jaw_from_track(track, method=CoupledRotation(coupling=coupling), jaw_sensors="MNI")
    mnm = track.positions[:, 7]
    use = ~first & (fit.status == Status.OK) & np.isfinite(mnm).all(axis=1)
    error = np.linalg.norm(fit.hidden_predicted[use] - mnm[use], axis=1)
    ref = fit.reference_frame
    translate = np.linalg.norm(mnm[ref] + track.positions[use, 6] - track.positions[ref, 6]
                               - mnm[use], axis=1)
    assert use.sum() > 350
    assert np.median(error) < 0.75 and np.percentile(error, 95) < 1.3
    assert np.median(error) < 0.6 * np.median(translate)


@needs_real
def test_real_default_couplings_are_what_the_recording_gives():
    from cassi_fit.txy import read_txy

    track = read_txy(REAL)
    for sensor in ("MNI", "MNM"):
        learned = learn_jaw_coupling([track], sensor, source="JW11")
        shipped = DEFAULT_COUPLINGS[sensor]
        np.testing.assert_allclose(learned.rad_per_mm, shipped.rad_per_mm, rtol=1e-5)
        assert learned.theta_sd_rad == pytest.approx(shipped.theta_sd_rad, rel=1e-5)
        assert learned.frames == shipped.frames


@needs_real
def test_real_one_sensor_pivot_is_badly_determined_without_a_prior():
    """The issue's measurement, reproduced: a pivot fitted freely to MNI alone lands about
    27 mm behind the incisors and misses MNM by about 7 mm (median); the default prior
    brings that under 3 mm."""
    from cassi_fit.jaw_fit import jaw_diagnostics
    from cassi_fit.txy import read_txy

    track = read_txy(REAL)
    jaw_points = track.positions[:, 6:8]
    free = jaw_from_track(track, method=FixedPivot(pivot_prior=PIVOT_FROM_DATA),
                          jaw_sensors="MNI")
    prior = jaw_from_track(track, method="fixed-pivot", jaw_sensors="MNI")
    assert -35.0 < free.pivot[0, 0] < -20.0
    assert 6.0 < jaw_diagnostics(free, jaw_points).hidden_error_median_mm < 9.0
    assert jaw_diagnostics(prior, jaw_points).hidden_error_median_mm < 3.0


@needs_real
def test_real_rows_of_the_generated_table_are_current():
    """A slice of experiments/single_sensor_jaw.py re-run (the real recording's same-speaker
    row) gives the numbers docs/generated/single_sensor_jaw.md shows: a stale table fails."""
    import importlib.util

    root = Path(__file__).resolve().parents[1]
    if str(root / "experiments") not in sys.path:  # its own imports (shared_data), when this
        sys.path.insert(0, str(root / "experiments"))  # file runs without the other files
    spec = importlib.util.spec_from_file_location(
        "single_sensor_jaw", root / "experiments" / "single_sensor_jaw.py")
    experiment = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(experiment)
    from cassi_fit.txy import read_txy

    row = experiment._split_rows([("JW11/tp005", "JW11", read_txy(REAL))], "MNI")
    table = (root / "docs" / "generated" / "single_sensor_jaw.md").read_text(encoding="utf-8")
    section = table.split("## real: MNM predicted from MNI")[1].split("##")[0]
    (line,) = [x for x in section.splitlines() if x.startswith(f"| {row['method']} |")]
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[3] == str(row["frames"])
    assert cells[4] == (f"{row['median_mm']:.2f} [{row['median_lo_mm']:.2f}, "
                        f"{row['median_hi_mm']:.2f}]")
    assert cells[5] == f"{row['p95_mm']:.2f}"
