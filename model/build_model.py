"""Build the toolkit's own Parke-style face model and write it to ``model/``.

This is NOT Parke's data (which is not available to us): it is a new mesh built in the
manner Parke described (a half face, mirrored across the midsagittal plane, whose vertex
groups move by rotation, translation and scaling), plus the inside of the mouth that
CASSI added (teeth, tongue, palate). Run ``python model/build_model.py`` to rebuild.

Construction (all mm, model frame: origin = upper incisor tip, +x front, +y up,
+z the subject's left):
* skin: a lofted half head on a structured grid. Rows are horizontal (or, in the lower
  face, tilted to follow the jaw line) cross-sections, columns run from the front
  midline around to the back midline. Nose, eye sockets, cheekbones, lips and chin are
  smooth bumps on top of the loft. The two lips are their own rows, with a real opening.
* eyes: spheres in the sockets; teeth: two arches of individual crowns; tongue: a closed
  body from the tip over the dorsum (through the four tongue pellet sites) down to the
  hyoid and along the floor of the mouth, with its jaw attachment and pellet share per
  vertex (docs/TONGUE.md); palate: ``cassi_fit.palate`` (joined to the upper teeth's
  necks, with a velum); pharyngeal wall: ``cassi_fit.pharynx``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cassi_fit._io import atomic_write  # noqa: E402
from cassi_fit.face_model import MATERIALS  # noqa: E402

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


def section_point(row, phi):
    """(x, y, z) of the loft (no bumps) at angle phi on a row."""
    name, y0, xf, cx, w, xb, e, lift, g = row
    c, s = np.cos(phi), np.sin(phi)
    if phi <= np.pi / 2:
        x = cx + (xf - cx) * abs(c) ** (2.0 / e)
        z = w * abs(s) ** (2.0 / e)
    else:
        x = cx - (cx - xb) * abs(c)
        # behind the jaw angle the rows under the jaw keep the neck's width, so the neck
        # rises into the head behind the ear instead of meeting a shelf under the skull
        if lift > 0 or y0 < -60:
            w = w + max(NECK_HALF_WIDTH - w, 0.0) * ramp(phi, np.pi / 2 + 0.05, np.pi / 2 + 0.6)
        z = w * s
    depth = np.clip(xf - x, 0.0, 80.0) / 80.0  # 0 at the front, 1 at the gonion and behind
    fade = 1.0  # the rows keep their lift round to the nape (no step under the skull)
    return np.array([x, y0 + lift * np.sin(np.pi / 2 * depth) * fade, z])


# The palpebral fissure: half width (mm, about the eyeball's centre line in z, shifted
# 0.5 mm out), the upper and lower lid margins' heights above / below the centre (the
# upper lid covers the iris's top 0.8 mm, the lower lid meets its bottom edge: a fissure
# 9.9 mm tall and 29 mm wide, Farkas' adult norms of about 10 and 28-30 mm; the margins
# are full arcs, not pointed, so that the eye does not read as a slit), the outer
# corner's lift (canthal tilt), the lids' thickness on the eyeball.
FISSURE = {"half_width": 14.5, "upper": 4.4, "lower": 5.5, "tilt": 0.8, "lid": 2.0}


def lid_margins(az):
    """(u, upper, lower): the fissure coordinate u (-1 inner corner, +1 outer) at ``az``
    and the heights of the upper and lower lid margins there (equal outside |u| < 1)."""
    ey, ez, f = EYE_CENTRE[1], EYE_CENTRE[2], FISSURE
    u = (az - ez - 0.5) / f["half_width"]
    opening = max(1.0 - u * u, 0.0)
    centre = ey + 0.4 + f["tilt"] * np.clip(u, -1.0, 1.0)
    return u, centre + f["upper"] * opening**0.45, centre - f["lower"] * opening**0.6


# Rows from below the eyes to the nasion (y) whose heights bend to the lid margins: the
# second and third run along the lower and upper margins (the fissure's outline follows
# grid rows instead of cutting across them).
EYE_ROW_Y = (54.0, 59.5, 65.5, 76.0)


def eye_row_y(y, az):
    """Height of a loft point of the eye rows, bent so that rows follow the lid margins."""
    if not EYE_ROW_Y[0] < y < EYE_ROW_Y[3]:
        return y
    u, up, lo = lid_margins(az)
    g = 1.0 - ramp(abs(u), 0.7, 2.0)
    target = (EYE_ROW_Y[0], g * lo + (1 - g) * EYE_ROW_Y[1], g * up + (1 - g) * EYE_ROW_Y[2],
              EYE_ROW_Y[3])
    return float(np.interp(y, EYE_ROW_Y, target))


def eyelids(x, y, az):
    """x of a skin point near the eye: inside the fissure just behind the eyeball's
    surface (the eyeball shows), around it the lids lying on the eyeball, blending into
    the face over 2-9 mm."""
    ex, ey, ez = EYE_CENTRE
    f = FISSURE
    u, y_up, y_lo = lid_margins(az)
    t_v = max(y - y_up, y_lo - y, 0.0)
    t_h = max(abs(u) - 1.0, 0.0) * f["half_width"]
    t = np.hypot(t_v, t_h)
    inside = abs(u) < 1.0 and y_lo + 0.05 < y < y_up - 0.05
    ball = np.sqrt(max(EYE_RADIUS**2 - (y - ey) ** 2 - (az - ez) ** 2, 0.0))
    shell = EYE_RADIUS * np.sqrt(max(1.0 - ((y - ey) / EYE_RADIUS) ** 2
                                     - ((az - ez) / (1.6 * EYE_RADIUS)) ** 2, 0.0))
    if inside:  # 3 mm behind the ball: the lid margins' triangles dive in at once
        return ex + ball - 3.0
    w = 1.0 - ramp(t, 0.5, 8.0 + 8.0 * ramp(-u, 0.3, 1.2))  # softer toward the nose
    lid = 0.3 + (f["lid"] - 0.3) * max(ramp(t, 0.0, 2.0), ramp(abs(u), 0.9, 1.1))  # thin margin
    lid += 3.0 * ramp(-u, 0.3, 1.3) * ramp(t, 1.0, 5.0)  # fuller toward the nose (no trough)
    x = w * (ex + shell + lid) + (1.0 - w) * x
    return max(x, ex + ball + 0.8) if ball > 0 else x


def bumps(name, p):
    """Add nose, lips, eye sockets, cheekbones, chin, jaw angle and ears to a loft point."""
    x, y, z = p
    az = abs(z)
    fr = ramp(x, -55.0, -30.0)  # face features only on the front of the head
    if name in EYE_ROWS:
        y = y + fr * (eye_row_y(y, az) - y)
    x0, y0 = x, y
    if name in LIP_BUMP:
        x += LIP_BUMP[name] * bell(az / (MOUTH_HALF_WIDTH + 3.0))
        if name in ("A_in", "B_in"):  # the inner lip rows curl in toward the teeth
            inside = bell(az / MOUTH_HALF_WIDTH)
            y += (1.5 if name == "A_in" else -1.5) * inside
    if name in ("A", "A_in", "B_in", "B"):  # lips parted at rest, closing to the corners
        mid = 0.5 * (STO_UPPER + STO_LOWER)
        y = mid + (y - mid) * np.sqrt(max(1.0 - (az / MOUTH_HALF_WIDTH) ** 2, 0.0))
    if name in ("UL", "ul_red", "ul_low", "ll_high", "ll_red", "LL"):
        # the vermilion is a lens: its height shrinks toward the mouth corners
        u = az / MOUTH_HALF_WIDTH
        squeeze = np.where(u <= 1.0, 1.0 - 0.75 * u**3, 0.25 + 0.75 * ramp(u, 1.0, 1.8))
        y = y * squeeze
    if name in NOSE:
        h, hw = NOSE[name]
        x += h * bell(az / hw) ** (1.3 if h < 15 else 1.0)
        if name == "nostril":  # alar wings and the two nostril dents
            x += 6.0 * bell((az - 14.5) / 6.0)
            x -= 8.0 * bell((az - 7.0) / 4.0)
        if name == "nose_tip":
            x += 4.0 * bell((az - 14.5) / 6.0)
        if name == "subnasale":
            x += 3.0 * bell((az - 15.0) / 5.0)
    # orbit (a shallow hollow above the upper lid), cheek fullness, a broad low brow ridge
    ex, ey, ez = EYE_CENTRE
    x -= 1.0 * bell(np.hypot((y - ey - 3.0) / 12.0, (az - ez) / 18.0))
    x += 4.0 * bell(np.hypot((y - 32.0) / 24.0, (az - 36.0) / 20.0))  # cheek fullness
    x += 1.5 * bell((y - 88.0) / 14.0) * (1.0 - ramp(az, 40.0, 64.0))  # brow ridge
    x = eyelids(x, y, az)
    x += 4.0 * bell(np.hypot((y - 47.0) / 13.0, (az - 52.0) / 16.0))
    if az > 30:
        z = np.sign(z) * (az + 2.0 * bell(np.hypot((y - 47.0) / 16.0, (x + 50.0) / 28.0)))
        az = abs(z)
    # chin prominence (mentalis)
    if name in ("chin", "chin_low", "fold"):
        x += 2.0 * bell(az / 18.0)
    x, y = x0 + fr * (x - x0), y0 + fr * (y - y0)
    # the lateral flare of the jaw angle
    if ROWS[ROW_INDEX[name]][8] == "l" and y < 10:
        gon = bell(np.hypot((x + 82.0) / 16.0, (y + 40.0) / 22.0))
        z = np.sign(z) * (az + 5.0 * gon)
    return np.array([x, y, z])


# ---------------------------------------------------------------------------- ears
# The left ear in the side plane: canal (x, y), length (superaurale to subaurale) and
# width (mm; Farkas' adult norms are about 60-65 and 30-35), backward tilt of the long axis.
EAR = {"canal": (-106.0, 38.0), "length": 62.0, "width": 33.0, "tilt_deg": 15.0}
EAR_N = 24  # points round the outline
# Rings from the attachment on the head out to the helix rim and back in over the front
# of the ear: (outline scale, lateral height as a fraction of the rim's, centre pull
# toward the concha 0..1). 0: base inside the head; 1-2: the back of the rim; 3: the rim's
# free edge (helix); 4: its inner lip; 5: the scapha groove; 6: the antihelix; 7: concha.
EAR_RINGS = ((0.80, -0.10, 0.0), (0.97, 0.45, 0.0), (1.03, 0.85, 0.0), (1.0, 1.0, 0.0),
             (0.88, 0.95, 0.0), (0.80, 0.50, 0.0), (0.64, 0.70, 0.15), (0.32, 0.05, 0.6))


def ear_outline(t):
    """(a, b) of the ear's outline at t in [0, 1): a forward, b up along the ear's axis,
    from the helix root (front, at the top of the tragus) up over the top, down the back
    and round the lobe; unit-free (half width 1, half length 1 at the top)."""
    th = 2 * np.pi * t
    s, c = np.sin(th), -np.cos(th)  # t = 0 at the bottom of the lobe, 0.25 at the front
    a = np.sign(s) * np.abs(s) ** 0.75  # fuller than an ellipse: a broad, round top
    b = np.sign(c) * np.abs(c) ** 0.85
    lobe = ramp(-b, 0.2, 1.0)
    return a * (1.0 - 0.3 * lobe) + 0.12 * lobe, b


def ear_rim_height(a, b):
    """Lateral stand-off (mm) of the helix rim from the head round the outline: small at
    the front where the ear joins the face, most at the back and top, less at the lobe."""
    back = ramp(-a, -0.6, 0.9)
    return 4.0 + 16.0 * back * (1.0 - 0.45 * ramp(-b, 0.2, 1.0))


def build_ears(skin):
    """Both ears: a folded sheet from the attachment inside the head out to the helix rim
    and back in to the concha, mirrored; its faces wound as the skin grid's."""
    from scipy.interpolate import LinearNDInterpolator

    side = skin[(skin[:, 2] > 20.0) & (skin[:, 0] < -60.0) & (skin[:, 1] > -20.0)]
    head_z = LinearNDInterpolator(side[:, :2], side[:, 2])
    cx, cy = EAR["canal"]
    tilt = np.radians(EAR["tilt_deg"])
    t = np.arange(EAR_N) / EAR_N
    a, b = ear_outline(t)
    rim = ear_rim_height(a, b)
    concha = np.array([0.35, -0.25])  # centre of the concha in outline units (front, low)
    half = np.array([EAR["width"] / 2, EAR["length"] / 2])
    centre = np.array([cx, cy]) + np.array([-0.15 * EAR["width"], 0.18 * EAR["length"]])

    def place(u, v):
        """outline units -> (x, y): forward is +x, the long axis leans back by tilt."""
        du, dv = u * half[0], v * half[1]
        return (centre[0] + du * np.cos(tilt) - dv * np.sin(tilt),
                centre[1] + du * np.sin(tilt) + dv * np.cos(tilt))

    verts = []
    for scale, height, pull in EAR_RINGS:
        u = (1 - pull) * scale * a + pull * concha[0]
        v = (1 - pull) * scale * b + pull * concha[1]
        x, y = place(u, v)
        verts += list(np.column_stack([x, y, head_z(x, y) + height * rim]))
    x, y = place(*concha)
    verts.append([x, y, float(head_z(x, y)) - 1.0])  # the canal
    verts = np.array(verts)
    if not np.all(np.isfinite(verts)):
        raise ValueError("an ear point lies off the side of the head")
    faces, n, last = [], EAR_N, len(verts) - 1
    for r in range(len(EAR_RINGS) - 1):
        for j in range(n):
            p, q = r * n + j, r * n + (j + 1) % n
            faces += [(p, q + n, q), (p, p + n, q + n)]
    r = len(EAR_RINGS) - 1
    faces += [(r * n + j, last, r * n + (j + 1) % n) for j in range(n)]
    faces = np.array(faces)
    mirrored = verts * [1, 1, -1]
    return (np.concatenate([verts, mirrored]),
            np.concatenate([faces, faces[:, ::-1] + len(verts)]))


