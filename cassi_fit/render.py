"""Offscreen rendering of the face model in the paper's four evaluation views.

The paper judged every animation from four views (Scheidt & Hamilton 1999, section 4):
``front`` (the full face), ``side`` (the full face in profile, looking to the right of the
image), ``inside`` (half the face from the side: skin, lips, teeth and palate on the
camera's side of the midsagittal plane z = 0 cut away, or the skin see-through, so that
tongue, teeth and palate show) and ``top`` (skin hidden: palate, teeth and tongue seen from
above, the front of the mouth to the right). Singly, in a row, or as a 2x2 grid (front,
side / inside, top); pellet markers in the side and inside views; a caption.

Speed (llvmpipe, the software OpenGL of headless machines, is the target):

- The whole grid is ONE draw of ONE pyrender scene. Every material is split once into the
  triangles on either side of the midsagittal plane; each piece is one pyrender primitive
  drawn *instanced*, one instance per view that shows it. An instance matrix places its
  view in its cell in front of one orthographic camera (and carries the cell, to which
  the vertex shader clips). The lights live in the shader, fixed to the camera, so every
  view is lit alike.
- Per frame only the vertex buffers are rewritten in place (``glBufferSubData``).
- pyrender's scene, buffers and context are kept; its PBR shading (lights re-bound in
  Python for every draw), 4x multisampling and depth read-back are replaced by a light
  two-sided shader, a plain framebuffer and an RGB read into a kept buffer.
- Back faces are culled wherever no view can show them (materials with a clear winding,
  away from the cut).

Geometry is in the model frame (mm): x front, y up, z to the subject's left, z = 0
midsagittal (docs/ARCHITECTURE.md). Cameras are fitted once to the rest mesh with a
margin, so a video does not jump.
"""

from __future__ import annotations

import functools
import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from ._io import atomic_write
from .errors import CassiError, RenderingUnavailableError

VIEWS = ("front", "side", "inside", "top")

# The face model's material order (cassi_fit.face_model.MATERIALS); repeated here so that
# rendering does not import JAX.
_MATERIALS = ("skin", "lips", "eye", "teeth", "tongue", "palate")

# sRGB colours. The paper draws the palate as the darkest object.
MATERIAL_COLOURS = {
    "skin": (0.89, 0.72, 0.60),
    "lips": (0.70, 0.30, 0.30),
    "eye": (0.96, 0.96, 0.94),
    "teeth": (0.96, 0.94, 0.86),
    "tongue": (0.93, 0.52, 0.58),
    "palate": (0.42, 0.17, 0.20),
}
MARKER_COLOURS = {"measured": (0.90, 0.08, 0.08), "model": (0.10, 0.72, 0.22)}
_EXTRA_MARKER_COLOURS = ((0.15, 0.35, 0.95), (0.98, 0.60, 0.05), (0.60, 0.20, 0.80))
_IRIS_COLOUR = (0.25, 0.17, 0.10)

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
    "front": set(_MATERIALS),
    "side": set(_MATERIALS),
    "inside": set(_MATERIALS) - {"eye"},  # an eyeball floating in the cut head distracts
    "top": {"teeth", "tongue", "palate"},
}
_CUT = {"skin", "lips", "eye", "teeth", "palate"}  # near half removed in the inside view
_GLASS = {"skin", "lips", "eye"}  # near half see-through with skin="transparent"
_MARKER_VIEWS = ("side", "inside")
_MARGIN_MM = 10.0  # free space around each view's rest bounds, for the motion

# --------------------------------------------------------------------------------------
# headless OpenGL
# --------------------------------------------------------------------------------------

_PLATFORM: str | None = None  # the answer of ensure_headless_gl, cached per process

