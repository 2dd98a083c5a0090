"""A 3D palate from a subject's 2D palatal centreline (``PAL.DAT``), joined to the upper
teeth, with a soft palate (velum) behind it.

CASSI (section 2, "the palatal outline"): the palate is narrow at the front of the mouth
and wider toward the back, with a slight downward slope from its centreline to its
edges, and with thickness. Its report (section 4) notes that for two subjects the palate
reached below the tip of the upper front teeth; here every vertex is clamped to stay at
least ``margin`` mm above the upper incisor tip (y = 0 in the model frame).

**The hard palate joined to the teeth.** Given the upper arch's lingual cervical chain
(the crowns' inner necks, ``FaceModel.collision["upper_lingual_cervical"]``), the hard
palate's rows stand at the chain's stations: each row runs from the right neck over the
PAL.DAT centreline (its midline, at the station's x) to the left neck, so its lateral
edges *are* the teeth's necks (no gap). In front of the first station (the central
incisors' lingual necks) two rows close the palate toward the centreline's front end
(the alveolar ridge behind the incisors); behind the last molar two rows carry it to the
centreline's back end, the edges held at the last molar's neck. Without a chain (a bare
outline) the old parametric shape is used: half width and edge drop growing from front
to back. Across a row the oral surface is ``y = centre + (edge - centre) v^2`` (v from
-1 at the right edge to 1 at the left): the vault.

**The velum.** ``N_VELUM`` rows continue from the centreline's back end (taken as the
posterior nasal spine) down and back: length ``VELUM_LENGTH_MM``, at ``VELUM_ANGLE_DEG``
to the palatal plane (taken as the model's horizontal), thickest a third of the way
down (``VELUM_THICKNESS_MM``) and narrowing to the uvula. Adult values from lateral
cephalograms: the velum (PNS to the uvula tip) is about 30-35 mm long and 8-10 mm thick,
hanging at about 130 degrees to the palatal plane at rest (e.g. Verma et al. 2014,
Imaging Sci Dent 44(3):193-198, 300 adults; You et al. 2008, Dentomaxillofac Radiol
37(6):344-349). Given the pharyngeal wall's midline (``cassi_fit.pharynx``), the velum's
back surface is kept ``VELUM_WALL_GAP_MM`` in front of it: at rest the airway behind
the velum is about 6 mm deep in adults (velum-level sagittal distances, J Oral
Maxillofac Res 2017;8(3):e4), and in speech the velum rises against the wall for every
oral sound; a subject whose velum would reach the wall gets one that hangs down along it,
a narrow port open.

**A palate from the tongue's upper envelope** (:func:`envelope_palate`). An articulograph
recording rarely comes with a palate trace (EMA labs trace one with a sensor, but not every
corpus ships it), and the default centreline, placed in a frame estimated without a
reference sensor, need not be the speaker's: the real IPS speaker mo1's tongue sensors
never come within 6.5 mm of it, even in /d n l k/ closures and the tongue at rest before
speaking, so the model's close vowels had no palatal constriction (docs/ACOUSTICS.md). A
tongue sensor never passes above the palate, and the tongue reaches the palate's midline in
the closures of /t d n l k g/ and, for most speakers, at rest: the sensors' highest
positions over the recording bound the palate from below and touch it. The estimate is the
default centreline with its heights above the occlusal plane scaled by one factor, the least
that leaves every tracked tongue sensor on or below it (``max y / h(x)`` over the sensor
positions within the palate's extent along x, ``h`` the default's height there): speakers'
hard palates differ mostly in how high the dome rises, a shape the few sensors could not
trace point by point. No constant is fitted to the sound. XRMB's ``PAL.DAT`` is always
preferred; CASSI mode keeps the default (the paper's choice).

The mesh has a fixed vertex and face count whatever the outline's point count. Vertex
layout: ``[oral sheet (N_ALONG, N_ACROSS), nasal sheet (N_ALONG, N_ACROSS)]`` flattened
row-major, rows front to back (``N_HARD`` hard-palate rows, then ``N_VELUM`` velum rows),
columns from the subject's right (z < 0) to the left; every row of the oral sheet lies
at one x (the collision treats it as a height field). The nasal sheet lies ``thickness``
mm above the hard palate's oral sheet and the velum's thickness behind its oral surface.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._exported import exported
from .errors import DegenerateGeometryError
from .face_model import FaceModel
from .pharynx import concrete_points, replace_region, slab_faces

#: Upper lingual cervical stations per side of the model's arch (7 crowns, 2 each).
N_STATIONS = 14
N_FRONT = 2   # rows in front of the first station (toward the alveolar ridge)
N_BACK = 2    # rows behind the last molar
#: Hard-palate rows, velum rows, all rows.
N_HARD = N_FRONT + N_STATIONS + N_BACK
N_VELUM = 5
N_ALONG = N_HARD + N_VELUM
N_ACROSS = 7

#: Velum (soft palate) at rest; sources in the module docstring.
VELUM_LENGTH_MM = 32.0
VELUM_ANGLE_DEG = 130.0
VELUM_THICKNESS_MM = 9.0
UVULA_HALF_WIDTH_MM = 5.0
VELUM_WALL_GAP_MM = 2.0
#: The least half width of a palate row (mm): the central incisors' necks meet at the
#: midline, where a row of zero width would make zero-area triangles.
MIN_HALF_WIDTH_MM = 1.0
# velum thickness profile along its rows (fraction of VELUM_THICKNESS_MM), root to tip
_VELUM_PROFILE = (0.7, 1.0, 0.9, 0.75, 0.55)

# A default centreline (mm, front to back) shaped like the palates in XRMB PAL.DAT files.
DEFAULT_OUTLINE = np.array([
    (-4.0, 4.0), (-6.0, 8.5), (-9.0, 12.5), (-13.0, 16.0), (-18.0, 19.0), (-24.0, 21.5),
    (-31.0, 23.5), (-38.0, 25.0), (-45.0, 26.0), (-52.0, 26.7), (-60.0, 27.0)])


def _check_outline(outline):
    """Reject outlines for which no palate exists (only when the values are concrete)."""
    values = concrete_points(outline, "palate outline")
    if values is not None and np.sum(np.linalg.norm(np.diff(values, axis=0), axis=1)) <= 0.0:
        raise DegenerateGeometryError("palate outline has zero length (all points coincide)")


def resample(outline: Float[Array, "k 2"], n: int = N_HARD) -> Float[Array, "n 2"]:
    """``n`` points equally spaced in arc length along a polyline (k, 2) mm -> (n, 2)."""
    outline = jnp.asarray(outline)
    seg = jnp.linalg.norm(jnp.diff(outline, axis=0), axis=1)
    s = jnp.concatenate([jnp.zeros(1, seg.dtype), jnp.cumsum(seg)])
    q = jnp.linspace(0.0, 1.0, n, dtype=s.dtype) * s[-1]
    return jnp.stack([jnp.interp(q, s, outline[:, 0]), jnp.interp(q, s, outline[:, 1])], -1)


def palate_faces(n_along: int = N_ALONG, n_across: int = N_ACROSS) -> Int[np.ndarray, "Q 3"]:
    """Triangles (Q, 3) of the closed palate slab; outward-facing winding (the oral sheet
    faces down; ``pharynx.slab_faces``)."""
    return slab_faces(n_along, n_across)


def _height_at(outline, x):
    """The centreline's height at each ``x`` (held beyond its ends; its x made
    non-increasing from front to back first, so a trace that steps forward is read as
    flat there)."""
    fine = resample(outline, 48)
    xs = jax.lax.cummin(fine[:, 0])
    return jnp.interp(-x, -xs, fine[:, 1])


def _parametric_hard(outline, front_half_width, back_half_width, front_edge_drop,
                     back_edge_drop):
    """Rows (centre (N_HARD, 2), right edge (N_HARD, 3), left edge (N_HARD, 3)) of the
    hard palate without teeth to join: CASSI's narrow-front, wide-back shape."""
    centre = resample(outline)
    u = jnp.linspace(0.0, 1.0, N_HARD, dtype=centre.dtype)
    # half width rises quickly behind the alveolar ridge (sin), the drop linearly
    half = front_half_width + (back_half_width - front_half_width) * jnp.sin(jnp.pi / 2 * u)
    drop = front_edge_drop + (back_edge_drop - front_edge_drop) * u
    left = jnp.stack([centre[:, 0], centre[:, 1] - drop, half], -1)
    return centre, left * jnp.array([[1.0, 1.0, -1.0]], left.dtype), left


