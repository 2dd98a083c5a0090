"""The lossy tube (cassi_fit.tube) against closed forms, published vowels and its gradient."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from cassi_fit import tube

C_MM_S = tube.C_CM_S * 10.0
N = 44  # every tract of this module (Story's): one compilation
# viscous loss alone: the peaks are those of the lossless tube to well under 0.1 % (the
# lossless tube's peaks are poles, not maxima a Newton step can refine)
NEARLY_LOSSLESS = tube.Losses(viscous=True, thermal=False, wall=False, radiation=False)

# Story (2008)'s MRI vowels and Peterson & Barney's men's means: the module's published data
STORY = tube.STORY_2008
PETERSON_BARNEY = tube.PETERSON_BARNEY_MEN


@pytest.fixture(scope="module")
def formants_jit():
    jitted = jax.jit(tube.formants)  # one compilation: every tract here has N sections

    def call(areas, lengths, losses=tube.ALL_LOSSES):
        as_bools = tube.Losses(*(bool(x) for x in losses))
        return jitted(np.asarray(areas, np.float64), np.asarray(lengths, np.float64), as_bools)

    return call


def test_uniform_tube_resonances_are_odd_quarter_waves(formants_jit):
    length = 175.0
    areas, lengths = tube.uniform_tube(length, 300.0, N)
    closed = np.array([(2 * n - 1) * C_MM_S / (4 * length) for n in range(1, 5)])
    # lossless: the denominator of H vanishes at (2n-1) c / 4L
    for f in closed:
        assert abs(1.0 / tube.transfer(f, areas, lengths, tube.LOSSLESS)) < 1e-9
    got = np.asarray(formants_jit(areas, lengths, NEARLY_LOSSLESS).frequency)
    np.testing.assert_allclose(got, closed, rtol=1e-3)


def test_two_tube_resonator_matches_its_resonance_condition(formants_jit):
    # back tube (glottis, closed) l1, A1; front tube (open) l2, A2: lossless resonances where
    # tan(k l1) tan(k l2) = A2 / A1
    l1, a1, l2, a2 = 90.0, 100.0, 80.0, 600.0
    areas = jnp.concatenate([jnp.full(N // 2, a1), jnp.full(N // 2, a2)])
    lengths = jnp.concatenate([jnp.full(N // 2, l1 / (N // 2)), jnp.full(N // 2, l2 / (N // 2))])

    def cond(f):
        k = 2 * np.pi * f / C_MM_S
        return a1 * np.sin(k * l1) * np.sin(k * l2) - a2 * np.cos(k * l1) * np.cos(k * l2)

    grid = np.arange(50.0, 5000.0, 1.0)
    v = cond(grid)
    roots = [brentq(cond, grid[i], grid[i + 1]) for i in np.nonzero(np.sign(v[:-1]) != np.sign(v[1:]))[0]]
    # the sign changes of the product form include the poles of tan: keep true zeros
    roots = [r for r in roots if abs(cond(r)) < 1e-6][:4]
    got = np.asarray(formants_jit(areas, lengths, NEARLY_LOSSLESS).frequency)
    np.testing.assert_allclose(got, roots, rtol=2e-3)


@pytest.mark.parametrize("vowel", ["i", "a", "u"])
def test_published_vowels_with_all_losses(formants_jit, vowel):
    """Story's MRI area functions of /i/, /a/, /u/ through the lossy tube land within 25 %
    of Peterson & Barney's men's average F1-F3 (one speaker against a population mean: the
    tolerance is the spread of men's vowels) and keep the vowels' order."""
    step, cm2 = STORY[vowel]
    areas = jnp.asarray(cm2) * 100.0
    lengths = jnp.full(len(cm2), step * 10.0)
    res = formants_jit(areas, lengths, tube.Losses())
    f = np.asarray(res.frequency)[:3]
    np.testing.assert_allclose(f, PETERSON_BARNEY[vowel], rtol=0.25)
    bw = np.asarray(res.bandwidth)[:3]
    assert np.all((bw > 10.0) & (bw < 300.0))


def test_losses_raise_f1_and_widen_bandwidths(formants_jit):
    areas, lengths = tube.uniform_tube(175.0, 300.0, N)
    lossy = formants_jit(areas, lengths, tube.Losses())
    nearly = formants_jit(areas, lengths, NEARLY_LOSSLESS)
    # the yielding wall raises F1 (Fant 1972; Sondhi & Schroeter 1987's Fig.)
    assert float(lossy.frequency[0]) > float(nearly.frequency[0]) + 10.0
    assert np.all(np.asarray(lossy.bandwidth) > np.asarray(nearly.bandwidth))


def test_formant_gradient_matches_finite_differences(formants_jit):
    step, cm2 = STORY["a"]
    areas = jnp.asarray(cm2) * 100.0
    lengths = jnp.full(len(cm2), step * 10.0)
    weights = jnp.array([1.0, 0.3, 0.1])

    def f(a, ln):  # one scalar of F1-F3: one reverse-mode compilation
        return weights @ tube.formants(a, ln).frequency[:3]

    grad_a, grad_l = jax.jit(jax.grad(f, argnums=(0, 1)))(areas, lengths)

    def f_jit(a, ln):
        return weights @ formants_jit(a, ln).frequency[:3]

    for k in (3, 20, 38):
        e = jnp.zeros(len(cm2)).at[k].set(1e-3)
        fd = (f_jit(areas + e, lengths) - f_jit(areas - e, lengths)) / 2e-3
        np.testing.assert_allclose(grad_a[k], fd, rtol=1e-4, atol=1e-6)
    # a longer tract lowers the formants
    assert float(jnp.sum(grad_l)) < 0
    assert np.all(np.isfinite(np.asarray(grad_a)))


def test_yielding_wall_raises_f1_by_the_closed_tract_resonance(formants_jit):
    """The magnitude of the wall's F1 shift: a uniform tube whose walls are a mass per area
    ``m`` (Maeda 1982's 1.5 g/cm^2) resonates where F1^2 = F1_rigid^2 + Fw^2, with the
    closed-tract resonance Fw^2 = S rho c^2 / (4 pi^2 A m) (the air's compliance against
    the walls' mass; Fant 1972, "Vocal tract wall effects, losses, and resonance
    bandwidths", STL-QPSR; about 180-250 Hz for adult men).
    The walls' resistance and stiffness move it by well under 1 %."""
    length, area_mm2 = 175.0, 300.0
    areas, lengths = tube.uniform_tube(length, area_mm2, N)
    wall_only = tube.Losses(viscous=True, thermal=False, wall=True, radiation=False)
    f1_wall = float(formants_jit(areas, lengths, wall_only).frequency[0])
    f1_rigid = float(formants_jit(areas, lengths, NEARLY_LOSSLESS).frequency[0])
    a_cm2 = area_mm2 / 100.0
    perimeter = 2.0 * np.sqrt(np.pi * a_cm2)
    fw = np.sqrt(perimeter * tube.RHO * tube.C_CM_S**2 / (a_cm2 * tube.WALL_MASS)) / (2 * np.pi)
    assert 180.0 < fw < 250.0
    np.testing.assert_allclose(f1_wall, np.hypot(f1_rigid, fw), rtol=0.01)
