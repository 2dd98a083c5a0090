"""The objective evaluation: CASSI's Table 2 ratings from measured quantities.

CASSI (Scheidt & Hamilton 1999, section 4, Table 2) rated each subject's animation by eye:
teeth, lips and tongue each EXCELLENT, VERY GOOD, GOOD or FAIR by the number of problems
seen (0, 1, 2, 3 or more). Here every problem is a measured quantity with a documented
threshold (the module constants below; ``docs/EVALUATION.md``), and the ratings follow the
same counting rule.

Pipeline: :func:`measure` (one animation -> floats), :func:`problems` (floats -> the
problems counted, per component), :func:`rating` (a count -> a word);
:func:`evaluate_recording` and :func:`evaluate_dataset` run the animation and aggregate
per subject; :func:`write_table`, :func:`plot_summary` and :func:`compare` write the
results (Markdown in Table 2's layout, CSV, a figure).

Statistics over frames. A problem CASSI saw "at times" (the tongue through the teeth, the
teeth overlapping, the lips never touching) is measured as a *sustained* extreme: the
most extreme value held for at least ``SUSTAIN_S`` (50 ms, 7 data lines at 145.6 Hz),
i.e. the maximum over time of the running minimum (or the reverse). One bad frame cannot
decide it, but a 100 ms lip closure or tongue poke does. Percentiles were not used for
these because they scale with the recording's length (the 95th percentile needs 1 s of
a 20 s paragraph but 30 ms of a short word). A problem that is a *look* (lips too tightly
together, the lower lip protruding, the tongue hidden, the lips beyond the teeth) is
measured on the median frame.

Geometry (model frame, mm: origin at the upper incisor tip, +x front, +y up): the upper
and lower dental arches are the model's collision chains (``FaceModel.collision``, each
station numbered by its tooth, 0 = central incisor); the lips' edges are the lowest
upper-lip and the highest lower-lip vertex on the midline (z = 0 at rest: rows "A" and
"B" of ``model/build_model.py``); the palate's oral sheet is the first half of the
palate region (``cassi_fit.palate`` layout).
"""

from __future__ import annotations

import csv
import io
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .animate import frame_bucket, model_call, pad_frames
from .errors import CassiError, DegenerateGeometryError, MissingDataError

# ----------------------------------------------------------------------------- thresholds
#: A problem "seen at times" must hold this long (s). 50 ms is 7 data lines at 145.6 Hz:
#: longer than a mistracked burst the quality check lets through (1-3 lines), shorter
#: than the briefest bilabial closure or tongue-tip contact (60-150 ms).
SUSTAIN_S = 0.05

# Teeth ----------------------------------------------------------------------------
#: Lower occlusal line (lower molar occlusal point -> lower incisor tip) against the upper
#: one, with the jaw most closed, degrees, + = rising toward the front. Over the 40 mm
#: from the back molar to the incisor tip, 3 deg lifts the front 2.1 mm (a fifth of a
#: crown: the slope first shows in the side view, CASSI's "slight"); 7 deg lifts it 4.9 mm
#: (half a crown: two problems); 11 deg lifts it 7.7 mm, most of a lower incisor crown (9 mm):
#: CASSI's "very steep" JW41, three problems.
SLOPE_UP_DEG = 3.0
SLOPE_STEEP_DEG = 7.0
SLOPE_VERY_STEEP_DEG = 11.0
#: The same slope falling toward the front even with the jaw most closed (CASSI's JW12,
#: "bottom teeth slant downwards"): one problem beyond the same 3 deg.
SLOPE_DOWN_DEG = 3.0
#: Front overlap (overbite): the lower incisal edge above the upper incisal edge, mm.
#: CASSI's ideal JW24 had "a very slight overlap in the front teeth"; a normal overbite is
#: 1-2 mm, a fifth of the 10.5 mm upper incisor crown; beyond 2 mm the overlap shows.
FRONT_OVERLAP_MM = 2.0
#: Back overlap: a lower molar/premolar occlusal point above the occlusal level of the
#: nearest upper crown, mm. Back teeth meet cusp to cusp and cannot overlap; their cusps
#: interdigitate by about 1 mm, so more than that is one crown inside the other.
BACK_OVERLAP_MM = 1.0
#: Teeth running into the lips (front view): deepest lip point inside either dental arch
#: (``collide`` "lips_upper_teeth"/"lips_lower_teeth"), mm. Below 1 mm the lip's surface
#: (rows 1-4 mm apart) still covers the crown; beyond it the tooth shows through.
TEETH_IN_LIPS_MM = 1.0
#: Teeth too far apart: the closest the arches come (interocclusal gap, the smaller of the
#: front and back vertical gaps), mm. Speech brings the incisors within 1-2 mm (/s/, /t/)
#: and the rest position leaves 2-3 mm (freeway space); a recording whose teeth never come
#: nearer than 3 mm never shows them together (CASSI's JW40, "too far apart").
TEETH_APART_MM = 3.0