def _joined_hard(outline, arch):
    """The hard palate's rows joined to the upper arch's lingual cervical chain ``arch
    (2 N_STATIONS, 3)`` (right back molar -> front -> left back molar)."""
    arch = jnp.asarray(arch)
    left = arch[N_STATIONS:]
    right = arch[:N_STATIONS][::-1]
    dtype = left.dtype
    x_st = jax.lax.cummin(left[:, 0])  # stations front to back, x non-increasing
    fine = resample(outline, 48)
    x_front = jnp.maximum(fine[0, 0], x_st[0])
    x_back = jnp.minimum(jax.lax.cummin(fine[:, 0])[-1], x_st[-1])
    t_front = jnp.arange(N_FRONT, dtype=dtype) / N_FRONT
    t_back = jnp.arange(1, N_BACK + 1, dtype=dtype) / N_BACK
    x_rows = jnp.concatenate([x_front + (x_st[0] - x_front) * t_front, x_st,
                              x_st[-1] + (x_back - x_st[-1]) * t_back])
    centre = jnp.stack([x_rows, _height_at(outline, x_rows)], -1)

    def edges(side, sign):
        z = sign * jnp.maximum(sign * side[:, 2], MIN_HALF_WIDTH_MM)
        first = jnp.stack([x_rows[:N_FRONT], jnp.full(N_FRONT, side[0, 1], dtype),
                           jnp.full(N_FRONT, sign * MIN_HALF_WIDTH_MM, dtype)], -1)
        # the front rows narrow from the first neck to the midline's front end
        first = first.at[:, 2].set(z[0] + (sign * MIN_HALF_WIDTH_MM - z[0]) * (1 - t_front))
        mid = jnp.stack([x_rows[N_FRONT:N_FRONT + N_STATIONS], side[:, 1], z], -1)
        last = jnp.stack([x_rows[N_FRONT + N_STATIONS:], jnp.full(N_BACK, side[-1, 1], dtype),
                          jnp.full(N_BACK, z[-1], dtype)], -1)
        return jnp.concatenate([first, mid, last])

    return centre, edges(right, -1.0), edges(left, 1.0)