# Probes run in a fresh interpreter (PyOpenGL fixes its platform at first import). They
# create a context the way pyrender will (EGL: the first device's platform display) but
# import only PyOpenGL, not pyrender: about 0.1 s instead of 1 s.
_PROBES = {
    "egl": """
import ctypes, os
os.environ["PYOPENGL_PLATFORM"] = "egl"
from OpenGL import EGL
def ext(name, restype):
    address = EGL.eglGetProcAddress(name)
    if address is None:
        return None
    return ctypes.CFUNCTYPE(restype)(address)
query = ext("eglQueryDevicesEXT", EGL.EGLBoolean)
display = None
if query is not None:
    from OpenGL._opaque import opaque_pointer_cls
    device_type = opaque_pointer_cls("EGLDeviceEXT")
    n = EGL.EGLint()
    devices = (device_type * 8)()
    query.argtypes = [EGL.EGLint, ctypes.POINTER(device_type), ctypes.POINTER(EGL.EGLint)]
    if query(8, devices, ctypes.pointer(n)) and n.value > 0:
        get_display = ext("eglGetPlatformDisplayEXT", EGL.EGLDisplay)
        display = get_display(0x313F, devices[0], None)
if display is None:
    display = EGL.eglGetDisplay(EGL.EGL_DEFAULT_DISPLAY)
EGL.eglInitialize(display, None, None)
attrs = [EGL.EGL_SURFACE_TYPE, EGL.EGL_PBUFFER_BIT, EGL.EGL_RENDERABLE_TYPE,
         EGL.EGL_OPENGL_BIT, EGL.EGL_DEPTH_SIZE, 24, EGL.EGL_NONE]
config, n = EGL.EGLConfig(), EGL.EGLint()
ok = EGL.eglChooseConfig(display, (EGL.EGLint * len(attrs))(*attrs), ctypes.pointer(config),
                         1, ctypes.pointer(n))
assert ok and n.value > 0, "no EGL configuration with OpenGL and a depth buffer"
EGL.eglBindAPI(EGL.EGL_OPENGL_API)
context = EGL.eglCreateContext(display, config, EGL.EGL_NO_CONTEXT, None)
EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, context)
""",
    "osmesa": """
import os
os.environ["PYOPENGL_PLATFORM"] = "osmesa"
from OpenGL import osmesa
assert osmesa.OSMesaCreateContextExt(osmesa.OSMESA_RGBA, 24, 0, 0, None), "no OSMesa context"
""",
    "native": """
import os
os.environ.pop("PYOPENGL_PLATFORM", None)
import pyrender
pyrender.OffscreenRenderer(16, 16).delete()
""",
}