# Lips -----------------------------------------------------------------------------
#: Lips never touching: the closest the upper lip's lower edge comes to the lower lip's
#: upper edge at the midline, mm. Within 2 mm the slit between them is a line; a recording
#: whose lips never come nearer shows a dark gap throughout (one problem, CASSI's JW16,
#: JW19, JW40 "a separation between lips").
LIP_APART_MM = 2.0
#: A large separation (two problems, CASSI's JW11 whose lips "never touch"): never nearer
#: than 6 mm, half the height of the model's upper red lip (11 mm).
LIP_APART_LARGE_MM = 6.0
#: Lips too tightly together: in the median frame the edges pass into each other by more
#: than this, mm. The model's lips are 0.4 mm apart at rest, so a negative gap is the lips
#: crossing; 1 mm is beyond the rounding of the lip rows (CASSI's JW15, JW18, JW502).
LIP_TIGHT_MM = 1.0
#: Lips beyond the teeth (front view): in the median frame the upper lip's edge above the
#: upper central incisors' cervical (gum) level, or the lower lip's edge below the lower
#: ones', by more than this, mm: the whole crown and a millimetre of gum show.
LIP_BEYOND_TEETH_MM = 1.0
#: Lower lip protruding (side view): its front-most point ahead of the upper lip's in the
#: median frame, mm. The model's own upper lip is 0.5 mm ahead and adult profiles have it
#: 1-3 mm ahead; a lower lip 1 mm ahead reads as protruding (CASSI's JW24, JW25, JW32).
LIP_PROTRUSION_MM = 1.0

# Tongue ---------------------------------------------------------------------------
#: Tongue through the front teeth (front view): the deepest tongue point inside the
#: front crowns (central, lateral incisor, canine; ``collide`` "tongue_upper_front" /
#: "tongue_lower_front"), sustained, mm. The incisal edges are 1.5 mm thick, so 1 mm in
#: is most of the way through; less hides in the rounding of the six-sided crowns.
TONGUE_POKE_MM = 1.0
#: Very noticeably through both (three problems, CASSI's JW11, JW21, JW24): in both arches
#: a tongue point 2 mm from every way out of the crowns (``collide`` measures the depth to
#: the nearer face and to the biting edge): in the middle of the crowns where they are
#: 4 mm thick or more, i.e. about halfway up the incisors (4.25 mm upper, 3.75 mm lower),
#: so the tongue is through them, not grazing their edge.
TONGUE_POKE_DEEP_MM = 2.0
#: Tongue barely visible from the front: in the median frame its front-most point more
#: than this behind the lingual face of the lower central incisors, mm. The model's rest
#: tongue tip sits 4 mm behind it (between the lateral incisors and the canines, 7 mm);
#: beyond 15 mm it is behind the first premolars (14 mm), framed by the side teeth and out
#: of the front view's sight (CASSI's JW15, JW45).
TONGUE_HIDDEN_MM = 15.0

# Reported, not counted (CASSI section 4) -------------------------------------------
#: The palate's oral surface below the upper incisor tip (CASSI's JW19, JW32), mm.
PALATE_BELOW_MM = 0.0
#: The tongue through the palate (CASSI: "in all but a few cases"), sustained, mm; the
#: same 1 mm as the teeth.
TONGUE_PALATE_MM = 1.0

