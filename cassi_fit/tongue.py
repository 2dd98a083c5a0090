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
from jaxtyping import Array, Float

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
        d = d + (displacement[k + 1] - displacement[k]) * _blend(u)
    behind = (s - site_s[3])
    if anchor == "fixed":
        d = d - displacement[3] * jnp.clip(behind / (anchor_s - site_s[3]), 0.0, 1.0)
    elif anchor == "none":
        trend = jnp.clip(behind / (site_s[3] - site_s[2]), 0.0, 0.5)
        d = d + (displacement[3] - displacement[2]) * trend
    return d
