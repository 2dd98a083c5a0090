"""CASSI's counting rule: thresholds with their reasons, the problems counted, the ratings.

CASSI (Scheidt & Hamilton 1999, section 4, Table 2) rated teeth, lips and tongue
EXCELLENT, VERY GOOD, GOOD or FAIR by the number of problems seen (0, 1, 2, 3 or more).
Here every problem is a measured quantity (``_measures.MEASURES``) beyond a documented
threshold (the constants below; ``docs/EVALUATION.md`` gives the same table).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from ..errors import CassiError, DegenerateGeometryError

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

#: The tongue's back in a V (CASSI: "a V-shape in the back at times", all tasks of all
#: subjects but one; not rated, section 4), deg: the sharpest concave turn of the upper
#: midline behind T3 between neighbouring stations (3-5 mm apart), sustained 50 ms
#: (``_measures.back_v_deg``). A real dorsum is convex from the blade to the root, and
#: the model's rest back turns only convexly; a concave turn comes from the pellets or
#: from how the back is tied to them. 30 deg over a 4 mm station is a radius of
#: curvature under 8 mm, finer than the pellets can show (T3-T4 are 12-13 mm apart, so
#: they resolve bends of half that radius at best): a crease made by the model, which
#: reads as a V in the inside view.
TONGUE_V_DEG = 30.0

RATINGS = ("EXCELLENT", "VERY GOOD", "GOOD", "FAIR")
COMPONENTS = ("teeth", "lips", "tongue")
#: CASSI's Table 2 totals (EXCELLENT, VERY GOOD, GOOD, FAIR over its 15 subjects).
CASSI_TOTALS = {"teeth": (1, 6, 6, 2), "lips": (2, 7, 4, 2), "tongue": (2, 4, 6, 3)}


# ----------------------------------------------------------------------------- counting
def _value(measures: Mapping[str, float], name: str) -> float:
    if name not in measures:
        raise CassiError(f"measure {name!r} missing; cannot count problems")
    value = float(measures[name])
    if not math.isfinite(value):
        raise DegenerateGeometryError(f"measure {name} is {value}; not rated")
    return value


def problems(measures: Mapping[str, float]) -> dict[str, list[str]]:
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
    if "tongue_back_v_deg" in measures and v("tongue_back_v_deg") > TONGUE_V_DEG:
        other.append("tongue's back in a V")
    return {"teeth": teeth, "lips": lips, "tongue": tongue, "not_counted": other}


def rating(n_problems: int) -> str:
    """CASSI's word for a count: 0 EXCELLENT, 1 VERY GOOD, 2 GOOD, 3 or more FAIR."""
    if isinstance(n_problems, bool) or int(n_problems) != n_problems or n_problems < 0:
        raise CassiError(f"a problem count is a non-negative integer, got {n_problems!r}")
    return RATINGS[min(int(n_problems), len(RATINGS) - 1)]


def rate(measures: Mapping[str, float]) -> tuple[dict[str, list[str]], dict[str, str]]:
    """``(problems(measures), ratings)``: the problems counted per component (and
    ``"not_counted"``) and, per component of ``COMPONENTS``, the word for their count."""
    found = problems(measures)
    return found, {c: rating(len(found[c])) for c in COMPONENTS}


def describe(names: Sequence[str]) -> str:
    """``["a", "a", "b"]`` -> ``"a x2; b"`` (repeats collapsed, first-seen order)."""
    counts = {n: names.count(n) for n in dict.fromkeys(names)}
    return "; ".join(n if c == 1 else f"{n} x{c}" for n, c in counts.items())

