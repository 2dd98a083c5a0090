"""The midsagittal view (issue 13): the mesh cut at z = 0 (known meshes give the expected
contours), drawn into its cell of the grid (it changes where the tongue moves), and the
matplotlib figure for notebooks."""

import numpy as np
import pytest
import trimesh
from test_render import SIZE, TEST_COLOURS, green, standin_model

from cassi_fit import render
from cassi_fit.render import Section, section_polylines, section_segments


def _box(centre=(0.0, 0.0, 0.0), extents=(2.0, 2.0, 2.0)):
    box = trimesh.creation.box(extents=extents)
    return np.asarray(box.vertices) + centre, np.asarray(box.faces)


def test_a_cube_cut_at_its_middle_is_one_closed_square():
    vertices, faces = _box()
    segments, edges = section_segments(vertices, faces)
    assert len(segments) == 8  # two triangles per side face, each cut once
    (points, closed), = section_polylines(segments, edges)
    assert closed
    np.testing.assert_allclose(np.abs(points).max(axis=1), 1.0, atol=1e-5)  # on the square
    ring = np.vstack([points, points[:1]])
    perimeter = np.linalg.norm(np.diff(ring, axis=0), axis=1).sum()
    assert perimeter == pytest.approx(8.0, abs=1e-4)


def test_a_plane_off_centre_and_a_mesh_beside_it():
    vertices, faces = _box(extents=(2.0, 4.0, 2.0))
    (points, closed), = section_polylines(*section_segments(vertices, faces, z=0.5))
    assert closed and np.ptp(points[:, 1]) == pytest.approx(4.0)
    beside, _ = _box(centre=(0.0, 0.0, 5.0))
    assert section_polylines(*section_segments(beside, faces)) == []


def test_vertices_on_the_plane_still_chain_into_one_loop():
    """An octahedron with four vertices exactly at z = 0: the cut is their square."""
    vertices = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])
    faces = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4],
                      [1, 0, 5], [2, 1, 5], [3, 2, 5], [0, 3, 5]])  # fmt: skip
    (points, closed), = section_polylines(*section_segments(vertices, faces))
    assert closed
    for corner in vertices[:4, :2]:
        assert np.linalg.norm(points - corner, axis=1).min() < 1e-5


@pytest.fixture(scope="module")
def face():
    from cassi_fit.face_model import MATERIALS, load_model

    model = load_model()
    section = Section(model.vertices, model.faces, model.face_material, MATERIALS,
                      regions=model.regions, landmarks=model.landmarks,
                      measures=model.measures)  # fmt: skip
    return model, section


def _distance(point, lines):
    return min(np.linalg.norm(p - point, axis=1).min() for p, _ in lines)


def test_the_rest_model_section_passes_through_its_midline_sites(face):
    model, section = face
    rest = np.asarray(model.vertices)
    contours = section.contours(rest)
    assert {"skin", "lips", "teeth", "tongue", "palate", "jaw"} <= set(contours)
    tongue = contours["tongue"]
    assert any(closed for _, closed in tongue)  # the tongue's section is a closed outline
    for name in ("T1", "T2", "T3", "T4"):  # pellet sites on the dorsum, at z = 0
        assert _distance(rest[model.landmarks[name], :2], tongue) < 0.5, name
    teeth = [p for p, closed in contours["teeth"] if closed]
    tip = rest[model.landmarks["upper_incisor_tip"], :2]
    assert _distance(tip, contours["teeth"]) < 1.0  # the upper incisor's section
    assert min(p[:, 1].min() for p in teeth) < -5 < max(p[:, 1].max() for p in teeth)  # both
    for name in ("UL", "LL"):
        assert _distance(rest[model.landmarks[name], :2], contours["skin"] + contours["lips"]) < 1.0
    # the mouth's back wall (skin material, no anatomy) is not drawn: every skin point the
    # section draws at the wall's depth lies outside the wall's height range
    wall = rest[np.asarray(model.regions["mouth_wall"])]
    wall = wall[wall[:, 0] == wall[:, 0].min()]  # the back wall (the cheek curtains are off z=0)
    x, (lo, hi) = wall[0, 0], (wall[:, 1].min(), wall[:, 1].max())
    skin = np.concatenate([p for p, _ in contours["skin"]])
    assert not np.any((np.abs(skin[:, 0] - x) < 0.5) & (skin[:, 1] > lo) & (skin[:, 1] < hi))


