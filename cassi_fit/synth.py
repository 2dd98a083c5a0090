"""A synthetic XRMB corpus with ground truth: subjects, kinematics, measurement, files.

The real X-ray microbeam database is distributed on request only; this module makes a
stand-in whose truth is known. Four stages, each a plain function:

1. anatomy (:func:`make_subject`): a subject's palate, jaw pellet spacing, condyle, lips,
   tongue rest positions, head measures, all in the pellet frame (mm);
2. kinematics (:func:`_kinematics`): the task's control curves (:mod:`cassi_fit.synth_tasks`)
   move a rigid mandible (rotation ``theta`` about the condyle plus a slide of the condyle
   forward and down along the articular eminence, so that the rotation centre moves: the
   motion is composed with :mod:`cassi_fit.rigid`, paper convention ``p' = R p + t``,
   Eqs 4-5), the lower lip and tongue partly carried by it and partly on their own, the
   tongue kept below the palate;
3. measurement (:func:`_measure`): white plus slowly drifting noise per pellet, all-untracked
   leading rows, dropouts (1000000) and a few unmarked mistracks, all recorded in the truth;
4. files (:func:`generate_corpus`): the real formats through the toolkit's writers, plus a
   ground-truth sidecar per recording and an ``anatomy.json`` per subject.

Everything is deterministic from the seed. See ``docs/SYNTHETIC.md``.
"""

from __future__ import annotations

import functools
import json
import os
import zlib
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

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
    "default_corpus_dir",
    "ensure_default_corpus",
]

GENERATOR_VERSION = 1  # bump when the generated numbers change (invalidates the cache)
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


