"""Offscreen rendering of the face model in the paper's four evaluation views, and the
midsagittal section.

The paper judged every animation from four views (Scheidt & Hamilton 1999, section 4):
``front`` (the full face), ``side`` (the full face in profile, looking to the right of the
image), ``inside`` (half the face from the side: skin, lips, teeth and palate on the
camera's side of the midsagittal plane z = 0 cut away, or the skin see-through, so that
tongue, teeth and palate show) and ``top`` (skin hidden: palate, teeth and tongue seen from
above, the front of the mouth to the right; the palate see-through and the tongue coloured
by height, dark low to light high, so that its position and groove show and change with
the data). Singly, in a row, or as a 2x2 grid (front, side / inside, top); pellet markers
in the side and inside views; a caption. The toolkit's fifth view, ``midsagittal``
(``_section``), is the posed mesh cut at z = 0 drawn as 2D contours as on an X-ray or MRI
tracing, with the subject's palate and pharynx traces and the pellets with trails; with
it the grid is 3x2 (front, side, inside / top, midsagittal).

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
  away from the cut); parts a view cannot show are not drawn in it (palate, pharynx and
  the mouth's walls from the side); a material's two sides drawn alike are one piece (one
  draw, one upload), and blending, culling and material uniforms are set only when they
  change.

The package, by concern: ``_gl`` chooses the OpenGL platform (probes in subprocesses;
EGL when there is no display, on a GPU if there is one (``CASSI_EGL_DEVICE``) else
llvmpipe, OSMesa as fallback) before OpenGL is
imported; ``_pieces`` cuts the mesh into drawable pieces (numpy); ``_section`` cuts it
at z = 0 and draws the midsagittal view (numpy and Pillow); ``_scene`` holds the
:class:`Renderer` (cameras, layout, markers); ``_draw`` the shaders and the OpenGL calls
(the only module that imports pyrender and OpenGL, when a Renderer is made); ``_images``
captions and PNG files; ``_pool`` draws frames in worker processes, each with its own
context (:class:`FramePool`). Importing :mod:`cassi_fit.render` imports neither OpenGL nor
pyrender, JAX or Pillow.
"""

from __future__ import annotations

from ..options import PAPER_VIEWS as PAPER_VIEWS
from ..options import VIEWS as VIEWS
from ._gl import HEADLESS_PLATFORMS as HEADLESS_PLATFORMS
from ._gl import choose_gl_platform as choose_gl_platform
from ._gl import egl_device as egl_device
from ._gl import ensure_headless_gl as ensure_headless_gl
from ._gl import prepare_gl as prepare_gl
from ._gl import probe_gl_platform as probe_gl_platform
from ._images import add_caption as add_caption
from ._images import save_png as save_png
from ._pieces import HAIR_COLOUR as HAIR_COLOUR
from ._pieces import MARKER_COLOURS as MARKER_COLOURS
from ._pieces import MATERIAL_COLOURS as MATERIAL_COLOURS
from ._pieces import SKINS as SKINS
from ._pieces import PieceInfo as PieceInfo
from ._pieces import hair_share as hair_share
from ._pieces import triangle_winding as triangle_winding
from ._pieces import vertex_colours_srgb as vertex_colours_srgb
from ._pool import FramePool as FramePool
from ._scene import Markers as Markers
from ._scene import MeshModel as MeshModel
from ._scene import Renderer as Renderer
from ._scene import view_cameras as view_cameras
from ._section import SECTION_VIEW as SECTION_VIEW
from ._section import Section as Section
from ._section import midsagittal_figure as midsagittal_figure
from ._section import section_polylines as section_polylines
from ._section import section_segments as section_segments

__all__ = [
    "HAIR_COLOUR",
    "HEADLESS_PLATFORMS",
    "MARKER_COLOURS",
    "MATERIAL_COLOURS",
    "SKINS",
    "FramePool",
    "VIEWS",
    "Markers",
    "MeshModel",
    "PAPER_VIEWS",
    "PieceInfo",
    "Renderer",
    "SECTION_VIEW",
    "Section",
    "add_caption",
    "choose_gl_platform",
    "egl_device",
    "midsagittal_figure",
    "ensure_headless_gl",
    "prepare_gl",
    "hair_share",
    "probe_gl_platform",
    "save_png",
    "section_polylines",
    "section_segments",
    "triangle_winding",
    "vertex_colours_srgb",
    "view_cameras",
]
