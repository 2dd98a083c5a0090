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

import argparse
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from inner_parts import (  # noqa: E402
    ARCH,
    LOWER_TEETH,
    UPPER_TEETH,
    build_arch,
    build_eye,
    build_tongue,
    collision_chains,
    tongue_at_rest,
)
from skin_attachments import build_ears, build_mouth_wall, nearest_skin_blend  # noqa: E402
from skin_fields import HAIR_EAR, jaw_shape_field, skin_fields, skin_weights  # noqa: E402
from skin_mesh import lip_columns, mirror_grid, skin_faces  # noqa: E402
from skin_rows import (  # noqa: E402
    CASSI_FACTOR,
    EYE_CENTRE,
    EYE_RADIUS,
    JAW_PIVOT,
    MAT,
    PARKE,
    ROW_INDEX,
    ROWS,
    SITES,
)
from skin_shape import build_skin  # noqa: E402

from cassi_fit._io import atomic_write  # noqa: E402
from cassi_fit.face_model import MATERIALS  # noqa: E402

# the parts built clockwise: turned so that every part faces outward
CLOCKWISE = ("skin", "upper_teeth", "lower_teeth", "tongue")
FIELDS = ("upper_lip", "lower_lip", "upper_vermilion", "lower_vermilion", "mouth", "nose",
          "nose_rise", "jaw_shape", "tongue_s", "tongue_jaw", "tongue_follow", "hair")


def skin_grid():
    """The mirrored skin grid with its weights, fields and lip material."""
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
    return SimpleNamespace(
        verts=sv, faces=np.array(sf), mat=skin_mat, w_parke=w_parke, fields=fields,
        jaw_shape=jaw_shape_field(sv), ids=ids, index=index, corner=corner, lower=lower,
        names=names, mouth_core=mouth_core, nose_tip=nose_tip_i, n_grid=len(sv), n_wall=0)


def _append(skin, verts, faces, material, carry, hair):
    """Add vertices and faces to the skin; ``carry`` takes each per-vertex field of the
    skin so far to the new vertices, ``hair`` their hair distance."""
    skin.w_parke = np.concatenate([skin.w_parke, carry(skin.w_parke)])
    skin.fields = {k: np.concatenate([f, carry(f) if k != "hair" else hair(f)])
                   for k, f in skin.fields.items()}  # fmt: skip
    skin.jaw_shape = np.concatenate([skin.jaw_shape, carry(skin.jaw_shape)])
    skin.faces = np.concatenate([skin.faces, faces + len(skin.verts)])
    skin.mat = np.concatenate([skin.mat, np.full(len(faces), material)])
    skin.verts = np.concatenate([skin.verts, verts])


def attach(skin):
    """The ears and the mouth's walls added to the skin grid."""
    grid = skin.verts[:skin.n_grid]
    av, af = build_ears(grid)
    # the ears follow the skin they sit on: weights and fields of the nearest skin vertices
    blend = nearest_skin_blend(grid, av)
    _append(skin, av, af, MAT["skin"], blend, lambda f: np.full(len(av), HAIR_EAR))
    # the mouth's walls, after the ears: the back wall static (weights and fields 0), the
    # curtains with the cheek's weights and fields (like the ears); drawn as the lining of
    # the mouth (the mucosa colour of the pharyngeal wall), not as skin
    wv, wf, curtain = build_mouth_wall(grid)
    from_cheek = nearest_skin_blend(grid, wv)
    cheek = lambda f: np.where(curtain, from_cheek(f[:skin.n_grid]), 0.0)
    _append(skin, wv, wf, MAT["pharynx"], cheek, cheek)
    skin.n_wall = len(wv)
    return skin


def inner_parts():
    """Eyes, teeth, tongue, palate and pharyngeal wall: the parts after the skin, and the
    tongue's fields, pellet sites and anchor arc length."""
    from cassi_fit.palate import DEFAULT_OUTLINE, build_palate
    from cassi_fit.pharynx import DEFAULT_WALL, build_pharynx, midline

    ev, ef = [], []
    for side in (1, -1):
        v, f_ = build_eye(np.array([EYE_CENTRE[0], EYE_CENTRE[1], EYE_CENTRE[2] * side]), EYE_RADIUS)
        ef.append(f_ + sum(len(a) for a in ev))
        ev.append(v)
    parts = [("eyes", np.concatenate(ev), np.concatenate(ef), MAT["eye"])]
    uv, uf = build_arch(ARCH, UPPER_TEETH, 0.0, True, snaps=[(0, 3, (0.0, 0.0))])
    lower_arch = ARCH * np.array([1.0, 0.93]) + np.array([-2.5, 0.0])
    lv, lf = build_arch(lower_arch, LOWER_TEETH, -0.5, False,
                        snaps=[(0, 8, SITES["MNI"]), (6, 1, SITES["MNM"])])
    parts.append(("upper_teeth", uv, uf, MAT["teeth"]))
    parts.append(("lower_teeth", lv, lf, MAT["teeth"]))
    tv, tf, tfields, tsites, anchor_s = build_tongue()
    parts.append(("tongue", tv, tf, MAT["tongue"]))
    # the palate's edges on the upper crowns' inner necks, its velum in front of the wall
    necks = uv[collision_chains({"upper_teeth": 0, "lower_teeth": 0},
                                len(UPPER_TEETH))["upper_lingual_cervical"]]
    pv, pf = build_palate(DEFAULT_OUTLINE, arch=necks, wall=midline(DEFAULT_WALL))
    parts.append(("palate", np.asarray(pv), np.asarray(pf), MAT["palate"]))
    hv, hf = build_pharynx(DEFAULT_WALL)
    parts.append(("pharynx", np.asarray(hv), np.asarray(hf), MAT["pharynx"]))
    return parts, tfields, tsites, anchor_s


