"""The one first-valid-line rule (cassi_fit.pellets), seen the same by every user of it."""

import json
import warnings

import numpy as np
import pytest
import zoo

from cassi_fit.cli import main
from cassi_fit.errors import MissingDataError
from cassi_fit.pellets import (
    JAW_INDEX,
    JAW_PELLETS,
    PELLET_NAMES,
    T1,
    T4,
    first_valid_line,
    pellet_index,
)
from cassi_fit.quality import quality_report
from cassi_fit.txy import PelletTrack, read_txy, write_txy


def _track(t4_never=True, t1_late=3):
    """A clean synthetic sentence; T4 never tracked; T1 untracked on the ``t1_late`` lines
    after the leading untracked rows (so the rule's line is not the first jaw line)."""
    track, _ = zoo.sentence(clean=True)
    valid = track.valid.copy()
    lead = int(np.argmax(valid.all(axis=(1, 2))))
    if t4_never:
        valid[:, T4] = False
    valid[lead : lead + t1_late, T1, 0] = False
    return PelletTrack(track.times, track.positions, valid), lead + t1_late


def test_names_and_indices_are_one_tuple():
    from cassi_fit import deform, txy

    assert deform.PELLET_SITES is PELLET_NAMES and txy.PELLET_NAMES is PELLET_NAMES
    assert [PELLET_NAMES[i] for i in JAW_INDEX] == list(JAW_PELLETS)
    assert pellet_index("t4") == T4
    with pytest.raises(ValueError, match="unknown pellet"):
        pellet_index("T5")


def test_the_rule_on_fully_tracked_and_never_tracked_pellets():
    full, expected = _track(t4_never=False)
    assert first_valid_line(full) == (expected, PELLET_NAMES)
    lost, expected = _track()
    first = first_valid_line(lost, "x.txy")
    assert first.index == expected and "T4" not in first.tracked and len(first.tracked) == 7
    valid = lost.valid.copy()
    valid[:, pellet_index("MNM")] = False  # one jaw sensor, as most EMA corpora: enough
    one = first_valid_line(PelletTrack(lost.times, lost.positions, valid), "x.txy")
    assert one.index == expected and "MNM" not in one.tracked and "MNI" in one.tracked
    valid[:, pellet_index("MNI")] = False
    with pytest.raises(MissingDataError, match="x.txy: jaw pellets MNI, MNM never tracked"):
        first_valid_line(PelletTrack(lost.times, lost.positions, valid), "x.txy")


def test_info_quality_txy_and_animate_agree_when_t4_is_never_tracked(tmp_path, capsys):
    """Before issue 10: ``cassi info`` printed "-", txy raised, animate started elsewhere."""
    from cassi_fit.dataset import load_recording
    from cassi_fit.face_model import load_model
    from cassi_fit.initialize import initialize

    track, expected = _track()
    path = write_txy(tmp_path / "S01_tp040.txy", track)
    track = read_txy(path)
    assert first_valid_line(track).index == expected  # the default: every tracked pellet
    assert first_valid_line(track, pellets=JAW_PELLETS).index < expected  # a subset
    assert quality_report(track).first_valid_frame == expected
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["quality"]["first_valid_frame"] == expected
    assert main(["info", str(path)]) == 0
    assert f"first valid frame {expected} " in capsys.readouterr().out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        recording = load_recording(path)
    state = initialize(recording, load_model())
    assert state.first_frame == expected and "T4" not in state.tracked_pellets
    # the jaw's reference is that line's jaw pellets, scaled
    np.testing.assert_allclose(
        state.reference_jaw, state.scale * track.positions[expected, list(JAW_INDEX)], rtol=1e-6
    )
