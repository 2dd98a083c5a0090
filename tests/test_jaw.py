"""The closed forms of jaw rotation (cassi_fit.jaw): Eqs 1-3, 6-7, the sound form, Procrustes."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cassi_fit import jaw, rigid
from cassi_fit.status import Status

# A typical jaw in the pellet frame (mm): MNI below and behind the upper incisor, MNM behind.
REFERENCE = jnp.array([[-2.0, -18.0], [-35.0, -24.0]])
rng = np.random.default_rng(7)

closed_form_batch = jaw.closed_form_frames  # the toolkit's one compiled closed form
paper_batch = jax.jit(jax.vmap(jaw.closed_form_paper, in_axes=(None, 0)))
move_batch = jax.vmap(rigid.apply, in_axes=(0, 0, None))


def random_motions(n, max_theta=0.6):
    theta = rng.uniform(-max_theta, max_theta, n)
    theta = np.where(np.abs(theta) < 1e-3, 1e-3, theta)
    t = rng.normal(0.0, 5.0, (n, 2))
    return jnp.asarray(theta), jnp.asarray(t)


def test_paper_eqs_6_7_against_a_linear_solve():
    """Eqs 6-7 as printed equal the solution of (I - R) q = p1' - R p1, solved numerically."""
    theta, t = random_motions(200)
    current = move_batch(theta, t, REFERENCE)
    theta_p, a, b = paper_batch(REFERENCE, current)
    np.testing.assert_allclose(theta_p, theta, atol=1e-12)
    for k in range(len(theta)):
        rot = np.asarray(rigid.rotation_matrix(theta[k]))
        rhs = np.asarray(current[k, 0]) - rot @ np.asarray(REFERENCE[0])
        q = np.linalg.solve(np.eye(2) - rot, rhs)
        np.testing.assert_allclose([a[k], b[k]], q, rtol=1e-9, atol=1e-9)


def test_sound_form_agrees_with_paper_where_both_defined():
    theta, t = random_motions(500)
    current = move_batch(theta, t, REFERENCE) + rng.normal(0, 0.3, (500, 2, 2))
    motion = closed_form_batch(REFERENCE, current)
    theta_p, a, b = paper_batch(REFERENCE, current)
    np.testing.assert_allclose(motion.theta, theta_p, atol=1e-12)
    np.testing.assert_allclose(motion.pivot, np.stack([a, b], -1), rtol=1e-9, atol=1e-9)
    assert np.all(np.asarray(motion.status) == Status.OK)


def test_noise_free_motion_recovered_exactly():
    theta, t = random_motions(300, max_theta=3.0)
    current = move_batch(theta, t, REFERENCE)
    for form in (closed_form_batch, jaw.procrustes_frames):
        motion = form(REFERENCE, current)
        np.testing.assert_allclose(motion.theta, theta, atol=1e-12)
        np.testing.assert_allclose(motion.translation, t, atol=1e-10)
        moved = move_batch(motion.theta, motion.translation, REFERENCE)
        np.testing.assert_allclose(moved, current, atol=1e-10)


def test_paper_form_fails_where_the_sound_form_does_not():
    """Reproduction, not repair: Eqs 6-7 divide by zero at theta = 0, Eq 1 is quadrant-blind."""
    _, a, _ = jaw.closed_form_paper(REFERENCE, REFERENCE + jnp.array([[1.0, 0.0]]))
    assert not np.isfinite(a)
    motion = jaw.closed_form(REFERENCE, REFERENCE + jnp.array([[1.0, 0.0]]))
    assert int(motion.status) == Status.PIVOT_UNDEFINED
    np.testing.assert_allclose(motion.translation, [1.0, 0.0])
    turned = rigid.apply(2.5, jnp.zeros(2), REFERENCE)
    assert abs(float(jaw.closed_form_paper(REFERENCE, turned)[0]) - 2.5) > 1.0
    assert float(jaw.closed_form(REFERENCE, turned).theta) == pytest.approx(2.5, abs=1e-12)


@pytest.mark.parametrize("theta", [0.0, np.pi, -np.pi / 2, 0.1])
def test_finite_gradients_including_theta_zero_and_pi(theta):
    current = rigid.apply(theta, jnp.array([0.5, -1.0]), REFERENCE)

    def scalar(ref, cur):
        m = jaw.closed_form(ref, cur)
        return m.theta + jnp.sum(m.translation) + jnp.sum(m.pivot)

    g_ref, g_cur = jax.grad(scalar, argnums=(0, 1))(REFERENCE, current)
    assert np.all(np.isfinite(g_ref)) and np.all(np.isfinite(g_cur))
    assert np.any(np.asarray(g_cur) != 0.0)
    m = jaw.closed_form(REFERENCE, current)
    wrapped = np.pi if theta == np.pi else theta
    assert float(m.theta) == pytest.approx(wrapped, abs=1e-12)


def test_gradient_matches_finite_differences():
    current = rigid.apply(0.3, jnp.array([0.5, -1.0]), REFERENCE) + 0.2

    def scalar(cur):
        m = jaw.closed_form(REFERENCE, cur)
        return m.theta * 10 + m.translation[0] + m.pivot[1] * 0.1

    grad = np.asarray(jax.grad(scalar)(current))
    h = 1e-6
    for i in range(2):
        for j in range(2):
            e = jnp.zeros((2, 2)).at[i, j].set(h)
            fd = (scalar(current + e) - scalar(current - e)) / (2 * h)
            assert grad[i, j] == pytest.approx(float(fd), rel=1e-6, abs=1e-8)


