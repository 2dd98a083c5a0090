"""Collisions: depths measured as documented, zero after projection, a usable penalty."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cassi_fit import collide
from cassi_fit.deform import default_params, deform
from cassi_fit.errors import CassiError
from cassi_fit.face_model import load_model

MODEL = load_model()
TOL = 0.01  # mm; the projection leaves points 1 um outside
# compiled once for the whole file (eager dispatch of these many small ops is slow)
_deform = jax.jit(lambda p: deform(MODEL, p))
_project = jax.jit(lambda v: collide.project(MODEL, v))
_report_c = jax.jit(lambda v: collide.report(MODEL, v))
_palate_depths = jax.jit(lambda v: collide.depths(MODEL, v)["tongue_palate"])


def _posed(**changes):
    p = default_params(MODEL)
    names = tuple(changes)
    values = tuple(jnp.asarray(v, jnp.asarray(getattr(p, k)).dtype) for k, v in changes.items())
    p = eqx.tree_at(lambda q: tuple(getattr(q, k) for k in names), p, values)
    return _deform(p)


def _report(v):
    return {k: float(x) for k, x in _report_c(v).items()}


def test_the_rest_model_touches_nothing_and_projection_leaves_it_alone():
    assert max(_report(MODEL.vertices).values()) == 0.0
    moved = _project(MODEL.vertices)
    np.testing.assert_array_equal(np.asarray(moved), np.asarray(MODEL.vertices))


def test_depth_is_the_shortest_way_out_of_a_crown():
    chains, teeth = collide.arch_chains(MODEL, MODEL.vertices, "upper")
    k = int(np.flatnonzero(teeth == 0)[-2])  # the left central incisor, mesial station
    lingual, labial = np.asarray(chains[0][k]), np.asarray(chains[2][k])
    assert 0.9 < np.linalg.norm((labial - lingual)[[0, 2]]) < 2.0  # a thin incisal edge
    # 0.3 mm above the biting edge, halfway between the lingual and the labial face:
    # 0.3 mm from the way out downward, more than 0.45 mm from either face
    mid = 0.5 * (lingual + labial)
    # one compilation for the three points (op by op, each costs seconds)
    teeth_depth = jax.jit(lambda q: collide.teeth_depth(q, chains, True, "lingual"))
    depth, move = teeth_depth(jnp.array([mid[0], 0.3, mid[2]]))
    assert float(depth) == pytest.approx(0.3, abs=1e-6)
    np.testing.assert_allclose(np.asarray(move), [0.0, -0.3 - collide.PROJECTION_MARGIN_MM, 0.0])
    # between the open teeth (below the upper edge) the same point is inside nothing, and
    # neither is one 2 mm in front of the crown (a tongue out over the lower lip)
    for point in ([mid[0], -0.3, mid[2]], [labial[0] + 2.0, 3.0, labial[2]]):
        assert float(teeth_depth(jnp.array(point))[0]) == 0.0


def test_a_tongue_pushed_through_the_front_teeth_is_measured_and_projected_out():
    tongue = np.zeros((4, 2))
    tongue[0] = (16.0, 6.0)  # T1 forward and up: the tip through the upper incisors
    tongue[1] = (8.0, 3.0)
    v = _posed(tongue=tongue)
    before = _report(v)
    assert before["tongue_upper_front"] > 1.0
    after = _report(_project(v))
    assert max(after.values()) < TOL, after


def test_a_tongue_pushed_into_the_palate_is_pushed_down():
    tongue = np.tile([0.0, 14.0], (4, 1))
    v = _posed(tongue=tongue)
    assert _report(v)["tongue_palate"] > 3.0
    projected = _project(v)
    assert max(_report(projected).values()) < TOL
    idx = np.asarray(MODEL.regions["tongue"])
    moved = np.asarray(projected - v)[idx]
    inside = np.asarray(_palate_depths(v)) > 0
    assert np.all(moved[inside, 1] <= 0)  # the way out of the palate is down


def test_teeth_closed_past_each_other_still_leave_no_penetration():
    # the jaw closed 3 degrees beyond contact: upper and lower crowns overlap, so there is
    # no gap to escape into vertically; with the tongue spread sideways
    v = _posed(jaw_theta=-0.05, tongue=np.tile([2.0, -2.0], (4, 1)))
    before = _report(v)
    assert before["tongue_lower_teeth"] > 0.5
    after = _report(_project(v))
    assert max(after.values()) < TOL, after


def test_lips_pushed_into_the_teeth_are_projected_out():
    v = _posed(upper_lip=np.array([-12.0, -10.0]), lower_lip=np.array([-12.0, 12.0]))
    before = _report(v)
    assert before["lips_upper_teeth"] > 1.0 or before["lips_lower_teeth"] > 1.0
    after = _report(_project(v))
    # pushed into the teeth and into each other at once: the teeth win, and the lips are
    # left crossing by a fraction of a millimetre at most
    assert max(v for k, v in after.items() if k != "lips_crossing") < TOL, after
    assert after["lips_crossing"] < 0.5


def test_lips_closed_past_each_other_are_pressed_together_instead():
    # the lips rest 1.6 mm apart (upper incisor show): close them 9.2 mm, 7.6 mm past each other
    v = _posed(upper_lip=np.array([0.0, -3.6]), lower_lip=np.array([0.0, 5.6]))
    assert _report(v)["lips_crossing"] > 7.0
    projected = _project(v)
    assert _report(projected)["lips_crossing"] == 0.0
    crossing = np.asarray(collide.lips_crossing(MODEL, projected))
    assert crossing.max() <= 1e-9  # the two edges meet, nothing crosses
    untouched = ~np.isin(np.arange(len(v)), np.asarray(MODEL.collision["upper_lip_columns"]))
    untouched &= ~np.isin(np.arange(len(v)), np.asarray(MODEL.collision["lower_lip_columns"]))
    untouched &= ~np.isin(np.arange(len(v)), np.asarray(MODEL.regions["tongue"]))
    np.testing.assert_array_equal(np.asarray(projected)[untouched], np.asarray(v)[untouched])


def test_penalty_is_zero_at_rest_and_its_gradient_pushes_the_tongue_back():
    def penalty(t1_x):
        tongue = jnp.zeros((4, 2)).at[0, 0].set(t1_x).at[0, 1].set(6.0)
        p = eqx.tree_at(lambda q: q.tongue, default_params(MODEL), tongue)
        return jnp.sum(collide.penalty_residuals(MODEL, deform(MODEL, p)) ** 2)

    # both compiled (op by op, the penalty's many small operations cost seconds)
    at_rest = jax.jit(lambda v: jnp.sum(collide.penalty_residuals(MODEL, v) ** 2))
    assert float(at_rest(MODEL.vertices)) == 0.0
    # the derivative in T1's x, forward (one input: the same number as jax.grad's, whose
    # reverse pass through the depths takes twice as long to compile)
    value, grad = jax.jit(lambda x: jax.jvp(penalty, (x,), (jnp.ones_like(x),)))(18.0)
    assert float(value) > 0 and np.isfinite(float(grad))
    assert float(grad) > 0  # more forward = deeper: gradient descent moves the tip back


def test_a_model_without_collision_chains_gets_a_clear_error():
    topology = dataclasses.replace(MODEL.topology, collision={})
    assert topology != MODEL.topology  # its digest is recomputed
    bare = dataclasses.replace(MODEL, topology=topology)
    assert not collide.has_collision_data(bare)
    with pytest.raises(CassiError, match="collision chains"):
        collide.report(bare, bare.vertices)
