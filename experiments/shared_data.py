"""Where the experiments (and the tests, through ``tests/real_data.py``) find the real
recordings, read-only and never copied into the project: ``$CASSI_REAL_DATA/NAME`` when
that variable is set, else ``shared/data/NAME`` in a folder above the checkout
(``../shared/data`` for a checkout beside it). One rule, so that a script and the test
of its table always look at the same recording."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
XRMB_JW11 = "xrmb_jw11"  # the real XRMB recording (speaker JW11, task 5 among others)
EMU_MO1 = "emu_ips_mo1"  # the real IPS Munich EMA recording as an EMU-SDMS bundle
JW11_TASK5 = "jw11_tp005.txy"  # the JW11 recording the experiments score
MO1_BUNDLE = "dfgspp_mo1_prosody_0024_bndl.json"  # its one bundle (speaker mo1)


def real_data(name: str) -> Path | None:
    """The folder of the real recording ``name`` (:data:`XRMB_JW11`, :data:`EMU_MO1`), or
    None when it is not on this machine."""
    candidates = [Path(os.environ["CASSI_REAL_DATA"]) / name] if os.environ.get(
        "CASSI_REAL_DATA") else []
    candidates += [parent / "shared" / "data" / name for parent in ROOT.parents]
    return next((p for p in candidates if p.is_dir()), None)


def real_file(name: str, file: str) -> Path | None:
    """``file`` inside the real recording ``name``'s folder, or None when either is missing."""
    folder = real_data(name)
    return folder / file if folder is not None and (folder / file).is_file() else None