def test_jit_and_no_jit_agree():
    theta, t = random_motions(20)
    current = move_batch(theta, t, REFERENCE)
    current = current.at[3, 0].set(jnp.nan).at[5, 1].set(current[5, 0])
    with jax.disable_jit():
        plain = [jaw.closed_form(REFERENCE, c) for c in current]
    jitted = closed_form_batch(REFERENCE, current)
    for k, m in enumerate(plain):
        assert float(m.theta) == pytest.approx(float(jitted.theta[k]), abs=1e-14)
        np.testing.assert_allclose(m.pivot, jitted.pivot[k], atol=1e-12)
        assert int(m.status) == int(jitted.status[k])
    assert [Status(int(c)).label for c in jitted.status[2:6]] == [
        "ok", "non-finite", "ok", "degenerate"]
    assert jitted.theta.shape == (20,) and jitted.translation.shape == (20, 2)


@pytest.mark.parametrize(
    "current, status",
    [
        (jnp.array([[1.0, 1.0], [1.0, 1.0]]), Status.DEGENERATE),
        (jnp.array([[jnp.nan, 1.0], [3.0, 1.0]]), Status.NON_FINITE),
        (jnp.array([[1.0, 1.0], [jnp.inf, 1.0]]), Status.NON_FINITE),
    ],
)
def test_bad_input_gives_status_never_nan(current, status):
    for form in (jaw.closed_form, jaw.procrustes):
        m = form(REFERENCE, current)
        assert int(m.status) == status
        assert not bool(m.pivot_defined)
        for leaf in (m.theta, m.translation, m.pivot):
            assert np.all(np.isfinite(leaf))
        g = jax.grad(lambda c, f=form: f(REFERENCE, c).theta + f(REFERENCE, c).translation.sum())(
            current
        )
        assert np.all(np.isfinite(g))
    # coincident pellets in the reference are degenerate too
    assert int(jaw.closed_form(jnp.zeros((2, 2)), REFERENCE).status) == Status.DEGENERATE


def test_procrustes_is_the_least_squares_motion():
    current = rigid.apply(0.2, jnp.array([1.0, 2.0]), REFERENCE) + jnp.array(
        [[0.3, -0.2], [-0.1, 0.4]]
    )
    m = jaw.procrustes(REFERENCE, current)

    def cost(theta, t):
        return float(jnp.sum((rigid.apply(theta, t, REFERENCE) - current) ** 2))

    best = cost(m.theta, m.translation)
    for d in np.eye(3) * 1e-4:
        assert cost(m.theta + d[0], m.translation + d[1:]) > best
        assert cost(m.theta - d[0], m.translation - d[1:]) > best


def test_float32_arctangent_is_accurate_in_every_octant():
    """The closed form's float32 arctangent (arithmetic only, since XLA's CPU one is a slow
    scalar loop) against numpy's float64 one: within 2 float32 ulps of pi everywhere,
    including the axes, the octant borders and -0.0 (which the closed form folds to +pi)."""
    angles = np.concatenate([np.linspace(-np.pi, np.pi, 20001),
                             np.arange(-8, 9) * np.pi / 8 + 1e-7])
    y, x = np.sin(angles), np.cos(angles)
    y = np.concatenate([y, [0.0, -0.0, -0.0, 1.0, -1.0, 3.0]]).astype(np.float32)
    x = np.concatenate([x, [-1.0, -1.0, 2.0, 0.0, 0.0, 3.0]]).astype(np.float32)
    got = np.asarray(jax.jit(jaw._atan2_float32)(jnp.asarray(y), jnp.asarray(x)))
    want = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    error = (got - want + np.pi) % (2 * np.pi) - np.pi  # -pi and +pi: one angle
    assert got.dtype == np.float32 and np.all(np.abs(got) <= np.float32(np.pi))
    assert np.max(np.abs(error)) <= 2 * np.spacing(np.float32(np.pi))
    folded = jaw._turn_angle(jnp.array([1.0, 0.0], jnp.float32),
                             jnp.array([-1.0, -0.0], jnp.float32))[0]
    assert folded == np.float32(np.pi)


def test_float32_closed_form_agrees_with_float64():
    theta, t = random_motions(500, max_theta=3.0)
    current = move_batch(theta, t, REFERENCE) + rng.normal(0, 0.3, (500, 2, 2))
    m64 = closed_form_batch(REFERENCE, current)
    m32 = closed_form_batch(REFERENCE.astype(jnp.float32), current.astype(jnp.float32))
    assert m32.theta.dtype == jnp.float32
    # float32 coordinates of ~40 mm carry ~2e-6 mm: angles to ~1e-7 rad, translations to
    # ~1e-5 mm
    np.testing.assert_allclose(m32.theta, m64.theta, atol=5e-7)
    np.testing.assert_allclose(m32.translation, m64.translation, atol=2e-4)
    np.testing.assert_array_equal(m32.status, m64.status)