# The glabella and the brow above the inner eye corners: rows from the upper lid to the
# forehead (y) whose front sections are made convex across z (up to GLABELLA_Z mm), with
# a weight ramping in from the upper lid: where the nose's bridge met the lids' fullness
# toward the nose, the bumps left a groove above each inner eye corner that read as a
# frown in front renders.
GLABELLA_Y, GLABELLA_Z = (65.0, 71.0, 96.0, 104.0), 34.0


def upper_hull(z, x):
    """Smallest concave function of z on or above the points (z, x), at the points' z."""
    hull = []
    for p in zip(z, x, strict=True):
        while len(hull) >= 2:
            (z0, x0), (z1, x1) = hull[-2], hull[-1]
            if (x1 - x0) * (p[0] - z0) <= (p[1] - x0) * (z1 - z0):
                hull.pop()
            else:
                break
        hull.append(p)
    hz, hx = zip(*hull, strict=True)
    return np.interp(z, hz, hx)


def smooth_glabella(grid):
    """Fill the grooves above the inner eye corners (in place): each row's front section
    lifted toward its convex hull across z, weighted by height (see GLABELLA_Y)."""
    lo, full, top, off = GLABELLA_Y
    for i in range(grid.shape[0]):
        y = grid[i, 0, 1]
        wy = ramp(y, lo, full) * (1.0 - ramp(y, top, off))
        if wy <= 0.0:
            continue
        cols = np.nonzero((grid[i, :, 2] <= GLABELLA_Z) & (column_angles() < np.pi / 2))[0]
        cols = cols[np.argsort(grid[i, cols, 2])]
        z, x = grid[i, cols, 2], grid[i, cols, 0]
        fade = 1.0 - ramp(z, 0.6 * GLABELLA_Z, GLABELLA_Z)
        grid[i, cols, 0] = x + wy * fade * (upper_hull(z, x) - x)


# The nose's side between the nose ridge and the inner eye corners, from below the eyes
# to the glabella (y range, mm; columns off the midline and inside the inner corner).
CANTHUS_Y, CANTHUS_Z = (54.0, 82.0), 16.5
CANTHUS_BULGE = 0.012  # the fill's curvature (-Laplacian of x, 1/mm): gently convex


def smooth_canthus(grid, sweeps=400):
    """The nose's side wall beside the inner eye corners made smooth (in place): x of the
    points there becomes the harmonic (membrane) fill of the points around it, weighted
    by their distances across the surface (y, z). The lids' pull toward the eyeball and
    the rows bending to the inner corner left a kink along each side of the nasal root,
    rising from the inner corner toward the glabella, that read as a frown."""
    lo, hi = CANTHUS_Y
    ys, zs = grid[:, :, 1], grid[:, :, 2]
    free = np.zeros(grid.shape[:2], bool)
    free[1:-1, 1:-1] = (ys[1:-1, 1:-1] > lo) & (ys[1:-1, 1:-1] < hi) & (zs[1:-1, 1:-1] < CANTHUS_Z)
    free[:, 0] = False
    idx = np.argwhere(free)
    x = grid[:, :, 0]

    def open_eye(a, b):
        """Whether grid point (a, b) lies in the fissure (on the eyeball, not skin)."""
        u, up, low = lid_margins(abs(zs[a, b]))
        return abs(u) < 1.0 and low + 0.05 < ys[a, b] < up - 0.05

    def corner_x(a, b):
        """x of a grid point, or for one in the fissure that of the lid margins beside it
        in its column (the skin slopes into the inner corner, not into the eyeball)."""
        if not open_eye(a, b):
            return x[a, b]
        up = next(k for k in range(a, -1, -1) if not open_eye(k, b))
        low = next(k for k in range(a, grid.shape[0]) if not open_eye(k, b))
        return 0.5 * (x[up, b] + x[low, b])

    nbs = [((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)) for i, j in idx]
    for _ in range(sweeps):
        for (i, j), nb in zip(idx, nbs, strict=True):
            w = np.array([1.0 / max(np.hypot(ys[a, b] - ys[i, j], zs[a, b] - zs[i, j]), 0.5) ** 2
                          for a, b in nb])
            x[i, j] = (sum(wk * corner_x(a, b) for wk, (a, b) in zip(w, nb, strict=True))
                       + CANTHUS_BULGE) / w.sum()


