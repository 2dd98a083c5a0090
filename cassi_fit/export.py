"""Export the animated face: one frame as OBJ/PLY (trimesh), the whole animation as glTF binary.

The ``.glb`` follows glTF 2.0 (written here by hand: trimesh's exporter writes no
animations) so that it plays in Blender, three.js and other ordinary viewers:

* one mesh, one triangle primitive: POSITION (the first keyframe), COLOR_0 (per-vertex
  colour from the face materials), indices;
* one morph target per later keyframe: the POSITION displacement (mm) from the first
  keyframe, stored as a *sparse* accessor holding only the vertices that move by more than
  ``tolerance_mm`` (the forehead, eyes, upper teeth and palate never move);
* one animation whose sampler has the keyframe times (seconds from the first rendered
  frame; the recording's own start time is kept in ``extras``) and, per keyframe, a
  one-hot weight vector (all zeros for the first keyframe). ``LINEAR`` interpolation
  then blends neighbouring keyframes linearly, ``STEP`` holds each one;
* units: the vertex data stay in the model frame and in mm (x front, y up, z the
  subject's left); a parent node scales by 0.001 (glTF's unit is the metre) and turns
  the face to glTF's convention (+y up, front toward +z, the subject's left toward +x).
  That axis map has determinant -1 (the model frame is left-handed), which glTF allows:
  viewers reverse the winding. The material is double-sided.

File size is bounded by ``max_keyframes`` (keyframes evenly subsampled from the frames given).
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from jaxtyping import Float, Integer

from ._io import atomic_output_path, atomic_write, commit_output, remove_quietly
from .errors import CassiError, DataFormatError
from .options import check_choice
from .render import MATERIAL_COLOURS

MESH_SUFFIXES = (".obj", ".ply")
GLB_SUFFIX = ".glb"
#: glTF's keyframe interpolations used here: blend neighbouring keyframes, or hold each.
GLB_INTERPOLATIONS = ("LINEAR", "STEP")

# glTF vertex colours are linear RGB in [0, 1]; one colour table serves the renderer and
# the export (render.MATERIAL_COLOURS, sRGB), so a .glb looks like the rendered video.
MATERIAL_COLORS = {name: tuple(c**2.2 for c in srgb) for name, srgb in MATERIAL_COLOURS.items()}
MATERIALS = tuple(MATERIAL_COLORS)  # the face model's material order (face_model.MATERIALS)

_GLB_MAGIC, _GLB_VERSION = b"glTF", 2
_CHUNK_JSON, _CHUNK_BIN = 0x4E4F534A, 0x004E4942
_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
# model frame (x front, y up, z left; mm) -> glTF (x = subject's left, y up, z front; m),
# column-major 4x4 as glTF stores it
_MODEL_TO_GLTF = [0, 0, 0.001, 0, 0, 0.001, 0, 0, 0.001, 0, 0, 0, 0, 0, 0, 1]


def vertex_colors(
    n_vertices: int,
    faces: Integer[np.ndarray, "f 3"],
    face_material: Integer[np.ndarray, " f"] | None = None,
    materials: Sequence[str] = MATERIALS,
) -> Float[np.ndarray, "v 3"]:
    """(V, 3) float32 RGB per vertex: the colour of (one of) the faces that use it; skin
    where no material is given."""
    colors = np.tile(np.asarray(MATERIAL_COLORS["skin"], np.float32), (n_vertices, 1))
    if face_material is None:
        return colors
    table = np.asarray(
        [MATERIAL_COLORS.get(m, MATERIAL_COLORS["skin"]) for m in materials], np.float32
    )
    faces = np.asarray(faces)
    per_face = table[np.asarray(face_material)]
    for corner in range(3):
        colors[faces[:, corner]] = per_face
    return colors


def export_frame(
    path: str | os.PathLike,
    vertices: Float[Any, "v 3"],
    faces: Integer[Any, "f 3"],
    *,
    face_material: Integer[Any, " f"] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write one frame (``vertices (V, 3)`` mm, ``faces (F, 3)``) as ``.obj`` or ``.ply``
    with per-vertex colours. Returns the path written."""
    import trimesh

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise CassiError(f"{path}: a single frame is written as {' or '.join(MESH_SUFFIXES)}")
    vertices = np.asarray(vertices, np.float64)
    colors = vertex_colors(len(vertices), faces, face_material)
    mesh = trimesh.Trimesh(
        vertices,
        np.asarray(faces),
        vertex_colors=(colors * 255).round().astype(np.uint8),
        process=False,
    )
    tmp, final = atomic_output_path(path, overwrite=overwrite)
    try:
        mesh.export(tmp, file_type=suffix[1:])
    except BaseException:  # Ctrl-C included: no partial hidden file stays
        remove_quietly(tmp)
        raise
    return commit_output(tmp, final)


def keyframe_indices(n_frames: int, max_keyframes: int | None) -> Integer[np.ndarray, " k"]:
    """Indices of at most ``max_keyframes`` frames, evenly spread, first and last included."""
    if max_keyframes is None or n_frames <= max_keyframes:
        return np.arange(n_frames)
    if max_keyframes < 2:
        raise CassiError(f"max_keyframes must be at least 2, got {max_keyframes}")
    return np.unique(np.linspace(0, n_frames - 1, max_keyframes).round().astype(int))