def _velum(centre, right, left, wall, thickness):
    """Velum rows: centre (N_VELUM, 2), right/left edges (N_VELUM, 3), thickness
    (N_VELUM,) and the unit normal (2,) toward its nasal side."""
    dtype = centre.dtype
    pns = centre[-1]
    a = jnp.deg2rad(180.0 - VELUM_ANGLE_DEG)
    d = jnp.array([-jnp.cos(a), -jnp.sin(a)], dtype)
    normal = jnp.array([-jnp.sin(a), jnp.cos(a)], dtype)
    f = jnp.arange(1, N_VELUM + 1, dtype=dtype) / N_VELUM
    c = pns[None] + (VELUM_LENGTH_MM * f)[:, None] * d[None]
    t = jnp.asarray(_VELUM_PROFILE, dtype) * VELUM_THICKNESS_MM
    if wall is not None:
        wall = jnp.asarray(wall, dtype)
        # the wall at the height of the back surface's midline point
        wall_x = jnp.interp(-(c[:, 1] + t * normal[1]), -wall[:, 1], wall[:, 0])
        # the back (nasal) surface, t * normal behind the oral one, stays gap mm in front
        c = c.at[:, 0].set(jnp.maximum(c[:, 0], wall_x + VELUM_WALL_GAP_MM - t * normal[0]))
    half_back = left[-1, 2]
    drop_back = pns[1] - left[-1, 1]
    half = half_back + (UVULA_HALF_WIDTH_MM - half_back) * f
    drop = drop_back + (2.0 - drop_back) * jnp.minimum(1.0, 2.0 * f)
    lv = jnp.stack([c[:, 0], c[:, 1] - drop, half], -1)
    return c, lv * jnp.array([[1.0, 1.0, -1.0]], dtype), lv, t, normal