def test_the_section_follows_the_posed_vertices(face):
    model, section = face
    moved = np.asarray(model.vertices).copy()
    moved[model.regions["tongue"], 1] += 5.0
    before = np.concatenate([p for p, _ in section.contours(model.vertices)["tongue"]])
    after = np.concatenate([p for p, _ in section.contours(moved)["tongue"]])
    assert after[:, 1].max() == pytest.approx(before[:, 1].max() + 5.0, abs=1e-6)
    # the schematic jaw moves with the lower teeth
    dropped = np.asarray(model.vertices).copy()
    dropped[model.regions["lower_teeth"], 1] -= 4.0
    jaw0 = section.contours(model.vertices)["jaw"][0][0]
    jaw1 = section.contours(dropped)["jaw"][0][0]
    np.testing.assert_allclose(jaw1 - jaw0, [[0.0, -4.0]] * len(jaw0), atol=1e-6)


# -- in the renderer ---------------------------------------------------------------------------

render_test = pytest.mark.render

FIVE = ("front", "side", "inside", "top", "midsagittal")


@pytest.fixture(scope="module")
def five(standin):
    traces = {"palate": np.array([[-50.0, 8.0], [-30.0, 10.0], [-10.0, 8.0]]), "pharynx": None}
    with render.Renderer(standin, size=SIZE, views=FIVE, colours=TEST_COLOURS,
                         traces=traces) as r:  # fmt: skip
        yield r


@pytest.fixture(scope="module")
def standin():
    return standin_model()


