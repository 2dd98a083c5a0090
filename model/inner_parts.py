"""The inside of the mouth and the eyes: crowns and dental arches, the tongue tube (its
rest pose pushed out of the teeth), the eyeballs, and the arches' collision chains.

Part of ``build_model.py`` (run that to rebuild the model).
"""

from __future__ import annotations

import numpy as np
from skin_rows import SITES


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
