"""A synthetic articulograph corpus with truth: the synthetic XRMB corpus, measured again.

:func:`write_ema_corpus` writes the same subjects and tasks as
:func:`cassi_fit.synth.generate_corpus` (it generates that corpus first, in a temporary
folder) as an articulograph would record them, in one of :data:`FORMATS`:

1. each XRMB pellet track (the measured one: noise, dropouts and mistracks included) is
   resampled to the format's usual rate (linear interpolation; a value next to an
   untracked one is untracked; a pellet with one coordinate untracked is an untracked
   sensor, since a 3D position is tracked as a whole);
2. lifted to 3D in the toolkit's frame: the eight pellets on the midline (z = 0), a left
   lip corner ``LC`` 25 mm to the left of the lips' midpoint (a sensor with no CASSI role),
   and reference sensors fixed to the skull (upper incisor ``UI``, nasion ``NAS``,
   mastoids ``LMA`` and ``RMA``; :data:`REFERENCES`);
3. placed in a **recording frame**: the device's axes and origin differ from the
   toolkit's (a proper rotation, a tilted occlusal plane, an origin 100-200 mm away;
   drawn per subject), and moved by a known **head movement** (slow rotations of up to
   about 3 degrees about a point near the neck and translations of a few mm, drawn per
   recording);
4. written in the format's units and axes (mm, the device frame; EST, ``.pos`` and Wave
   files name no units: mm), with the format's sensor names (``.pos`` and Wave files
   number their channels, so a ``sensors.toml`` beside names them).

``format="emu"`` writes an emuDB instead (:mod:`cassi_fit.ema.emu`), as messy as the
real exports: ``cassi_synth_DBconfig.json`` naming only the ``posy``/``posz`` columns,
session folders ``<SUBJECT>_ses`` holding each task as a bundle ``<task>_bndl/`` with
the sound inside, an annotation (``Segment``: the prompt's words spread evenly over the
recording, NOT aligned to the sound; ``Word``: an item above them) and one SSFF track per
sensor whose last 40 records are exact zeros (EMU's padding); the bite-plane recording is
the session's bundle ``bite_bndl``.

Every subject folder also holds a **bite-plane recording** (``bite.<ext>``: sensors
``OS`` at the incisor tip, ``MS`` 42 mm behind it, ``OL``/``OR`` at the molars, with the
references, under its own head movement), the XRMB corpus's ``PAL.DAT``, ``PHA.DAT``,
``anatomy.json`` and ``<task>.truth.csv``, its ``.wav`` files, and the truth of the EMA
measurement: ``frame.json`` (the recording frame and the sensors' layout) and per
recording ``<task>.head.csv`` (per frame: the head rotation as a rotation vector, rad, and
translation, mm, in the device frame; and every sensor's true position in the toolkit's
frame, mm). References are noise-free (the XRMB noise is in the articulators), so reading
a file back and correcting the head recovers both within float32 rounding.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._io import atomic_write, register_input
from ..errors import CassiError, DataFormatError, MissingDataError, OutputExistsError
from ..pellets import PELLET_NAMES
from ..tables import write_table
from ._raw import RawEma

#: Format -> (file suffix, sampling rate Hz).
FORMATS = {"est": (".ema", 200.0), "est-ascii": (".ema", 500.0), "ag501": (".pos", 250.0),
           "wave": (".tsv", 100.0), "mview": (".mat", 100.0), "emu": ("_bndl", 200.0)}
#: The emuDB's name (``<name>_DBconfig.json``) written for ``format="emu"``.
EMU_DB_NAME = "cassi_synth"
#: The eight pellets' sensor names (the synthetic corpus's built-in map).
ROLE_NAMES = {"UL": "UL", "LL": "LL", "T1": "TT", "T2": "TB", "T3": "TD", "T4": "TR",
              "MNI": "LI", "MNM": "LMOL"}
#: Reference sensors, toolkit frame (mm): fixed to the skull.
REFERENCES = {"UI": (1.0, 5.0, 0.0), "NAS": (8.0, 70.0, 0.0), "LMA": (-88.0, 22.0, 52.0),
              "RMA": (-88.0, 22.0, -52.0)}
#: Bite-plane sensors, toolkit frame (mm): the plate between the teeth.
BITE = {"OS": (0.0, 0.0, 0.0), "MS": (-42.0, 0.0, 0.0), "OL": (-38.0, 0.0, 22.0),
        "OR": (-38.0, 0.0, -22.0)}
#: Sensor sets: every XRMB pellet as a sensor, or MOCHA-TIMIT's (one jaw sensor on the lower
#: incisor; tongue tip, blade and dorsum: no molar sensor, no fourth tongue sensor).
SENSOR_SETS = {"xrmb": PELLET_NAMES, "mocha": ("UL", "LL", "T1", "T2", "T3", "MNI")}
LIP_CORNER_MM = (-10.0, 25.0)  # LC: x offset from the lips' midpoint, distance to the left
BITE_SECONDS = 2.0
COMPLETE_LINE = "complete: yes"
_PHYSICAL = np.diag([1.0, 1.0, -1.0])  # toolkit (z left) -> right-handed (x fwd, y up, z right)


def _rotvec_matrix(r: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` rotation matrices of rotation vectors ``r (n, 3)`` (rad)."""
    theta = np.linalg.norm(r, axis=-1)
    axis = r / np.where(theta > 0, theta, 1.0)[:, None]
    k = np.zeros(r.shape[:1] + (3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k = k - np.swapaxes(k, 1, 2)
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def _recording_frame(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``(M, origin)``: device = ``M @ p_toolkit + origin`` at rest. ``M`` = a proper
    rotation (device x to the subject's right, y forward, z up, then turned by a yaw of up
    to 25 degrees, an occlusal tilt of 8-20 degrees and a roll of up to 5) times the
    toolkit's left-handed z flip."""
    base = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    yaw, tilt, roll = np.deg2rad([rng.uniform(-25, 25), rng.uniform(8, 20), rng.uniform(-5, 5)])
    turn = (_rotvec_matrix(np.array([[0.0, 0.0, yaw]]))[0]
            @ _rotvec_matrix(np.array([[tilt, 0.0, 0.0]]))[0]
            @ _rotvec_matrix(np.array([[0.0, roll, 0.0]]))[0])
    origin = np.array([rng.uniform(-40, 40), rng.uniform(-160, -100), rng.uniform(100, 200)])
    return turn @ base @ _PHYSICAL, origin


def _head_motion(rng: np.random.Generator, times: np.ndarray, m: np.ndarray,
                 origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame ``(R (n,3,3), t (n,3))`` in the device frame: slow rotations (up to ~3
    degrees) about a point near the neck and translations of a few mm."""
    n = times.shape[0]
    rotvec = np.zeros((n, 3))
    shift = np.zeros((n, 3))
    for axis, amp in enumerate(np.deg2rad([2.5, 1.5, 1.0])):
        f, phase = rng.uniform(0.15, 0.7), rng.uniform(0, 2 * np.pi)
        rotvec[:, axis] = amp * np.sin(2 * np.pi * f * times + phase)
    for axis in range(3):
        f, phase = rng.uniform(0.1, 0.5), rng.uniform(0, 2 * np.pi)
        shift[:, axis] = rng.uniform(1.0, 3.0) * np.sin(2 * np.pi * f * times + phase)
    pivot = m @ np.array([-70.0, -80.0, 0.0]) + origin  # near the neck, device frame
    rotation = _rotvec_matrix(rotvec)
    translation = pivot - np.einsum("nij,j->ni", rotation, pivot) + shift
    return rotation, translation


def _resample(times: np.ndarray, values: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``values (n, ...)`` at ``new``; NaN where a neighbour is
    NaN (at an exact sample, that sample alone counts)."""
    i = np.clip(np.searchsorted(times, new, side="right") - 1, 0, times.shape[0] - 2)
    w = ((new - times[i]) / (times[i + 1] - times[i])).reshape((-1,) + (1,) * (values.ndim - 1))
    a, b = values[i], values[i + 1]
    out = a + w * (b - a)
    return np.where(w == 0, a, out)


def _layout(track_positions: np.ndarray, roles: tuple[str, ...] = PELLET_NAMES
            ) -> tuple[tuple[str, ...], np.ndarray]:
    """Sensor names and toolkit-frame 3D positions ``(n, k, 3)`` of one recording, with a
    sensor for each of ``roles`` (pellet names)."""
    n = track_positions.shape[0]
    names = [ROLE_NAMES[r] for r in roles]
    pos = np.zeros((n, len(names) + 1 + len(REFERENCES), 3))
    pos[:, : len(names), :2] = track_positions[:, [PELLET_NAMES.index(r) for r in roles]]
    lips = 0.5 * (track_positions[:, 0] + track_positions[:, 1])
    pos[:, len(names), 0] = lips[:, 0] + LIP_CORNER_MM[0]
    pos[:, len(names), 1] = lips[:, 1]
    pos[:, len(names), 2] = LIP_CORNER_MM[1]
    names.append("LC")
    for j, (name, p) in enumerate(REFERENCES.items(), start=len(names)):
        pos[:, j] = p
        names.append(name)
    return tuple(names), pos


def _to_device(pos: np.ndarray, m: np.ndarray, origin: np.ndarray, rotation: np.ndarray,
               translation: np.ndarray) -> np.ndarray:
    rest = np.einsum("ij,nkj->nki", m, pos) + origin
    return np.einsum("nij,nkj->nki", rotation, rest) + translation[:, None]


def _write(fmt: str, path: Path, raw: RawEma, audio=None, labels=()) -> None:
    from . import carstens, est, mview, wave

    if fmt == "est":
        est.write_est(path, raw, overwrite=True)
    elif fmt == "est-ascii":
        est.write_est(path, raw, ascii=True, overwrite=True)
    elif fmt == "ag501":
        carstens.write_pos(path, raw, overwrite=True)
    elif fmt == "wave":
        wave.write_wave_tsv(path, raw, overwrite=True)
    else:
        mview.write_mview(path, raw, audio=audio, labels=labels, overwrite=True)


def _sensor_map_text(names: Sequence[str]) -> str:
    lines = ["# Sensor names of this folder's files (.pos and Wave files number their channels)",
             "[channels]"]
    lines += [f'{i} = "{name}"' for i, name in enumerate(names, start=1)]
    return "\n".join(lines) + "\n"


def _seed(seed: int, index: int, task: str) -> list[int]:
    return [int(seed), 7, index, zlib.crc32(task.encode())]


def _truth_rows(times, rotation, translation, names, toolkit):
    from .head import rotation_angle_deg

    angle = np.deg2rad(rotation_angle_deg(rotation))
    skew = np.stack([rotation[:, 2, 1] - rotation[:, 1, 2], rotation[:, 0, 2] - rotation[:, 2, 0],
                     rotation[:, 1, 0] - rotation[:, 0, 1]], axis=1)
    norm = np.linalg.norm(skew, axis=1)
    rotvec = skew / np.where(norm > 0, norm, 1.0)[:, None] * angle[:, None]
    rows = []
    for i in range(times.shape[0]):
        row = {"time_s": times[i], "rot_x_rad": rotvec[i, 0], "rot_y_rad": rotvec[i, 1],
               "rot_z_rad": rotvec[i, 2], "tx_mm": translation[i, 0],
               "ty_mm": translation[i, 1], "tz_mm": translation[i, 2]}
        for j, name in enumerate(names):
            row[f"{name}_x_mm"], row[f"{name}_y_mm"] = toolkit[i, j, 0], toolkit[i, j, 1]
        rows.append(row)
    return rows


def _convert_subject(src: Path, dst: Path, index: int, fmt: str, seed: int,
                     sensors: str = "xrmb") -> tuple[str, ...] | None:
    """One subject of the XRMB corpus ``src`` into the EMA corpus folder ``dst``."""
    from ..txy import read_txy

    suffix, rate = FORMATS[fmt]
    rng = np.random.default_rng([int(seed), 7, index])
    m, origin = _recording_frame(rng)
    names = None
    for item in sorted(src.iterdir()):
        lower = item.name.lower()
        if lower.endswith(".txy"):
            continue
        if fmt == "emu" and lower.endswith(".wav"):
            continue  # the sound goes inside the bundle
        if item.is_file() and not lower.endswith((".truth.csv",)):
            target = dst / (lower if lower.endswith(".wav") else item.name)
            shutil.copyfile(item, target)
        elif lower.endswith(".truth.csv"):
            shutil.copyfile(item, dst / item.name)
    for txy in sorted(p for p in src.iterdir() if p.name.lower().endswith(".txy")):
        task = txy.stem.lower()
        track = read_txy(txy, check=False)
        times = np.arange(0.0, track.times[-1] + 1e-9, 1.0 / rate)
        pellets = _resample(track.times, track.positions, times)
        names, toolkit = _layout(pellets, SENSOR_SETS[sensors])
        motion_rng = np.random.default_rng(_seed(seed, index, task))
        rotation, translation = _head_motion(motion_rng, times, m, origin)
        device = _to_device(toolkit, m, origin, rotation, translation)
        raw = RawEma(format=fmt, times=times, names=names, positions=device, rate_hz=rate,
                     units="mm", axes="synthetic device frame")
        audio = None
        wav = next((p for p in src.iterdir() if p.name.lower() == f"{task}.wav"), None)
        if fmt == "mview" and wav is not None:
            audio = _wav_samples(wav)
        if fmt == "emu":
            from .emu import PAD_RECORDS, write_bundle

            write_bundle(dst, src.name, task, raw, wav=wav, tiers=_prompt_tiers(task, times),
                         overwrite=True)
            toolkit = toolkit.copy()
            toolkit[-PAD_RECORDS:] = np.nan  # the export's padding: not in the file
        else:
            _write(fmt, dst / f"{task}{suffix}", raw, audio)
        write_table(_truth_rows(times, rotation, translation, names, toolkit),
                    dst / f"{task}.head.csv", overwrite=True)
    _write_frame_json(dst, fmt, rate, m, origin)
    # the bite-plane recording: bite sensors and the references, its own head movement
    times = np.arange(0.0, BITE_SECONDS, 1.0 / rate)
    bite_names = tuple(BITE) + tuple(REFERENCES)
    layout = np.array([BITE[s] if s in BITE else REFERENCES[s] for s in bite_names])
    toolkit = np.broadcast_to(layout, (times.shape[0],) + layout.shape)
    rotation, translation = _head_motion(np.random.default_rng(_seed(seed, index, "bite")),
                                         times, m, origin)
    raw = RawEma(format=fmt, times=times, names=bite_names,
                 positions=_to_device(toolkit, m, origin, rotation, translation),
                 rate_hz=rate, units="mm", axes="synthetic device frame")
    if fmt == "emu":  # a bundle of the session, named bite
        from .emu import write_bundle

        write_bundle(dst, src.name, "bite", raw, overwrite=True)
    else:
        _write(fmt, dst / f"bite{suffix}", raw)
    if fmt in ("ag501", "wave"):  # their files number the channels: name them
        atomic_write(dst / "sensors.toml", _sensor_map_text(names or ()), overwrite=True)
        atomic_write(dst / "bite.sensors.toml", _sensor_map_text(bite_names), overwrite=True)
    return names


def _prompt_tiers(task: str, times: np.ndarray) -> tuple:
    """A ``Segment`` tier: the task's prompt words spread evenly over the recording (before
    the padded end); not aligned to the sound."""
    from ..labels import Labels
    from ..synth import TASKS

    words = [w for w in (TASKS[task].prompt.split() if task in TASKS else [task])
             if w.strip("|")] or [task]
    end = max(float(times[-1]) - 0.3, 0.2)
    edges = np.linspace(0.1, end, len(words) + 1)
    return (Labels(edges[:-1], edges[1:], words, "Segment"),)


def _write_frame_json(dst: Path, fmt: str, rate: float, m: np.ndarray,
                      origin: np.ndarray) -> None:
    frame = {"format": fmt, "rate_hz": rate,
             "device_from_toolkit": m.tolist(), "device_origin_mm": origin.tolist(),
             "references_mm": REFERENCES, "bite_plane_mm": BITE,
             "lip_corner_mm": {"x_from_lips": LIP_CORNER_MM[0], "left": LIP_CORNER_MM[1]},
             "note": "device = device_from_toolkit @ p + device_origin at rest; then per "
                     "frame device' = R device + t (<task>.head.csv)"}
    atomic_write(dst / "frame.json", json.dumps(frame, indent=1) + "\n", overwrite=True)


def _wav_samples(path: Path) -> tuple[np.ndarray, float]:
    import wave as wavefile

    with wavefile.open(str(path), "rb") as w:
        rate = w.getframerate()
        data = np.frombuffer(w.readframes(w.getnframes()), dtype="<i2")
    return data.astype(np.float64) / 32768.0, float(rate)


def write_ema_corpus(out_dir: str | os.PathLike, *, format: str, n_subjects: int = 15,
                     seed: int = 0, tasks: str | Sequence[str] | None = None,
                     noise_scale: float = 1.0, audio: bool = True, overwrite: bool = False,
                     jaw_kinematics: str | Sequence[str] | None = None,
                     noise_family: str = "realistic",
                     from_corpus: str | os.PathLike | None = None,
                     sensors: str = "xrmb") -> Path:
    """Write the synthetic EMA corpus (module docstring) in ``format`` (one of
    :data:`FORMATS`) to ``out_dir``; the other arguments are
    :func:`cassi_fit.synth.generate_corpus`'s, or ``from_corpus`` names a complete
    synthetic XRMB corpus to measure instead (its own subjects, tasks and seed; ``seed``
    then only draws the recording frames and head movements). ``sensors``: a set of
    :data:`SENSOR_SETS` (``"mocha"``: one jaw sensor and three tongue sensors, as
    MOCHA-TIMIT records them; the truth still holds every pellet). Written into a temporary
    sibling folder and moved into place, ``README.txt`` (its last line marks a complete
    corpus) last; an existing corpus is refused unless ``overwrite``."""
    from ..synth import generate_corpus

    if format not in FORMATS:
        raise CassiError(f"unknown EMA format {format!r} (formats: {', '.join(FORMATS)})")
    if sensors not in SENSOR_SETS:
        raise CassiError(f"unknown sensor set {sensors!r} (sets: {', '.join(SENSOR_SETS)})")
    out_dir = Path(out_dir)
    if (out_dir / "README.txt").exists() and not overwrite:
        raise OutputExistsError(f"{out_dir / 'README.txt'}: a corpus exists (pass "
                                "overwrite=True / --force)")
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputExistsError(f"{out_dir}: exists and is not a folder")
    if out_dir.is_dir():  # never into a real dataset, whatever overwrite says (issue 24)
        from ..synth._foreign import refuse_foreign_data

        refuse_foreign_data(out_dir, writer="cassi synth --format")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    try:
        if from_corpus is None:
            xrmb = generate_corpus(work / "xrmb", n_subjects=n_subjects, seed=seed,
                                   tasks=tasks, noise_scale=noise_scale, audio=audio,
                                   jaw_kinematics=jaw_kinematics, noise_family=noise_family)
        else:
            xrmb = Path(from_corpus)
            text = (xrmb / "README.txt").read_text(encoding="utf-8") if (
                xrmb / "README.txt").is_file() else ""
            if not text.rstrip().endswith(COMPLETE_LINE):
                raise MissingDataError(f"{xrmb}: not a complete synthetic XRMB corpus")
        ema = work / "ema"
        ema.mkdir()
        subjects = sorted(p for p in xrmb.iterdir() if p.is_dir())
        names = None
        for index, folder in enumerate(subjects):
            dst = ema / (f"{folder.name}_ses" if format == "emu" else folder.name)
            dst.mkdir()
            names = _convert_subject(folder, dst, index, format, seed, sensors) or names
        if format == "emu" and names:
            from .emu import write_dbconfig

            write_dbconfig(ema, EMU_DB_NAME, tuple(names) + tuple(BITE))  # bite bundles too
        shutil.copyfile(xrmb / "Headmeasures.txt", ema / "Headmeasures.txt")
        readme = (xrmb / "README.txt").read_text(encoding="utf-8").splitlines()
        lines = [f"cassi_fit synthetic EMA corpus, format {format} (NOT real data)",
                 "Made by cassi_fit.ema.synthetic.write_ema_corpus / `cassi synth --format`; "
                 "see docs/EMA.md.",
                 f"ema_format: {format}", f"ema_rate_hz: {FORMATS[format][1]:g}",
                 f"ema_sensors: {sensors}",
                 "From the synthetic XRMB corpus:"]
        lines += [f"  {line}" for line in readme if line and line != COMPLETE_LINE]
        lines.append(COMPLETE_LINE)
        (ema / "README.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
        from ..synth._foreign import move_into_place

        move_into_place(ema, out_dir)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out_dir


@dataclass(frozen=True, eq=False)
class EmaTruth:
    """The truth of one synthetic EMA recording.

    times ``(n,)`` s; head_rotation ``(n, 3, 3)`` and head_translation ``(n, 3)`` mm: the
    head movement in the device frame (``device' = R device + t``); device_from_toolkit
    ``(3, 3)`` and device_origin ``(3,)`` mm: the recording frame at rest; positions:
    sensor name -> ``(n, 2)`` toolkit-frame mm (NaN untracked).
    """

    times: np.ndarray
    head_rotation: np.ndarray
    head_translation: np.ndarray
    device_from_toolkit: np.ndarray
    device_origin: np.ndarray
    positions: dict[str, np.ndarray]


def load_ema_truth(root: str | os.PathLike, subject: str, task: str) -> EmaTruth:
    """Read the truth of ``subject``'s ``task`` from an EMA corpus written by
    :func:`write_ema_corpus` (``frame.json`` and ``<task>.head.csv``)."""
    root = Path(root)
    readme = root / "README.txt"
    if not readme.is_file() or not readme.read_text(encoding="utf-8").rstrip().endswith(
            COMPLETE_LINE):
        raise MissingDataError(f"{root}: not a complete synthetic EMA corpus")
    folder = root / subject
    if not folder.is_dir() and (root / f"{subject}_ses").is_dir():
        folder = root / f"{subject}_ses"  # an emuDB's session folder
    frame_path, table = folder / "frame.json", folder / f"{task}.head.csv"
    for path in (frame_path, table):
        if not path.is_file():
            raise MissingDataError(f"{path}: no such truth file")
        register_input(path)
    frame = json.loads(frame_path.read_text(encoding="utf-8"))
    lines = table.read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    try:
        data = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    except ValueError:
        raise DataFormatError(table, None, "a value is not a number") from None
    col = {name: j for j, name in enumerate(header)}
    rotation = _rotvec_matrix(data[:, [col["rot_x_rad"], col["rot_y_rad"], col["rot_z_rad"]]])
    sensors = [h[: -len("_x_mm")] for h in header if h.endswith("_x_mm")]
    return EmaTruth(
        times=data[:, col["time_s"]], head_rotation=rotation,
        head_translation=data[:, [col["tx_mm"], col["ty_mm"], col["tz_mm"]]],
        device_from_toolkit=np.array(frame["device_from_toolkit"]),
        device_origin=np.array(frame["device_origin_mm"]),
        positions={s: data[:, [col[f"{s}_x_mm"], col[f"{s}_y_mm"]]] for s in sensors})
