"""Where the tests find the real recordings (read-only, never copied into the project):
``shared/data/NAME`` in a folder above the checkout (``../shared/data`` for a checkout
beside it), or ``$CASSI_REAL_DATA/NAME``. Tests that need one skip with :func:`missing`'s
line when it is not on the machine."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
XRMB_JW11 = "xrmb_jw11"  # the real XRMB recording (speaker JW11, task 5 among others)
EMU_MO1 = "emu_ips_mo1"  # the real IPS Munich EMA recording as an EMU-SDMS bundle
MO1_BUNDLE = "dfgspp_mo1_prosody_0024_bndl.json"  # its one bundle (speaker mo1)


def real_data(name: str) -> Path | None:
    """The folder of the real recording ``name`` (:data:`XRMB_JW11`, :data:`EMU_MO1`), or None."""
    candidates = [Path(os.environ["CASSI_REAL_DATA"]) / name] if os.environ.get(
        "CASSI_REAL_DATA") else []
    candidates += [parent / "shared" / "data" / name for parent in ROOT.parents]
    return next((p for p in candidates if p.is_dir()), None)


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
