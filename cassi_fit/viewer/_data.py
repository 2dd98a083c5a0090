"""The one-file viewer's data: what the page shows of one recording run, as one JSON
object whose arrays are base64 (little-endian) with their dtype.

Keys: ``meta`` (what the recording is: subject, task, format, rate, jaw method,
calibration, frames), ``times`` (m,) s and ``frame_index`` (m,) data lines (0-based) of
every frame, ``mesh`` (the rest vertices, sRGB colours and one triangle list per part the
page can show or hide), ``motion`` (every frame, :mod:`cassi_fit.viewer._encode`),
``pellets`` (measured and model sites per frame, model frame mm), ``views`` (the paper's
four views as the toolkit's renderer frames them), ``section`` (the midsagittal panel's
area, colours and the subject's palate and pharynx traces), ``plots`` (jaw opening and lip
aperture per frame) and ``labels`` (tiers of ``[start, end, label]``).
"""

from __future__ import annotations

import base64
import sys
from typing import Any

import numpy as np

from ..pellets import PELLET_NAMES
from ..render import (
    HAIR_COLOUR,
    MATERIAL_COLOURS,
    PAPER_VIEWS,
    hair_share,
    vertex_colours_srgb,
    view_cameras,
)
from ._encode import TOLERANCE_MM, encode_motion

#: The page's parts: each a toggle in the page, made of the model's materials.
PARTS = {
    "skin": ("skin", "lips", "eye"),
    "teeth": ("teeth",),
    "tongue": ("tongue",),
    "palate": ("palate",),
    "pharynx": ("pharynx",),
}
BACKGROUND = (0.92, 0.92, 0.92)  # the toolkit's renderer's
TRAIL_S = 0.1  # the measured pellets' trail, as in the toolkit's videos
_SECTION_PAD_MM = 12.0


def array(values: Any, dtype: str) -> dict[str, Any]:
    """``{"dtype", "shape", "b64"}``: ``values`` as little-endian ``dtype`` (``"f4"``,
    ``"i2"``, ``"u4"``, ...), base64."""
    a = np.ascontiguousarray(np.asarray(values).astype(f"<{dtype}"))
    if sys.byteorder != "little":  # pragma: no cover - every supported machine is little
        a = a.byteswap().view(a.dtype.newbyteorder())
    return {"dtype": dtype, "shape": list(a.shape), "b64": base64.b64encode(a.tobytes()).decode()}


def hex_colour(rgb: tuple[float, ...], factor: float = 1.0) -> str:
    return "#" + "".join(f"{round(255 * min(1.0, c * factor)):02x}" for c in rgb[:3])


def mesh_data(model: Any) -> dict[str, Any]:
    """The rest mesh, its sRGB vertex colours and one triangle list per part in :data:`PARTS`."""
    from ..face_model import MATERIALS

    faces = np.asarray(model.faces, np.int64)
    material = np.asarray(model.face_material)
    parts = {}
    for part, names in PARTS.items():
        chosen = np.isin(material, [MATERIALS.index(n) for n in names if n in MATERIALS])
        if chosen.any():
            parts[part] = array(faces[chosen].reshape(-1), "u4")
    colours = np.round(255 * vertex_colours_srgb(model, hair=False)).astype(np.uint8)
    out = {"rest": array(np.asarray(model.vertices, np.float32).reshape(-1), "f4"),
           "colors": array(colours.reshape(-1), "u1"), "parts": parts}  # fmt: skip
    share = hair_share(model)
    if share is not None:  # clipped per pixel by the page's shader: the renderer's sharp edge
        out["hair"] = array(share, "f4")
        out["hair_colour"] = list(HAIR_COLOUR)
    return out


def _section_box(model: Any, pellets: np.ndarray, traces: dict) -> list[float]:
    """[xmin, ymin, xmax, ymax] mm of the midsagittal panel: the vocal tract (the parts but
    skin near z = 0 at rest, the pellets, the traces) with a margin."""
    from ..face_model import MATERIALS

    rest = np.asarray(model.vertices, np.float64)
    faces = np.asarray(model.faces)
    inner = [MATERIALS.index(n) for n in ("lips", "teeth", "tongue", "palate", "pharynx")]
    used = np.unique(faces[np.isin(np.asarray(model.face_material), inner)])
    points = [rest[used][np.abs(rest[used, 2]) < 2.0][:, :2], pellets.reshape(-1, 2)]
    points += [np.asarray(t, np.float64).reshape(-1, 2) for t in traces.values() if t is not None]
    allp = np.concatenate(points)
    allp = allp[np.isfinite(allp).all(axis=1)]
    lo, hi = allp.min(axis=0) - _SECTION_PAD_MM, allp.max(axis=0) + _SECTION_PAD_MM
    return [float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])]


