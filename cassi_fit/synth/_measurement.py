"""Stage 3 of the synthetic corpus, measurement: noise of one of :data:`NOISE_FAMILIES`
per pellet, all-untracked leading rows, dropouts (1000000) and a few unmarked mistracks,
all recorded in the truth; :func:`synth_recording` runs stages 2 and 3 for one trial."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import fields

import numpy as np

from ..errors import CassiError
from ..txy import FRAME_STEP_US, PelletTrack
from ._anatomy import _MNM, SubjectAnatomy, _check_family
from ._kinematics import (
    FRAME_STEP_S,
    JawTruth,
    _kinematics,
    speech_protrusion_mm,
    thrust_protrusion_mm,
)
from ._tasks import control_trajectories, get_task, task_duration, task_labels

# Each coordinate's noise SD (mm), white and drift contributing equal variance; the jaw
# inter-pellet distance then has SD sqrt(2) * 0.212 = 0.3 mm, as in real files.
DEFAULT_NOISE_MM = 0.3 / np.sqrt(2.0)
_DRIFT_S = 0.4  # time scale of the drifting noise component, s
_BAND_S = 0.03  # the xrmb family's band limit: a Gaussian of 30 ms (half power near 6 Hz)
#: The xrmb family's noise per coordinate at noise scale 1, mm: the jaw pellet distance
#: then varies by 0.2 mm SD from noise alone (JW11 task 5: 0.17 mm once the part that
#: follows the jaw opening is taken out; one speaker; docs/SYNTHETIC.md).
XRMB_NOISE_MM = 0.14
#: Measurement noise per coordinate: ``realistic`` white plus drift of equal variance (the
#: default: the jaw pellet distance then varies by 0.3 mm SD as in real files); ``white``;
#: ``drift`` (white noise low-pass filtered over ``_DRIFT_S``, rescaled to the same SD);
#: ``xrmb`` what a real XRMB file shows (docs/SYNTHETIC.md, "Measurement like XRMB"):
#: band-limited noise (no power above about 15 Hz) plus drift, of SD ``XRMB_NOISE_MM``
#: at noise scale 1, and the projection of the jaw's out-of-plane yaw on the molar pellet.
NOISE_FAMILIES = ("realistic", "white", "drift", "xrmb")
MAX_NOISE_SCALE = 10.0  # noise_scale above this (> 2 mm per coordinate) is refused


def _noise(rng: np.random.Generator, n: int, noise_mm: float, family: str) -> np.ndarray:
    """``(n, 8, 2)`` mm of measurement noise, each coordinate of SD ``noise_mm``.

    ``family`` (:data:`NOISE_FAMILIES`): ``white`` independent per frame; ``drift`` white
    noise smoothed by a Gaussian of ``_DRIFT_S`` (a slow wander, rescaled to unit SD);
    ``realistic`` the two added with equal variance; ``xrmb`` the white noise smoothed by
    a Gaussian of ``_BAND_S`` instead, plus the drift, of SD ``noise_mm * XRMB_NOISE_MM /
    DEFAULT_NOISE_MM``. The same rng draws the same numbers for every family, so families
    differ only in how the numbers are combined.
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
    if family == "xrmb":
        band = gaussian_filter1d(white, _BAND_S / FRAME_STEP_S, axis=0)
        band *= np.sqrt(2.0 * np.sqrt(np.pi) * _BAND_S / FRAME_STEP_S)
        return noise_mm * XRMB_NOISE_MM / DEFAULT_NOISE_MM / np.sqrt(2.0) * (band + drift)
    return noise_mm / np.sqrt(2.0) * (white + drift)


def _out_of_plane(anatomy: SubjectAnatomy, theta: np.ndarray, scale: float) -> np.ndarray:
    """``(n, 8, 2)`` mm: what the jaw's yaw adds to the pellets seen in projection.

    The jaw yaws with the opening (``jaw_yaw_per_deg`` degrees per degree, a few degrees at
    most in speech); MNI sits on the midsagittal plane and does not move with it, MNM
    ``mnm_lateral_mm`` beside it moves forward or back by ``lateral * sin(yaw)``. The
    sagittal truth (a rigid motion) does not hold this: to a 2D method it is an error that
    follows the jaw, as the real MNI-MNM distance does. ``scale`` (noise_mm over the
    default) scales it with the noise, so noise scale 0 gives ideal data.
    """
    out = np.zeros((theta.shape[0], 8, 2))
    yaw = np.deg2rad(anatomy.jaw_yaw_per_deg * np.rad2deg(theta))
    out[:, _MNM, 0] = scale * anatomy.mnm_lateral_mm * np.sin(yaw)
    return out


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
    """``(track, truth, controls, labels)``; see :func:`synth_recording`. ``labels``: a
    speech task's phone and word tiers (``_tasks.task_labels``, cut at the recording's
    end), ``()`` for the others."""
    spec = get_task(task)
    if not (np.isfinite(noise_mm) and 0 <= noise_mm <= MAX_NOISE_SCALE * DEFAULT_NOISE_MM):
        raise CassiError(
            f"noise_mm must be a number from 0 to {MAX_NOISE_SCALE * DEFAULT_NOISE_MM:.3g} mm,"
            f" got {noise_mm!r}"
        )
    _check_family(noise_family, NOISE_FAMILIES, "noise family")
    # A sixth stream for the thrust and speech families: spawned children do not depend on
    # how many are spawned, so the other five streams are those of generator version 3.
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
    times = np.arange(n) * FRAME_STEP_US / 1e6  # as read_txy gives them (us / 1e6)
    if anatomy.jaw_kinematics == "speech":
        protrusion = speech_protrusion_mm(anatomy, n, n_lead, thrust_rng)
    else:
        protrusion = thrust_protrusion_mm(anatomy, n, n_lead, thrust_rng)
    truth = _kinematics(anatomy, controls, times, protrusion)
    measured = truth.pellets_true + _noise(noise_rng, n, noise_mm, noise_family)
    if noise_family == "xrmb":
        measured += _out_of_plane(anatomy, truth.theta, noise_mm / DEFAULT_NOISE_MM)
    dropped = _dropouts(drop_rng, n, n_lead) if dropouts else np.zeros((n, 8, 2), bool)
    dropped[:n_lead] = True
    jumps, flags = _mistracks(jump_rng, n, n_lead) if mistracks else (0.0, np.zeros((n, 8), bool))
    measured = np.round((measured + jumps) * 1e3) / 1e3
    flags &= ~dropped.all(axis=2)
    truth = _replace(truth, dropped=dropped, mistracked=flags)
    track = PelletTrack(times=times, positions=measured, valid=~dropped)
    return track, truth, controls, _cut(task_labels(spec, keyframes, times[n_lead]), times[-1])


def _cut(tiers, end_s: float) -> tuple:
    """The tiers without what starts after ``end_s``, their last interval ending there."""
    from ..labels import Labels

    out = []
    for tier in tiers:
        keep = tier.starts < end_s
        if keep.any():
            out.append(Labels(tier.starts[keep], np.minimum(tier.ends[keep], end_s),
                              tuple(np.asarray(tier.labels, object)[keep]), tier=tier.tier))
    return tuple(out)


def _replace(truth: JawTruth, **changes) -> JawTruth:
    values = {f.name: getattr(truth, f.name) for f in fields(JawTruth)}
    return JawTruth(**{**values, **changes})