def assemble(parts):
    """One vertex array, face array and material per face; each part's vertex range."""
    verts, faces, mats, regions, offsets = [], [], [], {}, {}
    for name, v, f_, m in parts:
        base = sum(len(a) for a in verts)
        offsets[name] = base
        regions[name] = np.arange(base, base + len(v))
        verts.append(v)
        if name in CLOCKWISE:
            f_ = f_[:, ::-1]
        faces.append(f_ + base)
        mats.append(np.broadcast_to(m, (len(f_),)))
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(mats), regions, offsets


def vertex_fields(n, skin, regions, tfields):
    """Parke's weights and every deformation field over all ``n`` vertices (0 elsewhere)."""
    wp = np.zeros(n)
    wp[: len(skin.verts)] = skin.w_parke
    wp[regions["lower_teeth"]] = PARKE["lower_teeth"]
    full = {k: np.zeros(n) for k in FIELDS}
    for k, v in skin.fields.items():
        full[k][: len(skin.verts)] = v
    full["jaw_shape"][: len(skin.verts)] = skin.jaw_shape
    for k, v in tfields.items():
        full[k][regions["tongue"]] = v
    return wp, full


def skin_regions(skin, regions):
    """The skin's regions (the lips' middles, Parke's plateaus, the nose, the mouth's walls)."""
    n_grid = skin.n_grid
    grid = regions["skin"][:n_grid]  # the grid's vertices (the masks below), then the ears
    w_parke = skin.w_parke[:n_grid]
    up_rows = np.isin(skin.names, ["UL", "ul_red", "ul_low", "A", "A_in"])
    lo_rows = np.isin(skin.names, ["B_in", "B", "ll_high", "ll_red", "LL"])
    close = lambda value: np.isclose(w_parke, value, rtol=0.0, atol=1e-12)
    regions.update({
        "upper_lip": grid[up_rows & skin.mouth_core],
        "lower_lip": grid[lo_rows & skin.mouth_core],
        "jaw": grid[close(PARKE["jaw"])],
        "under_chin": grid[close(PARKE["under_chin"])],
        "neck": grid[close(PARKE["neck"])],
        "cheek": grid[close(PARKE["cheek"]) & ~skin.lower],
        "nose": grid[skin.fields["nose"][:n_grid] > 0.3],
    })
    # the mouth's walls (the last skin vertices): no anatomy, so the midsagittal section
    # (cassi_fit.render) leaves them out
    regions["mouth_wall"] = regions["skin"][len(regions["skin"]) - skin.n_wall:]


def landmarks_of(skin, offsets, tsites):
    """Named vertices: incisor tips, pellet sites, gonion, gnathion, nose, mouth corners,
    zygions."""
    index, corner, sv = skin.index, skin.corner, skin.verts
    T = lambda k: offsets["tongue"] + tsites[k]
    gonion = int(np.argmin(np.linalg.norm(sv - [-86.0, -34.0, 52.0], axis=1)))
    landmarks = {
        "upper_incisor_tip": offsets["upper_teeth"] + 3,
        "lower_incisor_tip": offsets["lower_teeth"] + 3,
        "MNI": offsets["lower_teeth"] + 8, "MNM": offsets["lower_teeth"] + 6 * 14 + 1,
        "UL": index[(ROW_INDEX["UL"], 0, 1)], "LL": index[(ROW_INDEX["LL"], 0, 1)],
        "T1": T("T1"), "T2": T("T2"), "T3": T("T3"), "T4": T("T4"),
        "gonion": gonion, "gnathion": index[(ROW_INDEX["menton"], 0, 1)],
        "nose_tip": skin.nose_tip, "subnasale": index[(ROW_INDEX["subnasale"], 0, 1)],
        "mouth_corner_left": index[(ROW_INDEX["A"], corner, 1)],
        "mouth_corner_right": index[(ROW_INDEX["A"], corner, -1)],
    }
    cheekbone = skin.ids[:, 0] == ROW_INDEX["cheekbone"]
    cheek = np.flatnonzero(cheekbone & (sv[:skin.n_grid, 0] > -75.0))  # skin comes first
    landmarks["zygion_left"] = cheek[np.argmax(sv[cheek, 2])]
    landmarks["zygion_right"] = cheek[np.argmin(sv[cheek, 2])]
    return {k: int(v) for k, v in landmarks.items()}


def face_measures(V, landmarks, anchor_s):
    """The rest face's measures (mm) as Headmeasures defines them, and the jaw pivot."""
    P = lambda k: V[landmarks[k]]
    forward = (P("MNI") - P("MNM"))[:2] / np.linalg.norm((P("MNI") - P("MNM"))[:2])
    return {
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


def build():
    """All parts -> (vertices, faces, material, regions, landmarks, measures, fields)."""
    skin = attach(skin_grid())
    inner, tfields, tsites, anchor_s = inner_parts()
    V, faces, mats, regions, offsets = assemble(
        [("skin", skin.verts, skin.faces, skin.mat), *inner])
    wp, full = vertex_fields(len(V), skin, regions, tfields)
    skin_regions(skin, regions)
    landmarks = landmarks_of(skin, offsets, tsites)
    measures = face_measures(V, landmarks, anchor_s)
    measures["collision"] = collision_chains(offsets, len(UPPER_TEETH))
    measures["collision"].update(lip_columns(skin.index, skin.corner))
    V = tongue_at_rest(V, regions, measures["collision"])
    return V, faces, mats, regions, landmarks, measures, wp * CASSI_FACTOR, wp, full


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
