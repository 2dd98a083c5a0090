"""The face mesh cut into drawable pieces: by material, by side of the midsagittal plane,
and by the views that show each piece (numpy only: no OpenGL here).

The paper's ``inside`` view removes the near half of skin, lips, eyes, teeth and palate
(here also of the pharyngeal wall) or draws the skin see-through, so every material is
split once into the triangles on either side of z = 0; each piece becomes one instanced pyrender primitive drawn once per
view that shows it (:mod:`cassi_fit.render._scene`). Back faces are culled wherever no
view can show them (materials with a clear winding, away from the cut).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from jaxtyping import Float, Integer

from ..errors import CassiError

# The face model's material order (cassi_fit.face_model.MATERIALS); repeated here so that
# rendering does not import JAX (tests/test_render.py holds the two equal).
_MATERIALS = ("skin", "lips", "eye", "teeth", "tongue", "palate", "pharynx")

# sRGB colours. The paper draws the palate as the darkest object.
MATERIAL_COLOURS = {
    "skin": (0.89, 0.72, 0.60),
    "lips": (0.70, 0.30, 0.30),
    "eye": (0.94, 0.92, 0.89),
    "teeth": (0.96, 0.94, 0.86),
    "tongue": (0.93, 0.52, 0.58),
    "palate": (0.42, 0.17, 0.20),
    "pharynx": (0.62, 0.34, 0.36),  # the pharyngeal wall: mucosa, lighter than the palate
}
# the walls of the mouth (a model's "mouth_wall" region, whatever its material): drawn
# as mucosa, in the front and side views only
_MOUTH_WALL = "mouth_wall"
MATERIAL_COLOURS[_MOUTH_WALL] = MATERIAL_COLOURS["pharynx"]
MARKER_COLOURS = {"measured": (0.90, 0.08, 0.08), "model": (0.10, 0.72, 0.22)}
_EXTRA_MARKER_COLOURS = ((0.15, 0.35, 0.95), (0.98, 0.60, 0.05), (0.60, 0.20, 0.80))
_IRIS_COLOUR = (0.33, 0.22, 0.13)
_HAIR_COLOUR = (0.20, 0.14, 0.10)  # dark brown
_HAIR_EDGE_MM = 3.0  # the hair's edge blends into the skin over this width
_PUPIL_COLOUR = (0.03, 0.03, 0.03)

# Rows: image right, image up, toward the camera, in model axes. The model frame (x front,
# y up, z to the subject's LEFT) is left-handed, so a view that shows the subject as a
# camera would (not mirrored) is a reflection in OpenGL's right-handed terms (det = -1):
# front: the subject's left on the image's right; side and inside: the subject's right
# side, the face looking to the right of the image; top: from above, the front of the
# mouth to the right and the subject's left up. (Triangle winding flips on screen with it:
# see _cull_face; lighting goes by the view direction, not the winding.)
_VIEW_AXES = {
    "front": ((0, 0, 1), (0, 1, 0), (1, 0, 0)),
    "side": ((1, 0, 0), (0, 1, 0), (0, 0, -1)),
    "inside": ((1, 0, 0), (0, 1, 0), (0, 0, -1)),
    "top": ((1, 0, 0), (0, 0, 1), (0, 1, 0)),
}
_SHOWN = {
    # the mouth's walls close the view through the open mouth; the inside view, which
    # removes the near half of the skin, would see them edge on as stray lines
    "front": set(_MATERIALS) | {_MOUTH_WALL},
    # not drawn from the side: palate, pharynx and the mouth's walls lie wholly within
    # the head, behind the cheeks and the neck (the lip gap, seen edge on, shows at most
    # teeth and tongue); not one pixel of JW11's 298 video frames changed without them
    "side": set(_MATERIALS) - {"palate", "pharynx"},
    "inside": set(_MATERIALS) - {"eye"},  # an eyeball floating in the cut head distracts
    "top": {"teeth", "tongue", "palate"},
    "midsagittal": set(),  # drawn in 2D by _section, not by OpenGL
    "tract": set(),  # drawn in 2D by _tract
}
_CUT = {"skin", "lips", "eye", "teeth", "palate", "pharynx"}  # near half removed in the inside view
_GLASS = {"skin", "lips", "eye"}  # near half see-through with skin="transparent"
# Drawn see-through in the top view, so that the tongue's position and groove show under
# it (otherwise the top view shows the palate's unchanging back in every frame).
# (Names a model may add for the soft palate or the pharynx wall are included: they would
# hide the tongue's back from above as the palate hides its front.)
_TOP_GLASS = {"palate", "velum", "soft_palate", "pharynx"}
_TOP_GLASS_ALPHA = 0.22
# Coloured by height in the top view (dark low, light high: a relief map of the dorsum,
# its groove a darker line down the middle), under the see-through palate.
_HEIGHT_COLOURED = {"tongue"}
_HEIGHT_LOW, _HEIGHT_HIGH = (0.30, 0.10, 0.30), (1.00, 0.93, 0.62)  # sRGB
_MARKER_VIEWS = ("side", "inside")
#: How the ``inside`` view opens the head: the near half cut away, or see-through skin.
SKINS = ("cut", "transparent")
_MARGIN_MM = 10.0  # free space around each view's rest bounds, for the motion


class PieceInfo(NamedTuple):
    """What one drawn piece is (:attr:`Renderer.pieces <cassi_fit.render.Renderer.pieces>`):
    a material's triangles on one side of z = 0 (``near``: the inside view's camera
    side; None: both sides, drawn alike), see-through (``glass``) or not, the views that
    draw it, and the on-screen face culled (``"front"``/``"back"``) or None (drawn
    double-sided)."""

    material: str
    near: bool | None
    glass: bool
    views: tuple[str, ...]
    cull: str | None


def _linear(srgb) -> tuple[float, ...]:
    """sRGB in [0, 1] -> linear (pyrender's shader applies gamma 1/2.2 on output)."""
    return tuple(float(c) ** 2.2 for c in srgb)


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray, incidence,
                    corners: np.ndarray | None = None) -> np.ndarray:
    """Area-weighted unit vertex normals, (V,3) float32, computed in float32 (twice as
    fast as in float64; they differ by under 1e-6, what the vertex buffer keeps anyway).

    ``incidence`` is the sparse (V,F) vertex-face matrix (:func:`_incidence`);
    ``corners`` (3F,) ``faces.T.ravel()``, if the caller keeps it. A vertex
    whose summed normal is zero (only zero-area triangles) gets (0, 0, 0): the shader then
    lights it with ambient light only, instead of dividing by zero.
    """
    # np.take along axis 0: a fancy index of (n, 3) rows costs three times as much
    corners = faces.T.ravel() if corners is None else corners
    p = np.take(np.asarray(vertices, np.float32), corners, axis=0, mode="clip")
    p = p.reshape(3, len(faces), 3)
    a, b = p[1] - p[0], p[2] - p[0]
    cross = np.empty_like(a)  # a x b as np.cross computes it: the same numbers, half the time
    np.multiply(a[:, 1], b[:, 2], out=cross[:, 0])
    cross[:, 0] -= a[:, 2] * b[:, 1]
    np.multiply(a[:, 2], b[:, 0], out=cross[:, 1])
    cross[:, 1] -= a[:, 0] * b[:, 2]
    np.multiply(a[:, 0], b[:, 1], out=cross[:, 2])
    cross[:, 2] -= a[:, 1] * b[:, 0]
    summed = incidence @ cross
    length = np.sqrt(np.einsum("ij,ij->i", summed, summed))
    zero = length == 0  # (a masked np.divide costs twice a plain one)
    out = summed / np.where(zero, np.float32(1), length)[:, None]
    out[zero] = 0
    return out


