"""A synthetic XRMB corpus with ground truth: subjects, kinematics, measurement, files.

The real X-ray microbeam database is distributed on request only; this module makes a
stand-in whose truth is known. Four stages, each a plain function:

1. anatomy (:func:`make_subject`): a subject's palate, jaw pellet spacing, condyle, lips,
   tongue rest positions, head measures, all in the pellet frame (mm), drawn from
   anthropometric norms (``NORMS``), never from the face model's numbers;
2. kinematics (:func:`_kinematics`): the task's control curves (:mod:`cassi_fit.synth_tasks`)
   move a rigid mandible, ``p' = R p + t`` (paper Eqs 4-5), as the subject's jaw-kinematics
   family says (:data:`JAW_KINEMATICS`: rotation about a fixed condyle; the physiological
   glide of the condyle along a curved eminence, coupled to the rotation; rotation plus an
   independent, jumping protrusion); the lower lip and tongue partly carried by it and
   partly on their own, the tongue kept below the palate;
3. measurement (:func:`_simulate`): noise of one of :data:`NOISE_FAMILIES` per pellet,
   all-untracked leading rows, dropouts (1000000) and a few unmarked mistracks, all
   recorded in the truth;
4. files (:func:`generate_corpus`): the real formats through the toolkit's writers, plus a
   ground-truth sidecar per recording and an ``anatomy.json`` per subject.

Everything is deterministic from the seed. See ``docs/SYNTHETIC.md``.
"""

from __future__ import annotations

import functools
import json
import os
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
from jaxtyping import Bool, Float, Int

from .errors import CassiError, DataFormatError, MissingDataError, OutputExistsError
from .synth_tasks import (
    CONTROLS,
    DEFAULT_TASKS,
    JAW_WAGGING_TASK,
    SENTENCE_TASK,
    TASKS,
    TaskSpec,
    control_trajectories,
    get_task,
    task_duration,
)
from .txy import PelletTrack

__all__ = [
    "SubjectAnatomy",
    "JawTruth",
    "TASKS",
    "TaskSpec",
    "DEFAULT_TASKS",
    "JAW_WAGGING_TASK",
    "SENTENCE_TASK",
    "DEFAULT_NOISE_MM",
    "GENERATOR_VERSION",
    "make_subject",
    "synth_recording",
    "synth_audio",
    "generate_corpus",
    "load_truth",
    "load_anatomy",
    "JAW_KINEMATICS",
    "DEFAULT_JAW_KINEMATICS_CYCLE",
    "NOISE_FAMILIES",
    "MAX_NOISE_SCALE",
    "NORMS",
    "COMPLETE_LINE",
    "default_jaw_kinematics",
    "eminence_path",
    "condyle_slide_mm",
    "thrust_protrusion_mm",
    "condyle_offset",
    "corpus_status",
    "default_corpus_dir",
    "ensure_default_corpus",
]

GENERATOR_VERSION = 4  # bump when the generated numbers change (invalidates the cache)
PELLETS = ("UL", "LL", "T1", "T2", "T3", "T4", "MNI", "MNM")  # = cassi_fit.txy.PELLET_NAMES
_UL, _LL, _T1, _T2, _T3, _T4, _MNI, _MNM = range(8)
_TONGUE = slice(_T1, _T4 + 1)
FRAME_STEP_S = 6866e-6  # = cassi_fit.txy.FRAME_STEP_US
# Each coordinate's noise SD (mm), white and drift contributing equal variance; the jaw
# inter-pellet distance then has SD sqrt(2) * 0.212 = 0.3 mm, as in real files.
DEFAULT_NOISE_MM = 0.3 / np.sqrt(2.0)
_DRIFT_S = 0.4  # time scale of the drifting noise component, s
# Fraction of the jaw's displacement that the tongue pellets ride along (front to back).
_TONGUE_JAW_SHARE = np.array([0.75, 0.65, 0.55, 0.45])
_PALATE_MARGIN_MM = 1.0  # the tongue pellets stay at least this far below the palate ...
_PALATE_SOFTNESS_MM = 0.7  # ... approached smoothly (a soft minimum of this width)
AUDIO_RATE_HZ = 16000

#: How the mandible moves (docs/SYNTHETIC.md, "Jaw kinematics", with sources):
#: ``fixed-condyle`` pure rotation about a fixed condyle (Parke's assumption);
#: ``physiological`` the condyle glides down and forward along a curved articular-eminence
#: path, by an amount coupled to the rotation (little at speech angles, 10-20 mm at wide
#: opening); ``thrust`` rotation about the condyle plus an independent, piecewise
#: constant protrusion (jumps within one frame): a translation no smooth prior expects.
JAW_KINEMATICS = ("fixed-condyle", "physiological", "thrust")
#: The default corpus's families, cycled over subjects S01, S02, S03, S04, ...
DEFAULT_JAW_KINEMATICS_CYCLE = ("physiological", "fixed-condyle", "thrust")
#: Measurement noise per coordinate: ``realistic`` white plus drift of equal variance (the
#: default: the jaw pellet distance then varies by 0.3 mm SD as in real files); ``white``;
#: ``drift`` (white noise low-pass filtered over ``_DRIFT_S``, rescaled to the same SD).
NOISE_FAMILIES = ("realistic", "white", "drift")
MAX_NOISE_SCALE = 10.0  # noise_scale above this (> 2 mm per coordinate) is refused


def default_jaw_kinematics(name: str) -> str:
    """The default corpus's family for subject ``name``: ``S01`` physiological, ``S02``
    fixed-condyle, ``S03`` thrust, ``S04`` physiological ... (any other name:
    physiological)."""
    digits = name[1:] if name[:1].upper() == "S" else ""
    if digits.isdigit() and int(digits) >= 1:
        cycle = DEFAULT_JAW_KINEMATICS_CYCLE
        return cycle[(int(digits) - 1) % len(cycle)]
    return "physiological"


def _check_family(value, choices, what: str) -> str:
    from .options import check_choice

    return check_choice(what, value, choices)


