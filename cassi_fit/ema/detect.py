"""Which format a recording file is in, by its content first and its name second.

Content decides where it can: an EST Track header (``EST_File``), a Carstens AG50x
header (``AG50xDATA_V00``), a MATLAB file header, numpy's ``.npy`` magic or an ``.npz``
(zip) with that suffix, an EMU bundle (a ``<bundle>_bndl`` folder, or its JSON as the
EMU-webApp serves it), a Wave export's header (``Wav Time`` ... ``Tx Ty Tz``), an XRMB
pellet line (17 whole numbers). A file with none of these is named by its suffix only
where the format has no header: ``.pos`` (a headerless AG500 file), ``.csv`` (an array
with a layout). So an EST file named ``.txt`` or ``.ema``, a ``.pos`` with or without a
header, and ``.txy`` files are all told apart; anything else is one clear error listing
what is understood.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from ..errors import DataFormatError, MissingDataError
from . import arrays, carstens, emu, est, mview, wave
from ._raw import RawEma

#: Formats :func:`detect_format` names (``xrmb`` is read by :mod:`cassi_fit.txy`).
EMA_FORMATS = ("est", "ag501", "ag500", "wave", "mview", "array", "emu")
_HEAD_BYTES = 4096


def _first_line(head: bytes) -> str | None:
    text = head.lstrip(b"\xef\xbb\xbf")
    try:
        decoded = text.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(text) - 4:  # a cut multi-byte character at the end is fine
            return None
        decoded = text[: exc.start].decode("utf-8")
    for line in decoded.replace("\r", "\n").split("\n"):
        if line.strip():
            return line
    return ""


def _is_xrmb_line(line: str) -> bool:
    tokens = line.split()
    return len(tokens) == 17 and all(t.lstrip("+-").isdigit() for t in tokens)


def detect_format(path: str | os.PathLike) -> str:
    """``"xrmb"`` or one of :data:`EMA_FORMATS` for the file at ``path`` (module
    docstring); :class:`DataFormatError` naming the file when it is none of them."""
    path = Path(path)
    if emu.is_bundle_folder(path):
        return "emu"
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except FileNotFoundError:
        raise MissingDataError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise DataFormatError(path, None, "is a folder, not a file") from None
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read: {exc.strerror or exc}") from None
    suffix = path.suffix.lower()
    if est.is_est(head):
        return "est"
    if carstens.is_ag50x(head):
        return "ag501"
    if mview.is_mat(head):
        return "mview"
    if emu.is_bundle_json(head, path):
        return "emu"
    if head.startswith(b"\x93NUMPY") or (head.startswith(b"PK\x03\x04") and suffix == ".npz"):
        return "array"
    line = _first_line(head)
    if line is not None and line:
        if wave.looks_like_wave(line):
            return "wave"
        if _is_xrmb_line(line):
            return "xrmb"
        if suffix == ".csv":
            return "array"
    if suffix == ".pos":
        return "ag500"
    if not head:
        raise DataFormatError(path, None, "empty file")
    raise DataFormatError(path, None, "not a recording this toolkit reads (XRMB .txy, EST "
                          "Track, Carstens .pos, NDI Wave .tsv, mview .mat, .npy/.npz/.csv "
                          "arrays, EMU bundles; docs/EMA.md)")


def read_ema(path: str | os.PathLike, *, format: str | None = None,
             layout: str | Sequence[str] | None = None, rate: float | None = None,
             **array_options) -> RawEma:
    """Read any articulograph file into a :class:`RawEma` (format detected unless given).

    ``layout``/``rate``/``array_options`` (``units``, ``mean_mm``, ``sd_mm``) are for
    arrays; ``rate`` also for a headerless ``.pos`` recorded at another rate than 200 Hz.
    """
    fmt = format or detect_format(path)
    if fmt == "est":
        return est.read_est(path)
    if fmt in ("ag501", "ag500"):
        return carstens.read_pos(path, rate=rate if fmt == "ag500" else None)
    if fmt == "wave":
        return wave.read_wave_tsv(path)
    if fmt == "mview":
        return mview.read_mview(path)
    if fmt == "emu":
        return emu.read_emu(path)
    if fmt == "array":
        return arrays.read_array(path, layout=layout, rate=rate, **array_options)
    if fmt == "xrmb":
        raise DataFormatError(path, None, "an XRMB pellet file: read it with read_txy")
    raise DataFormatError(path, None, f"unknown format {fmt!r} (formats: "
                          f"{', '.join(EMA_FORMATS)})")
