"""Drawing with OpenGL: the toolkit's shaders, pyrender's renderer made lean, and the
vertex and instance buffer updates.

This is the only module of :mod:`cassi_fit.render` that imports pyrender and OpenGL, and
it is imported only when a :class:`~cassi_fit.render.Renderer` is made, after
:func:`~cassi_fit.render.ensure_headless_gl` has chosen the platform (PyOpenGL fixes its
platform at first import).
"""

from __future__ import annotations

import ctypes
import itertools

import numpy as np
import OpenGL

# PyOpenGL calls glGetError after every call by default, and its wrappers then convert the
# result: with about a hundred calls a frame that was a large share of a frame's Python
# time. Errors are checked once a frame instead, after the read-back (_read_main_framebuffer).
# (Set before OpenGL.GL is first imported, by pyrender below.)
OpenGL.ERROR_CHECKING = False

import pyrender  # noqa: E402
from OpenGL import GL as gl  # noqa: E402
from OpenGL.raw.GL.VERSION.GL_1_5 import glBufferSubData as _buffer_sub_data  # noqa: E402
from OpenGL.raw.GL.VERSION.GL_3_1 import (  # noqa: E402
    glDrawElementsInstanced as _draw_elements_instanced,
)
from pyrender.shader_program import ShaderProgram  # noqa: E402