def _incidence(faces: np.ndarray, n_vertices: int):
    """Sparse (V,F) float32 matrix with a 1 where a vertex belongs to a face."""
    import scipy.sparse

    rows = faces.ravel()
    cols = np.repeat(np.arange(len(faces)), 3)
    return scipy.sparse.csr_matrix(
        (np.ones(len(rows), np.float32), (rows, cols)), shape=(n_vertices, len(faces))
    )


def _iris_factors(vertices: np.ndarray, faces: np.ndarray, face_material, eye: int):
    """Per-vertex colour factor (V,4) darkening the front of each eyeball into an iris.

    Each eye is the set of 'eye' vertices on one side of z = 0; its iris is the front half
    (x above the eye's centre) within 47 % of the eye's half-height of the gaze axis (the
    +x line through the centre; 5.6 mm on a 12 mm eyeball), its pupil within 17 % (2 mm),
    whatever the eyeball's shape or tessellation. Returns None if the model has no eye
    material.
    """
    used = np.unique(faces[face_material == eye])
    if used.size == 0:
        return None
    factors = np.ones((len(vertices), 4))
    white = np.array(_linear(MATERIAL_COLOURS["eye"]))
    ratio = np.array(_linear(_IRIS_COLOUR)) / white
    pupil_ratio = np.array(_linear(_PUPIL_COLOUR)) / white
    for side in (used[vertices[used, 2] > 0], used[vertices[used, 2] <= 0]):
        if side.size < 4:
            continue
        p = vertices[side]
        lo, hi = p.min(axis=0), p.max(axis=0)
        centre, half = (lo + hi) / 2, (hi[1] - lo[1]) / 2
        off_axis = np.hypot(p[:, 1] - centre[1], p[:, 2] - centre[2])
        iris = (p[:, 0] > centre[0]) & (off_axis < 0.47 * half)
        factors[side[iris], :3] = ratio
        factors[side[iris & (off_axis < 0.17 * half)], :3] = pupil_ratio
    return factors


