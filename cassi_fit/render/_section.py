"""The ``midsagittal`` view: the posed mesh cut at z = 0 and drawn as 2D section contours,
as MRI and X-ray microbeam tracings show the vocal tract (numpy and Pillow; no OpenGL).

What is drawn, back to front:

- the subject's traces: the hard-palate trace (PAL.DAT) and the rear pharyngeal wall
  (PHA.DAT), in the model frame (pellet-frame mm times the subject's scale), as thick
  grey lines: the fixed walls the tongue moves against;
- the lower jaw, schematically: there is no mandible bone in the model, so its outline
  (incisor root, chin, lower border, angle, ramus up to the condyle at the model's jaw
  pivot) is built once from the rest model's landmarks and moved in every frame with the
  rigid motion of the lower teeth (a 2D Procrustes fit of the posed ``lower_teeth``
  vertices to their rest places). As on a cephalometric tracing it is a projection of the
  whole bone, dashed, not a section (the mandible's body leaves the midline behind the
  chin);
- the section of every material at z = 0, coloured by material: skin (face profile:
  nose, lips, chin, the throat), lips, teeth (the model's dental arch crosses the midline
  at the central incisors, so its section is the incisors' crowns, upper and lower, as
  X-ray tracings show them), tongue (filled where its section is closed), palate, and any
  material a newer model adds (velum, pharynx wall...), in its colour from
  ``MATERIAL_COLOURS`` or grey;
- the pellets: measured (red) with a trail of the last few frames, the model's sites
  (green) when given, and the time.

Cutting: a vertex lies on the camera side when ``z > Z_EPS`` (1e-6 mm). Cutting just off
the plane rather than at it keeps every crossing on a mesh edge shared by two triangles,
so the segments chain into the section's polylines (closed loops for closed surfaces)
even where the mesh has vertices exactly on the midline, as this model's do.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from jaxtyping import Float, Integer

from ..errors import CassiError

#: The view's name in ``options.VIEWS``.
SECTION_VIEW = "midsagittal"
NEAR_MM = 12.0  # triangles farther than this from the plane at rest are never cut
Z_EPS = 1e-6  # mm: the cut plane, just off z = 0 (see the module's docstring)
_BACKGROUND = (250, 250, 247)
_TRACE_COLOUR = (0.62, 0.62, 0.64)
_JAW_COLOUR = (0.55, 0.50, 0.42)
_LINE_DARKEN = {"teeth": (0.55, 0.53, 0.45), "eye": (0.5, 0.5, 0.5)}
_FILLED = {"tongue", "teeth"}  # closed sections filled (light) under their outline
_DRAW_ORDER = ("skin", "lips", "palate", "teeth", "tongue")  # others after, in model order
# Parts that set the view's window (mm margin around their rest section and the traces).
_WINDOW_MATERIALS = ("tongue", "palate", "teeth", "lips", "velum", "soft_palate", "pharynx")
_WINDOW_MARGIN_MM = 8.0
_JAW_DROP_MM = 12.0  # more room below: the chin and lower teeth drop as the jaw opens


def section_segments(
    vertices: Float[Any, "v 3"], faces: Integer[Any, "f 3"], z: float = 0.0
) -> tuple[Float[np.ndarray, "s 2 2"], Integer[np.ndarray, "s 2"]]:
    """The triangles' intersection with the plane ``z`` (+ 1e-6 mm), as 2D segments.

    Returns ``segments (s, 2, 2)`` mm, the (x, y) of each segment's two ends, and
    ``edges (s, 2)``: for each end, the key ``min(i, j) * V + max(i, j)`` of the mesh edge
    (i, j) it lies on, by which neighbouring segments are chained (:func:`section_polylines`).
    Triangles wholly on one side give nothing.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    side = v[:, 2] > z + Z_EPS
    s = side[f]  # (F, 3)
    crossing = s.any(axis=1) & ~s.all(axis=1)
    f = f[crossing]
    if not len(f):
        return np.zeros((0, 2, 2)), np.zeros((0, 2), np.int64)
    a, b = f, np.roll(f, -1, axis=1)  # edges (0,1), (1,2), (2,0)
    cut = side[a] != side[b]  # exactly two per crossing triangle
    za, zb = v[a, 2], v[b, 2]
    denom = np.where(cut, zb - za, 1.0)
    t = np.clip((z + Z_EPS - za) / denom, 0.0, 1.0)
    points = v[a, :2] + t[..., None] * (v[b, :2] - v[a, :2])  # (F, 3, 2)
    keys = np.minimum(a, b) * len(v) + np.maximum(a, b)
    order = np.argsort(~cut, axis=1, kind="stable")[:, :2]  # the two cut edges, in order
    rows = np.arange(len(f))[:, None]
    return points[rows, order], keys[rows, order]


