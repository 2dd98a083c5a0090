"""The 3D palate from a PAL.DAT centreline: fixed topology, shape, never below the incisors,
joined to the upper teeth's necks, with a velum."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cassi_fit.errors import DegenerateGeometryError
from cassi_fit.face_model import load_model
from cassi_fit.palate import (
    DEFAULT_OUTLINE,
    MIN_HALF_WIDTH_MM,
    N_ACROSS,
    N_ALONG,
    N_HARD,
    VELUM_LENGTH_MM,
    VELUM_WALL_GAP_MM,
    build_palate,
    with_palate,
)
from cassi_fit.pharynx import DEFAULT_WALL, midline


def _outline(n, dip, seed):
    rng = np.random.default_rng(seed)
    x = np.linspace(-3.0, -65.0, n) + rng.normal(0, 0.5, n)
    y = 25.0 * np.sin(np.linspace(0.15, 1.5, n)) + dip + rng.normal(0, 1.0, n)
    return np.stack([x, y], -1)


# Outline point counts: the least (2), a few, PAL.DAT-like, and many. Each new count
# compiles the build anew, so the examples vary the shape (dip, noise) over these counts
# rather than over every count from 2 to 52.
POINT_COUNTS = (2, 3, 5, 11, 23, 52)
# compiled once per point count, as the model builds it (``palate._palate_vertices`` is a
# compiled kernel): op by op, 25 examples took 18 s, compiled 11 s
_compiled_build_palate = jax.jit(build_palate)


@settings(max_examples=25, deadline=None)
@given(n=st.sampled_from(POINT_COUNTS), dip=st.floats(-15.0, 5.0),
       seed=st.integers(0, 10_000))
def test_palate_never_below_the_upper_incisor_tip(n, dip, seed):
    verts, faces = _compiled_build_palate(_outline(n, dip, seed))
    assert verts.shape == (2 * N_ALONG * N_ACROSS, 3) and faces.max() < verts.shape[0]
    assert float(jnp.min(verts[:, 1])) >= 1.0 - 1e-12
    assert np.all(np.isfinite(np.asarray(verts)))


def test_narrow_front_wide_back_and_sloping_edges():
    v = np.asarray(_compiled_build_palate(DEFAULT_OUTLINE)[0])[: N_ALONG * N_ACROSS].reshape(N_ALONG, N_ACROSS, 3)
    v = v[:N_HARD]  # the hard palate (the velum narrows to the uvula)
    width = v[:, -1, 2] - v[:, 0, 2]
    assert width[0] < width[-1] and np.all(np.diff(width) >= 0)
    mid = N_ACROSS // 2
    assert np.all(v[1:, 0, 1] < v[1:, mid, 1])  # edges lower than the centreline
    np.testing.assert_allclose(v[:, mid, :2], np.asarray(_compiled_build_palate(DEFAULT_OUTLINE)[0])[mid:N_HARD * N_ACROSS:N_ACROSS, :2])


def test_palate_gradients_match_finite_differences():
    """The palate's vertices as a function of the PAL.DAT outline, joined to the model's
    teeth necks in front of its pharyngeal wall (as ``with_palate`` builds it): reverse
    derivatives agree with finite differences (float64)."""
    from jax.test_util import check_grads

    from cassi_fit.palate import model_arch
    from cassi_fit.pharynx import model_wall_midline

    model = load_model()
    where = {"arch": model_arch(model), "wall": model_wall_midline(model)}
    weights = jnp.asarray(np.random.default_rng(0).normal(size=(2 * N_ALONG * N_ACROSS, 3)))
    weighted = jax.jit(lambda o: jnp.sum(weights * build_palate(o, **where)[0]))
    check_grads(weighted, (jnp.asarray(DEFAULT_OUTLINE),), order=1, modes=["rev"],
                atol=1e-6, rtol=1e-6)


def test_with_palate_keeps_topology_and_moves_only_the_palate():
    model = load_model()
    # a subject's outline (below; its point count shares the compiled build with the
    # teeth-necks test), raised 3 mm
    out = SUBJECT_OUTLINE + np.array([0.0, 3.0])
    new = with_palate(model, out)
    idx = model.regions["palate"]
    moved = np.any(np.asarray(new.vertices) != np.asarray(model.vertices), axis=1)
    assert set(np.flatnonzero(moved)) <= set(idx) and moved[idx].any()


@pytest.mark.parametrize("bad", [np.zeros((1, 2)), np.zeros((5, 3)), np.zeros((4, 2)),
                                 np.array([[0.0, 1.0], [np.nan, 2.0]])])
def test_degenerate_outlines_raise(bad):
    with pytest.raises(DegenerateGeometryError):
        build_palate(bad)


MODEL = load_model()
# S01's PAL.DAT of the synthetic corpus (mm, pellet frame), every third point
SUBJECT_OUTLINE = np.array([
    (-4.141, 4.659), (-12.128, 14.206), (-20.115, 19.430), (-28.103, 22.289),
    (-36.090, 23.853), (-44.077, 24.709), (-52.064, 24.857), (-57.389, 24.084)])


def _necks(model):
    return np.asarray(model.vertices)[np.asarray(model.collision["upper_lingual_cervical"])]


def _oral(model):
    v = np.asarray(model.vertices)[np.asarray(model.regions["palate"])]
    return v[: N_ALONG * N_ACROSS].reshape(N_ALONG, N_ACROSS, 3)


@pytest.mark.parametrize("outline", [None, SUBJECT_OUTLINE], ids=["default", "subject"])
def test_the_hard_palate_meets_the_upper_teeth_necks(outline):
    model = MODEL if outline is None else with_palate(MODEL, outline)
    oral, necks = _oral(model), _necks(model)
    edges = np.concatenate([oral[:N_HARD, 0], oral[:N_HARD, -1]])
    gap = np.linalg.norm(necks[:, None] - edges[None], axis=-1).min(axis=1)
    # every neck is an edge vertex; the central incisors' mesial necks (at the midline)
    # only as near as a row's least half width allows
    off_midline = np.abs(necks[:, 2]) >= MIN_HALF_WIDTH_MM
    assert off_midline.sum() >= 24
    assert gap[off_midline].max() < 1e-3  # model.csv keeps 4 decimals
    assert gap.max() < MIN_HALF_WIDTH_MM + 0.5
    # the palate's midline is the centreline, and it is no wider than the necks
    if outline is not None:
        centre = oral[:N_HARD, N_ACROSS // 2]
        np.testing.assert_allclose(centre[:, 1], np.interp(-centre[:, 0], -outline[:, 0],
                                                           outline[:, 1]), atol=0.3)
    assert oral[:N_HARD, :, 2].max() <= necks[:, 2].max() + 1e-9


def test_the_velum_hangs_behind_the_hard_palate_attached():
    verts = np.asarray(_compiled_build_palate(DEFAULT_OUTLINE)[0])
    oral = verts[: N_ALONG * N_ACROSS].reshape(N_ALONG, N_ACROSS, 3)
    centre = oral[:, N_ACROSS // 2]
    pns, velum = centre[N_HARD - 1], centre[N_HARD:]
    steps = np.linalg.norm(np.diff(centre[N_HARD - 1:, :2], axis=0), axis=1)
    assert np.allclose(steps, steps[0]) and steps.sum() == pytest.approx(VELUM_LENGTH_MM)
    assert np.all(np.diff(velum[:, 0]) < 0) and np.all(np.diff(velum[:, 1]) < 0)  # down, back
    drop = np.degrees(np.arctan2(pns[1] - velum[-1, 1], pns[0] - velum[-1, 0]))
    assert drop == pytest.approx(50.0)  # 130 degrees to the palatal plane
    # one closed slab: the faces join the last hard row to the first velum row
    faces = _compiled_build_palate(DEFAULT_OUTLINE)[1]
    row = lambda i: (faces // N_ACROSS) % N_ALONG == i  # noqa: E731
    assert np.any(row(N_HARD - 1).any(axis=1) & row(N_HARD).any(axis=1))
    # the model's velum: present, thicker than the hard palate
    nasal = verts[N_ALONG * N_ACROSS:].reshape(N_ALONG, N_ACROSS, 3)
    thick = np.linalg.norm(nasal[:, N_ACROSS // 2] - centre, axis=1)
    assert thick[N_HARD:].max() > 2 * thick[:N_HARD].max()


def test_the_velum_stays_in_front_of_the_pharyngeal_wall():
    wall = np.asarray(midline(DEFAULT_WALL + np.array([12.0, 0.0])))  # a wall close behind
    verts = np.asarray(_compiled_build_palate(DEFAULT_OUTLINE, wall=wall)[0])
    free = np.asarray(_compiled_build_palate(DEFAULT_OUTLINE)[0])
    half = N_ALONG * N_ACROSS
    # the velum's midline, oral and nasal (back) surface, in front of the wall's midline
    velum = np.stack([verts[:half], verts[half:]]).reshape(2, N_ALONG, N_ACROSS, 3)
    back = velum[:, N_HARD:, N_ACROSS // 2].reshape(-1, 3)
    wall_x = np.interp(-back[:, 1], -wall[:, 1], wall[:, 0])
    assert np.all(back[:, 0] >= wall_x + VELUM_WALL_GAP_MM - 1e-6)
    # without the wall it would have crossed it
    fv = free[half:].reshape(N_ALONG, N_ACROSS, 3)[N_HARD:].reshape(-1, 3)
    assert np.any(fv[:, 0] < np.interp(-fv[:, 1], -wall[:, 1], wall[:, 0]))
