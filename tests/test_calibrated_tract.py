"""``acoustic_fit.calibrated_tract``: the subject's acoustic calibration as data (the
tract and the file read or looked for), which each caller words: ``cassi acoustics``
(``_cli.acoustics._calibrated_tract``) and the tract view (``acoustics.tract_panels``,
tested in test_tract_view.py)."""

from pathlib import Path

import numpy as np
import pytest

from cassi_fit.acoustic_fit import (
    AcousticFit,
    acoustic_calibration_path,
    calibrated_tract,
    write_acoustic_calibration,
)
from cassi_fit.area_function import TractParams

SUBJECT = "S01"


@pytest.fixture
def folder(tmp_path):
    """A ``cassi calibrate`` folder, still without the subject's acoustic calibration."""
    out = tmp_path / "cal"
    out.mkdir()
    return out


def _write(folder: Path) -> TractParams:
    tract = TractParams(*(np.float64(v) for v in (27.0, 1.5, 1.2, 1.3)))
    write_acoustic_calibration(acoustic_calibration_path(folder, SUBJECT), SUBJECT,
                               AcousticFit(tract, True, 5, np.zeros(3), np.zeros(3)),
                               recordings=["x"], frames=10, qualities=["a"])
    return tract


def test_the_answer_is_the_tract_and_its_file_not_a_sentence(folder):
    nothing = calibrated_tract(None, SUBJECT)
    assert nothing == (None, None) and nothing.tract is None and nothing.path is None
    assert calibrated_tract("", SUBJECT) == (None, None)
    expected = folder / f"{SUBJECT}.acoustic.json"
    missing = calibrated_tract(folder, SUBJECT)  # looked for, not there
    assert missing.tract is None and missing.path == expected
    fitted = _write(folder)
    for named in (folder, str(folder), folder / "S01.json"):  # the folder, or a file in it
        found = calibrated_tract(named, SUBJECT)
        assert found.path == expected
        assert float(found.tract.larynx_drop_mm) == float(fitted.larynx_drop_mm) == 27.0


def test_cassi_acoustics_words_the_calibration(folder):
    """The speaker's line's larynx words with a calibration (``CalibratedTract.larynx``,
    what ``cassi acoustics`` prints, one recording or a dataset); none without one, and
    none where the folder lacks the subject's file (``missing`` says so)."""
    assert calibrated_tract(None, SUBJECT).larynx() is None
    assert calibrated_tract(folder, SUBJECT).larynx() is None
    _write(folder)
    found = calibrated_tract(folder, SUBJECT)
    assert float(found.tract.larynx_drop_mm) == 27.0
    assert found.larynx() == (f"larynx 27 mm below the hyoid, fitted to the sound "
                              f"({SUBJECT}.acoustic.json)")


def test_the_answer_words_itself_once_for_every_caller(folder):
    """``label`` (what the tract view draws) and ``missing`` (the line for a calibration
    named without the subject's file): one wording, read by ``cassi acoustics`` and the
    tract view alike."""
    nothing = calibrated_tract(None, SUBJECT)
    assert nothing.label() == "the adult norms" and nothing.missing(SUBJECT) is None
    missing = calibrated_tract(folder, SUBJECT)
    assert missing.label() == "the adult norms"
    assert missing.missing(SUBJECT) == (f"no acoustic calibration for {SUBJECT} in {folder}: "
                                        "the adult norms")
    _write(folder)
    found = calibrated_tract(folder, SUBJECT)
    assert found.label() == f"fitted to the sound ({SUBJECT}.acoustic.json)"
    assert found.missing(SUBJECT) is None