# --------------------------------------------------------------------------- anatomy
@dataclass(frozen=True, eq=False)
class SubjectAnatomy:
    """One synthetic subject; positions in the pellet frame (mm), jaw closed (rest pose).

    Attributes beyond the obvious ones: ``pellets_rest`` ``(8, 2)`` all pellets at rest
    (jaw closed, tongue and lips neutral; rows 6-7 equal ``mni_rest``/``mnm_rest``);
    ``jaw_kinematics`` one of :data:`JAW_KINEMATICS`. For ``physiological`` the condyle
    glides ``s = k1 deg + k2 deg^2`` mm (``condyle_slide_mm_per_deg`` = k1,
    ``condyle_slide_mm_per_deg2`` = k2) along an arc that leaves the rest position
    ``eminence_angle_deg`` below the forward horizontal and flattens with radius
    ``eminence_radius_mm``; for ``thrust`` the condyle protrudes along that initial
    direction by independent steps (``thrust_rate_hz`` of them per second, levels up to
    ``thrust_max_mm``). ``f0_hz`` the synthetic voice pitch.
    """

    name: str
    palate: np.ndarray  # (n, 2) front to back
    pharynx: np.ndarray  # (2, 2)
    head: object  # cassi_fit.headmeasures.HeadMeasures
    mni_rest: np.ndarray  # (2,)
    mnm_rest: np.ndarray  # (2,)
    lower_incisor_tip_rest: np.ndarray  # (2,)
    chin_rest: np.ndarray  # (2,) gnathion
    condyle_rest: np.ndarray  # (2,)
    upper_lip_thickness: float
    lower_lip_thickness: float
    face_width: float
    pellets_rest: np.ndarray  # (8, 2)
    condyle_slide_mm_per_deg: float
    condyle_slide_mm_per_deg2: float
    eminence_angle_deg: float
    f0_hz: float
    jaw_kinematics: str = "physiological"
    eminence_radius_mm: float = 20.0
    thrust_rate_hz: float = 0.8
    thrust_max_mm: float = 3.0

    @property
    def jaw_pellet_distance(self) -> float:
        """|MNI - MNM| in mm (constant: the mandible is rigid)."""
        return float(np.linalg.norm(self.mni_rest - self.mnm_rest))


def _palate_outline(rng: np.random.Generator) -> np.ndarray:
    """``(n, 2)`` palate, front to back: a steep alveolar rise into a dome, 9-52 points."""
    n = int(rng.integers(14, 46))
    x_front, x_back = -rng.uniform(3.5, 5.0), -rng.uniform(56.0, 62.0)
    y_front, height = rng.uniform(4.2, 6.0), rng.uniform(24.5, 27.0)
    rise = rng.uniform(0.2, 0.28)  # fraction of the length over which it mostly rises
    x = np.linspace(x_front, x_back, n)
    u = (x - x_front) / (x_back - x_front)
    y = y_front + (height - y_front) * (1 - np.exp(-u / rise)) / (1 - np.exp(-1 / rise))
    y -= rng.uniform(0.0, 2.0) * np.clip((u - 0.8) / 0.2, 0.0, 1.0) ** 2  # velum droop
    return np.round(np.stack([x, y], axis=1), 3)  # um, as PAL.DAT holds it


def _drawn(rng: np.random.Generator, mean: float, sd: float) -> float:
    """One draw from N(mean, sd^2) cut at +-2.5 sd (anthropometric norms are given as
    mean and SD; the cut keeps a synthetic subject inside the range of real ones)."""
    return float(mean + sd * np.clip(rng.normal(), -2.5, 2.5))


# Anthropometric norms the subjects are drawn from (mean, SD; mm or degrees), with their
# sources in docs/SYNTHETIC.md ("Anatomy"). None of them is read from the face model.
NORMS = {
    "overjet": (3.0, 0.5),  # upper ahead of the lower incisal edge (Proffit: 2-3 mm)
    "rest_gap": (1.2, 0.4),  # lower incisal edge below the upper's at speech rest
    "mni_depth": (3.5, 0.8),  # MNI centre below the incisal edge along the crown (9 mm long)
    "mni_labial": (3.2, 0.5),  # MNI centre ahead of the edge line (crown convexity + pellet)
    "incisor_tilt_deg": (22.0, 6.0),  # lower incisor crown forward of the vertical
    "upper_lip_thickness": (13.9, 2.1),  # UL pellet ahead of the upper incisor tip
    "lower_lip_thickness": (14.9, 1.9),  # LL pellet ahead of the lower tip, along the jaw
    "face_width": (134.0, 6.0),  # bizygomatic breadth
    "jaw_width": (96.0, 6.0),  # bigonial breadth
    "mouth_width": (51.0, 3.5),  # cheilion to cheilion
    "nose_protrusion": (20.0, 2.0),  # subnasale to pronasale
}


def _head_measures(rng, gonion, gnathion, ul_thick, ll_thick):
    from .headmeasures import HeadMeasures

    um = functools.partial(round, ndigits=3)  # as Headmeasures.txt holds them
    widths = ("face_width", "jaw_width", "mouth_width", "nose_protrusion")
    face, jaw, mouth, nose = (_drawn(rng, *NORMS[k]) for k in widths)
    return HeadMeasures(
        gonion_x=um(float(gonion[0])),
        gonion_y=um(float(gonion[1])),
        gnathion_x=um(float(gnathion[0])),
        gnathion_y=um(float(gnathion[1])),
        face_width=um(face),
        jaw_width=um(jaw),
        mouth_width=um(mouth),
        upper_lip_thickness=um(float(ul_thick)),
        lower_lip_thickness=um(float(ll_thick)),
        nose_protrusion=um(nose),
    )