def smooth_cheeks(grid, phis, sigma=6.0, lo=-12.0, hi=100.0, cols=(45.0, 60.0, 110.0, 135.0)):
    """The side of the face (columns from 45 to 135 degrees, rows from below the lower
    lip to the forehead) smoothed over height, in place: x and z of each point become a
    Gaussian-weighted (sigma mm) local-linear fit over the column's rows. The cheekbone,
    cheek and eye-socket bumps and the rows' changing widths made the surface's slope
    change from row to row, which showed as horizontal light and dark bands in side
    views."""
    ys = grid[:, 0, 1].copy()
    rows = np.nonzero((ys >= lo - 2 * sigma) & (ys <= hi + 2 * sigma))[0]
    c0, c1, c2, c3 = np.radians(cols)
    wc = ramp(phis, c0, c1) * (1.0 - ramp(phis, c2, c3))
    wy = ramp(ys, lo, lo + 8.0) * (1.0 - ramp(ys, hi - 10.0, hi))
    out = grid.copy()
    for i in np.nonzero(wy > 0)[0]:
        for j in np.nonzero(wc > 0)[0]:
            yj = grid[rows, j, 1]  # the column's own heights (the jaw rows rise to the back)
            k = np.exp(-0.5 * ((yj - grid[i, j, 1]) / sigma) ** 2)
            a = np.vstack([np.ones(len(rows)), yj - grid[i, j, 1]]).T * np.sqrt(k)[:, None]
            for c in (0, 2):
                fit = np.linalg.lstsq(a, grid[rows, j, c] * np.sqrt(k), rcond=None)[0][0]
                out[i, j, c] = grid[i, j, c] + wy[i] * wc[j] * (fit - grid[i, j, c])
    grid[:] = out


# The walls of the oral cavity (a pocket of the skin, which has no inside otherwise: the
# background showed through the open mouth): a back wall far behind the tongue and the
# pharynx (x, y range, half width in z, mm) and, for views from the side of the front,
# three pairs of curtains across the cheeks (x, y range, inner |z|, largest |z|, least
# gap to the skin), outside the teeth and the tongue. All face the front and lie in planes
# of constant x at rest (side walls would show face-on behind the tongue in the inside
# view); the renderer draws the "mouth_wall" region double-sided, in the front and side
# views only. The back wall is static (weights and fields 0); the curtains move with the
# cheek beside them (the jaw weights and fields of the nearest skin), so that the jaw's
# opening, a calibrated jaw shape or a narrower mouth does not push the cheek in through
# them.
MOUTH_BACK = {"x": -100.0, "y": (-45.0, 30.0), "z": 32.0}
MOUTH_CURTAINS = ({"x": -22.0, "y": (-30.0, 20.0), "z": (25.0, 52.0), "gap": 3.0},
                  {"x": -46.0, "y": (-35.0, 25.0), "z": (27.0, 48.0), "gap": 4.0},
                  {"x": -75.0, "y": (-40.0, 28.0), "z": (24.0, 50.0), "gap": 4.0})


def build_mouth_wall(skin, n=6):
    """Vertices and faces (wound like the skin grid, before the flip in ``build``) of the
    back wall and the curtains of the mouth, all facing +x, and which vertices are the
    curtains' (they follow the cheek)."""
    from scipy.interpolate import LinearNDInterpolator

    side = skin[(skin[:, 2] > 20.0) & (skin[:, 1] > -70.0) & (skin[:, 1] < 60.0)]
    head_z = LinearNDInterpolator(side[:, :2], side[:, 2])
    verts, faces, curtain = [], [], []

    def sheet(x, ys, zs, is_curtain):
        """A sheet in the plane x at heights ys, zs[i] ascending across at ys[i]."""
        base, k = len(verts), zs.shape[1]
        verts.extend([x, y, z] for y, row in zip(ys, zs, strict=True) for z in row)
        curtain.extend([is_curtain] * (len(verts) - base))
        for i in range(len(ys) - 1):
            for j in range(k - 1):
                a, b = base + i * k + j, base + i * k + j + 1
                c, d = base + (i + 1) * k + j + 1, base + (i + 1) * k + j
                faces.extend([(b, d, a), (c, d, b)])

    y = np.linspace(*MOUTH_BACK["y"], n + 2)
    z = np.linspace(-MOUTH_BACK["z"], MOUTH_BACK["z"], n + 1)
    sheet(MOUTH_BACK["x"], y, np.tile(z, (len(y), 1)), False)
    for c in MOUTH_CURTAINS:
        y = np.linspace(*c["y"], n + 2)
        outer = np.array([min(c["z"][1], float(head_z(c["x"], a)) - c["gap"]) for a in y])
        if not np.all(np.isfinite(outer) & (outer > c["z"][0] + 2.0)):
            raise ValueError("a mouth curtain does not fit inside the cheek")
        zs = np.array([np.linspace(c["z"][0], o, 4) for o in outer])
        sheet(c["x"], y, zs, True)
        sheet(c["x"], y, -zs[:, ::-1], True)
    return np.array(verts), np.array(faces), np.array(curtain)


def build_skin():
    """Half-head grid -> full mirrored skin: vertices, faces, row/col ids, mouth mask."""
    phis = column_angles()
    n_r, n_c = len(ROWS), len(phis)
    grid = np.zeros((n_r, n_c, 3))
    for i, row in enumerate(ROWS):
        for j, phi in enumerate(phis):
            grid[i, j] = bumps(row[0], section_point(row, phi))
    grid[:, 0, 2] = 0.0
    grid[:, -1, 2] = 0.0
    smooth_glabella(grid)
    smooth_canthus(grid)
    smooth_cheeks(grid, phis)
    # the jaw angle's flare into the neck (a notch in three-quarter views)
    smooth_cheeks(grid, phis, sigma=7.0, lo=-80.0, hi=-8.0, cols=(55.0, 75.0, 140.0, 165.0))
    corner = FRONT_Z.index(MOUTH_HALF_WIDTH)
    # collapse the lip rows outside the mouth onto one line (the lips meet at the corners)
    a, a_in, b_in, b = (ROW_INDEX[k] for k in ("A", "A_in", "B_in", "B"))
    for j in range(corner, n_c):
        mid = 0.5 * (grid[a, j] + grid[b, j])
        grid[a, j] = grid[a_in, j] = grid[b_in, j] = grid[b, j] = mid
    # upper lip pellet site exactly at the midline vertex of row UL (x, y)
    return grid, corner


def mirror_grid(grid, corner):
    """Full skin from the half grid: vertex array, faces, (row, col, side) per vertex."""
    n_r, n_c, _ = grid.shape
    verts, ids, index = [], [], {}
    merged = {ROW_INDEX[k] for k in ("A_in", "B_in", "B")}
    for i in range(n_r):
        for j in range(n_c):
            for side in (1, -1):
                if side == -1 and j in (0, n_c - 1):
                    index[(i, j, -1)] = index[(i, j, 1)]
                    continue
                if j >= corner and i in merged:  # the lips meet: one vertex for 4 rows
                    index[(i, j, side)] = index[(ROW_INDEX["A"], j, side)]
                    continue
                index[(i, j, side)] = len(verts)
                p = grid[i, j].copy()
                p[2] *= side
                verts.append(p)
                ids.append((i, j, side))
    return np.array(verts), np.array(ids), index


def skin_faces(n_r, n_c, index, corner):
    """Quads between consecutive rows (not across the mouth opening), split in two."""
    a_in = ROW_INDEX["A_in"]
    faces = []
    for i in range(n_r - 1):
        for j in range(n_c - 1):
            if i == a_in and j < corner:
                continue  # the mouth opening
            for side in (1, -1):
                q = [index[(i, j, side)], index[(i, j + 1, side)],
                     index[(i + 1, j + 1, side)], index[(i + 1, j, side)]]
                tris = [(q[0], q[3], q[1]), (q[1], q[3], q[2])]
                for t in tris:
                    if len(set(t)) < 3:
                        continue
                    faces.append(t if side == 1 else (t[0], t[2], t[1]))
    return faces


# dy (mm below the jaw line) where the lower face's weight falls from one of Parke's
# plateaus to the next (jaw 1 -> under chin 0.75 -> neck 0.5 -> 0): spread over the whole
# submental skin, and to 0 above the neck's base. (The first model fell 1 -> 0.75 within
# 6.5 mm below the jaw line; the skin folded along it when the jaw opened.)
JAW_RAMPS = ((0.0, 8.8), (10.0, 20.0), (22.0, 70.0))

# |z| (mm) within which the upper lip stays still when the jaw moves (Parke's upper lip)
UPPER_LIP_STILL = 8


