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

GENERATOR_VERSION = 3  # bump when the generated numbers change (invalidates the cache)
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
# The toolkit's face model (model/model.json; checked by tests/test_synth.py): how far its
# MNI site sits ahead of its lower incisor tip along the jaw line MNM -> MNI, and its
# MNI-MNM distance (mm).
MODEL_TIP_TO_MNI_ALONG = 3.125
MODEL_JAW_PELLET_DISTANCE = 43.2897
MNI_BELOW_TIP_MM = 4.7  # MNI below the lower incisor tip, across the jaw line


# --------------------------------------------------------------------------- anatomy
@dataclass(frozen=True, eq=False)
class SubjectAnatomy:
    """One synthetic subject; positions in the pellet frame (mm), jaw closed (rest pose).

    Attributes beyond the obvious ones: ``pellets_rest`` ``(8, 2)`` all pellets at rest
    (jaw closed, tongue and lips neutral; rows 6-7 equal ``mni_rest``/``mnm_rest``);
    the condyle slides ``s = k1 deg + k2 deg^2`` mm (``condyle_slide_mm_per_deg`` = k1,
    ``condyle_slide_mm_per_deg2`` = k2; little in speech, 10-20 mm at wide opening) along
    ``eminence_angle_deg`` below the forward horizontal, so the rotation centre of the
    motion from rest moves back and down as the jaw opens; ``f0_hz`` the synthetic voice pitch.
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


def _head_measures(rng, gonion, gnathion, ul_thick, ll_thick, face_width):
    from .headmeasures import HeadMeasures

    um = functools.partial(round, ndigits=3)  # as Headmeasures.txt holds them
    return HeadMeasures(
        gonion_x=um(float(gonion[0])),
        gonion_y=um(float(gonion[1])),
        gnathion_x=um(float(gnathion[0])),
        gnathion_y=um(float(gnathion[1])),
        face_width=um(float(face_width)),
        jaw_width=um(float(rng.uniform(90.0, 110.0))),
        mouth_width=um(float(rng.uniform(45.0, 56.0))),
        upper_lip_thickness=um(float(ul_thick)),
        lower_lip_thickness=um(float(ll_thick)),
        nose_protrusion=um(float(rng.uniform(17.0, 24.0))),
    )


def make_subject(name: str, rng: np.random.Generator) -> SubjectAnatomy:
    """Draw one subject's anatomy (see the class for units and frames)."""
    r = rng.uniform
    tip = np.array([-r(2.5, 4.0), -r(0.5, 1.8)])  # lower incisor tip: 2.5-4 mm overjet
    spacing, slope = r(37.0, 44.5), np.deg2rad(r(4.0, 9.0))
    # MNI on the labial face below the tip: along the jaw line (MNM -> MNI) as far ahead
    # of the tip as on the toolkit's model scaled to this jaw (so that the lower lip's
    # thickness, measured along that line, is what the model can see), give or take
    # 0.25 mm; across it, MNI_BELOW_TIP_MM lower, give or take 0.5 mm
    forward = np.array([np.cos(slope), -np.sin(slope)])
    up = np.array([np.sin(slope), np.cos(slope)])
    along = spacing / MODEL_JAW_PELLET_DISTANCE * MODEL_TIP_TO_MNI_ALONG + r(-0.25, 0.25)
    mni = tip + along * forward - (MNI_BELOW_TIP_MM + r(-0.5, 0.5)) * up
    mnm = mni + spacing * np.array([-np.cos(slope), np.sin(slope)])
    condyle = tip + np.array([-r(90.0, 100.0), r(20.0, 30.0)])
    gnathion = tip + np.array([r(-1.0, 4.0), -r(38.0, 46.0)])
    gonion = condyle + np.array([r(2.0, 10.0), -r(50.0, 60.0)])
    ul_thick, ll_thick, face_width = r(12.0, 16.0), r(12.5, 16.5), r(125.0, 150.0)
    scale = r(0.95, 1.05)  # vocal tract size
    tongue = scale * np.array([[-16.5, 1.5], [-28.0, 8.0], [-39.5, 15.0], [-53.0, 17.0]])
    tongue = tongue + rng.normal(0.0, 0.8, size=(4, 2))
    palate = _palate_outline(rng)
    tongue[:, 1] = np.minimum(tongue[:, 1], _palate_height(palate, tongue[:, 0]) - 4.0)
    # Lip thickness as Headmeasures defines it: how far the lip pellet (on the vermilion)
    # sits ahead of the incisor tip, at rest (upper: from the origin; lower: from ``tip``).
    # (lower: along the mandible's forward direction, MNM -> MNI, so that it does not
    # change as the jaw turns)
    ul = np.array([ul_thick, r(16.5, 19.5)])
    forward = (mni - mnm) / np.linalg.norm(mni - mnm)
    ll_y = r(-18.0, -15.5)
    ll = np.array([tip[0] + (ll_thick - (ll_y - tip[1]) * forward[1]) / forward[0], ll_y])
    pellets = np.concatenate([ul[None], ll[None], tongue, mni[None], mnm[None]])
    head = _head_measures(rng, gonion, gnathion, ul_thick, ll_thick, face_width)
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
        condyle_slide_mm_per_deg=float(r(0.12, 0.28)),
        condyle_slide_mm_per_deg2=float(r(0.010, 0.018)),
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
    deg = np.rad2deg(theta_pad)
    slide = deg * anatomy.condyle_slide_mm_per_deg + deg**2 * anatomy.condyle_slide_mm_per_deg2
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
    times = np.arange(n) * 6866 / 1e6  # as read_txy gives them (us / 1e6)
    truth = _kinematics(anatomy, controls, times)
    measured = truth.pellets_true + _noise(noise_rng, n, noise_mm)
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
    controls: np.ndarray, times: np.ndarray, f0_hz: float, rng: np.random.Generator
) -> np.ndarray:
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


