"""``lips.apart_in_closures`` and ``lips.closures_line``: where a recording's labels mark a
bilabial closure, the model's lips should touch; the one line ``cassi acoustics`` prints
when they stay apart there (the lips' rest the model took is wrong)."""

import numpy as np

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