RATINGS = ("EXCELLENT", "VERY GOOD", "GOOD", "FAIR")
COMPONENTS = ("teeth", "lips", "tongue")
#: CASSI's Table 2 totals (EXCELLENT, VERY GOOD, GOOD, FAIR over its 15 subjects).
CASSI_TOTALS = {"teeth": (1, 6, 6, 2), "lips": (2, 7, 4, 2), "tongue": (2, 4, 6, 3)}


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
        "mm", "min", True, "tongue front behind the lower incisors' lingual face (median)"),
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
}  # fmt: skip


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

    def all(self) -> np.ndarray:
        parts = [np.atleast_1d(np.asarray(getattr(self, f))) for f in self.__dataclass_fields__]
        return np.concatenate(parts).astype(np.int64)


def _chain_stations(model, arch, chains, select) -> np.ndarray:
    """Indices of the stations of ``chains`` whose tooth number satisfies ``select``."""
    tooth = np.asarray(model.collision[f"{arch}_tooth"])
    keep = select(tooth)
    return np.concatenate([np.asarray(model.collision[f"{arch}_{c}"])[keep] for c in chains])


def _sites(model) -> _Sites:
    """The vertex sets of the measures; raises ``MissingDataError`` if the model lacks any."""
    from .collide import FRONT_TEETH, has_collision_data
    from .palate import N_ACROSS, N_ALONG

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
        palate_oral=palate[: N_ALONG * N_ACROSS],
    )


def _split(sites: _Sites, points):
    """``points (..., K, 3)`` gathered at ``sites.all()`` -> dict of the parts."""
    out, start = {}, 0
    for name in sites.__dataclass_fields__:
        n = np.atleast_1d(np.asarray(getattr(sites, name))).size
        out[name] = points[..., start : start + n, :]
        start += n
    return out


def _angle_deg(back, front):
    """Angle (deg) of the side-view line from ``back (3,)`` to ``front (3,)``."""
    d = front - back
    return jnp.degrees(jnp.arctan2(d[1], d[0]))


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
    }


_KERNELS: dict = {}


def _per_frame(sites: _Sites, points) -> dict:
    """Raw quantities of every frame, ``(m,)`` numpy each, from ``points (m, K, 3)``.

    One jitted, vmapped call; frames are padded to a size bucket (64, 128, 256, 512, then
    multiples of 256) so recordings of similar length share the compiled function.
    """
    m = points.shape[0]
    points = pad_frames(points, frame_bucket(m))
    key = tuple(np.atleast_1d(np.asarray(getattr(sites, f))).size
                for f in sites.__dataclass_fields__)
    kernel = _KERNELS.get(key)
    if kernel is None:
        kernel = _KERNELS[key] = jax.jit(
            jax.vmap(lambda pts: _frame_quantities(_split(sites, pts)))
        )
    return {k: np.asarray(v)[:m] for k, v in kernel(points).items()}


def sustain_frames(times) -> int:
    """Frames in ``SUSTAIN_S`` for frame times ``times (m,)`` s (at least 1)."""
    times = np.asarray(times, np.float64)
    if times.size < 2:
        return 1
    period = float(np.median(np.diff(times)))
    if not period > 0:
        raise DegenerateGeometryError("frame times do not increase")
    return max(1, int(round(SUSTAIN_S / period)))


def sustained_max(x, window: int) -> float:
    """The largest value ``x (m,)`` keeps for ``window`` consecutive frames: max over
    time of the running minimum (the whole series' minimum if shorter)."""
    x = np.asarray(x, np.float64)
    w = max(1, min(int(window), x.size))
    return float(np.lib.stride_tricks.sliding_window_view(x, w).min(-1).max())


def sustained_min(x, window: int) -> float:
    """The smallest value ``x (m,)`` keeps for ``window`` consecutive frames."""
    return -sustained_max(-np.asarray(x, np.float64), window)


def penetration_of(model, vertices) -> dict:
    """``collide.report`` of every frame of ``vertices (m, V, 3)``: key -> ``(m,)`` mm.

    For geometry that did not come from ``animate.animate`` (which reports it itself);
    compiled once per model content (``animate.model_call``).
    """
    from .collide import report

    m = vertices.shape[0]
    vertices = pad_frames(vertices, frame_bucket(m))
    out = model_call(model, "evaluate-report",
                     lambda rebuilt: jax.vmap(lambda v: report(rebuilt, v)), vertices)
    return {k: np.asarray(v)[:m] for k, v in out.items()}