def load_truth(root, subject: str, task: str) -> JawTruth:
    """Read the ground truth of ``subject``'s ``task`` from a corpus folder ``root``.

    Reads ``root/<subject>/<task>.truth.csv`` (names case-insensitive). Raises
    MissingDataError when absent, DataFormatError when malformed.
    """
    from ._io import register_input

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


def load_anatomy(root, subject: str) -> SubjectAnatomy:
    """Read ``root/<subject>/anatomy.json`` written by :func:`generate_corpus`."""
    from ._io import register_input
    from .headmeasures import HeadMeasures

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


def _readme(n_subjects, seed, tasks, noise_scale, audio) -> str:
    lines = [
        "cassi_fit synthetic XRMB corpus (NOT real data)",
        "",
        "Made by cassi_fit.synth.generate_corpus / `cassi synth`; see docs/SYNTHETIC.md.",
        f"generator_version: {GENERATOR_VERSION}",
        f"seed: {seed}",
        f"subjects: {n_subjects} ({', '.join(subject_names(n_subjects))})",
        f"tasks: {', '.join(tasks)}",
        f"noise_scale: {noise_scale}",
        f"audio: {'yes' if audio else 'no'}",
        "",
        "Per subject folder: pellet files (.txy, real format), PAL.DAT, PHA.DAT, audio (.wav,",
        "16 kHz, speech tasks), <task>.truth.csv (per frame: true jaw angle, translation,",
        "pivot, condyle, noise-free pellets, dropout and mistrack flags) and anatomy.json.",
        "Headmeasures.txt holds every subject's head measures.",
    ]
    return "\n".join(lines) + "\n"


