"""Measured quantities of one animation: the sites read, per-frame geometry, statistics.

Geometry (model frame, mm: origin at the upper incisor tip, +x front, +y up): the upper
and lower dental arches are the model's collision chains (``FaceModel.collision``, each
station numbered by its tooth, 0 = central incisor); the lips' edges are the lowest
upper-lip and the highest lower-lip vertex on the midline (z = 0 at rest: rows "A" and
"B" of ``model/build_model.py``); the palate's oral sheet is the first half of the
palate region (``cassi_fit.palate`` layout).

Statistics over frames. A problem CASSI saw "at times" (the tongue through the teeth, the
teeth overlapping, the lips never touching) is measured as a *sustained* extreme: the
most extreme value held for at least ``SUSTAIN_S`` (50 ms, 7 data lines at 145.6 Hz),
i.e. the maximum over time of the running minimum (or the reverse). One bad frame cannot
decide it, but a 100 ms lip closure or tongue poke does. Percentiles were not used for
these because they scale with the recording's length (the 95th percentile needs 1 s of
a 20 s paragraph but 30 ms of a short word). A problem that is a *look* (lips too tightly
together, the lower lip protruding, the tongue hidden, the lips beyond the teeth) is
measured on the median frame.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..collide import FRONT_TEETH, REPORT_KEYS, airway_frames, has_collision_data, report_frames
from ..errors import DegenerateGeometryError, MissingDataError
from ..frames import frame_bucket, pad_frames
from ..palate import N_ACROSS, N_ALONG, N_HARD
from ..tongue import tongue_volumes

if TYPE_CHECKING:
    from ..animate import Animation
    from ..face_model import FaceModel
    from ..initialize import SubjectState

#: A problem "seen at times" must hold this long (s). 50 ms is 7 data lines at 145.6 Hz:
#: longer than a mistracked burst the quality check lets through (1-3 lines), shorter
#: than the briefest bilabial closure or tongue-tip contact (60-150 ms).
SUSTAIN_S = 0.05
#: A frame has no airway when the least tongue-to-pharyngeal-wall distance
#: (``collide.airway``) is at most this (mm): the tongue on the wall (where projection
#: leaves it, ``collide.PROJECTION_MARGIN_MM`` in front) or through it.
AIRWAY_CLOSED_MM = 0.01


@dataclass(frozen=True)
class MeasureSpec:
    """One measured quantity: unit, how a subject combines recordings (``"max"``: the
    worst/most-closed over tasks, ``"min"``: the closest approach over tasks) and whether
    a problem is counted from it."""

    unit: str
    combine: str
    counted: bool
    description: str


MEASURES: dict[str, MeasureSpec] = {
    "lower_slope_deg": MeasureSpec(
        "deg", "max", True, "lower occlusal slope vs the upper, jaw most closed (+ up)"),
    "front_overlap_mm": MeasureSpec(
        "mm", "max", True, "lower incisal edge above the upper incisal edge (sustained)"),
    "back_overlap_mm": MeasureSpec(
        "mm", "max", True, "lower back crown above the upper back crown's level (sustained)"),
    "teeth_gap_mm": MeasureSpec(
        "mm", "min", True, "closest interocclusal gap (sustained)"),
    "teeth_in_upper_lip_mm": MeasureSpec(
        "mm", "max", True, "upper lip point inside the teeth (sustained)"),
    "teeth_in_lower_lip_mm": MeasureSpec(
        "mm", "max", True, "lower lip point inside the teeth (sustained)"),
    "lip_gap_min_mm": MeasureSpec(
        "mm", "min", True, "closest midline lip gap (sustained)"),
    "lip_gap_median_mm": MeasureSpec(
        "mm", "min", True, "midline lip gap in the median frame (< 0: crossing)"),
    "upper_lip_above_teeth_mm": MeasureSpec(
        "mm", "max", True, "upper lip edge above the upper incisors' cervical level (median)"),
    "lower_lip_below_teeth_mm": MeasureSpec(
        "mm", "max", True, "lower lip edge below the lower incisors' cervical level (median)"),
    "lower_lip_protrusion_mm": MeasureSpec(
        "mm", "max", True, "lower lip front ahead of the upper lip front (median)"),
    "tongue_upper_front_mm": MeasureSpec(
        "mm", "max", True, "tongue depth in the upper front teeth (sustained)"),
    "tongue_lower_front_mm": MeasureSpec(
        "mm", "max", True, "tongue depth in the lower front teeth (sustained)"),
    "tongue_behind_incisors_mm": MeasureSpec(
        "mm", "min", True, "free tongue's front behind the lower incisors' lingual face "
        "(median)"),
    "tongue_back_v_deg": MeasureSpec(
        "deg", "max", True, "sharpest concave (V) bend of the tongue's back midline, T3 to "
        "the root (sustained; not counted)"),
    "tongue_palate_mm": MeasureSpec(
        "mm", "max", True, "tongue depth in the palate (sustained; not counted)"),
    "palate_below_incisor_mm": MeasureSpec(
        "mm", "max", True, "palate's lowest point below the upper incisor tip (not counted)"),
    # before collision projection (equal to the above when collisions are off): reported
    "tongue_upper_front_before_mm": MeasureSpec(
        "mm", "max", False, "as tongue_upper_front_mm, before projection"),
    "tongue_lower_front_before_mm": MeasureSpec(
        "mm", "max", False, "as tongue_lower_front_mm, before projection"),
    "tongue_palate_before_mm": MeasureSpec(
        "mm", "max", False, "as tongue_palate_mm, before projection"),
    "teeth_in_lips_before_mm": MeasureSpec(
        "mm", "max", False, "deepest lip point in the teeth, before projection"),
    # the airway between the tongue and the pharyngeal wall (collide.airway): reported
    "airway_min_mm": MeasureSpec(
        "mm", "min", False, "least tongue-to-pharyngeal-wall distance over the frames "
        "(front-back; < 0: through the wall)"),
    "frames_without_airway": MeasureSpec(
        "frames", "max", False, "frames whose airway is at most AIRWAY_CLOSED_MM"),
    "tongue_pharynx_before_mm": MeasureSpec(
        "mm", "max", False, "deepest tongue point behind the pharyngeal wall, before "
        "projection (sustained)"),
    # the tongue's volume over the frames (docs/TONGUE.md; ~0 for CASSI's flat sheet)
    "tongue_volume_min_ml": MeasureSpec(
        "mL", "min", False, "smallest tongue volume over the frames (reported)"),
    "tongue_volume_max_ml": MeasureSpec(
        "mL", "max", False, "largest tongue volume over the frames (reported)"),
}  # fmt: skip


def combine(measures: Sequence[Mapping[str, float]]) -> dict[str, float]:
    """One subject's measures from its recordings' ``measures`` dicts, each measure
    combined by ``MEASURES[name].combine``: the worst over tasks (``"max"``), or the
    closest approach over tasks (``"min"``). A measure missing from every dict is left out.
    """
    if not measures:
        raise MissingDataError("no evaluated recording to combine")
    out = {}
    for name, spec in MEASURES.items():
        values = [m[name] for m in measures if name in m]
        if values:
            out[name] = float(max(values) if spec.combine == "max" else min(values))
    return out


# ----------------------------------------------------------------------------- geometry
@dataclass(frozen=True, eq=False)
class _Sites:
    """Vertex indices :func:`measure` reads, from the model (all static numpy)."""

    upper_tip: int
    lower_tip: int
    upper_molar: np.ndarray  # lingual occlusal stations of the last upper crown (both sides)
    lower_molar: np.ndarray
    upper_back: np.ndarray  # occlusal stations of the upper back teeth (tooth > 2)
    lower_back: np.ndarray
    upper_cervical: np.ndarray  # cervical stations of the upper central incisors
    lower_cervical: np.ndarray
    lower_lingual_front: np.ndarray  # lingual occlusal stations of the lower centrals
    upper_lip_mid: np.ndarray
    lower_lip_mid: np.ndarray
    upper_lip: np.ndarray
    lower_lip: np.ndarray
    tongue: np.ndarray
    palate_oral: np.ndarray
    tongue_back: np.ndarray  # upper-midline vertices from T3's station to the root, in order

    def all(self) -> np.ndarray:
        parts = [np.atleast_1d(np.asarray(getattr(self, f))) for f in self.__dataclass_fields__]
        return np.concatenate(parts).astype(np.int64)



    def layout(self) -> tuple[tuple[str, int], ...]:
        """``(field, number of indices)`` in ``all()``'s order: hashable, so the compiled
        per-frame kernel is keyed on it (not on the model)."""
        return tuple((f, int(np.atleast_1d(np.asarray(getattr(self, f))).size))
                     for f in self.__dataclass_fields__)


def _chain_stations(
    model: FaceModel, arch: str, chains: tuple[str, ...], select: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """Indices of the stations of ``chains`` whose tooth number satisfies ``select``."""
    tooth = np.asarray(model.collision[f"{arch}_tooth"])
    keep = select(tooth)
    return np.concatenate([np.asarray(model.collision[f"{arch}_{c}"])[keep] for c in chains])


def _sites(model: FaceModel) -> _Sites:
    """The vertex sets of the measures; raises ``MissingDataError`` if the model lacks any."""
    if not has_collision_data(model):
        raise MissingDataError(
            "the face model has no dental arch chains (model.json 'collision'); the "
            "evaluation needs them: rebuild the model with model/build_model.py"
        )
    for name in ("upper_incisor_tip", "lower_incisor_tip"):
        if name not in model.landmarks:
            raise MissingDataError(f"the face model has no {name!r} landmark")
    rest = np.asarray(model.vertices)
    occlusal, cervical = ("lingual_occlusal", "labial_occlusal"), ("lingual_cervical",
                                                                   "labial_cervical")
    last = {a: int(np.max(model.collision[f"{a}_tooth"])) for a in ("upper", "lower")}

    def midline(region):
        index = np.asarray(model.regions.get(region, []), np.int64)
        mid = index[np.abs(rest[index, 2]) < 1e-6]
        if mid.size == 0:
            raise MissingDataError(f"the face model's {region!r} region has no midline vertex")
        return mid

    palate = np.asarray(model.regions.get("palate", []), np.int64)
    if palate.size != 2 * N_ALONG * N_ACROSS:
        raise MissingDataError("the face model's palate region is not a cassi_fit.palate mesh")
    tongue = np.asarray(model.regions.get("tongue", []), np.int64)
    if tongue.size == 0:
        raise MissingDataError("the face model has no tongue region")
    # the free tongue (the part the pellets move fully: its upper surface and tip), which
    # shows between the teeth; the floor of the mouth, hung from the mandible, reaches
    # forward under the lower incisors and would hide a tongue pulled back
    free = tongue[np.asarray(model.fields["tongue_follow"])[tongue] > 0.999]
    tongue = free if free.size else tongue
    return _Sites(
        upper_tip=model.landmarks["upper_incisor_tip"],
        lower_tip=model.landmarks["lower_incisor_tip"],
        # lingual stations only: the labial ones of the last lower molar carry the MNM
        # pellet site, which sits below the crown's occlusal level
        upper_molar=_chain_stations(
            model, "upper", ("lingual_occlusal",), lambda t: t == last["upper"]),
        lower_molar=_chain_stations(
            model, "lower", ("lingual_occlusal",), lambda t: t == last["lower"]),
        upper_back=_chain_stations(model, "upper", occlusal, lambda t: t > FRONT_TEETH),
        lower_back=_chain_stations(model, "lower", occlusal, lambda t: t > FRONT_TEETH),
        upper_cervical=_chain_stations(model, "upper", cervical, lambda t: t == 0),
        lower_cervical=_chain_stations(model, "lower", cervical, lambda t: t == 0),
        lower_lingual_front=_chain_stations(
            model, "lower", ("lingual_occlusal",), lambda t: t == 0),
        upper_lip_mid=midline("upper_lip"),
        lower_lip_mid=midline("lower_lip"),
        upper_lip=np.asarray(model.regions["upper_lip"], np.int64),
        lower_lip=np.asarray(model.regions["lower_lip"], np.int64),
        tongue=tongue,
        palate_oral=palate[: N_HARD * N_ACROSS],  # the hard palate (not the velum)
        tongue_back=_tongue_back(model),
    )


def _tongue_back(model: FaceModel) -> np.ndarray:
    """The tongue's upper-midline vertices from T3's cross-section to the root, tip to
    root order (``deform.tongue_midline``): where CASSI saw its V (section 4)."""
    from ..deform import tongue_midline

    tops = np.unique(tongue_midline(model)[1])  # station order: the tube is built tip first
    start = int(np.searchsorted(tops, model.landmarks["T3"]))
    back = tops[start:]
    if back.size < 3:
        raise MissingDataError("the face model's tongue has fewer than 3 stations behind T3")
    return back



def _split(layout: tuple[tuple[str, int], ...], points: Float[Array, "*b k 3"]) -> dict:
    """``points (..., K, 3)`` gathered at ``_Sites.all()`` -> dict of the parts."""
    out, start = {}, 0
    for name, n in layout:
        out[name] = points[..., start : start + n, :]
        start += n
    return out


def _angle_deg(back, front):
    """Angle (deg) of the side-view line from ``back (3,)`` to ``front (3,)``."""
    d = front - back
    return jnp.degrees(jnp.arctan2(d[1], d[0]))


def back_v_deg(midline: Float[Array, "k 3"]) -> Float[Array, ""]:
    """The sharpest concave bend (deg) of a tongue midline ``(k, 3)`` (x, y used), tip to
    root order: at each interior point the turn from the incoming to the outgoing
    segment, + clockwise in the side view (+x front, +y up), which along a tongue running
    backwards is a valley, a V; a dome turns the other way. The largest such turn; <= 0
    when the whole back is convex."""
    d = jnp.diff(midline[:, :2], axis=0)
    cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    dot = jnp.sum(d[:-1] * d[1:], -1)
    return jnp.max(-jnp.degrees(jnp.arctan2(cross, dot)))


def _frame_quantities(parts: dict) -> dict:
    """One frame's raw quantities (mm, deg) from the gathered points (see ``_Sites``)."""
    p = parts
    upper_tip, lower_tip = p["upper_tip"][0], p["lower_tip"][0]
    slope = _angle_deg(p["lower_molar"].mean(0), lower_tip) - _angle_deg(
        p["upper_molar"].mean(0), upper_tip
    )
    front = lower_tip[1] - upper_tip[1]
    # each lower back station against the nearest upper back station (in x-z: top view)
    lo, up = p["lower_back"], p["upper_back"]
    xz = jnp.array([0, 2])
    d2 = jnp.sum((lo[:, None, xz] - up[None, :, xz]) ** 2, -1)
    back = jnp.max(lo[:, 1] - up[jnp.argmin(d2, axis=1), 1])
    upper_edge = jnp.min(p["upper_lip_mid"][:, 1])
    lower_edge = jnp.max(p["lower_lip_mid"][:, 1])
    return {
        "slope": slope,
        "front": front,
        "back": back,
        "teeth_gap": -jnp.maximum(front, back),
        "lip_gap": upper_edge - lower_edge,
        "upper_lip_above": upper_edge - jnp.mean(p["upper_cervical"][:, 1]),
        "lower_lip_below": jnp.mean(p["lower_cervical"][:, 1]) - lower_edge,
        "protrusion": jnp.max(p["lower_lip"][:, 0]) - jnp.max(p["upper_lip"][:, 0]),
        "tongue_behind": jnp.mean(p["lower_lingual_front"][:, 0]) - jnp.max(p["tongue"][:, 0]),
        "palate_below": upper_tip[1] - jnp.min(p["palate_oral"][:, 1]),
        "back_v": back_v_deg(p["tongue_back"]),
    }