def section_polylines(
    segments: Float[Any, "s 2 2"], edges: Integer[Any, "s 2"]
) -> list[tuple[Float[np.ndarray, "n 2"], bool]]:
    """Chain segments that share a mesh edge into polylines: ``[(points (n, 2), closed)]``.

    A closed surface cut by the plane gives closed loops (the first point not repeated);
    an open sheet (the palate, a skin edge) gives open polylines; a non-manifold edge
    just starts a new piece.
    """
    seg = np.asarray(segments, dtype=np.float64)
    ends = np.asarray(edges, dtype=np.int64)
    point_of = {}
    for k in range(len(seg)):
        for e in (0, 1):
            point_of.setdefault(int(ends[k, e]), seg[k, e])
    return [
        (np.array([point_of[n] for n in nodes]).reshape(-1, 2), closed)
        for nodes, closed in _chains(ends)
    ]


def _chains(ends: np.ndarray) -> list[tuple[list[int], bool]]:
    """The chains of segments ``ends (s, 2)`` (node keys) through shared nodes:
    ``[(node keys in order, closed)]``; a closed chain does not repeat its first node."""
    touching: dict[int, list[int]] = {}
    pairs = ends.tolist()
    for k, (p, q) in enumerate(pairs):
        touching.setdefault(p, []).append(k)
        touching.setdefault(q, []).append(k)
    used = [False] * len(pairs)

    def walk(end: int) -> list[int]:
        nodes = []
        while True:
            nxt = next((j for j in touching[end] if not used[j]), None)
            if nxt is None:
                return nodes
            used[nxt] = True
            p, q = pairs[nxt]
            end = q if p == end else p
            nodes.append(end)

    out = []
    for k, (start, end) in enumerate(pairs):
        if used[k]:
            continue
        used[k] = True
        forward = walk(end)
        nodes = [start, end, *forward]
        if len(nodes) > 3 and nodes[-1] == start:
            out.append((nodes[:-1], True))
            continue
        out.append((walk(start)[::-1] + nodes, False))
    return out