def recording_meta(run: Any) -> dict[str, Any]:
    """What the page's header says of a ``pipeline.RecordingRun``."""
    recording, animation, spec = run.recording, run.animation, run.spec
    line_s = float(recording.track.frame_step_s)
    return {
        "subject": recording.subject,
        "task": recording.task,
        "format": recording.format,
        "file": recording.path.name if recording.path is not None else "",
        "rate_hz": round(1.0 / line_s, 3),
        "line_step_s": line_s,
        "stride": int(animation.stride),
        "frames": int(animation.n_frames),
        "jaw_method": str(animation.jaw_method),
        "calibration": spec.calibration_label(run.state.calibration),
        "mode": str(spec.mode),
        "collisions": str(animation.collisions),
        "scale": float(run.state.scale),
    }


def page_data(run: Any, *, labels: list[dict[str, Any]] | None = None,
              tolerance_mm: float = TOLERANCE_MM) -> dict[str, Any]:  # fmt: skip
    """The page's data (see the module docstring) of a ``pipeline.RecordingRun``;
    ``labels``: tiers ``[{"name", "segments": [[start, end, label], ...]}]``."""
    from ..recording_video import subject_traces

    animation, model = run.animation, run.state.model
    times = np.asarray(animation.times, np.float64)
    measured = np.asarray(animation.pellets_measured, np.float64)
    sites = np.asarray(animation.pellets_model, np.float64)
    shown = np.isfinite(measured).any(axis=(0, 2))
    motion = encode_motion(np.asarray(animation.vertices), np.asarray(model.vertices),
                           tolerance_mm=tolerance_mm)  # fmt: skip
    traces = subject_traces(run.recording, run.state.scale)
    views = view_cameras(model, PAPER_VIEWS)
    height = float(np.ptp(np.asarray(model.vertices)[:, 1]))
    views.update(background=hex_colour(BACKGROUND), marker_radius_mm=0.012 * height)
    step = float(animation.frame_step_s)
    return {
        "meta": {**recording_meta(run), "max_error_mm": motion["max_error_mm"],
                 "components": motion["n_components"], "moving_vertices": len(motion["moving"])},
        "times": array(times, "f8"),
        "frame_index": array(animation.frame_index, "i4"),
        "mesh": mesh_data(model),
        "motion": {
            "moving": array(motion["moving"], "u4"), "mean": array(motion["mean"], "f4"),
            "basis": array(motion["basis"].reshape(-1), "i2"),
            "basis_scale": array(motion["basis_scale"], "f4"),
            "coeff": array(motion["coeff"].reshape(-1), "i2"),
            "coeff_scale": array(motion["coeff_scale"], "f4"),
            "n_components": motion["n_components"],
        },
        "pellets": {
            "names": list(PELLET_NAMES), "shown": [bool(s) for s in shown],
            "measured": array(measured.reshape(-1), "f4"), "model": array(sites.reshape(-1), "f4"),
            "trail_frames": max(2, round(TRAIL_S / step)),
        },
        "views": views,
        "section": {
            "box": _section_box(model, measured, traces),
            "background": "#ffffff",
            "colours": {p: hex_colour(MATERIAL_COLOURS[p], 0.75) for p in PARTS},
            "traces": {k: array(np.asarray(v, np.float32).reshape(-1), "f4")
                       for k, v in traces.items() if v is not None},
        },
        "plots": _plots(run, measured),
        "labels": labels or [],
    }  # fmt: skip


def _plots(run: Any, measured: np.ndarray) -> dict[str, Any]:
    """Jaw opening (deg, from the fitted jaw angle) and lip aperture (|UL - LL| in the
    recording's mm) per frame; NaN where not measured."""
    theta = np.asarray(run.animation.params.jaw_theta, np.float64).reshape(-1)
    ul, ll = PELLET_NAMES.index("UL"), PELLET_NAMES.index("LL")
    gap = (measured[:, ul] - measured[:, ll]) / float(run.state.scale)
    return {"jaw_deg": array(np.degrees(theta), "f4"),
            "lip_aperture_mm": array(np.hypot(gap[:, 0], gap[:, 1]), "f4")}  # fmt: skip
