"""What is attached to the skin: the ears, the mouth's walls (a static back wall and the
cheek curtains), and the blend that carries the skin's weights and fields to them.

Part of ``build_model.py`` (run that to rebuild the model).
"""

from __future__ import annotations

import numpy as np
from skin_rows import ramp

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


# ---------------------------------------------------------------------------- assembly
def nearest_skin_blend(skin, points, k=4):
    """A function taking a per-vertex field of ``skin`` (n,) to its values at ``points``
    (m,): the inverse-distance blend of the ``k`` nearest skin vertices (the ears' and the
    mouth curtains' weights and fields, so that they move with the skin beside them)."""
    from scipy.spatial import cKDTree

    dist, near = cKDTree(skin).query(points, k=k)
    inv = 1.0 / np.maximum(dist, 1e-6)
    return lambda f: (f[near] * inv).sum(axis=1) / inv.sum(axis=1)
