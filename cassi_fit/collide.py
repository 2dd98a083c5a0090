"""Collisions: the tongue against the teeth and the palate, the lips against the teeth
and each other.

CASSI's tongue poked through the front teeth for 13 of 15 subjects and through the palate
for nearly all (report section 4); its future work asks for collision detection. This
module measures how deep a point is inside an obstacle (mm), pushes it out (the
projection used in animation) and gives a smooth penalty (used inside fits).

Obstacles, all taken from the posed vertices of a frame, so they move with the jaw:

* **Teeth (with the gum and bone around their roots).** Each dental arch is described by
  vertex chains running from the right back molar round the front to the left back molar
  (``FaceModel.collision``; written by ``model/build_model.py``): the lingual and the
  labial faces of the crowns at their occlusal (biting) and cervical (gum) levels. At a
  height ``y`` each face is the occlusal chain for ``y`` at the occlusal level, the
  cervical chain from the gum line on, and in between a blend; between the two faces lies
  the band of the crowns (and, beyond the gum line, of the bone that holds them). For the
  **upper** arch a point is inside when it is in that band (measured in the horizontal
  x-z plane) *and* above the occlusal level; for the **lower** arch when in its band and
  below its occlusal level. The depth is the shortest way out: ``min(distance to the
  lingual face, distance to the labial face, vertical distance to the occlusal level)``.
  So a tongue between the open front teeth (interdental /th/, protrusion), or already out
  in front of them and hanging over the lower lip, is not inside anything, but a tongue
  through a crown is. Behind the last molar nothing counts. The projection moves a
  tongue point back across the lingual face or vertically (never forward through the
  teeth), a lip point back across the labial face or vertically.
* **The lips against each other.** Per skin column between the mouth corners, the lower
  lip's highest point must not be above the upper lip's lowest; where it is, both are
  brought to the middle (:func:`lips_apart`), as lips compress in a closure.
* **Palate.** The oral sheet of ``cassi_fit.palate`` (the hard palate joined to the
  teeth's necks and the velum behind it) is a height field ``y = h(x, z)`` over its
  footprint; a tongue point above it is inside by ``y - h``; the way out is down.
* **Pharyngeal wall.** The front sheet of ``cassi_fit.pharynx`` is a height field
  ``x = w(y, z)`` over its height (beyond its sides the lateral walls' x holds); a
  tongue point behind it is inside by ``w - x``; the way out is forward. A model without
  a pharynx region is given ``pharynx.DEFAULT_WALL``. :func:`airway` is the least
  front-back distance from the tongue to the wall (< 0: the tongue is through it).

All functions take one frame (``vertices (V, 3)`` mm) and are jit/vmap/grad friendly;
the model's index chains are static.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from . import pharynx as _pharynx
from .errors import CassiError
from .face_model import FaceModel
from .tongue import closed_mesh_volume, keep_volume, tongue_faces

#: Crowns counted as "front teeth" (0 central incisor, 1 lateral incisor, 2 canine).
FRONT_TEETH = 2
#: How far (mm) the projection pushes a point beyond the surface it was inside.
PROJECTION_MARGIN_MM = 1e-3
#: Alternating passes over the obstacles in :func:`project` (a push out of one obstacle
#: may enter another; the measured depth after the passes is reported).
PROJECTION_PASSES = 4
#: Rounds of lips apart, then out of the teeth, in :func:`project`.
LIP_ROUNDS = 3
#: Volume-restoring passes after the projection (:func:`settle`, the thick tongue).
TONGUE_VOLUME_PASSES = 3
#: Names of the per-frame depths :func:`report` returns (max over the part's vertices, mm).
REPORT_KEYS = (
    "tongue_palate",
    "tongue_pharynx",
    "tongue_upper_teeth",
    "tongue_lower_teeth",
    "tongue_upper_front",
    "tongue_lower_front",
    "lips_upper_teeth",
    "lips_lower_teeth",
    "lips_crossing",
)
_CHAINS = ("lingual_occlusal", "lingual_cervical", "labial_occlusal", "labial_cervical")
_PALATE_ACROSS = 7  # cassi_fit.palate.N_ACROSS (the palate region's oral sheet layout)


def has_collision_data(model: FaceModel) -> bool:
    """True if ``model`` has the collision chains of both arches."""
    return all(f"{a}_{c}" in model.collision for a in ("upper", "lower") for c in _CHAINS)


def require_collision_data(model: FaceModel) -> None:
    """``CassiError`` if ``model`` has no collision chains (``has_collision_data``)."""
    if not has_collision_data(model):
        raise CassiError(
            "this face model has no collision chains (model.json 'collision'); rebuild it "
            "with model/build_model.py to use collision handling"
        )


def arch_chains(
    model: FaceModel, vertices: Float[Array, "V 3"], arch: str
) -> tuple[list[Float[Array, "K 3"]], Int[np.ndarray, " K"]]:
    """Positions of the four chains of ``arch`` (each (K, 3)) and the tooth numbers (K,)."""
    chains = [vertices[np.asarray(model.collision[f"{arch}_{c}"])] for c in _CHAINS]
    return chains, np.asarray(model.collision[f"{arch}_tooth"])


def _perp(d):
    """The horizontal (x, z) vector ``d`` turned by 90 degrees."""
    return jnp.stack([-d[..., 1], d[..., 0]], -1)


def _wall_distance(q, wall, far, outward, y_occ):
    """Where one point ``q (3,)`` is across the band between two polylines (x, z): the
    entry ``wall (K, 2)`` and the ``far`` wall (the other face of the crowns, same
    stations). Returns ``(distance beyond the entry wall (> 0 into the band), distance
    beyond the far wall (> 0 past the teeth), occlusal y at the closest point, unit normal
    (2,) into the band, inside the chain's span)``; ``outward (K, 2)`` points into the band."""
    p = q[jnp.array([0, 2])]
    a, b = wall[:-1], wall[1:]
    ab = b - a
    length2 = jnp.sum(ab * ab, -1)
    safe = jnp.where(length2 > 0, length2, 1.0)
    t_raw = jnp.sum((p[None] - a) * ab, -1) / safe
    t = jnp.clip(t_raw, 0.0, 1.0)
    closest = a + t[:, None] * ab
    d2 = jnp.sum((p[None] - closest) ** 2, -1)
    j = jnp.argmin(d2)
    n = _perp(ab[j])
    n_len = jnp.sqrt(jnp.maximum(jnp.sum(n * n), 1e-24))
    n = n / n_len
    out_dir = 0.5 * (outward[j] + outward[j + 1])
    n = jnp.where(jnp.dot(n, out_dir) < 0, -n, n)
    signed = jnp.dot(p - closest[j], n)
    # the far face of the same crowns: the matching segment of the other chain
    fa, fb = far[j], far[j + 1]
    fab = fb - fa
    ft = jnp.clip(jnp.dot(p - fa, fab) / jnp.maximum(jnp.dot(fab, fab), 1e-12), 0.0, 1.0)
    beyond = jnp.dot(p - (fa + ft * fab), n)
    last = ab.shape[0] - 1
    within = ~(((j == 0) & (t_raw[0] < 0)) | ((j == last) & (t_raw[last] > 1)))
    y = y_occ[j] + t[j] * (y_occ[j + 1] - y_occ[j])
    return signed, beyond, y, n, within


def _walls(q, chains, upper: bool, side: str):
    """The two faces of one arch's crowns at the height of ``q``, entry face first:
    lingual then labial for ``side="lingual"`` (the tongue, from inside the mouth),
    labial then lingual for ``"labial"`` (the lips, from outside)."""
    ling_o, ling_c, lab_o, lab_c = chains
    sign = 1.0 if upper else -1.0
    # blend occlusal -> cervical by the height of q at each station
    span = ling_c[:, 1] - ling_o[:, 1]
    span = jnp.where(jnp.abs(span) > 1e-9, span, sign * 1e-9)
    f = jnp.clip((q[1] - ling_o[:, 1]) / span, 0.0, 1.0)[:, None]
    ling = ling_o[:, [0, 2]] + f * (ling_c[:, [0, 2]] - ling_o[:, [0, 2]])
    lab = lab_o[:, [0, 2]] + f * (lab_c[:, [0, 2]] - lab_o[:, [0, 2]])
    if side == "lingual":
        return _wall_distance(q, ling, lab, lab - ling, ling_o[:, 1])
    return _wall_distance(q, lab, ling, ling - lab, ling_o[:, 1])


def teeth_depth(
    q: Float[Array, " 3"], chains: list, upper: bool, side: str
) -> tuple[Float[Array, ""], Float[Array, " 3"]]:
    """Depth (mm, >= 0) of ``q`` inside one arch, and the displacement that takes it out
    (back across the face it came in by, or vertically to the occlusal level)."""
    sign = 1.0 if upper else -1.0
    d_h, beyond, y_occ, n, within = _walls(q, chains, upper, side)
    d_v = sign * (q[1] - y_occ)
    inside = within & (d_h > 0) & (beyond < 0) & (d_v > 0)
    depth = jnp.where(inside, jnp.minimum(jnp.minimum(d_h, -beyond), d_v), 0.0)
    horizontal = d_h <= d_v
    push = jnp.where(inside, jnp.where(horizontal, d_h, d_v) + PROJECTION_MARGIN_MM, 0.0)
    move_h = -push * jnp.array([n[0], 0.0, n[1]])
    move_v = jnp.array([0.0, -sign * push, 0.0])
    return depth, jnp.where(horizontal, move_h, move_v)


def _palate_sheet(model, vertices):
    """The palate's oral sheet as ``(N_ALONG, N_ACROSS, 3)`` (``cassi_fit.palate`` layout)."""
    index = np.asarray(model.regions["palate"])
    n_along = len(index) // (2 * _PALATE_ACROSS)
    if n_along < 2 or n_along * 2 * _PALATE_ACROSS != len(index):
        raise CassiError("the model's palate region is not a cassi_fit.palate mesh")
    return vertices[index[: n_along * _PALATE_ACROSS]].reshape(n_along, _PALATE_ACROSS, 3)


def _palate_depth(q, sheet):
    """Depth of ``q`` above the palate's oral surface (0 outside its footprint) and the
    displacement out (straight down)."""
    # rows run front (large x) to back, each at one x (its centre's); a row that comes
    # forward again (the velum along the pharyngeal wall) adds no footprint
    xs = jax.lax.cummin(sheet[:, _PALATE_ACROSS // 2, 0])
    rows = jnp.arange(xs.shape[0], dtype=q.dtype)
    r = jnp.interp(-q[0], -xs, rows)
    i0 = jnp.clip(jnp.floor(r).astype(jnp.int32), 0, xs.shape[0] - 2)
    w = r - i0

    def row_height(i):
        return jnp.interp(q[2], sheet[i, :, 2], sheet[i, :, 1])

    h = (1 - w) * row_height(i0) + w * row_height(i0 + 1)
    half = (1 - w) * sheet[i0, -1, 2] + w * sheet[i0 + 1, -1, 2]
    inside = (q[0] <= xs[0]) & (q[0] >= xs[-1]) & (jnp.abs(q[2]) <= half)
    depth = jnp.where(inside, jnp.maximum(q[1] - h, 0.0), 0.0)
    push = depth + jnp.where(depth > 0, PROJECTION_MARGIN_MM, 0.0)
    return depth, jnp.array([0.0, -1.0, 0.0]) * push


_DEFAULT_WALL = None


def _wall_sheet(model, vertices):
    """The pharyngeal wall's front sheet ``(N_HEIGHT, N_ACROSS, 3)``: the model's, or the
    default wall's for a model without a pharynx region."""
    global _DEFAULT_WALL
    if _pharynx.has_pharynx(model):
        return _pharynx.front_sheet(model, vertices)
    if _DEFAULT_WALL is None:
        _DEFAULT_WALL = np.asarray(_pharynx.build_pharynx(None)[0], np.float64)
    n = _pharynx.N_HEIGHT * _pharynx.N_ACROSS
    return jnp.asarray(_DEFAULT_WALL[:n], vertices.dtype).reshape(
        _pharynx.N_HEIGHT, _pharynx.N_ACROSS, 3)


def _wall_gap(q, sheet):
    """How far ``q`` is in front of the wall (mm, along x; < 0 behind it) and whether it
    is within the wall's height. Columns run top to bottom; beyond the sides the lateral
    walls' x holds."""
    ys = sheet[:, :, 1]
    # each column's x and z at the height of q (rows top -> bottom: y decreasing)
    xk = jax.vmap(lambda yc, xc: jnp.interp(-q[1], -yc, xc))(ys.T, sheet[:, :, 0].T)
    zk = jax.vmap(lambda yc, zc: jnp.interp(-q[1], -yc, zc))(ys.T, sheet[:, :, 2].T)
    x_wall = jnp.interp(q[2], zk, xk)
    mid = sheet.shape[1] // 2
    within = (q[1] <= ys[0, mid]) & (q[1] >= ys[-1, mid])
    return q[0] - x_wall, within


def _pharynx_depth(q, sheet):
    """Depth of ``q`` behind the wall (0 in front of it or beyond its height) and the
    displacement out (straight forward)."""
    gap, within = _wall_gap(q, sheet)
    depth = jnp.where(within, jnp.maximum(-gap, 0.0), 0.0)
    push = depth + jnp.where(depth > 0, PROJECTION_MARGIN_MM, 0.0)
    return depth, jnp.array([1.0, 0.0, 0.0]) * push


def airway(model: FaceModel, vertices: Float[Array, "V 3"]) -> Float[Array, ""]:
    """The airway left between the tongue and the pharyngeal wall in one frame (mm): the
    least front-back distance (along x, at the vertex's height and side) from a tongue
    vertex to the wall's front surface, over the tongue vertices within the wall's
    height; < 0 when the tongue is through the wall, +inf when no tongue vertex is
    within the wall's height."""
    tongue = np.asarray(model.regions["tongue"])
    sheet = _wall_sheet(model, vertices)
    gap, within = jax.vmap(lambda q: _wall_gap(q, sheet))(vertices[tongue])
    return jnp.min(jnp.where(within, gap, jnp.inf))


@eqx.filter_jit
def airway_frames(model: FaceModel, vertices: Float[Array, "m V 3"]) -> Float[Array, " m"]:
    """:func:`airway` of every frame of ``vertices (m, V, 3)`` mm: ``(m,)`` mm."""
    return jax.vmap(lambda v: airway(model, v))(vertices)


def _parts(model):
    tongue = np.asarray(model.regions["tongue"])
    lips = np.concatenate([model.regions["upper_lip"], model.regions["lower_lip"]]).astype(np.int64)
    return tongue, np.asarray(lips)


#: The keys of :func:`depths`, in its order.
DEPTH_KEYS = ("tongue_palate", "tongue_pharynx", "tongue_upper", "tongue_upper_front",
              "lips_upper", "tongue_lower", "tongue_lower_front", "lips_lower")


def depths(model: FaceModel, vertices: Float[Array, "V 3"],
           keys: tuple[str, ...] | None = None) -> dict[str, Array]:
    """Per-vertex depths (mm) of one frame: ``tongue_palate``, ``tongue_pharynx``
    (behind the pharyngeal wall), ``tongue_upper`` and
    ``tongue_lower`` (tongue vertices, the teeth of that arch), ``lips_upper`` and
    ``lips_lower`` (lip vertices); plus ``tongue_upper_front``/``tongue_lower_front``,
    the teeth depths counted only where the closest crown is a front tooth.

    ``keys``: only these of :data:`DEPTH_KEYS` (default all), the others not computed
    (a caller that needs the lips alone does not trace, compile and run the tongue's)."""
    require_collision_data(model)
    want = DEPTH_KEYS if keys is None else tuple(keys)
    unknown = [k for k in want if k not in DEPTH_KEYS]
    if unknown:
        raise CassiError(f"unknown depth key(s) {', '.join(unknown)}; "
                         f"known: {', '.join(DEPTH_KEYS)}")
    tongue, lips = _parts(model)
    vt, vl = vertices[tongue], vertices[lips]
    out = {}
    if "tongue_palate" in want:
        sheet = _palate_sheet(model, vertices)
        out["tongue_palate"] = jax.vmap(lambda q: _palate_depth(q, sheet)[0])(vt)
    if "tongue_pharynx" in want:
        wall = _wall_sheet(model, vertices)
        out["tongue_pharynx"] = jax.vmap(lambda q: _pharynx_depth(q, wall)[0])(vt)
    for arch in ("upper", "lower"):
        of_tongue = {f"tongue_{arch}", f"tongue_{arch}_front"} & set(want)
        of_lips = f"lips_{arch}" in want
        if not (of_tongue or of_lips):
            continue
        chains, teeth = arch_chains(model, vertices, arch)
        upper = arch == "upper"
        if of_tongue:
            d_t = jax.vmap(lambda q, c=chains, u=upper: teeth_depth(q, c, u, "lingual")[0])(vt)
            if f"tongue_{arch}" in want:
                out[f"tongue_{arch}"] = d_t
            if f"tongue_{arch}_front" in want:
                front = _front_mask(vt, chains, teeth)
                out[f"tongue_{arch}_front"] = jnp.where(front, d_t, 0.0)
        if of_lips:
            out[f"lips_{arch}"] = jax.vmap(
                lambda q, c=chains, u=upper: teeth_depth(q, c, u, "labial")[0])(vl)
    return out


def _front_mask(points, chains, teeth):
    """True where the closest occlusal-chain station belongs to a front tooth."""
    station = chains[0][:, [0, 2]]
    d2 = jnp.sum((points[:, None, [0, 2]] - station[None]) ** 2, -1)
    nearest = jnp.argmin(d2, axis=1)
    return jnp.asarray(teeth <= FRONT_TEETH)[nearest]


def report(model: FaceModel, vertices: Float[Array, "V 3"]) -> dict[str, Float[Array, ""]]:
    """The deepest point of each kind in one frame (mm): the keys of ``REPORT_KEYS``."""
    d = depths(model, vertices)
    return {
        "tongue_palate": jnp.max(d["tongue_palate"]),
        "tongue_pharynx": jnp.max(d["tongue_pharynx"]),
        "tongue_upper_teeth": jnp.max(d["tongue_upper"]),
        "tongue_lower_teeth": jnp.max(d["tongue_lower"]),
        "tongue_upper_front": jnp.max(d["tongue_upper_front"]),
        "tongue_lower_front": jnp.max(d["tongue_lower_front"]),
        "lips_upper_teeth": jnp.max(d["lips_upper"]),
        "lips_lower_teeth": jnp.max(d["lips_lower"]),
        "lips_crossing": jnp.maximum(jnp.max(lips_crossing(model, vertices)), 0.0),
    }


@eqx.filter_jit
def report_frames(
    model: FaceModel, vertices: Float[Array, "m V 3"]
) -> dict[str, Float[Array, " m"]]:
    """:func:`report` of every frame of ``vertices (m, V, 3)`` mm, one compiled call per
    (model topology, ``m``): key -> ``(m,)`` mm. Pad ``m`` to a frame bucket
    (``frames.frame_bucket``) to share the compilation between recordings."""
    return jax.vmap(lambda v: report(model, v))(vertices)


def _escape(q, arches, side, ceiling=None):
    """The shortest move (3,) that takes ``q`` out of both arches (and below ``ceiling``,
    the palate, if given): either vertically into the band the arches leave free (below
    the upper occlusal level where ``q`` is beyond the upper wall, above the lower one
    where beyond the lower wall), or horizontally back inside the walls it is beyond.
    Where the band is empty (the teeth overlap, or the palate comes down to the lower
    teeth) only the horizontal way is taken."""
    (cu, _), (cl, _) = arches
    du, bu, yu, nu, wu = _walls(q, cu, True, side)
    dl, bl, yl, nl, wl = _walls(q, cl, False, side)
    # within the band of the crowns (and the bone above/below them) horizontally
    out_u, out_l = wu & (du > 0) & (bu < 0), wl & (dl > 0) & (bl < 0)
    inf = jnp.asarray(jnp.inf, q.dtype)
    hi = jnp.where(out_u, yu, inf)
    if ceiling is not None:
        hi = jnp.minimum(hi, ceiling)
    lo = jnp.where(out_l, yl, -inf)
    inside = (q[1] > hi) | (q[1] < lo)
    band = lo <= hi
    y_to = jnp.clip(q[1], lo, hi)
    cost_v = jnp.where(band, jnp.abs(y_to - q[1]), inf)
    h_u, h_l = jnp.where(out_u, du, 0.0), jnp.where(out_l, dl, 0.0)
    cost_h = jnp.maximum(h_u, h_l)
    n = jnp.where(h_u >= h_l, nu, nl)
    # a palate problem alone has no horizontal way out
    horizontal = (cost_h < cost_v) & (cost_h > 0)
    margin = PROJECTION_MARGIN_MM
    move_v = jnp.array([0.0, 1.0, 0.0]) * (y_to - q[1] + margin * jnp.sign(y_to - q[1]))
    move_h = -(cost_h + margin) * jnp.array([n[0], 0.0, n[1]])
    move = jnp.where(horizontal, move_h, jnp.where(band, move_v, jnp.zeros(3, q.dtype)))
    return jnp.where(inside, move, jnp.zeros(3, q.dtype))


def _palate_ceiling(q, sheet):
    """The palate's height above ``q`` (+inf outside its footprint)."""
    depth, _ = _palate_depth(q, sheet)
    return jnp.where(depth > 0, q[1] - depth, jnp.inf)


def project(model: FaceModel, vertices: Float[Array, "V 3"], passes: int = PROJECTION_PASSES) -> Float[Array, "V 3"]:
    """One frame with the tongue pushed out of the palate and both arches and in front
    of the pharyngeal wall, and the lips out of both arches, each point by its shortest
    way out of all of them at once (:func:`_escape`, then forward out of the wall;
    ``passes`` rounds, for the few points whose way out of one leads into another).
    A last push forward out of the wall ends it, so no tongue vertex is left behind the
    wall (the wall wins where it and another obstacle pull apart). Vertices that are
    inside nothing do not move."""
    require_collision_data(model)
    tongue, lips = _parts(model)
    sheet = _palate_sheet(model, vertices)
    wall = _wall_sheet(model, vertices)
    arches = [(arch_chains(model, vertices, a)[0], a == "upper") for a in ("upper", "lower")]

    def until_out(step):
        # all points together, up to ``passes`` rounds, stopping as soon as a round moves
        # nothing: a point that did not move does not move again (``step`` depends on the
        # point alone), so this is each point's own loop, traced once instead of batched
        def push(q):
            def body(carry):
                q, k, _ = carry
                move = jax.vmap(step)(q).astype(q.dtype)
                return q + move, k + 1, jnp.any(move != 0)

            q, _, _ = jax.lax.while_loop(
                lambda c: (c[1] < passes) & c[2], body, (q, 0, jnp.asarray(True))
            )
            return q

        return push

    def tongue_step(q):
        moved = q + _escape(q, arches, "lingual", _palate_ceiling(q, sheet)).astype(q.dtype)
        return moved + _pharynx_depth(moved, wall)[1].astype(q.dtype) - q

    def out_of_wall(q):
        return q + _pharynx_depth(q, wall)[1].astype(q.dtype)

    push_tongue = until_out(tongue_step)
    push_lips = until_out(lambda q: _escape(q, arches, "labial"))

    def lips_round(_, vertices):
        # the lips apart, then out of the teeth (which win where both pull)
        vertices = lips_apart(model, vertices)
        return vertices.at[lips].set(push_lips(vertices[lips]))

    vertices = vertices.at[tongue].set(jax.vmap(out_of_wall)(push_tongue(vertices[tongue])))
    # three rounds in a loop: traced once (tracing, not running, is what an unrolled
    # Python loop costs every process that animates)
    return jax.lax.fori_loop(0, LIP_ROUNDS, lips_round, vertices)


def lips_crossing(model: FaceModel, vertices: Float[Array, "V 3"]) -> Float[Array, " C"]:
    """Per lip column (C,), how far (mm) the lower lip's highest point is above the
    upper lip's lowest (> 0: the lips pass into each other). Zeros if the model has no
    lip columns."""
    if "upper_lip_columns" not in model.collision:
        return jnp.zeros(1, vertices.dtype)
    upper = vertices[np.asarray(model.collision["upper_lip_columns"]), 1]
    lower = vertices[np.asarray(model.collision["lower_lip_columns"]), 1]
    return jnp.max(lower, axis=1) - jnp.min(upper, axis=1)


def lips_apart(model: FaceModel, vertices: Float[Array, "V 3"]) -> Float[Array, "V 3"]:
    """The lips pressed together instead of passing into each other: in every column
    where they cross, both meet at the middle of the crossing (the upper lip's points
    below it raised to it, the lower lip's above it lowered), as lips compress in a
    closure. Columns that do not cross do not move."""
    if "upper_lip_columns" not in model.collision:
        return vertices
    ui = np.asarray(model.collision["upper_lip_columns"])
    li = np.asarray(model.collision["lower_lip_columns"])
    uy, ly = vertices[ui, 1], vertices[li, 1]
    top, bottom = jnp.max(ly, axis=1), jnp.min(uy, axis=1)
    contact = (0.5 * (top + bottom))[:, None]
    crossing = (top > bottom)[:, None]
    uy = jnp.where(crossing, jnp.maximum(uy, contact), uy)
    ly = jnp.where(crossing, jnp.minimum(ly, contact), ly)
    return vertices.at[ui, 1].set(uy).at[li, 1].set(ly)


def penalty_residuals(
    model: FaceModel, vertices: Float[Array, "V 3"], *, tongue: bool = True, lips: bool = True
) -> Float[Array, " r"]:
    """Residuals for a least-squares fit: every depth (mm) of the chosen parts, one per
    vertex and obstacle, flattened. Zero where nothing collides; the sum of their squares
    is the penalty. Differentiable almost everywhere (its gradient pushes points out)."""
    keys = []
    if tongue:
        keys += ["tongue_palate", "tongue_pharynx", "tongue_upper", "tongue_lower"]
    if lips:
        keys += ["lips_upper", "lips_lower"]
    if not keys:
        return jnp.zeros(0, vertices.dtype)
    d = depths(model, vertices, tuple(keys))  # only the chosen parts' depths computed
    return jnp.concatenate([d[k] for k in keys])


def project_keeping_volume(model: FaceModel, vertices: Float[Array, "V 3"],
                           tongue_shape: str = "thick") -> Float[Array, "V 3"]:
    """:func:`project`; for the thick tongue, then ``TONGUE_VOLUME_PASSES`` times: the
    tongue's volume restored to what it was before the projection
    (``tongue.keep_volume``: its width scaled) and projected again. Pushing the tongue
    out of the teeth and the palate takes up to about 6 % of its volume off; each pass
    gives back most of what is left (docs/TONGUE.md)."""
    if tongue_shape != "thick":  # CASSI's flat sheet has no volume to keep
        return project(model, vertices)
    volume = closed_mesh_volume(vertices, tongue_faces(model))

    def one_pass(i, v):  # pass 0 projects as it is; the others restore the volume first
        return project(model, jnp.where(i == 0, v, keep_volume(model, v, volume)))

    # a loop, not Python's: the projection is traced once, not 1 + TONGUE_VOLUME_PASSES times
    return jax.lax.fori_loop(0, 1 + TONGUE_VOLUME_PASSES, one_pass, vertices)


def settle(model: FaceModel, vertices: Float[Array, "V 3"], *, collisions: str = "off",
           measure: bool = False, tongue_shape: str = "thick") -> tuple:
    """One posed frame's collision step, as the geometry kernel hands it down:
    ``(vertices, before, after)``. With ``measure``, ``before`` is :func:`report` of the
    posed vertices (else None); with ``collisions="project"`` the vertices are
    :func:`project_keeping_volume`'d and ``after`` is their report; otherwise ``after``
    is ``before`` and the vertices are returned as they came."""
    before = after = report(model, vertices) if measure else None
    if collisions == "project":
        vertices = project_keeping_volume(model, vertices, tongue_shape)
        if measure:
            after = report(model, vertices)
    return vertices, before, after
