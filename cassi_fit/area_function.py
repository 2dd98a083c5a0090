"""The area function of a frame: the model's midsagittal airway, glottis to lips (JAX).

The airway's two walls in the midsagittal plane (model frame, mm), glottis first:

* the *front/lower wall*: the glottis, straight up the front of the larynx to the tongue's
  hyoid end, the tongue's upper midline back to its tip, the lower incisor's tip, the lower
  lip's inner and upper midline points (every one a vertex of the posed frame, so it moves
  with the jaw, the tongue and the lips);
* the *back/upper wall*: the posterior pharyngeal wall (the model's wall from ``PHA.DAT``,
  ``cassi_fit.pharynx``) extended further down in a straight line along its lowest segment
  (the wall follows the cervical spine, nearly straight from C2 to C6) to below the
  glottis; the oral surface of the velum and the hard palate (``cassi_fit.palate``, the
  subject's ``PAL.DAT``), the upper incisor's tip and the upper lip's lower midline points.

**The larynx** (the model has none): the glottis lies ``larynx_drop_mm`` below the tongue's
hyoid end (the hyoid body at about C3, the vocal folds at about C5-C6 in adult men: about
two vertebrae, ``GLOTTIS_BELOW_HYOID_MM`` = 30 mm by default; a per-subject parameter, and
the handle acoustic calibration moves for the vocal tract's length), and
``GLOTTIS_DEPTH_MM`` in front of the wall (the male glottis is about 16 mm long front to
back, Hirano et al. 1988's adult men: 14-17 mm). An adult woman's larynx sits higher
(``LARYNX_DROP_MM["female"]`` = 15 mm: ten women's vocal folds 8.25 cm and hyoid 6.73 cm
below the palate, means, in a midsagittal real-time MRI of a sustained vowel at habitual
pitch and loudness, "Morphophysiological adjustments of the larynx and vocal tract of
young women during the dynamic vocal analysis by dynamic magnetic resonance", Voice
Foundation symposium abstract, voicefoundation.org 2026-abstracts entry 6958: the folds
15.2 mm below the hyoid; the male 30 mm is not measured the same way, and no ratio of
female to male pharynx length could be read here, ``docs/ACOUSTICS.md``);
:func:`default_tract` takes the speaker (``male`` by default; the female 15 mm rests on
that one abstract and is an option, ``cassi_fit.acoustics.speaker_norms``).

**The tongue base** (below T4, the last pellet: no pellet sees it): the model's template
placed it for the synthetic corpus's walls (``pharynx.DEFAULT_WALL``, x = -66..-78 mm): the
hyoid end about 32 mm in front of C3 (Bibby & Preston 1981, Am J Orthod 80:92-97: C3-H
31.8 +- 2.9 mm), the base about 10-15 mm in front of the wall (McNamara 1984, Am J Orthod
86:449-469; ``docs/TONGUE.md``). Both placements are measured from the cervical spine, which
the subject's own wall (``PHA.DAT``) follows; a subject whose wall lies elsewhere keeps the
template's base against the template's wall (JW11's wall lies 22.7 mm behind it: its /a/
pharynx was wide open, ``docs/ACOUSTICS.md``). The area function carries the base by the
difference of the two walls in x at the hyoid end's height
(``TractGeometry.base_shift_x``): in full at the hyoid end, falling linearly in the rest
arc length to nothing at T4 (the linear fall of CASSI's fixed tongue anchor,
``cassi_fit.tongue``), so the pellets' tongue is kept exactly. A subject without
``PHA.DAT`` has the template's wall and is not moved. The posed mesh is not changed: the
face's renderer still draws the template's base.

**The tongue root** (the same stretch below T4, the tongue's free surface facing the
pharynx) keeps the tongue's midsagittal area. The tongue is a muscular hydrostat: its
volume is constant (Kier & Smith 1985, Zool. J. Linn. Soc. 83:307-324), so tissue the
pellets show going up in front must come from somewhere, and in cineradiographic tongue
shapes it comes from the root: the root advances as the front of the tongue rises (/i/)
and retracts toward the pharyngeal wall as the dorsum lowers (/a/), the "front raising"
factor of Harshman, Ladefoged & Goldstein (1977, JASA 62:693-707). The model's posed
tongue keeps its volume by its width (``tongue.keep_volume``), which widens or narrows it
evenly and leaves the root where the pellets' displacement spreads it. Here, for the
airway, the midsagittal section (the polygon of the tongue's upper midline, base carried,
and its lower midline, the floor and the genial/hyoid attachment) is kept at its rest
area instead: the base's points move in x by one shift (:func:`root_shift`) times
``base_weight`` (0 at T4, 1 at the hyoid end, as the carry), the shift that makes the
area the rest's (exact in one step: the shoelace area is linear in x). Nothing is fitted:
the rest area is the subject's model at rest (``TractGeometry.rest_midsagittal_mm2``;
None turns it off). The posed mesh is not changed.

**The lips' width** (no midsagittal sensor sees it): the lips' sections take their area
from the midsagittal opening by Soquet et al.'s labial rule (below), which holds for their
speakers' lips as they were, not for lips rounded or spread. As the lips come forward
(rounding) the opening narrows across: in Maeda's (1990) lip model (Maeda, "Compensatory
articulation during speech", in Hardcastle & Marchal, *Speech Production and Speech
Modelling*, Kluwer, 131-149; a factor analysis of one French speaker's lateral and frontal
lip films: the jaw, the lips' protrusion, height and width), the regression of the width
on the protrusion and the height that its lip factor loadings and standard deviations
imply (as its specification, ``pb1_spec.dat``, distributed with Maeda's VTCalcs, gives
them; R^2 0.78) falls 1.72 mm per mm of protrusion at a fixed height, of that speaker's
mean width of 24.4 mm: ``LIP_WIDTH_PER_MM`` = 7.0 % per mm. The lips' sections' areas are multiplied by
``1 - LIP_WIDTH_PER_MM * protrusion`` (:func:`lip_protrusion`: the lips' forward
displacement from the subject's rest, the mean of the upper lip's and of the lower lip's
relative to the lower incisor, which carries it with the jaw, at their inner midsagittal
points, which the conformation's lip thickness does not move; in the subject's mm; spread
lips, behind their rest, widen), held at nothing (then at ``MIN_AREA_MM2``). The height
dependence stays Soquet's (their rule already widens the opening as it opens); the model's
rest (``TractGeometry.lip_rest_x``; None turns the narrowing off) has the published rule
unchanged.

**Cross-distances to areas**: the front wall is resampled at ``N_SECTIONS`` points equally
spaced in arc length; each point's cross-distance ``d`` is its distance to the nearest
segment of the back wall (unsigned; a tongue through the palate gives a small area, not a
negative one); the section's centre is the middle of that chord, and the sections' lengths
follow the centres' path (so the tract's length moves with the larynx, the tongue and the
lips). ``d`` becomes an area by ``A = alpha d^beta`` (d in cm, A in cm^2) with the region's
coefficients of Soquet, Lecuit, Metens & Demolin (2002, Speech Commun. 36:169-180; male
speakers, MRI): larynx, lower, middle and upper (oro-) pharynx, velum, hard palate,
alveolar region, lips. The region is the back wall's where the nearest point lies. The
coefficients stay as published: calibration scales them through :class:`TractParams`
(``area_scale`` for all, ``pharynx_scale`` for the pharynx, ``lip_scale`` for the lips), never
by refitting them on the scored data. An area below ``MIN_AREA_MM2`` is held there (a
closure is not modelled: the tube needs a finite area).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .deform import tongue_midline
from .errors import MissingDataError
from .face_model import FaceModel

N_SECTIONS = 40
GLOTTIS_BELOW_HYOID_MM = 30.0
#: The adult norms' glottis below the tongue's hyoid end, mm, by speaker (module docstring)
LARYNX_DROP_MM = {"male": GLOTTIS_BELOW_HYOID_MM, "female": 15.0}
GLOTTIS_DEPTH_MM = 16.0
WALL_EXTENSION_MM = 60.0  # how far below the model's wall the straight extension reaches
MIN_AREA_MM2 = 5.0
ALVEOLAR_X_MM = -15.0  # palate in front of this (about the alveolar ridge's back) is alveolar

REGIONS = ("larynx", "low pharynx", "mid pharynx", "oropharynx", "velum", "hard palate",
           "alveolar", "labial")
# Soquet et al. (2002), male speakers: alpha (cm^(2-beta)), beta, per region above
ALPHA = np.array([0.78, 1.86, 1.74, 1.99, 1.84, 1.82, 2.67, 2.42])
BETA = np.array([0.7, 1.22, 1.23, 0.81, 0.93, 1.43, 1.48, 1.67])
PHARYNX_REGIONS = np.array([0, 1, 1, 1, 0, 0, 0, 0], bool)
LIP_REGIONS = np.array([0, 0, 0, 0, 0, 0, 0, 1], bool)
#: The lip opening's width lost per mm of protrusion, relative (module docstring, *the
#: lips' width*: Maeda 1990's lip model, 1.72 mm per mm of a mean width of 24.4 mm)
LIP_WIDTH_PER_MM = 1.72 / 24.4


class TractParams(eqx.Module):
    """A speaker's vocal-tract parameters (acoustic calibration's unknowns), scalars:
    ``larynx_drop_mm`` the glottis below the tongue's hyoid end; ``area_scale``,
    ``pharynx_scale``, ``lip_scale`` multiply the published alpha of every region, of the
    three pharyngeal regions and of the lips (the airway's width across, which the
    midsagittal section does not see)."""

    larynx_drop_mm: Float[Array, ""]
    area_scale: Float[Array, ""]
    pharynx_scale: Float[Array, ""]
    lip_scale: Float[Array, ""]


def default_tract(dtype=float, speaker: str = "male") -> TractParams:
    """The published rules unscaled and the adult norm's larynx of ``speaker`` (``male``
    or ``female``: :data:`LARYNX_DROP_MM`); ``ValueError`` for another."""
    if speaker not in LARYNX_DROP_MM:
        raise ValueError(f"speaker {speaker!r}: one of {', '.join(LARYNX_DROP_MM)}")
    one = jnp.asarray(1.0, dtype)
    return TractParams(jnp.asarray(LARYNX_DROP_MM[speaker], dtype), one, one, one)


class TractGeometry(eqx.Module):
    """What the area function needs of one subject's model: the vertex indices of the
    front wall and of the upper lip (static: the model's topology), and the back wall's
    fixed parts (the wall, palate and velum do not move with the frames) as segments with
    their regions. What differs between subjects of one topology (the wall, the palate,
    the regions and heights) is data, not static: a compiled function of the geometry
    serves every subject."""

    tongue_tops: tuple[int, ...] = eqx.field(static=True)
    lower: tuple[int, ...] = eqx.field(static=True)
    upper: tuple[int, ...] = eqx.field(static=True)
    wall: Float[Array, "h 2"]
    palate: Float[Array, "p 2"]
    palate_region: Int[np.ndarray, " p1"]
    hyoid_y: Float[np.ndarray, ""]
    velum_tip_y: Float[np.ndarray, ""]
    back_region: Int[np.ndarray, " s"] | None = None
    base_weight: Float[np.ndarray, " t"] | None = None
    base_shift_x: Float[np.ndarray, ""] | None = None
    tongue_bottoms: tuple[int, ...] = eqx.field(static=True, default=())
    rest_midsagittal_mm2: Float[np.ndarray, ""] | None = None
    lip_rest_x: Float[np.ndarray, " 2"] | None = None


def _lip_points(model: FaceModel, region: str, upper: bool) -> np.ndarray:
    """The lip's two midsagittal vertices facing the mouth opening, inner first."""
    idx = np.asarray(model.regions[region])
    v = np.asarray(model.vertices)[idx]
    mid = idx[np.abs(v[:, 2]) < 0.3]
    if len(mid) < 2:
        raise MissingDataError(f"the face model's {region} has fewer than two midsagittal vertices")
    y = np.asarray(model.vertices)[mid, 1]
    pick = mid[np.argsort(y)[:2]] if upper else mid[np.argsort(-y)[:2]]
    return pick[np.argsort(np.asarray(model.vertices)[pick, 0])]


def tract_geometry(model: FaceModel) -> TractGeometry:
    """The :class:`TractGeometry` of a subject's model (with its palate and pharynx):
    ``MissingDataError`` if the model lacks a palate, a pharynx or the tube tongue."""
    from .palate import N_ACROSS as P_ACROSS
    from .palate import N_ALONG, N_HARD
    from .pharynx import N_ACROSS as W_ACROSS
    from .pharynx import front_sheet, has_pharynx

    if not has_pharynx(model) or "palate" not in model.regions:
        raise MissingDataError("the area function needs the model's palate and pharyngeal wall")
    vertices = np.asarray(model.vertices)
    _, top = tongue_midline(model)
    tops = np.array(sorted(set(top.tolist())))  # station order: tip -> hyoid end
    wall = np.asarray(front_sheet(model, jnp.asarray(vertices)))[:, W_ACROSS // 2, :2]
    palate_idx = np.asarray(model.regions["palate"])[: N_ALONG * P_ACROSS]
    palate = vertices[palate_idx.reshape(N_ALONG, P_ACROSS)[:, P_ACROSS // 2], :2]  # front -> back
    rows = np.arange(N_ALONG - 1)
    mid_x = 0.5 * (palate[:-1, 0] + palate[1:, 0])
    region = np.where(rows >= N_HARD - 1, 4, np.where(mid_x < ALVEOLAR_X_MM, 5, 6))
    lm = model.landmarks
    lower = np.concatenate([[lm["lower_incisor_tip"]], _lip_points(model, "lower_lip", False)])
    upper = np.concatenate([[lm["upper_incisor_tip"]], _lip_points(model, "upper_lip", True)])
    as_ints = lambda x: tuple(int(i) for i in np.asarray(x).reshape(-1))  # noqa: E731
    geometry = TractGeometry(as_ints(tops), as_ints(lower), as_ints(upper), jnp.asarray(wall),
                             jnp.asarray(palate), np.asarray(region, np.int32),
                             np.asarray(vertices[tops[-1], 1], np.float64),
                             np.asarray(palate[-1, 1], np.float64))
    weight, shift = _base_transfer(model, tops, wall)
    geometry = dataclasses.replace(geometry,
                                   back_region=np.asarray(_wall_regions(geometry), np.int32),
                                   base_weight=weight, base_shift_x=shift,
                                   tongue_bottoms=as_ints(_tongue_bottoms(model, tops)))
    area = midsagittal_area(geometry, jnp.asarray(vertices))
    return dataclasses.replace(geometry, rest_midsagittal_mm2=np.asarray(area, np.float64),
                               lip_rest_x=np.asarray(_lip_x(geometry, vertices), np.float64))


def _lip_x(geometry: TractGeometry, vertices):
    """``(2,)``: the upper lip's inner midsagittal point's x, and the lower lip's less the
    lower incisor tip's (the jaw carries the lower lip), model mm. The inner points move
    with the lips' displacements in full and not with the lip thickness of the subject's
    conformation (which moves the outer, vermilion points: no protrusion)."""
    x = jnp.asarray(vertices)[:, 0]
    return jnp.stack([x[geometry.upper[1]], x[geometry.lower[1]] - x[geometry.lower[0]]])


def lip_protrusion(geometry: TractGeometry, vertices) -> Float[Array, ""]:
    """How far (model mm, + forward) the lips of ``vertices (V, 3)`` are forward of the
    subject's rest: the mean of the upper lip's and of the lower lip's (relative to the
    lower incisor) forward displacement (module docstring, *the lips' width*); 0 without
    ``lip_rest_x``."""
    if geometry.lip_rest_x is None:
        return jnp.zeros((), vertices.dtype)
    x = _lip_x(geometry, vertices)
    return jnp.mean(x - jnp.asarray(geometry.lip_rest_x, x.dtype))


def _tongue_bottoms(model: FaceModel, tops: np.ndarray) -> np.ndarray:
    """The lower-midline vertex (ring vertex ``R / 2``, the attached side: the floor of the
    mouth and the genial/hyoid attachment) of each station whose upper-midline vertex is
    ``tops`` (tip -> hyoid end), ``deform.tongue_midline``'s layout."""
    ring = (model.landmarks["T2"] - model.landmarks["T1"]) // 4
    return np.asarray(tops) + ring // 2


def _carried_tongue(geometry: TractGeometry, vertices):
    """The tongue's upper midline ``(t, 2)``, hyoid end -> tip, with the base carried to the
    subject's wall (module docstring, *the tongue base*)."""
    g = geometry
    tongue = vertices[np.asarray(g.tongue_tops[::-1]), :2]
    if g.base_weight is not None:
        carry = jnp.asarray(g.base_weight[::-1], tongue.dtype) * jnp.asarray(g.base_shift_x, tongue.dtype)
        tongue = tongue.at[:, 0].add(carry)
    return tongue


def _midsagittal_area(upper, lower):
    """The area (mm^2) of the tongue's midsagittal section: the polygon of its upper midline
    ``upper`` (hyoid end -> tip) and its lower midline ``lower`` (tip -> hyoid end), by the
    shoelace formula (linear in the points' x at fixed y)."""
    p = jnp.concatenate([upper, lower])
    x, y = p[:, 0], p[:, 1]
    return 0.5 * jnp.abs(jnp.sum(x * jnp.roll(y, -1) - jnp.roll(x, -1) * y))


def midsagittal_area(geometry: TractGeometry, vertices) -> Float[Array, ""]:
    """The area (mm^2) of the tongue's midsagittal section in ``vertices (V, 3)`` (one
    frame), its base carried to the subject's wall and its root not moved."""
    return _midsagittal_area(_carried_tongue(geometry, vertices),
                             vertices[np.asarray(geometry.tongue_bottoms), :2])


def root_shift(geometry: TractGeometry, vertices):
    """How far (mm, +x forward) the tongue root moves so that the tongue's midsagittal
    section keeps its rest area (module docstring, *the tongue root*): 0 without
    ``rest_midsagittal_mm2``. The base's points move by this times ``base_weight`` (0 at T4,
    1 at the hyoid end); the shoelace area is linear in them, so one step is exact."""
    g = geometry
    if g.rest_midsagittal_mm2 is None or g.base_weight is None:
        return jnp.zeros((), vertices.dtype)
    upper = _carried_tongue(g, vertices)
    lower = vertices[np.asarray(g.tongue_bottoms), :2]
    area = _midsagittal_area(upper, lower)  # midsagittal_area, its parts kept for the step
    w = jnp.asarray(g.base_weight[::-1], vertices.dtype)  # hyoid end -> tip, as upper
    moved = _midsagittal_area(upper.at[:, 0].add(w), lower)  # the area's change per mm forward
    return (jnp.asarray(g.rest_midsagittal_mm2, vertices.dtype) - area) / (moved - area)


def lip_opening(geometry: TractGeometry, vertices) -> np.ndarray:
    """The lips' opening (model mm) of ``vertices (..., V, 3)``: the upper lip's lowest
    midsagittal point above the lower lip's highest (negative: the lips cross), per frame
    (numpy; the midsagittal lip points after the incisor tips, ``geometry.upper[1:]`` and
    ``geometry.lower[1:]``)."""
    v = np.asarray(vertices)
    upper, lower = np.asarray(geometry.upper[1:]), np.asarray(geometry.lower[1:])
    return v[..., upper, 1].min(-1) - v[..., lower, 1].max(-1)


def _line_x(points: np.ndarray, y: float) -> float:
    """The x at height ``y`` of the straight line through a wall's last two points."""
    (x0, y0), (x1, y1) = np.asarray(points, np.float64)[-2:]
    return float(x0 + (x1 - x0) * (y - y0) / (y1 - y0))


def _base_transfer(model: FaceModel, tops: np.ndarray, wall: np.ndarray):
    """``(weight (t,), shift_x)``: how far the tongue base is carried to this subject's
    pharyngeal wall (module docstring, *the tongue base*). ``tops`` tip -> hyoid end; the
    weight is 0 up to T4 and rises linearly in the rest arc length to 1 at the hyoid end;
    the shift is the subject's wall minus the template's (``pharynx.DEFAULT_WALL``) in x
    at the hyoid end's height, both walls as the straight lines of their lowest stretch."""
    from .pharynx import DEFAULT_WALL

    s = np.asarray(model.fields["tongue_s"], np.float64)[tops]
    s_t4 = float(s[np.nonzero(tops == model.landmarks["T4"])[0][0]])
    weight = np.clip((s - s_t4) / (s[-1] - s_t4), 0.0, 1.0)
    y_h = float(np.asarray(model.vertices)[tops[-1], 1])
    # to a hundredth of a millimetre: the model's single-precision vertices round the
    # template's own wall by about 1e-4 mm, which must carry nothing
    shift = round(_line_x(wall, y_h) - _line_x(DEFAULT_WALL, y_h), 2)
    return weight, np.asarray(shift, np.float64)


def _nearest(p, a, b):
    """Distance from ``p (2,)`` to the segments ``a -> b (s, 2)`` and the nearest points."""
    ab = b - a
    t = jnp.clip(jnp.sum((p[None] - a) * ab, -1) / jnp.sum(ab * ab, -1), 0.0, 1.0)
    q = a + t[:, None] * ab
    d2 = jnp.sum((p[None] - q) ** 2, -1)
    return d2, q


def _resample(line, n):
    """``n`` points equally spaced in arc length along ``line (k, 2)``, centred in their
    stretches (differentiable in the points)."""
    seg = jnp.sqrt(jnp.sum(jnp.diff(line, axis=0) ** 2, -1))
    s = jnp.concatenate([jnp.zeros(1, line.dtype), jnp.cumsum(seg)])
    q = (jnp.arange(n, dtype=line.dtype) + 0.5) / n * s[-1]
    return jnp.stack([jnp.interp(q, s, line[:, 0]), jnp.interp(q, s, line[:, 1])], -1)


def _walls(geometry: TractGeometry, vertices, params: TractParams):
    """The front wall ``(k, 2)`` and the back wall's segments ``a -> b`` (their regions:
    :func:`_wall_regions`, in the same order)."""
    g = geometry
    tongue = _carried_tongue(g, vertices)  # hyoid end -> tip
    if g.rest_midsagittal_mm2 is not None:  # the root keeps the section's rest area
        tongue = tongue.at[:, 0].add(jnp.asarray(g.base_weight[::-1], tongue.dtype)
                                     * root_shift(g, vertices))
    hyoid = tongue[0]
    w = g.wall
    down = (w[-1] - w[-2]) / jnp.linalg.norm(w[-1] - w[-2])
    wall = jnp.concatenate([w, (w[-1] + WALL_EXTENSION_MM * down)[None]])  # top -> bottom
    y_g = hyoid[1] - params.larynx_drop_mm
    # the extended wall's x at the glottis's height (its last stretch is straight)
    x_wall = w[-1, 0] + down[0] * (y_g - w[-1, 1]) / down[1]
    glottis = jnp.stack([x_wall + GLOTTIS_DEPTH_MM, y_g])
    front = jnp.concatenate([glottis[None], tongue, vertices[np.asarray(g.lower), :2]])
    lips = vertices[np.asarray(g.upper), :2]
    a = jnp.concatenate([wall[:-1], g.palate[:-1], g.palate[:1], lips[:-1]])
    b = jnp.concatenate([wall[1:], g.palate[1:], lips[:1], lips[1:]])
    return front, a, b


def _wall_regions(geometry: TractGeometry) -> np.ndarray:
    """Each back-wall segment's region, from the rest geometry (static)."""
    w = np.asarray(geometry.wall)
    down = (w[-1] - w[-2]) / np.linalg.norm(w[-1] - w[-2])
    wall = np.concatenate([w, (w[-1] + WALL_EXTENSION_MM * down)[None]])
    mid_y = 0.5 * (wall[:-1, 1] + wall[1:, 1])
    hyoid_y, velum_tip_y = float(geometry.hyoid_y), float(geometry.velum_tip_y)
    third = (velum_tip_y - hyoid_y) / 3.0
    wall_region = np.where(mid_y < hyoid_y, 0,
                           np.clip(1 + (mid_y - hyoid_y) // third, 1, 3)).astype(int)
    return np.concatenate([wall_region, np.asarray(geometry.palate_region), [6],
                           [7] * (len(geometry.upper) - 1)])


def area_function(
    geometry: TractGeometry, vertices: Float[Array, "V 3"], params: TractParams,
    scale: float | Float[Array, ""] = 1.0,
) -> tuple[Float[Array, " n"], Float[Array, " n"], Int[Array, " n"]]:
    """``(areas mm^2, lengths mm, regions)`` ``(N_SECTIONS,)`` of one posed frame, glottis
    first (module docstring), in the subject's millimetres: ``scale`` is the model's mm per
    subject mm (``SubjectState.scale``); ``regions`` index :data:`REGIONS`. Differentiable in
    the vertices and ``params``; vmap over frames (:func:`area_functions`)."""
    params = eqx.tree_at(lambda p: p.larynx_drop_mm, params, params.larynx_drop_mm * scale)
    front, a, b = _walls(geometry, vertices, params)
    region_of = jnp.asarray(geometry.back_region, jnp.int32)
    points = _resample(front, N_SECTIONS)

    def one(p):
        d2, q = _nearest(p, a, b)
        k = jnp.argmin(d2)
        return d2[k], q[k], region_of[k]

    d2, q, region = jax.vmap(one)(points)
    ok = d2 > 0
    d_cm = jnp.where(ok, jnp.sqrt(jnp.where(ok, d2, 1.0)), 0.0) / (10.0 * scale)
    alpha = jnp.asarray(ALPHA, d_cm.dtype)[region] * params.area_scale
    alpha = alpha * jnp.where(jnp.asarray(PHARYNX_REGIONS)[region], params.pharynx_scale, 1.0)
    rounding = jnp.maximum(1.0 - LIP_WIDTH_PER_MM * lip_protrusion(geometry, vertices) / scale, 0.0)
    alpha = alpha * jnp.where(jnp.asarray(LIP_REGIONS)[region], params.lip_scale * rounding, 1.0)
    beta = jnp.asarray(BETA, d_cm.dtype)[region]
    pos = d_cm > 0
    area = jnp.where(pos, alpha * jnp.exp(beta * jnp.log(jnp.where(pos, d_cm, 1.0))), 0.0) * 100.0
    area = jnp.maximum(area, MIN_AREA_MM2)
    centre = 0.5 * (points + q)
    step = jnp.sqrt(jnp.sum(jnp.diff(centre, axis=0) ** 2, -1))
    lengths = 0.5 * (jnp.concatenate([step[:1], step]) + jnp.concatenate([step, step[-1:]]))
    return area, lengths / scale, region


def area_functions(
    geometry: TractGeometry, vertices: Float[Array, "m V 3"], params: TractParams,
    scale: float | Float[Array, ""] = 1.0,
) -> tuple[Float[Array, "m n"], Float[Array, "m n"], Int[Array, "m n"]]:
    """:func:`area_function` of every frame of ``vertices (m, V, 3)``."""
    return jax.vmap(lambda v: area_function(geometry, v, params, scale))(vertices)


def tract_length(lengths: Float[Array, "... n"]) -> Float[Array, "..."]:
    """The vocal tract's length (mm): the sum of its sections."""
    return jnp.sum(lengths, axis=-1)