from ..errors import RenderingUnavailableError  # noqa: E402

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
    // The per-vertex colour factor applies by its share in the fourth component, clipped
    // here per pixel: 1 for the iris and the height scale, the interpolated signed
    // distance to the hair's edge on the skin (a sharp hairline within a triangle).
    vec3 factor = mix(vec3(1.0), frag_colour.rgb, clamp(frag_colour.a, 0.0, 1.0));
    vec3 base = shade * material.base_color_factor.rgb * factor;
    float light = 0.20 + 0.66 * n.z + 0.30 * max(dot(n, FILL), 0.0);
    // (weaker where a colour factor darkens the material: a white sheen on dark hair read
    // as a bald patch)
    float dark = clamp(1.0 - dot(factor, vec3(1.0 / 3.0)), 0.0, 1.0);
    float highlight = 0.25 * (1.0 - material.roughness_factor) * pow(n.z, 24.0)
                      * mix(1.0, 0.4, dark);
    vec3 c = base * light + vec3(highlight) + material.emissive_factor;
    frag_color = vec4(pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2)), material.base_color_factor.a);
}
"""


class _Program(ShaderProgram):
    def __init__(self, has_colour: bool, inst_m_loc: int):
        super().__init__("cassi.vert", "cassi.frag")
        self._defines = {"HAS_COLOUR": int(has_colour), "INST_M_LOC": inst_m_loc}

    def _load(self, name):
        text = _VERTEX_SHADER if name.endswith(".vert") else _FRAGMENT_SHADER
        for key, value in self._defines.items():
            text = text.replace(key, str(value))
        return text


class ColourOnlyRenderer(pyrender.Renderer):
    """pyrender's Renderer with the toolkit's light shader and a plain framebuffer.

    pyrender renders into a 4x multisample buffer, reads back colour and depth (converting
    depth in numpy) and shades with a full PBR shader whose lights are re-bound in Python
    for every draw; with llvmpipe that is most of a frame. This keeps pyrender's scene,
    buffers and draw loop, and replaces those three parts.
    """

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
        self.draw_frame(scene, flags)
        return self.read_frame(), None

    def draw_frame(self, scene, flags) -> None:
        """:meth:`render`'s drawing, into a framebuffer of its own, flushed: llvmpipe's
        raster threads draw it while the caller goes on; :meth:`read_frame` reads it.
        With one frame waiting to be read, the next is drawn into the second
        framebuffer, so that drawing frame k + 1 need not wait for frame k's pixels."""
        pending = self.__dict__.setdefault("_cassi_pending", [])
        if len(pending) > 1:
            raise RuntimeError("draw_frame: two frames wait to be read already")
        if scene.meshes != self._meshes:
            self._update_context(scene, flags)
        self._configure_forward_pass_viewport(flags)
        target = self._main_targets()[1 if pending and pending[0] == 0 else 0]
        gl.glBindFramebuffer(gl.GL_DRAW_FRAMEBUFFER, target[0])
        gl.glClearColor(*scene.bg_color)
        gl.glClear(gl.GL_COLOR_BUFFER_BIT | gl.GL_DEPTH_BUFFER_BIT)
        for k in range(4):
            gl.glEnable(gl.GL_CLIP_DISTANCE0 + k)
        view, projection = self._get_camera_matrices(scene)
        # in the order the meshes were made (scene.mesh_nodes is a set, ordered by memory
        # address): see-through pieces blend in the same order in every renderer, so
        # two renderers of one model (worker processes) draw the same bytes
        nodes = [n for n in scene.mesh_nodes if n.mesh.is_visible]
        nodes.sort(key=lambda n: (n.mesh.is_transparent, getattr(n.mesh, "cassi_order", -1)))
        bound, state = None, {}
        for node in nodes:
            for primitive in node.mesh.primitives:
                program = self._get_primitive_program(primitive, flags, 0)
                if program is not bound:  # every node has the identity pose
                    program._bind()
                    _uniform(program, "V", view)
                    _uniform(program, "P", projection)
                    _uniform(program, "M", np.eye(4))
                    bound = program
                    state.pop("uniforms", None)  # the other program's values
                _draw_primitive(gl, program, primitive, state)
        gl.glBindVertexArray(0)
        if bound is not None:
            bound._unbind()
        gl.glFlush()
        pending.append(0 if target[0] == self._main_fb_ms else 1)

    def read_frame(self) -> np.ndarray:
        """The oldest frame :meth:`draw_frame` drew and nobody read yet: a new (H, W, 3)
        uint8 image, top row first."""
        pending = self.__dict__.get("_cassi_pending")
        if not pending:
            raise RuntimeError("read_frame: no frame drawn")
        return self._read_main_framebuffer(self._main_targets()[pending.pop(0)])

    def _main_targets(self) -> tuple[tuple[int, int], tuple[int, int]]:
        """The two framebuffers frames are drawn into, as (drawn, resolved) pairs (the
        same framebuffer twice without multisampling): pyrender's main one, and a
        second made on first use."""
        spare = self.__dict__.get("_cassi_spare")
        if spare is None:
            dims = self._main_fb_dims
            spare = _framebuffer(gl, dims, 0)
            spare_ms = _framebuffer(gl, dims, self.samples) if self.samples else spare
            spare = self._cassi_spare = (spare_ms, spare)
        return ((self._main_fb_ms, self._main_fb), (spare[0][0], spare[1][0]))

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
        spare, self._cassi_spare, self._cassi_pending = (
            self.__dict__.get("_cassi_spare"), None, [])
        for fb, colour, depth in set(spare or ()):
            fbs.add(fb)
            rbs |= {colour, depth}
        if fbs:
            gl.glDeleteFramebuffers(len(fbs), list(fbs))
        if rbs:
            gl.glDeleteRenderbuffers(len(rbs), list(rbs))
        self._main_fb = self._main_cb = self._main_db = None
        self._main_fb_ms = self._main_cb_ms = self._main_db_ms = None
        self._main_fb_dims = (None, None)

    def _read_main_framebuffer(self, target):
        drawn, resolved = target
        width, height = self._main_fb_dims
        if drawn != resolved:
            gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, drawn)
            gl.glBindFramebuffer(gl.GL_DRAW_FRAMEBUFFER, resolved)
            gl.glBlitFramebuffer(
                0, 0, width, height, 0, 0, width, height,
                gl.GL_COLOR_BUFFER_BIT, gl.GL_LINEAR,
            )  # fmt: skip
        gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, resolved)
        # RGB straight into a kept buffer: dropping alpha in numpy costs 1.4 ms a frame.
        buffer = self.__dict__.get("_cassi_pixels")
        if buffer is None or buffer.shape != (height, width, 3):
            buffer = self._cassi_pixels = np.empty((height, width, 3), np.uint8)
        gl.glPixelStorei(gl.GL_PACK_ALIGNMENT, 1)
        gl.glReadPixels(0, 0, width, height, gl.GL_RGB, gl.GL_UNSIGNED_BYTE, buffer)
        error = gl.glGetError()  # the frame's one error check (ERROR_CHECKING is off)
        if error != gl.GL_NO_ERROR:
            raise RenderingUnavailableError(f"OpenGL error {int(error):#x} while drawing a "
                                            "frame")
        return buffer[::-1].copy()


def _uniform(program, name, value):
    """Set a uniform of a pyrender ShaderProgram, its location cached on the program.

    ``value``: a (4,4) matrix, or a tuple of 1, 3 or 4 floats.
    """
    locations = program.__dict__.setdefault("_cassi_locations", {})
    if name not in locations:
        locations[name] = gl.glGetUniformLocation(program._program_id, name)
    loc = locations[name]
    if loc < 0:
        return
    # a program keeps its uniforms' values: set only what changed since the last frame
    # (the camera's matrices never do, the materials' only between draws)
    kept = program.__dict__.setdefault("_cassi_values", {})
    matrix = isinstance(value, np.ndarray) and value.ndim == 2
    if matrix:
        value = value.astype(np.float32)
    key = value.tobytes() if matrix else value
    if kept.get(name) == key:
        return
    kept[name] = key
    if matrix:
        gl.glUniformMatrix4fv(loc, 1, gl.GL_TRUE, value)
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


