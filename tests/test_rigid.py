"""Planar rigid motions: the paper's convention, composition, fractional motion, pivot."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cassi_fit import rigid

RNG = np.random.default_rng(7)


def test_positive_theta_opens_the_jaw():
    # A point in front of and above the pivot moves down when theta > 0 (Eqs 4-5).
    theta, t = rigid.from_pivot(0.2, jnp.array([-90.0, 25.0]))
    incisor = jnp.array([-1.0, -8.0])
    assert rigid.apply(theta, t, incisor)[1] < incisor[1]


def test_apply_matches_eqs_4_5():
    a, b = -85.0, 20.0
    for theta in RNG.uniform(-1, 1, 5):
        x, y = RNG.uniform(-50, 10, 2)
        motion = rigid.from_pivot(theta, jnp.array([a, b]))
        xp, yp = np.asarray(rigid.apply(*motion, jnp.array([x, y])))
        assert xp - a == pytest.approx((x - a) * np.cos(theta) + (y - b) * np.sin(theta), abs=1e-10)
        assert yp - b == pytest.approx(-(x - a) * np.sin(theta) + (y - b) * np.cos(theta), abs=1e-10)


def test_third_axis_is_kept():
    p = jnp.array([[1.0, 2.0, 3.0]])
    assert float(rigid.apply(0.3, jnp.array([1.0, 1.0]), p)[0, 2]) == 3.0


def test_compose_inverse_relative():
    m1 = (0.3, jnp.array([1.0, -2.0]))
    m2 = (-0.1, jnp.array([4.0, 0.5]))
    p = jnp.array([3.0, 4.0])
    np.testing.assert_allclose(
        rigid.apply(*rigid.compose(m2, m1), p), rigid.apply(*m2, rigid.apply(*m1, p)), atol=1e-12
    )
    np.testing.assert_allclose(rigid.apply(*rigid.inverse(m1), rigid.apply(*m1, p)), p, atol=1e-12)
    rel = rigid.relative(m1, m2)
    np.testing.assert_allclose(rigid.apply(*rel, rigid.apply(*m1, p)), rigid.apply(*m2, p), atol=1e-12)


@pytest.mark.parametrize("weight", [0.0, 0.39, 0.83, 1.0, 1.11111])
@pytest.mark.parametrize("theta", [-0.4, -1e-5, 1e-4, 0.05, 0.4, np.pi])
def test_fractional_turns_about_the_same_pivot(weight, theta):
    pivot = jnp.array([-92.0, 24.0])
    w_theta, w_t = rigid.fractional(rigid.from_pivot(theta, pivot), weight)
    expected = rigid.from_pivot(weight * theta, pivot)
    assert float(w_theta) == pytest.approx(weight * theta)
    np.testing.assert_allclose(w_t, expected[1], rtol=1e-9, atol=1e-9)


def test_fractional_of_a_translation_scales_it():
    t = jnp.array([1.5, -2.0])
    _, w_t = rigid.fractional((0.0, t), 0.56)
    np.testing.assert_allclose(w_t, 0.56 * t, atol=1e-15)


def test_fractional_gradient_is_finite_and_continuous_at_zero():
    t = jnp.array([1.0, 2.0])

    def f(theta):
        return rigid.fractional((theta, t), 0.39)[1].sum()

    g0 = jax.grad(f)(0.0)
    eps = 1e-2  # well outside the series branch
    fd = (f(eps) - f(-eps)) / (2 * eps)
    assert np.isfinite(g0)
    assert float(g0) == pytest.approx(float(fd), rel=1e-4)
    # both sides of the series threshold agree
    assert float(jax.grad(f)(0.999e-3 * 2)) == pytest.approx(float(jax.grad(f)(1.001e-3 * 2)), rel=1e-6)


def test_pivot_recovered_and_undefined_at_zero():
    q = jnp.array([-80.0, 30.0])
    found, defined = rigid.pivot(rigid.from_pivot(0.1, q))
    assert bool(defined)
    np.testing.assert_allclose(found, q, atol=1e-9)
    found, defined = rigid.pivot((0.0, jnp.array([1.0, 0.0])))
    assert not bool(defined)
    assert np.all(np.isfinite(np.asarray(found)))
    grad = jax.grad(lambda th: rigid.pivot((th, jnp.array([1.0, 0.0])))[0].sum())(0.0)
    assert np.isfinite(grad)


def test_jit_and_vmap_agree_with_eager():
    thetas = jnp.linspace(-0.3, 0.3, 7)
    ts = jnp.stack([jnp.linspace(-1, 1, 7), jnp.linspace(2, -2, 7)], axis=1)
    eager = [rigid.fractional((th, t), 0.83) for th, t in zip(thetas, ts, strict=True)]
    batched = jax.jit(jax.vmap(lambda th, t: rigid.fractional((th, t), 0.83)))(thetas, ts)
    np.testing.assert_allclose(batched[1], np.stack([e[1] for e in eager]), atol=1e-12)
