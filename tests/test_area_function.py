"""The area function (cassi_fit.area_function) of the model's posed frames."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cassi_fit import area_function as af
from cassi_fit.deform import default_params, deform
from cassi_fit.face_model import load_model


@pytest.fixture(scope="module")
def setup():
    model = load_model()
    geometry = af.tract_geometry(model)
    p0 = default_params(model)
    # the jaw lowered 12 mm, and the tongue's back pellets down and back: an /a/-like frame
    opened = eqx.tree_at(lambda p: (p.jaw_translation, p.tongue), p0,
                         (jnp.array([0.0, -12.0]),
                          p0.tongue + jnp.array([[0, -12], [0, -12], [-4, -14], [-6, -12]], float)))
    posed = jax.jit(jax.vmap(lambda p: deform(model, p)))
    frames = posed(jax.tree.map(lambda a, b: jnp.stack([a, b]), p0, opened))
    run = jax.jit(lambda v, t: af.area_functions(geometry, v, t))
    return model, geometry, frames, run


def test_areas_and_lengths_of_rest_and_open_frames(setup):
    _, _, frames, run = setup
    areas, lengths, regions = (np.asarray(x) for x in run(frames, af.default_tract()))
    assert areas.shape == lengths.shape == regions.shape == (2, af.N_SECTIONS)
    assert np.all(areas >= af.MIN_AREA_MM2) and np.all(lengths > 0)
    # an adult male tract from the glottis to the lips: 14-20 cm (Fitch & Giedd 1999)
    assert np.all((lengths.sum(1) > 140) & (lengths.sum(1) < 200))
    # glottis first (larynx), lips last
    assert regions[0, 0] == 0 and regions[0, -1] == 7
    # opening the jaw opens the lips and the front of the mouth
    assert areas[1, -1] > 2 * areas[0, -1]


def test_larynx_drop_lengthens_the_tract_and_is_differentiable(setup):
    _, geometry, frames, run = setup
    base = af.default_tract()
    longer = eqx.tree_at(lambda p: p.larynx_drop_mm, base, base.larynx_drop_mm + 10.0)
    l0 = np.asarray(run(frames, base)[1]).sum(1)
    l1 = np.asarray(run(frames, longer)[1]).sum(1)
    np.testing.assert_allclose(l1 - l0, 10.0, atol=3.0)

    def total(drop, lip):
        p = af.TractParams(drop, jnp.asarray(1.0), jnp.asarray(1.0), lip)
        a, ln, _ = af.area_function(geometry, frames[1], p)
        return jnp.sum(jnp.log(a)) + jnp.sum(ln)

    g = jax.jit(jax.grad(total, argnums=(0, 1)))(jnp.asarray(30.0), jnp.asarray(1.0))
    total = jax.jit(total)
    h = 1e-4
    fd0 = (total(30.0 + h, 1.0) - total(30.0 - h, 1.0)) / (2 * h)
    fd1 = (total(30.0, 1.0 + h) - total(30.0, 1.0 - h)) / (2 * h)
    np.testing.assert_allclose([g[0], g[1]], [fd0, fd1], rtol=1e-5)
    assert float(g[1]) > 0  # the lips' scale widens the lips' sections


def test_vmapped_equals_one_frame(setup):
    _, geometry, frames, run = setup
    many = run(frames, af.default_tract())
    one = jax.jit(lambda v, t: af.area_function(geometry, v, t))(frames[1], af.default_tract())
    for x, y in zip(many, one, strict=True):
        np.testing.assert_allclose(np.asarray(x)[1], np.asarray(y), rtol=1e-12)


def test_tongue_base_is_carried_to_the_subjects_wall(setup):
    """A subject whose pharyngeal wall lies 20 mm behind the template's: the area function
    carries the tongue's hyoid end 20 mm back with it, T4 and everything in front of it
    (where the pellets put the tongue) not at all, and the stretch between by the share
    its arc length gives; the template's own wall carries nothing."""
    import dataclasses

    from cassi_fit.pharynx import DEFAULT_WALL, with_pharynx

    model, geometry, frames, _ = setup
    assert float(geometry.base_shift_x) == 0.0
    deeper = af.tract_geometry(with_pharynx(model, DEFAULT_WALL + np.array([-20.0, 0.0])))
    # the carry alone (the root's area rule, tested below, moves the base again)
    geometry, deeper = (dataclasses.replace(g, rest_midsagittal_mm2=None) for g in (geometry, deeper))
    np.testing.assert_allclose(float(deeper.base_shift_x), -20.0, atol=1e-3)
    tract = af.default_tract()
    front0 = np.asarray(af._walls(geometry, frames[1], tract)[0])
    front1 = np.asarray(af._walls(deeper, frames[1], tract)[0])
    n_tongue = len(geometry.tongue_tops)
    moved = (front1 - front0)[1:1 + n_tongue]  # hyoid end -> tip (after the glottis)
    np.testing.assert_allclose(moved[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(moved[0, 0], -20.0, atol=1e-3)
    t4 = list(geometry.tongue_tops[::-1]).index(model.landmarks["T4"])
    np.testing.assert_allclose(moved[t4:, 0], 0.0, atol=1e-9)
    assert np.all(np.diff(moved[:t4 + 1, 0]) > 0)  # less and less carried toward T4
    # the glottis keeps its place in front of the (moved) wall
    np.testing.assert_allclose(front1[0, 0] - front0[0, 0], -20.0, atol=1e-3)


def test_tongue_root_keeps_the_midsagittal_area(setup):
    """The root (the base below T4, which no pellet sees) moves forward or back so that the
    tongue's midsagittal section keeps its rest area: nothing at rest; forward when the
    pellets raise the front of the tongue (an /i/), back when they lower the dorsum (the
    jaw held); the shifted section has the rest area; T4 and the tongue in front of
    it stay where the pellets put them; differentiable."""
    import dataclasses

    model, geometry, frames, _ = setup
    rest = jnp.asarray(model.vertices)
    assert abs(float(af.root_shift(geometry, rest))) < 1e-3
    p0 = default_params(model)
    front_up = eqx.tree_at(lambda p: p.tongue, p0, p0.tongue + jnp.array([[0, 6], [0, 8], [0, 4], [0, 0]], float))
    raised = deform(model, front_up)
    lowered = deform(model, eqx.tree_at(lambda p: p.tongue, p0, p0.tongue + jnp.array([[0.0, -8.0]] * 4)))
    forward, back = float(af.root_shift(geometry, raised)), float(af.root_shift(geometry, lowered))
    assert forward > 1.0 and back < -1.0
    tract = af.default_tract()
    off = dataclasses.replace(geometry, rest_midsagittal_mm2=None)
    for v, shift in ((raised, forward), (lowered, back), (frames[1], None)):
        moved = np.asarray(af._walls(geometry, v, tract)[0]) - np.asarray(af._walls(off, v, tract)[0])
        tongue = moved[1:1 + len(geometry.tongue_tops)]  # hyoid end -> tip
        if shift is not None:
            np.testing.assert_allclose(tongue[0, 0], shift, rtol=1e-4)
        t4 = list(geometry.tongue_tops[::-1]).index(model.landmarks["T4"])
        np.testing.assert_allclose(tongue[t4:], 0.0, atol=1e-9)
        np.testing.assert_allclose(tongue[:, 1], 0.0, atol=1e-9)
        upper = np.asarray(af._walls(geometry, v, tract)[0])[1:1 + len(geometry.tongue_tops)]
        lower = np.asarray(v)[np.asarray(geometry.tongue_bottoms), :2]
        np.testing.assert_allclose(float(af._midsagittal_area(jnp.asarray(upper), jnp.asarray(lower))),
                                   float(geometry.rest_midsagittal_mm2), rtol=1e-4)
    g = jax.grad(lambda v: af.root_shift(geometry, v))(raised)
    assert np.all(np.isfinite(np.asarray(g))) and float(jnp.abs(g).sum()) > 0


def test_lips_forward_narrow_their_opening(setup):
    """The lips' width (module docstring, *the lips' width*; Maeda 1990): lips brought
    forward of their rest narrow the lips' sections by LIP_WIDTH_PER_MM per mm of
    protrusion, lips drawn back widen them; at rest, and for every section that is not
    the lips', nothing changes; the jaw alone protrudes nothing; differentiable."""
    import dataclasses

    model, geometry, frames, _ = setup
    areas = eqx.filter_jit(af.area_function)  # compiled once a geometry, not run op by op
    rest = jnp.asarray(model.vertices)
    assert abs(float(af.lip_protrusion(geometry, rest))) < 1e-6
    assert abs(float(af.lip_protrusion(geometry, frames[1]))) < 1e-4  # the jaw lowered
    p0 = default_params(model)
    tract = af.default_tract()
    off = dataclasses.replace(geometry, lip_rest_x=None)
    for mm in (4.0, -3.0):
        moved = eqx.tree_at(lambda p: (p.upper_lip, p.lower_lip), p0,
                            (p0.upper_lip + jnp.array([mm, 0.0]), p0.lower_lip + jnp.array([mm, 0.0])))
        v = deform(model, moved)
        np.testing.assert_allclose(float(af.lip_protrusion(geometry, v)), mm, atol=1e-4)
        a1, _, region = (np.asarray(x) for x in areas(geometry, v, tract))
        a0 = np.asarray(areas(off, v, tract)[0])
        lips = region == 7
        assert lips.any()
        np.testing.assert_allclose(a1[lips], np.maximum(a0[lips] * (1 - af.LIP_WIDTH_PER_MM * mm),
                                                        af.MIN_AREA_MM2), rtol=1e-6)
        np.testing.assert_allclose(a1[~lips], a0[~lips], rtol=1e-12)
        assert (a1[lips].sum() < a0[lips].sum()) == (mm > 0)
    for v in (rest, frames[0]):
        np.testing.assert_allclose(np.asarray(areas(geometry, v, tract)[0]),
                                   np.asarray(areas(off, v, tract)[0]), rtol=1e-6)
    g = jax.grad(lambda v: jnp.sum(areas(geometry, v, tract)[0]))(v)
    assert np.all(np.isfinite(np.asarray(g)))


def test_lip_thickness_is_no_protrusion(setup):
    """A subject's thicker lips (the conformation's lip thickness moves the vermilion
    forward) stand no further forward: their lips are not narrowed at rest."""
    model, geometry, _, _ = setup
    p0 = default_params(model)
    thick = eqx.tree_at(lambda p: (p.upper_lip_thickness, p.lower_lip_thickness), p0,
                        (p0.upper_lip_thickness + 3.0, p0.lower_lip_thickness + 3.0))
    v = deform(model, thick)
    assert float(jnp.abs(v - deform(model, p0)).max()) > 1.0  # the vermilion did move
    assert abs(float(af.lip_protrusion(geometry, v))) < 1e-5