def _incisor_and_mni(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Lower incisor tip and MNI (mm, pellet frame) from the dental norms in ``NORMS``.

    MNI is glued to the labial face of the lower incisor: ``mni_depth`` below the incisal
    edge along the crown (tilted ``incisor_tilt_deg`` forward of vertical, so going down
    the crown goes back) and ``mni_labial`` ahead of it, across the crown.
    """
    tip = np.array([-_drawn(rng, *NORMS["overjet"]), -_drawn(rng, *NORMS["rest_gap"])])
    tilt = np.deg2rad(_drawn(rng, *NORMS["incisor_tilt_deg"]))
    down = np.array([-np.sin(tilt), -np.cos(tilt)])  # along the crown, toward the root
    labial = np.array([np.cos(tilt), -np.sin(tilt)])
    mni = tip + _drawn(rng, *NORMS["mni_depth"]) * down + _drawn(rng, *NORMS["mni_labial"]) * labial
    return tip, mni


def make_subject(
    name: str, rng: np.random.Generator, *, jaw_kinematics: str | None = None
) -> SubjectAnatomy:
    """Draw one subject's anatomy (see the class for units and frames).

    ``jaw_kinematics`` one of :data:`JAW_KINEMATICS`, or None for the default corpus's
    choice for this name (:func:`default_jaw_kinematics`). The family does not change any
    other draw: the same rng gives the same geometry whatever the family.
    """
    family = default_jaw_kinematics(name) if jaw_kinematics is None else jaw_kinematics
    family = _check_family(family, JAW_KINEMATICS, "jaw kinematics")
    r = rng.uniform
    tip, mni = _incisor_and_mni(rng)
    spacing, slope = r(37.0, 44.5), np.deg2rad(r(4.0, 9.0))
    mnm = mni + spacing * np.array([-np.cos(slope), np.sin(slope)])
    condyle = tip + np.array([-r(90.0, 100.0), r(20.0, 30.0)])
    gnathion = tip + np.array([r(-1.0, 4.0), -r(38.0, 46.0)])
    gonion = condyle + np.array([r(2.0, 10.0), -r(50.0, 60.0)])
    ul_thick = _drawn(rng, *NORMS["upper_lip_thickness"])
    ll_thick = _drawn(rng, *NORMS["lower_lip_thickness"])
    scale = r(0.95, 1.05)  # vocal tract size
    tongue = scale * np.array([[-16.5, 1.5], [-28.0, 8.0], [-39.5, 15.0], [-53.0, 17.0]])
    tongue = tongue + rng.normal(0.0, 0.8, size=(4, 2))
    palate = _palate_outline(rng)
    tongue[:, 1] = np.minimum(tongue[:, 1], _palate_height(palate, tongue[:, 0]) - 4.0)
    # Lip thickness as Headmeasures defines it (docs/FORMATS.md): how far the lip pellet
    # (on the vermilion) sits ahead of the incisor tip, at rest (upper: from the origin;
    # lower: from ``tip``, along the mandible's forward direction MNM -> MNI, so that it
    # does not change as the jaw turns).
    ul = np.array([ul_thick, r(16.5, 19.5)])
    forward = (mni - mnm) / np.linalg.norm(mni - mnm)
    ll_y = r(-18.0, -15.5)
    ll = np.array([tip[0] + (ll_thick - (ll_y - tip[1]) * forward[1]) / forward[0], ll_y])
    pellets = np.concatenate([ul[None], ll[None], tongue, mni[None], mnm[None]])
    head = _head_measures(rng, gonion, gnathion, ul_thick, ll_thick)
    return SubjectAnatomy(
        name=str(name),
        palate=palate,
        pharynx=np.round([[-r(70.0, 78.0), r(15.0, 22.0)], [-r(66.0, 74.0), -r(25.0, 35.0)]], 3),
        head=head,
        mni_rest=mni,
        mnm_rest=mnm,
        lower_incisor_tip_rest=tip,
        chin_rest=np.array([head.gnathion_x, head.gnathion_y]),
        condyle_rest=condyle,
        upper_lip_thickness=head.upper_lip_thickness,
        lower_lip_thickness=head.lower_lip_thickness,
        face_width=head.face_width,
        pellets_rest=pellets,
        condyle_slide_mm_per_deg=float(r(0.05, 0.15)),
        condyle_slide_mm_per_deg2=float(r(0.010, 0.016)),
        eminence_angle_deg=float(r(35.0, 50.0)),
        f0_hz=float(r(100.0, 220.0)),
        jaw_kinematics=family,
        eminence_radius_mm=float(r(15.0, 25.0)),
        thrust_rate_hz=float(r(0.6, 1.2)),
        thrust_max_mm=float(r(2.0, 4.0)),
    )


def _palate_height(palate: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Palate y (mm) above each x (mm); held at its end values beyond the outline."""
    return np.interp(x, palate[::-1, 0], palate[::-1, 1])


# ------------------------------------------------------------------------ kinematics
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


def condyle_offset(
    anatomy: SubjectAnatomy,
    theta: Float[np.ndarray, " n"],
    protrusion: Float[np.ndarray, " n"],
) -> Float[np.ndarray, "n 2"]:
    """``(n, 2)`` mm: where the condyle is, relative to its rest, in each frame."""
    family = anatomy.jaw_kinematics
    if family == "fixed-condyle":
        return np.zeros((theta.shape[0], 2))
    if family == "physiological":
        slide = condyle_slide_mm(anatomy, theta)
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


# ----------------------------------------------------------------------- measurement
def _noise(rng: np.random.Generator, n: int, noise_mm: float, family: str) -> np.ndarray:
    """``(n, 8, 2)`` mm of measurement noise, each coordinate of SD ``noise_mm``.

    ``family`` (:data:`NOISE_FAMILIES`): ``white`` independent per frame; ``drift`` white
    noise smoothed by a Gaussian of ``_DRIFT_S`` (a slow wander, rescaled to unit SD);
    ``realistic`` the two added with equal variance. The same rng draws the same numbers
    for every family, so families differ only in how the numbers are combined.
    """
    from scipy.ndimage import gaussian_filter1d

    white = rng.normal(size=(n, 8, 2))
    drift = gaussian_filter1d(rng.normal(size=(n, 8, 2)), _DRIFT_S / FRAME_STEP_S, axis=0)
    # The filtered unit white noise has SD 1/sqrt(2 sqrt(pi) sigma); restore unit SD.
    drift *= np.sqrt(2.0 * np.sqrt(np.pi) * _DRIFT_S / FRAME_STEP_S)
    if family == "white":
        return noise_mm * white
    if family == "drift":
        return noise_mm * drift
    return noise_mm / np.sqrt(2.0) * (white + drift)


def _dropouts(rng: np.random.Generator, n: int, n_lead: int) -> np.ndarray:
    """``(n, 8, 2)`` bool: all-untracked leading rows plus at least one run of dropouts.

    The back tongue pellets drop out most often; x and y go together nine times in ten.
    """
    dropped = np.zeros((n, 8, 2), bool)
    dropped[:n_lead] = True
    weights = np.array([1.0, 1.0, 1.0, 1.0, 2.0, 3.0, 0.7, 1.5])
    for _ in range(1 + rng.poisson(1.5 * n * FRAME_STEP_S / 4.0)):
        pellet = rng.choice(8, p=weights / weights.sum())
        start = int(rng.integers(n_lead + 1, n))
        length = int(min(1 + rng.geometric(0.15), 30))
        axes = slice(None) if rng.random() < 0.9 else int(rng.integers(2))
        dropped[start : start + length, pellet, axes] = True
    return dropped


def _mistracks(rng: np.random.Generator, n: int, n_lead: int):
    """``(offsets (n, 8, 2) mm, mistracked (n, 8) bool)``: one to three brief jumps."""
    offsets = np.zeros((n, 8, 2))
    flags = np.zeros((n, 8), bool)
    for _ in range(int(rng.integers(1, 4))):
        pellet = int(rng.integers(8))
        start = int(rng.integers(n_lead + 1, n))
        length = int(rng.integers(1, 6))
        angle = rng.uniform(0.0, 2 * np.pi)
        jump = rng.uniform(4.0, 10.0) * np.array([np.cos(angle), np.sin(angle)])
        offsets[start : start + length, pellet] += jump
        flags[start : start + length, pellet] = True
    return offsets, flags


def synth_recording(
    anatomy: SubjectAnatomy,
    task: str,
    *,
    seed: int | Sequence[int] | np.random.SeedSequence,
    noise_mm: float = DEFAULT_NOISE_MM,
    duration_s: float | None = None,
    dropouts: bool = True,
    mistracks: bool = True,
    noise_family: str = "realistic",
) -> tuple[PelletTrack, JawTruth]:
    """One synthetic recording in memory: ``(PelletTrack, JawTruth)``.

    ``seed`` is anything ``numpy.random.SeedSequence`` accepts. ``noise_mm`` is each
    coordinate's noise SD (mm; the default gives the jaw inter-pellet distance an SD of
    0.3 mm). ``duration_s`` overrides the task's natural length (s, leading rows
    included). Positions are rounded to 1 um as in the files, so writing and reading the
    track gives it back exactly. The track holds 4-10 leading all-untracked rows from
    time 0 and, unless switched off, dropouts and 1-3 unmarked mistracks (see the truth's
    ``dropped`` and ``mistracked``). ``noise_family`` one of :data:`NOISE_FAMILIES`. The
    jaw moves as ``anatomy.jaw_kinematics`` says.
    """
    return _simulate(
        anatomy, task, seed, noise_mm, duration_s, dropouts, mistracks, noise_family
    )[:2]


def _simulate(anatomy, task, seed, noise_mm, duration_s, dropouts, mistracks, noise_family):
    """``(track, truth, controls)``; see :func:`synth_recording`."""


    spec = get_task(task)
    if not (np.isfinite(noise_mm) and 0 <= noise_mm <= MAX_NOISE_SCALE * DEFAULT_NOISE_MM):
        raise CassiError(
            f"noise_mm must be a number from 0 to {MAX_NOISE_SCALE * DEFAULT_NOISE_MM:.3g} mm,"
            f" got {noise_mm!r}"
        )
    _check_family(noise_family, NOISE_FAMILIES, "noise family")
    # A sixth stream for the thrust family: spawned children do not depend on how many
    # are spawned, so the other five streams are those of generator version 3.
    task_rng, noise_rng, drop_rng, jump_rng, lead_rng, thrust_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(6)
    )
    n_lead = int(lead_rng.integers(4, 11))
    natural_s, keyframes = task_duration(spec, task_rng)
    total_s = duration_s if duration_s is not None else natural_s + n_lead * FRAME_STEP_S
    n = int(round(total_s / FRAME_STEP_S))
    if n < n_lead + 10:
        raise CassiError(f"duration_s={duration_s!r} is too short for a recording")
    controls = control_trajectories(spec, keyframes, n - n_lead, FRAME_STEP_S, task_rng)
    controls = np.concatenate([np.repeat(controls[:1], n_lead, axis=0), controls])
    times = np.arange(n) * 6866 / 1e6  # as read_txy gives them (us / 1e6)
    protrusion = thrust_protrusion_mm(anatomy, n, n_lead, thrust_rng)
    truth = _kinematics(anatomy, controls, times, protrusion)
    measured = truth.pellets_true + _noise(noise_rng, n, noise_mm, noise_family)
    dropped = _dropouts(drop_rng, n, n_lead) if dropouts else np.zeros((n, 8, 2), bool)
    dropped[:n_lead] = True
    jumps, flags = _mistracks(jump_rng, n, n_lead) if mistracks else (0.0, np.zeros((n, 8), bool))
    measured = np.round((measured + jumps) * 1e3) / 1e3
    flags &= ~dropped.all(axis=2)
    truth = _replace(truth, dropped=dropped, mistracked=flags)
    track = PelletTrack(times=times, positions=measured, valid=~dropped)
    return track, truth, controls


