"""The skin's rows: the model's constants (materials, pellet sites, Parke's region
weights) and the table of horizontal cross-sections the skin is lofted from, refined
(rows added halfway, sides smoothed) before use.

Part of ``build_model.py`` (run that to rebuild the model).
"""

from __future__ import annotations

import numpy as np

from cassi_fit.face_model import MATERIALS

MAT = {name: i for i, name in enumerate(MATERIALS)}

# Pellet sites of the model (x, y) mm, placed where real pellets sit (one speaker's medians).
SITES = {"UL": (14.9, 17.8), "LL": (9.4, -21.4), "MNI": (-1.0, -8.0), "MNM": (-44.0, -3.0),
         "T1": (-17.0, 1.0), "T2": (-29.0, 7.0), "T3": (-41.0, 12.5), "T4": (-53.0, 17.0)}
MOUTH_HALF_WIDTH = 24.5
NECK_HALF_WIDTH = 55.0  # behind the jaw angle, under the ears
EYE_CENTRE = (-7.5, 64.0, 32.0)  # left eyeball centre, mm
EYE_RADIUS = 12.0
JAW_PIVOT = (-95.0, 22.0)  # condyle, mm
PARKE = {"jaw": 1.00, "lower_teeth": 0.90, "under_chin": 0.75, "neck": 0.50, "cheek": 0.35}
CASSI_FACTOR = 1.0 / 0.9   # CASSI's 1.11111: the lower teeth move 100 %

# ---------------------------------------------------------------------------- skin rows
# name, y0 (midline height), xf (front midline x, before nose/lip bumps), cx (section
# centre), w (half width), xb (back midline x), e (front superellipse exponent),
# lift (mm the row rises toward the back, following the jaw line), group (upper/lower).
# The lips at rest (the stomion of each lip, y mm): the upper lip's edge 1.9 mm above the
# upper incisor tip (the incisor show at rest), the lower lip's 1.6 mm below it, lying on
# the incisal third of the upper incisors (see model/README.md, "The face", for sources).
STO_UPPER, STO_LOWER = 1.9, 0.3
ROWS = [
    ("vertex", 177, -88, -88, 0.0, -88, 2.0, 0, "u"),
    ("crown1", 172, -48, -90, 30, -132, 2.0, 0, "u"),
    ("crown2", 162, -18, -92, 52, -160, 2.0, 0, "u"),
    ("crown3", 147, 1, -92, 66, -173, 2.1, 0, "u"),
    ("forehead1", 129, 9, -92, 73, -179, 2.2, 0, "u"),
    ("forehead2", 110, 13, -92, 75, -181, 2.3, 0, "u"),
    ("brow", 94, 15, -90, 74, -180, 2.5, 0, "u"),
    ("glabella", 84, 15, -88, 72.5, -177, 2.65, 0, "u"),
    ("nasion", 76, 11, -86, 70.5, -174, 2.8, 0, "u"),
    ("lid_up", 70, 10, -84, 69, -171, 2.9, 0, "u"),
    ("eye_hi", 67, 10, -83, 68, -170, 2.95, 0, "u"),
    ("eyes", 64, 10, -81.5, 67.5, -168, 3.0, 0, "u"),
    ("eye_lo", 61, 10, -80, 67, -166, 3.0, 0, "u"),
    ("lid_low", 58, 10, -78.5, 66.5, -164, 3.0, 0, "u"),
    ("eyes_low", 54, 10.5, -76, 66, -162, 3.0, 0, "u"),
    ("cheekbone", 47, 11, -74, 65, -158, 3.0, 0, "u"),
    ("nose_tip_high", 40.0, 12, -73, 64, -155, 2.9, 0, "u"),
    ("nose_tip", 34.5, 12, -72, 63, -153, 2.8, 0, "u"),
    ("nostril", 29.0, 12, -72, 62, -151, 2.7, 0, "u"),
    ("subnasale", 24.5, 12, -72, 61, -150, 2.6, 0, "u"),
    ("philtrum", 21.3, 11.5, -72, 60, -149, 2.5, 0, "u"),
    ("UL", 17.8, 6.0, -72, 59, -148, 2.4, 0, "u"),
    ("ul_red", 10.5, 5.5, -73, 57.5, -147, 2.4, 0, "u"),
    ("ul_low", 5.5, 5.0, -73, 57, -147, 2.4, 0, "u"),
    ("A", STO_UPPER, 5.0, -74, 56.5, -147, 2.4, 0, "u"),
    ("A_in", STO_UPPER, 5.0, -74, 56.5, -147, 2.4, 0, "u"),
    ("B_in", STO_LOWER, 5.0, -74, 56.5, -147, 2.4, 0, "l"),
    ("B", STO_LOWER, 5.0, -74, 56.5, -147, 2.4, 0, "l"),
    ("ll_high", -3.0, 5.0, -74, 56, -147, 2.4, 0, "l"),
    ("ll_red", -9.6, 5.0, -75, 55, -147, 2.3, 0, "l"),
    ("LL", -21.4, 4.0, -76, 54, -147, 2.2, 0.5, "l"),
    ("fold", -29, 3.0, -78, 52.5, -146, 2.0, 2, "l"),
    ("chin", -37, 8.0, -80, 50.5, -144, 2.0, 5, "l"),
    ("chin_low", -44, 6.0, -82, 48.5, -141, 2.0, 9, "l"),
    ("menton", -49.5, -4.0, -84, 46, -139, 2.0, 13, "l"),
    ("under_chin", -55, -24.0, -95, 48, -136, 2.0, 14, "l"),
    ("throat", -63, -42.0, -92, 51, -133, 2.0, 12, "l"),
    ("neck1", -81, -47.0, -90, 53, -130, 2.0, 6, "l"),
    ("neck2", -105, -47.0, -90, 55, -130, 2.0, 2, "l"),
    ("neck_base", -125, -44.0, -90, 58, -134, 2.0, 0, "l"),
]
ROW_INDEX = {r[0]: i for i, r in enumerate(ROWS)}
# Lip protrusion (mm, at the midline) on top of xf; falls to 0 at the mouth corners.
LIP_BUMP = {"UL": 8.9, "ul_red": 9.6, "ul_low": 8.6, "A": 6.5, "A_in": 1.0,
            "B_in": 1.0, "B": 6.5, "ll_high": 8.8, "ll_red": 9.6, "LL": 5.4, "fold": 0.0}
