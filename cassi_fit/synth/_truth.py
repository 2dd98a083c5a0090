"""Stage 5 of the synthetic corpus, truth files: the per-recording ground-truth sidecar
(``<task>.truth.csv``, written through :func:`cassi_fit.tables.csv_text` after one ``#``
comment line) and the per-subject ``anatomy.json``, both written and parsed here."""

from __future__ import annotations

import json
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from ..errors import DataFormatError
from ..tables import csv_text
from ._anatomy import PELLETS, SubjectAnatomy
from ._kinematics import JawTruth


def _truth_columns() -> list[str]:
    cols = ["time_s", "theta_deg", "tx_mm", "ty_mm", "pivot_x_mm", "pivot_y_mm"]
    cols += ["condyle_x_mm", "condyle_y_mm"]
    cols += [f"{p}_{a}_mm" for p in PELLETS for a in "xy"]
    cols += [f"dropped_{p}_{a}" for p in PELLETS for a in "xy"]
    return cols + [f"mistracked_{p}" for p in PELLETS]


TRUTH_COLUMNS = tuple(_truth_columns())
# Decimals per column: 1 um / 1 us everywhere, the angle to 1e-10 degree (its small
# values carry the pivot, Eqs 6-7, which a reader may recompute from them).
_DIGITS = {"theta_deg": 10}


def _truth_text(truth: JawTruth, comment: str) -> str:
    """The sidecar CSV: a ``#`` comment line, a header, one row per frame (the pivot
    cells empty where the pivot does not exist; flags 0/1)."""
    n = truth.n_frames
    values = np.concatenate(
        [
            truth.times[:, None],
            np.rad2deg(truth.theta)[:, None],
            truth.translation,
            truth.pivot,
            truth.condyle,
            truth.pellets_true.reshape(n, 16),
        ],
        axis=1,
    ).tolist()
    flags = np.concatenate([truth.dropped.reshape(n, 16), truth.mistracked], axis=1)
    flags = flags.astype(int).tolist()
    rows = []
    for row, flag_row, defined in zip(values, flags, truth.pivot_defined.tolist(), strict=True):
        if not defined:  # the pivot columns are left empty where the pivot does not exist
            row[4] = row[5] = None
        rows.append(dict(zip(TRUTH_COLUMNS, row + flag_row, strict=True)))
    return f"# {comment}\n" + csv_text(rows, TRUTH_COLUMNS, digits=_DIGITS)


def _parse_truth(path: Path, text: str) -> JawTruth:
    rows, header_seen = [], False
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        fields_ = line.strip().split(",")
        if not header_seen:
            if tuple(fields_) != TRUTH_COLUMNS:
                raise DataFormatError(path, lineno, "not a synthetic ground-truth header")
            header_seen = True
            continue
        if len(fields_) != len(TRUTH_COLUMNS):
            raise DataFormatError(
                path, lineno, f"expected {len(TRUTH_COLUMNS)} fields, found {len(fields_)}"
            )
        try:
            rows.append([float(f) if f else np.nan for f in fields_])
        except ValueError:
            raise DataFormatError(path, lineno, "a field is not a number") from None
    if not rows:
        raise DataFormatError(path, None, "no ground-truth rows")
    a = np.array(rows)
    n = a.shape[0]
    defined = np.isfinite(a[:, 4]) & np.isfinite(a[:, 5])
    return JawTruth(
        times=a[:, 0],
        theta=np.deg2rad(a[:, 1]),
        translation=a[:, 2:4],
        pivot=np.where(defined[:, None], a[:, 4:6], 0.0),
        pivot_defined=defined,
        condyle=a[:, 6:8],
        pellets_true=a[:, 8:24].reshape(n, 8, 2),
        dropped=a[:, 24:40].reshape(n, 8, 2) != 0,
        mistracked=a[:, 40:48] != 0,
    )


def _anatomy_json(anatomy: SubjectAnatomy) -> str:
    out = {}
    for f in fields(SubjectAnatomy):
        value = getattr(anatomy, f.name)
        if f.name == "head":
            value = asdict(value)
        elif isinstance(value, np.ndarray):
            value = value.tolist()
        out[f.name] = value
    return json.dumps(out, indent=1) + "\n"


def _parse_anatomy(path: Path, text: str) -> SubjectAnatomy:
    """The :class:`SubjectAnatomy` of an ``anatomy.json`` text (DataFormatError naming
    ``path`` when it is not one)."""
    from ..headmeasures import HeadMeasures

    try:
        raw = json.loads(text)
        values = {}
        for f in fields(SubjectAnatomy):
            value = raw[f.name]
            if f.name == "head":
                value = HeadMeasures(**value)
            elif isinstance(value, list):
                value = np.asarray(value, dtype=np.float64)
            values[f.name] = value
        return SubjectAnatomy(**values)
    except (ValueError, KeyError, TypeError) as exc:
        raise DataFormatError(path, None, f"not a synthetic anatomy file ({exc})") from None