def _draw_primitive(gl, program, primitive, state):
    """Material uniforms, blending and culling, then one instanced draw of ``primitive``.

    ``state``: what the previous draws of this frame set (a dict, empty at the start of
    the frame); only what changes is set again (PyOpenGL's calls cost Python time)."""
    material = primitive.material
    uniforms = primitive.__dict__.get("cassi_uniforms")
    if uniforms is None:
        uniforms = primitive.cassi_uniforms = _material_uniforms(material)
    if state.get("uniforms") != uniforms:
        base, emissive, roughness = uniforms
        _uniform(program, "material.base_color_factor", base)
        _uniform(program, "material.emissive_factor", emissive)
        _uniform(program, "material.roughness_factor", roughness)
        state["uniforms"] = uniforms
    blend = material.alphaMode == "BLEND"
    if state.get("blend") != blend:
        if blend:
            gl.glEnable(gl.GL_BLEND)
            gl.glBlendFunc(gl.GL_SRC_ALPHA, gl.GL_ONE_MINUS_SRC_ALPHA)
        else:
            gl.glDisable(gl.GL_BLEND)
        state["blend"] = blend
    # Double-sided where the inside can show (the cut, the mouth). Drawing the front faces
    # first and the back faces after costs the same with llvmpipe: rasterising
    # depth-rejected triangles costs as much as shading them; culling is what saves.
    cull = getattr(primitive, "cassi_cull", None)
    if state.get("cull", "unset") != cull:
        if cull is None:
            gl.glDisable(gl.GL_CULL_FACE)
        else:
            gl.glEnable(gl.GL_CULL_FACE)
            gl.glCullFace(gl.GL_FRONT if cull == "front" else gl.GL_BACK)
        state["cull"] = cull
    gl.glBindVertexArray(primitive._vaid)
    _draw_elements_instanced(gl.GL_TRIANGLES, primitive.indices.size, gl.GL_UNSIGNED_INT,
                             None, len(primitive.poses))


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


_MESH_ORDER = itertools.count()


def add_mesh(scene: pyrender.Scene, mesh: pyrender.Mesh) -> pyrender.Node:
    """Add ``mesh`` to ``scene``, numbered so that it is drawn after the meshes added
    before it (opaque ones first, then see-through ones)."""
    mesh.cassi_order = next(_MESH_ORDER)
    return scene.add(mesh)


def set_poses(primitive: pyrender.Primitive, poses: np.ndarray) -> None:
    """Replace an instanced primitive's (n,4,4) poses, in the GL buffer if it is there."""
    primitive.poses = poses
    if primitive._in_context():
        data = np.ascontiguousarray(np.transpose(poses, (0, 2, 1)), dtype=np.float32)
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, primitive._buffers[1])
        gl.glBufferData(gl.GL_ARRAY_BUFFER, data.nbytes, data, gl.GL_DYNAMIC_DRAW)


def write_vertices(primitive: pyrender.Primitive, buffer: np.ndarray) -> None:
    """Put one frame's interleaved (n, 6 + k) float32 vertex data (position, normal,
    extra columns) into ``primitive``: in place in its GL buffer once it has one."""
    if primitive._in_context():
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, primitive._buffers[0])
        # the raw call: PyOpenGL's wrapper converts the array again on every call
        assert buffer.flags.c_contiguous and buffer.dtype == np.float32
        _buffer_sub_data(gl.GL_ARRAY_BUFFER, 0, buffer.nbytes, ctypes.c_void_p(buffer.ctypes.data))
    else:
        primitive.positions = buffer[:, :3].copy()
        primitive.normals = buffer[:, 3:6].copy()


def draw_frame(offscreen: pyrender.OffscreenRenderer, scene: pyrender.Scene) -> bool:
    """The first half of ``offscreen.render(scene)``: the frame drawn and flushed, not read
    (:func:`read_frame`); False, nothing drawn, where the platform has no framebuffers
    (OSMesa: call ``offscreen.render``)."""
    platform = offscreen._platform
    if not platform.supports_framebuffers():
        return False
    platform.make_current()
    renderer = offscreen._renderer
    renderer.viewport_width = offscreen.viewport_width
    renderer.viewport_height = offscreen.viewport_height
    renderer.point_size = offscreen.point_size
    renderer.draw_frame(scene, pyrender.RenderFlags.OFFSCREEN)
    return True


def read_frame(offscreen: pyrender.OffscreenRenderer) -> np.ndarray:
    """The oldest frame :func:`draw_frame` drew and nobody read yet, (H, W, 3) uint8."""
    offscreen._platform.make_current()
    return offscreen._renderer.read_frame()


def drop_frames(offscreen: pyrender.OffscreenRenderer) -> None:
    """Forget the frames :func:`draw_frame` drew and nobody read (a stopped video)."""
    offscreen._renderer.__dict__["_cassi_pending"] = []


def release(offscreen: pyrender.OffscreenRenderer) -> None:
    """Delete ``offscreen``'s OpenGL context (and only that one)."""
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