# Nose: protrusion (mm at the midline) and half width per row.
NOSE = {"glabella": (0.5, 12), "nasion": (1.0, 12), "lid_up": (2.5, 11), "eye_hi": (4.0, 10.5),
        "eyes": (5.5, 10), "eye_lo": (7.0, 10), "lid_low": (8.5, 10), "eyes_low": (11.0, 10),
        "cheekbone": (15.5, 10.5), "nose_tip_high": (19.5, 13), "nose_tip": (21.5, 17),
        "nostril": (14.0, 17), "subnasale": (1.5, 12)}


def _eye_rows():
    """Extra rows halfway between the rows from the nasion to below the eyes (2-3 mm apart:
    the lids' edges are drawn by where the skin meets the eyeball), nose bumps interpolated."""
    top, bottom = ROW_INDEX["nasion"], ROW_INDEX["eyes_low"]
    out = list(ROWS[:top + 1])
    for r0, r1 in zip(ROWS[top:bottom], ROWS[top + 1:bottom + 1], strict=True):
        name = f"{r0[0]}_{r1[0]}"
        out.append((name, *[0.5 * (p + q) for p, q in zip(r0[1:8], r1[1:8], strict=True)], r0[8]))
        NOSE[name] = tuple(0.5 * (p + q) for p, q in zip(NOSE[r0[0]], NOSE[r1[0]], strict=True))
        out.append(r1)
    return out + list(ROWS[bottom + 1:])


def _nape(rows):
    """Back midline x (xb) of the rows below the cheekbones from one smooth profile of the
    height at the back (y0 + lift): the back of the head curves into the nape and the neck
    instead of falling straight and stepping in under the skull."""
    ys, xs = (-125, -81, -55, -30, 0, 20, 47), (-134, -130, -131, -135, -143, -150, -158)
    out = []
    for r in rows:
        if r[1] < 47:
            r = (*r[:5], round(float(np.interp(r[1] + r[7], ys, xs)), 2), *r[6:])
        out.append(r)
    return out


def _midway_row(r_, r0, r1, r2, curved):
    """The row halfway between rows r0 and r1 (named r0_r1, in r0's group): columns
    ``curved`` (indices into y0, xf, cx, w, xb, e, lift) on the 4-point subdivision curve
    through r_, r0, r1, r2 (Dyn, Levin & Gregory 1987), the others halfway."""
    mid = [0.5 * (p + q) for p, q in zip(r0[1:8], r1[1:8], strict=True)]
    for c in curved:
        mid[c] = (9.0 * (r0[c + 1] + r1[c + 1]) - r_[c + 1] - r2[c + 1]) / 16.0
    return (f"{r0[0]}_{r1[0]}", *mid, r0[8])


