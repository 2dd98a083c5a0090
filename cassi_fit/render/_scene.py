"""The Renderer: one pyrender scene holding every view, drawn in one pass per frame.

The whole grid is ONE draw of ONE pyrender scene. Each piece of the mesh
(:mod:`cassi_fit.render._pieces`) is one pyrender primitive drawn *instanced*, one
instance per view that shows it. An instance matrix places its view in its cell in front
of one orthographic camera (and carries the cell, to which the vertex shader clips). Per
frame only the vertex buffers are rewritten in place; the OpenGL work is in
:mod:`cassi_fit.render._draw`, imported when the first Renderer is made.

Geometry is in the model frame (mm): x front, y up, z to the subject's left, z = 0
midsagittal (docs/ARCHITECTURE.md). Cameras are fitted once to the rest mesh with a
margin, so a video does not jump.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
from jaxtyping import Float, Integer, UInt8

from ..errors import CassiError, RenderingUnavailableError
from ..options import ALL_VIEWS, PAPER_VIEWS, check_choice
from ._gl import ensure_headless_gl
from ._images import add_caption
from ._pieces import (
    _EXTRA_MARKER_COLOURS,
    _MARGIN_MM,
    _MARKER_VIEWS,
    _TOP_GLASS_ALPHA,
    _VIEW_AXES,
    MARKER_COLOURS,
    MATERIAL_COLOURS,
    SKINS,
    PieceInfo,
    _incidence,
    _linear,
    _model_arrays,
    _split_pieces,
    _vertex_normals,
    _with_mouth_wall,
    height_colours,
)
from ._section import SECTION_VIEW, Section
from ._tract import TRACT_VIEW, draw_tract

#: The views drawn in 2D after the OpenGL pass (no camera, no mesh pieces).
_FLAT_VIEWS = (SECTION_VIEW, TRACT_VIEW)

RGB = tuple[float, float, float]
#: Marker points per label: ``(k, 3)`` or ``(k, 2)`` mm (numpy or JAX).
Markers = Mapping[str, Float[Any, "k d"]]


class MeshModel(Protocol):
    """What a Renderer reads of a model (a :class:`~cassi_fit.FaceModel` has it):
    ``vertices (V, 3)`` mm at rest, ``faces (F, 3)`` and ``face_material (F,)`` indices
    into ``face_model.MATERIALS``; if the model has them, also ``fields["hair"]`` (V,)
    (signed distance in mm to the edge of the hair: the skin is drawn in the hair's colour
    where it is positive) and, for the midsagittal view, ``regions``, ``landmarks`` and
    ``measures``."""

    vertices: Float[Any, "v 3"]
    faces: Integer[Any, "f 3"]
    face_material: Integer[Any, " f"]


def _as_frame(vertices, n_vertices: int) -> np.ndarray:
    """One frame of vertices as a finite (V,3) float64 numpy array, or a CassiError."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.shape != (n_vertices, 3):
        raise CassiError(f"render: vertices must have shape ({n_vertices}, 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise CassiError("render: vertices contain NaN or infinite values")
    return v


def _marker_points(points) -> np.ndarray:
    """(k,3) or (k,2) marker points (mm) -> finite (k',3); non-finite rows are not drawn."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 1 and p.size in (2, 3):
        p = p[None]
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise CassiError(f"render: marker points must have shape (k, 3) or (k, 2), got {p.shape}")
    if p.shape[1] == 2:
        p = np.concatenate([p, np.zeros((len(p), 1))], axis=1)
    return p[np.all(np.isfinite(p), axis=1)]


def _cells(views, size, grid: bool) -> dict[str, tuple[float, float, float, float]]:
    """Cell of each view: (centre x, centre y, width, height) in pixels, y up.

    Grid: two columns (front, side / inside, top), three for five or six views (front,
    side, inside / top, midsagittal); the midsagittal view, when last in a short last
    row, takes the rest of the row (two cells wide among five views). One view fills the image.
    Not grid: one row.
    """
    width, height = size
    n = len(views)
    cols = 1 if n == 1 else ((2 if n <= 4 else 3) if grid else n)
    rows = -(-n // cols)
    cw, ch = width / cols, height / rows
    out = {}
    for i, v in enumerate(views):
        span = cols - i % cols if (i == n - 1 and v == SECTION_VIEW) else 1
        out[v] = ((i % cols + span / 2) * cw, height - (i // cols + 0.5) * ch, span * cw, ch)
    return out


def _sphere(subdivisions: int = 2):
    """Unit icosphere (positions, normals, faces) for the markers."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(s.vertices), np.asarray(s.vertex_normals), np.asarray(s.faces)


class Renderer:
    """Offscreen renderer of one face model: one OpenGL context, one scene, reused per frame.

    ``size`` is the whole output image (W, H) in pixels; in grid mode the views share it as
    a 2x2 grid (front, side / inside, top), each view a (W/2, H/2) cell, or with five
    views a 3x2 grid (front, side, inside / top, midsagittal two cells wide); with
    ``grid=False`` the views stand in one row. The ``midsagittal`` view (:mod:`cassi_fit.render._section`)
    is the posed mesh cut at z = 0, drawn in 2D into its cell after the OpenGL pass, with
    ``traces`` (``{"palate": (n, 2), "pharynx": (m, 2)}`` mm in the model frame, e.g. the
    subject's PAL.DAT and PHA.DAT times its scale; :meth:`set_traces`), the pellets with
    their trails and the time (:meth:`render`'s ``trails`` and ``time``). ``skin`` is
    ``"cut"`` (the inside view removes the near half of skin, lips, eyes, teeth and
    palate) or ``"transparent"`` (the near skin, lips and eyes drawn see-through). ``antialias`` is the number of multisample samples
    (0 = none, the fast default). ``marker_radius`` is in mm (default: 1.2 % of the
    head's height). Cameras are fitted to ``model.vertices`` (the rest mesh) plus
    ``margin`` (a fraction of each cell kept free on every side). ``colours`` overrides
    :data:`MATERIAL_COLOURS` (``{material: sRGB triple in [0, 1]}``). ``cull``: skip the
    back faces of materials whose winding is clear (outside counter-clockwise or
    clockwise) wherever the view cannot show their inside (a third less work per frame);
    ``False`` draws everything double-sided, for meshes whose holes show their inside.
    """

    def __init__(
        self,
        model: MeshModel,
        *,
        size: tuple[int, int] = (640, 480),
        views: str | Sequence[str] = PAPER_VIEWS,
        grid: bool = True,
        skin: str = "cut",
        background: RGB = (0.92, 0.92, 0.92),
        antialias: int = 0,
        marker_radius: float | None = None,
        margin: float = 0.06,
        colours: Mapping[str, RGB] | None = None,
        cull: bool = True,
        traces: Mapping[str, Float[Any, "n 2"] | None] | None = None,
    ) -> None:
        self.size, self.views, skin = _check_options(size, views, skin, background)
        self.grid = bool(grid)
        rest, faces, face_material, materials = _model_arrays(model)
        self._n_vertices = len(rest)
        self._faces = faces
        self._incidence = _incidence(faces, len(rest))
        self._corners = np.ascontiguousarray(faces.T).ravel()  # for _vertex_normals
        self._posed = np.zeros((len(rest), 6), np.float32)
        drawn, drawn_materials = _with_mouth_wall(
            faces, face_material, materials, getattr(model, "regions", None)
        )
        self._pieces = _split_pieces(
            rest, faces, drawn, drawn_materials, self.views, skin, bool(cull),
            fields=getattr(model, "fields", None),
        )
        self._section = None
        if SECTION_VIEW in self.views:
            self._section = Section(
                rest, faces, face_material, materials, regions=getattr(model, "regions", None),
                landmarks=getattr(model, "landmarks", None),
                measures=getattr(model, "measures", None), traces=traces,
            )  # fmt: skip
        self._section_box = self._tract_box = None
        self._fits = {v: self._fit(v, rest) for v in self.views if v not in _FLAT_VIEWS}
        height = (
            self._fits.get("side", next(iter(self._fits.values())))[3][1]
            if self._fits
            else float(np.ptp(rest[:, 1]))
        )
        self._marker_radius = float(marker_radius) if marker_radius else 0.012 * height
        self._margin = float(margin)
        self._colours = {**MATERIAL_COLOURS, **(colours or {})}
        self.platform = ensure_headless_gl()
        self._background = tuple(int(round(255 * c)) for c in background)
        self._build_scene(background, int(antialias))
        self._layout_key, self._placements, self._markers = None, {}, {}
        self.render(rest)  # warm-up: shaders compiled, buffers in the GL context

    # -- set-up ------------------------------------------------------------------------

    def _fit(self, view, rest):
        """(R (3,3), mid (3,), lo (3,), extent (3,)) of the view's visible rest geometry."""
        return _fit_view(self._pieces, view, rest)

    def _build_scene(self, background, samples):
        import pyrender

        from . import _draw  # OpenGL's first import: after ensure_headless_gl

        width, height = self.size
        depth = 4.0 * (width + height)
        self._scene = pyrender.Scene(bg_color=(*background, 1.0))
        camera = pyrender.OrthographicCamera(width / 2, height / 2, znear=1.0, zfar=2 * depth)
        pose = np.eye(4)
        pose[:3, 3] = (width / 2, height / 2, depth)
        self._scene.add(camera, pose=pose)
        for piece in self._pieces:
            self._add_piece(pyrender, piece)
        try:
            self._gl = pyrender.OffscreenRenderer(width, height)
        except Exception as exc:  # the probe passed, but this process's context did not
            reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise RenderingUnavailableError(
                f"no offscreen OpenGL context with PYOPENGL_PLATFORM={self.platform}: {reason}"
            ) from exc
        self._gl._renderer.__class__ = _draw.ColourOnlyRenderer
        self._gl._renderer.samples = samples

    def _add_piece(self, pyrender, piece):
        from . import _draw

        alpha = 0.35 if piece.glass else 1.0
        if piece.glass and piece.views == ("top",):  # the palate over the tongue's relief
            alpha = _TOP_GLASS_ALPHA
        material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=(*_linear(self._colours.get(piece.material, (0.7,) * 3)), alpha),
            metallicFactor=0.0,
            roughnessFactor=0.75 if piece.material in ("skin", "palate") else 0.5,
            doubleSided=piece.cull is None,
            alphaMode="BLEND" if piece.glass else "OPAQUE",
        )
        n = len(piece.vertex_index)
        piece.primitive = pyrender.Primitive(
            positions=np.zeros((n, 3), np.float32),
            normals=np.tile(np.float32([1, 0, 0]), (n, 1)),
            color_0=piece.static if piece.static.shape[1] else None,
            indices=piece.faces,
            material=material,
            poses=np.tile(np.eye(4), (len(piece.views), 1, 1)),
        )
        piece.primitive.cassi_cull = piece.cull
        piece.mesh = pyrender.Mesh([piece.primitive])
        _draw.add_mesh(self._scene, piece.mesh)

    # -- per frame ---------------------------------------------------------------------

    def _set_layout(self, key):
        """Place the views: ``"grid"`` (all views in their cells) or one view filling the image."""
        from . import _draw

        if key == self._layout_key:
            return
        width, height = self.size
        cells = (
            _cells(self.views, self.size, self.grid)
            if key == "grid"
            else {key: (width / 2, height / 2, width, height)}
        )
        self._placements = {
            v: self._placement(v, cell) for v, cell in cells.items() if v not in _FLAT_VIEWS
        }
        # the 2D views' boxes: (left, top, right, bottom) in image rows, y down
        boxes = {v: tuple(int(round(c)) for c in (cx - cw / 2, height - cy - ch / 2,
                                                  cx + cw / 2, height - cy + ch / 2))
                 for v, (cx, cy, cw, ch) in cells.items() if v in _FLAT_VIEWS}  # fmt: skip
        self._section_box = boxes.get(SECTION_VIEW)
        self._tract_box = boxes.get(TRACT_VIEW)
        for piece in self._pieces:
            poses = [self._placements[v] for v in piece.views if v in self._placements]
            piece.mesh.is_visible = bool(poses)
            if poses:
                _draw.set_poses(piece.primitive, np.stack(poses))
        self._layout_key = key

    def _placement(self, view, cell) -> np.ndarray:
        """(4,4) instance matrix of ``view`` in ``cell``: a similarity taking model mm to
        image pixels, with the cell's rectangle (x0, y0, x1, y1) in its bottom row.

        The shader rebuilds the affine matrix and clips every instance to its own cell, so
        a tongue or jaw moving past the rest-mesh bounds never spills into a neighbour.
        The fit keeps ``margin`` of the cell and at least _MARGIN_MM around the bounds.
        """
        rotation, mid, _, extent = self._fits[view]
        cx, cy, cw, ch = cell
        padded = extent[:2] + 2 * _MARGIN_MM
        scale = min(cw / padded[0], ch / padded[1]) * (1 - 2 * self._margin)
        pose = np.eye(4)
        pose[:3, :3] = scale * rotation
        pose[:3, 3] = np.array([cx, cy, 0.0]) - scale * mid
        pose[3] = (cx - cw / 2, cy - ch / 2, cx + cw / 2, cy + ch / 2)
        return pose

    def _upload(self, vertices: np.ndarray):
        """Write one frame's positions and normals into every piece's vertex buffer."""
        from . import _draw

        posed = self._posed  # (V, 6) float32: positions, normals; one gather per piece
        posed[:, :3] = vertices
        posed[:, 3:] = _vertex_normals(vertices, self._faces, self._incidence,
                                        self._corners)
        self._gl._platform.make_current()
        for piece in self._pieces:  # (np.take: a third of a fancy index's time)
            if piece.buffer.shape[1] == 6:
                np.take(posed, piece.vertex_index, axis=0, out=piece.buffer, mode="clip")
            else:
                piece.buffer[:, :6] = np.take(posed, piece.vertex_index, axis=0, mode="clip")
            if piece.heights is not None:
                base = self._colours.get(piece.material, (0.7,) * 3)
                piece.buffer[:, 6:] = height_colours(piece.buffer[:, 1], piece.heights, base)
            _draw.write_vertices(piece.primitive, piece.buffer)

    def _set_markers(self, markers):
        """Instanced spheres for each label's points in the side and inside views.

        The points are moved along the view direction to just in front of the model's rest
        bounds (this does not move them in the orthographic image), so the face never hides
        them.
        """
        import pyrender

        from . import _draw

        markers = {} if markers is None else dict(markers)
        # in a fixed order (not a set's, which varies with each process's string hashes):
        # the markers are drawn at one depth, so the first drawn shows where they overlap
        for label in [*self._markers, *(k for k in markers if k not in self._markers)]:
            pts = _marker_points(markers.get(label, np.zeros((0, 3))))
            poses = self._marker_poses(pts)
            if label not in self._markers:
                if not len(poses):
                    continue
                self._markers[label] = self._marker_mesh(pyrender, label, poses)
            mesh = self._markers[label]
            mesh.is_visible = bool(len(poses))
            if len(poses):
                _draw.set_poses(mesh.primitives[0], poses)

    def _marker_poses(self, points) -> np.ndarray:
        """(n,4,4) sphere poses for ``points`` (k,3) mm in the marker views laid out now.

        Radius: ``marker_radius`` mm, but at least 3 pixels so that small images show them.
        """
        out = []
        for view in _MARKER_VIEWS:
            if view not in self._placements or not len(points):
                continue
            rotation, _, lo, extent = self._fits[view]
            pose = self._placements[view]
            scale = np.linalg.norm(pose[:3, 0])
            radius = max(self._marker_radius * scale, 3.0)
            poses = np.tile(np.eye(4), (len(points), 1, 1))
            poses[:, :3, :3] *= radius
            poses[:, 3] = pose[3]  # the view's cell, for clipping
            poses[:, :3, 3] = points @ pose[:3, :3].T + pose[:3, 3]
            poses[:, 2, 3] = scale * (lo[2] + extent[2]) + pose[2, 3] + 2 * radius
            out.append(poses)
        return np.concatenate(out) if out else np.zeros((0, 4, 4))

    def _marker_mesh(self, pyrender, label, poses):
        from . import _draw

        colours = _EXTRA_MARKER_COLOURS
        colour = MARKER_COLOURS.get(label, colours[len(self._markers) % len(colours)])
        material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=(*_linear(colour), 1.0),
            emissiveFactor=tuple(0.5 * c for c in _linear(colour)),
            metallicFactor=0.0,
            roughnessFactor=0.4,
        )
        positions, normals, faces = _sphere()
        primitive = pyrender.Primitive(
            positions=positions, normals=normals, indices=faces, material=material, poses=poses
        )
        mesh = pyrender.Mesh([primitive])
        _draw.add_mesh(self._scene, mesh)
        return mesh

    def _draw(self) -> np.ndarray:
        colour, _ = self._gl.render(self._scene)
        return colour

    # -- public ------------------------------------------------------------------------

    @property
    def pieces(self) -> tuple[PieceInfo, ...]:
        """The pieces the mesh is drawn in (material, side, views, culling), for checking."""
        return tuple(p.info() for p in self._pieces)

    def drawn(self) -> tuple[int, int]:
        """(draw calls, triangles) of the mesh in one grid frame (markers not counted)."""
        self._set_layout("grid")
        counts = [len(p.faces) * sum(v in self._placements for v in p.views)
                  for p in self._pieces]
        return sum(c > 0 for c in counts), sum(counts)

    def render(
        self,
        vertices: Float[Any, "v 3"],
        *,
        markers: Markers | None = None,
        caption: str | None = None,
        trails: Mapping[str, Float[Any, "t k 2"]] | None = None,
        time: float | None = None,
        tract: Mapping[str, Any] | None = None,
    ) -> UInt8[np.ndarray, "h w 3"]:
        """One frame as an (H, W, 3) uint8 image: the grid (or the single view).

        ``vertices``: (V,3) mm, model frame, the model's topology (numpy or JAX).
        ``markers``: optional ``{label: (k,3) or (k,2) points in mm}``, drawn as spheres in
        the side and inside views and as dots in the midsagittal one ("measured" red,
        "model" green, others blue, orange, ...; non-finite points are not drawn).
        ``caption``: text drawn onto the image. Midsagittal view only: ``trails``
        ``{label: (T, k, 2) mm}``, each point's last T positions (oldest first; the last
        is drawn as a dot when ``markers`` lacks the label) and ``time`` in seconds.
        Tract view only: ``tract``, the frame's panel (``acoustics.tract_panels``).
        """
        image, frame = self.render_gl(vertices, markers=markers)
        return self.finish_frame(image, frame, markers=markers, caption=caption,
                                 trails=trails, time=time, tract=tract)

    def render_gl(
        self, vertices: Float[Any, "v 3"], *, markers: Markers | None = None
    ) -> tuple[UInt8[np.ndarray, "h w 3"], Float[np.ndarray, "v 3"]]:
        """The first of :meth:`render`'s two steps: the OpenGL views of the grid.

        Returns ``(image, frame)``: a new (H, W, 3) uint8 image (the midsagittal cell and
        the caption not drawn yet) and the checked (V, 3) float64 vertices, both for
        :meth:`finish_frame`. Must run in the thread that made the renderer (the OpenGL
        context's)."""
        frame = _as_frame(vertices, self._n_vertices)
        self._set_layout("grid")
        return self._draw_gl(frame, markers), frame

    def finish_frame(
        self,
        image: UInt8[np.ndarray, "h w 3"],
        frame: Float[np.ndarray, "v 3"],
        *,
        markers: Markers | None = None,
        caption: str | None = None,
        trails: Mapping[str, Float[Any, "t k 2"]] | None = None,
        time: float | None = None,
        tract: Mapping[str, Any] | None = None,
    ) -> UInt8[np.ndarray, "h w 3"]:
        """The second of :meth:`render`'s steps, on :meth:`render_gl`'s ``(image,
        frame)``: the 2D views (midsagittal, tract) drawn into their cells and the caption
        into its band, in place (``image`` is returned).
        numpy and Pillow only, no OpenGL: it may run in another thread while the next
        frame's OpenGL views are drawn (one thread at a time), and gives the same bytes
        as :meth:`render`."""
        self._draw_section(image, frame, markers, trails, time)
        if self._tract_box is not None:
            draw_tract(image, self._tract_box, tract)
        return add_caption(image, caption, in_place=True) if caption else image

    def render_frames(
        self, work: Iterable[tuple[Float[Any, "v 3"], Mapping[str, Any]]]
    ) -> Iterator[UInt8[np.ndarray, "h w 3"]]:
        """``render(vertices, **keywords)`` of each ``(vertices, keywords)`` of ``work``,
        in order, the same bytes, pipelined: frame k + 1's OpenGL views are drawn (vertex
        upload and processing, here) before frame k's pixels are read back and finished
        (midsagittal view, caption), so that llvmpipe's raster threads draw frame k while
        this thread works on its neighbours instead of waiting for them. Must run in the
        thread that made the renderer; one frame is drawn ahead of the one yielded."""
        from . import _draw

        pending = None
        try:
            for vertices, kwargs in work:
                frame = _as_frame(vertices, self._n_vertices)
                self._set_layout("grid")
                if not self._placements or not self._submit(_draw, frame, kwargs):
                    if pending is not None:  # (only on the first frame: no framebuffers)
                        yield self._finish_pending(_draw, *pending)
                        pending = None
                    yield self.render(vertices, **kwargs)
                    continue
                if pending is not None:
                    yield self._finish_pending(_draw, *pending)
                pending = (frame, kwargs)
            if pending is not None:
                frame_kwargs, pending = pending, None
                yield self._finish_pending(_draw, *frame_kwargs)
        finally:  # stopped early (or failed): frames drawn and not read are dropped
            if self._gl is not None:
                _draw.drop_frames(self._gl)

    def _submit(self, _draw, frame, kwargs) -> bool:
        """Upload and draw ``frame``'s OpenGL views without reading them back; False
        (nothing drawn) where the platform cannot (see :func:`_draw.draw_frame`)."""
        self._upload(frame)
        self._set_markers(kwargs.get("markers"))
        return _draw.draw_frame(self._gl, self._scene)

    def _finish_pending(self, _draw, frame, kwargs) -> UInt8[np.ndarray, "h w 3"]:
        image = _draw.read_frame(self._gl)
        return self.finish_frame(image, frame, markers=kwargs.get("markers"),
                                 caption=kwargs.get("caption"), trails=kwargs.get("trails"),
                                 time=kwargs.get("time"), tract=kwargs.get("tract"))

    def set_traces(self, traces: Mapping[str, Float[Any, "n 2"] | None] | None) -> None:
        """Replace the midsagittal view's fixed traces (``{name: (n, 2) mm}``, model frame)."""
        if self._section is not None:
            self._section.set_traces(traces)

    def _draw_gl(self, frame, markers) -> np.ndarray:
        """The OpenGL views of the current layout (skipped if it holds none)."""
        if not self._placements:  # the midsagittal view alone: no OpenGL work
            width, height = self.size
            return np.full((height, width, 3), self._background, np.uint8)
        self._upload(frame)
        self._set_markers(markers)
        return self._draw()

    def _draw_section(self, image, frame, markers, trails, time) -> None:
        if self._section is None or self._section_box is None:
            return
        points = None
        if markers is not None:
            points = {k: _marker_points(v)[:, :2] for k, v in markers.items()}
        self._section.draw(
            image, self._section_box, frame, colours=self._colours, markers=points,
            trails=trails, time=time,
        )  # fmt: skip

    def render_views(
        self,
        vertices: Float[Any, "v 3"],
        *,
        markers: Markers | None = None,
        trails: Mapping[str, Float[Any, "t k 2"]] | None = None,
        time: float | None = None,
        tract: Mapping[str, Any] | None = None,
    ) -> dict[str, UInt8[np.ndarray, "h w 3"]]:
        """Each view alone, filling the whole image: ``{view: (H, W, 3) uint8}``."""
        frame = _as_frame(vertices, self._n_vertices)
        out = {}
        for view in self.views:
            self._set_layout(view)
            out[view] = self._draw_gl(frame, markers)
            self._draw_section(out[view], frame, markers, trails, time)
            if self._tract_box is not None:
                draw_tract(out[view], self._tract_box, tract)
        return out

    def close(self) -> None:
        """Release the OpenGL context (idempotent)."""
        offscreen, self._gl = getattr(self, "_gl", None), None
        if offscreen is not None:
            from . import _draw

            _draw.release(offscreen)

    def __del__(self):  # an unclosed renderer must not eglTerminate the shared display
        try:
            self.close()
        except Exception:
            pass

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc: object) -> bool:
        self.close()
        return False


