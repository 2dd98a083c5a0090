"""Parameters -> vertices: the one pure function that animates the face model.

``deform`` runs four plain stages on the rest mesh, each a small function:

1. conformation (Parke's shape parameters: mouth width, lip thickness, face width, nose
   tip, jaw/chin shape) -- the subject's face, before any animation;
2. jaw: Parke's jaw rotation, each vertex moved by the fraction ``w_i`` of the jaw motion
   about the same pivot (``rigid.fractional``, paper Eqs 4-5 with the region weights);
3. lips: CASSI's #63/#64 (upper lip) and #65/#66 (lower lip, on top of where the jaw took
   it), with two couplings: lip rounding (the corners move toward each other when the lips
   come forward, CASSI's future work) and the nose tip rising with the upper lip so that a
   gap always remains between them (CASSI section 2, step 3);
4. tongue: CASSI's #55-#62 (``cassi_fit.tongue``) on a tongue hung from the jaw whose
   volume is kept (the width scaled by ``V_rest / V``; docs/TONGUE.md); with
   ``tongue_shape="flat"`` every cross-section collapses onto its upper midline point
   (CASSI's tongue: "a flat surface with no thickness", paper section 5), a sheet as wide
   as the model's tongue, moved by the pellets only.

Everything is written for one frame; ``jax.vmap`` over frames. With default parameters
every stage is the identity to the last bit, so ``deform`` returns the stored rest mesh.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jaxtyping import Float, Int

from . import rigid
from .face_model import FaceModel
from .options import JAW_WEIGHTS, TONGUE_ANCHORS, TONGUE_SHAPES, check_choice
from .pellets import PELLET_NAMES
from .tongue import closed_mesh_volume, keep_volume, tongue_displacement, tongue_faces

#: The model's pellet-site landmarks, in pellet order (``pellets.PELLET_NAMES``).
PELLET_SITES = PELLET_NAMES
# Lip rounding: relative narrowing of the mouth per mm of mean forward lip displacement.
LIP_ROUNDING_PER_MM = 0.015
# Smooth positive part used for the nose coupling: quadratic over the first 2 mm.
_NOSE_KNEE_MM = 2.0


class FaceParams(eqx.Module):
    """One frame of face parameters (mm, rad, scales); every leaf a float array."""

    jaw_theta: Array
    jaw_translation: Array
    tongue: Array
    upper_lip: Array
    lower_lip: Array
    mouth_width: Array
    upper_lip_thickness: Array
    lower_lip_thickness: Array
    face_width: Array
    nose_tip: Array
    jaw_shape_theta: Array
    jaw_shape_translation: Array
    jaw_shape_scale: Array = None


def default_params(model: FaceModel | None = None, dtype: object = float) -> FaceParams:
    """Neutral parameters: ``deform(model, default_params())`` is the rest mesh exactly."""
    z = lambda *shape: jnp.zeros(shape, dtype)
    one = jnp.ones((), dtype)
    return FaceParams(z(), z(2), z(4, 2), z(2), z(2), one, z(), z(), one, z(2), z(), z(2),
                      jnp.ones(2, dtype))


def _move_by_fraction(motion, weights, xy):
    """Each point ``xy[i]`` (n, 2) moved by ``rigid.fractional(motion, weights[i])``."""
    def one(w, p):
        theta, t = rigid.fractional(motion, w)
        return rigid.apply(theta, t, p)

    return jax.vmap(one)(weights, xy)


def _smooth_positive(u):
    """0 for u <= 0, u^2/(2k) up to k, u - k/2 beyond: C1, exact 0 (and slope 0) at 0."""
    k = _NOSE_KNEE_MM
    return jnp.where(u <= 0.0, 0.0, jnp.where(u < k, u * u / (2 * k), u - k / 2))


def _mask(model, names) -> np.ndarray:
    m = np.zeros(model.vertices.shape[0], bool)
    for n in names:
        m[model.regions[n]] = True
    return m


def conformation(model: FaceModel, v: Float[Array, "V 3"], p: FaceParams) -> Float[Array, "V 3"]:
    """Stage 1: the subject's face shape (all identities at the neutral values)."""
    f = model.fields
    z = v[:, 2] * (1.0 + (p.mouth_width - 1.0) * f["mouth"])
    z = z * jnp.where(_mask(model, ("skin", "eyes")), p.face_width, 1.0)
    x = v[:, 0] + p.upper_lip_thickness * f["upper_vermilion"] \
        + p.lower_lip_thickness * f["lower_vermilion"]
    xy = jnp.stack([x, v[:, 1]], -1) + p.nose_tip[None] * f["nose"][:, None]
    if p.jaw_shape_scale is not None:  # jaw proportions: scaled about the lower incisor tip
        centre = jnp.asarray(model.vertices)[model.landmarks["lower_incisor_tip"], :2]
        xy = xy + f["jaw_shape"][:, None] * (p.jaw_shape_scale - 1.0)[None] * (xy - centre[None])
    xy = _move_by_fraction((p.jaw_shape_theta, p.jaw_shape_translation), f["jaw_shape"], xy)
    return jnp.concatenate([xy, z[:, None]], -1)


