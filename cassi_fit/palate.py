"""A 3D palate from a subject's 2D palatal centreline (``PAL.DAT``), as CASSI drew it.

CASSI (section 2, "the palatal outline"): the palate is narrow at the front of the mouth
and wider toward the back, with a slight downward slope from its centreline to its
edges, and with thickness. Its report (section 4) notes that for two subjects the palate
reached below the tip of the upper front teeth; here every vertex is clamped to stay at
least ``margin`` mm above the upper incisor tip (y = 0 in the model frame).

The mesh has a fixed vertex and face count whatever the outline's point count: the
centreline is resampled to ``N_ALONG`` points equally spaced in arc length. Vertex layout:
``[oral sheet (N_ALONG, N_ACROSS), nasal sheet (N_ALONG, N_ACROSS)]`` flattened row-major;
the nasal sheet lies ``thickness`` mm above the oral one.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .errors import DegenerateGeometryError
from .face_model import FaceModel

N_ALONG = 12
N_ACROSS = 7

# A default centreline (mm, front to back) shaped like the palates in XRMB PAL.DAT files.
DEFAULT_OUTLINE = np.array([
    (-4.0, 4.0), (-6.0, 8.5), (-9.0, 12.5), (-13.0, 16.0), (-18.0, 19.0), (-24.0, 21.5),
    (-31.0, 23.5), (-38.0, 25.0), (-45.0, 26.0), (-52.0, 26.7), (-60.0, 27.0)])


def _check_outline(outline):
    """Reject outlines for which no palate exists (only when the values are concrete)."""
    shape = jnp.shape(outline)
    if len(shape) != 2 or shape[1] != 2 or shape[0] < 2:
        raise DegenerateGeometryError(
            f"palate outline must be an (n >= 2, 2) array of x, y in mm, got shape {shape}")
    try:
        values = np.asarray(outline, dtype=float)
    except Exception:  # a tracer under jit: checked by the caller's concrete run
        return
    if not np.all(np.isfinite(values)):
        raise DegenerateGeometryError("palate outline contains non-finite values")
    if np.sum(np.linalg.norm(np.diff(values, axis=0), axis=1)) <= 0.0:
        raise DegenerateGeometryError("palate outline has zero length (all points coincide)")


def resample(outline: Float[Array, "k 2"], n: int = N_ALONG) -> Float[Array, "n 2"]:
    """``n`` points equally spaced in arc length along a polyline (k, 2) mm -> (n, 2)."""
    outline = jnp.asarray(outline)
    seg = jnp.linalg.norm(jnp.diff(outline, axis=0), axis=1)
    s = jnp.concatenate([jnp.zeros(1, seg.dtype), jnp.cumsum(seg)])
    q = jnp.linspace(0.0, 1.0, n, dtype=s.dtype) * s[-1]
    return jnp.stack([jnp.interp(q, s, outline[:, 0]), jnp.interp(q, s, outline[:, 1])], -1)


def palate_faces(n_along: int = N_ALONG, n_across: int = N_ACROSS) -> Int[np.ndarray, "Q 3"]:
    """Triangles (Q, 3) of the closed palate slab; outward-facing winding."""
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


def build_palate(
    outline_mm: Float[np.ndarray, "n 2"] | Float[Array, "n 2"], *, front_half_width: float = 8.0,
    back_half_width: float = 22.0, front_edge_drop: float = 3.0, back_edge_drop: float = 9.0,
    thickness: float = 3.0, margin: float = 1.0,
) -> tuple[Float[Array, "P 3"], Int[np.ndarray, "Q 3"]]:
    """Palate vertices ``(2 * N_ALONG * N_ACROSS, 3)`` mm and faces ``(Q, 3)``.

    ``outline_mm``: (n, 2) palatal centreline in the model frame (x front, y up), front to
    back, any n >= 2. Across the palate (z from -half width to +half width) the oral surface
    drops quadratically from the centreline by ``edge_drop`` at the edges; half width and
    drop grow from front to back (narrow at the front, wider toward the back). Every
    vertex satisfies ``y >= margin`` (above the upper incisor tip): the oral sheet is
    clamped with ``maximum`` (gradient 0 through the clamped points, 1 elsewhere) and the
    nasal sheet is the clamped oral sheet raised by ``thickness``. Differentiable in the
    outline; jit-compatible (the point count n is static).
    """
    _check_outline(outline_mm)
    centre = resample(outline_mm)
    u = jnp.linspace(0.0, 1.0, N_ALONG, dtype=centre.dtype)[:, None]   # front -> back
    v = jnp.linspace(-1.0, 1.0, N_ACROSS, dtype=centre.dtype)[None, :]  # right -> left
    # half width rises quickly behind the alveolar ridge (sin), the drop linearly
    half_width = front_half_width + (back_half_width - front_half_width) * jnp.sin(jnp.pi / 2 * u)
    drop = front_edge_drop + (back_edge_drop - front_edge_drop) * u
    x = jnp.broadcast_to(centre[:, :1], (N_ALONG, N_ACROSS))
    y = jnp.maximum(centre[:, 1:] - drop * v**2, margin)
    z = half_width * v
    oral = jnp.stack([x, y, z], -1).reshape(-1, 3)
    nasal = oral + jnp.array([0.0, thickness, 0.0], dtype=oral.dtype)
    return jnp.concatenate([oral, nasal]), palate_faces()


def with_palate(
    model: FaceModel, outline_mm: Float[np.ndarray, "n 2"] | Float[Array, "n 2"], **shape: float
) -> FaceModel:
    """The model with its palate region rebuilt from ``outline_mm`` (same topology)."""
    verts, _ = build_palate(outline_mm, **shape)
    index = np.asarray(model.regions["palate"])
    if len(index) != verts.shape[0]:
        raise DegenerateGeometryError(
            f"the model's palate region has {len(index)} vertices, build_palate makes "
            f"{verts.shape[0]}: the model was not built with cassi_fit.palate")
    new = jnp.asarray(model.vertices).at[index].set(verts.astype(model.vertices.dtype))
    return eqx.tree_at(lambda m: m.vertices, model, new)