def build_palate(
    outline_mm: Float[np.ndarray, "n 2"] | Float[Array, "n 2"], *,
    arch: Float[np.ndarray, "k 3"] | Float[Array, "k 3"] | None = None,
    wall: Float[np.ndarray, "w 2"] | Float[Array, "w 2"] | None = None,
    front_half_width: float = 8.0, back_half_width: float = 22.0, front_edge_drop: float = 3.0,
    back_edge_drop: float = 9.0, thickness: float = 3.0, margin: float = 1.0,
) -> tuple[Float[Array, "P 3"], Int[np.ndarray, "Q 3"]]:
    """Palate vertices ``(2 * N_ALONG * N_ACROSS, 3)`` mm and faces ``(Q, 3)``.

    ``outline_mm``: (n, 2) palatal centreline in the model frame (x front, y up), front to
    back, any n >= 2: the palate's midline. ``arch``: the upper arch's lingual cervical
    chain ``(2 * N_STATIONS, 3)`` (``FaceModel.collision["upper_lingual_cervical"]``
    positions): the hard palate's edges then run along it (module docstring); None: the
    parametric shape (``front_half_width`` ... ``back_edge_drop``). ``wall``: the
    pharyngeal wall's midline ``(w, 2)`` (x, y) top to bottom, or None: the velum's back
    surface is kept in front of it. Every vertex satisfies ``y >= margin`` (above the
    upper incisor tip): the oral sheet is clamped with ``maximum`` (gradient 0 through
    the clamped points, 1 elsewhere) and the nasal sheet is the clamped oral sheet moved
    by the thickness toward the nasal side. Differentiable in the outline, the arch and
    the wall; jit-compatible (the point counts are static).
    """
    _check_outline(outline_mm)
    outline = jnp.asarray(outline_mm)
    if arch is None:
        centre, right, left = _parametric_hard(outline, front_half_width, back_half_width,
                                               front_edge_drop, back_edge_drop)
    else:
        if jnp.shape(arch) != (2 * N_STATIONS, 3):
            raise DegenerateGeometryError(
                f"the arch chain must be ({2 * N_STATIONS}, 3), got {jnp.shape(arch)}")
        centre, right, left = _joined_hard(outline, jnp.asarray(arch, outline.dtype))
    vc, vr, vl, vt, vn = _velum(centre, right, left, wall, thickness)
    centre = jnp.concatenate([centre, vc])
    right = jnp.concatenate([right, vr])
    left = jnp.concatenate([left, vl])
    dtype = centre.dtype
    v = jnp.linspace(-1.0, 1.0, N_ACROSS, dtype=dtype)[None, :]
    v = 0.5 * (v - v[:, ::-1])  # exactly antisymmetric: a mirror-symmetric mesh
    side = jnp.where(v < 0, 1.0, 0.0)
    edge_y = side * right[:, 1:2] + (1 - side) * left[:, 1:2]
    y = centre[:, 1:2] + (edge_y - centre[:, 1:2]) * v**2
    z = jnp.where(v < 0, -v * right[:, 2:3], v * left[:, 2:3])
    x = jnp.broadcast_to(centre[:, :1], (N_ALONG, N_ACROSS))
    # the edges keep their own x (the chain's), the rest stand on the row's x
    x = x.at[:, 0].set(right[:, 0]).at[:, -1].set(left[:, 0])
    y = jnp.maximum(y, margin)
    oral = jnp.stack([x, y, z], -1)
    up = jnp.array([0.0, 1.0, 0.0], dtype)
    offset = jnp.concatenate([
        jnp.broadcast_to(thickness * up, (N_HARD, 3)),
        vt[:, None] * jnp.array([[vn[0], vn[1], 0.0]], dtype)])
    nasal = oral + offset[:, None, :]
    return jnp.concatenate([oral.reshape(-1, 3), nasal.reshape(-1, 3)]), palate_faces()