def generate_corpus(
    out_dir,
    *,
    n_subjects: int = 15,
    seed: int = 0,
    tasks=None,
    noise_scale: float = 1.0,
    audio: bool = True,
    overwrite: bool = False,
) -> Path:
    """Write a synthetic corpus to ``out_dir`` and return its path.

    ``tasks``: task names (default ``DEFAULT_TASKS``); ``noise_scale`` multiplies the
    default measurement noise (0 = noise-free, dropouts and mistracks stay); ``audio``
    writes a ``.wav`` for speech tasks. Refuses (OutputExistsError, before writing
    anything) if a file it would write exists, unless ``overwrite``. Deterministic: the
    same arguments give byte-identical files, and each recording depends only on
    (seed, subject, task).
    """
    from ._io import atomic_write
    from .headmeasures import write_headmeasures
    from .outlines import write_outline
    from .txy import write_txy

    out_dir = Path(out_dir)
    tasks = _check_arguments(n_subjects, tasks, noise_scale)
    names = subject_names(n_subjects)
    plan = _corpus_plan(out_dir, names, tasks, audio)
    top = {"readme": out_dir / "README.txt", "head": out_dir / "Headmeasures.txt"}
    if not overwrite:
        for path in [*top.values(), *(p for *_, files in plan for p in files.values())]:
            if path.exists():
                raise OutputExistsError(f"{path}: file exists (pass overwrite=True / --force)")
    anatomies = {}
    for i, name, task, files in plan:
        if task is None:
            anatomy = make_subject(name, np.random.default_rng([int(seed), 1, i]))
            anatomies[name] = anatomy
            write_outline(files["pal"], anatomy.palate, overwrite=overwrite)
            write_outline(files["pha"], anatomy.pharynx, overwrite=overwrite)
            atomic_write(files["anatomy"], _anatomy_json(anatomy), overwrite=overwrite)
            continue
        anatomy = anatomies[name]
        rec_seed = _recording_seed(seed, i, task)
        track, truth, controls = _simulate(
            anatomy, task, rec_seed, noise_scale * DEFAULT_NOISE_MM, None, True, True
        )
        write_txy(files["txy"], track, overwrite=overwrite)
        comment = f"cassi_fit synthetic ground truth; subject {name}; task {task}; seed {seed}"
        atomic_write(files["truth"], _truth_text(truth, comment), overwrite=overwrite)
        if "wav" in files:
            rng = np.random.default_rng([*rec_seed, 3])
            samples = synth_audio(controls, truth.times, anatomy.f0_hz, rng)
            _write_wav(files["wav"], samples, overwrite=overwrite)
    heads = {name: a.head for name, a in anatomies.items()}
    write_headmeasures(top["head"], heads, overwrite=overwrite)
    atomic_write(
        top["readme"], _readme(n_subjects, seed, tasks, noise_scale, audio), overwrite=overwrite
    )
    return out_dir


def _check_arguments(n_subjects, tasks, noise_scale) -> tuple[str, ...]:
    """Validate :func:`generate_corpus`'s arguments; returns the task names (lower case)."""
    if not isinstance(n_subjects, (int, np.integer)) or not 1 <= n_subjects <= 99:
        raise CassiError(f"n_subjects must be an integer from 1 to 99, got {n_subjects!r}")
    if not (np.isfinite(noise_scale) and noise_scale >= 0):
        raise CassiError(f"noise_scale must be a finite number >= 0, got {noise_scale!r}")
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


def _is_complete(folder: Path) -> bool:
    readme = folder / "README.txt"
    return readme.is_file() and f"generator_version: {GENERATOR_VERSION}" in readme.read_text(
        encoding="utf-8", errors="replace"
    )


def ensure_default_corpus() -> Path:
    """The default corpus (15 subjects, default tasks, seed 0), generated if absent.

    Generated into a temporary sibling folder and renamed into place, so a crash or a
    second process never leaves a half-written corpus behind. The README written last
    marks a complete corpus.
    """
    import shutil
    import tempfile

    target = default_corpus_dir()
    if _is_complete(target):
        return target
    if target.exists() and any(target.iterdir()):
        raise OutputExistsError(
            f"{target}: exists but is not a complete synthetic corpus of this version; "
            "remove it or point CASSI_SYNTH_DIR elsewhere"
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        generate_corpus(tmp, **_DEFAULT_CORPUS_ARGS, overwrite=True)
        if target.exists():
            target.rmdir()  # empty (checked above); fails if another process filled it
        os.replace(tmp, target)
    except OSError:
        if not _is_complete(target):
            raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return target