def _probe_platform(platform: str) -> str | None:
    """Try an offscreen context with ``platform`` in a fresh interpreter.

    PyOpenGL fixes its platform at first import, so each candidate is tried in its own
    process. Returns ``None`` if a context was created, else the reason (one line).
    """
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBES[platform]], capture_output=True, text=True, timeout=120
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"{type(exc).__name__}: {exc}"
    if proc.returncode == 0:
        return None
    lines = [ln.strip() for ln in proc.stderr.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else f"exit code {proc.returncode}"


def _imported_platform() -> str:
    """The platform of an already imported PyOpenGL, if pyrender can use it."""
    import OpenGL.platform

    name = type(OpenGL.platform.PLATFORM).__name__.lower()
    for platform in ("egl", "osmesa"):
        if name.startswith(platform):
            return platform
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return "native"
    raise RenderingUnavailableError(
        f"OpenGL was imported (platform {name}) before cassi_fit.render could choose a "
        "headless one: import cassi_fit.render first, or set PYOPENGL_PLATFORM=egl"
    )


def ensure_headless_gl() -> str:
    """Choose the OpenGL platform for offscreen rendering; returns its name.

    A ``PYOPENGL_PLATFORM`` set by the user is respected as is. Otherwise the candidates
    are, in order: the native window system (only if ``DISPLAY``/``WAYLAND_DISPLAY`` is
    set), ``"egl"`` (Mesa's llvmpipe works without a GPU), ``"osmesa"``. Each is probed in
    a subprocess; the first that creates a context is put in ``PYOPENGL_PLATFORM`` (before
    pyrender/OpenGL are imported here) and cached for the process. Raises
    :class:`RenderingUnavailableError` (one line) if none works.
    """
    global _PLATFORM
    if _PLATFORM is not None:
        return _PLATFORM
    chosen = os.environ.get("PYOPENGL_PLATFORM")
    if chosen:
        _PLATFORM = chosen
        return chosen
    if "OpenGL.platform" in sys.modules:  # too late to choose: PyOpenGL has its platform
        _PLATFORM = _imported_platform()
        return _PLATFORM
    candidates = ["egl", "osmesa"]
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        candidates.insert(0, "native")
    failures = []
    for platform in candidates:
        reason = _probe_platform(platform)
        if reason is None:
            if platform != "native":
                os.environ["PYOPENGL_PLATFORM"] = platform
            _PLATFORM = platform
            return platform
        failures.append(f"{platform} ({reason})")
    raise RenderingUnavailableError(
        f"no offscreen OpenGL: tried {'; '.join(failures)}. Install Mesa EGL (apt install "
        "libegl1 libgl1-mesa-dri) or OSMesa (libosmesa6), or set PYOPENGL_PLATFORM"
    )


# --------------------------------------------------------------------------------------
# geometry helpers (numpy, one frame)
# --------------------------------------------------------------------------------------


def _linear(srgb) -> tuple[float, ...]:
    """sRGB in [0, 1] -> linear (pyrender's shader applies gamma 1/2.2 on output)."""
    return tuple(float(c) ** 2.2 for c in srgb)


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray, incidence) -> np.ndarray:
    """Area-weighted unit vertex normals, (V,3) float32.

    ``incidence`` is the sparse (V,F) vertex-face matrix. A vertex whose summed normal is
    zero (only zero-area triangles) gets (0, 0, 0): the shader then lights it with ambient
    light only, instead of dividing by zero.
    """
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    summed = incidence @ np.cross(b - a, c - a)
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    out = np.zeros_like(summed)
    np.divide(summed, length, out=out, where=length > 0)
    return out.astype(np.float32)


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

    Grid: two columns (front, side / inside, top); one view fills the image. Not grid:
    one row.
    """
    width, height = size
    n = len(views)
    cols = 1 if n == 1 else (2 if grid else n)
    rows = -(-n // cols)
    cw, ch = width / cols, height / rows
    return {
        v: ((i % cols + 0.5) * cw, height - (i // cols + 0.5) * ch, cw, ch)
        for i, v in enumerate(views)
    }


def _iris_factors(vertices: np.ndarray, faces: np.ndarray, face_material, eye: int):
    """Per-vertex colour factor (V,4) darkening the front of each eyeball into an iris.

    Each eye is the set of 'eye' vertices on one side of z = 0; its iris is the front half
    (x above the eye's centre) within 62 % of the eye's half-height of the gaze axis (the
    +x line through the centre), whatever the eyeball's shape or tessellation. Returns
    None if the model has no eye material.
    """
    used = np.unique(faces[face_material == eye])
    if used.size == 0:
        return None
    factors = np.ones((len(vertices), 4))
    ratio = np.array(_linear(_IRIS_COLOUR)) / np.array(_linear(MATERIAL_COLOURS["eye"]))
    for side in (used[vertices[used, 2] > 0], used[vertices[used, 2] <= 0]):
        if side.size < 4:
            continue
        p = vertices[side]
        lo, hi = p.min(axis=0), p.max(axis=0)
        centre, half = (lo + hi) / 2, (hi[1] - lo[1]) / 2
        off_axis = np.hypot(p[:, 1] - centre[1], p[:, 2] - centre[2])
        iris = (p[:, 0] > centre[0]) & (off_axis < 0.62 * half)
        factors[side[iris], :3] = ratio
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
        self.buffer = np.zeros((len(vertex_index), 6 + static.shape[1]), np.float32)
        self.buffer[:, 6:] = static
        self.primitive = self.mesh = None


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
        if (glass and glass_here) or (not glass and not cut and not glass_here):
            out.append(v)
    return tuple(out)


def _winding(vertices: np.ndarray, faces: np.ndarray) -> int:
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


def _split_pieces(vertices, faces, face_material, materials, views, skin, cull) -> list[_Piece]:
    """Split the mesh by material and by side of the midsagittal plane (triangle centroid);
    "near" is the inside view's camera side.

    With ``cull``, a material with a clear winding hides its back faces wherever they
    cannot be seen, the far half of a cut material in the inside view (whose inside shows)
    being its own double-sided piece: back faces cost as much to rasterise as visible ones.
    """
    toward_camera = np.asarray(_VIEW_AXES["inside"][2], float)
    near_side = vertices[faces].mean(axis=1) @ toward_camera > 0
    eye = materials.index("eye") if "eye" in materials else -1
    iris = _iris_factors(vertices, faces, face_material, eye) if eye >= 0 else None
    pieces = []
    for m, name in enumerate(materials):
        face = _cull_face(_winding(vertices, faces[face_material == m])) if cull else None
        opened = name in _CUT and (skin == "cut" or name in _GLASS)  # inside shows at the cut
        for near in (False, True):
            for glass in (False, True):
                mask = (face_material == m) & (near_side == near)
                shown = _piece_views(name, near, glass, views, skin)
                if not mask.any() or not shown:
                    continue
                index, local = np.unique(faces[mask], return_inverse=True)
                static = (
                    iris[index] if (m == eye and iris is not None) else np.zeros((len(index), 0))
                )
                args = (name, near, glass, index, local.reshape(-1, 3), static)
                if face is None or glass:
                    pieces.append(_Piece(*args, shown))
                    continue
                if opened and not near and "inside" in shown:
                    pieces.append(_Piece(*args, ("inside",)))
                    shown = tuple(v for v in shown if v != "inside")
                if shown:
                    pieces.append(_Piece(*args, shown, cull=face))
    return pieces


# Shading, in the camera's frame (orthographic, looking along -z; the lights are fixed to
# the camera): ambient + a key light from the camera + a fill light from the upper left +
# a weak highlight, on linear colours, then gamma 1/2.2. Lighting is two-sided by view
# direction: a surface seen from behind (the inside of the cut skin) is lit as if it faced
# the camera, whatever the triangle winding. The instance matrices are similarities, so
# mat3(M * inst_m) transforms normals up to a scale that normalisation removes.
_VERTEX_SHADER = """#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
#if HAS_COLOUR
layout(location = 2) in vec4 color_0;
#endif
layout(location = INST_M_LOC) in mat4 inst_m;
uniform mat4 M;
uniform mat4 V;
uniform mat4 P;
out vec3 frag_normal;
out vec4 frag_colour;
void main() {
    // inst_m: an affine map whose bottom row carries the view's cell (x0, y0, x1, y1) in
    // image pixels (= world x, y); clip to it.
    vec4 cell = vec4(inst_m[0][3], inst_m[1][3], inst_m[2][3], inst_m[3][3]);
    mat4 affine = inst_m;
    affine[0][3] = 0.0; affine[1][3] = 0.0; affine[2][3] = 0.0; affine[3][3] = 1.0;
    mat4 model = M * affine;
    vec4 world = model * vec4(position, 1.0);
    gl_ClipDistance[0] = world.x - cell.x;
    gl_ClipDistance[1] = world.y - cell.y;
    gl_ClipDistance[2] = cell.z - world.x;
    gl_ClipDistance[3] = cell.w - world.y;
    gl_Position = P * V * world;
    frag_normal = mat3(model) * normal;
#if HAS_COLOUR
    frag_colour = color_0;
#else
    frag_colour = vec4(1.0);
#endif
}
"""
_FRAGMENT_SHADER = """#version 330 core
struct Material {
    vec4 base_color_factor;
    vec3 emissive_factor;
    float roughness_factor;
};
uniform Material material;
in vec3 frag_normal;
in vec4 frag_colour;
out vec4 frag_color;
const vec3 FILL = vec3(-0.397, 0.476, 0.794);  // unit, from the upper left and front
void main() {
    // A zero normal (a vertex of zero-area triangles only) is taken as facing the camera:
    // the ternary selects before dividing, so no NaN is formed.
    float len = length(frag_normal);
    vec3 n = len > 0.0 ? frag_normal / len : vec3(0.0, 0.0, 1.0);
    // Seen from behind (the inside of the cut skin, the throat through the open mouth):
    // lit as if facing the camera, darker, as a cavity.
    float shade = n.z < 0.0 ? 0.6 : 1.0;
    n = n.z < 0.0 ? -n : n;
    vec3 base = shade * material.base_color_factor.rgb * frag_colour.rgb;
    float light = 0.20 + 0.66 * n.z + 0.30 * max(dot(n, FILL), 0.0);
    float highlight = 0.25 * (1.0 - material.roughness_factor) * pow(n.z, 24.0);
    vec3 c = base * light + vec3(highlight) + material.emissive_factor;
    frag_color = vec4(pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2)), material.base_color_factor.a);
}
"""


def _colour_only_renderer_class():
    """pyrender's Renderer with the toolkit's light shader and a plain framebuffer.

    pyrender renders into a 4x multisample buffer, reads back colour and depth (converting
    depth in numpy) and shades with a full PBR shader whose lights are re-bound in Python
    for every draw; with llvmpipe that is most of a frame. This keeps pyrender's scene,
    buffers and draw loop, and replaces those three parts.
    """
    import pyrender
    from OpenGL import GL as gl
    from pyrender.shader_program import ShaderProgram

    class _Program(ShaderProgram):
        def __init__(self, has_colour: bool, inst_m_loc: int):
            super().__init__("cassi.vert", "cassi.frag")
            self._defines = {"HAS_COLOUR": int(has_colour), "INST_M_LOC": inst_m_loc}

        def _load(self, name):
            text = _VERTEX_SHADER if name.endswith(".vert") else _FRAGMENT_SHADER
            for key, value in self._defines.items():
                text = text.replace(key, str(value))
            return text

    class _ColourOnlyRenderer(pyrender.Renderer):
        samples = 0  # multisample anti-aliasing; 0 = none

        def _get_primitive_program(self, primitive, flags, program_flags):
            has_colour = primitive.color_0 is not None
            programs = self.__dict__.setdefault("_cassi_programs", {})
            if has_colour not in programs:
                programs[has_colour] = _Program(has_colour, 3 if has_colour else 2)
                programs[has_colour]._add_to_context()
            return programs[has_colour]

        def _bind_lighting(self, scene, program, node, flags):
            pass  # the lights live in the shader

        def render(self, scene, flags, seg_node_map=None):
            """pyrender's render loop, lean: one program, cached uniform locations, no
            per-draw lighting or sorting (opaque pieces first, then see-through ones)."""
            if scene.meshes != self._meshes:
                self._update_context(scene, flags)
            self._configure_forward_pass_viewport(flags)
            gl.glClearColor(*scene.bg_color)
            gl.glClear(gl.GL_COLOR_BUFFER_BIT | gl.GL_DEPTH_BUFFER_BIT)
            for k in range(4):
                gl.glEnable(gl.GL_CLIP_DISTANCE0 + k)
            view, projection = self._get_camera_matrices(scene)
            nodes = [n for n in scene.mesh_nodes if n.mesh.is_visible]
            nodes.sort(key=lambda n: n.mesh.is_transparent)
            bound = None
            for node in nodes:
                for primitive in node.mesh.primitives:
                    program = self._get_primitive_program(primitive, flags, 0)
                    if program is not bound:  # every node has the identity pose
                        program._bind()
                        _uniform(program, "V", view)
                        _uniform(program, "P", projection)
                        _uniform(program, "M", np.eye(4))
                        bound = program
                    _draw_primitive(gl, program, primitive)
            if bound is not None:
                bound._unbind()
            gl.glFlush()
            return self._read_main_framebuffer(scene, flags)

        def _configure_main_framebuffer(self):
            dims = (self.viewport_width, self.viewport_height)
            if self._main_fb is not None and self._main_fb_dims != dims:
                self._delete_main_framebuffer()
            if self._main_fb is None:
                self._main_fb, self._main_cb, self._main_db = _framebuffer(gl, dims, 0)
                self._main_fb_ms, self._main_cb_ms, self._main_db_ms = (
                    _framebuffer(gl, dims, self.samples)
                    if self.samples
                    else (self._main_fb, self._main_cb, self._main_db)
                )
                self._main_fb_dims = dims

        def _delete_main_framebuffer(self):
            fbs = {self._main_fb, self._main_fb_ms} - {None}
            rbs = {self._main_cb, self._main_db, self._main_cb_ms, self._main_db_ms} - {None}
            if fbs:
                gl.glDeleteFramebuffers(len(fbs), list(fbs))
            if rbs:
                gl.glDeleteRenderbuffers(len(rbs), list(rbs))
            self._main_fb = self._main_cb = self._main_db = None
            self._main_fb_ms = self._main_cb_ms = self._main_db_ms = None
            self._main_fb_dims = (None, None)

        def _read_main_framebuffer(self, scene, flags):
            width, height = self._main_fb_dims
            if self._main_fb_ms != self._main_fb:
                gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, self._main_fb_ms)
                gl.glBindFramebuffer(gl.GL_DRAW_FRAMEBUFFER, self._main_fb)
                gl.glBlitFramebuffer(
                    0, 0, width, height, 0, 0, width, height,
                    gl.GL_COLOR_BUFFER_BIT, gl.GL_LINEAR,
                )  # fmt: skip
            gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, self._main_fb)
            # RGB straight into a kept buffer: dropping alpha in numpy costs 1.4 ms a frame.
            buffer = self.__dict__.get("_cassi_pixels")
            if buffer is None or buffer.shape != (height, width, 3):
                buffer = self._cassi_pixels = np.empty((height, width, 3), np.uint8)
            gl.glPixelStorei(gl.GL_PACK_ALIGNMENT, 1)
            gl.glReadPixels(0, 0, width, height, gl.GL_RGB, gl.GL_UNSIGNED_BYTE, buffer)
            return buffer[::-1].copy(), None

    return _ColourOnlyRenderer


def _uniform(program, name, value):
    """Set a uniform of a pyrender ShaderProgram, its location cached on the program.

    ``value``: a (4,4) matrix, or a tuple of 1, 3 or 4 floats.
    """
    from OpenGL import GL as gl

    locations = program.__dict__.setdefault("_cassi_locations", {})
    if name not in locations:
        locations[name] = gl.glGetUniformLocation(program._program_id, name)
    loc = locations[name]
    if loc < 0:
        return
    if isinstance(value, np.ndarray) and value.ndim == 2:
        gl.glUniformMatrix4fv(loc, 1, gl.GL_TRUE, value.astype(np.float32))
    elif len(value) == 4:
        gl.glUniform4f(loc, *value)
    elif len(value) == 3:
        gl.glUniform3f(loc, *value)
    else:
        gl.glUniform1f(loc, value[0])


def _material_uniforms(material) -> tuple:
    """(base colour (4,), emissive (3,), (roughness,)) as Python floats, for _uniform."""
    return (
        tuple(float(c) for c in material.baseColorFactor),
        tuple(float(c) for c in material.emissiveFactor),
        (float(material.roughnessFactor),),
    )


def _draw_primitive(gl, program, primitive):
    """Material uniforms, blending and culling, then one instanced draw of ``primitive``."""
    material = primitive.material
    uniforms = primitive.__dict__.get("cassi_uniforms")
    if uniforms is None:
        uniforms = primitive.cassi_uniforms = _material_uniforms(material)
    base, emissive, roughness = uniforms
    _uniform(program, "material.base_color_factor", base)
    _uniform(program, "material.emissive_factor", emissive)
    _uniform(program, "material.roughness_factor", roughness)
    if material.alphaMode == "BLEND":
        gl.glEnable(gl.GL_BLEND)
        gl.glBlendFunc(gl.GL_SRC_ALPHA, gl.GL_ONE_MINUS_SRC_ALPHA)
    else:
        gl.glDisable(gl.GL_BLEND)
    # Double-sided where the inside can show (the cut, the mouth). Drawing the front faces
    # first and the back faces after costs the same with llvmpipe: rasterising
    # depth-rejected triangles costs as much as shading them; culling is what saves.
    cull = getattr(primitive, "cassi_cull", None)
    if cull is None:
        gl.glDisable(gl.GL_CULL_FACE)
    else:
        gl.glEnable(gl.GL_CULL_FACE)
        gl.glCullFace(gl.GL_FRONT if cull == "front" else gl.GL_BACK)
    primitive._bind()
    gl.glDrawElementsInstanced(
        gl.GL_TRIANGLES, primitive.indices.size, gl.GL_UNSIGNED_INT, None, len(primitive.poses)
    )
    primitive._unbind()


def _framebuffer(gl, dims, samples):
    """A framebuffer with RGBA8 colour and 24-bit depth renderbuffers: (fb, colour, depth)."""
    colour, depth = gl.glGenRenderbuffers(2)
    for rb, fmt in ((colour, gl.GL_RGBA8), (depth, gl.GL_DEPTH_COMPONENT24)):
        gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, rb)
        if samples:
            gl.glRenderbufferStorageMultisample(gl.GL_RENDERBUFFER, samples, fmt, *dims)
        else:
            gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, fmt, *dims)
    fb = gl.glGenFramebuffers(1)
    gl.glBindFramebuffer(gl.GL_DRAW_FRAMEBUFFER, fb)
    for attachment, rb in ((gl.GL_COLOR_ATTACHMENT0, colour), (gl.GL_DEPTH_ATTACHMENT, depth)):
        gl.glFramebufferRenderbuffer(gl.GL_DRAW_FRAMEBUFFER, attachment, gl.GL_RENDERBUFFER, rb)
    return fb, colour, depth


def _sphere(subdivisions: int = 2):
    """Unit icosphere (positions, normals, faces) for the markers."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(s.vertices), np.asarray(s.vertex_normals), np.asarray(s.faces)