def _penetration(model, anim):
    """``(before, after)`` dicts of ``(m,)`` mm from the animation (or computed)."""
    from .collide import REPORT_KEYS

    before = getattr(anim, "penetration", None) or {}
    after = getattr(anim, "penetration_after", None) or before
    if not all(k in after for k in REPORT_KEYS):
        after = penetration_of(model, anim.vertices)
        before = before if all(k in before for k in REPORT_KEYS) else after
    return before, after


def measure(state, anim) -> dict:
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
        "tongue_palate_mm": hi(after["tongue_palate"]),
        "palate_below_incisor_mm": float(np.max(raw["palate_below"])),
        "tongue_upper_front_before_mm": hi(before["tongue_upper_front"]),
        "tongue_lower_front_before_mm": hi(before["tongue_lower_front"]),
        "tongue_palate_before_mm": hi(before["tongue_palate"]),
        "teeth_in_lips_before_mm": hi(
            np.maximum(before["lips_upper_teeth"], before["lips_lower_teeth"])
        ),
    }
    return {k: float(v) for k, v in out.items()}


# ----------------------------------------------------------------------------- counting
def _value(measures: dict, name: str) -> float:
    if name not in measures:
        raise CassiError(f"measure {name!r} missing; cannot count problems")
    value = float(measures[name])
    if not math.isfinite(value):
        raise DegenerateGeometryError(f"measure {name} is {value}; not rated")
    return value


def problems(measures: dict) -> dict[str, list[str]]:
    """The problems counted, per component: ``{"teeth", "lips", "tongue"}`` -> names, and
    ``"not_counted"`` -> the palate items CASSI reported without counting.

    A problem worth two or three (a large lip gap, a steep slope, the tongue through both
    front arches) appears that many times, so ``len(out[c])`` is the count CASSI rated.
    """
    v = lambda name: _value(measures, name)  # noqa: E731
    teeth, lips, tongue, other = [], [], [], []
    slope = v("lower_slope_deg")
    if slope > SLOPE_VERY_STEEP_DEG:
        teeth += ["lower teeth slope up very steeply"] * 3
    elif slope > SLOPE_STEEP_DEG:
        teeth += ["lower teeth slope up steeply"] * 2
    elif slope > SLOPE_UP_DEG:
        teeth.append("lower teeth slope up")
    elif slope < -SLOPE_DOWN_DEG:
        teeth.append("lower teeth slope down")
    front, back = v("front_overlap_mm") > FRONT_OVERLAP_MM, v("back_overlap_mm") > BACK_OVERLAP_MM
    if front or back:
        which = "front and back" if front and back else "front" if front else "back"
        teeth.append(f"{which} teeth overlap")
    if max(v("teeth_in_upper_lip_mm"), v("teeth_in_lower_lip_mm")) > TEETH_IN_LIPS_MM:
        teeth.append("teeth run into the lips")
    if v("teeth_gap_mm") > TEETH_APART_MM:
        teeth.append("teeth too far apart")

    gap = v("lip_gap_min_mm")
    if gap > LIP_APART_LARGE_MM:
        lips += ["lips far apart"] * 2
    elif gap > LIP_APART_MM:
        lips.append("lips never touch")
    if v("lip_gap_median_mm") < -LIP_TIGHT_MM:
        lips.append("lips too tightly together")
    if v("upper_lip_above_teeth_mm") > LIP_BEYOND_TEETH_MM:
        lips.append("upper lip above the upper teeth")
    if v("lower_lip_below_teeth_mm") > LIP_BEYOND_TEETH_MM:
        lips.append("lower lip below the lower teeth")
    if v("lower_lip_protrusion_mm") > LIP_PROTRUSION_MM:
        lips.append("lower lip protrudes")

    upper, lower = v("tongue_upper_front_mm"), v("tongue_lower_front_mm")
    if min(upper, lower) > TONGUE_POKE_DEEP_MM:
        tongue += ["tongue very noticeably through both front teeth"] * 3
    elif min(upper, lower) > TONGUE_POKE_MM:
        tongue += ["tongue through upper and lower front teeth"] * 2
    elif upper > TONGUE_POKE_MM:
        tongue.append("tongue through upper front teeth")
    elif lower > TONGUE_POKE_MM:
        tongue.append("tongue through lower front teeth")
    if v("tongue_behind_incisors_mm") > TONGUE_HIDDEN_MM:
        tongue.append("tongue barely visible")

    if v("palate_below_incisor_mm") > PALATE_BELOW_MM:
        other.append("palate below the upper incisor tip")
    if v("tongue_palate_mm") > TONGUE_PALATE_MM:
        other.append("tongue through the palate")
    return {"teeth": teeth, "lips": lips, "tongue": tongue, "not_counted": other}