def _hair_factors(n_vertices: int, fields) -> np.ndarray | None:
    """Per-vertex colour (V,4) for the skin from the model's ``hair`` field (signed distance
    in mm to the edge of the hair, positive on it): the hair's colour relative to the
    default skin colour, and in the fourth column the share of it, 0.5 + distance /
    ``_HAIR_EDGE_MM``, left unclipped so that the shader clips it per pixel (a sharp edge
    along the interpolated line, not along the triangles). None if the model has no hair
    (no positive value)."""
    if not fields or "hair" not in fields:
        return None
    distance = np.asarray(fields["hair"], np.float64)
    if distance.shape != (n_vertices,) or not np.any(distance > 0):
        return None
    factors = np.empty((n_vertices, 4))
    factors[:, :3] = np.array(_linear(_HAIR_COLOUR)) / np.array(_linear(MATERIAL_COLOURS["skin"]))
    factors[:, 3] = 0.5 + distance / _HAIR_EDGE_MM
    return factors


class _Piece:
    """The triangles of one material on one side of z = 0: one instanced pyrender primitive.

    ``vertex_index`` (n,) picks the piece's vertices from the whole mesh; ``faces`` (m,3)
    index into them; ``static`` (n,k) holds extra per-vertex columns (colour) that follow
    position and normal in the interleaved vertex buffer; ``views`` are the views that draw
    it; ``cull`` is the OpenGL face to cull ("front"/"back" on screen) or None (drawn
    double-sided).
    """

    def __init__(self, material, near, glass, vertex_index, faces, static, views, cull=None):
        self.material, self.near, self.glass, self.cull = material, near, glass, cull
        self.vertex_index, self.faces, self.static, self.views = (
            vertex_index,
            faces,
            static,
            views,
        )
        self.heights = None  # (low, high) mm: coloured by height per frame (height_colours)
        self.buffer = np.zeros((len(vertex_index), 6 + static.shape[1]), np.float32)
        self.buffer[:, 6:] = static
        self.primitive = self.mesh = None

    def info(self) -> PieceInfo:
        return PieceInfo(self.material, self.near, self.glass, self.views, self.cull)


def _piece_views(material: str, near: bool, glass: bool, views, skin: str) -> tuple:
    """The views among ``views`` that draw this piece."""
    out = []
    for v in views:
        if material not in _SHOWN[v]:
            continue
        cut = v == "inside" and near and material in _CUT
        if skin == "transparent" and material not in _GLASS:
            cut = False  # see-through skin: teeth and palate stay whole
        glass_here = v == "inside" and near and skin == "transparent" and material in _GLASS
        glass_here = glass_here or (v == "top" and material in _TOP_GLASS)
        if (glass and glass_here) or (not glass and not cut and not glass_here):
            out.append(v)
    return tuple(out)


def triangle_winding(vertices: Float[np.ndarray, "v 3"], faces: Integer[np.ndarray, "f 3"]) -> int:
    """+1 if the triangles turn counter-clockwise seen from outside, -1 if clockwise, 0 if
    unclear (signed volume under 5 % of the bounding box: open sheets, mixed winding)."""
    used = np.unique(faces)
    if used.size < 4:
        return 0
    p = vertices - vertices[used].mean(axis=0)
    a, b, c = (p[faces[:, k]] for k in range(3))
    volume = np.einsum("ij,ij->", a, np.cross(b, c)) / 6
    box = np.prod(np.ptp(p[used], axis=0))
    ratio = volume / box if box > 0 else 0.0
    return 1 if ratio > 0.05 else (-1 if ratio < -0.05 else 0)