class Renderer:
    """Offscreen renderer of one face model: one OpenGL context, one scene, reused per frame.

    ``size`` is the whole output image (W, H) in pixels; in grid mode the views share it as
    a 2x2 grid (front, side / inside, top), each view a (W/2, H/2) cell; with ``grid=False``
    the views stand in one row. ``skin`` is ``"cut"`` (the inside view removes the near
    half of skin, lips, eyes, teeth and palate) or ``"transparent"`` (the near skin, lips
    and eyes drawn see-through). ``antialias`` is the number of multisample samples
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
        model,
        *,
        size=(640, 480),
        views=VIEWS,
        grid=True,
        skin="cut",
        background=(0.92, 0.92, 0.92),
        antialias=0,
        marker_radius=None,
        margin=0.06,
        colours=None,
        cull=True,
    ):
        self.size, self.views, skin = _check_options(size, views, skin, background)
        self.grid = bool(grid)
        rest, faces, face_material, materials = _model_arrays(model)
        self._n_vertices = len(rest)
        self._faces = faces
        self._incidence = _incidence(faces, len(rest))
        self._pieces = _split_pieces(
            rest, faces, face_material, materials, self.views, skin, bool(cull)
        )
        self._fits = {v: self._fit(v, rest) for v in self.views}
        height = self._fits.get("side", next(iter(self._fits.values())))[3][1]
        self._marker_radius = float(marker_radius) if marker_radius else 0.012 * height
        self._margin = float(margin)
        self._colours = {**MATERIAL_COLOURS, **(colours or {})}
        self.platform = ensure_headless_gl()
        self._build_scene(background, int(antialias))
        self._layout_key, self._placements, self._markers = None, {}, {}
        self.render(rest)  # warm-up: shaders compiled, buffers in the GL context

    # -- set-up ------------------------------------------------------------------------

    def _fit(self, view, rest):
        """(R (3,3), mid (3,), lo (3,), extent (3,)) of the view's visible rest geometry."""
        idx = np.unique(np.concatenate(
            [p.vertex_index for p in self._pieces if view in p.views] or [np.arange(len(rest))]
        ))  # fmt: skip
        rotation = np.asarray(_VIEW_AXES[view], float)
        q = rest[idx] @ rotation.T
        lo, hi = q.min(axis=0), q.max(axis=0)
        return rotation, (lo + hi) / 2, lo, np.maximum(hi - lo, 1e-9 * (1 + np.abs(hi)))

    def _build_scene(self, background, samples):
        import pyrender

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
        cls = _colour_only_renderer_class()
        self._gl._renderer.__class__ = cls
        self._gl._renderer.samples = samples

    def _add_piece(self, pyrender, piece):
        alpha = 0.35 if piece.glass else 1.0
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
        self._scene.add(piece.mesh)

    # -- per frame ---------------------------------------------------------------------

    def _set_layout(self, key):
        """Place the views: ``"grid"`` (all views in their cells) or one view filling the image."""
        if key == self._layout_key:
            return
        width, height = self.size
        cells = (
            _cells(self.views, self.size, self.grid)
            if key == "grid"
            else {key: (width / 2, height / 2, width, height)}
        )
        self._placements = {v: self._placement(v, cell) for v, cell in cells.items()}
        for piece in self._pieces:
            poses = [self._placements[v] for v in piece.views if v in self._placements]
            piece.mesh.is_visible = bool(poses)
            if poses:
                _set_poses(piece.primitive, np.stack(poses))
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
        from OpenGL import GL as gl

        normals = _vertex_normals(vertices, self._faces, self._incidence)
        self._gl._platform.make_current()
        for piece in self._pieces:
            piece.buffer[:, :3] = vertices[piece.vertex_index]
            piece.buffer[:, 3:6] = normals[piece.vertex_index]
            if piece.primitive._in_context():
                gl.glBindBuffer(gl.GL_ARRAY_BUFFER, piece.primitive._buffers[0])
                gl.glBufferSubData(gl.GL_ARRAY_BUFFER, 0, piece.buffer.nbytes, piece.buffer)
            else:
                piece.primitive.positions = piece.buffer[:, :3].copy()
                piece.primitive.normals = piece.buffer[:, 3:6].copy()

    def _set_markers(self, markers):
        """Instanced spheres for each label's points in the side and inside views.

        The points are moved along the view direction to just in front of the model's rest
        bounds (this does not move them in the orthographic image), so the face never hides
        them.
        """
        import pyrender

        markers = {} if markers is None else dict(markers)
        for label in set(self._markers) | set(markers):
            pts = _marker_points(markers.get(label, np.zeros((0, 3))))
            poses = self._marker_poses(pts)
            if label not in self._markers:
                if not len(poses):
                    continue
                self._markers[label] = self._marker_mesh(pyrender, label, poses)
            mesh = self._markers[label]
            mesh.is_visible = bool(len(poses))
            if len(poses):
                _set_poses(mesh.primitives[0], poses)

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
        self._scene.add(mesh)
        return mesh

    def _draw(self) -> np.ndarray:
        colour, _ = self._gl.render(self._scene)
        return colour

    # -- public ------------------------------------------------------------------------

    def render(self, vertices, *, markers=None, caption=None) -> np.ndarray:
        """One frame as an (H, W, 3) uint8 image: the grid (or the single view).

        ``vertices``: (V,3) mm, model frame, the model's topology (numpy or JAX).
        ``markers``: optional ``{label: (k,3) or (k,2) points in mm}``, drawn as spheres in
        the side and inside views ("measured" red, "model" green, others blue, orange, ...;
        non-finite points are not drawn). ``caption``: text drawn onto the image.
        """
        frame = _as_frame(vertices, self._n_vertices)
        self._upload(frame)
        self._set_layout("grid")
        self._set_markers(markers)
        image = self._draw()
        return add_caption(image, caption) if caption else image

    def render_views(self, vertices, *, markers=None) -> dict[str, np.ndarray]:
        """Each view alone, filling the whole image: ``{view: (H, W, 3) uint8}``."""
        frame = _as_frame(vertices, self._n_vertices)
        self._upload(frame)
        out = {}
        for view in self.views:
            self._set_layout(view)
            self._set_markers(markers)
            out[view] = self._draw()
        return out

    def close(self):
        """Release the OpenGL context (idempotent)."""
        offscreen, self._gl = getattr(self, "_gl", None), None
        if offscreen is None:
            return
        platform = offscreen._platform
        if type(platform).__name__ != "EGLPlatform":
            offscreen.delete()
            return
        # pyrender's delete() would eglTerminate the EGL display, which every renderer of
        # the process shares: destroy only this context.
        from OpenGL import EGL

        platform.make_current()
        offscreen._renderer.delete()
        display = platform._egl_display
        EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
        EGL.eglDestroyContext(display, platform._egl_context)
        platform._egl_context = platform._egl_display = None
        offscreen._renderer = offscreen._platform = None

    def __del__(self):  # an unclosed renderer must not eglTerminate the shared display
        try:
            self.close()
        except Exception:
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def _set_poses(primitive, poses: np.ndarray):
    """Replace an instanced primitive's (n,4,4) poses, in the GL buffer if it is there."""
    primitive.poses = poses
    if primitive._in_context():
        from OpenGL import GL as gl

        data = np.ascontiguousarray(np.transpose(poses, (0, 2, 1)), dtype=np.float32)
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, primitive._buffers[1])
        gl.glBufferData(gl.GL_ARRAY_BUFFER, data.nbytes, data, gl.GL_DYNAMIC_DRAW)


