"""Stage 2 of the synthetic corpus, kinematics: a task's control curves
(:mod:`cassi_fit.synth._tasks`) move a rigid mandible, ``p' = R p + t`` (paper Eqs 4-5),
as the subject's jaw-kinematics family says; the lower lip and tongue are partly carried by
it and partly move on their own, the tongue kept below the palate. Noise-free: the truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Bool, Float

from ..txy import FRAME_STEP_US
from ._anatomy import _LL, _T1, _T2, _T3, _T4, _TONGUE, _UL, SubjectAnatomy, _palate_height
from ._tasks import CONTROLS

#: The XRMB frame period, s (:data:`cassi_fit.txy.FRAME_STEP_US` is its one home).
FRAME_STEP_S = FRAME_STEP_US * 1e-6
# Fraction of the jaw's displacement that the tongue pellets ride along (front to back).
_TONGUE_JAW_SHARE = np.array([0.75, 0.65, 0.55, 0.45])
_PALATE_MARGIN_MM = 1.0  # the tongue pellets stay at least this far below the palate ...
_PALATE_SOFTNESS_MM = 0.7  # ... approached smoothly (a soft minimum of this width)
_SPEECH_PROTRUSION_S = 0.12  # time scale of the speech family's own protrusion, s


@dataclass(frozen=True, eq=False)
class JawTruth:
    """Ground truth of one recording, per frame, relative to the rest (jaw closed) pose.

    Attributes (``n`` frames, including the leading untracked rows):
        times: ``(n,)`` s.
        theta: ``(n,)`` rad, opening positive; the mandible moves as
            ``p_t = R(theta_t) p_rest + translation_t`` (:mod:`cassi_fit.rigid`, Eqs 4-5).
        translation: ``(n, 2)`` mm.
        pivot: ``(n, 2)`` mm, the fixed point of that motion (Eqs 6-7); 0 where undefined.
        pivot_defined: ``(n,)`` bool, False where ``theta == 0``.
        condyle: ``(n, 2)`` mm, the condyle position.
        pellets_true: ``(n, 8, 2)`` mm, noise-free pellet positions.
        dropped: ``(n, 8, 2)`` bool, values written as untracked (leading rows included).
        mistracked: ``(n, 8)`` bool, pellets displaced by an unmarked tracking error.

    The jaw motion from the first valid frame ``f`` to frame ``k`` is
    ``rigid.relative((theta[f], translation[f]), (theta[k], translation[k]))``.
    """

    times: np.ndarray
    theta: np.ndarray
    translation: np.ndarray
    pivot: np.ndarray
    pivot_defined: np.ndarray
    condyle: np.ndarray
    pellets_true: np.ndarray
    dropped: np.ndarray
    mistracked: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])


def _rotate(theta: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``R(theta) p`` for ``theta`` (n,) rad and ``points`` (k, 2): (n, k, 2) mm; the paper's
    ``R = [[cos, sin], [-sin, cos]]`` (Eqs 4-5, as :func:`cassi_fit.rigid.apply`)."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x, y = points[None, :, 0], points[None, :, 1]
    return np.stack([c * x + s * y, -s * x + c * y], axis=-1)


def eminence_path(
    s_mm: Float[np.ndarray, " n"], angle_deg: float, radius_mm: float
) -> Float[np.ndarray, "n 2"]:
    """``(n, 2)`` mm: the condyle's displacement after gliding ``s_mm`` (n,) along the
    articular eminence: an arc leaving the rest position ``angle_deg`` below the forward
    horizontal and turning up (flattening toward the eminence's crest) with
    ``radius_mm``; its heading never passes the horizontal."""
    phi0 = np.deg2rad(angle_deg)
    turned = np.minimum(np.asarray(s_mm, float) / radius_mm, phi0)  # heading change, rad
    x = radius_mm * (np.sin(phi0) - np.sin(phi0 - turned))
    y = -radius_mm * (np.cos(phi0 - turned) - np.cos(phi0))
    beyond = np.asarray(s_mm, float) - turned * radius_mm  # straight on at the crest
    return np.stack([x + beyond, y], axis=-1)


def condyle_slide_mm(
    anatomy: SubjectAnatomy, theta: Float[np.ndarray, " n"]
) -> Float[np.ndarray, " n"]:
    """``(n,)`` mm: the physiological family's glide along the eminence at ``theta`` (rad):
    ``k1 deg + k2 deg^2``, rotation first and translation growing with the opening."""
    deg = np.rad2deg(np.maximum(theta, 0.0))
    return deg * anatomy.condyle_slide_mm_per_deg + deg**2 * anatomy.condyle_slide_mm_per_deg2


def thrust_protrusion_mm(
    anatomy: SubjectAnatomy, n: int, n_lead: int, rng: np.random.Generator
) -> Float[np.ndarray, " n"]:
    """``(n,)`` mm: the thrust family's protrusion, independent of the rotation and not
    smooth: it holds a level and jumps to a new one (uniform in -0.5 .. ``thrust_max_mm``)
    within one frame, ``thrust_rate_hz`` times a second on average; 0 before the first."""
    level = np.zeros(n)
    n_jumps = rng.poisson(anatomy.thrust_rate_hz * n * FRAME_STEP_S)
    starts = np.sort(rng.integers(n_lead, max(n, n_lead + 1), size=n_jumps))
    for start in starts:
        level[start:] = rng.uniform(-0.5, anatomy.thrust_max_mm)
    return level


def speech_protrusion_mm(
    anatomy: SubjectAnatomy, n: int, n_lead: int, rng: np.random.Generator
) -> Float[np.ndarray, " n"]:
    """``(n,)`` mm: the speech family's own protrusion, a smooth random wander of SD
    ``speech_protrusion_sd_mm`` at the pace of syllables (white noise smoothed by a
    Gaussian of ``_SPEECH_PROTRUSION_S``); 0 in the leading rows and starting from 0."""
    from scipy.ndimage import gaussian_filter1d

    sigma = _SPEECH_PROTRUSION_S / FRAME_STEP_S
    wander = gaussian_filter1d(rng.normal(size=n), sigma, mode="nearest")
    wander *= np.sqrt(2.0 * np.sqrt(np.pi) * sigma)  # unit SD (as the drift noise)
    wander = anatomy.speech_protrusion_sd_mm * (wander - wander[min(n_lead, n - 1)])
    wander[:n_lead] = 0.0
    return wander


def condyle_offset(
    anatomy: SubjectAnatomy,
    theta: Float[np.ndarray, " n"],
    protrusion: Float[np.ndarray, " n"],
) -> Float[np.ndarray, "n 2"]:
    """``(n, 2)`` mm: where the condyle is, relative to its rest, in each frame;
    ``protrusion`` (n,) mm is the thrust or speech family's own protrusion."""
    family = anatomy.jaw_kinematics
    if family == "fixed-condyle":
        return np.zeros((theta.shape[0], 2))
    if family == "physiological":
        slide = condyle_slide_mm(anatomy, theta)
        return eminence_path(slide, anatomy.eminence_angle_deg, anatomy.eminence_radius_mm)
    if family == "speech":  # linear in the rotation, plus its own protrusion
        slide = anatomy.speech_slide_mm_per_deg * np.rad2deg(theta) + protrusion
        return eminence_path(slide, anatomy.eminence_angle_deg, anatomy.eminence_radius_mm)
    angle = np.deg2rad(anatomy.eminence_angle_deg)  # thrust: along the eminence's slope
    return protrusion[:, None] * np.array([np.cos(angle), -np.sin(angle)])


def _jaw_motion(
    anatomy: SubjectAnatomy,
    theta: Float[np.ndarray, " n"],
    offset: Float[np.ndarray, "n 2"],
    points: Float[np.ndarray, "k 2"],
) -> tuple[
    Float[np.ndarray, "n 2"], Float[np.ndarray, "n 2"], Bool[np.ndarray, " n"],
    Float[np.ndarray, "n k 2"],
]:
    """The mandible's motion from rest: rotation ``theta`` (n,) about the rest condyle, then
    the condyle moved by ``offset`` (n, 2) mm; ``p' = R p + t`` (Eqs 4-5).

    Returns ``(translation (n, 2), pivot (n, 2), pivot defined (n,), moved points (n, k, 2))``;
    the pivot is the motion's fixed point, ``(I - R)^-1 t`` (Eqs 6-7), 0 where theta = 0.
    """
    condyle = anatomy.condyle_rest
    translation = condyle + offset - _rotate(theta, condyle[None])[:, 0]
    one_minus_c, s = 1.0 - np.cos(theta), np.sin(theta)
    det = one_minus_c**2 + s**2  # det(I - R) = 2 - 2 cos theta
    defined = det > 0.0
    safe = np.where(defined, det, 1.0)
    tx, ty = translation[:, 0], translation[:, 1]
    pivot = np.stack([one_minus_c * tx + s * ty, -s * tx + one_minus_c * ty], axis=-1)
    pivot = np.where(defined[:, None], pivot / safe[:, None], 0.0)
    moved = _rotate(theta, points) + translation[:, None, :]
    return translation, pivot, defined, moved


def _soft_below(y: np.ndarray, ceiling: np.ndarray) -> np.ndarray:
    """``min(y, ceiling)`` smoothed over ``_PALATE_SOFTNESS_MM``; never above ``ceiling``."""
    k = _PALATE_SOFTNESS_MM
    return ceiling - k * np.logaddexp(0.0, (ceiling - y) / k)


def _own_motion(anatomy: SubjectAnatomy, c: dict, jaw_drop_ll: np.ndarray) -> np.ndarray:
    """``(n, 8, 2)`` mm: displacements of lips and tongue by their own muscles.

    ``c`` maps control names to ``(n,)`` curves; ``jaw_drop_ll`` is how far (mm) the jaw
    has lowered the lower lip, which a bilabial closure must make up.
    """
    n = jaw_drop_ll.shape[0]
    d = np.zeros((n, 8, 2))
    close, rnd, labio = c["lip_close"], c["lip_round"], c["labiodental"]
    d[:, _UL, 0] = 4.5 * rnd
    d[:, _UL, 1] = -5.5 * close + 0.3 * c["jaw_deg"]
    d[:, _LL, 0] = 4.0 * rnd - 6.0 * labio
    d[:, _LL, 1] = close * (6.0 + 0.9 * jaw_drop_ll) + labio * (3.0 + 0.5 * jaw_drop_ll)
    tip_up, tip_fwd = c["tip_up"], c["tip_fwd"]
    body_up, body_fwd = c["body_up"], c["body_fwd"]
    d[:, _T1, 0] = tip_fwd + 1.0 * body_fwd
    d[:, _T1, 1] = 15.0 * tip_up + 0.5 * body_up - 0.35 * np.maximum(tip_fwd, 0.0)
    d[:, _T2, 0] = 0.4 * tip_fwd + 1.1 * body_fwd
    d[:, _T2, 1] = 5.0 * tip_up + 0.7 * body_up
    d[:, _T3, 0] = 0.15 * tip_fwd + 1.2 * body_fwd
    d[:, _T3, 1] = 1.0 * body_up
    d[:, _T4, 0] = 1.0 * body_fwd
    d[:, _T4, 1] = 0.8 * body_up - 0.2 * body_fwd
    return d


def _kinematics(
    anatomy: SubjectAnatomy, controls: np.ndarray, times: np.ndarray, protrusion: np.ndarray
) -> JawTruth:
    """Noise-free truth of one trial from its ``(n, len(CONTROLS))`` control curves and
    the thrust family's protrusion ``(n,)`` mm (ignored by the other families)."""
    c = {name: controls[:, i] for i, name in enumerate(CONTROLS)}
    theta = np.deg2rad(np.maximum(c["jaw_deg"], 0.0))
    rest = anatomy.pellets_rest
    # Points carried by the mandible: LL, T1..T4 (their rest), MNI, MNM, the condyle.
    carried = np.concatenate([rest[_LL:], anatomy.condyle_rest[None]])
    offset = condyle_offset(anatomy, theta, protrusion)
    translation, pivot, defined, moved = _jaw_motion(anatomy, theta, offset, carried)
    jaw_disp = moved - carried  # (n, 8, 2)
    pellets = np.broadcast_to(rest, (times.shape[0], 8, 2)).copy()
    pellets[:, _LL:] += jaw_disp[:, :7]
    share = _TONGUE_JAW_SHARE[None, :, None]
    pellets[:, _TONGUE] += (share - 1.0) * jaw_disp[:, 1:5]  # tongue rides only partly
    pellets += _own_motion(anatomy, c, -jaw_disp[:, 0, 1])
    ceiling = _palate_height(anatomy.palate, pellets[:, _TONGUE, 0]) - _PALATE_MARGIN_MM
    pellets[:, _TONGUE, 1] = _soft_below(pellets[:, _TONGUE, 1], ceiling)
    n = times.shape[0]
    return JawTruth(
        times=times,
        theta=theta,
        translation=translation,
        pivot=pivot,
        pivot_defined=defined,
        condyle=moved[:, 7],
        pellets_true=pellets,
        dropped=np.zeros((n, 8, 2), bool),
        mistracked=np.zeros((n, 8), bool),
    )
