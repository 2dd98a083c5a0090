"""deform: exact rest pose, jaw fractions, lips, nose gap, tongue sites, gradients, jit/vmap."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from cassi_fit import rigid
from cassi_fit.deform import default_params, deform, model_pellets, vertex_normals
from cassi_fit.face_model import load_model

MODEL = load_model()
L = MODEL.landmarks
REST = np.asarray(MODEL.vertices)
PIVOT = jnp.array([MODEL.measures["jaw_pivot_x"], MODEL.measures["jaw_pivot_y"]])
DEFORM = jax.jit(lambda p: deform(MODEL, p))


def with_(**kw):
    p = default_params(MODEL)
    names = tuple(kw)
    return eqx.tree_at(lambda q: tuple(getattr(q, n) for n in names), p,
                       tuple(jnp.asarray(kw[n], dtype=float) for n in names))


@pytest.mark.parametrize("anchor", ["fixed", "follow", "none"])
def test_default_params_give_the_rest_mesh_exactly(anchor):
    out = np.asarray(deform(MODEL, default_params(MODEL), tongue_anchor=anchor))
    assert np.array_equal(out, REST)


@pytest.mark.parametrize("weights, fraction", [("cassi", 1.0), ("parke", 0.9)])
def test_lower_incisor_follows_the_jaw(weights, fraction):
    theta, t = rigid.from_pivot(0.2, PIVOT)
    out = deform(MODEL, with_(jaw_theta=theta, jaw_translation=t), jaw_weights=weights)
    expected = rigid.apply(*rigid.fractional((theta, t), fraction), REST[L["lower_incisor_tip"], :2])
    np.testing.assert_allclose(out[L["lower_incisor_tip"], :2], expected, atol=1e-12)
    np.testing.assert_allclose(out[L["upper_incisor_tip"]], 0.0, atol=1e-12)
    if weights == "cassi":  # the jaw pellet sites ride exactly on the motion too
        for site in ("MNI", "MNM"):
            np.testing.assert_allclose(out[L[site], :2], rigid.apply(theta, t, REST[L[site], :2]), atol=1e-12)


def test_jaw_opening_opens_the_mouth():
    theta, t = rigid.from_pivot(0.25, PIVOT)
    out = np.asarray(DEFORM(with_(jaw_theta=theta, jaw_translation=t)))
    assert out[L["LL"], 1] < REST[L["LL"], 1] - 15
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize("anchor", ["fixed", "follow", "none"])
def test_tongue_sites_move_exactly_by_their_params(anchor):
    d = np.array([[3.0, -2.0], [1.0, 4.0], [-2.0, 5.0], [4.0, -3.0]])
    out = deform(MODEL, with_(tongue=d), tongue_anchor=anchor)
    for k, name in enumerate(("T1", "T2", "T3", "T4")):
        np.testing.assert_allclose(out[L[name], :2] - REST[L[name], :2], d[k], atol=1e-12)


def test_tongue_anchor_modes_differ_at_the_back():
    d = np.tile([0.0, 8.0], (4, 1))
    root = MODEL.regions["tongue"][-1]
    share = float(MODEL.fields["tongue_follow"][root])  # the pellets' share at the hyoid end
    assert 0.2 < share < 1.0
    fixed = deform(MODEL, with_(tongue=d), tongue_anchor="fixed")
    follow = deform(MODEL, with_(tongue=d), tongue_anchor="follow")
    np.testing.assert_allclose(fixed[root], REST[root], atol=1e-12)  # anchors never move
    np.testing.assert_allclose(follow[root, 1] - REST[root, 1], 8.0 * share, atol=1e-12)


def test_lip_sites_move_by_their_params():
    out = DEFORM(with_(upper_lip=[2.0, -1.5], lower_lip=[-1.0, -3.0]))
    pel = np.asarray(model_pellets(MODEL, out))
    rest = np.asarray(model_pellets(MODEL, MODEL.vertices))
    np.testing.assert_allclose(pel[0] - rest[0], [2.0, -1.5], atol=1e-12)
    np.testing.assert_allclose(pel[1] - rest[1], [-1.0, -3.0], atol=1e-12)


def test_lower_lip_is_applied_after_the_jaw():
    theta, t = rigid.from_pivot(0.15, PIVOT)
    jaw_only = DEFORM(with_(jaw_theta=theta, jaw_translation=t))
    both = DEFORM(with_(jaw_theta=theta, jaw_translation=t, lower_lip=[1.0, 2.0]))
    np.testing.assert_allclose(both[L["LL"], :2] - jaw_only[L["LL"], :2], [1.0, 2.0], atol=1e-12)


def test_lip_rounding_moves_the_corners_inward():
    out = DEFORM(with_(upper_lip=[6.0, 0.0], lower_lip=[6.0, 0.0]))
    width = lambda v: v[L["mouth_corner_left"], 2] - v[L["mouth_corner_right"], 2]
    assert width(out) < width(REST) - 2.0


@pytest.mark.parametrize("rise", [5.0, 10.0, 20.0])
def test_nose_gap_stays_positive_when_the_upper_lip_rises(rise):
    out = DEFORM(with_(upper_lip=[0.0, rise]))
    gap = out[L["subnasale"], 1] - out[L["UL"], 1]
    assert gap > 5.0
    assert out[L["nose_tip"], 1] > REST[L["nose_tip"], 1]


def test_conformation_parameters_act():
    out = DEFORM(with_(face_width=1.1, mouth_width=1.2, upper_lip_thickness=2.0, nose_tip=[3.0, 0.0]))
    assert out[L["gonion"], 2] > REST[L["gonion"], 2] * 1.05
    assert out[L["UL"], 0] == pytest.approx(REST[L["UL"], 0] + 2.0)
    assert out[L["nose_tip"], 0] == pytest.approx(REST[L["nose_tip"], 0] + 3.0)
    shaped = DEFORM(with_(jaw_shape_theta=0.05))
    assert not np.allclose(shaped[L["gnathion"]], REST[L["gnathion"]])


def _scalar(p):
    v = deform(MODEL, p, tongue_anchor="fixed")
    w = jnp.asarray(np.random.default_rng(0).normal(size=v.shape))
    return jnp.sum(w * v)


def test_gradients_match_finite_differences_for_every_parameter():
    p = with_(jaw_theta=0.1, jaw_translation=[0.5, -0.3], tongue=np.ones((4, 2)),
              upper_lip=[1.0, 1.0], lower_lip=[0.5, -0.5], jaw_shape_theta=0.02)
    check_grads(_scalar, (p,), order=1, modes=["rev"], atol=1e-5, rtol=1e-5)


def test_gradients_are_finite_at_the_neutral_pose():
    g = jax.grad(_scalar)(default_params(MODEL))
    assert all(np.all(np.isfinite(np.asarray(leaf))) for leaf in jax.tree_util.tree_leaves(g))


def test_jit_and_vmap_match_eager():
    thetas = jnp.array([0.0, 0.1, 0.2])
    batch = jax.vmap(lambda th: with_(jaw_theta=th, upper_lip=jnp.stack([th, th])))(thetas)
    vm = jax.jit(jax.vmap(lambda p: deform(MODEL, p)))(batch)
    for i, th in enumerate(thetas):
        eager = deform(MODEL, with_(jaw_theta=th, upper_lip=[th, th]))
        np.testing.assert_allclose(vm[i], eager, atol=1e-12)


def test_vertex_normals_unit_and_safe_on_degenerate_triangles():
    n = np.asarray(vertex_normals(MODEL.vertices, MODEL.faces))
    lengths = np.linalg.norm(n, axis=1)
    assert np.all(np.isfinite(n)) and np.allclose(lengths[lengths > 0], 1.0)
    v = jnp.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])  # a zero-area triangle
    f = np.array([[0, 1, 2]])
    assert np.all(np.asarray(vertex_normals(v, f)) == 0.0)
    g = jax.grad(lambda v: jnp.sum(vertex_normals(v, f)))(v)
    assert np.all(np.isfinite(np.asarray(g)))


def test_bad_options_raise():
    from cassi_fit.errors import InvalidChoiceError

    with pytest.raises(InvalidChoiceError, match="jaw weights"):
        deform(MODEL, default_params(MODEL), jaw_weights="nope")
    with pytest.raises(InvalidChoiceError, match="tongue anchor"):
        deform(MODEL, default_params(MODEL), tongue_anchor="nope")
