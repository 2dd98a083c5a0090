"""Export: OBJ/PLY frames and the animated glTF binary, parsed back structurally."""

import numpy as np
import pytest
import trimesh

from cassi_fit import _io
from cassi_fit.errors import CassiError, DataFormatError, OutputExistsError
from cassi_fit.export import (
    accessor_array,
    export_frame,
    export_glb,
    keyframe_indices,
    read_glb,
    vertex_colors,
)
from cassi_fit.render import MATERIAL_COLOURS

STEP = 0.006866


@pytest.fixture(scope="module")
def sphere():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=30.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _animation(vertices, m=40, t0=1.25):
    """Only the front cap (x > 15 mm) moves, up and down: a stand-in for the jaw."""
    front = vertices[:, 0] > 15.0
    lift = 4.0 * np.sin(np.arange(m) / 6.0)
    frames = np.repeat(vertices[None], m, axis=0)
    frames[:, front, 1] += lift[:, None]
    return frames, t0 + STEP * np.arange(m), front


def test_glb_container_and_animation_structure(tmp_path, sphere):
    vertices, faces = sphere
    frames, times, front = _animation(vertices)
    path = export_glb(tmp_path / "face.glb", frames, faces, times)
    raw = path.read_bytes()
    assert raw[:4] == b"glTF" and int.from_bytes(raw[8:12], "little") == len(raw)
    doc, binary = read_glb(path)
    assert doc["asset"]["version"] == "2.0"
    assert doc["buffers"][0]["byteLength"] == len(binary)
    for view in doc["bufferViews"]:
        assert view["byteOffset"] % 4 == 0
        assert view["byteOffset"] + view["byteLength"] <= len(binary)
    prim = doc["meshes"][0]["primitives"][0]
    pos = doc["accessors"][prim["attributes"]["POSITION"]]
    assert pos["count"] == len(vertices)
    np.testing.assert_allclose(pos["min"], frames[0].min(axis=0), atol=1e-4)
    np.testing.assert_allclose(pos["max"], frames[0].max(axis=0), atol=1e-4)
    assert accessor_array(doc, binary, prim["indices"]).size == faces.size
    # one target per later frame; sparse: only the moving vertices are stored
    assert len(prim["targets"]) == len(frames) - 1
    assert len(doc["meshes"][0]["weights"]) == len(frames) - 1
    for k, target in enumerate(prim["targets"], start=1):
        acc = doc["accessors"][target["POSITION"]]
        assert acc["count"] == len(vertices) and "bufferView" not in acc
        shift = frames[k] - frames[0]
        if "sparse" in acc:
            assert acc["sparse"]["count"] == front.sum()
        decoded = accessor_array(doc, binary, target["POSITION"])
        np.testing.assert_allclose(decoded, shift, atol=1e-5)
        np.testing.assert_allclose(acc["min"], shift.min(axis=0), atol=1e-5)
        np.testing.assert_allclose(acc["max"], shift.max(axis=0), atol=1e-5)
    # the animation: recording timing from the first frame, one-hot weights
    (anim,) = doc["animations"]
    (channel,) = anim["channels"]
    assert channel["target"]["path"] == "weights"
    assert "mesh" in doc["nodes"][channel["target"]["node"]]
    sampler = anim["samplers"][channel["sampler"]]
    key_times = accessor_array(doc, binary, sampler["input"])
    assert np.all(np.diff(key_times) > 0)
    np.testing.assert_allclose(key_times, times - times[0], atol=1e-6)
    assert doc["extras"]["recording_start_s"] == pytest.approx(1.25)
    weights = accessor_array(doc, binary, sampler["output"]).reshape(len(frames), -1)
    np.testing.assert_array_equal(weights[1:], np.eye(len(frames) - 1))
    assert not weights[0].any()


def test_glb_replays_every_keyframe(tmp_path, sphere):
    """base + weights(t_k) . targets reproduces frame k (what a viewer computes)."""
    vertices, faces = sphere
    frames, times, _ = _animation(vertices, m=30)
    doc, binary = read_glb(export_glb(tmp_path / "a.glb", frames, faces, times, max_keyframes=12))
    prim = doc["meshes"][0]["primitives"][0]
    base = accessor_array(doc, binary, prim["attributes"]["POSITION"])
    targets = np.stack([accessor_array(doc, binary, t["POSITION"]) for t in prim["targets"]])
    sampler = doc["animations"][0]["samplers"][0]
    weights = accessor_array(doc, binary, sampler["output"]).reshape(-1, len(targets))
    keys = doc["extras"]["keyframes"]
    assert len(keys) == 12 and keys[0] == 0 and keys[-1] == 29
    for w, k in zip(weights, keys, strict=True):
        np.testing.assert_allclose(base + np.tensordot(w, targets, 1), frames[k], atol=1e-4)


