"""Stage 1 of the synthetic corpus, anatomy: a subject's palate, jaw pellets, condyle,
lips, tongue rest and head measures (pellet frame, mm), drawn from anthropometric norms
(:data:`NORMS`), never from the face model's numbers. Also the vocabulary of the jaw
kinematics families, since a subject carries its family."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

PELLETS = ("UL", "LL", "T1", "T2", "T3", "T4", "MNI", "MNM")  # = cassi_fit.txy.PELLET_NAMES
_UL, _LL, _T1, _T2, _T3, _T4, _MNI, _MNM = range(8)
_TONGUE = slice(_T1, _T4 + 1)

#: How the mandible moves (docs/SYNTHETIC.md, "Jaw kinematics", with sources):
#: ``fixed-condyle`` pure rotation about a fixed condyle (Parke's assumption);
#: ``physiological`` the condyle glides down and forward along a curved articular-eminence
#: path, by an amount coupled to the rotation (little at speech angles, 10-20 mm at wide
#: opening); ``thrust`` rotation about the condyle plus an independent, piecewise
#: constant protrusion (jumps within one frame): a translation no smooth prior expects;
#: ``speech`` the glide along the eminence is linear in the rotation from the first degree
#: (``speech_slide_mm_per_deg``) plus a smooth protrusion of its own at the pace of
#: syllables (``speech_protrusion_sd_mm``): rotation and translation correlated but
#: separately controlled, as measured in speech (docs/SYNTHETIC.md, "Speech-like jaw").
JAW_KINEMATICS = ("fixed-condyle", "physiological", "thrust", "speech")
#: The default corpus's families, cycled over subjects S01, S02, S03, S04, ...
DEFAULT_JAW_KINEMATICS_CYCLE = ("physiological", "fixed-condyle", "thrust")


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
    from ..options import check_choice

    return check_choice(what, value, choices)




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
    ``thrust_max_mm``); for ``speech`` the condyle glides ``speech_slide_mm_per_deg`` mm
    per degree of opening plus a smooth protrusion of SD ``speech_protrusion_sd_mm``.
    ``jaw_yaw_per_deg`` (degrees of yaw per degree of opening, signed) and
    ``mnm_lateral_mm`` (the molar pellet's distance from the midsagittal plane) give the
    out-of-plane error of the ``xrmb`` noise family. ``f0_hz`` the synthetic voice pitch.
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
    speech_slide_mm_per_deg: float = 0.55
    speech_protrusion_sd_mm: float = 0.7
    jaw_yaw_per_deg: float = 0.2
    mnm_lateral_mm: float = 21.0

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
    "gonial_angle_deg": (130.0, 7.0),  # at the gonion, ramus to mandibular body (Jarabak)
}


def _head_measures(rng, gonion, gnathion, ul_thick, ll_thick):
    from ..headmeasures import HeadMeasures

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


def _quantile_drawn(u: float, mean: float, sd: float) -> float:
    """:func:`_drawn` from one uniform ``u`` in (0, 1) (the normal quantile, cut at +-2.5
    sd): one uniform draw, so the draws after it stay as they were."""
    from scipy.special import ndtri

    return float(mean + sd * np.clip(ndtri(np.clip(u, 1e-12, 1.0 - 1e-12)), -2.5, 2.5))


def _gonion(condyle: np.ndarray, gnathion: np.ndarray, ramus: float,
            angle_deg: float) -> np.ndarray:
    """The gonion ``ramus`` mm from the condyle, where the ramus (gonion to condyle) and
    the mandibular body (gonion to gnathion) meet at ``angle_deg`` (the gonial angle),
    on the lower side of the condyle-gnathion line.

    The triangle condyle-gonion-gnathion has two sides and the angle between them fixed,
    its third side ``d`` by the condyle and gnathion: the body is ``b = r cos a +
    sqrt(d^2 - r^2 sin^2 a)`` (law of cosines) and the ramus leaves the condyle at the
    angle ``g`` below the line to the gnathion, ``cos g = (r^2 + d^2 - b^2) / (2 r d)``.
    """
    a = np.deg2rad(angle_deg)
    to_gn = gnathion - condyle
    d = float(np.linalg.norm(to_gn))
    body = ramus * np.cos(a) + np.sqrt(d * d - (ramus * np.sin(a)) ** 2)
    g = np.arccos((ramus**2 + d * d - body**2) / (2.0 * ramus * d))
    heading = np.arctan2(to_gn[1], to_gn[0]) - g  # clockwise: below the line
    return condyle + ramus * np.array([np.cos(heading), np.sin(heading)])


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
    # the gonion from the gonial angle and the ramus height (condyle to gonion), so that
    # the jaw has adult proportions (docs/SYNTHETIC.md, "Anatomy"); one uniform draw each,
    # in the two draws' place that set the gonion straight below the condyle until v5
    angle = _quantile_drawn(r(0.0, 1.0), *NORMS["gonial_angle_deg"])
    gonion = _gonion(condyle, gnathion, r(50.0, 60.0), angle)
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
        # drawn last, so every draw above is as in generator version 4
        speech_slide_mm_per_deg=float(r(0.6, 1.2)),
        speech_protrusion_sd_mm=float(r(0.4, 1.0)),
        jaw_yaw_per_deg=float(rng.choice([-1.0, 1.0]) * r(0.15, 0.35)),
        mnm_lateral_mm=float(r(18.0, 24.0)),
    )


def _palate_height(palate: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Palate y (mm) above each x (mm); held at its end values beyond the outline."""
    return np.interp(x, palate[::-1, 0], palate[::-1, 1])


