"""Synthetic articulograph recordings that look like the labs' files, with the truth.

Real lab recordings often have no upper-incisor sensor and no bite plane, channels
exported as numbers, a device (or lab-normalised) frame whose midline is not at zero,
parasagittal sensors, a loose reference and dropouts. :func:`lab_like_speaker` makes one
speaker's session of such files in memory; :func:`write_lab_like_corpus` writes them
(``cassi synth --format ag501|wave|mview --lab-like``) with the truth beside each file.

The articulation is the synthetic XRMB corpus's (:mod:`cassi_fit.synth`: a rigid mandible,
lips, tongue). What the frame estimator (:mod:`cassi_fit.ema.placement`) relies on is
drawn here again from **this module's own distributions**, never the estimator's norms
nor the synthetic corpus's, so that a score is not the estimator meeting its own
assumptions:

* the lower incisor's tip at the closed jaw, relative to the upper tip (the origin): 1-5
  mm behind, from 2.5 mm below to 1.5 mm above (uniform; the whole mandible, with the
  lower lip and tongue, is shifted to put it there);
* the jaw sensor on the lower incisor's labial face: half the speakers at the incisal edge
  (0.5-4.5 mm below it), half at the gum (7.5-12 mm), 1-3.5 mm labial, on a crown tilted
  2-30 degrees forward; moved with the mandible's exact motion;
* a second jaw sensor on a lower molar for 40 % of speakers, 32-47 mm behind the lower
  tip, 0-10 mm below the occlusal level, 15-25 mm to one side (on the molar's cheek side);
* the upper-lip sensor 8-19 mm ahead of the upper tip and 3-20 mm above it;
* the recording frame: for a *head-normalised* file (half the speakers) the lab's axes
  (x forward, z up) tilted -20 to +20 degrees from the occlusal plane, the midline 15-45
  mm off the file's zero, no head movement; else a random rotation with head movement
  and three skull references (nasion, mastoids; one of them *loose* for 30 % of speakers:
  skin drift and noise).

Every file: its sound (the synthetic corpus's buzz that follows the articulators: inside
an mview file as its ``AUDIO`` entry, beside the others as ``<task>.wav``); an mview file
of a speech task also carries its ``PHONES`` and ``WORDS`` (the task's phone string on the
schedule of its articulatory targets, ``synth._tasks.task_labels``; the other formats
carry none, as their devices export none), shuffled channels named by number (``Ch1``...
/ ``S1``...), one or two unused channels (never tracked), a lip-corner and a lateral tongue sensor (parasagittal), per-
sensor offsets of up to 2 mm from the midline, extra dropouts. The truth
(``placement.json`` beside the files): the origin (the upper incisor's tip) and the
occlusal plane's forward and up directions in each file's coordinates (at rest, for files
with head movement: with the references' toolkit positions to place them), and each
channel's role.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CassiError, OutputExistsError
from ._raw import RawEma
from .synthetic import _PHYSICAL, _head_motion, _resample, _rotvec_matrix, _write
from .synthetic import FORMATS as _EMA_FORMATS

#: Formats :func:`write_lab_like_corpus` writes.
FORMATS = ("ag501", "wave", "mview")
ROLES = ("UL", "LL", "T1", "T2", "T3", "T4", "MNI", "MNM")
_TASKS = ("tp011", "tp101")
REFERENCES = {"NAS": (9.0, 68.0, 0.0), "LMA": (-118.0, 8.0, 55.0),
              "RMA": (-118.0, 8.0, -55.0)}  # nasion; mastoid processes, behind the condyles
_PREFIX = {"ag501": "Ch", "wave": "S", "mview": "S"}


@dataclass(frozen=True, eq=False)
class LabLike:
    """One lab-like recording: ``raw`` (numbered channels, the file's frame) and
    ``truth`` (JSON-ready: module docstring)."""

    raw: RawEma
    truth: dict
    audio: np.ndarray | None = None  # int16 samples at synth.AUDIO_RATE_HZ, time 0 = the file's
    labels: tuple = ()  # a speech task's phones and words tiers (labels.Labels), file time


def _rot2(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)  # cassi_fit.rigid's


def _speaker_draws(rng: np.random.Generator) -> dict:
    edge = rng.random() < 0.5
    return {
        "lower_tip": np.array([-rng.uniform(1.0, 5.0), rng.uniform(-2.5, 1.5)]),
        "jaw_depth": rng.uniform(0.5, 4.5) if edge else rng.uniform(7.5, 12.0),
        "jaw_glued": "edge" if edge else "gum",
        "jaw_labial": rng.uniform(1.0, 3.5),
        "crown_tilt_deg": rng.uniform(2.0, 30.0),
        "molar": rng.random() < 0.4,
        "molar_at": np.array([-rng.uniform(32.0, 47.0), -rng.uniform(0.0, 10.0)]),
        "ul": np.array([rng.uniform(8.0, 19.0), rng.uniform(3.0, 20.0)]),
        "normalised": rng.random() < 0.5,
        "pitch_deg": rng.uniform(-20.0, 20.0),
        "midline_mm": rng.choice([-1.0, 1.0]) * rng.uniform(15.0, 45.0),
        "loose": int(rng.integers(0, 3)) if rng.random() < 0.3 else None,
        "unused": int(rng.integers(1, 3)),
        "lateral": np.concatenate([rng.uniform(-2.0, 2.0, 7),
                                   [rng.choice([-1.0, 1.0]) * rng.uniform(15.0, 25.0)]]),
        "corner": rng.uniform(22.0, 28.0) * rng.choice([-1.0, 1.0]),
        "corner_back": rng.uniform(8.0, 14.0),
        "tongue_side": rng.uniform(10.0, 16.0) * rng.choice([-1.0, 1.0]),
    }


def _frame(rng: np.random.Generator, d: dict) -> tuple[np.ndarray, np.ndarray]:
    """``(M, origin)``: file = ``M @ p_toolkit + origin`` at rest (M proper after the
    toolkit's left-handed z flip)."""
    if d["normalised"]:  # x forward, z up; the lab's tilt, a little yaw and roll
        base = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # x, y(left->-)...
        turn = (_rotvec_matrix(np.array([[0.0, 0.0, np.deg2rad(rng.uniform(-3, 3))]]))[0]
                @ _rotvec_matrix(np.array([[0.0, np.deg2rad(d["pitch_deg"]), 0.0]]))[0]
                @ _rotvec_matrix(np.array([[np.deg2rad(rng.uniform(-3, 3)), 0.0, 0.0]]))[0])
        m = turn @ base @ _PHYSICAL
        origin = np.array([rng.uniform(-90.0, -40.0), d["midline_mm"], rng.uniform(-60.0, -20.0)])
        return m, origin
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    return rot @ _PHYSICAL, rng.uniform(-150.0, 150.0, 3)


def _articulators(anatomy, track, truth, d: dict) -> dict[str, np.ndarray]:
    """Each midline sensor's measured 2D positions (toolkit frame), jaw re-placed."""
    pos = np.asarray(track.positions, float)
    shift = d["lower_tip"] - anatomy.lower_incisor_tip_rest
    rot = _rot2(truth.theta)
    tilt = np.deg2rad(d["crown_tilt_deg"])
    down = np.array([-np.sin(tilt), -np.cos(tilt)])
    labial = np.array([np.cos(tilt), -np.sin(tilt)])
    out = {r: pos[:, ROLES.index(r)] + shift for r in ("LL", "T1", "T2", "T3", "T4")}

    def on_mandible(rest, carrier):
        moved = np.einsum("nij,j->ni", rot, rest - shift) + truth.translation + shift
        noise = np.random.default_rng(abs(hash(tuple(np.round(rest, 3)))) % 2**32).normal(
            0.0, 0.15, moved.shape)
        return np.where(np.isfinite(pos[:, carrier]), moved + noise, np.nan)

    mni = d["lower_tip"] + d["jaw_depth"] * down + d["jaw_labial"] * labial
    out["MNI"] = on_mandible(mni, ROLES.index("MNI"))
    if d["molar"]:
        out["MNM"] = on_mandible(d["lower_tip"] + d["molar_at"], ROLES.index("MNM"))
    out["UL"] = pos[:, 0] - anatomy.pellets_rest[0] + d["ul"]
    return out


def _layout(arts: dict, d: dict, rng) -> tuple[list[str], np.ndarray]:
    """Sensor roles and toolkit-frame 3D positions ``(n, k, 3)``."""
    n = arts["UL"].shape[0]
    names, cols = [], []
    for j, role in enumerate(ROLES):
        if role in arts:
            names.append(role)
            cols.append(np.concatenate([arts[role], np.full((n, 1), d["lateral"][j])], 1))
    lips = 0.5 * (arts["UL"] + arts["LL"])
    names.append("corner")  # spreads and rounds on its own: slow motion along x, noise
    spread = np.sin(np.linspace(0.0, rng.uniform(3.0, 12.0), n) + rng.uniform(0, 6.3))
    corner = lips + [-d["corner_back"], 0.0] + np.outer(spread, [rng.uniform(1.0, 3.0), 0.0])
    cols.append(np.concatenate([corner + rng.normal(0.0, 0.2, (n, 2)),
                                np.full((n, 1), d["corner"])], 1))
    names.append("lateral_tongue")
    side = d["tongue_side"]  # glued once for the session
    lateral = 0.6 * arts["T2"] + 0.4 * arts["T3"] + [-2.0, -5.0] + rng.normal(0.0, 0.3, (n, 2))
    cols.append(np.concatenate([lateral, np.full((n, 1), side)], 1))
    if not d["normalised"]:
        for j, (name, p) in enumerate(REFERENCES.items()):
            ref = np.broadcast_to(np.asarray(p), (n, 3)).copy()
            if d["loose"] == j:
                t = np.linspace(0.0, 1.0, n)[:, None]
                ref = ref + t * rng.uniform(-1.5, 1.5, 3) + rng.normal(0.0, 0.3, (n, 3))
            names.append(name)
            cols.append(ref)
    return names, np.stack(cols, 1)


def _dropouts(pos: np.ndarray, rng) -> np.ndarray:
    out = pos.copy()
    n, k = out.shape[:2]
    for _ in range(int(rng.integers(2, 6))):
        j, start = int(rng.integers(0, k)), int(rng.integers(0, n))
        out[start:start + int(rng.integers(3, 30)), j] = np.nan
    return out


def _recording(anatomy, task, seed, d, m, origin, fmt, order, rate, rng) -> LabLike:
    from ..synth import DEFAULT_NOISE_MM, synth_audio
    from ..synth._measurement import _simulate  # synth_recording, with the controls

    track, truth, controls, labels = _simulate(anatomy, task, seed, DEFAULT_NOISE_MM, None,
                                               True, True, "realistic")
    audio = synth_audio(controls, truth.times, anatomy.f0_hz, np.random.default_rng([*seed, 3]))
    arts = _articulators(anatomy, track, truth, d)
    roles, toolkit = _layout(arts, d, rng)
    times = np.arange(0.0, track.times[-1] + 1e-9, 1.0 / rate)
    toolkit = _resample(track.times, toolkit, times)
    device = np.einsum("ij,nkj->nki", m, toolkit) + origin
    if not d["normalised"]:
        r, t = _head_motion(rng, times, m, origin)
        device = np.einsum("nij,nkj->nki", r, device) + t[:, None]
    device = _dropouts(device, rng)
    k = len(roles) + d["unused"]
    device = np.concatenate([device, np.full(device.shape[:1] + (d["unused"], 3), np.nan)], 1)
    roles = roles + ["unused"] * d["unused"]
    names = tuple(f"{_PREFIX[fmt]}{i + 1}" for i in range(k))
    positions = device[:, order]
    channels = {names[i]: roles[order[i]] for i in range(k)}
    raw = RawEma(format=fmt, times=times, names=names, positions=positions, rate_hz=rate,
                 units="mm", axes="lab-like synthetic frame")
    truth_json = {
        "task": task, "head_normalised": bool(d["normalised"]),
        "origin_mm": origin.tolist(), "forward": m[:, 0].tolist(), "up": m[:, 1].tolist(),
        "device_from_toolkit": m.tolist(), "channels": channels,
        "references_toolkit_mm": {} if d["normalised"] else REFERENCES,
        "jaw_sensor": d["jaw_glued"], "second_jaw_sensor": bool(d["molar"]),
        "loose_reference": None if d["loose"] is None else list(REFERENCES)[d["loose"]],
    }
    return LabLike(raw=raw, truth=truth_json, audio=audio, labels=labels)


def lab_like_speaker(index: int, *, seed: int = 0, fmt: str = "ag501",
                     tasks: tuple[str, ...] = _TASKS, normalised: bool | None = None
                     ) -> list[LabLike]:
    """One speaker's session of lab-like recordings in memory (module docstring);
    ``normalised`` forces the frame kind (None: drawn)."""
    from ..synth import make_subject

    if fmt not in FORMATS:
        raise CassiError(f"lab-like files: format {fmt!r} is not one of {', '.join(FORMATS)}")
    rng = np.random.default_rng([int(seed), 28, int(index)])
    anatomy = make_subject(f"L{index + 1:02d}", np.random.default_rng([int(seed), 29, index]))
    d = _speaker_draws(rng)
    if normalised is not None:
        d["normalised"] = bool(normalised)
    m, origin = _frame(rng, d)
    n_sensors = 8 + (0 if d["molar"] else -1) + 2 + (0 if d["normalised"] else 3) + d["unused"]
    order = rng.permutation(n_sensors)
    rate = _EMA_FORMATS[fmt][1]
    return [_recording(anatomy, task, [int(seed), 30, index, i], d, m, origin, fmt, order,
                       rate, rng) for i, task in enumerate(tasks)]


def true_sensor_map(rec: LabLike) -> str:
    """The TOML sensor map a lab would write for ``rec`` (its channels named by role)."""
    lines = ["[channels]"]
    for i, name in enumerate(rec.raw.names, start=1):
        lines.append(f'{i} = "{rec.truth["channels"][name]}{"" if rec.truth["channels"][name] != "unused" else i}"')
    return "\n".join(lines) + "\n"


def write_lab_like_corpus(out_dir: str | os.PathLike, *, format: str = "ag501",
                          n_subjects: int = 6, seed: int = 0, overwrite: bool = False,
                          tasks: tuple[str, ...] | None = None, audio: bool = True) -> Path:
    """Write ``n_subjects`` lab-like sessions (module docstring) in ``format`` to
    ``out_dir/<subject>/``: each task's file with its sound (inside an mview file, else a
    ``.wav`` beside it; none with ``audio=False``), ``placement.json`` (the truth of every
    file) and ``truth_sensors.toml`` (the true names, for checking a proposed map; not
    named ``sensors.toml`` so the toolkit does not find it). A folder with files is
    refused unless ``overwrite``, and never one holding real data."""
    from .._io import atomic_write
    from ..synth import AUDIO_RATE_HZ
    from ..synth._audio import _write_wav
    from ..synth._foreign import refuse_foreign_data

    if format not in FORMATS:
        raise CassiError(f"lab-like files: format {format!r} is not one of {', '.join(FORMATS)}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise OutputExistsError(f"{out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise OutputExistsError(f"{out}: exists and is not empty (pass --force)")
        refuse_foreign_data(out, writer="cassi synth --lab-like")
    suffix = _EMA_FORMATS[format][0]
    for index in range(n_subjects):
        recs = lab_like_speaker(index, seed=seed, fmt=format, tasks=tasks or _TASKS)
        folder = out / f"L{index + 1:02d}"
        folder.mkdir(parents=True, exist_ok=True)
        truth = {}
        for rec in recs:
            name = f"{rec.truth['task']}{suffix}"
            if format == "mview" and audio:  # sound and labels inside, as Haskins' files
                _write(format, folder / name, rec.raw,
                       (rec.audio.astype(np.float64) / 32768.0, float(AUDIO_RATE_HZ)),
                       labels=rec.labels)
            else:  # the sound (unless audio=False) beside the file
                _write(format, folder / name, rec.raw)
                if audio:
                    _write_wav(folder / f"{rec.truth['task']}.wav", rec.audio, overwrite=True)
            truth[name] = rec.truth
        atomic_write(folder / "placement.json", json.dumps(truth, indent=1) + "\n",
                     overwrite=True)
        atomic_write(folder / "truth_sensors.toml", true_sensor_map(recs[0]), overwrite=True)
    return out


def true_frame(truth: dict, head_config: np.ndarray | None = None,
               config_channels: tuple[str, ...] = ()
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(origin, forward, up)`` of a lab-like file's truth in the coordinates the toolkit
    placed it in: the file's own for a head-normalised file, else the head frame whose
    reference configuration is ``head_config`` (the positions of ``config_channels``, in
    that order; the toolkit's positions, z toward the left, turned right-handed first)."""
    if truth["head_normalised"]:
        return (np.array(truth["origin_mm"]), np.array(truth["forward"]),
                np.array(truth["up"]))
    from .head import kabsch

    refs = truth["references_toolkit_mm"]
    src = np.array([refs[truth["channels"].get(c, c)] for c in config_channels]) @ _PHYSICAL
    rot, shift = kabsch(src[None], np.asarray(head_config, float), np.ones((1, len(src))))
    return shift[0], rot[0][:, 0], rot[0][:, 1]
