"""The 3D palate from a PAL.DAT centreline: fixed topology, shape, never below the incisors."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cassi_fit.errors import DegenerateGeometryError
from cassi_fit.face_model import load_model
from cassi_fit.palate import DEFAULT_OUTLINE, N_ACROSS, N_ALONG, build_palate, with_palate


def _outline(n, dip, seed):
    rng = np.random.default_rng(seed)
    x = np.linspace(-3.0, -65.0, n) + rng.normal(0, 0.5, n)
    y = 25.0 * np.sin(np.linspace(0.15, 1.5, n)) + dip + rng.normal(0, 1.0, n)
    return np.stack([x, y], -1)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 52), dip=st.floats(-15.0, 5.0), seed=st.integers(0, 10_000))
def test_palate_never_below_the_upper_incisor_tip(n, dip, seed):
    verts, faces = build_palate(_outline(n, dip, seed))
    assert verts.shape == (2 * N_ALONG * N_ACROSS, 3) and faces.max() < verts.shape[0]
    assert float(jnp.min(verts[:, 1])) >= 1.0 - 1e-12
    assert np.all(np.isfinite(np.asarray(verts)))


def test_narrow_front_wide_back_and_sloping_edges():
    v = np.asarray(build_palate(DEFAULT_OUTLINE)[0])[: N_ALONG * N_ACROSS].reshape(N_ALONG, N_ACROSS, 3)
    width = v[:, -1, 2] - v[:, 0, 2]
    assert width[0] < width[-1] and np.all(np.diff(width) >= 0)
    mid = N_ACROSS // 2
    assert np.all(v[1:, 0, 1] < v[1:, mid, 1])  # edges lower than the centreline
    np.testing.assert_allclose(v[:, mid, :2], np.asarray(build_palate(DEFAULT_OUTLINE)[0])[mid:N_ALONG * N_ACROSS:N_ACROSS, :2])


def test_palate_gradient_is_finite():
    g = jax.grad(lambda o: jnp.sum(build_palate(o)[0] ** 2))(jnp.asarray(DEFAULT_OUTLINE))
    assert np.all(np.isfinite(np.asarray(g))) and np.any(np.asarray(g) != 0)


def test_with_palate_keeps_topology_and_moves_only_the_palate():
    model = load_model()
    out = DEFAULT_OUTLINE + np.array([0.0, 3.0])
    new = with_palate(model, out)
    idx = model.regions["palate"]
    moved = np.any(np.asarray(new.vertices) != np.asarray(model.vertices), axis=1)
    assert set(np.flatnonzero(moved)) <= set(idx) and moved[idx].any()


@pytest.mark.parametrize("bad", [np.zeros((1, 2)), np.zeros((5, 3)), np.zeros((4, 2)),
                                 np.array([[0.0, 1.0], [np.nan, 2.0]])])
def test_degenerate_outlines_raise(bad):
    with pytest.raises(DegenerateGeometryError):
        build_palate(bad)