def _incidence(faces: np.ndarray, n_vertices: int):
    """Sparse (V,F) matrix with a 1 where a vertex belongs to a face."""
    import scipy.sparse

    rows = faces.ravel()
    cols = np.repeat(np.arange(len(faces)), 3)
    return scipy.sparse.csr_matrix(
        (np.ones(len(rows)), (rows, cols)), shape=(n_vertices, len(faces))
    )


def _model_arrays(model):
    """(rest (V,3) float64, faces (F,3) int64, face_material (F,), material names)."""
    try:
        from .face_model import MATERIALS as materials
    except ImportError:
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


def _check_options(size, views, skin, background):
    try:
        width, height = (int(s) for s in size)
    except (TypeError, ValueError):
        raise CassiError(f"render: size must be (width, height), got {size!r}") from None
    if width < 8 or height < 8:
        raise CassiError(f"render: size must be at least 8x8 pixels, got {width}x{height}")
    views = (views,) if isinstance(views, str) else tuple(views)
    unknown = [v for v in views if v not in VIEWS]
    if not views or unknown or len(set(views)) != len(views):
        raise CassiError(f"render: views must be distinct names from {VIEWS}, got {views}")
    if skin not in ("cut", "transparent"):
        raise CassiError(f"render: skin must be 'cut' or 'transparent', got {skin!r}")
    if len(background) != 3:
        raise CassiError(f"render: background must be an RGB triple, got {background!r}")
    return (width, height), views, skin


