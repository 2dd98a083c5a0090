"""Head correction and the occlusal frame: rigid fits to reference sensors, frames from a
bite plane or from documented axes, the midsagittal plane. numpy only.

**Head correction.** Articulograph positions are in the device's frame, so every head
movement moves every sensor. Sensors fixed to the skull (upper incisor, nose bridge or
nasion, behind the ears) are the *references*: each frame's references are fitted by a
rigid motion onto one *reference configuration* (Kabsch's least squares: the SVD of the
weighted cross-covariance, with the reflection removed), and that motion is applied to
every sensor of the frame, leaving articulation only. The configuration is the references
of the first frame where all are tracked, refined once to their median over the fitted
frames (so one noisy frame does not define the head frame). The fit's per-frame RMS
residual over the references (mm) is the quality measure: a reference sensor that came
loose, or skin movement, shows there.

What can be removed depends on the references a frame has:

* 3D, three or more references not on one line: the full motion (3 rotations, 3
  translations).
* 3D, two references: translation and the rotations that move the line through them; the
  rotation *about* that line cannot be seen and is not removed.
* one reference (2D or 3D): translation only.
* 2D (midsagittal data such as MOCHA), two or more references: the full planar motion.

A frame with fewer references than the file's usual number is not corrected at a lower
level (a partial correction would add a jump): its sensors are marked untracked and the
frames are counted in the report.

**Occlusal frame.** The toolkit's frame has its origin at the upper incisor tip, x toward
the front along the upper occlusal plane, y up, z toward the subject's left (left-handed,
as the model's; docs/ARCHITECTURE.md). From a bite-plane recording (a plate held between
the teeth with sensors at its front, back and optionally left and right molars): origin at
the front sensor, x from the back sensor to the front one, the lateral axis from the right
to the left sensor (or the normal of the midsagittal plane found from the midline
sensors), up = x cross left, its sign checked against the anatomy (the upper lip or nasion
lies above the occlusal plane).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Bool, Float

#: Three 3D references closer to a line than this (second singular value of the centred
#: points over the first) do not fix the rotation about that line.
COLLINEAR_RATIO = 1e-3


@dataclass(frozen=True, eq=False)
class RigidFits:
    """Per frame ``R p + t`` taking a frame's references onto the reference configuration.

    rotation ``(n, d, d)``, translation ``(n, d)`` mm, residual ``(n,)`` mm (RMS over the
    references; NaN where not fitted), ok ``(n,)`` bool (fitted at the file's level).
    """

    rotation: np.ndarray
    translation: np.ndarray
    residual: np.ndarray
    ok: np.ndarray


def kabsch(src: Float[np.ndarray, "n m d"], dst: Float[np.ndarray, "m d"],
           weights: Float[np.ndarray, "n m"]) -> tuple[Float[np.ndarray, "n d d"],
                                                      Float[np.ndarray, "n d"]]:
    """Per frame, the proper rotation ``R`` and translation ``t`` minimising
    ``sum_i w_i |R src_i + t - dst_i|^2`` (weights 0 drop a point; NaN in a dropped point
    is ignored). Frames with no weight get the identity."""
    d = src.shape[-1]
    w = np.where(np.isfinite(src).all(-1), weights, 0.0)
    total = w.sum(axis=1, keepdims=True)
    safe = np.where(total > 0, total, 1.0)  # frames without weight: identity below
    p = np.where(w[..., None] > 0, src, 0.0)
    q = np.where(w[..., None] > 0, dst[None], 0.0)
    cp = (w[..., None] * p).sum(1) / safe
    cq = (w[..., None] * q).sum(1) / safe
    h = np.einsum("nm,nmi,nmj->nij", w, p - cp[:, None], q - cq[:, None])
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, 1, 2)
    sign = np.sign(np.linalg.det(v @ np.swapaxes(u, 1, 2)))
    fix = np.broadcast_to(np.eye(d), (src.shape[0], d, d)).copy()
    fix[:, -1, -1] = np.where(sign == 0, 1.0, sign)
    rotation = v @ fix @ np.swapaxes(u, 1, 2)
    none = total[:, 0] == 0
    rotation[none] = np.eye(d)
    translation = cq - np.einsum("nij,nj->ni", rotation, cp)
    return rotation, translation


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` the smallest rotations taking unit directions ``a`` to ``b`` (n, 3)
    (Rodrigues; the identity where they already agree, a half turn about any
    perpendicular where they are opposite)."""
    v = np.cross(a, b)
    c = np.einsum("ni,ni->n", a, b)
    k = np.zeros((a.shape[0], 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    k = k - np.swapaxes(k, 1, 2)
    opposite = c < -1 + 1e-12
    scale = np.where(opposite, 0.0, 1.0 / np.where(opposite, 1.0, 1.0 + c))
    r = np.eye(3) + k + (k @ k) * scale[:, None, None]
    if opposite.any():  # a half turn about an axis perpendicular to a
        for i in np.flatnonzero(opposite):
            perp = np.cross(a[i], [1.0, 0, 0])
            if np.linalg.norm(perp) < 1e-6:
                perp = np.cross(a[i], [0, 1.0, 0])
            perp /= np.linalg.norm(perp)
            r[i] = 2 * np.outer(perp, perp) - np.eye(3)
    return r


def tracked_mean(points: Float[np.ndarray, "n m d"]) -> Float[np.ndarray, "n d"]:
    """Per frame, the mean of the tracked points (every coordinate finite); NaN for a
    frame with none (no warning)."""
    tracked = np.isfinite(points).all(-1)
    count = tracked.sum(1)[:, None]
    total = np.where(tracked[..., None], points, 0.0).sum(1)
    return np.where(count > 0, total / np.where(count > 0, count, 1), np.nan)


def reference_level(dims: int, n_refs: int) -> str:
    """What the references can remove: ``"full"``, ``"two"`` (3D, two references),
    ``"translation"`` or ``"none"``."""
    if n_refs == 0:
        return "none"
    if n_refs == 1:
        return "translation"
    if dims == 2 or n_refs >= 3:
        return "full"
    return "two"


def fit_references(refs: Float[np.ndarray, "n m d"], config: Float[np.ndarray, "m d"],
                   level: str) -> RigidFits:
    """Rigid motions taking each frame's references ``refs`` (NaN untracked) onto
    ``config``, at ``level`` (:func:`reference_level`); frames that lack the references
    that level needs (or whose three 3D references are collinear) are not ok."""
    n, m, d = refs.shape
    tracked = np.isfinite(refs).all(-1)
    rotation = np.broadcast_to(np.eye(d), (n, d, d)).copy()
    translation = np.zeros((n, d))
    if level == "full":
        ok = tracked.sum(1) >= (3 if d == 3 else 2)
        if d == 3:
            centred = np.where(tracked[..., None], refs - tracked_mean(refs)[:, None], 0.0)
            sv = np.linalg.svd(np.nan_to_num(centred), compute_uv=False)
            ok &= sv[:, 1] > COLLINEAR_RATIO * np.where(sv[:, 0] > 0, sv[:, 0], 1.0)
        rotation, translation = kabsch(refs, config, tracked.astype(float))
    elif level == "two":
        ok = tracked.all(1)
        a = np.nan_to_num(refs[:, 1] - refs[:, 0])
        b = np.broadcast_to(config[1] - config[0], a.shape)
        norm = np.linalg.norm(a, axis=1, keepdims=True)
        a = a / np.where(norm > 0, norm, 1.0)
        rotation = _rotation_between(a, b / np.linalg.norm(b, axis=1, keepdims=True))
        mid = np.nan_to_num(refs.mean(axis=1))
        translation = config.mean(axis=0) - np.einsum("nij,nj->ni", rotation, mid)
        ok &= norm[:, 0] > 0
    elif level == "translation":
        ok = tracked[:, 0]
        translation = np.where(ok[:, None], config[0] - np.nan_to_num(refs[:, 0]), 0.0)
    else:
        ok = np.ones(n, bool)
    moved = np.einsum("nij,nmj->nmi", rotation, refs) + translation[:, None]
    sq = np.where(tracked, ((moved - config[None]) ** 2).sum(-1), 0.0)
    count = tracked.sum(1)
    residual = np.sqrt(sq.sum(1) / np.where(count > 0, count, 1))
    residual = np.where(ok & (count > 0) & (level != "none"), residual, np.nan)
    return RigidFits(rotation=rotation, translation=translation, residual=residual, ok=ok)


def reference_configuration(refs: Float[np.ndarray, "n m d"], level: str
                            ) -> Float[np.ndarray, "m d"] | None:
    """The head frame's references: those of the first frame with every reference
    tracked, refined once to the median of all frames fitted onto it; None when no frame
    has them all."""
    complete = np.isfinite(refs).all(axis=(1, 2))
    if not complete.any():
        return None
    first = refs[int(np.argmax(complete))]
    fits = fit_references(refs, first, level)
    moved = np.einsum("nij,nmj->nmi", fits.rotation, refs) + fits.translation[:, None]
    use = fits.ok & complete
    return np.median(moved[use], axis=0) if use.any() else first


def apply(fits: RigidFits, positions: Float[np.ndarray, "n k d"]) -> Float[np.ndarray, "n k d"]:
    """Every sensor moved by its frame's fit (``R p + t``); NaN in frames not ok."""
    out = np.einsum("nij,nkj->nki", fits.rotation, positions) + fits.translation[:, None]
    return np.where(fits.ok[:, None, None], out, np.nan)


def rotation_angle_deg(rotation: Float[np.ndarray, "n d d"]) -> Float[np.ndarray, " n"]:
    """The angle of each rotation, degrees (from its trace)."""
    d = rotation.shape[-1]
    trace = np.trace(rotation, axis1=1, axis2=2)
    cos = (trace - 1.0) / 2.0 if d == 3 else trace / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


# ------------------------------------------------------------------ planes and frames
def fit_plane(points: Float[np.ndarray, "m 3"]) -> tuple[Float[np.ndarray, " 3"],
                                                         Float[np.ndarray, " 3"]] | None:
    """``(unit normal, centroid)`` of the least-squares plane through ``points`` (NaN rows
    dropped); None for fewer than 3 points or points on a line."""
    pts = points[np.isfinite(points).all(1)]
    if pts.shape[0] < 3:
        return None
    centroid = pts.mean(0)
    _, sv, vt = np.linalg.svd(pts - centroid)
    if sv[1] <= COLLINEAR_RATIO * sv[0]:
        return None
    return vt[2], centroid


@dataclass(frozen=True, eq=False)
class Frame:
    """A rigid change of frame into the toolkit's: ``p_toolkit = rotation @ (p - origin)``.

    rotation ``(d, d)``: rows are the toolkit's x (forward), y (up) and, in 3D, z (toward
    the subject's left) in the source frame; origin ``(d,)`` mm in the source frame;
    source: how it was found (for the report).
    """

    rotation: np.ndarray
    origin: np.ndarray
    source: str

    def apply(self, positions: Float[np.ndarray, "... d"]) -> Float[np.ndarray, "... d"]:
        """Positions in the toolkit's frame (mm)."""
        return np.einsum("ij,...j->...i", self.rotation, positions - self.origin)


def _unit(v: np.ndarray) -> np.ndarray | None:
    norm = float(np.linalg.norm(v))
    return None if norm < 1e-9 else v / norm


def frame_from_axes(forward: Float[np.ndarray, " d"], up_hint: Float[np.ndarray, " d"] | None,
                    origin: Float[np.ndarray, " d"], source: str,
                    lateral: Float[np.ndarray, " d"] | None = None) -> Frame | None:
    """The toolkit frame with x along ``forward``, y the part of ``up_hint`` perpendicular
    to it (3D with ``lateral``, toward the subject's left: y = x cross left, its sign
    checked against ``up_hint`` when one is given, else trusted: a right-handed source
    frame), z toward the subject's left; None when the directions are degenerate."""
    x = _unit(np.asarray(forward, np.float64))
    if x is None:
        return None
    if x.shape[0] == 2:
        y = np.array([-x[1], x[0]])
        if up_hint is not None and np.dot(y, up_hint) < 0:
            y = -y
        return Frame(np.stack([x, y]), np.asarray(origin, np.float64), source)
    if lateral is not None:
        left = _unit(lateral - np.dot(lateral, x) * x)
        if left is None:
            return None
        y = np.cross(x, left)
        if up_hint is not None and np.dot(y, up_hint) < 0:  # the anatomy decides the sign
            left, y = -left, -y
    else:
        if up_hint is None:
            return None
        y = _unit(up_hint - np.dot(up_hint, x) * x)
        if y is None:
            return None
        left = np.cross(y, x)
    return Frame(np.stack([x, y, left]), np.asarray(origin, np.float64), source)


def signed_axis(text: str, dims: int) -> np.ndarray:
    """``"+x"``, ``"-y"``, ``"z"`` as a unit vector of ``dims`` components."""
    text = text.strip().lower()
    sign = -1.0 if text.startswith("-") else 1.0
    axis = "xyz".index(text[-1])
    if axis >= dims:
        raise ValueError(f"axis {text!r} in {dims}D data")
    v = np.zeros(dims)
    v[axis] = sign
    return v


def bite_frame(front: Float[np.ndarray, " d"], back: Float[np.ndarray, " d"],
               up_hint: Float[np.ndarray, " d"] | None, *, left: np.ndarray | None = None,
               right: np.ndarray | None = None, lateral: np.ndarray | None = None,
               source: str = "bite plane") -> Frame | None:
    """The occlusal frame from bite-plane sensor positions (head frame, mm): origin at
    ``front``, x from ``back`` to ``front``, the lateral axis from ``right`` to ``left``
    when both are given, else ``lateral`` (e.g. the midsagittal plane's normal); None
    when degenerate."""
    if left is not None and right is not None:
        lateral = np.asarray(left) - np.asarray(right)
    return frame_from_axes(np.asarray(front) - np.asarray(back), up_hint, front, source,
                           lateral=lateral)


def valid_mask(positions: Float[np.ndarray, "n k d"]) -> Bool[np.ndarray, "n k"]:
    """``(n, k)``: True where every coordinate of a sensor is finite."""
    return np.isfinite(positions).all(-1)