def _under_jaw_rows(rows):
    """Extra rows halfway between those from the menton down the throat: the jaw's weights
    fall from 1 to 0.5 there, and with rows 10-20 mm apart the skin folded along them
    when the jaw opened wide; twice as many rows spread the stretch. The new rows' height
    and front (y0, xf) follow the 4-point subdivision scheme (Dyn, Levin & Gregory 1987)
    rather than the chord, so the chin-throat corner is rounded over three rows instead of
    bent 50 degrees at one."""
    names = [r[0] for r in rows]
    top, bottom = names.index("menton"), names.index("neck1")
    out = list(rows[:top + 1])
    for k in range(top, bottom):
        out.append(_midway_row(rows[k - 1], rows[k], rows[k + 1], rows[k + 2], (0, 1)))
        out.append(rows[k + 1])
    return out + list(rows[bottom + 1:])


def _crown_rows(rows):
    """Extra rows halfway between those from the vertex down to the forehead, on the
    4-point subdivision curve (Dyn, Levin & Gregory 1987) in height, front, half width
    and back (y0, xf, w, xb): the crown's rows were 5-18 mm apart and its outline showed
    their corners in front and side views."""
    names = [r[0] for r in rows]
    top, bottom = names.index("vertex"), names.index("forehead2")
    out = []
    for k in range(top, bottom):
        before = rows[k - 1] if k > top else rows[k]
        out += [rows[k], _midway_row(before, rows[k], rows[k + 1], rows[k + 2], (0, 1, 3, 4))]
    return out + list(rows[bottom:])


def _smooth_sides(rows, lo=-25.0, hi=125.0, sigma=7.0):
    """Section centre (cx) and half width (w) of the rows from the forehead down to the
    chin smoothed over height (Gaussian kernel, sigma mm, locally linear): their slopes
    changed from row to row, and the side of the face showed horizontal light and dark
    bands in side views. The front midline (xf, e: the profile, the lips) is untouched."""
    ys = np.array([r[1] for r in rows])
    keep = (ys >= lo - 2 * sigma) & (ys <= hi + 2 * sigma)
    out = []
    for r in rows:
        y = r[1]
        if not lo <= y <= hi:
            out.append(r)
            continue
        k = np.exp(-0.5 * ((ys[keep] - y) / sigma) ** 2)
        new = []
        for col in (3, 4):  # cx, w
            v = np.array([q[col] for q in rows])[keep]
            a = np.vstack([np.ones_like(ys[keep]), ys[keep] - y]).T
            coef = np.linalg.lstsq(a * k[:, None] ** 0.5, v * k**0.5, rcond=None)[0]
            new.append(round(float(coef[0]), 3))
        out.append((*r[:3], *new, *r[5:]))
    return out


ROWS = _smooth_sides(_nape(_under_jaw_rows(_crown_rows(_eye_rows()))))
ROW_INDEX = {r[0]: i for i, r in enumerate(ROWS)}
EYE_ROWS = {r[0] for r in ROWS[ROW_INDEX["nasion"] + 1:ROW_INDEX["eyes_low"]]}
# Front z targets (on the mouth row) of the columns; the mouth corner is one of them.
FRONT_Z = [0, 4, 8, 12, 16, 20, MOUTH_HALF_WIDTH, 29, 31.5, 34, 36.5, 39, 41.5, 44, 49, 53.5]


def bell(u):
    """Raised cosine: 1 at u = 0, 0 for |u| >= 1, smooth in between."""
    u = np.clip(np.abs(u), 0.0, 1.0)
    return 0.5 + 0.5 * np.cos(np.pi * u)


def ramp(u, lo, hi):
    """Raised-cosine step: 0 below lo, 1 above hi."""
    t = np.clip((u - lo) / (hi - lo), 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * t)


def column_angles():
    """Angles phi (0 = front midline, pi = back midline) of the half-head columns."""
    name, y0, xf, cx, w, xb, e, lift, g = ROWS[ROW_INDEX["A"]]
    front = [np.arcsin(min((z / w), 1.0) ** (e / 2.0)) for z in FRONT_Z]
    n_side = 4
    side = list(np.linspace(front[-1], np.pi / 2, n_side + 2)[1:])
    back = list(np.radians([100.0, 110.0, 120.0, 135.0, 150.0, 165.0, 180.0]))
    return np.array(front + side + back)