def skin_weights(verts, ids, corner_z):
    """Per-vertex fraction of the jaw rotation (Parke's values) and the region cores.

    One smooth field of position (raised-cosine ramps between plateaus), the same for
    the upper and lower rows except across the mouth opening, so the skin stretches
    instead of tearing: chin and lower lip 1.00, beside the mouth the cheeks 0.35 (fading
    to 0 toward the cheekbones and the ears), under the chin 0.75, upper neck 0.50, 0 on
    the lower neck, the ears and the back of the head. Inside the mouth the lips blend to
    the corner value (0.35): the lower lip from the midline, so that with the jaw open
    wide it hangs in a curve, the upper lip from UPPER_LIP_STILL mm out (blends over the
    mouth's outer third folded the lower lip's triangles over at the corners, and bent
    the upper lip's edge 39 degrees where its blend began).
    """
    x, y = verts[:, 0], verts[:, 1]
    lower = np.array([ROWS[i][8] == "l" for i in ids[:, 0]])
    phis = column_angles()
    phi = phis[ids[:, 1]]
    phi_c = phis[FRONT_Z.index(MOUTH_HALF_WIDTH)]
    phi_in = phis[FRONT_Z.index(UPPER_LIP_STILL)]
    p = PARKE
    # jaw line from menton to gonion; dy > 0 below it
    y_line = np.interp(x, [-86.0, -4.0], [-34.0, -49.5])
    dy = y_line - y
    vert = (p["jaw"] + (p["under_chin"] - p["jaw"]) * ramp(dy, *JAW_RAMPS[0])
            + (p["neck"] - p["under_chin"]) * ramp(dy, *JAW_RAMPS[1])
            - p["neck"] * ramp(dy, *JAW_RAMPS[2]))
    back = 1.0 - ramp(-x, 60.0, 140.0)
    # 0 in the middle of the mouth, 1 at the corners: the lower lip from the midline, the
    # upper lip from UPPER_LIP_STILL mm out
    lat = np.where(lower, ramp(phi, phis[0], phi_c), ramp(phi, phi_in, phi_c))
    lat = np.where(phi > np.pi / 2, 1.0, lat)
    below = ramp(-y, 4.0, 30.0)               # mouth level -> mandible
    side_low = p["cheek"] * (1.0 - below) + vert * below
    w_lower = back * ((1.0 - lat) * vert + lat * side_low)
    w_upper = back * lat * p["cheek"] * (1.0 - ramp(y, 6.0, 30.0))
    w = np.where(lower, w_lower, w_upper)
    return w, lower


def jaw_shape_field(verts):
    """Weights of the jaw/chin conformation (C7-C11): the whole lower face and the neck
    (1), fading smoothly to 0 from below the mouth up to the upper lip and toward the
    back of the neck. Broader and smoother than the jaw rotation's region weights: the
    conformation may move the jaw angle by 10-20 mm, which Parke's regions would crease."""
    x, y = verts[:, 0], verts[:, 1]
    return (1.0 - ramp(y, -15.0, 10.0)) * (1.0 - ramp(-x, 90.0, 135.0))


def tooth(point, tangent, width, thick_cerv, thick_occ, height, up):
    """One crown: a six-sided frustum from the occlusal ring to the cervical ring.

    ``point`` is where the labial/buccal face meets the occlusal level on the arch;
    ``tangent`` the arch direction (x, z) away from the midline. Left side only.
    """
    t = np.array([tangent[0], 0.0, tangent[1]])
    n = np.array([tangent[1], 0.0, -tangent[0]])  # outward (labial/buccal) in the x-z plane
    v = np.array([0.0, 1.0, 0.0]) * (1 if up else -1)
    ring = []
    for level, thick, shrink in ((0.0, thick_occ, 0.92), (height, thick_cerv, 0.80)):
        centre = point - n * thick / 2 + v * level
        for a in np.linspace(0, 2 * np.pi, 7)[:-1]:
            ring.append(centre + t * np.cos(a) * width / 2 * shrink + n * np.sin(a) * thick / 2)
    ring.append(point - n * thick_occ / 2 - v * 0.4)         # occlusal cap
    ring.append(point - n * thick_cerv / 2 + v * (height + 0.5))  # cervical cap
    faces = []
    for k in range(6):
        a0, a1, b0, b1 = k, (k + 1) % 6, 6 + k, 6 + (k + 1) % 6
        faces += [(a0, b0, a1), (a1, b0, b1), (12, a1, a0), (13, b0, b1)]
    if not up:
        faces = [(a, c, b) for a, b, c in faces]
    return np.array(ring), faces


ARCH = np.array([(0.0, 0.0), (-2.5, 6.0), (-6.5, 12.0), (-11.5, 16.5), (-18.5, 20.5),
                 (-26.0, 23.5), (-34.0, 25.5), (-43.0, 27.0), (-52.0, 28.0), (-60.0, 28.5)])
UPPER_TEETH = [  # width, cervical thickness, occlusal thickness, crown height
    (8.5, 7.0, 1.5, 10.5), (6.5, 6.0, 1.5, 9.0), (7.5, 8.0, 2.5, 10.0), (7.0, 9.0, 7.0, 8.0),
    (6.5, 9.0, 7.0, 7.5), (10.0, 11.0, 9.5, 7.0), (9.0, 10.5, 9.0, 6.5)]
LOWER_TEETH = [
    (5.5, 6.0, 1.5, 9.0), (6.0, 6.0, 1.5, 9.5), (7.0, 7.5, 2.5, 10.0), (7.0, 8.0, 6.5, 8.0),
    (7.0, 8.5, 7.0, 7.5), (11.0, 10.5, 9.5, 7.5), (10.5, 10.0, 9.0, 7.0)]