def rating(n_problems: int) -> str:
    """CASSI's word for a count: 0 EXCELLENT, 1 VERY GOOD, 2 GOOD, 3 or more FAIR."""
    if isinstance(n_problems, bool) or int(n_problems) != n_problems or n_problems < 0:
        raise CassiError(f"a problem count is a non-negative integer, got {n_problems!r}")
    return RATINGS[min(int(n_problems), len(RATINGS) - 1)]


def _rate(measures: dict) -> tuple[dict, dict]:
    found = problems(measures)
    return found, {c: rating(len(found[c])) for c in COMPONENTS}


def describe(names: list[str]) -> str:
    """``["a", "a", "b"]`` -> ``"a x2; b"`` (repeats collapsed, first-seen order)."""
    counts = {n: names.count(n) for n in dict.fromkeys(names)}
    return "; ".join(n if c == 1 else f"{n} x{c}" for n, c in counts.items())


# ----------------------------------------------------------------------------- running
def _calibration_label(calibration) -> str:
    if calibration is None:
        return "default"
    if isinstance(calibration, str):
        return calibration
    return "calibrated"


def _row(subject, task, status, settings, measures=None, extra=None) -> dict:
    row = {"subject": subject, "task": task, "status": status, **settings, **(extra or {})}
    row["measures"] = measures or {}
    if measures:
        row["problems"], row["ratings"] = _rate(measures)
    else:
        row["problems"], row["ratings"] = {}, {}
    return row


def evaluate_recording(
    recording, *, calibration=None, collisions="off", jaw="closed-form", stride=1, model=None
) -> dict:
    """Animate one recording and rate it: a row ``{subject, task, status, frames, stride,
    jaw, calibration, collisions, measures, problems, ratings}``.

    ``calibration``: None (the toolkit's conformation from Headmeasures), ``"cassi"``
    (only what the paper did) or a ``calibrate.Calibration``; ``collisions``: ``"off"``
    or ``"project"``; ``jaw``, ``stride``: as ``animate.animate``. Errors propagate.
    """
    from .animate import animate, initialize

    state = initialize(recording, model, calibration=calibration)
    anim = animate(state, recording, jaw=jaw, stride=stride, collisions=collisions)
    settings = {
        "frames": int(anim.n_frames),
        "stride": int(stride),
        "jaw": jaw,
        "calibration": _calibration_label(calibration),
        "collisions": collisions,
    }
    return _row(recording.subject, recording.task, "ok", settings, measure(state, anim))


def combine(rows: list[dict]) -> dict:
    """One subject's measures from its recordings' (each combined by ``MEASURES[k]
    .combine``: the worst over tasks, or the closest approach over tasks)."""
    if not rows:
        raise MissingDataError("no evaluated recording to combine")
    out = {}
    for name, spec in MEASURES.items():
        values = [r["measures"][name] for r in rows if name in r["measures"]]
        if values:
            out[name] = float(max(values) if spec.combine == "max" else min(values))
    return out


@dataclass
class EvaluationResult:
    """Rows of :func:`evaluate_dataset`: ``recordings`` (one per file, failed ones with a
    ``status`` other than ``"ok"`` and no ratings) and ``subjects`` (combined measures,
    problems and ratings per subject), plus the ``settings`` used."""

    recordings: list[dict]
    subjects: list[dict]
    settings: dict = field(default_factory=dict)

    def totals(self) -> dict[str, tuple[int, ...]]:
        """Per component, the number of rated subjects per rating (``RATINGS`` order)."""
        rated = [s for s in self.subjects if s["ratings"]]
        return {c: tuple(sum(s["ratings"][c] == r for s in rated) for r in RATINGS)
                for c in COMPONENTS}

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.recordings if r["status"] != "ok"]


