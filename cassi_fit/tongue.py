"""The tongue's deformation: four pellet displacements spread smoothly along its length.

CASSI (Table 1, parameters #55-#62) moves the tongue by the X and Z displacements of the
four tongue pellet sites T1..T4 from rest. Here every tongue vertex carries its arc length
``s`` (mm from the tip along the upper midline, ``FaceModel.fields["tongue_s"]``); the
whole cross-section at ``s`` moves by one displacement ``d(s)``, so the tongue keeps its
thickness. Between sites, ``d`` is a raised-cosine blend (C1, no overshoot, exact at the
sites); in front of T1 it equals T1's. Behind T4 the back anchor option decides:

* ``"fixed"`` (CASSI): anchor points far back and down never move; ``d`` falls linearly
  from T4's to zero at the anchor arc length (this gave CASSI's tongue its V shape).
* ``"follow"``: the anchors move with T4 (the back translates with T4).
* ``"none"``: no anchors; the back continues T3->T4's trend for half the T3-T4 spacing.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from .face_model import MATERIALS, FaceModel
from .options import TONGUE_ANCHORS, check_choice


def _blend(u):
    """Raised cosine 0 -> 1 on u in [0, 1] (exactly 0 and 1 at the ends), clipped outside."""
    return 0.5 - 0.5 * jnp.cos(jnp.pi * jnp.clip(u, 0.0, 1.0))


def tongue_displacement(
    s: Float[Array, " n"], site_s: Float[Array, " 4"], displacement: Float[Array, "4 2"],
    anchor_s: float | Float[Array, ""], anchor: str = "follow",
) -> Float[Array, "n 2"]:
    """Displacement (n, 2) mm of tongue points at arc lengths ``s`` (n,) mm.

    ``site_s`` (4,): arc lengths of T1..T4 (increasing); ``displacement`` (4, 2): params
    #55-#62 as rows (X, Z) of T1..T4; ``anchor_s``: arc length of the fixed anchors
    (> site_s[3]); ``anchor``: one of ``options.TONGUE_ANCHORS`` (static;
    ``InvalidChoiceError`` otherwise).
    """
    check_choice("tongue anchor", anchor, TONGUE_ANCHORS)
    s = s[:, None]
    d = jnp.broadcast_to(displacement[0], (s.shape[0], 2))
    for k in range(3):  # telescoping sum: segment k contributes fully once passed
        u = (s - site_s[k]) / (site_s[k + 1] - site_s[k])
        d = d + (displacement[k + 1] - displacement[k])[None] * _blend(u)
    behind = (s - site_s[3])
    if anchor == "fixed":
        d = d - displacement[3][None] * jnp.clip(behind / (anchor_s - site_s[3]), 0.0, 1.0)
    elif anchor == "none":
        trend = jnp.clip(behind / (site_s[3] - site_s[2]), 0.0, 0.5)
        d = d + (displacement[3] - displacement[2])[None] * trend
    return d


#: Cubic millimetres per millilitre (volumes are reported in mL).
MM3_PER_ML = 1000.0


def closed_mesh_volume(vertices: Float[Array, "V 3"], faces: Int[np.ndarray, "F 3"]) -> Float[Array, ""]:
    """Signed volume (mm^3) enclosed by the triangles ``faces (F, 3)`` (indices into
    ``vertices (V, 3)`` mm), by the divergence theorem: the sum over the triangles of
    ``a . (b x c) / 6``. Exact for a closed, consistently oriented mesh (positive when
    the triangles face outward), independent of the origin, smooth in the vertices."""
    faces = np.asarray(faces)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return jnp.sum(a * jnp.cross(b, c)) / 6.0


def tongue_faces(model: FaceModel) -> Int[np.ndarray, "F 3"]:
    """The triangles ``(F, 3)`` of the tongue (material ``"tongue"``), as static numpy:
    a closed tube (model/build_model.py), so :func:`closed_mesh_volume` is its volume."""
    mat = list(MATERIALS).index("tongue")
    return np.asarray(model.faces)[np.asarray(model.face_material) == mat]


def tongue_volume(model: FaceModel, vertices: Float[Array, "V 3"]) -> Float[Array, ""]:
    """Volume (mL) of the tongue of ``model`` posed at ``vertices (V, 3)`` mm."""
    return closed_mesh_volume(vertices, tongue_faces(model)) / MM3_PER_ML


def tongue_volumes(model: FaceModel, vertices: Float[ArrayLike, "m V 3"]) -> Float[np.ndarray, " m"]:
    """Per-frame tongue volumes ``(m,)`` mL of ``vertices (m, V, 3)`` mm, in numpy float64
    (no compilation, so reporting adds none per recording length)."""
    faces = tongue_faces(model)
    used = np.unique(faces)
    v = np.asarray(np.asarray(vertices)[:, used], np.float64)
    local = np.searchsorted(used, faces)
    a, b, c = (v[:, local[:, k]] for k in range(3))
    return np.einsum("mfi,mfi->m", a, np.cross(b, c)) / 6.0 / MM3_PER_ML


def keep_volume(model: FaceModel, vertices: Float[Array, "V 3"], volume: Float[ArrayLike, ""]) -> Float[Array, "V 3"]:
    """``vertices (V, 3)`` with the tongue's width scaled about the midsagittal plane
    (``z -> k z``, tongue vertices only) so that its volume is ``volume`` mm^3.

    A linear map in ``z`` scales a closed mesh's volume by ``k`` exactly, so one step is
    exact: ``k = volume / V``. The pellet sites (at ``z = 0``) do not move; smooth in
    everything (``V > 0`` for any sane pose of the closed tube)."""
    idx = np.asarray(model.regions["tongue"])
    k = volume / closed_mesh_volume(vertices, tongue_faces(model))
    return vertices.at[idx, 2].set(vertices[idx, 2] * k)
