"""The pharyngeal wall: a curved sheet behind the tongue from the subject's ``PHA.DAT``.

XRMB's ``PHA.DAT`` holds two points of the posterior pharyngeal wall in the midsagittal
plane (x, y in the pellet frame; ``cassi_fit.outlines``). The wall built here passes
through that line in the midsagittal plane and is extended along it: up by
``EXTEND_UP_MM`` into the nasopharynx (behind the velum), bending forward by
``NASOPHARYNX_TILT_DEG`` toward the skull base, and down by ``EXTEND_DOWN_MM`` toward
the level of the hyoid and the larynx. Across, it is U-shaped (concave forward): at a
height, ``x = x_mid + SIDE_DEPTH_MM v^2``, ``z = half_width v`` for v in [-1, 1], the
lateral walls curving forward. The half width grows from ``HALF_WIDTH_TOP_MM`` at the
top to ``HALF_WIDTH_BOTTOM_MM`` at the bottom: the airway is about 23-28 mm wide at the
nasal floor and the velum, about 31 mm at the tongue root and about 38 mm at the hyoid
(transversal distances of adults' pharyngeal airways on CBCT, J Oral Maxillofac Res
2017;8(3):e4; the lateral walls, not the bones, set that width: Schwab et al. 1995,
Am J Respir Crit Care Med 152:1673-1689), and 6-17 mm deep front to back, which the
lateral walls' forward reach ``SIDE_DEPTH_MM`` stays within.

Without a ``PHA.DAT`` the wall is built from ``DEFAULT_WALL``: the middle of the ranges
the synthetic corpus draws its subjects' walls from (``cassi_fit.synth``).

Fixed topology, as ``cassi_fit.palate``: vertex layout ``[front sheet (N_HEIGHT,
N_ACROSS), back sheet (N_HEIGHT, N_ACROSS)]`` flattened row-major, rows from the top
down, columns from the subject's right (z < 0) to the left; the back sheet lies
``thickness`` mm behind the front one (the airway's side is the front sheet). Each
column runs strictly downward, so the wall is a height field ``x = w(y, z)`` (which
``cassi_fit.collide`` uses).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._exported import exported
from .errors import DegenerateGeometryError
from .face_model import FaceModel

N_HEIGHT = 12
N_ACROSS = 7
EXTEND_UP_MM = 22.0
EXTEND_DOWN_MM = 25.0
NASOPHARYNX_TILT_DEG = 30.0
HALF_WIDTH_TOP_MM = 13.0
HALF_WIDTH_BOTTOM_MM = 19.0
SIDE_DEPTH_MM = 12.0
THICKNESS_MM = 4.0

#: The default wall (mm, model frame, top point then bottom point) when a subject has no
#: ``PHA.DAT``: the middle of the ranges of ``cassi_fit.synth``'s subjects.
DEFAULT_WALL = np.array([(-74.0, 18.5), (-70.0, -30.0)])


def concrete_points(points, what: str) -> np.ndarray | None:
    """An ``(n >= 2, 2)`` array of x, y mm as numpy, None under ``jit`` (a tracer: checked
    by the caller's concrete run); ``DegenerateGeometryError`` naming ``what`` for another
    shape or a non-finite value. Shared by the pharyngeal wall and the palate."""
    shape = jnp.shape(points)
    if len(shape) != 2 or shape[1] != 2 or shape[0] < 2:
        raise DegenerateGeometryError(
            f"{what} must be an (n >= 2, 2) array of x, y in mm, got shape {shape}")
    try:
        values = np.asarray(points, dtype=float)
    except Exception:  # a tracer under jit
        return None
    if not np.all(np.isfinite(values)):
        raise DegenerateGeometryError(f"{what} contains non-finite values")
    return values


def _check_points(points):
    values = concrete_points(points, "pharyngeal wall")
    if values is not None and abs(values[0, 1] - values[-1, 1]) < 1.0:
        raise DegenerateGeometryError(
            "the pharyngeal wall's points must span at least 1 mm in height (the wall runs "
            f"down behind the tongue), got y {values[0, 1]:.1f} and {values[-1, 1]:.1f}")


def slab_faces(n_along: int, n_across: int) -> Int[np.ndarray, "Q 3"]:
    """Triangles (Q, 3) of a closed slab of two sheets ``(n_along, n_across)`` (layout as
    ``cassi_fit.palate``): outward-facing where the first sheet's rows run along -x (or
    -y) and its columns along +z, the second sheet behind it."""
    def idx(sheet, i, k):
        return sheet * n_along * n_across + i * n_across + k

    faces = []
    for i in range(n_along - 1):
        for k in range(n_across - 1):
            a, b, c, d = idx(0, i, k), idx(0, i, k + 1), idx(0, i + 1, k + 1), idx(0, i + 1, k)
            faces += [(a, b, c), (a, c, d)]               # oral sheet faces down
            a, b, c, d = idx(1, i, k), idx(1, i, k + 1), idx(1, i + 1, k + 1), idx(1, i + 1, k)
            faces += [(a, c, b), (a, d, c)]               # nasal sheet faces up
    for i in range(n_along - 1):                          # the two long edges
        for k, flip in ((0, False), (n_across - 1, True)):
            a, b, c, d = idx(0, i, k), idx(0, i + 1, k), idx(1, i + 1, k), idx(1, i, k)
            tris = [(a, b, c), (a, c, d)]
            faces += [(x, z, y) for x, y, z in tris] if flip else tris
    for k in range(n_across - 1):                         # front and back ends
        for i, flip in ((0, True), (n_along - 1, False)):
            a, b, c, d = idx(0, i, k), idx(0, i, k + 1), idx(1, i, k + 1), idx(1, i, k)
            tris = [(a, b, c), (a, c, d)]
            faces += [(x, z, y) for x, y, z in tris] if flip else tris
    return np.array(faces, dtype=np.int64)


def wall_faces() -> Int[np.ndarray, "Q 3"]:
    """Triangles of the closed wall slab, outward-facing (the front sheet faces forward)."""
    return slab_faces(N_HEIGHT, N_ACROSS)


def midline(points_mm: Float[Array, "n 2"]) -> Float[Array, "h 2"]:
    """The wall's midsagittal line ``(N_HEIGHT, 2)`` (x, y) mm, top to bottom: the
    ``PHA.DAT`` line (its first and last point, whichever is higher first) extended up
    (tilted forward) and down, resampled equally in arc length."""
    p = jnp.asarray(points_mm)
    top = jnp.where(p[0, 1] >= p[-1, 1], p[0], p[-1])
    bottom = jnp.where(p[0, 1] >= p[-1, 1], p[-1], p[0])
    d = (bottom - top) / jnp.linalg.norm(bottom - top)  # downward along the wall
    a = jnp.deg2rad(NASOPHARYNX_TILT_DEG)
    up = -d
    # turned toward the front (+x): for a wall running down (d_y < 0) that is a turn
    # by -a in the x-y plane
    up_tilted = jnp.array([up[0] * jnp.cos(a) + up[1] * jnp.sin(a),
                           -up[0] * jnp.sin(a) + up[1] * jnp.cos(a)])
    line = jnp.stack([top + EXTEND_UP_MM * up_tilted, top, bottom,
                      bottom + EXTEND_DOWN_MM * d])
    seg = jnp.linalg.norm(jnp.diff(line, axis=0), axis=1)
    s = jnp.concatenate([jnp.zeros(1, seg.dtype), jnp.cumsum(seg)])
    q = jnp.linspace(0.0, 1.0, N_HEIGHT, dtype=s.dtype) * s[-1]
    return jnp.stack([jnp.interp(q, s, line[:, 0]), jnp.interp(q, s, line[:, 1])], -1)


def build_pharynx(
    points_mm: Float[np.ndarray, "n 2"] | Float[Array, "n 2"] | None = None, *,
    thickness: float = THICKNESS_MM,
) -> tuple[Float[Array, "P 3"], Int[np.ndarray, "Q 3"]]:
    """Wall vertices ``(2 * N_HEIGHT * N_ACROSS, 3)`` mm and faces ``(Q, 3)``.

    ``points_mm``: the ``PHA.DAT`` points in the model frame (``(n >= 2, 2)``, scaled
    like the palate), or None for ``DEFAULT_WALL``. Differentiable in the points;
    jit-compatible. ``DegenerateGeometryError`` if the points are not finite or span
    less than 1 mm in height."""
    points = DEFAULT_WALL if points_mm is None else points_mm
    _check_points(points)
    mid = midline(jnp.asarray(points, dtype=jnp.result_type(float)))
    dtype = mid.dtype
    f = jnp.linspace(0.0, 1.0, N_HEIGHT, dtype=dtype)[:, None]
    half = HALF_WIDTH_TOP_MM + (HALF_WIDTH_BOTTOM_MM - HALF_WIDTH_TOP_MM) * f
    v = jnp.linspace(-1.0, 1.0, N_ACROSS, dtype=dtype)[None, :]
    v = 0.5 * (v - v[:, ::-1])  # exactly antisymmetric: a mirror-symmetric mesh
    x = mid[:, :1] + SIDE_DEPTH_MM * v**2
    y = jnp.broadcast_to(mid[:, 1:], (N_HEIGHT, N_ACROSS))
    z = half * v
    front = jnp.stack([x, y, z], -1).reshape(-1, 3)
    back = front - jnp.array([[thickness, 0.0, 0.0]], dtype)
    return jnp.concatenate([front, back]), wall_faces()


def front_sheet(model: FaceModel, vertices: Float[Array, "V 3"]) -> Float[Array, "h k 3"]:
    """The wall's front (airway) sheet ``(N_HEIGHT, N_ACROSS, 3)`` from ``vertices``."""
    index = np.asarray(model.regions["pharynx"])
    if len(index) != 2 * N_HEIGHT * N_ACROSS:
        raise DegenerateGeometryError(
            f"the model's pharynx region has {len(index)} vertices, not the "
            f"{2 * N_HEIGHT * N_ACROSS} of a cassi_fit.pharynx mesh")
    return vertices[index[: N_HEIGHT * N_ACROSS]].reshape(N_HEIGHT, N_ACROSS, 3)