def _replace(truth: JawTruth, **changes) -> JawTruth:
    values = {f.name: getattr(truth, f.name) for f in fields(JawTruth)}
    return JawTruth(**{**values, **changes})


# ------------------------------------------------------------------------------ audio
def synth_audio(
    controls: Float[np.ndarray, "n c"], times: Float[np.ndarray, " n"], f0_hz: float,
    rng: np.random.Generator,
) -> Int[np.ndarray, " samples"]:
    """A voiced buzz that follows the articulators: ``(n_samples,)`` int16 at 16 kHz.

    ``controls`` ``(n, len(CONTROLS))`` on the frame times ``times`` (s). Sample ``k`` is at
    ``k / 16000`` s, so the audio starts with the recording (time 0) and lasts as long
    (``n * 6866`` us). Loudness follows voicing and the mouth opening (silent in a lip
    or tongue-tip closure); the first two formants follow jaw opening and tongue body
    position. It is a harmonic sum, not speech, but its envelope is aligned to the
    movements, which is what a speech-sync demo needs.
    """
    c = {name: controls[:, i] for i, name in enumerate(CONTROLS)}
    n_samples = int(round(times.shape[0] * FRAME_STEP_S * AUDIO_RATE_HZ))
    t = np.arange(n_samples) / AUDIO_RATE_HZ
    # Linear interpolation from frames to samples, shared by every curve below.
    pos = np.clip((t - times[0]) / FRAME_STEP_S, 0.0, times.shape[0] - 1.0)
    i0 = np.minimum(pos.astype(np.int64), times.shape[0] - 2)
    w = pos - i0

    def at_samples(curve):
        return curve[i0] * (1.0 - w) + curve[i0 + 1] * w

    closure = np.clip(np.maximum(c["lip_close"], c["tip_up"] - 0.2), 0.0, 1.0)
    opening = (1.0 - closure) * (0.35 + 0.65 * np.clip(c["jaw_deg"] / 8.0, 0.0, 1.0))
    loud = at_samples(np.clip(c["voicing"], 0.0, 1.0) * opening)
    f1 = 300.0 + 55.0 * c["jaw_deg"] - 8.0 * c["body_up"]  # per frame, Hz
    f2 = 1450.0 + 70.0 * c["body_fwd"] + 25.0 * c["body_up"] - 250.0 * c["lip_round"]
    f0 = f0_hz * (1.05 - 0.1 * t / max(t[-1], 1e-9)) * (1.0 + 0.02 * np.sin(2 * np.pi * 4.0 * t))
    base = np.exp(1j * (2 * np.pi * np.cumsum(f0) / AUDIO_RATE_HZ))
    harmonic = base.copy()  # exp(i k phase), by repeated multiplication (cheaper than sin)
    signal = np.zeros(n_samples)
    # Harmonic gains change at the articulators' pace: computed per frame, interpolated.
    for k in range(1, int(3800.0 // f0_hz) + 1):
        fk = k * f0_hz
        gain = (
            np.exp(-0.5 * ((fk - f1) / 120.0) ** 2)
            + 0.6 * np.exp(-0.5 * ((fk - f2) / 180.0) ** 2)
            + 0.25 * np.exp(-0.5 * ((fk - 2700.0) / 250.0) ** 2)
            + 0.3 / k
        )
        signal += at_samples(gain) * harmonic.imag
        harmonic *= base
    hiss = np.diff(rng.normal(size=n_samples + 1)) * at_samples(c["frication"]) * 0.15
    signal = signal * loud + hiss
    peak = np.max(np.abs(signal))
    scale = 0.6 * 32767 / peak if peak > 0 else 0.0
    return np.round(signal * scale).astype(np.int16)


def _write_wav(path: Path, samples: np.ndarray, *, overwrite: bool) -> Path:
    """16 kHz mono int16 ``.wav`` (stdlib ``wave``), written atomically."""
    import wave

    from ._io import atomic_write

    def write(fh):
        with wave.open(fh, "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(AUDIO_RATE_HZ)
            w.writeframes(samples.astype("<i2").tobytes())

    return atomic_write(path, write, overwrite=overwrite, binary=True, data_file=True)


# ----------------------------------------------------------------------- truth files
def _truth_columns() -> list[str]:
    cols = ["time_s", "theta_deg", "tx_mm", "ty_mm", "pivot_x_mm", "pivot_y_mm"]
    cols += ["condyle_x_mm", "condyle_y_mm"]
    cols += [f"{p}_{a}_mm" for p in PELLETS for a in "xy"]
    cols += [f"dropped_{p}_{a}" for p in PELLETS for a in "xy"]
    return cols + [f"mistracked_{p}" for p in PELLETS]


TRUTH_COLUMNS = tuple(_truth_columns())
_N_FLOAT_COLUMNS = 8 + 16


def _truth_text(truth: JawTruth, comment: str) -> str:
    """The sidecar CSV: a ``#`` comment line, a header, one row per frame."""
    n = truth.n_frames
    values = np.concatenate(
        [
            truth.times[:, None],
            np.rad2deg(truth.theta)[:, None],
            truth.translation,
            truth.pivot,
            truth.condyle,
            truth.pellets_true.reshape(n, 16),
        ],
        axis=1,
    )
    flags = np.concatenate([truth.dropped.reshape(n, 16), truth.mistracked], axis=1)
    fmt = ",".join(["%.6f", "%.10f"] + ["%.6f"] * (_N_FLOAT_COLUMNS - 2)) + ","
    fmt_flags = ",".join(["%d"] * 24)
    lines = [f"# {comment}", ",".join(TRUTH_COLUMNS)]
    for row, flag_row, defined in zip(
        values.tolist(), flags.astype(int).tolist(), truth.pivot_defined, strict=True
    ):
        text = fmt % tuple(row)
        if not defined:  # the pivot columns are left empty where the pivot does not exist
            parts = text.split(",")
            parts[4] = parts[5] = ""
            text = ",".join(parts)
        lines.append(text + fmt_flags % tuple(flag_row))
    return "\n".join(lines) + "\n"


def _parse_truth(path: Path, text: str) -> JawTruth:
    rows, header_seen = [], False
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        fields_ = line.strip().split(",")
        if not header_seen:
            if tuple(fields_) != TRUTH_COLUMNS:
                raise DataFormatError(path, lineno, "not a synthetic ground-truth header")
            header_seen = True
            continue
        if len(fields_) != len(TRUTH_COLUMNS):
            raise DataFormatError(
                path, lineno, f"expected {len(TRUTH_COLUMNS)} fields, found {len(fields_)}"
            )
        try:
            rows.append([float(f) if f else np.nan for f in fields_])
        except ValueError:
            raise DataFormatError(path, lineno, "a field is not a number") from None
    if not rows:
        raise DataFormatError(path, None, "no ground-truth rows")
    a = np.array(rows)
    n = a.shape[0]
    defined = np.isfinite(a[:, 4]) & np.isfinite(a[:, 5])
    return JawTruth(
        times=a[:, 0],
        theta=np.deg2rad(a[:, 1]),
        translation=a[:, 2:4],
        pivot=np.where(defined[:, None], a[:, 4:6], 0.0),
        pivot_defined=defined,
        condyle=a[:, 6:8],
        pellets_true=a[:, 8:24].reshape(n, 8, 2),
        dropped=a[:, 24:40].reshape(n, 8, 2) != 0,
        mistracked=a[:, 40:48] != 0,
    )


def _find_ci(folder: Path, name: str) -> Path | None:
    """The entry of ``folder`` called ``name`` ignoring case, or None."""
    if not folder.is_dir():
        return None
    exact = folder / name
    if exact.exists():
        return exact
    matches = sorted(p for p in folder.iterdir() if p.name.lower() == name.lower())
    return matches[0] if matches else None


def load_truth(root: str | os.PathLike, subject: str, task: str) -> JawTruth:
    """Read the ground truth of ``subject``'s ``task`` from a corpus folder ``root``.

    Reads ``root/<subject>/<task>.truth.csv`` (names case-insensitive). Raises
    MissingDataError when absent or when the corpus is incomplete (its README.txt lacks
    the completion line: an interrupted generation), DataFormatError when malformed.
    """
    from ._io import register_input

    _check_corpus(Path(root))
    folder = _find_ci(Path(root), str(subject))
    path = _find_ci(folder, f"{task}.truth.csv") if folder is not None else None
    if path is None:
        raise MissingDataError(f"{Path(root) / str(subject)}: no ground truth for task {task!r}")
    register_input(path)
    return _parse_truth(path, path.read_text(encoding="utf-8"))


# --------------------------------------------------------------------- anatomy files
def _anatomy_json(anatomy: SubjectAnatomy) -> str:
    out = {}
    for f in fields(SubjectAnatomy):
        value = getattr(anatomy, f.name)
        if f.name == "head":
            value = asdict(value)
        elif isinstance(value, np.ndarray):
            value = value.tolist()
        out[f.name] = value
    return json.dumps(out, indent=1) + "\n"


def load_anatomy(root: str | os.PathLike, subject: str) -> SubjectAnatomy:
    """Read ``root/<subject>/anatomy.json`` written by :func:`generate_corpus` (refused,
    MissingDataError, when the corpus is incomplete, as :func:`load_truth`)."""
    from ._io import register_input
    from .headmeasures import HeadMeasures

    _check_corpus(Path(root))
    folder = _find_ci(Path(root), str(subject))
    path = _find_ci(folder, "anatomy.json") if folder is not None else None
    if path is None:
        raise MissingDataError(f"{Path(root) / str(subject)}: no anatomy.json")
    register_input(path)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
        values = {}
        for f in fields(SubjectAnatomy):
            value = raw[f.name]
            if f.name == "head":
                value = HeadMeasures(**value)
            elif isinstance(value, list):
                value = np.asarray(value, dtype=np.float64)
            values[f.name] = value
        return SubjectAnatomy(**values)
    except (ValueError, KeyError, TypeError) as exc:
        raise DataFormatError(path, None, f"not a synthetic anatomy file ({exc})") from None


# ---------------------------------------------------------------------------- corpus
def subject_names(n_subjects: int) -> list[str]:
    """``S01``, ``S02``, ... (never the real database's JW names)."""
    return [f"S{i + 1:02d}" for i in range(n_subjects)]


def _file_names(index: int) -> dict[str, str]:
    """Upper-case file names for odd-numbered subjects (S01, S03, ...), lower for even:
    the real distribution mixes both, and readers must not care."""
    upper = index % 2 == 0
    case = str.upper if upper else str.lower
    return {
        "pal": case("PAL.DAT"),
        "pha": case("PHA.DAT"),
        "txy": case(".txy"),
        "wav": case(".wav"),
    }


def _recording_seed(seed: int, index: int, task: str) -> list[int]:
    return [int(seed), 2, index, zlib.crc32(task.encode())]


def _corpus_plan(out_dir: Path, names, tasks, audio):
    """``[(subject index, name, task or None, {kind: path})]`` of every file to write."""
    plan = []
    for i, name in enumerate(names):
        fn, folder = _file_names(i), out_dir / name
        plan.append((i, name, None, {"pal": folder / fn["pal"], "pha": folder / fn["pha"],
                                     "anatomy": folder / "anatomy.json"}))  # fmt: skip
        for task in tasks:
            stem = task.upper() if fn["txy"] == ".TXY" else task
            files = {"txy": folder / f"{stem}{fn['txy']}", "truth": folder / f"{task}.truth.csv"}
            if audio and TASKS[task].audio:
                files["wav"] = folder / f"{stem}{fn['wav']}"
            plan.append((i, name, task, files))
    return plan


COMPLETE_LINE = "complete: yes"  # the README's last line, written last of all files


def _readme(n_subjects, seed, tasks, noise_scale, audio, families, noise_family) -> str:
    names = subject_names(n_subjects)
    lines = [
        "cassi_fit synthetic XRMB corpus (NOT real data)",
        "",
        "Made by cassi_fit.synth.generate_corpus / `cassi synth`; see docs/SYNTHETIC.md.",
        f"generator_version: {GENERATOR_VERSION}",
        f"seed: {seed}",
        f"subjects: {n_subjects} ({', '.join(names)})",
        f"tasks: {', '.join(tasks)}",
        f"noise_scale: {noise_scale}",
        f"noise_family: {noise_family}",
        "jaw_kinematics: " + ", ".join(f"{n} {f}" for n, f in zip(names, families, strict=True)),
        f"audio: {'yes' if audio else 'no'}",
        "",
        "Per subject folder: pellet files (.txy, real format), PAL.DAT, PHA.DAT, audio (.wav,",
        "16 kHz, speech tasks), <task>.truth.csv (per frame: true jaw angle, translation,",
        "pivot, condyle, noise-free pellets, dropout and mistrack flags) and anatomy.json.",
        "Headmeasures.txt holds every subject's head measures.",
        "The last line below is written after every other file: without it the corpus is",
        "incomplete (generation was interrupted) and the readers refuse it.",
        COMPLETE_LINE,
    ]
    return "\n".join(lines) + "\n"


def _families(n_subjects: int, jaw_kinematics) -> list[str]:
    """Each subject's jaw-kinematics family: None or "mixed" for the default cycle
    (:func:`default_jaw_kinematics`), one family for all, or a comma-separated string /
    sequence of families cycled over the subjects."""
    names = subject_names(n_subjects)
    if jaw_kinematics is None or jaw_kinematics == "mixed":
        return [default_jaw_kinematics(n) for n in names]
    if isinstance(jaw_kinematics, str):
        jaw_kinematics = [f.strip() for f in jaw_kinematics.split(",") if f.strip()]
    cycle = [_check_family(f, JAW_KINEMATICS, "jaw kinematics") for f in jaw_kinematics]
    if not cycle:
        raise CassiError("no jaw kinematics family given")
    return [cycle[i % len(cycle)] for i in range(n_subjects)]


def generate_corpus(
    out_dir: str | os.PathLike,
    *,
    n_subjects: int = 15,
    seed: int = 0,
    tasks: str | Sequence[str] | None = None,
    noise_scale: float = 1.0,
    audio: bool = True,
    overwrite: bool = False,
    jaw_kinematics: str | Sequence[str] | None = None,
    noise_family: str = "realistic",
) -> Path:
    """Write a synthetic corpus to ``out_dir`` and return its path.

    ``tasks``: task names (default ``DEFAULT_TASKS``); ``noise_scale`` (0 to
    ``MAX_NOISE_SCALE``) multiplies the default measurement noise (0 = noise-free,
    dropouts and mistracks stay); ``noise_family`` one of :data:`NOISE_FAMILIES`;
    ``jaw_kinematics`` None / "mixed" (the default cycle over subjects: S01 physiological,
    S02 fixed-condyle, S03 thrust, ...), one of :data:`JAW_KINEMATICS` for every subject,
    or several (comma-separated or a sequence) cycled over the subjects; ``audio`` writes
    a ``.wav`` for speech tasks. Every argument is checked, and existing files refused
    (OutputExistsError, unless ``overwrite``), before anything is written. The corpus is
    written into a temporary sibling folder and moved into place at the end, README.txt
    (whose last line marks a complete corpus) last; an interrupted run leaves nothing.
    Deterministic: the same arguments give byte-identical files, and each recording
    depends only on (seed, subject, task, its family, the noise options).
    """
    import shutil
    import tempfile

    out_dir = Path(out_dir)
    tasks = _check_arguments(n_subjects, seed, tasks, noise_scale, audio)
    families = _families(n_subjects, jaw_kinematics)
    noise_family = _check_family(noise_family, NOISE_FAMILIES, "noise family")
    names = subject_names(n_subjects)
    relative = _corpus_plan(Path(), names, tasks, audio)
    if not overwrite:
        for rel in [Path("README.txt"), Path("Headmeasures.txt"),
                    *(p for *_, files in relative for p in files.values())]:  # fmt: skip
            if (out_dir / rel).exists():
                raise OutputExistsError(
                    f"{out_dir / rel}: file exists (pass overwrite=True / --force)"
                )
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputExistsError(f"{out_dir}: exists and is not a folder")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    try:
        _chmod_as_umask(tmp)
        options = (seed, tasks, noise_scale, audio, families, noise_family)
        _write_corpus(tmp, names, _corpus_plan(tmp, names, tasks, audio), options)
        _move_into_place(tmp, out_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out_dir


def _chmod_as_umask(folder: Path) -> None:
    """``mkdtemp`` makes a 0700 folder; the corpus gets the user's normal folder mode."""
    mask = os.umask(0)
    os.umask(mask)
    folder.chmod(0o777 & ~mask)


def _write_corpus(root: Path, names, plan, options) -> None:
    """Every file of the corpus into ``root`` (a fresh folder), README.txt last."""
    from ._io import atomic_write
    from .headmeasures import write_headmeasures
    from .outlines import write_outline
    from .txy import write_txy

    seed, tasks, noise_scale, audio, families, noise_family = options
    anatomies = {}
    for i, name, task, files in plan:
        if task is None:
            rng = np.random.default_rng([int(seed), 1, i])
            anatomy = make_subject(name, rng, jaw_kinematics=families[i])
            anatomies[name] = anatomy
            write_outline(files["pal"], anatomy.palate, overwrite=True)
            write_outline(files["pha"], anatomy.pharynx, overwrite=True)
            atomic_write(files["anatomy"], _anatomy_json(anatomy), overwrite=True)
            continue
        anatomy = anatomies[name]
        rec_seed = _recording_seed(seed, i, task)
        noise_mm = noise_scale * DEFAULT_NOISE_MM
        track, truth, controls = _simulate(
            anatomy, task, rec_seed, noise_mm, None, True, True, noise_family
        )
        write_txy(files["txy"], track, overwrite=True)
        comment = (f"cassi_fit synthetic ground truth; subject {name}; task {task}; seed {seed};"
                   f" jaw kinematics {anatomy.jaw_kinematics}; noise {noise_family}")  # fmt: skip
        atomic_write(files["truth"], _truth_text(truth, comment), overwrite=True)
        if "wav" in files:
            rng = np.random.default_rng([*rec_seed, 3])
            samples = synth_audio(controls, truth.times, anatomy.f0_hz, rng)
            _write_wav(files["wav"], samples, overwrite=True)
    heads = {name: a.head for name, a in anatomies.items()}
    write_headmeasures(root / "Headmeasures.txt", heads, overwrite=True)
    readme = _readme(len(names), seed, tasks, noise_scale, audio, families, noise_family)
    atomic_write(root / "README.txt", readme, overwrite=True)


def _move_into_place(tmp: Path, out_dir: Path) -> None:
    """Rename the finished ``tmp`` to ``out_dir`` (one atomic rename if ``out_dir`` is
    absent or empty); else move file by file into it, its old README.txt removed first and
    the new one moved last, so an interruption leaves a corpus marked incomplete."""
    if out_dir.is_dir() and not any(out_dir.iterdir()):
        out_dir.rmdir()
    if not out_dir.exists():
        os.replace(tmp, out_dir)
        return
    (out_dir / "README.txt").unlink(missing_ok=True)
    for path in sorted(p for p in tmp.rglob("*") if p.is_file() and p.name != "README.txt"):
        target = out_dir / path.relative_to(tmp)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(path, target)
    os.replace(tmp / "README.txt", out_dir / "README.txt")


def _check_arguments(n_subjects, seed, tasks, noise_scale, audio) -> tuple[str, ...]:
    """Validate :func:`generate_corpus`'s arguments; returns the task names (lower case).

    Every option out of range is refused here, before anything is written.
    """
    if not isinstance(n_subjects, (int, np.integer)) or not 1 <= n_subjects <= 99:
        raise CassiError(f"n_subjects must be an integer from 1 to 99, got {n_subjects!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not (
        0 <= seed < 2**63
    ):
        raise CassiError(f"seed must be an integer from 0 to 2**63 - 1, got {seed!r}")
    if not (
        isinstance(noise_scale, (int, float, np.number))
        and np.isfinite(noise_scale)
        and 0 <= noise_scale <= MAX_NOISE_SCALE
    ):
        raise CassiError(
            f"noise_scale must be a number from 0 to {MAX_NOISE_SCALE:g} (the default noise "
            f"times at most {MAX_NOISE_SCALE:g}: > 2 mm per coordinate is not a pellet "
            f"track), got {noise_scale!r}"
        )
    if not isinstance(audio, bool):
        raise CassiError(f"audio must be True or False, got {audio!r}")
    if tasks is None:
        return DEFAULT_TASKS
    if isinstance(tasks, str):
        tasks = [t for t in tasks.split(",") if t.strip()]
    names = tuple(dict.fromkeys(get_task(t).name for t in tasks))
    if not names:
        raise CassiError("no tasks given")
    return names


# ---------------------------------------------------------------- the default corpus
DEFAULT_CORPUS_SEED = 0
_DEFAULT_CORPUS_ARGS = {"n_subjects": 15, "seed": DEFAULT_CORPUS_SEED}


def default_corpus_dir() -> Path:
    """Where the default corpus lives: ``$CASSI_SYNTH_DIR`` if set, else
    ``$XDG_CACHE_HOME/cassi_fit/synthetic-v<version>`` (``~/.cache`` by default)."""
    override = os.environ.get("CASSI_SYNTH_DIR")
    if override:
        return Path(override).expanduser()
    cache = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(cache).expanduser() / "cassi_fit" / f"synthetic-v{GENERATOR_VERSION}"


def corpus_status(folder: str | os.PathLike) -> str:
    """``"complete"`` (README.txt of this generator version ending in the completion line),
    ``"stale"`` (complete, another generator version), ``"incomplete"`` (a README without
    the completion line: generation was interrupted) or ``"absent"`` (no README.txt)."""
    readme = Path(folder) / "README.txt"
    if not readme.is_file():
        return "absent"
    text = readme.read_text(encoding="utf-8", errors="replace")
    if not text.rstrip("\n").endswith(COMPLETE_LINE):
        return "incomplete"
    current = f"generator_version: {GENERATOR_VERSION}\n" in text
    return "complete" if current else "stale"


def _is_complete(folder: Path) -> bool:
    return corpus_status(folder) == "complete"


def _check_corpus(root: Path) -> None:
    """Refuse to read ground truth from a corpus whose writing did not finish."""
    status = corpus_status(root)
    if status in ("absent", "incomplete"):
        raise MissingDataError(
            f"{root}: not a complete synthetic corpus (README.txt "
            f"{'missing' if status == 'absent' else 'lacks its last line'}: its generation "
            "was interrupted?); generate it again with `cassi synth --force`"
        )


def ensure_default_corpus() -> Path:
    """The default corpus (15 subjects, default tasks, seed 0), generated if absent.

    :func:`generate_corpus` writes into a temporary sibling folder and renames it into
    place, so a crash or a second process never leaves a half-written corpus behind; a
    folder that is there but not complete (interrupted, or of another generator version)
    is refused, not silently reused.
    """
    target = default_corpus_dir()
    if _is_complete(target):
        return target
    if target.exists() and any(target.iterdir()):
        raise OutputExistsError(
            f"{target}: exists but is not a complete synthetic corpus of this version "
            f"({corpus_status(target)}); remove it or point CASSI_SYNTH_DIR elsewhere"
        )
    try:
        generate_corpus(target, **_DEFAULT_CORPUS_ARGS, overwrite=False)
    except (OSError, OutputExistsError):
        if not _is_complete(target):  # another process may have finished it meanwhile
            raise
    return target