def test_glb_base_mesh_loads_in_trimesh(tmp_path, sphere):
    vertices, faces = sphere
    frames, times, _ = _animation(vertices, m=5)
    path = export_glb(tmp_path / "b.glb", frames, faces, times, interpolation="STEP")
    scene = trimesh.load(path)
    (mesh,) = scene.geometry.values()
    assert mesh.vertices.shape == vertices.shape and len(mesh.faces) == len(faces)
    np.testing.assert_allclose(mesh.vertices, frames[0], atol=1e-4)  # data kept in mm
    world = scene.to_geometry()
    # the parent node: metres, front (model +x) toward glTF +z
    np.testing.assert_allclose(world.vertices[:, 2], frames[0][:, 0] * 1e-3, atol=1e-7)
    np.testing.assert_allclose(world.vertices[:, 0], frames[0][:, 2] * 1e-3, atol=1e-7)


def test_glb_single_frame_has_no_animation(tmp_path, sphere):
    vertices, faces = sphere
    doc, _ = read_glb(export_glb(tmp_path / "c.glb", vertices[None], faces, [0.0]))
    assert "animations" not in doc and "targets" not in doc["meshes"][0]["primitives"][0]


def test_glb_rejects_bad_input(tmp_path, sphere):
    vertices, faces = sphere
    frames, times, _ = _animation(vertices, m=4)
    with pytest.raises(CassiError, match="increase"):
        export_glb(tmp_path / "d.glb", frames, faces, times[::-1])
    bad = frames.copy()
    bad[2, 0, 0] = np.nan
    with pytest.raises(CassiError, match="finite"):
        export_glb(tmp_path / "d.glb", bad, faces, times)
    with pytest.raises(CassiError, match=".glb"):
        export_glb(tmp_path / "d.gltf", frames, faces, times)
    assert not list(tmp_path.iterdir())
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"PK\x03\x04" + b"\x00" * 40)
    with pytest.raises(DataFormatError, match="junk.glb"):
        read_glb(junk)


def test_keyframe_indices():
    np.testing.assert_array_equal(keyframe_indices(5, None), np.arange(5))
    np.testing.assert_array_equal(keyframe_indices(5, 10), np.arange(5))
    keys = keyframe_indices(730, 100)
    assert len(keys) == 100 and keys[0] == 0 and keys[-1] == 729 and np.all(np.diff(keys) > 0)


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_frame_export_round_trip(tmp_path, sphere, suffix):
    vertices, faces = sphere
    material = np.zeros(len(faces), int)
    material[: len(faces) // 2] = 3  # teeth
    path = export_frame(tmp_path / f"frame{suffix}", vertices, faces, face_material=material)
    mesh = trimesh.load(path, process=False)
    assert mesh.vertices.shape == vertices.shape
    np.testing.assert_allclose(mesh.vertices, vertices, atol=1e-5)
    with pytest.raises(OutputExistsError):
        export_frame(path, vertices, faces)
    _io.register_input(tmp_path / f"input{suffix}")
    with pytest.raises(OutputExistsError):
        export_frame(tmp_path / f"input{suffix}", vertices, faces, overwrite=True)


def test_vertex_colors_follow_materials(sphere):
    vertices, faces = sphere
    material = np.full(len(faces), 4)  # tongue
    colors = vertex_colors(len(vertices), faces, material)
    assert colors.shape == (len(vertices), 3)
    np.testing.assert_allclose(
        colors[faces[0, 0]], [c**2.2 for c in MATERIAL_COLOURS["tongue"]], atol=1e-6
    )


def test_exports_get_the_users_normal_mode(tmp_path, sphere):
    import os

    vertices, faces = sphere
    frames, times, _ = _animation(vertices, m=4)
    old = os.umask(0o022)
    try:
        paths = [export_frame(tmp_path / f"f{s}", vertices, faces) for s in (".obj", ".ply")]
        paths.append(export_glb(tmp_path / "a.glb", frames, faces, times))
    finally:
        os.umask(old)
    for path in paths:
        assert path.stat().st_mode & 0o777 == 0o644, path


def test_an_interrupted_frame_export_leaves_nothing(tmp_path, sphere, monkeypatch):
    vertices, faces = sphere

    def interrupted(self, file_obj=None, **kwargs):
        open(file_obj, "w").write("ply\nhalf")
        raise KeyboardInterrupt

    monkeypatch.setattr(trimesh.Trimesh, "export", interrupted)
    with pytest.raises(KeyboardInterrupt):
        export_frame(tmp_path / "frame.ply", vertices, faces)
    assert list(tmp_path.iterdir()) == []


def test_a_bad_interpolation_is_an_invalid_choice(tmp_path, sphere):
    from cassi_fit.errors import InvalidChoiceError

    vertices, faces = sphere
    frames, times, _ = _animation(vertices, m=3)
    with pytest.raises(InvalidChoiceError, match="LINEAR, STEP"):
        export_glb(tmp_path / "a.glb", frames, faces, times, interpolation="CUBIC")
    assert list(tmp_path.iterdir()) == []