def _subject_row(subject: str, rows: list[dict], settings: dict) -> dict:
    ok = [r for r in rows if r["status"] == "ok"]
    tasks = " ".join(r["task"] for r in ok)
    extra = {"tasks": tasks, "recordings": len(ok), "failed": len(rows) - len(ok)}
    if not ok:
        return _row(subject, "", "no recording evaluated", settings, None, extra)
    calib = sorted({r["calibration"] for r in ok})
    return _row(subject, "", "ok", {**settings, "calibration": "/".join(calib)}, combine(ok),
                extra)


def _calibration_for(calibrations, subject):
    if calibrations is None or isinstance(calibrations, str):
        return calibrations
    if subject in calibrations:
        return calibrations[subject]
    warnings.warn(f"{subject}: no calibration given; using the default conformation",
                  stacklevel=3)
    return None


def evaluate_dataset(
    dataset_or_path,
    *,
    calibrations=None,
    collisions="off",
    tasks=None,
    subjects=None,
    progress=True,
    jaw="closed-form",
    stride=1,
    model=None,
) -> EvaluationResult:
    """Evaluate every recording of a dataset (or the chosen ``subjects``/``tasks``) and
    rate each subject.

    ``calibrations``: None (the default conformation), ``"cassi"`` (CASSI-like, for
    everyone) or a dict subject (upper case) -> ``Calibration`` (a subject missing from it
    gets the default, with a warning). A recording that fails (a ``CassiError``: bad data,
    non-finite geometry) is kept with its message as ``status`` and not rated; its
    subject is rated from the others. Progress bar over the files on stderr (tqdm).
    """
    from tqdm import tqdm

    from .dataset import Dataset, DefaultHeadMeasuresWarning

    dataset = dataset_or_path if isinstance(dataset_or_path, Dataset) else Dataset(
        dataset_or_path)
    names = dataset.subjects() if subjects is None else [str(s).upper() for s in subjects]
    if not names:
        raise MissingDataError(f"{dataset.root}: no recordings found")
    wanted = None if tasks is None else {str(t).lower() for t in tasks}
    plan = []
    for subject in names:
        chosen = [t for t in dataset.tasks(subject) if wanted is None or t in wanted]
        plan += [(subject, t) for t in chosen]
    if not plan:
        raise MissingDataError(
            f"{dataset.root}: none of the tasks {', '.join(sorted(wanted or []))} found for "
            f"{', '.join(names)}"
        )
    settings = {"stride": int(stride), "jaw": jaw, "collisions": collisions}
    label = "cassi" if calibrations == "cassi" else (
        "default" if calibrations is None else "calibrated")
    rows = []
    bar = tqdm(plan, desc="evaluate", unit="file", disable=not progress)
    for subject, task in bar:
        bar.set_postfix_str(f"{subject} {task}")
        calibration = _calibration_for(calibrations, subject)
        try:
            with warnings.catch_warnings():  # the rows name the calibration used
                warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
                recording = dataset.load(subject, task)
            rows.append(evaluate_recording(recording, calibration=calibration,
                                           collisions=collisions, jaw=jaw, stride=stride,
                                           model=model))
        except CassiError as exc:
            rows.append(_row(subject, task, f"error: {exc}", {
                **settings, "frames": 0, "calibration": _calibration_label(calibration)}))
    planned = list(dict.fromkeys(subject for subject, _ in plan))  # those with chosen tasks
    per_subject = [_subject_row(s, [r for r in rows if r["subject"] == s], settings)
                   for s in planned]
    return EvaluationResult(rows, per_subject, {**settings, "calibration": label})


# ----------------------------------------------------------------------------- writing
_META = ("subject", "task", "status", "frames", "stride", "jaw", "calibration", "collisions")
_SUBJECT_META = ("subject", "tasks", "recordings", "failed", "status", "stride", "jaw",
                 "calibration", "collisions")