@eqx.filter_jit
def _frame_kernel(
    points: Float[Array, "m k 3"], layout: tuple[tuple[str, int], ...]
) -> dict[str, Float[Array, " m"]]:
    """Every frame's raw quantities, vmapped; compiled once per (frame bucket, layout)."""
    return jax.vmap(lambda pts: _frame_quantities(_split(layout, pts)))(points)


def _per_frame(sites: _Sites, points: Float[Array, "m k 3"]) -> dict[str, np.ndarray]:
    """Raw quantities of every frame, ``(m,)`` numpy each, from ``points (m, K, 3)``.

    One compiled, vmapped call; frames are padded to a size bucket
    (``frames.frame_bucket``) so recordings of similar length share the compilation.
    """
    m = points.shape[0]
    out = _frame_kernel(pad_frames(points, frame_bucket(m)), sites.layout())
    return {k: np.asarray(v)[:m] for k, v in out.items()}


def sustain_frames(times: Float[ArrayLike, " m"]) -> int:
    """Frames in ``SUSTAIN_S`` for frame times ``times (m,)`` s (at least 1)."""
    times = np.asarray(times, np.float64)
    if times.size < 2:
        return 1
    from ..txy import frame_step

    period = frame_step(times)
    if not period > 0:
        raise DegenerateGeometryError("frame times do not increase")
    return max(1, int(round(SUSTAIN_S / period)))