# --------------------------------------------------------------------------------------
# captions and files
# --------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def _font(size: int):
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def add_caption(image, text) -> np.ndarray:
    """A copy of ``image`` ((H,W,3) uint8) with ``text`` in white on a dark band at the bottom.

    Only the band is touched (about 1 ms at 640x480, so a caption on every frame is cheap).
    """
    from PIL import Image, ImageDraw

    out = np.array(image, dtype=np.uint8, copy=True)
    if out.ndim != 3 or out.shape[2] != 3:
        raise CassiError(f"add_caption: an image must be (H, W, 3) uint8, got {out.shape}")
    height = out.shape[0]
    text = str(text)
    font = _font(max(10, height // 32))
    left, top, right, bottom = ImageDraw.Draw(Image.new("L", (1, 1))).multiline_textbbox(
        (0, 0), text, font=font
    )
    pad = max(2, height // 120)
    band_top = max(0, height - (bottom - top) - 2 * pad)
    band = out[band_top:].astype(np.uint16) * 85 // 255 + 13  # 2/3 toward dark grey
    pil = Image.fromarray(band.astype(np.uint8))
    ImageDraw.Draw(pil).multiline_text((pad - left, pad - top), text, font=font, fill=(255,) * 3)
    out[band_top:] = np.asarray(pil)
    return out


def save_png(path, image, *, overwrite=True) -> Path:
    """Write an (H,W,3) or (H,W,4) uint8 image as PNG, atomically; returns the path."""
    from PIL import Image

    array = np.asarray(image)
    if array.dtype != np.uint8 or array.ndim != 3 or array.shape[2] not in (3, 4):
        raise CassiError(
            f"{path}: an image must be (H, W, 3|4) uint8, got {array.shape} {array.dtype}"
        )
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return atomic_write(path, buffer.getvalue(), overwrite=overwrite)