# --------------------------------------------------------------------------- anatomy
@dataclass(frozen=True, eq=False)
class SubjectAnatomy:
    """One synthetic subject; positions in the pellet frame (mm), jaw closed (rest pose).

    Attributes beyond the obvious ones: ``pellets_rest`` ``(8, 2)`` all pellets at rest
    (jaw closed, tongue and lips neutral; rows 6-7 equal ``mni_rest``/``mnm_rest``);
    ``condyle_slide_mm_per_deg`` how far the condyle slides per degree of opening, along
    ``eminence_angle_deg`` below the forward horizontal; ``f0_hz`` the synthetic voice pitch.
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
    eminence_angle_deg: float
    f0_hz: float

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
    return np.stack([x, y], axis=1)


def _head_measures(rng, gonion, gnathion, ul_thick, ll_thick, face_width):
    from .headmeasures import HeadMeasures

    return HeadMeasures(
        gonion_x=float(gonion[0]),
        gonion_y=float(gonion[1]),
        gnathion_x=float(gnathion[0]),
        gnathion_y=float(gnathion[1]),
        face_width=float(face_width),
        jaw_width=float(rng.uniform(90.0, 110.0)),
        mouth_width=float(rng.uniform(45.0, 56.0)),
        upper_lip_thickness=float(ul_thick),
        lower_lip_thickness=float(ll_thick),
        nose_protrusion=float(rng.uniform(17.0, 24.0)),
    )


def make_subject(name: str, rng: np.random.Generator) -> SubjectAnatomy:
    """Draw one subject's anatomy (see the class for units and frames)."""
    r = rng.uniform
    tip = np.array([-r(0.8, 2.2), -r(0.5, 1.8)])  # lower incisor tip, behind/below origin
    mni = tip + np.array([r(0.6, 1.6), -r(1.8, 2.8)])  # on the labial face, below the tip
    spacing, slope = r(37.0, 44.5), np.deg2rad(r(1.0, 6.0))
    mnm = mni + spacing * np.array([-np.cos(slope), np.sin(slope)])
    condyle = tip + np.array([-r(90.0, 100.0), r(20.0, 30.0)])
    gnathion = tip + np.array([r(-1.0, 4.0), -r(38.0, 46.0)])
    gonion = condyle + np.array([r(2.0, 10.0), -r(50.0, 60.0)])
    ul_thick, ll_thick, face_width = r(11.0, 15.0), r(12.0, 16.0), r(125.0, 150.0)
    scale = r(0.95, 1.05)  # vocal tract size
    tongue = scale * np.array([[-16.5, 1.5], [-28.0, 8.0], [-39.5, 15.0], [-53.0, 17.0]])
    tongue = tongue + rng.normal(0.0, 0.8, size=(4, 2))
    palate = _palate_outline(rng)
    tongue[:, 1] = np.minimum(tongue[:, 1], _palate_height(palate, tongue[:, 0]) - 4.0)
    ul = np.array([ul_thick + r(0.5, 2.0), r(16.5, 19.5)])
    ll = np.array([ll_thick - r(2.0, 4.0), r(-18.0, -15.5)])
    pellets = np.concatenate([ul[None], ll[None], tongue, mni[None], mnm[None]])
    return SubjectAnatomy(
        name=str(name),
        palate=palate,
        pharynx=np.array([[-r(70.0, 78.0), r(15.0, 22.0)], [-r(66.0, 74.0), -r(25.0, 35.0)]]),
        head=_head_measures(rng, gonion, gnathion, ul_thick, ll_thick, face_width),
        mni_rest=mni,
        mnm_rest=mnm,
        lower_incisor_tip_rest=tip,
        chin_rest=gnathion,
        condyle_rest=condyle,
        upper_lip_thickness=float(ul_thick),
        lower_lip_thickness=float(ll_thick),
        face_width=float(face_width),
        pellets_rest=pellets,
        condyle_slide_mm_per_deg=float(r(0.35, 0.55)),
        eminence_angle_deg=float(r(25.0, 40.0)),
        f0_hz=float(r(100.0, 220.0)),
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


def _jaw_pose(theta, slide, condyle_rest, eminence, jaw_points):
    """One frame: rotate by ``theta`` (rad) about the rest condyle, then slide it.

    ``slide`` mm along the unit vector ``eminence``; ``jaw_points`` ``(k, 2)`` mm at rest.
    Returns ``(translation (2,), pivot (2,), pivot defined, moved points (k, 2))``.
    """
    from . import rigid

    rotation = rigid.from_pivot(theta, condyle_rest)
    motion = rigid.compose((0.0 * theta, slide * eminence), rotation)
    pivot, defined = rigid.pivot(motion)
    return motion[1], pivot, defined, rigid.apply(*motion, jaw_points)


@functools.cache
def _jaw_poses_compiled():
    import jax

    return jax.jit(jax.vmap(_jaw_pose, in_axes=(0, 0, None, None, None)))


def _jaw_motion(anatomy: SubjectAnatomy, theta: np.ndarray, points: np.ndarray):
    """Vectorised :func:`_jaw_pose` in float64; frames padded to a multiple of 1024 so the
    compiled function is reused across recordings."""
    import jax

    n = theta.shape[0]
    n_pad = -(-n // 1024) * 1024
    theta_pad = np.zeros(n_pad)
    theta_pad[:n] = theta
    slide = np.rad2deg(theta_pad) * anatomy.condyle_slide_mm_per_deg
    angle = np.deg2rad(anatomy.eminence_angle_deg)
    eminence = np.array([np.cos(angle), -np.sin(angle)])
    with jax.enable_x64(True):
        out = _jaw_poses_compiled()(theta_pad, slide, anatomy.condyle_rest, eminence, points)
        out = [np.asarray(a, dtype=np.float64 if a.dtype != bool else bool)[:n] for a in out]
    return out


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


def _kinematics(anatomy: SubjectAnatomy, controls: np.ndarray, times: np.ndarray) -> JawTruth:
    """Noise-free truth of one trial from its ``(n, len(CONTROLS))`` control curves."""
    c = {name: controls[:, i] for i, name in enumerate(CONTROLS)}
    theta = np.deg2rad(np.maximum(c["jaw_deg"], 0.0))
    rest = anatomy.pellets_rest
    # Points carried by the mandible: LL, T1..T4 (their rest), MNI, MNM, the condyle.
    carried = np.concatenate([rest[_LL:], anatomy.condyle_rest[None]])
    translation, pivot, defined, moved = _jaw_motion(anatomy, theta, carried)
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
def _noise(rng: np.random.Generator, n: int, noise_mm: float) -> np.ndarray:
    """``(n, 8, 2)`` mm: white plus slowly drifting noise, each of variance noise_mm^2 / 2."""
    from scipy.ndimage import gaussian_filter1d

    white = rng.normal(size=(n, 8, 2))
    drift = gaussian_filter1d(rng.normal(size=(n, 8, 2)), _DRIFT_S / FRAME_STEP_S, axis=0)
    # The filtered unit white noise has SD 1/sqrt(2 sqrt(pi) sigma); restore unit SD.
    drift *= np.sqrt(2.0 * np.sqrt(np.pi) * _DRIFT_S / FRAME_STEP_S)
    return noise_mm / np.sqrt(2.0) * (white + drift)


def _dropouts(rng: np.random.Generator, n: int, n_lead: int) -> np.ndarray:
    """``(n, 8, 2)`` bool: all-untracked leading rows plus occasional runs of dropouts.

    The back tongue pellets drop out most often; x and y go together nine times in ten.
    """
    dropped = np.zeros((n, 8, 2), bool)
    dropped[:n_lead] = True
    weights = np.array([1.0, 1.0, 1.0, 1.0, 2.0, 3.0, 0.7, 1.5])
    for _ in range(rng.poisson(1.5 * n * FRAME_STEP_S / 4.0)):
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
    seed,
    noise_mm: float = DEFAULT_NOISE_MM,
    duration_s: float | None = None,
    dropouts: bool = True,
    mistracks: bool = True,
):
    """One synthetic recording in memory: ``(PelletTrack, JawTruth)``.

    ``seed`` is anything ``numpy.random.SeedSequence`` accepts. ``noise_mm`` is each
    coordinate's noise SD (mm; the default gives the jaw inter-pellet distance an SD of
    0.3 mm). ``duration_s`` overrides the task's natural length (s, leading rows
    included). Positions are rounded to 1 um as in the files, so writing and reading the
    track gives it back exactly. The track holds 4-10 leading all-untracked rows from
    time 0 and, unless switched off, dropouts and 1-3 unmarked mistracks (see the truth's
    ``dropped`` and ``mistracked``).
    """
    return _simulate(anatomy, task, seed, noise_mm, duration_s, dropouts, mistracks)[:2]


def _simulate(anatomy, task, seed, noise_mm, duration_s, dropouts, mistracks):
    """``(track, truth, controls)``; see :func:`synth_recording`."""
    from .txy import PelletTrack

    spec = get_task(task)
    if not (np.isfinite(noise_mm) and noise_mm >= 0):
        raise CassiError(f"noise_mm must be a finite number >= 0, got {noise_mm!r}")
    task_rng, noise_rng, drop_rng, jump_rng, lead_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(5)
    )
    n_lead = int(lead_rng.integers(4, 11))
    natural_s, keyframes = task_duration(spec, task_rng)
    total_s = duration_s if duration_s is not None else natural_s + n_lead * FRAME_STEP_S
    n = int(round(total_s / FRAME_STEP_S))
    if n < n_lead + 10:
        raise CassiError(f"duration_s={duration_s!r} is too short for a recording")
    controls = control_trajectories(spec, keyframes, n - n_lead, FRAME_STEP_S, task_rng)
    controls = np.concatenate([np.repeat(controls[:1], n_lead, axis=0), controls])
    times = np.arange(n) * FRAME_STEP_S
    truth = _kinematics(anatomy, controls, times)
    measured = truth.pellets_true + _noise(noise_rng, n, noise_mm)
    dropped = _dropouts(drop_rng, n, n_lead) if dropouts else np.zeros((n, 8, 2), bool)
    dropped[:n_lead] = True
    jumps, flags = _mistracks(jump_rng, n, n_lead) if mistracks else (0.0, np.zeros((n, 8), bool))
    measured = np.round((measured + jumps) * 1e3) / 1e3
    flags &= ~dropped.all(axis=2)
    truth = _replace(truth, dropped=dropped, mistracked=flags)
    track = PelletTrack(times=np.round(times * 1e6) / 1e6, positions=measured, valid=~dropped)
    return track, truth, controls


def _replace(truth: JawTruth, **changes) -> JawTruth:
    values = {f.name: getattr(truth, f.name) for f in fields(JawTruth)}
    return JawTruth(**{**values, **changes})