def sustained_max(x: Float[ArrayLike, " m"], window: int) -> float:
    """The largest value ``x (m,)`` keeps for ``window`` consecutive frames: max over
    time of the running minimum (the whole series' minimum if shorter)."""
    x = np.asarray(x, np.float64)
    w = max(1, min(int(window), x.size))
    return float(np.lib.stride_tricks.sliding_window_view(x, w).min(-1).max())


def sustained_min(x: Float[ArrayLike, " m"], window: int) -> float:
    """The smallest value ``x (m,)`` keeps for ``window`` consecutive frames."""
    return -sustained_max(-np.asarray(x, np.float64), window)


def penetration_of(
    model: FaceModel, vertices: Float[ArrayLike, "m v 3"]
) -> dict[str, Float[np.ndarray, " m"]]:
    """``collide.report`` of every frame of ``vertices (m, V, 3)``: key -> ``(m,)`` mm.

    For geometry that did not come from ``animate.animate`` (which reports it itself);
    frames padded to ``frames.frame_bucket`` sizes, compiled once per model content.
    """
    vertices = jnp.asarray(vertices)
    m = vertices.shape[0]
    padded = pad_frames(vertices, frame_bucket(m))
    out = report_frames(model, padded)
    return {k: np.asarray(v)[:m] for k, v in out.items()}


