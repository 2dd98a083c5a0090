"""The closed form's half turn: its angle range is (-pi, pi] (docs/JAW.md), so a jaw line
turned by exactly half a turn reads +pi, on every path that runs it over frames."""

import jax.numpy as jnp
import numpy as np

from cassi_fit import jaw
from cassi_fit.jaw_fit import fit_jaw

# MNI 40 mm ahead of MNM on a level line; then the line turned by a quarter (both ways)
# and by half a turn about MNM, as exact coordinates: the half turn puts MNI 40 mm behind
# MNM with a y difference of exactly zero, where atan2(-0.0, -1600) is -pi.
REFERENCE = np.array([[0.0, 0.0], [-40.0, 0.0]])
FRAMES = np.array([
    [[0.0, 0.0], [-40.0, 0.0]],
    [[-40.0, 40.0], [-40.0, 0.0]],
    [[-40.0, -40.0], [-40.0, 0.0]],
    [[-80.0, 0.0], [-40.0, 0.0]],
])
WANT = np.array([0.0, -np.pi / 2, np.pi / 2, np.pi])  # + opens (turns the line down)


def test_a_half_turn_reads_plus_pi_in_the_closed_form_over_frames():
    motion = jaw.closed_form_frames(jnp.asarray(REFERENCE), jnp.asarray(FRAMES))
    theta = np.asarray(motion.theta)
    assert theta.dtype == np.float64
    np.testing.assert_allclose(theta, WANT, atol=1e-12)
    assert theta[-1] == np.pi  # not -pi: the range is (-pi, pi]


def test_a_half_turn_reads_plus_pi_in_the_jaw_fit():
    fit = fit_jaw(REFERENCE, FRAMES, method="closed-form")
    theta = np.asarray(fit.theta)
    np.testing.assert_allclose(theta, WANT, atol=1e-12)
    assert theta[-1] == np.pi
