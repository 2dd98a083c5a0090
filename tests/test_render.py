"""Tests of cassi_fit.render: headless GL selection, the four views, grid, markers, caption.

Most tests use a stand-in head built from ellipsoids (known geometry, independent of the
face model's evolution) drawn with saturated test colours, so that each material can be
told apart by its dominant colour channels. One test renders the repository's face model.
"""

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from cassi_fit import render
from cassi_fit._io import register_input
from cassi_fit.errors import (
    CassiError,
    InvalidChoiceError,
    OutputExistsError,
    RenderingUnavailableError,
)

pytestmark = pytest.mark.render

# material index (MATERIALS order: skin, lips, eye, teeth, tongue, palate), centre, radii (mm)
_PARTS = (
    (0, (-45, 20, 0), (75, 110, 70)),
    (1, (27, -8, 0), (8, 10, 22)),
    (2, (12, 50, 30), (12, 12, 12)),
    (2, (12, 50, -30), (12, 12, 12)),
    (3, (-3, -8, 0), (6, 10, 22)),
    (4, (-35, -15, 0), (30, 12, 20)),
    (5, (-30, 6, 0), (30, 4, 22)),
)
TEST_COLOURS = {
    "skin": (0.25, 0.25, 0.95),  # blue
    "lips": (0.95, 0.95, 0.15),  # yellow
    "eye": (0.95, 0.95, 0.95),
    "teeth": (0.95, 0.95, 0.95),
    "tongue": (0.15, 0.95, 0.15),  # green
    "palate": (0.95, 0.15, 0.95),  # magenta
}
SIZE = (320, 240)


def standin_model():
    """A head-like stand-in with the FaceModel attributes the renderer reads."""
    vertices, faces, material, n = [], [], [], 0
    for m, centre, radii in _PARTS:
        sphere = trimesh.creation.icosphere(subdivisions=2)
        vertices.append(np.asarray(sphere.vertices) * radii + centre)
        faces.append(np.asarray(sphere.faces) + n)
        material.append(np.full(len(sphere.faces), m))
        n += len(sphere.vertices)
    return SimpleNamespace(
        vertices=np.concatenate(vertices),
        faces=np.concatenate(faces),
        face_material=np.concatenate(material),
    )


def blue(img):  # skin
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (b > r + 40) & (b > g + 40)


def green(img):  # tongue
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (g > r + 40) & (g > b + 40)


def magenta(img):  # palate
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > g + 40) & (b > g + 40)


def red(img):  # "measured" markers
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > g + 60) & (r > b + 60)


def quadrants(img):
    h, w = img.shape[0] // 2, img.shape[1] // 2
    return {
        "front": img[:h, :w],
        "side": img[:h, w:],
        "inside": img[h:, :w],
        "top": img[h:, w:],
    }


@pytest.fixture(scope="module")
def model():
    return standin_model()


@pytest.fixture(scope="module")
def renderer(model):
    with render.Renderer(model, size=SIZE, colours=TEST_COLOURS) as r:
        yield r


@pytest.fixture(scope="module")
def views(renderer, model):
    return renderer.render_views(model.vertices)


# -- headless GL selection ----------------------------------------------------------------


class FakeProbe:
    """Stands in for probe_gl_platform: ``working`` platforms create a context."""

    def __init__(self, working):
        self.working, self.calls = set(working), []

    def __call__(self, platform):
        self.calls.append(platform)
        return None if platform in self.working else f"{platform} does not work here"


def choose(working, environ=None, imported=None):
    probe = FakeProbe(working)
    platform = render.choose_gl_platform(probe=probe, environ=environ or {}, imported=imported)
    return platform, probe.calls


def test_headless_picks_egl_without_display():
    assert choose({"egl", "osmesa", "native"}) == ("egl", ["egl"])


def test_headless_falls_back_to_osmesa():
    assert choose({"osmesa"}) == ("osmesa", ["egl", "osmesa"])


def test_headless_tries_native_first_with_a_display():
    assert choose({"egl"}, {"DISPLAY": ":0"}) == ("egl", ["native", "egl"])
    assert choose({"native", "egl"}, {"WAYLAND_DISPLAY": "w"}) == ("native", ["native"])