def build_arch(arch, teeth, y0, up, snaps=()):
    """Teeth along an arch (x, z) curve, left side then mirrored.

    ``snaps``: (tooth k, ring vertex r, (x, y)) moving one vertex onto a pellet site.
    Returns vertices, faces and ``{(side, k, r): vertex index}`` for the left side.
    """
    seg = np.linalg.norm(np.diff(arch, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    at = lambda q: np.array([np.interp(q, s, arch[:, 0]), np.interp(q, s, arch[:, 1])])
    left_v, left_f, pos = [], [], 0.0
    for k, (wd, tc, to, h) in enumerate(teeth):
        mid = pos + wd / 2
        pos += wd
        d = at(mid + 0.5) - at(mid - 0.5)
        d /= np.linalg.norm(d)
        p = np.array([at(mid)[0], y0, at(mid)[1]])
        ring, fs = tooth(p, d, wd, tc, to, h, up)
        for kk, r, xy in snaps:
            if kk == k:
                ring[r, :2] = xy
                if r in (3,) and xy == (0.0, 0.0):
                    ring[r, 2] = 0.0
        base = len(left_v)
        left_v.extend(ring)
        left_f.extend([(a + base, b + base, c + base) for a, b, c in fs])
    left_v = np.array(left_v)
    n = len(left_v)
    right_v = left_v * np.array([1.0, 1.0, -1.0])
    verts = np.concatenate([left_v, right_v])
    faces = np.array(left_f + [(a + n, c + n, b + n) for a, b, c in left_f])
    return verts, faces


# ---------------------------------------------------------------------------- tongue
# The tongue as an organ, midsagittal outline in two lines from the tip to the hyoid:
# * TONGUE_UPPER: the free surface, tip -> dorsum (through T1..T4 exactly, control points
#   2, 4, 6, 8) -> down the pharyngeal surface of the tongue base (facing the oropharynx)
#   -> the vallecula -> the hyoid's upper border;
# * TONGUE_LOWER: the attached side, the tip's underside -> the frenulum -> the floor of the
#   mouth at the genial tubercles behind the symphysis (genioglossus, geniohyoid) -> along
#   the floor (mylohyoid, geniohyoid) back to the hyoid.
# Control point k of one line pairs with control point k of the other: each pair is one
# cross-section (a fan of sections from the genial/hyoid attachment up into the dorsum,
# the way the genioglossus fibres run), so no section crosses another.
# Sources (docs/TONGUE.md): the hyoid body sits about 32 mm in front of C3 (Bibby & Preston
# 1981, the hyoid triangle: C3-H 31.8 +- 2.9 mm) and about 15 mm below the mandibular
# plane; with the synthetic pharyngeal walls at x = -66..-78 mm that puts hyoidale at about
# (-43, -46) mm. The tongue base is kept about 10-15 mm in front of those walls (the
# oropharyngeal airway's depth). The rest volume (measured, docs/TONGUE.md) is checked
# against Liegeois et al. 2010 (MRI, 70 adults: 68.9 +- 7.0 mL women, 89.9 +- 11.5 mL men).
TONGUE_UPPER = [  # x, y: tip -> hyoid
    (-9.0, -4.5), (-12.5, -1.0), SITES["T1"], (-23.0, 4.5), SITES["T2"], (-35.0, 10.0),
    SITES["T3"], (-47.0, 15.1), SITES["T4"], (-58.0, 15.5), (-61.0, 9.0), (-61.5, 0.0),
    (-60.5, -11.0), (-57.5, -23.0), (-53.0, -33.0), (-48.0, -41.0)]
TONGUE_LOWER = [  # x, y: the tip's underside -> floor of the mouth -> hyoid
    (-11.5, -9.0), (-15.5, -11.5), (-19.0, -15.0), (-19.5, -20.5), (-17.5, -26.0),
    (-15.5, -31.0), (-18.5, -34.5), (-23.5, -37.5), (-28.5, -40.0), (-32.5, -42.0),
    (-36.0, -43.5), (-38.5, -44.5), (-40.5, -45.5), (-42.0, -46.0), (-43.5, -46.0),
    (-45.0, -45.0)]
# half width (mm) of each section: the free tongue widens to the dorsum; below the lower
# teeth's occlusal level it must stay inside the lower arch (the rest projection flattens
# what does not); the base behind the molars is the widest part.
TONGUE_HALF_WIDTH = [8.0, 11.5, 14.5, 17.0, 19.0, 20.5, 21.5, 22.5, 23.5, 24.0, 24.0, 23.0,
                     21.0, 18.0, 13.0, 7.0]
# jaw attachment at each section's lower end (fraction of the mandible's motion): the
# floor at the genial tubercles moves with the mandible; toward the hyoid less (the hyoid
# hangs between mandible, skull base and larynx, and drops only part of the way when the
# jaw opens)
TONGUE_FLOOR_JAW = [0.6, 0.8, 0.9, 1.0, 1.0, 1.0, 1.0, 0.95, 0.9, 0.85, 0.8, 0.75, 0.7,
                    0.65, 0.6, 0.55]
TONGUE_DORSUM_JAW = 0.35   # jaw-carried share of the free surface (the pellets move it)
TONGUE_RING = 16
TONGUE_UNDER_TAPER = 0.25  # the underside narrows into the floor of the mouth
TONGUE_ANCHOR = 10  # control point index from which CASSI's fixed anchors hold the back
TONGUE_FREE_TIP = 2  # in front of control point 2 (T1) the whole section follows the pellets
TONGUE_FLOOR_FOLLOW = 0.2  # share of the pellets' displacement the floor still takes
TONGUE_BASE = 11  # control point where the back turns down into the base (y about 0)
TONGUE_ROOT_FOLLOW = 0.5  # share of the pellets' displacement left at the hyoid end


def catmull_rom(points, per_segment=2):
    """Points on a Catmull-Rom spline through ``points`` (k, d), the points included."""
    p = np.concatenate([points[:1] * 2 - points[1:2], points, points[-1:] * 2 - points[-2:-1]])
    out = []
    for i in range(1, len(p) - 2):
        for t in np.arange(per_segment) / per_segment:
            a, b, c, d = p[i - 1], p[i], p[i + 1], p[i + 2]
            out.append(0.5 * (2 * b + (c - a) * t + (2 * a - 5 * b + 4 * c - d) * t**2
                              + (3 * b - a - 3 * c + d) * t**3))
    out.append(points[-1])
    return np.array(out)


def build_tongue():
    """Closed tongue tube: vertices, faces, per-vertex fields (``tongue_s`` arc length
    along the upper line, ``tongue_jaw`` jaw attachment, ``tongue_follow`` share of the
    pellet displacement), control station ids of T1..T4, the anchor arc length.

    Station i is the section from the upper-line point U_i (ring vertex 0) to the
    lower-line point L_i (ring vertex R/2); ring vertex k sits at the fraction
    u = (1 - cos a_k) / 2 of the way and at z = +-half width x |sin a_k|^0.6 (narrower
    toward the floor)."""
    per = np.column_stack([TONGUE_UPPER, TONGUE_LOWER, TONGUE_HALF_WIDTH, TONGUE_FLOOR_JAW])
    st = catmull_rom(per, 2)                # stations; control point k is station 2k
    up, lo, hw, floor_jaw = st[:, :2], st[:, 2:4], st[:, 4], st[:, 5]
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(up, axis=0), axis=1))])
    psi = 2 * np.pi * np.arange(TONGUE_RING) / TONGUE_RING
    s_free = s[2 * TONGUE_FREE_TIP]
    # down the tongue base toward the hyoid the pellets' share falls to TONGUE_ROOT_FOLLOW
    s_base = s[2 * TONGUE_BASE]
    root_fall = 1.0 - (1.0 - TONGUE_ROOT_FOLLOW) * np.clip((s - s_base) / (s[-1] - s_base), 0, 1)
    verts, svals, jaw, follow = [], [], [], []
    for i in range(len(st)):
        # the sections in front of T1 (the free tip) follow the pellets whole; behind,
        # the floor takes only TONGUE_FLOOR_FOLLOW of it
        attached = min(1.0, s[i] / s_free) if s_free > 0 else 1.0
        for k in range(len(psi)):
            a_m = 2 * np.pi * min(k, TONGUE_RING - k) / TONGUE_RING  # mirror-exact
            u = 0.5 * (1 - np.cos(a_m))
            p = up[i] + u * (lo[i] - up[i])
            sgn = 0.0 if k in (0, TONGUE_RING // 2) else (1.0 if k < TONGUE_RING // 2 else -1.0)
            z = hw[i] * sgn * abs(np.sin(a_m)) ** 0.6
            z *= 1.0 - TONGUE_UNDER_TAPER * max(0.0, -np.cos(a_m))  # narrower below
            verts.append([p[0], p[1], z])
            svals.append(s[i])
            jaw.append(min(1.0, TONGUE_DORSUM_JAW + u * (floor_jaw[i] - TONGUE_DORSUM_JAW)))
            follow.append((1.0 - attached * u * (1.0 - TONGUE_FLOOR_FOLLOW)) * root_fall[i])
    n_st = len(st)
    tang0 = (up[1] - up[0]) / np.linalg.norm(up[1] - up[0])
    tip = 0.5 * (up[0] + lo[0]) - 2.5 * tang0
    root = 0.5 * (up[-1] + lo[-1]) + 1.0 * (up[-1] - up[-2]) / np.linalg.norm(up[-1] - up[-2])
    verts += [[tip[0], tip[1], 0.0], [root[0], root[1], 0.0]]
    svals += [s[0], s[-1]]
    jaw += [TONGUE_DORSUM_JAW + 0.5 * (floor_jaw[0] - TONGUE_DORSUM_JAW),
            TONGUE_DORSUM_JAW + 0.5 * (floor_jaw[-1] - TONGUE_DORSUM_JAW)]
    follow += [1.0, (1.0 - 0.5 * (1.0 - TONGUE_FLOOR_FOLLOW)) * TONGUE_ROOT_FOLLOW]
    faces, R = [], TONGUE_RING
    for i in range(n_st - 1):
        for k in range(R):
            a, b = i * R + k, i * R + (k + 1) % R
            c, d = (i + 1) * R + (k + 1) % R, (i + 1) * R + k
            faces += [(a, b, c), (a, c, d)]
    t0, t1 = n_st * R, n_st * R + 1
    for k in range(R):
        faces.append((t0, (k + 1) % R, k))
        faces.append((t1, (n_st - 1) * R + k, (n_st - 1) * R + (k + 1) % R))
    sites = {name: 2 * k * R for name, k in (("T1", 2), ("T2", 4), ("T3", 6), ("T4", 8))}
    fields = {"tongue_s": np.array(svals), "tongue_jaw": np.array(jaw),
              "tongue_follow": np.array(follow)}
    return np.array(verts), np.array(faces), fields, sites, s[2 * TONGUE_ANCHOR]


# Polar angles (degrees from the gaze axis) of the eyeball's rings: close rings at the
# pupil's and the iris's edges (radius 2.0 and 5.6 mm on a 12 mm ball) keep the colours
# that cassi_fit.render paints there (per vertex) crisp circles.
EYE_RINGS = (5.0, 8.5, 10.5, 18.0, 26.0, 29.0, 38.0, 55.0, 75.0, 100.0, 130.0, 160.0)


def build_eye(centre, radius=12.0, n_lon=20):
    """A sphere (the eyeball) whose poles lie on the gaze axis (+x), rings at EYE_RINGS."""
    verts = [centre + [radius, 0, 0]]
    for th in np.radians(EYE_RINGS):
        for j in range(n_lon):
            ph = 2 * np.pi * j / n_lon
            verts.append(centre + radius * np.array([np.cos(th), np.sin(th) * np.cos(ph),
                                                     np.sin(th) * np.sin(ph)]))
    verts.append(centre - [radius, 0, 0])
    n_lat = len(EYE_RINGS)
    faces, last = [], len(verts) - 1
    ring = lambda i, j: 1 + i * n_lon + j % n_lon
    for j in range(n_lon):
        faces.append((0, ring(0, j + 1), ring(0, j)))
        faces.append((last, ring(n_lat - 1, j), ring(n_lat - 1, j + 1)))
        for i in range(n_lat - 1):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)
            faces += [(a, b, c), (a, c, d)]
    return np.array(verts), np.array(faces)


# ---------------------------------------------------------------------------- hair
# The hairline: height (y mm) above which the scalp is hair, by azimuth about the head's
# vertical axis (x = HAIR_AXIS_X, z = 0; 0 degrees front, 90 at the side, 180 at the
# back): the forehead's hairline about 58 mm above the glabella (trichion-glabella,
# Farkas' adult norms 55-65 mm), the temples, a sideburn down to the ear's middle in
# front of it, the hair's edge over the ear, and down to the nape behind it.
HAIRLINE = ((0.0, 142.0), (35.0, 140.0), (55.0, 128.0), (70.0, 100.0), (80.0, 60.0),
            (90.0, 48.0), (96.0, 72.0), (104.0, 80.0), (114.0, 74.0), (125.0, 40.0),
            (145.0, 5.0), (180.0, -12.0))