def jaw(model: FaceModel, v: Float[Array, "V 3"], p: FaceParams, weights: str = "cassi") -> Float[Array, "V 3"]:
    """Stage 2: jaw rotation with per-vertex fractions (``"cassi"`` or ``"parke"`` set)."""
    check_choice("jaw weights", weights, JAW_WEIGHTS)
    xy = _move_by_fraction((p.jaw_theta, p.jaw_translation), model.jaw_weights[weights], v[:, :2])
    return v.at[:, :2].set(xy)


def lips(
    model: FaceModel, v: Float[Array, "V 3"], p: FaceParams, rounding: bool = True
) -> Float[Array, "V 3"]:
    """Stage 3: lip displacements, the nose tip coupling (CASSI section 3) and, with
    ``rounding`` (static; CASSI's future work, so off in its reproduction), lip rounding."""
    f = model.fields
    xy = (v[:, :2] + p.upper_lip[None] * f["upper_lip"][:, None]
          + p.lower_lip[None] * f["lower_lip"][:, None])
    xy = xy.at[:, 1].add(_smooth_positive(p.upper_lip[1]) * f["nose_rise"])
    if not rounding:
        return jnp.concatenate([xy, v[:, 2:]], -1)
    forward = 0.5 * (p.upper_lip[0] + p.lower_lip[0])
    z = v[:, 2] * (1.0 - LIP_ROUNDING_PER_MM * forward * f["mouth"])
    return jnp.concatenate([xy, z[:, None]], -1)