def _csv_text(rows: list[dict], meta) -> str:
    columns = [*meta, *MEASURES]
    for c in COMPONENTS:
        columns += [f"{c}_rating", f"{c}_problems_n", f"{c}_problems"]
    columns.append("not_counted")
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for r in rows:
        line = [r.get(k, "") for k in meta]
        line += [f"{r['measures'][k]:.4f}" if k in r["measures"] else "" for k in MEASURES]
        for c in COMPONENTS:
            found = r["problems"].get(c)
            line += ([r["ratings"][c], len(found), describe(found)] if found is not None
                     else ["", "", ""])
        line.append(describe(r["problems"].get("not_counted", [])))
        writer.writerow(line)
    return buffer.getvalue()


def _cell(row: dict, component: str) -> str:
    if not row["ratings"]:
        return "not rated"
    found = row["problems"][component]
    text = row["ratings"][component]
    return f"{text} ({describe(found)})" if found else text


def _totals_text(totals: tuple[int, ...]) -> str:
    return "/".join(str(n) for n in totals)


def markdown_table(result: EvaluationResult) -> str:
    """Table 2's layout: Subject | Tasks | Teeth | Lips | Tongue, each cell the rating and
    the problems counted; a totals row (EXCELLENT/VERY GOOD/GOOD/FAIR per column); then
    the problems reported but not counted, and any recording not evaluated."""
    s = result.settings
    lines = [
        "| Subject | Tasks | Teeth | Lips | Tongue |",
        "|---|---|---|---|---|",
    ]
    for row in result.subjects:
        lines.append(f"| {row['subject']} | {row['tasks']} | "
                     + " | ".join(_cell(row, c) for c in COMPONENTS) + " |")
    totals = result.totals()
    lines.append("| **Total** (EXCELLENT/VERY GOOD/GOOD/FAIR) | | "
                 + " | ".join(_totals_text(totals[c]) for c in COMPONENTS) + " |")
    head = (f"Calibration: {s.get('calibration', '?')}; collisions: {s.get('collisions', '?')}; "
            f"jaw: {s.get('jaw', '?')}; stride {s.get('stride', '?')}. "
            "Problems counted as in CASSI's Table 2 (thresholds: docs/EVALUATION.md); "
            "xN = a problem counted N times.")
    out = [head, "", *lines]
    noted = [f"{r['subject']}: {describe(r['problems']['not_counted'])}"
             for r in result.subjects if r["problems"].get("not_counted")]
    if noted:
        out += ["", "Seen but not counted (as in CASSI): " + "; ".join(noted) + "."]
    if result.failed:
        out += ["", "Not evaluated: " + "; ".join(
            f"{r['subject']} {r['task']} ({r['status']})" for r in result.failed) + "."]
    return "\n".join(out) + "\n"


OUTPUT_NAMES = ("evaluation_subjects.csv", "evaluation_recordings.csv", "evaluation.md")


def write_table(result: EvaluationResult, out_dir, *, overwrite=False) -> list[Path]:
    """Write ``evaluation_subjects.csv``, ``evaluation_recordings.csv`` and
    ``evaluation.md`` into ``out_dir``; each atomically. Refuses (``OutputExistsError``)
    before writing anything if one exists and ``overwrite`` is false."""
    from ._io import atomic_write
    from .errors import OutputExistsError

    out_dir = Path(out_dir)
    paths = [out_dir / name for name in OUTPUT_NAMES]
    existing = [str(p) for p in paths if p.exists()]
    if existing and not overwrite:
        raise OutputExistsError(
            f"{', '.join(existing)}: file exists (pass overwrite=True / --force to replace it)")
    md = "# Objective evaluation (CASSI Table 2)\n\n" + markdown_table(result)
    texts = (_csv_text(result.subjects, _SUBJECT_META), _csv_text(result.recordings, _META), md)
    return [atomic_write(p, t, overwrite=overwrite) for p, t in zip(paths, texts, strict=True)]