def model_arch(model: FaceModel) -> Float[Array, "k 3"] | None:
    """The model's upper lingual cervical chain positions, or None if it has none (or
    not ``2 * N_STATIONS`` stations)."""
    index = model.collision.get("upper_lingual_cervical") if model.collision else None
    if index is None or len(index) != 2 * N_STATIONS:
        return None
    if isinstance(model.vertices, jax.core.Tracer):
        return model.vertices[np.asarray(index)]
    return jax.device_put(np.asarray(model.vertices)[np.asarray(index)])  # no compilation


@exported
def _palate_vertices(outline, arch, wall, **shape):
    """``build_palate``'s vertices, compiled once per shape (op by op, its few hundred
    small operations cost seconds of dispatch and compilation per subject) and exported
    (:mod:`cassi_fit._exported`: a warm process loads it instead of tracing it again)."""
    return build_palate(outline, arch=arch, wall=wall, **shape)[0]


def with_palate(
    model: FaceModel, outline_mm: Float[np.ndarray, "n 2"] | Float[Array, "n 2"], **shape: float
) -> FaceModel:
    """The model with its palate region rebuilt from ``outline_mm`` (same topology), its
    edges on the model's upper teeth necks and its velum in front of the model's
    pharyngeal wall (when the model has them)."""
    from .pharynx import model_wall_midline

    _check_outline(outline_mm)  # on the concrete values: the compiled build cannot
    verts = _palate_vertices(jnp.asarray(outline_mm, jnp.asarray(model.vertices).dtype),
                             model_arch(model), model_wall_midline(model), **shape)
    return replace_region(model, "palate", verts, "build_palate",
                          ": the model was not built with cassi_fit.palate")


def envelope_factor(points: Float[np.ndarray, "n 2"],
                    outline: Float[np.ndarray, "k 2"] = DEFAULT_OUTLINE) -> tuple[float, int] | None:
    """``(factor, index)``: the least factor by which ``outline``'s heights (model mm, front
    to back) are scaled so that no point of ``points (n, 2)`` (model mm, NaN rows ignored)
    within the outline's extent along x lies above it, and the index of the point that then
    touches it (module docstring, *a palate from the tongue's upper envelope*); None when no
    point lies under the outline or the outline is not above the occlusal plane there."""
    outline = np.asarray(outline, np.float64)
    xs = np.minimum.accumulate(outline[:, 0])  # front to back, x non-increasing
    p = np.asarray(points, np.float64).reshape(-1, 2)
    under = np.isfinite(p).all(1) & (p[:, 0] <= xs[0]) & (p[:, 0] >= xs[-1])
    h = np.interp(-p[:, 0], -xs, outline[:, 1])
    under &= h > 0
    if not under.any():
        return None
    ratio = np.where(under, p[:, 1] / np.where(under, h, 1.0), -np.inf)
    k = int(np.argmax(ratio))
    return float(ratio[k]), k


def envelope_palate(track, roles: dict, scale: float) -> tuple[np.ndarray, str] | None:
    """``(outline (k, 2) model mm, note)``: the palate of a recording without a palate trace
    from its tongue sensors' upper envelope (:func:`envelope_factor` on the default
    centreline; ``track`` a :class:`~cassi_fit.txy.PelletTrack` in subject mm, ``scale``
    model mm per subject mm, ``roles`` the sensor name of each pellet role for the note),
    or None without a tracked tongue sensor under the palate. Untracked and mistracked
    values (``gaps.usable_values``) are not used."""
    from .gaps import usable_values
    from .pellets import PELLET_NAMES, T1, T4

    pos = scale * np.asarray(track.positions, np.float64)[:, T1:T4 + 1]
    good = usable_values(track)[:, T1:T4 + 1]  # a spike must not lift the palate
    pos = np.where(good[..., None], pos, np.nan)
    found = envelope_factor(pos.reshape(-1, 2))
    if found is None:
        return None
    factor, k = found
    frame, role = divmod(k, T4 - T1 + 1)
    name = roles.get(PELLET_NAMES[T1 + role]) or PELLET_NAMES[T1 + role]
    note = ("palate estimated from the tongue sensors' upper envelope: no palate trace (the "
            f"default palate's heights x{factor:.2f}, the least that no tongue sensor passes "
            f"above; {name} touches it at {float(track.times[frame]):.2f} s)")
    return DEFAULT_OUTLINE * np.array([1.0, factor]), note