def test_headless_respects_the_users_platform():
    assert choose(set(), {"PYOPENGL_PLATFORM": "osmesa"}) == ("osmesa", [])


def test_no_gl_is_one_clear_line():
    with pytest.raises(RenderingUnavailableError) as info:
        choose(set())
    message = str(info.value)
    assert "\n" not in message
    assert "egl" in message and "osmesa" in message and "libegl1" in message


def test_an_already_imported_opengl_is_reported_not_guessed():
    """Once PyOpenGL is imported its platform is fixed: the answer is that platform, or
    one clear error if pyrender cannot use it headless."""

    class EGLPlatform:
        pass

    class GLXPlatform:
        pass

    assert choose({"osmesa"}, imported=EGLPlatform()) == ("egl", [])
    assert choose(set(), {"DISPLAY": ":0"}, imported=GLXPlatform()) == ("native", [])
    with pytest.raises(RenderingUnavailableError, match="import cassi_fit.render first"):
        choose({"egl"}, imported=GLXPlatform())


_FRESH = """
import os, sys
import cassi_fit.render as render
assert not [m for m in sys.modules if m.split(".")[0] in ("OpenGL", "pyrender", "jax")], "eager"
platform = render.ensure_headless_gl()
assert "OpenGL" not in sys.modules, "OpenGL imported by the choice"
assert render.ensure_headless_gl() == platform  # cached
print(platform, os.environ.get("PYOPENGL_PLATFORM"))
"""


def test_importing_render_imports_no_opengl_and_the_choice_comes_first():
    """In a fresh process without a display: importing cassi_fit.render imports neither
    OpenGL, pyrender nor JAX; ensure_headless_gl writes its choice (EGL here) into
    PYOPENGL_PLATFORM before anything imports OpenGL."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "PYOPENGL_PLATFORM")}  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-c", _FRESH], capture_output=True, text=True, env=env
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["egl", "egl"]


_ARRAYS_ONLY = """
import sys
import numpy as np
from types import SimpleNamespace
import cassi_fit.render as render
import trimesh
ball = trimesh.creation.icosphere(subdivisions=2)
model = SimpleNamespace(vertices=np.asarray(ball.vertices) * 50, faces=np.asarray(ball.faces),
                        face_material=np.zeros(len(ball.faces), int))
with render.Renderer(model, size=(64, 48)) as renderer:
    image = renderer.render(model.vertices)