def _procrustes_2d(rest: np.ndarray, posed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (2,2), t (2,)) minimising |R rest + t - posed|: the rigid motion of a point set."""
    mr, mp = rest.mean(axis=0), posed.mean(axis=0)
    u, _, vt = np.linalg.svd((posed - mp).T @ (rest - mr))
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    r = u @ np.diag([1.0, d]) @ vt
    return r, mp - r @ mr


def _jaw_outline(rest: np.ndarray, landmarks: Mapping, measures: Mapping) -> list | None:
    """The schematic lower jaw at rest: two polylines (n, 2) mm, a projection as on a
    cephalometric tracing, or None if the model lacks the landmarks.

    The outer outline runs from the condyle (the model's jaw pivot) down the back of the
    ramus to the angle (the skin gonion's (x, y) moved 6 mm forward and 8 mm up), along
    the lower border to menton (the skin gnathion raised by 7 mm, about the midline
    soft-tissue depth there, Rhine & Moore 1984) and up the chin's front (pogonion, the
    B-point concavity) to the lower incisor's neck; the second line is the ramus's front
    edge, from the sigmoid notch over the coronoid process down to behind the last molar.
    Schematic: placed by these landmarks, not measured bone.
    """
    try:
        tip = rest[landmarks["lower_incisor_tip"], :2]
        gnathion = rest[landmarks["gnathion"], :2]
        gonion = rest[landmarks["gonion"], :2]
        condyle = np.array([measures["jaw_pivot_x"], measures["jaw_pivot_y"]], float)
    except (KeyError, IndexError, TypeError):
        return None
    menton = gnathion + (-4.0, 7.0)
    angle = gonion + (6.0, 8.0)
    pogonion = np.array([tip[0] + 2.0, menton[1] + 7.0])
    b_point = tip + (-3.0, -20.0)
    neck = tip + (-1.0, -10.5)
    lowest = menton + 0.5 * (angle - menton) + (0.0, -2.0)
    outer = np.array([condyle, condyle + (3.0, -25.0), angle + (-2.0, 6.0), angle,
                      angle + (6.0, -5.0), lowest, menton + (-2.0, 0.0), menton,
                      pogonion, b_point, neck])  # fmt: skip
    retromolar = np.array([condyle[0] + 45.0, tip[1] - 8.0])
    front = np.array([condyle + (14.0, -12.0), condyle + (26.0, -3.0),
                      condyle + (29.0, -14.0), retromolar])  # fmt: skip
    return [outer, front]


class Section:
    """The midsagittal section of one face model, ready to draw frame after frame.

    Built once from the rest model (faces by material, the window, the schematic jaw);
    :meth:`contours` cuts one frame's posed vertices; :meth:`draw` rasterises the view
    into an image cell. ``traces``: ``{"palate": (n, 2), "pharynx": (m, 2)}`` mm in the
    model frame (other names are drawn alike); set with :meth:`set_traces`.
    """

    def __init__(
        self,
        rest: Float[Any, "v 3"],
        faces: Integer[Any, "f 3"],
        face_material: Integer[Any, " f"],
        materials: Sequence[str],
        *,
        regions: Mapping[str, Any] | None = None,
        landmarks: Mapping[str, int] | None = None,
        measures: Mapping[str, float] | None = None,
        traces: Mapping[str, Any] | None = None,
    ) -> None:
        self.rest = np.asarray(rest, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        face_material = np.asarray(face_material, dtype=np.int64)
        materials = tuple(materials)
        order = [m for m in _DRAW_ORDER if m in materials]
        order += [m for m in materials if m not in order]
        # Only triangles within NEAR_MM of the plane at rest can be cut in a frame (the
        # animation moves vertices in x and y, and across z only by the widths' scaling).
        z = self.rest[self.faces, 2]
        near = (z.min(axis=1) < NEAR_MM) & (z.max(axis=1) > -NEAR_MM)
        # the mouth's walls keep the background out of the rendered open mouth; they are
        # no anatomy, and a tracing does not show them
        wall = np.zeros(len(self.rest), bool)
        wall[np.asarray((regions or {}).get("mouth_wall", ()), dtype=np.int64)] = True
        near &= ~wall[self.faces].all(axis=1)
        self.parts = {
            name: self.faces[near & (face_material == materials.index(name))]
            for name in order
            if np.any(near & (face_material == materials.index(name)))
        }
        self._near = np.unique(np.concatenate([f.ravel() for f in self.parts.values()] or
                                              [np.zeros(0, np.int64)]))  # fmt: skip
        self._topologies: dict[bytes, tuple] = {}
        regions = regions or {}
        lower = np.asarray(regions.get("lower_teeth", ()), dtype=np.int64)
        self._lower = lower if lower.size >= 3 else None
        self._jaw = _jaw_outline(self.rest, landmarks or {}, measures or {})
        if self._lower is None:
            self._jaw = None
        self.traces: dict[str, np.ndarray] = {}
        self.set_traces(traces)

    def set_traces(self, traces: Mapping[str, Any] | None) -> None:
        """Replace the fixed traces (``{name: (n, 2) mm}``, None values skipped)."""
        out = {}
        for name, points in (traces or {}).items():
            if points is None:
                continue
            p = np.asarray(points, dtype=np.float64)
            if p.ndim != 2 or p.shape[1] < 2:
                raise CassiError(f"render: the {name} trace must be (n, 2) mm, got {p.shape}")
            p = p[:, :2][np.all(np.isfinite(p[:, :2]), axis=1)]
            if len(p) >= 2:
                out[str(name)] = p
        self.traces = out
        self._window = None
        self._base = None

    def window(self) -> tuple[Float[np.ndarray, "2"], Float[np.ndarray, "2"]]:
        """(lo, hi) (x, y) mm of the view: the rest section of tongue, palate, teeth and
        lips with the traces and the schematic jaw, plus a margin (the whole rest section
        if none of those exist). Fixed for the model, so a video does not jump."""
        if self._window is None:
            self._window = self._fit_window()
        return self._window

    def _fit_window(self):
        points = [
            pts
            for name in _WINDOW_MATERIALS
            if name in self.parts
            for pts, _ in section_polylines(*section_segments(self.rest, self.parts[name]))
        ]
        points += list(self.traces.values())
        if self._jaw is not None:
            points += self._jaw
        if not points:
            points = [section_segments(self.rest, self.faces)[0].reshape(-1, 2)]
        p = np.concatenate(points)
        if not len(p):
            p = self.rest[:, :2]
        lo, hi = p.min(axis=0) - _WINDOW_MARGIN_MM, p.max(axis=0) + _WINDOW_MARGIN_MM
        return lo - (0.0, _JAW_DROP_MM), hi

    def contours(self, vertices: Float[Any, "v 3"], transform=None) -> dict[str, list]:
        """``{material: [(points (n, 2) mm, closed)]}`` of one posed frame, plus ``"jaw"``:
        the schematic lower jaw moved with the lower teeth (if the model allows it).
        ``transform``: a function of (n, 2) points applied to every point (to pixels),
        once for all the section's points."""
        v = np.asarray(vertices, dtype=np.float64)
        edges, chains = self._topology(v[self._near, 2] > Z_EPS)
        za, zb = v[edges[:, 0], 2], v[edges[:, 1], 2]
        t = np.clip((Z_EPS - za) / np.where(zb != za, zb - za, 1.0), 0.0, 1.0)
        nodes = v[edges[:, 0], :2] + t[:, None] * (v[edges[:, 1], :2] - v[edges[:, 0], :2])
        if transform is not None:
            nodes = transform(nodes)
        out = {name: [(nodes[index], closed) for index, closed in lines]
               for name, lines in chains.items()}  # fmt: skip
        if self._jaw is not None:
            r, t = _procrustes_2d(self.rest[self._lower, :2], v[self._lower, :2])
            out["jaw"] = [(line @ r.T + t if transform is None else transform(line @ r.T + t),
                           False) for line in self._jaw]
        return out

    def _topology(self, side: np.ndarray):
        """(edges (e, 2) vertex pairs cut by the plane, {material: [(node index array,
        closed)]}) for this pattern of vertex sides; kept for the last few patterns (the
        chaining is the slow part, and the pattern rarely changes from frame to frame:
        speech moves the vertices little across the midline)."""
        key = side.tobytes()
        hit = self._topologies.get(key)
        if hit is not None:
            return hit
        n = len(self.rest)
        every, chains = [], {}
        for name, faces in self.parts.items():
            _, ends = section_segments(np.where(self._side_z(side)[:, None], 1.0, -1.0)
                                       * np.array([0.0, 0.0, 1.0]), faces)  # fmt: skip
            chains[name] = [(np.asarray(nodes), closed) for nodes, closed in _chains(ends)]
            every.append(ends.ravel())
        keys = np.unique(np.concatenate(every)) if every else np.zeros(0, np.int64)
        edges = np.stack([keys // n, keys % n], axis=1)
        for name, lines in chains.items():
            chains[name] = [(np.searchsorted(keys, nodes), closed) for nodes, closed in lines]
        if len(self._topologies) >= 8:
            self._topologies.pop(next(iter(self._topologies)))
        self._topologies[key] = (edges, chains)
        return edges, chains

    def _side_z(self, side: np.ndarray) -> np.ndarray:
        """Every vertex's side (V,) from the near vertices' ``side``; far vertices keep
        their rest side."""
        out = self.rest[:, 2] > Z_EPS
        out[self._near] = side
        return out

    def draw(
        self,
        image: np.ndarray,
        box: tuple[int, int, int, int],
        vertices: Float[Any, "v 3"],
        *,
        colours: Mapping[str, Any],
        markers: Mapping[str, Any] | None = None,
        trails: Mapping[str, Any] | None = None,
        time: float | None = None,
    ) -> None:
        """Draw the view into ``image[top:bottom, left:right]`` (``box`` = left, top, right,
        bottom in pixels), in place. ``markers``: ``{label: (k, 2|3) mm}`` points;
        ``trails``: ``{label: (T, k, 2) mm}`` the last T positions of each point (oldest
        first); ``time``: seconds, written in the cell's corner."""
        from PIL import Image, ImageDraw

        from ._images import _font

        left, top, right, bottom = box
        w, h = right - left, bottom - top
        if w < 4 or h < 4:
            return
        lo, hi = self.window()
        scale = min(w / (hi[0] - lo[0]), h / (hi[1] - lo[1]))
        mid = (lo + hi) / 2

        factor, offset = np.array([scale, -scale]), np.array([w / 2, h / 2])

        def to_px(p: np.ndarray) -> np.ndarray:
            """Model mm (..., 2) float64 -> pixels (..., 2)."""
            return (p - mid) * factor + offset

        def px(points) -> list[float]:
            """Model mm (n, 2+) -> the flat pixel list [x0, y0, x1, y1, ...] PIL takes."""
            return to_px(np.asarray(points, dtype=np.float64)[:, :2]).ravel().tolist()

        line = max(1, round(min(w, h) / 180))
        key = (w, h, id(self._window))
        if self._base is None or self._base[0] != key:  # background and traces: drawn once
            base = Image.new("RGB", (w, h), _BACKGROUND)
            ink = ImageDraw.Draw(base)
            for points in self.traces.values():
                # wide, under the model: a grey band that shows beside the model's own
                # outline where they coincide (the model's palate is built from PAL.DAT)
                ink.line(px(points), fill=_rgb(_TRACE_COLOUR), width=5 * line, joint="curve")
            self._base = (key, base)
        pil = self._base[1].copy()
        draw = ImageDraw.Draw(pil)
        self._draw_contours(draw, to_px, line, vertices, colours)
        self._draw_points(draw, to_px, px, line, markers or {}, trails or {})
        if time is not None:
            draw.text((4 * line, 3 * line), f"t = {float(time):.3f} s", fill=(40, 40, 40),
                      font=_font(max(10, h // 18)))  # fmt: skip
        image[top:bottom, left:right] = np.asarray(pil)

    def _draw_contours(self, draw, to_px, line: int, vertices,
                       colours: Mapping[str, Any]) -> None:
        """The parts' outlines in the plane (filled where closed), the jaw's dashed."""
        contours = self.contours(vertices, transform=to_px)  # in pixels
        jaw = contours.pop("jaw", ())
        for points, _ in jaw:
            _dashed(draw, points, _rgb(_JAW_COLOUR), line, dash=max(4, 5 * line))
        for name, lines in contours.items():
            ink, fill = _inks(name, tuple(colours.get(name, (0.6, 0.6, 0.6))))
            for points, closed in lines:
                xy = points.ravel().tolist()
                if closed and fill is not None and len(xy) >= 6:
                    draw.polygon(xy, fill=fill)
                _line(draw, xy + (xy[:2] if closed else []), ink, 2 * line,
                      joint="curve" if line > 1 else None)

    @staticmethod
    def _draw_points(draw, to_px, px, line: int, markers: Mapping[str, Any],
                     trails: Mapping[str, Any]) -> None:
        """Each label's trail (faded) and its points: the model's sites as rings, under
        the data's filled dots."""
        from ._pieces import _EXTRA_MARKER_COLOURS, MARKER_COLOURS

        labels = sorted(dict.fromkeys([*trails, *markers]), key=lambda name: name != "model")
        for i, label in enumerate(labels):
            colour = MARKER_COLOURS.get(label, _EXTRA_MARKER_COLOURS[i % 3])
            trail = np.asarray(trails.get(label, np.zeros((0, 0, 2))), np.float64)
            if trail.ndim == 3 and trail.shape[0] >= 2:
                faded = _rgb(tuple(0.45 * c + 0.55 * b / 255 for c, b in zip(colour, _BACKGROUND,
                                                                                 strict=True)))
                paths = to_px(trail[:, :, :2])  # (T, k, 2) pixels
                finite = np.all(np.isfinite(trail[:, :, :2]), axis=2)
                for k in range(trail.shape[1]):
                    path = paths[finite[:, k], k]
                    if len(path) >= 2:
                        _line(draw, path.ravel().tolist(), faded, 2 * line)
            points = markers.get(label)
            if points is None and trail.ndim == 3 and len(trail):
                points = trail[-1]
            if points is None:
                continue
            p = np.asarray(points, np.float64).reshape(-1, np.shape(points)[-1])[:, :2]
            r = 2.5 * line + 1
            flat = px(p[np.all(np.isfinite(p), axis=1)])
            for x, y in zip(flat[::2], flat[1::2], strict=True):
                if label == "model":  # the model's sites: rings, the data stays on top
                    draw.ellipse((x - r - line, y - r - line, x + r + line, y + r + line),
                                 outline=_rgb(colour), width=max(1, line))  # fmt: skip
                else:
                    draw.ellipse((x - r, y - r, x + r, y + r), fill=_rgb(colour))


@functools.lru_cache(maxsize=64)
def _inks(name: str, colour: tuple) -> tuple[tuple, tuple | None]:
    """(line colour, fill colour or None) of a material, as 0-255 RGB."""
    ink = _rgb(_LINE_DARKEN.get(name, tuple(0.72 * c for c in colour)))
    fill = _rgb(tuple(0.55 + 0.45 * c for c in colour)) if name in _FILLED else None
    return ink, fill


def _rgb(colour) -> tuple[int, int, int]:
    return tuple(int(round(255 * min(max(float(c), 0.0), 1.0))) for c in colour)


def _line(draw, xy: list, fill, width: int, joint: str | None = None) -> None:
    """``draw.line(xy, fill, width, joint)``, the same pixels; without a joint straight to
    Pillow's core with the colour's ink looked up once (a frame draws a hundred lines)."""
    if joint is not None:
        draw.line(xy, fill=fill, width=width, joint=joint)
        return
    inks = draw.__dict__.setdefault("_cassi_inks", {})
    ink = inks.get(fill)
    if ink is None:
        ink = inks[fill] = draw._getink(fill)[0]
    if width != 0:
        draw.draw.draw_lines(xy, ink, width)


def _dashed(draw, xy, fill, width: int, dash: float) -> None:
    """A dashed polyline: ``dash`` pixels drawn, ``dash`` skipped, along the path (each
    dash straight from its start to its end). ``xy``: (n, 2) pixels or the flat list."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if len(p) < 2:
        return
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    marks = np.arange(0.0, s[-1], dash)
    q = np.stack([np.interp(marks, s, p[:, 0]), np.interp(marks, s, p[:, 1])], axis=1).tolist()
    for a, b in zip(q[::2], q[1::2], strict=False):
        _line(draw, (*a, *b), fill, width)


def midsagittal_figure(
    model: Any,
    vertices: Float[Any, "v 3"],
    *,
    traces: Mapping[str, Float[Any, "n 2"] | None] | None = None,
    pellets: Float[Any, "k 2"] | None = None,
    trail: Float[Any, "t k 2"] | None = None,
    time: float | None = None,
    ax: Any = None,
) -> Any:
    """The midsagittal view of one frame as a matplotlib figure (for notebooks and papers).

    ``model``: a :class:`~cassi_fit.FaceModel` (or anything with ``vertices``, ``faces``,
    ``face_material`` and optionally ``regions``, ``landmarks``, ``measures``);
    ``vertices (V, 3)`` mm: the posed frame (e.g. ``animation.vertices[k]``); ``traces``:
    ``{"palate": (n, 2), "pharynx": (m, 2)}`` mm in the model frame
    (``recording_video.subject_traces(recording, state.scale)``); ``pellets (k, 2)`` mm and
    ``trail (T, k, 2)`` mm (the last T positions, oldest first); ``time`` in seconds for
    the title; ``ax``: draw into these axes instead of a new figure. Returns the figure.
    Lines carry the part's name as their label (``"tongue"``, ``"palate trace"``,
    ``"jaw (schematic)"``...), so a legend names them.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    from ._pieces import MARKER_COLOURS, MATERIAL_COLOURS, _model_arrays

    rest, faces, face_material, materials = _model_arrays(model)
    section = Section(
        rest, faces, face_material, materials, regions=getattr(model, "regions", None),
        landmarks=getattr(model, "landmarks", None), measures=getattr(model, "measures", None),
        traces=traces,
    )  # fmt: skip
    v = np.asarray(vertices, dtype=np.float64)
    if v.shape != rest.shape or not np.all(np.isfinite(v)):
        raise CassiError(f"midsagittal_figure: vertices must be finite {rest.shape}, got {v.shape}")
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 5))
    else:
        fig = ax.figure
    for name, points in section.traces.items():
        ax.plot(*points.T, color=_TRACE_COLOUR, lw=5, label=f"{name} trace",
                solid_capstyle="round")  # fmt: skip
    contours = section.contours(v)
    for k, (points, _) in enumerate(contours.pop("jaw", ())):
        ax.plot(*points.T, ls="--", lw=1, color=_JAW_COLOUR,
                label="jaw (schematic)" if k == 0 else "_nolegend_")  # fmt: skip
    for name, lines in contours.items():
        colour = MATERIAL_COLOURS.get(name, (0.6, 0.6, 0.6))
        ink = _LINE_DARKEN.get(name, tuple(0.72 * c for c in colour))
        for k, (points, closed) in enumerate(lines):
            if closed and name in _FILLED and len(points) >= 3:
                ax.add_patch(Polygon(points, closed=True, lw=0,
                                     fc=tuple(0.55 + 0.45 * c for c in colour)))  # fmt: skip
            xy = np.vstack([points, points[:1]]) if closed else points
            ax.plot(*xy.T, color=ink, lw=1.8, label=name if k == 0 else "_nolegend_")
    red = MARKER_COLOURS["measured"]
    if trail is not None:
        t = np.asarray(trail, dtype=np.float64)
        for k in range(t.shape[1]):
            ax.plot(*t[:, k, :2].T, color=red, alpha=0.35, lw=2,
                    label="pellet trails" if k == 0 else "_nolegend_")  # fmt: skip
    if pellets is not None:
        p = np.asarray(pellets, dtype=np.float64).reshape(-1, 2)
        ax.plot(*p.T, "o", color=red, ms=6, label="pellets")
    lo, hi = section.window()
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm, front)")
    ax.set_ylabel("y (mm, up)")
    ax.set_title("midsagittal section" + ("" if time is None else f", t = {float(time):.3f} s"))
    return fig