def _fit_view(pieces, view, rest):
    """(R (3,3), mid (3,), lo (3,), extent (3,)) of ``view``'s visible rest geometry."""
    idx = np.unique(np.concatenate(
        [p.vertex_index for p in pieces if view in p.views] or [np.arange(len(rest))]
    ))  # fmt: skip
    rotation = np.asarray(_VIEW_AXES[view], float)
    q = rest[idx] @ rotation.T
    lo, hi = q.min(axis=0), q.max(axis=0)
    return rotation, (lo + hi) / 2, lo, np.maximum(hi - lo, 1e-9 * (1 + np.abs(hi)))


def view_cameras(model: MeshModel, views: Sequence[str] = PAPER_VIEWS,
                 skin: str = "cut") -> dict[str, dict[str, Any]]:
    """How a :class:`Renderer` frames each of ``views`` (numpy only, no OpenGL), for
    drawing the same views elsewhere (the one-file viewer): per view, ``right``, ``up``
    and ``toward`` (the camera) as model-frame unit vectors, ``centre`` (3,) mm of the
    visible rest geometry and its ``extent`` (width, height) mm on screen; with
    ``margin_mm`` (kept free around the bounds) and ``margin`` (the default fraction of
    the image kept free on each side): the scale is
    ``min(W / (width + 2 margin_mm), H / (height + 2 margin_mm)) * (1 - 2 margin)``."""
    rest, faces, face_material, materials = _model_arrays(model)
    views = tuple(v for v in views if v not in _FLAT_VIEWS)
    drawn, drawn_materials = _with_mouth_wall(
        faces, face_material, materials, getattr(model, "regions", None)
    )
    pieces = _split_pieces(rest, faces, drawn, drawn_materials, views, skin, True,
                           fields=getattr(model, "fields", None))  # fmt: skip
    out: dict[str, dict[str, Any]] = {"margin_mm": _MARGIN_MM, "margin": 0.06}
    for view in views:
        rotation, mid, _, extent = _fit_view(pieces, view, rest)
        out[view] = {"right": rotation[0].tolist(), "up": rotation[1].tolist(),
                     "toward": rotation[2].tolist(), "centre": (rotation.T @ mid).tolist(),
                     "extent": extent[:2].tolist()}  # fmt: skip
    return out


def _check_options(size, views, skin, background) -> tuple[tuple[int, int], tuple, str]:
    """The checked (size, views, skin); one clear error per bad option (a bad view or skin
    name is an :class:`~cassi_fit.errors.InvalidChoiceError`)."""
    try:
        width, height = (int(s) for s in size)
    except (TypeError, ValueError):
        raise CassiError(f"render: size must be (width, height), got {size!r}") from None
    if width < 8 or height < 8:
        raise CassiError(f"render: size must be at least 8x8 pixels, got {width}x{height}")
    views = (views,) if isinstance(views, str) else tuple(views)
    for view in views:
        check_choice("view", view, ALL_VIEWS)
    if not views or len(set(views)) != len(views):
        raise CassiError(f"render: views must be distinct names from {ALL_VIEWS}, got {views}")
    check_choice("skin", skin, SKINS)
    if len(background) != 3:
        raise CassiError(f"render: background must be an RGB triple, got {background!r}")
    return (width, height), views, skin
