"""``lips.apart_in_closures`` and ``lips.closures_line``: where a recording's labels mark a
bilabial closure, the model's lips should touch; the one line ``cassi acoustics`` prints
when they stay apart there (the lips' rest the model took is wrong)."""

import numpy as np
import pytest

from cassi_fit.lips import APART_MM, apart_in_closures, closures_line


def test_the_model_lips_opening_is_read_in_the_labelled_closures_only():
    names = np.array(["", "a:", "m", "m", "b", "P", "i:", "p_h", "sil"], dtype=object)
    opening = np.array([9.0, 14.0, 7.0, 8.0, np.nan, 6.0, 12.0, 9.0, 0.0])
    # m, m, P (upper case), p_h: b's opening is not finite and is left out
    assert apart_in_closures(names, opening) == (4, 7.5)
    assert apart_in_closures(np.array(["a", "s", "sil"], object), np.ones(3)) is None
    assert apart_in_closures(np.array(["m", "m"], object), np.full(2, np.nan)) is None


def test_one_line_where_the_lips_stay_apart_and_none_where_they_touch():
    apart = closures_line((72, 7.26), lip_closure=False)
    assert apart.startswith("lips: in the 72 frames labelled /p b m/ the model's lips are "
                            "7.3 mm apart (median), where the speaker's touch")
    assert "--lip-closure takes them to touch" in apart and "\n" not in apart
    assert "with --lip-closure" in closures_line((72, 3.5), lip_closure=True)
    assert closures_line((72, APART_MM), lip_closure=False) is None  # touching, near enough
    assert closures_line((72, -1.0), lip_closure=False) is None  # pressed together
    assert closures_line(None, lip_closure=False) is None


def test_a_run_whose_labelled_closures_leave_the_lips_apart_gets_the_line():
    """``lips.run_closures_line`` (``cassi animate``): the model with its lower lip 6 mm
    lower than at rest (1.6 mm apart) in frames labelled /m/ inside the recording gets the
    line; with the same frames labelled /a/, or no labels, none."""
    import types

    from cassi_fit.area_function import lip_opening, tract_geometry
    from cassi_fit.face_model import load_model
    from cassi_fit.labels import Labels
    from cassi_fit.lips import run_closures_line

    model = load_model()
    times = np.arange(20) / 10.0
    rest = np.array(model.vertices, np.float64)
    rest[np.asarray(tract_geometry(model).lower[1:]), 1] -= 6.0
    assert lip_opening(tract_geometry(model), rest) == pytest.approx(7.6, abs=0.01)
    vertices = np.broadcast_to(rest, (20,) + rest.shape)

    def run(labels, lip_closure=False):
        track = types.SimpleNamespace(length_s=2.0)
        recording = types.SimpleNamespace(path=None, labels=labels, track=track)
        return types.SimpleNamespace(
            recording=recording, state=types.SimpleNamespace(model=model),
            animation=types.SimpleNamespace(times=times, vertices=vertices),
            spec=types.SimpleNamespace(lip_closure=lip_closure))

    tier = Labels(np.array([0.0, 0.5, 1.0]), np.array([0.5, 1.0, 2.0]), ("a:", "m", "a:"),
                  tier="Segment")
    line = run_closures_line(run((tier,)))
    assert line is not None and line.startswith("lips: in the 5 frames labelled /p b m/")
    assert "--lip-closure takes them" in line
    assert "with --lip-closure" in run_closures_line(run((tier,), lip_closure=True))
    vowels = Labels(tier.starts, tier.ends, ("a:", "a:", "a:"), tier="Segment")
    assert run_closures_line(run((vowels,))) is None
    assert run_closures_line(run(())) is None