def has_pharynx(model: FaceModel) -> bool:
    """True if ``model`` has a ``pharynx`` region (models built before it have none)."""
    return "pharynx" in model.regions


def model_wall_midline(model: FaceModel) -> Float[Array, "h 2"] | None:
    """The model's wall midline ``(N_HEIGHT, 2)`` (x, y) top to bottom, or None."""
    if not has_pharynx(model):
        return None
    if isinstance(model.vertices, jax.core.Tracer):
        return front_sheet(model, model.vertices)[:, N_ACROSS // 2, :2]
    # concrete: picked out in numpy (the same numbers; jnp would compile each indexing)
    sheet = front_sheet(model, np.asarray(model.vertices))
    return jax.device_put(np.ascontiguousarray(sheet[:, N_ACROSS // 2, :2]))


@exported
def _pharynx_vertices(points):
    """``build_pharynx``'s vertices, compiled once per shape (op by op, its many small
    operations cost a second or more of dispatch and compilation per subject) and
    exported (:mod:`cassi_fit._exported`: a warm process loads it instead of tracing)."""
    return build_pharynx(points)[0]


def with_pharynx(
    model: FaceModel, points_mm: Float[np.ndarray, "n 2"] | Float[Array, "n 2"] | None = None,
) -> FaceModel:
    """The model with its pharynx region rebuilt from ``points_mm`` (None: the default
    wall), same topology."""
    if points_mm is not None:
        _check_points(points_mm)  # on the concrete values: the compiled build cannot
        points_mm = jnp.asarray(points_mm, jnp.asarray(model.vertices).dtype)
    verts = _pharynx_vertices(points_mm)
    if not has_pharynx(model):
        raise DegenerateGeometryError(
            "the face model has no pharynx region: rebuild it with model/build_model.py")
    return replace_region(model, "pharynx", verts, "build_pharynx", "")


def replace_region(
    model: FaceModel, region: str, verts: Float[Array, "P 3"], builder: str, why: str
) -> FaceModel:
    """``model`` with the vertices of ``region`` replaced by ``verts`` (same topology);
    ``DegenerateGeometryError`` (naming ``builder``, then ``why``) if the counts differ.
    Shared by ``with_pharynx`` and ``palate.with_palate``."""
    index = np.asarray(model.regions[region])
    if len(index) != verts.shape[0]:
        raise DegenerateGeometryError(
            f"the model's {region} region has {len(index)} vertices, {builder} makes "
            f"{verts.shape[0]}{why}")
    if isinstance(model.vertices, jax.core.Tracer) or isinstance(verts, jax.core.Tracer):
        new = jnp.asarray(model.vertices).at[index].set(verts.astype(model.vertices.dtype))
    else:  # concrete: copied in numpy (the same numbers; jnp compiles each step)
        new = np.array(model.vertices)
        new[index] = np.asarray(verts).astype(new.dtype)
        new = jax.device_put(new)
    return eqx.tree_at(lambda m: m.vertices, model, new)