def _cull_face(winding: int) -> str | None:
    """The on-screen face to cull for a material of this winding, or None.

    Every view is a reflection (det = -1, see _VIEW_AXES), which turns an outside that
    winds counter-clockwise into clockwise on screen: OpenGL's front faces are then the
    inside ones.
    """
    assert all(np.linalg.det(np.asarray(r, float)) < 0 for r in _VIEW_AXES.values())
    return {1: "front", -1: "back"}.get(winding)


def _height_range(points: np.ndarray) -> tuple[float, float]:
    """(low, high) y mm of the colour scale: the upper 70 % of the part's rest height range
    (its top surface, which the top view shows), widened by 5 mm up for its motion."""
    lo, hi = float(points[..., 1].min()), float(points[..., 1].max())
    return lo + 0.3 * (hi - lo), hi + 5.0


def height_colours(
    y: Float[np.ndarray, " n"], heights: tuple[float, float], base
) -> Float[np.ndarray, "n 4"]:
    """Per-vertex colour factors (n, 4) that turn the material's ``base`` sRGB colour into
    a dark-to-light height scale over ``heights`` (low, high) mm."""
    low, high = heights
    h = np.clip((np.asarray(y, np.float64) - low) / max(high - low, 1e-9), 0.0, 1.0)[:, None]
    target = (1 - h) * np.array(_linear(_HEIGHT_LOW)) + h * np.array(_linear(_HEIGHT_HIGH))
    out = np.ones((len(h), 4))
    out[:, :3] = target / np.maximum(np.array(_linear(base)), 1e-3)
    return out


def _split_pieces(vertices, faces, face_material, materials, views, skin, cull,
                  fields=None) -> list[_Piece]:  # fmt: skip
    """Split the mesh by material and by side of the midsagittal plane (triangle centroid);
    "near" is the inside view's camera side. The eyes carry their iris and pupil and the
    skin its hair (the model's ``hair`` field, ``fields``) as per-vertex colour factors.

    With ``cull``, a material with a clear winding hides its back faces wherever they
    cannot be seen, the far half of a cut material in the inside view (whose inside shows)
    being its own double-sided piece: back faces cost as much to rasterise as visible ones.
    The two sides of a material drawn alike (same views, culling, see-through) are then one
    piece (``near`` None), its far triangles first: one draw and one upload instead of two.
    """
    toward_camera = np.asarray(_VIEW_AXES["inside"][2], float)
    near_side = vertices[faces].mean(axis=1) @ toward_camera > 0
    eye = materials.index("eye") if "eye" in materials else -1
    iris = _iris_factors(vertices, faces, face_material, eye) if eye >= 0 else None
    hair = _hair_factors(len(vertices), fields)
    pieces = []
    for m, name in enumerate(materials):
        specs = _material_specs(vertices, faces, face_material, m, name, near_side, views,
                                skin, cull)
        colour = iris if m == eye else (hair if name == "skin" else None)
        for (near, glass, views_, face, heights), face_ids in _merge_sides(specs):
            index, local = np.unique(faces[face_ids], return_inverse=True)
            if heights is not None:
                static = np.ones((len(index), 4))
            else:
                static = colour[index] if colour is not None else np.zeros((len(index), 0))
            piece = _Piece(name, near, glass, index, local.reshape(-1, 3), static, views_,
                           cull=face)
            piece.heights = heights
            pieces.append(piece)
    return pieces


def _material_specs(vertices, faces, face_material, m, name, near_side, views, skin, cull):
    """One material's pieces before merging: ``[((near, glass, views, cull, heights),
    face ids)]`` in drawing order (see :func:`_split_pieces`)."""
    # (the mouth's walls are open sheets: their signed volume says nothing of which
    # side faces out, so they are drawn double-sided)
    clear = cull and name != _MOUTH_WALL
    winding = triangle_winding(vertices, faces[face_material == m]) if clear else 0
    face = _cull_face(winding)
    opened = name in _CUT and (skin == "cut" or name in _GLASS)  # inside shows at the cut
    out = []
    for near in (False, True):
        for glass in (False, True):
            ids = np.flatnonzero((face_material == m) & (near_side == near))
            shown = _piece_views(name, near, glass, views, skin)
            if not len(ids) or not shown:
                continue
            if name in _HEIGHT_COLOURED and "top" in shown:  # its own, recoloured piece
                heights = _height_range(vertices[faces[face_material == m]])
                out.append(((near, glass, ("top",), face, heights), ids))
                shown = tuple(v for v in shown if v != "top")
                if not shown:
                    continue
            if face is None or glass:
                out.append(((near, glass, shown, None, None), ids))
                continue
            if opened and not near and "inside" in shown:
                out.append(((near, glass, ("inside",), None, None), ids))
                shown = tuple(v for v in shown if v != "inside")
            if shown:
                out.append(((near, glass, shown, face, None), ids))
    return out