HAIR_AXIS_X, HAIR_RADIUS = -90.0, 75.0  # mm; the radius turns azimuth into arc length
# The eyebrows: centre line (|z|, y) mm, about 21 mm above the eyes' centres from above
# the inner eye corner to beyond the outer one, and half height (mm) along it (thick at
# the head, thin at the tail). Near the glabella row (84 mm): the rows above and below
# are 8-10 mm away, and the drawn edge is the interpolated distance's zero.
BROW = ((14.0, 84.5, 4.5), (24.0, 85.5, 4.2), (36.0, 86.0, 3.5), (46.0, 85.5, 2.6),
        (52.0, 84.5, 1.6))
HAIR_EAR = -50.0  # mm: the ears' value (bare skin, far from any hair)


def _polyline_distance(points, line):
    """Distance (n,) from 2-D points (n,2) to a polyline (m,2)."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(((points[:, None] - a) * ab).sum(2) / (ab * ab).sum(1), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=2).min(axis=1)


def hair_distance(verts):
    """The ``hair`` field of the skin grid's vertices: signed distance (mm) to the edge of
    the hair, positive on it: the scalp above the ``HAIRLINE`` (distance in the plane of
    arc length round the head and height) and the eyebrows (``BROW``: half height minus
    the distance from the centre line). The renderer interpolates it across each triangle
    and colours where it is positive, so the edge follows these curves, not the grid."""
    az = np.arctan2(np.abs(verts[:, 2]), verts[:, 0] - HAIR_AXIS_X)
    a, h = np.array(HAIRLINE).T
    line = np.column_stack([np.radians(a) * HAIR_RADIUS, h])
    dist = _polyline_distance(np.column_stack([az * HAIR_RADIUS, verts[:, 1]]), line)
    scalp = np.where(verts[:, 1] > np.interp(np.degrees(az), a, h), dist, -dist)
    z, y = np.abs(verts[:, 2]), verts[:, 1]
    bz, by, half = np.array(BROW).T
    # distance from the centre line, plus the distance past its ends
    off = np.abs(y - np.interp(z, bz, by)) + np.maximum(bz[0] - z, 0) + np.maximum(z - bz[-1], 0)
    brow = np.where(verts[:, 0] > -60.0, np.interp(z, bz, half) - off, -off)
    return np.maximum(scalp, brow)


# ---------------------------------------------------------------------------- assembly
def nearest_skin_blend(skin, points, k=4):
    """A function taking a per-vertex field of ``skin`` (n,) to its values at ``points``
    (m,): the inverse-distance blend of the ``k`` nearest skin vertices (the ears' and the
    mouth curtains' weights and fields, so that they move with the skin beside them)."""
    from scipy.spatial import cKDTree

    dist, near = cKDTree(skin).query(points, k=k)
    inv = 1.0 / np.maximum(dist, 1e-6)
    return lambda f: (f[near] * inv).sum(axis=1) / inv.sum(axis=1)


def skin_fields(verts, ids, lower, corner_z, nose_tip):
    """Deformation fields of the skin vertices (see model/README.md)."""
    y, z = verts[:, 1], np.abs(verts[:, 2])
    names = [ROWS[i][0] for i in ids[:, 0]]
    lat = 1.0 - ramp(z, 6.0, corner_z + 8.0)
    up_v = {"philtrum": 0.55, "UL": 1, "ul_red": 1, "ul_low": 1, "A": 1, "A_in": 1}
    lo_v = {"B_in": 1, "B": 1, "ll_high": 1, "ll_red": 1, "LL": 1, "fold": 0.5}
    ured = {"philtrum": 0.3, "UL": 1, "ul_red": 1, "ul_low": 0.8, "A": 0.5}
    lred = {"B": 0.5, "ll_high": 0.8, "ll_red": 1, "LL": 1, "fold": 0.3}
    f = {}
    f["upper_lip"] = np.array([up_v.get(n, 0.0) for n in names]) * lat
    f["lower_lip"] = np.array([lo_v.get(n, 0.0) for n in names]) * lat
    red_lat = bell(z / (corner_z + 2.0))
    f["upper_vermilion"] = np.array([ured.get(n, 0.0) for n in names]) * red_lat
    f["lower_vermilion"] = np.array([lred.get(n, 0.0) for n in names]) * red_lat
    f["mouth"] = (1.0 - ramp(z, corner_z + 2.0, corner_z + 22.0)) * (
        1.0 - ramp(np.abs(y + 3.0), 26.0, 40.0))
    f["nose"] = bell(np.linalg.norm(verts - nose_tip, axis=1) / 24.0)
    rise_v = np.where(y >= ROWS[ROW_INDEX["subnasale"]][1] - 0.5, 1.0 - ramp(y, 45.0, 66.0), 0.0)
    rise_v = np.where([n == "philtrum" for n in names], 1.0 - 0.55, rise_v)
    f["nose_rise"] = rise_v * (1.0 - ramp(z, 20.0, 34.0))
    f["hair"] = hair_distance(verts)
    return f


def build():
    """All parts -> (vertices, faces, material, regions, landmarks, measures, fields)."""
    grid, corner = build_skin()
    sv, ids, index = mirror_grid(grid, corner)
    sf = skin_faces(grid.shape[0], grid.shape[1], index, corner)
    corner_z = grid[ROW_INDEX["A"], corner, 2]
    w_parke, lower = skin_weights(sv, ids, corner_z)
    nose_tip_i = index[(ROW_INDEX["nose_tip"], 0, 1)]
    fields = skin_fields(sv, ids, lower, corner_z, sv[nose_tip_i])
    names = [ROWS[i][0] for i in ids[:, 0]]
    # the red of the lips: from a little inside the pellet sites (UL, LL sit on the lips'
    # outer surface, just beyond the vermilion) to the mouth line
    lip_row = np.isin(names, ["ul_red", "ul_low", "A", "A_in", "B_in", "B", "ll_high",
                              "ll_red"])
    in_mouth = (np.abs(sv[:, 2]) < corner_z + 1e-9) & (sv[:, 0] > -30.0)
    mouth_core = (np.abs(sv[:, 2]) < 16.0 + 1e-6) & (sv[:, 0] > -30.0)  # the lips' middle
    lip_vertex = lip_row & in_mouth
    skin_mat = np.where(lip_vertex[np.array(sf)].all(axis=1), MAT["lips"], MAT["skin"])
    n_grid = len(sv)
    av, af = build_ears(sv)
    # the ears follow the skin they sit on: weights and fields of the nearest skin vertices
    blend = nearest_skin_blend(sv, av)
    w_parke = np.concatenate([w_parke, blend(w_parke)])
    fields = {k: np.concatenate([f, blend(f) if k != "hair" else np.full(len(av), HAIR_EAR)])
              for k, f in fields.items()}  # fmt: skip
    jaw_shape = jaw_shape_field(sv)
    jaw_shape = np.concatenate([jaw_shape, blend(jaw_shape)])
    sf = np.concatenate([np.array(sf), af + n_grid])
    skin_mat = np.concatenate([skin_mat, np.full(len(af), MAT["skin"])])
    sv = np.concatenate([sv, av])
    # the mouth's walls, after the ears: the back wall static (weights and fields 0), the
    # curtains with the cheek's weights and fields (like the ears); drawn as the lining of
    # the mouth (the mucosa colour of the pharyngeal wall), not as skin
    wv, wf, curtain = build_mouth_wall(sv[:n_grid])
    from_cheek = nearest_skin_blend(sv[:n_grid], wv)
    cheek = lambda f: np.where(curtain, from_cheek(f[:n_grid]), 0.0)
    w_parke = np.concatenate([w_parke, cheek(w_parke)])
    fields = {k: np.concatenate([f, cheek(f)]) for k, f in fields.items()}
    jaw_shape = np.concatenate([jaw_shape, cheek(jaw_shape)])
    sf = np.concatenate([sf, wf + len(sv)])
    skin_mat = np.concatenate([skin_mat, np.full(len(wf), MAT["pharynx"])])
    sv = np.concatenate([sv, wv])
    parts = [("skin", sv, sf, skin_mat)]
    ev, ef = [], []
    for side in (1, -1):
        v, f_ = build_eye(np.array([EYE_CENTRE[0], EYE_CENTRE[1], EYE_CENTRE[2] * side]), EYE_RADIUS)
        ef.append(f_ + sum(len(a) for a in ev))
        ev.append(v)
    parts.append(("eyes", np.concatenate(ev), np.concatenate(ef), MAT["eye"]))
    uv, uf = build_arch(ARCH, UPPER_TEETH, 0.0, True, snaps=[(0, 3, (0.0, 0.0))])
    lower_arch = ARCH * np.array([1.0, 0.93]) + np.array([-2.5, 0.0])
    lv, lf = build_arch(lower_arch, LOWER_TEETH, -0.5, False,
                        snaps=[(0, 8, SITES["MNI"]), (6, 1, SITES["MNM"])])
    parts.append(("upper_teeth", uv, uf, MAT["teeth"]))
    parts.append(("lower_teeth", lv, lf, MAT["teeth"]))
    tv, tf, tfields, tsites, anchor_s = build_tongue()
    parts.append(("tongue", tv, tf, MAT["tongue"]))
    from cassi_fit.palate import DEFAULT_OUTLINE, build_palate
    from cassi_fit.pharynx import DEFAULT_WALL, build_pharynx, midline
    # the palate's edges on the upper crowns' inner necks, its velum in front of the wall
    necks = uv[collision_chains({"upper_teeth": 0, "lower_teeth": 0},
                                len(UPPER_TEETH))["upper_lingual_cervical"]]
    pv, pf = build_palate(DEFAULT_OUTLINE, arch=necks, wall=midline(DEFAULT_WALL))
    parts.append(("palate", np.asarray(pv), np.asarray(pf), MAT["palate"]))
    hv, hf = build_pharynx(DEFAULT_WALL)
    parts.append(("pharynx", np.asarray(hv), np.asarray(hf), MAT["pharynx"]))

    verts, faces, mats, regions, offsets = [], [], [], {}, {}
    for name, v, f_, m in parts:
        base = sum(len(a) for a in verts)
        offsets[name] = base
        regions[name] = np.arange(base, base + len(v))
        verts.append(v)
        if name in ("skin", "upper_teeth", "lower_teeth", "tongue"):
            f_ = f_[:, ::-1]  # these parts are built clockwise: make every part face outward
        faces.append(f_ + base)
        mats.append(np.broadcast_to(m, (len(f_),)))
    V = np.concatenate(verts)
    n = len(V)
    wp = np.zeros(n)
    wp[: len(sv)] = w_parke
    wp[regions["lower_teeth"]] = PARKE["lower_teeth"]
    full = {k: np.zeros(n) for k in ("upper_lip", "lower_lip", "upper_vermilion",
                                     "lower_vermilion", "mouth", "nose", "nose_rise",
                                     "jaw_shape", "tongue_s", "tongue_jaw", "tongue_follow",
                                     "hair")}
    for k, v in fields.items():
        full[k][: len(sv)] = v
    full["jaw_shape"][: len(sv)] = jaw_shape
    for k, v in tfields.items():
        full[k][regions["tongue"]] = v
    skin = regions["skin"][:n_grid]  # the grid's vertices (the masks below), then the ears
    w_parke = w_parke[:n_grid]
    row_of = {k: ids[:, 0] == ROW_INDEX[k] for k in ROW_INDEX}
    up_rows = np.isin(names, ["UL", "ul_red", "ul_low", "A", "A_in"])
    lo_rows = np.isin(names, ["B_in", "B", "ll_high", "ll_red", "LL"])
    close = lambda value: np.isclose(w_parke, value, rtol=0.0, atol=1e-12)
    regions.update({
        "upper_lip": skin[up_rows & mouth_core],
        "lower_lip": skin[lo_rows & mouth_core],
        "jaw": skin[close(PARKE["jaw"])],
        "under_chin": skin[close(PARKE["under_chin"])],
        "neck": skin[close(PARKE["neck"])],
        "cheek": skin[close(PARKE["cheek"]) & ~lower],
        "nose": skin[fields["nose"][:n_grid] > 0.3],
    })
    # the mouth's walls (the last skin vertices): no anatomy, so the midsagittal section
    # (cassi_fit.render) leaves them out
    regions["mouth_wall"] = regions["skin"][len(regions["skin"]) - len(wv):]
    T = lambda k: offsets["tongue"] + tsites[k]
    ui = offsets["upper_teeth"] + 3
    li = offsets["lower_teeth"] + 3
    gonion = int(np.argmin(np.linalg.norm(sv - [-86.0, -34.0, 52.0], axis=1)))
    landmarks = {
        "upper_incisor_tip": ui, "lower_incisor_tip": li,
        "MNI": offsets["lower_teeth"] + 8, "MNM": offsets["lower_teeth"] + 6 * 14 + 1,
        "UL": index[(ROW_INDEX["UL"], 0, 1)], "LL": index[(ROW_INDEX["LL"], 0, 1)],
        "T1": T("T1"), "T2": T("T2"), "T3": T("T3"), "T4": T("T4"),
        "gonion": gonion, "gnathion": index[(ROW_INDEX["menton"], 0, 1)],
        "nose_tip": nose_tip_i, "subnasale": index[(ROW_INDEX["subnasale"], 0, 1)],
        "mouth_corner_left": index[(ROW_INDEX["A"], corner, 1)],
        "mouth_corner_right": index[(ROW_INDEX["A"], corner, -1)],
    }
    cheek = np.flatnonzero(row_of["cheekbone"] & (sv[:n_grid, 0] > -75.0))  # skin comes first
    landmarks["zygion_left"] = cheek[np.argmax(sv[cheek, 2])]
    landmarks["zygion_right"] = cheek[np.argmin(sv[cheek, 2])]
    landmarks = {k: int(v) for k, v in landmarks.items()}
    P = lambda k: V[landmarks[k]]
    forward = (P("MNI") - P("MNM"))[:2] / np.linalg.norm((P("MNI") - P("MNM"))[:2])
    measures = {
        "face_width": float(P("zygion_left")[2] - P("zygion_right")[2]),
        "jaw_width": float(2 * abs(P("gonion")[2])),
        "mouth_width": float(P("mouth_corner_left")[2] - P("mouth_corner_right")[2]),
        "upper_lip_thickness": float(P("UL")[0] - P("upper_incisor_tip")[0]),
        # along the mandible's forward direction (MNM -> MNI), as Headmeasures defines it
        "lower_lip_thickness": float((P("LL") - P("lower_incisor_tip"))[:2] @ forward),
        "nose_protrusion": float(P("nose_tip")[0] - P("subnasale")[0]),
        "jaw_pivot_x": JAW_PIVOT[0], "jaw_pivot_y": JAW_PIVOT[1],
        "tongue_anchor_s": float(anchor_s),
    }
    w_cassi = wp * CASSI_FACTOR
    measures["collision"] = collision_chains(offsets, len(UPPER_TEETH))
    measures["collision"].update(lip_columns(index, corner))
    V = tongue_at_rest(V, regions, measures["collision"])
    return (V, np.concatenate(faces), np.concatenate(mats), regions, landmarks, measures,
            w_cassi, wp, full)


def lip_columns(index, corner):
    """Per skin column between the mouth corners, the upper lip's vertices from its edge
    up (rows A_in, A, ul_low, ul_red, UL) and the lower lip's from its edge down (B_in,
    B, ll_high, ll_red, LL): ``cassi_fit.collide`` keeps the two lips from crossing."""
    upper, lower = ("A_in", "A", "ul_low", "ul_red", "UL"), ("B_in", "B", "ll_high", "ll_red",
                                                            "LL")
    cols = [(j, side) for j in range(corner) for side in ((1,) if j == 0 else (1, -1))]
    pick = lambda rows: [[int(index[(ROW_INDEX[r], j, side)]) for r in rows] for j, side in cols]
    return {"upper_lip_columns": pick(upper), "lower_lip_columns": pick(lower)}


def tongue_at_rest(V, regions, chains):
    """The rest tongue touching, never crossing, the teeth and the palate: its vertices
    inside them are pushed out by ``cassi_fit.collide.project`` (where the round tube meets
    the lingual faces of the crowns, it flattens against them as a real tongue does)."""
    from types import SimpleNamespace

    import jax
    import jax.numpy as jnp

    from cassi_fit.collide import project

    jax.config.update("jax_enable_x64", True)

    rest = SimpleNamespace(regions={**regions, "upper_lip": [], "lower_lip": []},
                           collision={k: np.asarray(v) for k, v in chains.items()})
    out = np.array(project(rest, jnp.asarray(V, jnp.float64)))
    # the projection is not exactly mirror-symmetric where the two halves of an arch meet:
    # of each mirror pair of ring vertices keep the one pushed farther, mirrored
    idx = np.asarray(regions["tongue"])
    R = TONGUE_RING
    ring = idx[:-2].reshape(-1, R)
    mirror = ring[:, (-np.arange(R)) % R]
    moved = np.linalg.norm(out[ring] - V[ring], axis=-1)
    pick = np.where(moved >= np.linalg.norm(out[mirror] - V[mirror], axis=-1), ring, mirror)
    out[ring] = out[pick] * np.where((pick == ring)[..., None], 1.0, [1.0, 1.0, -1.0])
    out[ring[:, [0, R // 2]], 2] = 0.0
    return out


# Ring vertices of a crown (see ``tooth``): 0-5 occlusal ring, 6-11 cervical ring, at
# angles 0, 60, ..., 300 degrees; 1, 2 labial (distal, mesial), 4, 5 lingual (mesial,
# distal). 14 vertices per crown, left arch first, then the mirrored right arch.
CHAIN_RING = {"lingual_occlusal": (4, 5), "lingual_cervical": (10, 11),
              "labial_occlusal": (2, 1), "labial_cervical": (8, 7)}


def collision_chains(offsets, n_teeth):
    """Vertex chains along each dental arch for ``cassi_fit.collide``.

    Each chain runs from the right back molar round the front to the left back molar,
    two stations per crown (mesial, distal); ``*_tooth`` numbers each station's tooth
    (0 = central incisor). Indices refer to vertices, so the chains move with the teeth.
    """
    chains = {}
    for arch in ("upper", "lower"):
        base = offsets[f"{arch}_teeth"]
        half = 14 * n_teeth
        for name, ring in CHAIN_RING.items():
            left = [base + 14 * k + r for k in range(n_teeth) for r in ring]
            right = [i + half for i in left][::-1]
            chains[f"{arch}_{name}"] = right + left
        teeth = [k for k in range(n_teeth) for _ in range(2)]
        chains[f"{arch}_tooth"] = teeth[::-1] + teeth
    return chains


PARAMETERS = [  # number, name, unit, min, max, default, kind, stored positions / rule, description
    # kind follows Parke: interpolation between two stored positions per vertex (the
    # second stored position is the rest position plus the named vertices.csv field
    # times a unit step), rotation about a pivot, scaling, translation.
    ('J1', 'jaw_theta', 'rad', -0.1, 0.5, 0.0, 'rotation', "about the jaw motion's pivot; vertex i turns by w_cassi (or w_parke) x theta", "jaw rotation (Parke's jaw rotation; + opens)"),
    ('J2', 'jaw_translation_x', 'mm', -15, 15, 0.0, 'rotation', "with J1 one rigid motion p' = R p + t; the pivot follows from it", 'jaw translation x'),
    ('J3', 'jaw_translation_y', 'mm', -15, 15, 0.0, 'rotation', 'as J2', 'jaw translation y'),
    ('C1', 'mouth_width', 'scale', 0.7, 1.3, 1.0, 'scale', 'z scaled by 1 + (value - 1) x mouth', 'mouth width scale (z of lips and corners)'),
    ('C2', 'upper_lip_thickness', 'mm', -5, 10, 0.0, 'interpolation', 'rest (x y z) and rest + (upper_vermilion 0 0) at 1 mm', 'added to the upper vermilion; outward'),
    ('C3', 'lower_lip_thickness', 'mm', -5, 10, 0.0, 'interpolation', 'rest (x y z) and rest + (lower_vermilion 0 0) at 1 mm', 'added to the lower vermilion; outward'),
    ('C4', 'face_width', 'scale', 0.8, 1.2, 1.0, 'scale', 'z of skin and eyes scaled by value', 'face width scale'),
    ('C5', 'nose_tip_x', 'mm', -10, 10, 0.0, 'translation', 'x moved by value x nose', 'nose tip offset x (falloff 24 mm)'),
    ('C6', 'nose_tip_y', 'mm', -10, 10, 0.0, 'translation', 'y moved by value x nose', 'nose tip offset y'),
    ('C7', 'jaw_shape_theta', 'rad', -0.3, 0.3, 0.0, 'rotation', "vertex i turns by jaw_shape x theta about the motion's pivot", 'jaw/chin conformation rotation'),
    ('C8', 'jaw_shape_translation_x', 'mm', -15, 15, 0.0, 'rotation', 'with C7 one rigid motion', 'jaw/chin conformation translation x'),
    ('C9', 'jaw_shape_translation_y', 'mm', -15, 15, 0.0, 'rotation', 'as C8', 'jaw/chin conformation translation y'),
    ('C10', 'jaw_shape_scale_x', 'scale', 0.7, 1.4, 1.0, 'scale', 'x moved by (value - 1) x jaw_shape x (x - lower incisor tip x), before C7-C9', 'jaw/chin conformation: scale along x about the lower incisor tip'),
    ('C11', 'jaw_shape_scale_y', 'scale', 0.7, 1.4, 1.0, 'scale', 'y moved by (value - 1) x jaw_shape x (y - lower incisor tip y), before C7-C9', 'jaw/chin conformation: scale along y about the lower incisor tip'),
    ('55', 'T1_X', 'mm', -30, 30, 0.0, 'interpolation', 'along the tongue between the T1-T4 sites and the back anchors (cassi_fit.tongue)', 'tongue T1 site; x displacement'),
    ('56', 'T1_Z', 'mm', -30, 30, 0.0, 'interpolation', 'as the X parameter', 'tongue T1 site; vertical (y) displacement'),
    ('57', 'T2_X', 'mm', -30, 30, 0.0, 'interpolation', 'along the tongue between the T1-T4 sites and the back anchors (cassi_fit.tongue)', 'tongue T2 site; x displacement'),
    ('58', 'T2_Z', 'mm', -30, 30, 0.0, 'interpolation', 'as the X parameter', 'tongue T2 site; vertical (y) displacement'),
    ('59', 'T3_X', 'mm', -30, 30, 0.0, 'interpolation', 'along the tongue between the T1-T4 sites and the back anchors (cassi_fit.tongue)', 'tongue T3 site; x displacement'),
    ('60', 'T3_Z', 'mm', -30, 30, 0.0, 'interpolation', 'as the X parameter', 'tongue T3 site; vertical (y) displacement'),
    ('61', 'T4_X', 'mm', -30, 30, 0.0, 'interpolation', 'along the tongue between the T1-T4 sites and the back anchors (cassi_fit.tongue)', 'tongue T4 site; x displacement'),
    ('62', 'T4_Z', 'mm', -30, 30, 0.0, 'interpolation', 'as the X parameter', 'tongue T4 site; vertical (y) displacement'),
    ('63', 'upper_lip_X', 'mm', -20, 20, 0.0, 'interpolation', 'rest (x y z) and rest + (upper_lip 0 0) at 1 mm', 'upper lip (UL site) x displacement'),
    ('64', 'upper_lip_Z', 'mm', -20, 20, 0.0, 'interpolation', 'rest (x y z) and rest + (0 upper_lip 0) at 1 mm; nose rises by nose_rise', 'upper lip vertical displacement'),
    ('65', 'lower_lip_X', 'mm', -20, 20, 0.0, 'interpolation', 'jaw-moved position and that + (lower_lip 0 0) at 1 mm', 'lower lip x displacement; after the jaw'),
    ('66', 'lower_lip_Z', 'mm', -20, 20, 0.0, 'interpolation', 'jaw-moved position and that + (0 lower_lip 0) at 1 mm', 'lower lip vertical displacement; after the jaw'),
]


def lip_measures(V, landmarks, collision):
    """The rest face's lip measures (mm, on the midline; model/README.md, "The face"):
    subnasale to the upper lip's stomion (sn-sto), the vermilion heights (labrale superius
    to stomion, stomion to labrale inferius), the upper incisor shown below the upper lip
    and the gap between the lips."""
    up, lo = collision["upper_lip_columns"][0], collision["lower_lip_columns"][0]
    y = lambda i: float(V[i][1])
    sto_u, ls, sto_l, li = y(up[1]), y(up[3]), y(lo[1]), y(lo[3])  # rows A, ul_red, B, ll_red
    return {"sn-sto": y(landmarks["subnasale"]) - sto_u, "ls-sto": ls - sto_u,
            "sto-li": sto_l - li, "incisor show": sto_u - y(landmarks["upper_incisor_tip"]),
            "lip gap": sto_u - sto_l}


def _csv(rows, header):
    return ",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent))
    args = ap.parse_args(argv)
    out = Path(args.out)
    V, F, M, regions, landmarks, measures, wc, wp, fields = build()
    names = ["x", "y", "z", "w_cassi", "w_parke"] + list(fields)
    cols = np.column_stack([V, wc, wp] + [fields[k] for k in fields])
    fmt = lambda r: [f"{v:.4f}" for v in r[:3]] + [repr(float(v)) for v in r[3:5]] + [
        f"{v:.6f}" for v in r[5:]]
    atomic_write(out / "vertices.csv", _csv([fmt(r) for r in cols], names), overwrite=True)
    atomic_write(out / "faces.csv", _csv([(*f, m) for f, m in zip(F, M, strict=True)],
                                         ["a", "b", "c", "material"]), overwrite=True)
    collision = measures.pop("collision")
    meta = {"format": "cassi_fit face model 1",
            "frame": "mm; origin upper incisor tip; +x front, +y up, +z subject's left",
            "materials": list(MATERIALS),
            "measures": measures, "landmarks": landmarks, "collision": collision,
            "regions": {k: [int(i) for i in v] for k, v in regions.items()}}
    atomic_write(out / "model.json", json.dumps(meta, indent=1) + "\n", overwrite=True)
    atomic_write(out / "parameters.csv",
                 _csv(PARAMETERS, ["number", "name", "unit", "min", "max", "default",
                                   "kind", "stored_positions", "description"]), overwrite=True)
    print(f"{len(V)} vertices, {len(F)} triangles -> {out}")
    lips = lip_measures(V, landmarks, collision)
    print("lips at rest (mm): " + ", ".join(f"{k} {v:.1f}" for k, v in lips.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
