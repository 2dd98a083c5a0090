"""Where the tests find the real recordings: the experiments' one rule
(``experiments/shared_data.py``: ``$CASSI_REAL_DATA/NAME``, else ``shared/data/NAME`` in a
folder above the checkout), so that a test and the script whose table it checks look at
the same recording. Tests that need one skip with :func:`missing`'s line when it is not on
the machine."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# the one rule, shared with the experiments (experiments/shared_data.py)
_spec = importlib.util.spec_from_file_location("shared_data", ROOT / "experiments" / "shared_data.py")
_shared = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_shared)
XRMB_JW11, EMU_MO1, MO1_BUNDLE = _shared.XRMB_JW11, _shared.EMU_MO1, _shared.MO1_BUNDLE
real_data = _shared.real_data


def missing(name: str) -> str:
    """The skip reason when :func:`real_data` finds nothing."""
    return (f"the real recording {name} is not here (shared/data/{name} in a folder above "
            f"the checkout, or $CASSI_REAL_DATA/{name})")


def load_mo1():
    """The real IPS speaker mo1's recording (:data:`MO1_BUNDLE`), read with the reader's
    warnings (no head measures, the padding) silenced; call only where :func:`real_data`
    finds :data:`EMU_MO1`."""
    import warnings

    from cassi_fit.dataset import load_recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_recording(real_data(EMU_MO1) / MO1_BUNDLE)