def _merge_sides(specs):
    """``specs`` (:func:`_material_specs`) with the far and near pieces that are drawn
    alike made one (``near`` None; the far triangles first, as they were drawn before)."""
    merged: dict = {}
    for (near, *rest), ids in specs:
        key = (rest[0], rest[1], rest[2], rest[3] is not None)
        if key in merged:
            (_, *kept), first = merged[key]
            merged[key] = ((None, *kept), np.concatenate([first, ids]))
        else:
            merged[key] = ((near, *rest), ids)
    return list(merged.values())


def _with_mouth_wall(faces, face_material, materials, regions):
    """(face_material, materials) with the triangles of the model's ``mouth_wall`` region
    (all three vertices in it) given a drawing material of their own, ``"mouth_wall"``."""
    wall = np.asarray((regions or {}).get(_MOUTH_WALL, ()), dtype=np.int64)
    on_wall = np.isin(faces, wall).all(axis=1)
    if not on_wall.any():
        return face_material, materials
    return np.where(on_wall, len(materials), face_material), (*materials, _MOUTH_WALL)


def _model_arrays(model):
    """(rest (V,3) float64, faces (F,3) int64, face_material (F,), material names)."""
    # the copy, not face_model's: importing face_model imports JAX (over a second of a
    # drawing worker's start-up, which has only arrays); a test holds the two equal
    materials = _MATERIALS
    rest = np.asarray(model.vertices, dtype=np.float64)
    faces = np.asarray(model.faces, dtype=np.int64)
    face_material = np.asarray(model.face_material, dtype=np.int64)
    if rest.ndim != 2 or rest.shape[1] != 3 or not np.all(np.isfinite(rest)):
        raise CassiError(f"render: model vertices must be finite (V, 3), got {rest.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(rest):
        raise CassiError("render: model faces must be (F, 3) indices into the vertices")
    if face_material.shape != (len(faces),) or face_material.max() >= len(materials):
        raise CassiError("render: model face_material must be (F,) indices into MATERIALS")
    return rest, faces, face_material, tuple(materials)


def vertex_colours_srgb(model, *, hair: bool = True) -> np.ndarray:
    """(V, 3) sRGB in [0, 1] per vertex, as the renderer colours the model: each material's
    colour (:data:`MATERIAL_COLOURS`), the eyes' iris and pupil and, with ``hair``, the
    skin's hair blended per vertex (the renderer's edge is per pixel: draw
    :func:`hair_share` to have it); for drawing the model elsewhere (the one-file viewer).
    numpy only."""
    rest, faces, face_material, materials = _model_arrays(model)
    linear = np.tile(np.asarray(_linear(MATERIAL_COLOURS["skin"])), (len(rest), 1))
    for m, name in enumerate(materials):
        used = faces[face_material == m].ravel()
        linear[used] = _linear(MATERIAL_COLOURS.get(name, (0.7,) * 3))
    if "eye" in materials:
        iris = _iris_factors(rest, faces, face_material, materials.index("eye"))
        if iris is not None:
            linear *= iris[:, :3]
    share = hair_share(model) if hair else None
    if share is not None:
        share = np.clip(share, 0.0, 1.0)[:, None]
        linear = linear * (1.0 - share) + share * np.asarray(_linear(HAIR_COLOUR))
    return np.clip(linear, 0.0, 1.0) ** (1 / 2.2)


#: The hair's colour (sRGB) where :func:`hair_share` reaches 1.
HAIR_COLOUR = _HAIR_COLOUR


def hair_share(model) -> np.ndarray | None:
    """(V,) the hair's share of each skin vertex's colour before clipping to [0, 1]:
    ``0.5 + distance / edge`` (the model's ``hair`` field, signed mm to the hair's edge);
    interpolated across a triangle and clipped per pixel it draws the renderer's sharp
    edge. 0 off the skin; None if the model has no hair."""
    rest, faces, face_material, materials = _model_arrays(model)
    factors = _hair_factors(len(rest), getattr(model, "fields", None))
    if factors is None:
        return None
    out = np.zeros(len(rest))
    skin = np.unique(faces[face_material == materials.index("skin")])
    out[skin] = factors[skin, 3]
    return out