class _Buffer:
    """The glTF binary buffer under construction: 4-byte aligned bufferViews and accessors."""

    def __init__(self):
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, array, target=None) -> int:
        while len(self.data) % 4:
            self.data += b"\x00"
        raw = np.ascontiguousarray(array).tobytes()
        entry = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target is not None:
            entry["target"] = target
        self.data += raw
        self.views.append(entry)
        return len(self.views) - 1

    def accessor(self, entry: dict) -> int:
        self.accessors.append(entry)
        return len(self.accessors) - 1

    def dense(self, array, kind, target=None, bounds=False) -> int:
        array = np.asarray(array)
        ctype = _UINT if array.dtype.kind == "u" else _FLOAT
        entry = {
            "bufferView": self.view(array, target),
            "componentType": ctype,
            "count": int(array.shape[0]),
            "type": kind,
        }
        if bounds:
            flat = array.reshape(array.shape[0], -1)
            entry["min"] = flat.min(axis=0).tolist()
            entry["max"] = flat.max(axis=0).tolist()
        return self.accessor(entry)

    def sparse_vec3(self, displacement, tolerance) -> int:
        """A VEC3 float accessor of ``displacement (V, 3)`` storing only rows above tolerance.

        min/max (required for morph-target POSITION) are those of the array as a viewer
        reconstructs it: zeros everywhere except the stored rows.
        """
        moving = np.flatnonzero(np.abs(displacement).max(axis=1) > tolerance)
        kept = np.zeros_like(displacement)
        kept[moving] = displacement[moving]
        entry = {
            "componentType": _FLOAT,
            "count": int(len(displacement)),
            "type": "VEC3",
            "min": kept.min(axis=0).tolist(),
            "max": kept.max(axis=0).tolist(),
        }
        if moving.size:
            entry["sparse"] = {
                "count": int(moving.size),
                "indices": {
                    "bufferView": self.view(moving.astype(np.uint32)),
                    "componentType": _UINT,
                },
                "values": {"bufferView": self.view(displacement[moving])},
            }
        return self.accessor(entry)


def _glb_bytes(document: dict, binary: bytes) -> bytes:
    """Assemble header + JSON chunk (space padded) + BIN chunk (zero padded)."""
    text = json.dumps(document, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    binary = bytes(binary) + b"\x00" * (-len(binary) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return b"".join(
        [
            struct.pack("<4sII", _GLB_MAGIC, _GLB_VERSION, total),
            struct.pack("<II", len(text), _CHUNK_JSON),
            text,
            struct.pack("<II", len(binary), _CHUNK_BIN),
            binary,
        ]
    )


def glb_document(
    frames: Float[Any, "m v 3"],
    faces: Integer[Any, "f 3"],
    times: Float[Any, " m"],
    *,
    face_material: Integer[Any, " f"] | None = None,
    materials: Sequence[str] = MATERIALS,
    max_keyframes: int | None = 240,
    interpolation: str = "LINEAR",
    tolerance_mm: float = 1e-3,
    name: str = "cassi_face",
    extras: dict[str, Any] | None = None,
) -> tuple[dict[str, Any], bytes]:
    """The glTF JSON and binary buffer of an animation; see the module docstring.

    ``frames (m, V, 3)`` mm, ``faces (F, 3)``, ``times (m,)`` s, strictly increasing.
    Returns ``(document, binary)``.
    """
    frames, times = _checked_animation(frames, times, interpolation)
    keys = keyframe_indices(len(frames), max_keyframes)
    base = frames[keys[0]]
    buf = _Buffer()
    position = buf.dense(base, "VEC3", _ARRAY_BUFFER, bounds=True)
    colors = buf.dense(
        vertex_colors(len(base), faces, face_material, materials), "VEC3", _ARRAY_BUFFER
    )
    indices = buf.dense(np.asarray(faces, np.uint32).reshape(-1), "SCALAR", _ELEMENT_ARRAY_BUFFER)
    targets = [{"POSITION": buf.sparse_vec3(frames[k] - base, tolerance_mm)} for k in keys[1:]]
    primitive = {
        "attributes": {"POSITION": position, "COLOR_0": colors},
        "indices": indices,
        "material": 0,
        "mode": 4,
    }
    mesh = {"name": name, "primitives": [primitive]}
    document = _scene_document(name, mesh)
    document["extras"] = {
        "recording_start_s": float(times[0]),
        "units": "mm (node scale 0.001 m)",
        "keyframes": [int(k) for k in keys],
        **(extras or {}),
    }
    if targets:
        primitive["targets"] = targets
        mesh["weights"] = [0.0] * len(targets)
        mesh["extras"] = {"targetNames": [f"t={times[k]:.6f}s" for k in keys[1:]]}
        document["animations"] = [_weights_animation(buf, times, keys, interpolation)]
    document["accessors"] = buf.accessors
    document["bufferViews"] = buf.views
    document["buffers"] = [{"byteLength": len(buf.data)}]
    return document, bytes(buf.data)


def _checked_animation(frames, times, interpolation) -> tuple[np.ndarray, np.ndarray]:
    """``frames`` as float32 (m, V, 3) and ``times`` as float64 (m,), or one clear error."""
    frames = np.asarray(frames, np.float32)
    times = np.asarray(times, np.float64)
    if frames.ndim != 3 or frames.shape[2] != 3 or len(times) != len(frames) or len(frames) == 0:
        raise CassiError(
            f"glTF export needs frames (m, V, 3) and times (m,), got {frames.shape}, {times.shape}"
        )
    if not np.all(np.isfinite(frames)):
        raise CassiError("glTF export: the vertices are not all finite")
    if np.any(np.diff(times) <= 0):
        raise CassiError("glTF export: frame times must increase strictly")
    check_choice("glTF interpolation", interpolation, GLB_INTERPOLATIONS)
    return frames, times


def _scene_document(name: str, mesh: dict) -> dict:
    """The document's scene: the model-frame node (mm -> m, glTF axes) over the mesh."""
    return {
        "asset": {"version": "2.0", "generator": "cassi_fit.export"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "model_frame_mm", "matrix": _MODEL_TO_GLTF, "children": [1]},
            {"name": name, "mesh": 0},
        ],
        "materials": [
            {
                "name": "cassi",
                "doubleSided": True,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [1, 1, 1, 1],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.8,
                },
            }
        ],
        "meshes": [mesh],
    }