def compare(a: EvaluationResult, b: EvaluationResult, *, labels=("a", "b"),
            paper=True) -> str:
    """A small Markdown table of the two results' rating totals side by side (and CASSI's
    own Table 2 totals when ``paper``), with the mean number of problems per subject."""
    lines = ["| | Teeth | Lips | Tongue | problems per subject (teeth/lips/tongue) |",
             "|---|---|---|---|---|"]
    if paper:  # its mean counts follow from the totals, FAIR taken as 3 problems
        mean = "/".join(f"{np.dot(CASSI_TOTALS[c], np.arange(4)) / 15:.1f}" for c in COMPONENTS)
        lines.append("| CASSI (paper, 15 subjects; FAIR as 3) | "
                     + " | ".join(_totals_text(CASSI_TOTALS[c]) for c in COMPONENTS)
                     + f" | {mean} |")
    for label, result in zip(labels, (a, b), strict=True):
        rated = [s for s in result.subjects if s["ratings"]]
        mean = "/".join(
            f"{np.mean([len(s['problems'][c]) for s in rated]):.1f}" if rated else "-"
            for c in COMPONENTS)
        totals = result.totals()
        lines.append(f"| {label} ({len(rated)} subjects) | "
                     + " | ".join(_totals_text(totals[c]) for c in COMPONENTS)
                     + f" | {mean} |")
    return "Counts are EXCELLENT/VERY GOOD/GOOD/FAIR.\n\n" + "\n".join(lines) + "\n"


# Measures drawn per subject in the summary figure, per component: (names, thresholds).
_PLOTTED = {
    "teeth": (("lower_slope_deg",), (SLOPE_UP_DEG, SLOPE_STEEP_DEG, SLOPE_VERY_STEEP_DEG)),
    "lips": (("lip_gap_min_mm", "lip_gap_median_mm"),
             (-LIP_TIGHT_MM, LIP_APART_MM, LIP_APART_LARGE_MM)),
    "tongue": (("tongue_upper_front_mm", "tongue_lower_front_mm"),
               (TONGUE_POKE_MM, TONGUE_POKE_DEEP_MM)),
}


def plot_summary(result: EvaluationResult, path, *, overwrite=False) -> Path:
    """A PNG: top row, subjects per rating for teeth, lips, tongue (beside CASSI's Table 2
    counts); bottom row, the key measures per subject against their thresholds (dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ._io import atomic_output_path, commit_output

    tmp, final = atomic_output_path(path, overwrite=overwrite)
    rated = [s for s in result.subjects if s["ratings"]]
    totals = result.totals()
    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5), constrained_layout=True)
    x = np.arange(len(RATINGS))
    for k, c in enumerate(COMPONENTS):
        ax = axes[0, k]
        ax.bar(x - 0.2, totals[c], 0.4, label=f"measured ({len(rated)} subjects)")
        ax.bar(x + 0.2, CASSI_TOTALS[c], 0.4, label="CASSI Table 2 (15)", alpha=0.5,
               hatch="//")
        ax.set_xticks(x, RATINGS, fontsize=9)
        ax.set_ylim(0, 1.3 * max(max(totals[c]), max(CASSI_TOTALS[c]), 1))
        ax.set_title(f"{c}: subjects per rating")
        ax.set_ylabel("subjects")
        ax.legend(fontsize=8, loc="upper left")
        names, limits = _PLOTTED[c]
        ax = axes[1, k]
        width = 0.8 / len(names)
        where = np.arange(len(rated))
        for j, name in enumerate(names):
            values = [s["measures"].get(name, np.nan) for s in rated]
            ax.bar(where + (j - (len(names) - 1) / 2) * width, values, width,
                   label=f"{name} ({MEASURES[name].unit})")
        for limit in limits:
            ax.axhline(limit, color="tab:red", lw=1, ls="--")
        ax.axhline(0.0, color="black", lw=0.5)
        ax.set_xticks(where, [s["subject"] for s in rated], rotation=90, fontsize=8)
        ax.set_title(f"{c}: key measures per subject (dashed: thresholds)", fontsize=10)
        ax.legend(fontsize=8)
    s = result.settings
    fig.suptitle(f"Objective evaluation: calibration {s.get('calibration', '?')}, "
                 f"collisions {s.get('collisions', '?')}")
    try:
        fig.savefig(tmp, dpi=100)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        plt.close(fig)
    return commit_output(tmp, final)