def _penetration(model: FaceModel, anim: Animation) -> tuple[dict, dict]:
    """``(before, after)`` dicts of ``(m,)`` mm from the animation (or computed)."""
    before = getattr(anim, "penetration", None) or {}
    after = getattr(anim, "penetration_after", None) or before
    if not all(k in after for k in REPORT_KEYS):
        after = penetration_of(model, anim.vertices)
        before = before if all(k in before for k in REPORT_KEYS) else after
    return before, after


def airway_of(
    model: FaceModel, vertices: Float[ArrayLike, "m v 3"]
) -> Float[np.ndarray, " m"]:
    """``collide.airway`` of every frame of ``vertices (m, V, 3)``: ``(m,)`` mm, the
    least front-back distance from the tongue to the pharyngeal wall per frame (< 0:
    through it; +inf: no tongue vertex within the wall's height). Frames padded to
    ``frames.frame_bucket`` sizes."""
    vertices = jnp.asarray(vertices)
    m = vertices.shape[0]
    return np.asarray(airway_frames(model, pad_frames(vertices, frame_bucket(m))))[:m]


def measure(state: SubjectState, anim: Animation) -> dict[str, float]:
    """Per-recording measured quantities (floats, mm and degrees; keys ``MEASURES``).

    ``state``: the ``SubjectState`` (only ``state.model`` is read: landmarks, regions and
    collision chains); ``anim``: the ``Animation`` (``vertices (m, V, 3)``, the final
    geometry; ``times (m,)`` s; ``penetration``/``penetration_after``, per-frame depths
    before/after collision projection; computed with ``collide.report`` if absent).
    Penetration measures come from the final geometry (``penetration_after``), what a
    viewer sees; the ``*_before_mm`` ones from before projection. Raises
    ``DegenerateGeometryError`` when the geometry is not finite (never rated as NaN).
    """
    model = state.model
    vertices = jnp.asarray(anim.vertices)
    if vertices.ndim != 3 or vertices.shape[0] == 0 or vertices.shape[-1] != 3:
        raise DegenerateGeometryError(
            f"the animation's vertices must be (m >= 1, V, 3), got {tuple(vertices.shape)}"
        )
    sites = _sites(model)
    raw = _per_frame(sites, jnp.take(vertices, jnp.asarray(sites.all()), axis=1))
    before, after = _penetration(model, anim)
    for name, values in (*raw.items(), *after.items(), *before.items()):
        bad = ~np.isfinite(values)
        if bad.any():
            raise DegenerateGeometryError(
                f"{getattr(state, 'source', 'animation')}: {name} is not finite in "
                f"{int(bad.sum())} of {bad.size} frames (first: frame {int(np.argmax(bad))})"
            )
    w = sustain_frames(getattr(anim, "times", np.zeros(1)))
    hi, lo, median = (lambda x: sustained_max(x, w)), (lambda x: sustained_min(x, w)), np.median
    out = {
        "lower_slope_deg": hi(raw["slope"]),
        "front_overlap_mm": hi(raw["front"]),
        "back_overlap_mm": hi(raw["back"]),
        "teeth_gap_mm": lo(raw["teeth_gap"]),
        "teeth_in_upper_lip_mm": hi(after["lips_upper_teeth"]),
        "teeth_in_lower_lip_mm": hi(after["lips_lower_teeth"]),
        "lip_gap_min_mm": lo(raw["lip_gap"]),
        "lip_gap_median_mm": median(raw["lip_gap"]),
        "upper_lip_above_teeth_mm": median(raw["upper_lip_above"]),
        "lower_lip_below_teeth_mm": median(raw["lower_lip_below"]),
        "lower_lip_protrusion_mm": median(raw["protrusion"]),
        "tongue_upper_front_mm": hi(after["tongue_upper_front"]),
        "tongue_lower_front_mm": hi(after["tongue_lower_front"]),
        "tongue_behind_incisors_mm": median(raw["tongue_behind"]),
        "tongue_back_v_deg": hi(raw["back_v"]),
        "tongue_palate_mm": hi(after["tongue_palate"]),
        "palate_below_incisor_mm": float(np.max(raw["palate_below"])),
        "tongue_upper_front_before_mm": hi(before["tongue_upper_front"]),
        "tongue_lower_front_before_mm": hi(before["tongue_lower_front"]),
        "tongue_palate_before_mm": hi(before["tongue_palate"]),
        "teeth_in_lips_before_mm": hi(
            np.maximum(before["lips_upper_teeth"], before["lips_lower_teeth"])
        ),
    }
    gap = airway_of(model, vertices)
    if np.isnan(gap).any():
        raise DegenerateGeometryError(
            f"{getattr(state, 'source', 'animation')}: the airway is not a number in "
            f"{int(np.isnan(gap).sum())} of {gap.size} frames")
    out["airway_min_mm"] = float(np.min(gap))
    out["frames_without_airway"] = float(np.sum(gap <= AIRWAY_CLOSED_MM))
    out["tongue_pharynx_before_mm"] = hi(before["tongue_pharynx"])
    volume = tongue_volumes(model, anim.vertices)
    out["tongue_volume_min_ml"], out["tongue_volume_max_ml"] = volume.min(), volume.max()
    return {k: float(v) for k, v in out.items()}