def _weights_animation(buf: _Buffer, times, keys, interpolation: str) -> dict:
    """The animation: keyframe times from the first key (s), one-hot morph weights."""
    n_targets = len(keys) - 1
    key_times = (times[keys] - times[keys[0]]).astype(np.float32)
    weights = np.zeros((len(keys), n_targets), np.float32)
    weights[np.arange(1, len(keys)), np.arange(n_targets)] = 1.0
    sampler = {
        "input": buf.dense(key_times, "SCALAR", bounds=True),
        "output": buf.dense(weights.reshape(-1), "SCALAR"),
        "interpolation": interpolation,
    }
    return {
        "name": "speech",
        "samplers": [sampler],
        "channels": [{"sampler": 0, "target": {"node": 1, "path": "weights"}}],
    }


def export_glb(
    path: str | os.PathLike,
    frames: Float[Any, "m v 3"],
    faces: Integer[Any, "f 3"],
    times: Float[Any, " m"],
    *,
    overwrite: bool = False,
    **options: Any,
) -> Path:
    """Write the animation ``frames (m, V, 3)`` mm at ``times (m,)`` s as one ``.glb``;
    ``options`` as :func:`glb_document`. Returns the path written."""
    path = Path(path)
    if path.suffix.lower() != GLB_SUFFIX:
        raise CassiError(f"{path}: an animation is exported as {GLB_SUFFIX}")
    document, binary = glb_document(frames, faces, times, **options)
    return atomic_write(path, _glb_bytes(document, binary), overwrite=overwrite)


def read_glb(path: str | os.PathLike) -> tuple[dict[str, Any], bytes]:
    """Parse a ``.glb`` into ``(json document, binary chunk)``, checking the container."""
    path = Path(path)
    data = path.read_bytes()
    if len(data) < 20:
        raise DataFormatError(path, None, "too short to be a glTF binary")
    magic, version, total = struct.unpack_from("<4sII", data, 0)
    if magic != _GLB_MAGIC or version != _GLB_VERSION or total != len(data):
        raise DataFormatError(path, None, "not a glTF 2.0 binary (bad header)")
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != _CHUNK_JSON:
        raise DataFormatError(path, None, "first chunk is not JSON")
    document = json.loads(data[20 : 20 + length])
    binary = b""
    at = 20 + length
    if at < len(data):
        blength, bkind = struct.unpack_from("<II", data, at)
        if bkind != _CHUNK_BIN:
            raise DataFormatError(path, None, "second chunk is not BIN")
        binary = data[at + 8 : at + 8 + blength]
    return document, binary


def accessor_array(document: dict[str, Any], binary: bytes, index: int) -> np.ndarray:
    """Decode accessor ``index`` (dense or sparse, float32 or uint32) to a numpy array."""
    acc = document["accessors"][index]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    dtype = {_FLOAT: np.float32, _UINT: np.uint32}[acc["componentType"]]

    def from_view(view_index, count, dt, per):
        view = document["bufferViews"][view_index]
        start = view.get("byteOffset", 0)
        return np.frombuffer(binary, dt, count * per, start).reshape(count, per)

    if "bufferView" in acc:
        out = from_view(acc["bufferView"], acc["count"], dtype, width).copy()
    else:
        out = np.zeros((acc["count"], width), dtype)
    if "sparse" in acc:
        sp = acc["sparse"]
        idx = from_view(sp["indices"]["bufferView"], sp["count"], np.uint32, 1)[:, 0]
        out[idx] = from_view(sp["values"]["bufferView"], sp["count"], dtype, width)
    return out if width > 1 else out[:, 0]