assert image.shape == (48, 64, 3)
assert not [m for m in sys.modules if m.split(".")[0] in ("jax", "equinox")], "JAX imported"
"""


def test_a_renderer_of_plain_arrays_imports_no_jax():
    """A drawing worker (render.FramePool) is sent the model's arrays: its Renderer must
    not import JAX (the face model's module), over a second of each worker's start-up.
    The renderer's copy of the material names is face_model's."""
    import os
    import subprocess
    import sys

    from cassi_fit.face_model import MATERIALS
    from cassi_fit.render._pieces import _MATERIALS

    assert _MATERIALS == MATERIALS
    done = subprocess.run([sys.executable, "-c", _ARRAYS_ONLY], capture_output=True,
                          text=True, env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert done.returncode == 0, done.stderr


_PREPARED = """
import hashlib, os, sys, time
import cassi_fit.render as render
from cassi_fit.face_model import load_model
if sys.argv[1] == "prepared":
    render.prepare_gl()
    render.prepare_gl()  # once per process
    time.sleep(0.05)  # the thread under way while this one works
model = load_model()
with render.Renderer(model, size=(96, 72)) as renderer:
    image = renderer.render(model.vertices, caption="x")
print(render.ensure_headless_gl(), hashlib.sha256(image.tobytes()).hexdigest())
"""


def test_prepare_gl_readies_the_same_renderer_in_the_background():
    """prepare_gl (what cassi animate calls before fitting and animating) chooses the
    platform and imports pyrender and OpenGL in a background thread, in a Renderer's
    order (_draw's error-checking switch after OpenGL: EGL's functions need the checker
    class): a Renderer made after it draws the same bytes as one made without."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "PYOPENGL_PLATFORM")}  # fmt: skip
    out = []
    for how in ("prepared", "plain"):
        done = subprocess.run([sys.executable, "-c", _PREPARED, how], capture_output=True,
                              text=True, env=env)
        assert done.returncode == 0, done.stderr
        out.append(done.stdout.split())
    assert out[0] == out[1] and out[0][0] == "egl"


def test_egl_really_works_here():
    assert render.probe_gl_platform("egl") is None
    assert render.ensure_headless_gl() in render.HEADLESS_PLATFORMS


# -- the views ------------------------------------------------------------------------------


def test_each_view_is_non_blank_and_sized(views):
    assert set(views) == set(render.PAPER_VIEWS)  # a Renderer's default
    for name, img in views.items():
        assert img.shape == (SIZE[1], SIZE[0], 3) and img.dtype == np.uint8, name
        background = np.all(img == img[0, 0], axis=-1)
        assert background.mean() < 0.9, f"{name} is (nearly) blank"


def test_front_and_side_show_skin_not_tongue(views):
    for name in ("front", "side"):
        assert blue(views[name]).mean() > 0.2, name
        assert green(views[name]).sum() == 0, name


def test_inside_view_shows_the_tongue_and_palate(views):
    assert green(views["inside"]).sum() > 200
    assert magenta(views["inside"]).sum() > 50
    assert blue(views["inside"]).sum() > 200  # the far half of the skin


def test_top_view_shows_the_palate_see_through_without_skin(views):
    assert magenta(views["top"]).sum() > 200  # the palate's tint where nothing is under it
    assert blue(views["top"]).sum() == 0


def test_top_view_changes_where_the_tongue_moves_under_the_palate(renderer, model):
    """Issue 13: the top view must tell something. The palate is see-through there and the
    tongue coloured by height, so raising the tongue by 5 mm (its outline seen from above
    unchanged) changes the pixels under the palate; an opaque palate would hide it."""
    raised = model.vertices.copy()
    tongue = np.unique(model.faces[model.face_material == 4])
    raised[tongue, 1] += 5.0
    away = model.vertices.copy()
    away[tongue, 0] += 1000.0  # out of the view: the palate's footprint over the background
    footprint = magenta(renderer.render_views(away)["top"])
    a = renderer.render_views(model.vertices)["top"].astype(int)
    b = renderer.render_views(raised)["top"].astype(int)
    changed = np.abs(a - b).sum(axis=-1) > 30
    assert (changed & footprint).sum() > 300


def test_grid_holds_the_four_views(renderer, model, views):
    grid = renderer.render(model.vertices)
    assert grid.shape == (SIZE[1], SIZE[0], 3) and grid.dtype == np.uint8
    cells = quadrants(grid)
    assert blue(cells["front"]).mean() > 0.2 and green(cells["front"]).sum() == 0
    assert green(cells["inside"]).sum() > 50
    assert magenta(cells["top"]).sum() > 50 and blue(cells["top"]).sum() == 0
    # a cell is its view at half the size
    half = views["side"][::2, ::2]
    assert abs(blue(cells["side"]).mean() - blue(half).mean()) < 0.05


def test_render_is_deterministic(renderer, model):
    a = renderer.render(model.vertices)
    renderer.render(model.vertices * 1.01)
    b = renderer.render(model.vertices)
    np.testing.assert_array_equal(a, b)


def test_vertices_are_updated_per_frame(renderer, model):
    """Moving the tongue up 8 mm changes the inside view (vertex buffers updated in place)."""
    moved = model.vertices.copy()
    tongue = np.unique(model.faces[model.face_material == 4])
    moved[tongue, 1] += 8.0
    a = quadrants(renderer.render(model.vertices))["inside"]
    b = quadrants(renderer.render(moved))["inside"]
    rows_a = np.nonzero(green(a).any(axis=1))[0]
    rows_b = np.nonzero(green(b).any(axis=1))[0]
    assert rows_b.min() < rows_a.min()  # higher in the image


def test_single_view_renderer_matches_render_views(model, views):
    with render.Renderer(model, size=SIZE, views=("side",), colours=TEST_COLOURS) as r:
        np.testing.assert_array_equal(r.render(model.vertices), views["side"])


def test_size_option_and_row_layout(model):
    with render.Renderer(
        model, size=(200, 80), views=("front", "top"), grid=False, colours=TEST_COLOURS
    ) as r:
        img = r.render(model.vertices)
        assert img.shape == (80, 200, 3)
        assert blue(img[:, :100]).sum() > 100 and blue(img[:, 100:]).sum() == 0
        assert magenta(img[:, 100:]).sum() > 20


def test_transparent_skin_shows_the_tongue(model):
    with render.Renderer(
        model, size=SIZE, views=("inside",), skin="transparent", colours=TEST_COLOURS
    ) as r:
        img = r.render(model.vertices)
    tongue = green(img) | (img[..., 1].astype(int) > img[..., 0] + 25)
    assert tongue.sum() > 100
    assert blue(img).sum() > 200


def test_markers_are_drawn_in_the_side_and_inside_views(renderer, model):
    pellets = np.array([[-20.0, -5.0, 0.0], [-40.0, -8.0, 0.0]])  # inside the head
    plain = quadrants(renderer.render(model.vertices))
    marked = quadrants(renderer.render(model.vertices, markers={"measured": pellets}))
    for name in ("side", "inside"):
        assert red(plain[name]).sum() == 0
        assert red(marked[name]).sum() > 4, name
    for name in ("front", "top"):
        assert red(marked[name]).sum() == 0, name
    # at the projected position: the side cell shows the model's x-y plane
    again = quadrants(renderer.render(model.vertices, markers={"measured": pellets[:1]}))
    assert 0 < red(again["side"]).sum() < red(marked["side"]).sum()
    # and gone again when not given
    assert red(quadrants(renderer.render(model.vertices))["side"]).sum() == 0


def test_markers_accept_2d_points_and_skip_missing_ones(renderer, model):
    pts = np.array([[-20.0, -5.0], [np.nan, np.nan]])
    img = renderer.render(model.vertices, markers={"measured": pts})
    assert red(quadrants(img)["side"]).sum() > 4
    with pytest.raises(CassiError):
        renderer.render(model.vertices, markers={"measured": np.zeros((2, 4))})


def test_caption_changes_pixels_in_a_band_at_the_bottom(renderer, model):
    plain = renderer.render(model.vertices)
    captioned = renderer.render(model.vertices, caption="JW11 task 18  t = 1.250 s  frame 10")
    changed = np.any(plain != captioned, axis=-1)
    assert changed.sum() > 500
    assert not changed[: SIZE[1] // 2].any()
    direct = render.add_caption(plain, "JW11 task 18  t = 1.250 s  frame 10")
    np.testing.assert_array_equal(direct, captioned)


def test_bad_vertices_raise_clear_errors(renderer, model):
    with pytest.raises(CassiError, match="shape"):
        renderer.render(model.vertices[:-1])
    bad = model.vertices.copy()
    bad[3, 1] = np.nan
    with pytest.raises(CassiError, match="NaN"):
        renderer.render(bad)


def test_bad_options_raise_clear_errors(model):
    with pytest.raises(InvalidChoiceError, match="unknown view 'back'; choose one of front"):
        render.Renderer(model, views=("back",))
    with pytest.raises(InvalidChoiceError, match="unknown skin 'glass'; choose one of cut"):
        render.Renderer(model, skin="glass")
    with pytest.raises(CassiError, match="distinct"):
        render.Renderer(model, views=("side", "side"))
    with pytest.raises(CassiError, match="size"):
        render.Renderer(model, size=(4, 4))


def test_save_png_round_trip_and_refusals(tmp_path, renderer, model):
    from PIL import Image

    img = renderer.render(model.vertices)
    path = render.save_png(tmp_path / "out" / "grid.png", img)
    np.testing.assert_array_equal(np.asarray(Image.open(path)), img)
    with pytest.raises(OutputExistsError):
        render.save_png(path, img, overwrite=False)
    register_input(path)
    with pytest.raises(OutputExistsError):
        render.save_png(path, img)


def test_png_gets_the_users_mode_and_spares_recording_data(tmp_path, renderer, model):
    import os

    img = renderer.render(model.vertices)
    old = os.umask(0o022)
    try:
        path = render.save_png(tmp_path / "still.png", img)
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o644
    pal = tmp_path / "PAL.DAT"
    pal.write_text("1 2\n")
    with pytest.raises(OutputExistsError, match="PAL.DAT: refusing to replace a palate trace"):
        render.save_png(pal, img)
    assert pal.read_text() == "1 2\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["PAL.DAT", "still.png"]


def test_jax_vertices_are_accepted(renderer, model):
    import jax.numpy as jnp

    a = renderer.render(jnp.asarray(model.vertices))
    np.testing.assert_array_equal(a, renderer.render(model.vertices))


@pytest.mark.slow
def test_the_face_model_renders_in_all_views():
    from cassi_fit.face_model import load_model

    face = load_model()
    with render.Renderer(face, size=SIZE) as r:
        views = r.render_views(np.asarray(face.vertices))
    skin = np.array(render.MATERIAL_COLOURS["skin"]) * 255
    for name, img in views.items():
        assert (np.all(img == img[0, 0], axis=-1)).mean() < 0.9, name
    near_skin = np.linalg.norm(views["front"].astype(float) - skin, axis=-1) < 40
    assert near_skin.mean() > 0.1


def test_front_view_is_not_mirrored(model):
    """The model's +z is the subject's left: in the front view it is on the image's right."""
    one_eye = SimpleNamespace(**vars(model))
    eye_faces = model.face_material == 2
    left_eye = model.vertices[model.faces].mean(axis=1)[:, 2] > 0
    keep = ~eye_faces | left_eye
    one_eye.faces, one_eye.face_material = model.faces[keep], model.face_material[keep]
    with render.Renderer(one_eye, size=SIZE, views=("front",), colours=TEST_COLOURS) as r:
        img = r.render(model.vertices)
    white = np.all(img > 200, axis=-1) & ~np.all(img == img[0, 0], axis=-1)
    cols = np.nonzero(white.any(axis=0))[0]
    assert cols.size and cols.min() > SIZE[0] // 2


def test_an_unclosed_renderer_does_not_break_the_others(renderer, model):
    import gc

    before = renderer.render(model.vertices)
    other = render.Renderer(model, size=(64, 48), views=("top",))
    other.render(model.vertices)
    del other
    gc.collect()
    np.testing.assert_array_equal(renderer.render(model.vertices), before)


def test_views_are_clipped_to_their_cells(renderer, model):
    """A tongue moved far out of the inside view's cell never shows in the top view's cell.

    Moved 220 mm forward and 149 mm up, the inside view would draw it on the background
    near the top cell's upper-left corner; the top view itself puts it off the image.
    """
    moved = model.vertices.copy()
    tongue = np.unique(model.faces[model.face_material == 4])
    moved[tongue, :2] += (220.0, 149.0)
    cells = quadrants(renderer.render(moved))
    assert green(cells["top"]).sum() == 0
    assert green(cells["inside"]).sum() == 0


def test_culling_hidden_faces_changes_no_pixel(renderer, model):
    with render.Renderer(model, size=SIZE, colours=TEST_COLOURS, cull=False) as double:
        np.testing.assert_array_equal(
            double.render(model.vertices), renderer.render(model.vertices)
        )
    assert any(p.cull for p in renderer.pieces)  # culling did happen
    inside = [p for p in renderer.pieces if p.material == "skin" and "inside" in p.views]
    assert inside and all(p.cull is None for p in inside)  # the cut's inside shows


def test_winding_is_read_from_the_signed_volume():
    sphere = trimesh.creation.icosphere(subdivisions=1)
    v, f = np.asarray(sphere.vertices) * 30 + 5, np.asarray(sphere.faces)
    assert render.triangle_winding(v, f) == 1
    assert render.triangle_winding(v, f[:, ::-1]) == -1
    sheet_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    assert render.triangle_winding(sheet_v, np.array([[0, 1, 2], [1, 3, 2]])) == 0


def test_antialiasing_softens_edges_only(model, views):
    with render.Renderer(model, size=SIZE, views=("side",), colours=TEST_COLOURS, antialias=4) as r:
        smooth = r.render(model.vertices)
    changed = np.any(smooth != views["side"], axis=-1)
    assert 0 < changed.mean() < 0.1  # the silhouette's pixels, not the picture


def _with_hair(model, edge_y):
    """The stand-in with a ``hair`` field: hair above ``edge_y`` mm (signed distance)."""
    return SimpleNamespace(**vars(model), fields={"hair": np.asarray(model.vertices)[:, 1] - edge_y})


def test_hair_field_darkens_the_skin_above_its_edge_with_a_sharp_line(model):
    """The model's ``hair`` field (signed distance to the hair's edge, mm) colours the skin:
    dark above the edge, unchanged below, and the edge is a line a few pixels wide at its
    height, not the triangles' staircase (the stand-in's triangles are 15-25 mm across)."""
    with render.Renderer(model, size=SIZE, views=("front",), colours=TEST_COLOURS) as r:
        bare = r.render(model.vertices).astype(int)
    edges = []
    for edge_y in (40.0, 70.0):
        hairy = _with_hair(model, edge_y)
        with render.Renderer(hairy, size=SIZE, views=("front",), colours=TEST_COLOURS) as r:
            img = r.render(model.vertices).astype(int)
        changed = np.abs(img - bare).sum(axis=-1) > 30
        rows = np.nonzero(changed.any(axis=1))[0]
        assert rows.size > 10
        below = rows.max()  # the edge: the lowest changed image row (image y grows down)
        above = img[: below - 3][blue(bare[: below - 3])]
        assert above.size and above[:, 2].mean() < 0.6 * bare[: below - 3][blue(bare[: below - 3])][:, 2].mean()
        np.testing.assert_array_equal(img[below + 3 :], bare[below + 3 :])  # bare skin below
        # the edge is level across the head: its row varies by a pixel or two
        cols = np.nonzero(changed[below])[0]
        lowest = [np.nonzero(changed[:, c])[0].max() for c in range(cols.min(), cols.max() + 1)
                  if changed[:, c].any()]
        assert np.ptp(lowest) <= 3
        edges.append(below)
    assert edges[0] > edges[1] + 10  # the edge 30 mm lower is lower in the image


def test_a_model_without_hair_is_drawn_as_before(model, views):
    """No ``hair`` field, or one without a positive value: the skin keeps its colour."""
    no_hair = SimpleNamespace(**vars(model), fields={"hair": np.full(len(model.vertices), -5.0)})
    with render.Renderer(no_hair, size=SIZE, colours=TEST_COLOURS) as r:
        np.testing.assert_array_equal(r.render(model.vertices), r.render(model.vertices))
        img = r.render_views(model.vertices)
    for name in views:
        np.testing.assert_array_equal(img[name], views[name])


def test_mouth_walls_are_drawn_in_the_front_view_only(model, views):
    """A model's ``mouth_wall`` region (the walls that close the open mouth) is drawn in the
    front view, in the walls' colour, and not in the inside view, which would see the
    walls edge on as stray lines, nor in the top view, nor from the side, where the cheeks
    hide them. Here the stand-in's tongue plays the walls."""
    tongue = np.unique(model.faces[model.face_material == 4])
    walled = SimpleNamespace(**vars(model), regions={"mouth_wall": tongue})
    colours = {**TEST_COLOURS, "mouth_wall": TEST_COLOURS["tongue"]}
    with render.Renderer(walled, size=SIZE, colours=colours) as r:
        pieces = [p for p in r.pieces if p.material == "mouth_wall"]
        img = r.render_views(model.vertices)
    assert pieces and all(p.views == ("front",) for p in pieces)
    assert all(p.cull is None for p in pieces)  # open sheets: no winding to cull by
    assert green(views["inside"]).sum() > 100 and green(img["inside"]).sum() == 0
    assert green(img["top"]).sum() == 0
    for name in ("front", "side"):
        np.testing.assert_array_equal(img[name], views[name])
