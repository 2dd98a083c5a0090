"""The half head's grid: the loft through the rows (``skin_rows``), the nose, lips, lids
and cheekbones as bumps on it, and the smoothing of the glabella, the inner eye corners
and the cheeks.

Part of ``build_model.py`` (run that to rebuild the model).
"""

from __future__ import annotations

import numpy as np
from skin_rows import (
    EYE_CENTRE,
    EYE_RADIUS,
    EYE_ROWS,
    FRONT_Z,
    LIP_BUMP,
    MOUTH_HALF_WIDTH,
    NECK_HALF_WIDTH,
    NOSE,
    ROW_INDEX,
    ROWS,
    STO_LOWER,
    STO_UPPER,
    bell,
    column_angles,
    ramp,
)


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
