"""The skin's per-vertex fields: Parke's jaw-rotation weights, the jaw conformation's
field, the lips', nose's and mouth's deformation fields and the hair distance.

Part of ``build_model.py`` (run that to rebuild the model).
"""

from __future__ import annotations

import numpy as np
from skin_rows import (
    FRONT_Z,
    MOUTH_HALF_WIDTH,
    PARKE,
    ROW_INDEX,
    ROWS,
    bell,
    column_angles,
    ramp,
)

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
