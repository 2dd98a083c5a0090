"""Sensor maps that contradict the anatomy (issue 28 part 6): one error naming the roles,
never a track accepted with exit status 0. Lab-like synthetic files (cassi_fit.ema.lab_like),
read once with their true map (accepted) and with lying ones."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from cassi_fit.ema import ema_to_track
from cassi_fit.ema.lab_like import lab_like_speaker, true_sensor_map
from cassi_fit.ema.sensor_map import read_sensor_map
from cassi_fit.errors import DataFormatError


@pytest.fixture(scope="module")
def session():
    return {kind: lab_like_speaker(i, tasks=("tp011",), normalised=kind)[0]
            for i, kind in ((1, True), (2, False))}


def _swap(text: str, a: str, b: str) -> str:
    """The true map with the names ``a`` and ``b`` exchanged (two channels' roles swapped)."""
    return re.sub(rf'"({a}|{b})"', lambda m: f'"{b if m.group(1) == a else a}"', text)


def _read(tmp_path: Path, text: str):
    path = tmp_path / "lying.toml"
    path.write_text(text)
    return read_sensor_map(path)


@pytest.mark.parametrize("kind", [True, False], ids=["normalised", "head-moving"])
def test_the_true_map_is_accepted(session, tmp_path, kind):
    rec = session[kind]
    track, report = ema_to_track(rec.raw, _read(tmp_path, true_sensor_map(rec)))
    assert np.isfinite(track.positions[:, 0]).any() and report.roles["T1"] == "T1"


@pytest.mark.parametrize("kind", [True, False], ids=["normalised", "head-moving"])
def test_tip_and_dorsum_swapped_is_an_error_naming_them(session, tmp_path, kind):
    rec = session[kind]
    smap = _read(tmp_path, _swap(true_sensor_map(rec), "T1", "T3"))
    with pytest.raises(DataFormatError, match=r"roles T1 = 'T1' and T\d = 'T\d' contradict "
                                              r"the anatomy.*swapped"):
        ema_to_track(rec.raw, smap)


@pytest.mark.parametrize("kind", [True, False], ids=["normalised", "head-moving"])
def test_the_jaw_role_on_the_lower_lip_is_an_error_naming_them(session, tmp_path, kind):
    rec = session[kind]
    smap = _read(tmp_path, _swap(true_sensor_map(rec), "MNI", "LL"))
    with pytest.raises(DataFormatError, match=r"roles MNI = 'MNI' and (LL = 'LL'|UL = 'UL') "
                                              r"contradict the anatomy.*lower lip"):
        ema_to_track(rec.raw, smap)


def test_the_upper_incisor_reference_on_the_upper_lip_is_an_error(session, tmp_path):
    rec = session[True]
    smap = _read(tmp_path, true_sensor_map(rec) + '\n[references]\nupper_incisor = "UL"\n')
    with pytest.raises(DataFormatError, match=r"upper-incisor reference 'UL' contradicts the "
                                              r"anatomy.*upper lip"):
        ema_to_track(rec.raw, smap)


def test_the_jaw_role_on_the_lower_lip_alone_is_an_error(session, tmp_path):
    # the lower lip's channel named the jaw, the real jaw sensor left unnamed
    rec = session[True]
    text = true_sensor_map(rec).replace('"MNI"', '"JAWX"').replace('"LL"', '"MNI"')
    with pytest.raises(DataFormatError, match=r"contradict the anatomy"):
        ema_to_track(rec.raw, _read(tmp_path, text))
