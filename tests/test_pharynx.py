"""The pharyngeal wall from PHA.DAT (or the default), the tongue kept in front of it, and
the airway between them."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cassi_fit import collide
from cassi_fit.errors import DegenerateGeometryError
from cassi_fit.face_model import load_model
from cassi_fit.pharynx import (
    DEFAULT_WALL,
    N_ACROSS,
    N_HEIGHT,
    SIDE_DEPTH_MM,
    build_pharynx,
    front_sheet,
    with_pharynx,
)

jax.config.update("jax_enable_x64", True)
MODEL = load_model()
S01_WALL = np.array([(-73.530, 15.572), (-73.471, -28.551)])  # the synthetic S01's PHA.DAT


@eqx.filter_jit
def _measures(model, v):
    """One frame's airway, collision report, per-vertex depths behind the wall and
    tongue penalty residuals, compiled once for both tests below (op by op, their many
    small operations compile one by one: seconds each); the model is a traced argument,
    so the default model and one with the subject's wall share the compilation."""
    return (collide.airway(model, v), collide.report(model, v),
            collide.depths(model, v)["tongue_pharynx"],
            collide.penalty_residuals(model, v, lips=False))


def _airway(model, v):
    return _measures(model, v)[0]


def _report(model, v):
    return _measures(model, v)[1]


def _front(verts):
    return np.asarray(verts)[: N_HEIGHT * N_ACROSS].reshape(N_HEIGHT, N_ACROSS, 3)


@pytest.mark.parametrize("points", [S01_WALL, None, S01_WALL[::-1]], ids=["s01", "default", "reversed"])
def test_the_wall_runs_through_the_pha_line_and_curves_forward_at_the_sides(points):
    verts, faces = build_pharynx(points)
    assert verts.shape == (2 * N_HEIGHT * N_ACROSS, 3) and faces.max() < verts.shape[0]
    front = _front(verts)
    line = DEFAULT_WALL if points is None else points
    (x0, y0), (x1, y1) = sorted(line.tolist(), key=lambda p: -p[1])
    mid = front[:, N_ACROSS // 2]
    between = (mid[:, 1] <= y0) & (mid[:, 1] >= y1)
    assert between.sum() >= 4  # rows within the traced part of the wall ...
    on_line = x0 + (mid[between, 1] - y0) * (x1 - x0) / (y1 - y0)
    np.testing.assert_allclose(mid[between, 0], on_line, atol=1e-9)  # ... lie on its line
    assert mid[0, 1] > y0 + 15 and mid[-1, 1] < y1 - 20  # extended up and down
    assert np.all(np.diff(mid[:, 1]) < 0)  # a height field: rows run down
    # U-shaped: the sides come forward, the wall is symmetric and 26-38 mm wide
    np.testing.assert_allclose(front[:, 0, 0] - mid[:, 0], SIDE_DEPTH_MM)
    np.testing.assert_allclose(front[:, 0, 2], -front[:, -1, 2])
    width = front[:, -1, 2] - front[:, 0, 2]
    assert 24 <= width.min() and width.max() <= 40
    # the back sheet lies behind the front one
    assert np.all(np.asarray(verts)[N_HEIGHT * N_ACROSS:, 0] < front.reshape(-1, 3)[:, 0])


@pytest.mark.parametrize("bad", [np.zeros((1, 2)), np.zeros((2, 3)),
                                 np.array([[-70.0, 10.0], [-72.0, 10.2]]),
                                 np.array([[-70.0, np.nan], [-72.0, -20.0]])])
def test_degenerate_walls_raise(bad):
    with pytest.raises(DegenerateGeometryError):
        build_pharynx(bad)


def test_with_pharynx_moves_only_the_wall():
    new = with_pharynx(MODEL, S01_WALL)
    moved = np.any(np.asarray(new.vertices) != np.asarray(MODEL.vertices), axis=1)
    assert set(np.flatnonzero(moved)) <= set(MODEL.regions["pharynx"]) and moved.any()


def test_wall_gradients_match_finite_differences():
    """The wall's vertices as a function of the PHA.DAT points: reverse derivatives
    agree with finite differences (float64)."""
    from jax.test_util import check_grads

    weights = jnp.asarray(np.random.default_rng(0).normal(size=(2 * N_HEIGHT * N_ACROSS, 3)))
    weighted = jax.jit(lambda p: jnp.sum(weights * build_pharynx(p)[0]))
    check_grads(weighted, (jnp.asarray(S01_WALL),), order=1, modes=["rev"], atol=1e-6,
                rtol=1e-6)


def _tongue_at(model, points):
    """The model's vertices with its tongue vertices all at ``points`` (cycled)."""
    v = np.asarray(model.vertices).copy()
    tongue = np.asarray(model.regions["tongue"])
    v[tongue] = np.resize(np.asarray(points, float), (len(tongue), 3))
    return jnp.asarray(v)


def test_airway_against_a_hand_computed_wall_distance():
    # the default wall's midline at y = 0 lies on its PHA line: x = -74 + 18.5 * 4 / 48.5
    wall_x = -74.0 + 18.5 * 4.0 / 48.5
    v = _tongue_at(MODEL, [(-60.0, 0.0, 0.0), (-50.0, 5.0, 0.0), (-70.0, 0.0, 0.0)])
    assert float(_airway(MODEL, v)) == pytest.approx(-70.0 - wall_x, abs=1e-3)  # model.csv keeps 4 decimals
    v = _tongue_at(MODEL, [(-60.0, 0.0, 0.0), (-75.0, 0.0, 0.0)])
    assert float(_airway(MODEL, v)) == pytest.approx(-75.0 - wall_x, abs=1e-3)  # model.csv keeps 4 decimals
    assert float(_report(MODEL, v)["tongue_pharynx"]) == pytest.approx(wall_x + 75.0, abs=1e-3)
    # at the side (z = half width) the lateral wall is SIDE_DEPTH_MM further forward
    front = front_sheet(MODEL, jnp.asarray(MODEL.vertices))
    half = float(np.interp(0.0, -np.asarray(front[:, -1, 1]), np.asarray(front[:, -1, 2])))
    v = _tongue_at(MODEL, [(-50.0, 0.0, half)])
    assert float(_airway(MODEL, v)) == pytest.approx(-50.0 - wall_x - SIDE_DEPTH_MM, abs=1e-3)
    frames = collide.airway_frames(MODEL, jnp.stack([v, v]))
    assert frames.shape == (2,)


def test_a_tongue_pushed_through_the_wall_is_projected_in_front_of_it():
    model = with_pharynx(MODEL, S01_WALL)
    v = np.asarray(model.vertices).copy()
    tongue = np.asarray(model.regions["tongue"])
    # the whole tongue pushed back through the wall: 12 mm beyond its rest airway
    v[tongue, 0] -= 12.0 + max(float(_airway(model, jnp.asarray(v))), 0.0)
    v = jnp.asarray(v)
    airway_before, _, before, penalty = _measures(model, v)
    before = np.asarray(before)
    assert before.max() > 10.0 and float(airway_before) < -10.0
    after = eqx.filter_jit(collide.project)(model, v)
    airway_after, _, behind_after, _ = _measures(model, after)
    assert float(np.max(np.asarray(behind_after))) == 0.0
    assert float(airway_after) >= 0.0
    moved = np.asarray(after - v)
    # out of the wall is forward: every tongue point that was behind it moved forward
    behind = tongue[before > 0]  # depths are per tongue vertex
    assert behind.size > 0 and np.all(moved[behind, 0] > 0.0)
    assert np.any(np.asarray(penalty) > 10.0)