def _cell(img, k):  # the 3x2 grid's k-th cell; the fifth (midsagittal) is two wide
    h, w = img.shape[0] // 2, img.shape[1] // 3
    right = img.shape[1] if k == 4 else (k % 3 + 1) * w
    return img[(k // 3) * h : (k // 3 + 1) * h, (k % 3) * w + 2 : right]


@render_test
def test_the_grid_holds_five_views_and_the_section_moves_with_the_tongue(five, standin):
    rest = standin.vertices
    raised = rest.copy()
    tongue = np.unique(standin.faces[standin.face_material == 4])
    raised[tongue, 1] += 8.0
    a, b = five.render(rest), five.render(raised)
    assert a.shape == (SIZE[1], SIZE[0], 3)
    section_a, section_b = _cell(a, 4), _cell(b, 4)
    background = np.all(section_a == section_a[2, -3], axis=-1)
    assert 0.02 < (~background).mean() < 0.6  # contours drawn, not a filled cell
    rows_a = np.nonzero(green(section_a).any(axis=1))[0]  # the tongue's outline (green here)
    rows_b = np.nonzero(green(section_b).any(axis=1))[0]
    assert rows_b.min() < rows_a.min() - 3  # higher in the image
    assert green(_cell(a, 2)).sum() > 20  # the GL cells are still drawn (inside view)
    top = _cell(a, 3)
    assert np.any(top != top[0, 0], axis=-1).sum() > 500  # the top view, left of the section
    assert np.all(a[SIZE[1] // 2 + 2 :, SIZE[0] // 3 + 2] == section_a[2, -3])  # its edge


@render_test
def test_pellets_trails_and_time_are_drawn_in_the_section(five, standin):
    from test_render import red

    plain = _cell(five.render(standin.vertices), 4)
    trail = np.array([[[-40.0, -20.0]], [[-35.0, -15.0]], [[-30.0, -10.0]]])
    marked = _cell(five.render(standin.vertices, trails={"measured": trail}, time=1.25), 4)
    assert red(plain).sum() == 0 and red(marked).sum() > 10
    assert np.any(plain[:20, :80] != marked[:20, :80])  # "t = 1.250 s" in the corner


def _extent(mask):
    """``(centre x, centre y, width, height)`` in pixels of the drawn pixels ``mask``."""
    ys, xs = np.nonzero(mask)
    assert len(xs), "nothing drawn in that colour"
    return (xs.min() + xs.max()) / 2, (ys.min() + ys.max()) / 2, np.ptp(xs) + 1, np.ptp(ys) + 1


def _yellow(img):  # lips
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > b + 60) & (g > b + 60)


@render_test
@pytest.mark.parametrize("size", [SIZE, (80, 60)])
def test_the_section_alone_is_the_model_cut_to_scale(standin, size):
    """The midsagittal view alone (no GL view), of a model without regions or jaw
    landmarks: the stand-in's tongue (an ellipsoid 60 x 24 mm at z = 0) is drawn as an
    ellipse of that shape, and its lips (16 x 20 mm, 62 mm ahead and 7 mm above the
    tongue's centre) in front of it, at the same scale in x and y."""
    with render.Renderer(standin, size=size, views=("midsagittal",), colours=TEST_COLOURS) as r:
        image = r.render(standin.vertices)
    assert image.shape == (size[1], size[0], 3)
    tx, ty, tw, th = _extent(green(image))
    lx, ly, lw, lh = _extent(_yellow(image))
    px = (lx - tx) / 62.0  # pixels per mm; > 0: +x (the front) is to the right
    assert px > 0.5
    tol = 3.0  # pixels: the outlines' width, the mesh's facets
    assert ty - ly == pytest.approx(7.0 * px, abs=tol)  # +y (up) is up, at the same scale
    for drawn, mm in ((tw, 60.0), (th, 24.0), (lw, 16.0), (lh, 20.0)):
        assert drawn == pytest.approx(mm * px, abs=tol), (drawn, mm, px)


@render_test
def test_the_grid_draws_the_same_section_in_its_cell(five, standin):
    """``render_views``' midsagittal image is the section cell's drawing: the tongue in
    the same proportions as drawn alone."""
    alone = five.render_views(standin.vertices)["midsagittal"]
    assert alone.shape == (SIZE[1], SIZE[0], 3)
    _, _, width, height = _extent(green(alone))
    assert width / height == pytest.approx(60.0 / 24.0, rel=0.06)


# -- the figure --------------------------------------------------------------------------------


def test_the_figure_names_its_parts(face):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cassi_fit import midsagittal_figure

    model, _ = face
    sites = np.asarray(model.vertices)[[model.landmarks[n] for n in ("T1", "T2")], :2]
    fig = midsagittal_figure(
        model, model.vertices, traces={"palate": [[-40, 20], [-10, 12]], "pharynx": None},
        pellets=sites, trail=np.stack([sites - 1, sites]), time=0.25,
    )  # fmt: skip
    (ax,) = fig.axes
    labels = {line.get_label() for line in ax.lines}
    assert {"tongue", "palate", "teeth", "skin", "palate trace", "jaw (schematic)",
            "pellets", "pellet trails"} <= labels  # fmt: skip
    assert "pharynx trace" not in labels
    assert ax.patches and "0.250" in ax.get_title()
    plt.close(fig)


def test_bad_traces_and_vertices_are_clear_errors(face):
    from cassi_fit import CassiError, midsagittal_figure

    model, section = face
    with pytest.raises(CassiError, match="palate trace"):
        section.set_traces({"palate": np.zeros(5)})
    with pytest.raises(CassiError, match="vertices"):
        midsagittal_figure(model, np.zeros((3, 3)))
