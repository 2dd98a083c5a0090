"""The mirrored skin mesh: vertices and triangles from the half grid, and the lips'
vertex columns for ``cassi_fit.collide``.

Part of ``build_model.py`` (run that to rebuild the model).
"""

from __future__ import annotations

import numpy as np
from skin_rows import ROW_INDEX


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


def lip_columns(index, corner):
    """Per skin column between the mouth corners, the upper lip's vertices from its edge
    up (rows A_in, A, ul_low, ul_red, UL) and the lower lip's from its edge down (B_in,
    B, ll_high, ll_red, LL): ``cassi_fit.collide`` keeps the two lips from crossing."""
    upper, lower = ("A_in", "A", "ul_low", "ul_red", "UL"), ("B_in", "B", "ll_high", "ll_red",
                                                            "LL")
    cols = [(j, side) for j in range(corner) for side in ((1,) if j == 0 else (1, -1))]
    pick = lambda rows: [[int(index[(ROW_INDEX[r], j, side)]) for r in rows] for j, side in cols]
    return {"upper_lip_columns": pick(upper), "lower_lip_columns": pick(lower)}
