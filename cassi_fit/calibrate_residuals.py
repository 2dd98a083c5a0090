"""The unknowns and residuals of the subject calibration (:mod:`cassi_fit.calibrate`), and
the compiled kernels over them: a stage's solve (:func:`stage_kernel`) and everything a
calibration reports (:func:`summary_arrays`).

The unknowns are the named pytree :class:`Unknowns`; :class:`Problem` gives one subject's
residual groups (model mm) at them, every one computed on the vertices that
``deform.deform`` produces. Both kernels are :func:`cassi_fit._exported.exported`: a new
process loads them instead of tracing them again.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, Float

from ._exported import exported
from .calibration import JAW_SCALE_BOUND, JAW_TURN_BOUND_RAD
from .conformation import lips_ahead, with_values
from .pellets import LL, MNI, MNM, UL

#: Weight of the lips-in-teeth penalty residuals relative to a 1 mm lip residual.
COLLISION_WEIGHT = 10.0

#: The unknowns' names, in order.
UNKNOWN_NAMES = ("log_scale", "upper_lip", "lower_lip", "face_width", "jaw_theta",
                 "log_jaw_scale")


class Unknowns(eqx.Module):
    """The unknowns of the calibration (model units), a pytree with named fields.

    ``log_scale``: log of ``p/d``; ``upper_lip``, ``lower_lip``: lip thickness change (mm);
    ``face_width``: face width change (mm); ``jaw_theta``: jaw shape rotation (rad) and
    ``log_jaw_scale (2,)``: the jaw's log scales along x and y, both about the model's
    lower incisor tip. The solver sees them flattened in this order (``ravel_pytree``).
    """

    log_scale: Float[Array, ""]
    upper_lip: Float[Array, ""]
    lower_lip: Float[Array, ""]
    face_width: Float[Array, ""]
    jaw_theta: Float[Array, ""]
    log_jaw_scale: Float[Array, " 2"]

    @classmethod
    def zeros(cls, dtype=float) -> Unknowns:
        """Every unknown 0 (scale 1, the model's own shape)."""
        z = jnp.zeros((), dtype)
        return cls(z, z, z, z, z, jnp.zeros(2, dtype))

    @classmethod
    def mask(cls, free, dtype=float) -> Unknowns:
        """1 for the fields named in ``free``, 0 elsewhere (which unknowns a stage fits)."""
        zero = cls.zeros(dtype)
        return cls(*(jnp.full(jnp.shape(getattr(zero, name)), float(name in free), dtype)
                     for name in UNKNOWN_NAMES))


def bounded_jaw(x: Unknowns) -> tuple[Float[Array, ""], Float[Array, " 2"]]:
    """``(theta rad, log scales (2,))`` of the jaw shape from the unknowns, each kept
    smoothly inside its anatomical bound ``B`` (``calibration.JAW_TURN_BOUND_RAD``,
    ``log JAW_SCALE_BOUND``) as ``B tanh(u / B)``: slope 1 at 0 and a bijection onto
    (-B, B), so a fit whose optimum lies inside the bounds reaches the same shape, and
    none goes beyond ``B``."""
    b = math.log(JAW_SCALE_BOUND)
    return (JAW_TURN_BOUND_RAD * jnp.tanh(x.jaw_theta / JAW_TURN_BOUND_RAD),
            b * jnp.tanh(x.log_jaw_scale / b))


_INDEX = ("UL", "LL", "MNI", "MNM", "upper_incisor_tip", "lower_incisor_tip", "gonion",
          "gnathion", "zygion_left", "zygion_right")


class Problem:
    """The residuals of one subject (model mm); ``model`` may be rebuilt inside jit."""

    def __init__(self, model, data, measured):
        self.model, self.data, self.measured = model, data, measured
        self.index = {k: model.landmarks[k] for k in _INDEX}

    def params(self, x):
        """FaceParams of the :class:`Unknowns` ``x``."""
        from .deform import default_params

        m, data = self.model.measures, self.data
        dtype = x.log_scale.dtype
        s = jnp.exp(x.log_scale)
        names = ["upper_lip_thickness", "lower_lip_thickness", "face_width"]
        values = [x.upper_lip, x.lower_lip, 1.0 + x.face_width / m["face_width"]]
        if self.measured:
            from .rigid import rotation_matrix

            # the jaw's proportions (x, y scale) and a turn, both about the lower incisor
            # tip, so that the skin over the teeth stays where the teeth are
            tip = jnp.asarray(self.model.vertices)[self.index["lower_incisor_tip"], :2]
            tip = tip.astype(dtype)
            theta, log_scale = bounded_jaw(x)
            turn = tip - rotation_matrix(theta) @ tip
            names += ["jaw_shape_theta", "jaw_shape_translation", "jaw_shape_scale",
                      "mouth_width", "nose_tip"]
            values += [theta, turn, jnp.exp(log_scale), s * data["mouth_width"] / m["mouth_width"],
                       jnp.stack([s * data["nose"] - m["nose_protrusion"], jnp.zeros_like(s)])]
        p = default_params(dtype=dtype)
        return with_values(p, {k: jnp.asarray(v, dtype) for k, v in zip(names, values, strict=True)})

    def vertices(self, x):
        from .deform import deform

        return deform(self.model, self.params(x))

    def lip_thickness_model(self, v):
        """(upper, lower) on the model at rest, model mm."""
        i = self.index
        upper = v[i["UL"], 0] - v[i["upper_incisor_tip"], 0]
        fwd = v[i["MNI"], :2] - v[i["MNM"], :2]
        fwd = fwd / jnp.linalg.norm(fwd)
        lower = jnp.dot(v[i["LL"], :2] - v[i["lower_incisor_tip"], :2], fwd)
        return upper, lower

    def lip_thickness_observed(self, s):
        """Per recording row (R, padding included) (upper, lower) in model mm at scale ``s``: the lip pellets
        ahead of the incisor tips on the first valid line (the lower tip = the model's,
        placed on that line's jaw pellets by the paper's closed form)."""
        v = self.model.vertices
        i = self.index
        rest_jaw = jnp.stack([v[i["MNI"], :2], v[i["MNM"], :2]])
        tip = v[i["lower_incisor_tip"], :2]
        return jax.vmap(lambda pel: lips_ahead(rest_jaw, tip, pel, s))(self.data["pellets"])

    def lip_rest_offset(self, v, s):
        """(upper, lower) model mm: how far above the model's UL and LL sites the lip
        pellets sit on the first valid lines (the lower one after the model's jaw is placed
        on that line's jaw pellets), averaged over the recordings that track them."""
        from . import rigid
        from .jaw import closed_form

        i = self.index
        rest_jaw = jnp.stack([v[i["MNI"], :2], v[i["MNM"], :2]])
        w_ll = jnp.asarray(self.model.jaw_weights["cassi"])[i["LL"]]

        def one(pel):
            motion = closed_form(rest_jaw, s * pel[jnp.array([MNI, MNM])])
            theta, t = rigid.fractional((motion.theta, motion.translation), w_ll)
            ll = rigid.apply(theta, t, v[i["LL"], :2])
            return s * pel[UL, 1] - v[i["UL"], 1], s * pel[LL, 1] - ll[1]

        du, dl = jax.vmap(one)(self.data["pellets"])
        mu, ml = self.data["mask_ul"], self.data["mask_ll"]
        return (jnp.sum(mu * du) / jnp.maximum(jnp.sum(mu), 1.0),
                jnp.sum(ml * dl) / jnp.maximum(jnp.sum(ml), 1.0))

    def residual_groups(self, x, collisions):
        """Dict of residual vectors (model mm) at the :class:`Unknowns` ``x``."""
        from .collide import penalty_residuals

        data = self.data
        s = jnp.exp(x.log_scale)
        v = self.vertices(x)
        i = self.index
        upper, lower = self.lip_thickness_model(v)
        obs_u, obs_l = self.lip_thickness_observed(s)
        groups = {
            "upper_lip": data["mask_ul"] * (upper - obs_u),
            "lower_lip": data["mask_ll"] * (lower - obs_l),
            "jaw_pellets": data["rows"] * (
                jnp.linalg.norm(v[i["MNI"], :2] - v[i["MNM"], :2]) - s * data["d"]),
        }
        if self.measured:
            ours = jnp.stack([v[i["gonion"], :2], v[i["gnathion"], :2]])
            groups["jaw_shape"] = (ours - s * data["head_xy"]).ravel()
            width = v[i["zygion_left"], 2] - v[i["zygion_right"], 2]
            groups["face_width"] = jnp.atleast_1d(width - s * data["face_width"])
        if collisions:
            depth = penalty_residuals(self.model, v, tongue=False, lips=True)
            groups["collision"] = math.sqrt(COLLISION_WEIGHT) * depth
        return groups


#: The residual groups, in the order a stage concatenates them.
GROUPS = ("jaw_pellets", "upper_lip", "lower_lip", "jaw_shape", "face_width", "collision")


@exported
def stage_kernel(model, data, measured, x, mask, weights):
    """One compiled solver per (model topology, head measured): which unknowns are free
    (``mask``, an ``Unknowns`` of 0/1, per element) and which residual groups count
    (``weights``) are arrays, so every stage of both methods, with or without the penalty,
    and its re-solve with a bound held (``calibrate._solve_stage``), share it. Returns ``(x,
    converged, gradient)``, the gradient of half the squared residuals over the flat
    unknowns at the answer (0 for the held ones)."""
    from .jaw_fit import solve

    problem = Problem(model, data, measured)
    flat, unravel = ravel_pytree(x)
    free = ravel_pytree(mask)[0]

    def residuals(y, base):
        g = problem.residual_groups(unravel(base + free * (y - base)), True)
        return jnp.concatenate([weights[k] * jnp.atleast_1d(g[k]) for k in GROUPS if k in g])

    y, converged = solve(residuals, flat, flat, "optimistix-lm")
    gradient = jax.grad(lambda z: 0.5 * jnp.sum(residuals(z, flat) ** 2))(y)
    return unravel(flat + free * (y - flat)), converged, gradient


@exported
def summary_arrays(model, data, measured, x):
    """Everything ``calibrate._summarise`` reports, in one compiled call per model topology."""
    from .collide import depths

    problem = Problem(model, data, measured)
    v = problem.vertices(x)
    d = depths(model, v, ("lips_upper", "lips_lower"))  # the tongue's are not reported
    lips = jnp.maximum(jnp.max(d["lips_upper"]), jnp.max(d["lips_lower"]))
    s = jnp.exp(x.log_scale)
    return (v, problem.residual_groups(x, False), problem.lip_thickness_model(v),
            problem.lip_thickness_observed(s), lips, problem.params(x),
            problem.lip_rest_offset(v, s))
