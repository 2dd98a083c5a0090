"""The occlusal frame found from a recording itself (issue 28 part 1): lab-like synthetic
sessions whose anatomy is drawn apart from the estimator's norms (cassi_fit.ema.lab_like),
and the real XRMB speaker JW11 moved by a random rigid motion."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from real_data import XRMB_JW11, missing, real_data

from cassi_fit.ema import RawEma, SensorMap, ema_to_track
from cassi_fit.ema.lab_like import lab_like_speaker, true_frame, true_sensor_map
from cassi_fit.ema.placement import estimate_placement
from cassi_fit.ema.sensor_map import read_sensor_map
from cassi_fit.ema.track import session_placement
from cassi_fit.errors import DataFormatError

JW11 = real_data(XRMB_JW11)


def _map(tmp_path: Path, rec, extra: str = "", name: str = "m.toml") -> SensorMap:
    path = tmp_path / name
    path.write_text(true_sensor_map(rec) + extra)
    return read_sensor_map(path)


def _errors(placement, truth_origin, truth_forward):
    """Origin error (mm, in the plane) and plane angle error (deg) of a placement."""
    frame = placement.frame
    local = frame.rotation @ (truth_origin - frame.origin)
    fwd = frame.rotation @ truth_forward
    return float(np.hypot(local[0], local[1])), abs(float(np.degrees(np.arctan2(fwd[1], fwd[0]))))


@pytest.fixture(scope="module")
def speakers():
    """Four lab-like speakers: two head-normalised, two in a device frame with head
    movement; one task each."""
    return [lab_like_speaker(i, tasks=("tp011",), normalised=bool(i % 2)) for i in range(4)]


def test_origin_and_plane_are_found_without_an_incisor_sensor(speakers, tmp_path):
    for i, recs in enumerate(speakers):
        smap = _map(tmp_path, recs[0], name=f"m{i}.toml")
        placed = session_placement([r.raw for r in recs], smap)
        origin, forward, _ = true_frame(recs[0].truth, placed.head_config,
                                        placed.head_references)
        # the file's own origin is far from the incisor: without the estimate this fails
        assert np.linalg.norm(origin) > 30.0
        origin_error, plane_error = _errors(placed, origin, forward)
        assert origin_error < 8.0 and plane_error < 15.0, (i, origin_error, plane_error)
        assert placed.origin_sd_mm.min() > 0.5 and placed.plane_sd_deg > 1.0
        assert "estimated" in placed.source


def test_a_declared_frame_whose_midline_is_off_zero_is_corrected(speakers, tmp_path):
    recs = speakers[1]  # head-normalised: x forward, z up, the midline 15-45 mm off y = 0
    smap = _map(tmp_path, recs[0], '\n[file]\nanterior = "+x"\nup = "+z"\n')
    track, report = ema_to_track(recs[0].raw, smap)
    offset = recs[0].truth["origin_mm"][1]
    assert abs(offset) > 14.0
    place = report.placement
    assert place["declared_midline_offset_mm"] == pytest.approx(offset, abs=3.0)
    assert "corrected" in report.frame_source
    for role in ("UL", "LL", "T1", "MNI"):
        assert abs(report.midsagittal_distance_mm[role]) < 4.0
    assert place["origin_sd_mm"]["along_plane"] > 0 and place["plane_sd_deg"] > 0


def test_an_origin_given_by_hand_is_used(speakers, tmp_path):
    for recs in (speakers[1], speakers[0]):  # normalised, then with head movement
        truth = recs[0].truth
        o, f = truth["origin_mm"], truth["forward"]
        extra = (f"\n[file]\norigin = [{o[0]}, {o[1]}, {o[2]}]\n"
                 f"occlusal_plane = [{f[0]}, {f[1]}, {f[2]}]\n")
        smap = _map(tmp_path, recs[0], extra, name=f"given{int(truth['head_normalised'])}.toml")
        _, report = ema_to_track(recs[0].raw, smap)
        assert "given by the sensor map" in report.frame_source
        if truth["head_normalised"]:  # used as given (moved only onto the midsagittal plane)
            local = report.frame_rotation @ (np.asarray(o) - report.frame_origin)
            np.testing.assert_allclose(local[:2], 0.0, atol=1e-9)
            assert abs(local[2]) < 3.0
        else:  # the given point moved into the head frame as the references' median pose
            raw = recs[0].raw
            placed = session_placement([raw], smap)
            origin, _, _ = true_frame(truth, placed.head_config, placed.head_references)
            assert np.linalg.norm(placed.frame.origin - origin) < 3.0


def test_the_jaw_sensor_option_moves_the_origin(speakers, tmp_path):
    recs = speakers[1]
    heights = {}
    for kind in ("edge", "gum"):
        smap = _map(tmp_path, recs[0], f'\n[file]\njaw_sensor = "{kind}"\n', name=f"{kind}.toml")
        track, _ = ema_to_track(recs[0].raw, smap, check=False)  # one of them is wrong
        mni = track.positions[:, 6]
        heights[kind] = float(np.nanmedian(mni[:, 1]))
    assert heights["gum"] < heights["edge"] - 3.0  # a gum sensor lies deeper below the edge


def test_the_jaw_sensor_is_at_one_place_not_between_two(speakers, tmp_path):
    """Not told where the jaw sensor is glued, the estimate weighs the edge and the gum
    as two hypotheses (with the upper lip and the plane's cues), never their average: a
    depth between the two places, where no sensor is, would put the origin midway."""
    confident = 0
    for i, recs in enumerate(speakers):
        placed = {kind: session_placement([r.raw for r in recs], _map(
            tmp_path, recs[0], "" if kind == "unknown" else f'\n[file]\njaw_sensor = "{kind}"\n',
            name=f"{kind}{i}.toml")) for kind in ("unknown", "edge", "gum")}
        gum = placed["unknown"].cues["jaw_sensor_gum_probability"]
        assert 0.0 <= gum <= 1.0
        if 0.1 < gum < 0.9:
            continue
        confident += 1
        near, far = ("gum", "edge") if gum >= 0.9 else ("edge", "gum")
        origin = placed["unknown"].frame.origin
        assert np.linalg.norm(placed[near].frame.origin - origin) < 1.0, i
        assert np.linalg.norm(placed[far].frame.origin - origin) > 4.0, i
    assert confident >= 2


def test_the_files_of_a_session_share_one_frame(speakers, tmp_path):
    from cassi_fit.dataset import Dataset

    recs = lab_like_speaker(1, tasks=("tp011", "tp101"), normalised=True)
    folder = tmp_path / "data" / "L02"
    folder.mkdir(parents=True)
    from cassi_fit.ema.carstens import write_pos

    for rec in recs:
        write_pos(folder / f"{rec.truth['task']}.pos", rec.raw)
    (folder / "sensors.toml").write_text(true_sensor_map(recs[0]))
    ds = Dataset(tmp_path / "data")
    with pytest.warns(UserWarning, match="no head measures"):
        reports = [ds.load("L02", t).sensors for t in ("tp011", "tp101")]
    np.testing.assert_allclose(reports[0].frame_origin, reports[1].frame_origin)
    assert reports[0].frame_source == reports[1].frame_source
    alone = [ema_to_track(r.raw, read_sensor_map(folder / "sensors.toml"))[1] for r in recs]
    assert not np.allclose(alone[0].frame_origin, alone[1].frame_origin)


def test_a_placement_outside_the_anatomy_is_one_error_naming_the_file(speakers, tmp_path):
    recs = speakers[1]
    o = np.array(recs[0].truth["origin_mm"]) + 60.0 * np.array(recs[0].truth["up"])
    smap = _map(tmp_path, recs[0], f"\n[file]\norigin = [{o[0]}, {o[1]}, {o[2]}]\n")
    raw = dataclasses.replace(recs[0].raw, path=tmp_path / "lab_01.pos")
    with pytest.raises(DataFormatError, match=r"lab_01\.pos: .*outside a head.*\[file\] origin"):
        ema_to_track(raw, smap)


def test_3d_data_with_nothing_to_place_them_say_what_to_give(tmp_path):
    rng = np.random.default_rng(0)
    raw = RawEma(format="wave", times=np.arange(50) / 100, names=("UL", "LL", "TT", "JAW"),
                 positions=rng.normal(scale=30, size=(50, 4, 3)) + 200.0, rate_hz=100.0,
                 units="mm", axes="device", path=tmp_path / "noise.tsv")
    with pytest.raises(DataFormatError, match=r"noise\.tsv: .*(bite-plane recording|contradict)"):
        ema_to_track(raw)  # sensors at random: never placed (what to give, or which roles)


@pytest.mark.skipif(JW11 is None, reason=missing(XRMB_JW11))
def test_the_real_xrmb_speaker_is_placed_from_his_own_data():
    from cassi_fit.txy import read_txy

    track = read_txy(JW11 / "jw11_tp005.txy", check=False)
    pos = np.where(np.asarray(track.valid).all(-1, keepdims=True), track.positions, np.nan)
    p3 = np.concatenate([pos, np.zeros(pos.shape[:2] + (1,))], -1)
    rng = np.random.default_rng(5)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    shift = rng.uniform(-100, 100, 3)
    moved = p3 @ q.T + shift
    names = ("UL", "LL", "T1", "T2", "T3", "T4", "MNI")  # the one-jaw-sensor case
    placed = estimate_placement([(moved[:, :7], names)], {n: n for n in names}, names)
    origin_error, plane_error = _errors(placed, shift, q[:, 0])  # XRMB: origin, x = truth
    assert origin_error < 8.0 and plane_error < 15.0


@pytest.mark.parametrize("line, message", [
    ('origin = "front"', r"\[file\] origin = 'front': expected \[x, y, z\]"),
    ("origin = [1, 2, 3, 4]", r"\[file\] origin = .*expected \[x, y, z\]"),
    ("origin = [1, nan, 3]", r"\[file\] origin = .*expected \[x, y, z\]"),
    ("occlusal_plane = [0, 0, 0]", r"\[file\] occlusal_plane = .*expected"),
    ('occlusal_plane = "declared"', r'\[file\] occlusal_plane = "declared" needs the axes'),
    ('jaw_sensor = "tooth"', r"\[file\] jaw_sensor = 'tooth': expected 'edge', 'gum'"),
    ("jaw_sensor = -3", r"\[file\] jaw_sensor = -3"),
])
def test_frame_keys_that_make_no_sense_are_errors_naming_the_map(tmp_path, line, message):
    path = tmp_path / "bad.toml"
    path.write_text(f"[file]\n{line}\n")
    with pytest.raises(DataFormatError, match=rf"bad\.toml: {message}"):
        read_sensor_map(path)