def tongue_midline(model: FaceModel) -> tuple[Int[np.ndarray, " n"], Int[np.ndarray, " n"]]:
    """``(tongue, top)``: the tongue region's vertex indices ``(n,)`` and, for each, the
    index of the upper-midline vertex of its cross-section ``(n,)``. Static numpy, from
    the topology only (usable under ``jit``).

    The layout is ``model/build_model.py``'s tube: stations of ``R`` ring vertices, ring
    vertex 0 on the upper midline, then a tip and a root vertex; T1..T4 are the upper
    midline vertices of stations 4, 8, 12, 16, so ``R = (T2 - T1) / 4``. A model with
    another layout raises ``MissingDataError`` (the flat tongue cannot be built).
    """
    from .errors import MissingDataError

    idx = np.asarray(model.regions["tongue"], np.int64)
    t1, t2 = model.landmarks["T1"], model.landmarks["T2"]
    ring = (t2 - t1) // 4
    start = t1 - 4 * ring
    stations = (idx.size - 2) // ring if ring > 0 else 0
    if ring < 3 or stations * ring + 2 != idx.size or not np.array_equal(
            idx, start + np.arange(idx.size)):
        raise MissingDataError(
            "the face model's tongue is not build_model.py's tube (stations of rings, "
            "then tip and root); the flat tongue needs that layout")
    station = np.minimum(np.arange(idx.size) // ring, stations - 1)
    station[-2] = 0  # the tip vertex belongs to the first station
    return idx, start + station * ring


def tongue_site_arcs(model: FaceModel) -> Float[np.ndarray, " 4"]:
    """The arc lengths ``(4,)`` mm of the tongue sites T1..T4 from the tip along the
    upper midline (``fields["tongue_s"]`` at their landmarks), float64 numpy."""
    s = np.asarray(model.fields["tongue_s"], np.float64)
    return np.array([s[model.landmarks[k]] for k in ("T1", "T2", "T3", "T4")])


def tongue_points_at(model: FaceModel, vertices: Float[np.ndarray, "*m V 3"],
                     arc_s: Float[np.ndarray, " k"]) -> Float[np.ndarray, "*m k 2"]:
    """The tongue's upper midline ``(*m, k, 2)`` mm (x, y) at the arc lengths ``arc_s``
    (model mm from the tip along the midline, ``fields["tongue_s"]``), in the posed
    ``vertices`` ``(V, 3)`` or ``(m, V, 3)``: linear between the midline's vertices,
    the end vertex's beyond either end. Where an articulograph's tongue sensors sit
    (``SubjectState.tongue_sites``), in every frame as at rest. Numpy, concrete arrays."""
    s = np.asarray(model.fields["tongue_s"], np.float64)
    top = np.unique(tongue_midline(model)[1])
    top = top[np.argsort(s[top])]
    curve_s = s[top]
    arc_s = np.clip(np.asarray(arc_s, np.float64), curve_s[0], curve_s[-1])
    j = np.clip(np.searchsorted(curve_s, arc_s, side="right"), 1, curve_s.size - 1)
    u = (arc_s - curve_s[j - 1]) / (curve_s[j] - curve_s[j - 1])
    curve = np.asarray(np.asarray(vertices)[..., top, :2], np.float64)
    return (1.0 - u)[:, None] * curve[..., j - 1, :] + u[:, None] * curve[..., j, :]


def tongue(
    model: FaceModel, v: Float[Array, "V 3"], p: FaceParams, anchor: str = "follow",
    shape: str = "thick", jaw_weights: str = "cassi",
) -> Float[Array, "V 3"]:
    """Stage 4: tongue params #55-#62 (``cassi_fit.tongue``).

    ``shape`` (static, ``options.TONGUE_SHAPES``):

    * ``"thick"`` (the tongue as an organ, docs/TONGUE.md): every tongue vertex is first
      carried by the fraction ``fields["tongue_jaw"]`` of the jaw motion (``j``: the floor
      of the mouth and the genial attachment move with the mandible, the hyoid end less);
      then the pellets' displacement relative to that, ``p.tongue[k] - j(T_k)``, is spread
      along the tongue (``tongue_displacement``) and added with the weight
      ``fields["tongue_follow"]`` (1 on the upper surface, so T1..T4 land exactly on
      rest + ``p.tongue``; small on the floor); last, the width ``z`` is scaled about the
      midsagittal plane by ``V_in / V`` (a linear map in ``z`` scales a closed mesh's
      volume by the same factor), so the tongue keeps the volume it had on entering the
      stage (the rest volume), exactly and differentiably; the pellet sites, at ``z = 0``,
      stay put. A muscular hydrostat narrows as it lengthens.
    * ``"flat"`` (CASSI): every vertex of a cross-section goes to its upper midline point
      in x, y (keeping z, the width): a sheet of zero thickness through T1..T4, moved by
      the pellets only, as CASSI's tongue (no jaw attachment, no volume).
    """
    check_choice("tongue anchor", anchor, TONGUE_ANCHORS)
    check_choice("tongue shape", shape, TONGUE_SHAPES)
    check_choice("jaw weights", jaw_weights, JAW_WEIGHTS)
    idx, top = tongue_midline(model)
    f = model.fields
    s = f["tongue_s"]
    names = ("T1", "T2", "T3", "T4")
    site_s = jnp.stack([s[model.landmarks[k]] for k in names])
    anchor_s = model.measures["tongue_anchor_s"]
    if shape == "flat":
        d = tongue_displacement(s[idx], site_s, p.tongue, anchor_s, anchor)
        v = v.at[idx, :2].set(v[top, :2])
        return v.at[idx, :2].add(d)
    rest = v[idx, :2]
    mandible = model.jaw_weights[jaw_weights][model.landmarks["lower_incisor_tip"]]
    carried = _move_by_fraction((p.jaw_theta, p.jaw_translation),
                                f["tongue_jaw"][idx] * mandible, rest)
    sites = np.array([model.landmarks[k] for k in names]) - idx[0]
    relative = p.tongue - (carried[sites] - rest[sites])
    d = tongue_displacement(s[idx], site_s, relative, anchor_s, anchor)
    xy = carried + f["tongue_follow"][idx][:, None] * d
    return keep_volume(model, v.at[idx, :2].set(xy), closed_mesh_volume(v, tongue_faces(model)))


def deform(
    model: FaceModel, params: FaceParams, *, jaw_weights: str = "cassi",
    tongue_anchor: str = "follow", tongue_shape: str = "thick", lip_rounding: bool = True,
) -> Float[Array, "V 3"]:
    """Vertices (V, 3) mm of ``model`` posed by ``params`` (one frame; vmap for many).

    ``jaw_weights``: ``"cassi"`` (Parke's fractions x 1.11111, lower teeth 100 %) or
    ``"parke"``; ``tongue_anchor``: ``"fixed"`` | ``"follow"`` | ``"none"``;
    ``tongue_shape``: ``"thick"`` | ``"flat"`` (CASSI's zero-thickness sheet);
    ``lip_rounding``: the corners come together as the lips come forward. All static.
    With ``tongue_shape="flat"`` the default parameters no longer give the rest mesh.
    """
    v = jnp.asarray(model.vertices)
    v = conformation(model, v, params)
    v = jaw(model, v, params, jaw_weights)
    v = lips(model, v, params, bool(lip_rounding))
    return tongue(model, v, params, tongue_anchor, tongue_shape, jaw_weights)


def vertex_normals(vertices: Float[Array, "V 3"], faces: Int[np.ndarray, "F 3"]) -> Float[Array, "V 3"]:
    """Unit vertex normals (V, 3): area-weighted sums of the incident face normals.

    Zero-area triangles contribute nothing. A vertex whose sum is zero (only degenerate
    triangles) gets the zero vector, with zero gradient: the norm is taken through a double
    ``where`` so that neither branch divides by zero.
    """
    faces = np.asarray(faces)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    face_n = jnp.cross(b - a, c - a)  # length = 2 x area
    summed = jnp.zeros_like(vertices)
    for k in range(3):
        summed = summed.at[faces[:, k]].add(face_n)
    sq = jnp.sum(summed * summed, axis=-1, keepdims=True)
    ok = sq > 0.0
    norm = jnp.sqrt(jnp.where(ok, sq, 1.0))
    return jnp.where(ok, summed / norm, 0.0)


def model_pellets(model: FaceModel, vertices: Float[Array, "V 3"]) -> Float[Array, "8 2"]:
    """(8, 2) x, y of the model's pellet sites, order UL, LL, T1, T2, T3, T4, MNI, MNM."""
    idx = np.array([model.landmarks[k] for k in PELLET_SITES])
    return vertices[idx, :2]
