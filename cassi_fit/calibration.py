"""A subject's calibration: the record and its file, in one place.

:class:`Calibration` is one subject's face fitted through the model by
``cassi_fit.calibrate`` (``cassi calibrate``), and what ``initialize(...,
calibration=...)``, ``cassi animate --calibration`` and ``cassi evaluate --calibration``
read back. This module is its one home: the record; what it says about itself
(:meth:`Calibration.problems`: a fit that did not converge or reached an anatomical
bound, also warned as :class:`CalibrationWarning`; :meth:`Calibration.caveats`: limits
every calibration has, with their sizes); its file (``SUBJECT.calibration.json``,
:data:`FORMAT`), written by :func:`write_calibration` and read by
:func:`read_calibration` against a schema (:data:`SCHEMA`, :data:`PARAMS`: types and
plausible ranges, the calibration's own bounds among them); the folder layout
(:func:`calibration_path`, :func:`load_calibrations`). A run's choice of calibration is
resolved by ``run_spec.RunSpec.calibration_for``. Fitting lives in ``cassi_fit.calibrate``; the rest of the
subject's conformation in ``cassi_fit.conformation``. docs/CALIBRATION.md, "The file".

A file that is not a calibration gets one line naming the file, the line where the JSON
has one, and the field: ``S01.calibration.json:4: scale: 1000 is outside the plausible
range 0.5 to 2 (model mm per subject mm)``. Any encoding a text editor writes is read:
UTF-8 with or without a byte-order mark, UTF-16 with one (``_io.read_json``).
"""

from __future__ import annotations

import difflib
import json
import math
import os
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import CassiError, DataFormatError, MissingDataError
from .headmeasures import DEFAULT_HEAD_MEASURES, PLAUSIBLE_RANGES
from .options import CALIBRATION_METHODS

if TYPE_CHECKING:
    from .deform import FaceParams

#: The ``format`` entry of the calibration files this version writes.
FORMAT = "cassi_fit calibration 2"
#: The formats it reads: version 1 lacks ``unconverged`` and ``lower_lip_bias`` (and, in
#: its earliest files, ``bounds_hit`` and ``lip_rest_offset``), which then take their
#: defaults.
FORMATS = ("cassi_fit calibration 1", FORMAT)

#: The fitted jaw's proportions (x and y scale about the lower incisor tip, relative to
#: the model after the p/d scaling) stay within 1 / b .. b, b = 1.30. Two spreads add up
#: in that ratio: the jaw itself (the model's bony gonion is 77 mm behind its lower
#: incisor tip, at the short end of adult jaws, whose gonion lies 80-100 mm behind the
#: incisors: condyle 90-100 mm, ramus set 2-10 mm ahead of it, the norms of
#: docs/SYNTHETIC.md), up to 1.25; and p/d, whose pellet spacing MNI-MNM (37-45 mm
#: against the model's 43.3) scales the whole subject by up to 1.17 although the jaw
#: is not that much larger. 1.30 admits the first and most of the second; a fit that
#: wants more is fitting a mismatch (bone read as skin, a wrong measure), not a jaw.
JAW_SCALE_BOUND = 1.30
#: The fitted jaw shape's turn stays within +-10 deg: the mandibular plane angle (to
#: SN) is 32 +- 5 deg in adults, so 2 SD.
JAW_TURN_BOUND_RAD = float(np.radians(10.0))
#: A bound counts as hit when the fitted value reaches this fraction of it (the bounded
#: parameterisation approaches a bound only asymptotically).
BOUND_HIT_FRACTION = 0.95
#: The jaw-shape unknowns that can reach a bound (``Calibration.bounds_hit``).
BOUND_NAMES = ("jaw_scale_x", "jaw_scale_y", "jaw_turn")
#: The stages of the fit (``Calibration.unconverged``): ``separate`` fits the jaw shape,
#: then the face width, then the lips; ``joint`` everything at once.
STAGES = ("jaw_shape", "face_width", "lips", "joint")
#: Plausible ``p/d`` (model mm per subject mm): the subject's jaw pellets (MNI-MNM) 22 to
#: 87 mm apart, half to twice the model's 43.3 mm (real ones: 37-45 mm).
SCALE_RANGE = (0.5, 2.0)


class CalibrationWarning(UserWarning):
    """A calibration that did not converge or reached an anatomical bound
    (:meth:`Calibration.problems`): given by ``calibrate_subject``, ``calibrate_dataset``
    and by reading a file that records one."""


@dataclass(frozen=True)
class Calibration:
    """One subject's calibrated face. Lengths in the subject's mm unless named ``model``.

    ``scale``: model mm per subject mm (``p/d``). ``params``: the model's conformation
    parameters (``deform.FaceParams`` names, model units): what the face is drawn from.
    ``residuals``: what is left of each residual group, subject mm (rms over recordings
    where there are several). ``observed``: the per-recording first-line estimates of the
    lip thicknesses. ``lip_rest_offset``: (upper, lower) model mm, how far above the
    model's UL and LL sites the lip pellets sit on the first valid lines; animation
    measures the lips' vertical displacement from there, so that the lips are together
    (at rest) where the first valid line has them, as the report assumes, instead of
    being pushed into each other or apart by a pellet placed higher or lower on the lip
    than the model's site. ``converged``: every stage of the fit met its solver's test;
    ``unconverged``: the stages (:data:`STAGES`) that did not. ``bounds_hit``: the
    jaw-shape unknowns (:data:`BOUND_NAMES`) that reached their anatomical bound
    (:data:`JAW_SCALE_BOUND`, :data:`JAW_TURN_BOUND_RAD`); empty when the fit stayed
    inside. ``lower_lip_bias``: ``(low, high)`` mm, the range of the lower-lip estimate's
    error (estimate minus truth) that the unobserved incisor tip can cause
    (``calibrate.lower_lip_bias``), ``()`` when unknown (files of format 1).
    """

    subject: str
    method: str
    scale: float
    upper_lip_thickness: float
    lower_lip_thickness: float
    face_width: float
    mouth_width: float
    nose_protrusion: float
    gonion: tuple
    gnathion: tuple
    params: dict
    lip_rest_offset: tuple
    residuals: dict
    observed: dict
    recordings: tuple
    first_lines: tuple
    head_is_default: bool
    collisions: bool
    converged: bool
    format: str = field(default=FORMAT)
    bounds_hit: tuple = field(default=())
    unconverged: tuple = field(default=())
    lower_lip_bias: tuple = field(default=())

    def face_params(self, dtype: type | np.dtype = float) -> FaceParams:
        """The conformation as a ``deform.FaceParams`` (no animation)."""
        import jax.numpy as jnp

        from .deform import default_params

        values = {k: jnp.asarray(v, dtype) for k, v in self.params.items()}
        return replace(default_params(dtype=dtype), **values)

    def to_json(self) -> str:
        """The calibration file's text (JSON, one subject)."""
        return json.dumps(plain(asdict(self)), indent=1) + "\n"

    def problems(self) -> list[str]:
        """What went wrong in this calibration, one line each (empty when nothing did): a
        fit that did not converge, a jaw shape that reached its anatomical bound, a value
        outside the file's plausible ranges (:func:`implausible`; such a calibration is
        not written). Each starts with the subject."""
        out = []
        wrong = implausible(self)
        if wrong is not None:
            out.append(f"{self.subject}: implausible calibration, {wrong}")
        if not self.converged:
            where = f" (stage {', '.join(self.unconverged)})" if self.unconverged else ""
            out.append(f"{self.subject}: the calibration did not converge{where}: the "
                       "values of that stage and those after it may be wrong")
        if self.bounds_hit:
            at = ", ".join(f"{name} {value:.3f}" for name, value in self._bounded().items()
                           if name in self.bounds_hit)
            out.append(f"{self.subject}: the jaw shape reached its anatomical bound ({at}; "
                       f"bounds {1 / JAW_SCALE_BOUND:.3f}..{JAW_SCALE_BOUND:.3f}, +-"
                       f"{math.degrees(JAW_TURN_BOUND_RAD):.0f} deg, flagged from "
                       f"{BOUND_HIT_FRACTION:.0%} of them): its Headmeasures gonion and "
                       "gnathion ask for a jaw at or beyond the edge of adult proportions for "
                       "the model (check them); the jaw is drawn within the bound")
        return out

    def caveats(self) -> list[str]:
        """What every calibration of this kind cannot see, with its size, one line each:
        the lower lip's unobserved incisor tip (:attr:`lower_lip_bias`), and a subject
        without Headmeasures."""
        out = []
        if len(self.lower_lip_bias) == 2:
            low, high = self.lower_lip_bias
            t = self.lower_lip_thickness
            out.append(f"{self.subject}: lower lip thickness {t:.1f} mm: no pellet sees the "
                       "lower incisor tip, so it may be up to "
                       f"{max(high, 0.0):.1f} mm ({100 * max(high, 0.0) / t:.0f} %) too "
                       f"thick or {max(-low, 0.0):.1f} mm ({100 * max(-low, 0.0) / t:.0f} %) "
                       "too thin (95 % range of the dental norms)")
        if self.head_is_default:
            out.append(f"{self.subject}: no Headmeasures: the jaw shape, face and mouth "
                       "width and nose are the model's, scaled by p/d")
        return out

    def _bounded(self) -> dict[str, float]:
        """The jaw-shape values :data:`BOUND_NAMES` name: x and y scale, turn (deg)."""
        kx, ky = self.params.get("jaw_shape_scale", (math.nan, math.nan))
        turn = math.degrees(self.params.get("jaw_shape_theta", math.nan))
        return {"jaw_scale_x": kx, "jaw_scale_y": ky, "jaw_turn": turn}


def implausible(calibration: Calibration) -> str | None:
    """Why ``calibration`` breaks the file's schema (:func:`validate`: a value outside its
    plausible range ...), one line, or None: a calibration that could not be read back."""
    data = json.loads(calibration.to_json())
    if data.get("format") in FORMATS:  # an earlier format's optional entries: placeholders
        version = FORMATS.index(data["format"]) + 1
        data = {k: v for k, v in data.items() if k not in _DEFAULTS or SCHEMA[k].since <= version}
    try:
        validate(data)
    except DataFormatError as exc:
        return exc.reason
    return None


def warn_problems(calibration: Calibration, source: str | os.PathLike | None = None,
                  stacklevel: int = 2) -> None:
    """One :class:`CalibrationWarning` per line of ``calibration.problems()``, naming
    ``source`` (e.g. its file) when given."""
    for line in calibration.problems():
        where = f"{source}: " if source is not None else ""
        warnings.warn(CalibrationWarning(where + line), stacklevel=stacklevel + 1)


def plain(x: object) -> object:
    """``x`` with numpy arrays and scalars turned into lists and Python numbers (for JSON)."""
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return x


# ------------------------------------------------------------------------- the schema


@dataclass(frozen=True)
class Field:
    """One entry of a calibration file. ``kind``: ``"text"`` (a non-empty string),
    ``"choice"`` (one of ``choices``), ``"flag"`` (true/false), ``"number"``,
    ``"numbers"`` (``size`` numbers), ``"names"`` (a list of strings, from ``choices``
    if given), ``"lines"`` (a list of line numbers from 1), ``"table"`` (name -> a number
    >= 0), ``"observed"`` (name -> a list of numbers or null), ``"params"``
    (:data:`PARAMS`). Numbers lie within ``[low, high]`` (per element for ``"numbers"``)
    in ``unit``. ``since``: the format version from which the field is required."""

    kind: str
    low: float | tuple = -math.inf
    high: float | tuple = math.inf
    unit: str = ""
    choices: tuple = ()
    size: int = 0
    since: int = 1


def _measure(name: str) -> Field:
    return Field("number", *PLAUSIBLE_RANGES[name], "mm", since=1)


def _point(name: str) -> Field:
    (xl, xh), (yl, yh) = PLAUSIBLE_RANGES[f"{name}_x"], PLAUSIBLE_RANGES[f"{name}_y"]
    return Field("numbers", (xl, yl), (xh, yh), "mm, pellet frame", size=2, since=2)


#: Every entry of a calibration file: name -> :class:`Field`. The subject's measures (mm)
#: have Headmeasures' plausible ranges (``headmeasures.PLAUSIBLE_RANGES``, adult norms
#: widened to about +-6 SD), the scale :data:`SCALE_RANGE`.
SCHEMA: dict[str, Field] = {
    "format": Field("choice", choices=FORMATS),
    "subject": Field("text"),
    "method": Field("choice", choices=CALIBRATION_METHODS),
    "scale": Field("number", *SCALE_RANGE, "model mm per subject mm"),
    "upper_lip_thickness": _measure("upper_lip_thickness"),
    "lower_lip_thickness": _measure("lower_lip_thickness"),
    "face_width": _measure("face_width"),
    "mouth_width": replace(_measure("mouth_width"), since=2),
    "nose_protrusion": replace(_measure("nose_protrusion"), since=2),
    "gonion": _point("gonion"),
    "gnathion": _point("gnathion"),
    "params": Field("params"),
    "lip_rest_offset": Field("numbers", (-25.0, -25.0), (25.0, 25.0), "model mm", size=2,
                             since=2),
    "residuals": Field("table", 0.0, 1000.0, "mm", since=2),
    "observed": Field("observed", since=2),
    "recordings": Field("names", since=2),
    "first_lines": Field("lines", since=2),
    "head_is_default": Field("flag", since=2),
    "collisions": Field("flag", since=2),
    "converged": Field("flag", since=2),
    "bounds_hit": Field("names", choices=BOUND_NAMES, since=2),
    "unconverged": Field("names", choices=STAGES, since=2),
    "lower_lip_bias": Field("numbers", (-20.0, -20.0), (20.0, 20.0), "mm", size=2, since=2),
}

_OWN = DEFAULT_HEAD_MEASURES  # the model's own measures (headmeasures.DEFAULT_HEAD_MEASURES)


def _lip_change(name: str) -> tuple[tuple, float, float, str]:
    low, high = PLAUSIBLE_RANGES[name]
    own = getattr(_OWN, name)
    return (), low - own, high - own, "model mm added to the model's lip"


#: The model's conformation parameters a calibration sets (all of them): name -> (shape,
#: low, high, unit). The jaw shape's are the fit's own bounds; the lips keep the model's
#: lip (the model's own thickness plus the change) within the plausible range; the widths
#: are ratios to the model's own, the scale's range times the plausible widths over the
#: model's.
PARAMS: dict[str, tuple[tuple, float, float, str]] = {
    "upper_lip_thickness": _lip_change("upper_lip_thickness"),
    "lower_lip_thickness": _lip_change("lower_lip_thickness"),
    "face_width": ((), SCALE_RANGE[0] * PLAUSIBLE_RANGES["face_width"][0] / _OWN.face_width,
                   SCALE_RANGE[1] * PLAUSIBLE_RANGES["face_width"][1] / _OWN.face_width,
                   "times the model's"),
    "mouth_width": ((), SCALE_RANGE[0] * PLAUSIBLE_RANGES["mouth_width"][0] / _OWN.mouth_width,
                    SCALE_RANGE[1] * PLAUSIBLE_RANGES["mouth_width"][1] / _OWN.mouth_width,
                    "times the model's"),
    "nose_tip": ((2,), -25.0, 25.0, "model mm"),
    "jaw_shape_theta": ((), -JAW_TURN_BOUND_RAD, JAW_TURN_BOUND_RAD, "rad"),
    "jaw_shape_translation": ((2,), -25.0, 25.0, "model mm"),
    "jaw_shape_scale": ((2,), 1.0 / JAW_SCALE_BOUND, JAW_SCALE_BOUND, ""),
}

#: What a field takes when a file of an earlier format lacks it.
_DEFAULTS = {"mouth_width": math.nan, "nose_protrusion": math.nan,
             "gonion": (math.nan, math.nan), "gnathion": (math.nan, math.nan),
             "lip_rest_offset": (0.0, 0.0), "residuals": {}, "observed": {},
             "recordings": (), "first_lines": (), "head_is_default": False,
             "collisions": False, "converged": True, "bounds_hit": (), "unconverged": (),
             "lower_lip_bias": ()}


class _Invalid(Exception):
    """A field's problem, raised by the checks and turned into a DataFormatError."""

    def __init__(self, key: tuple, problem: str):
        super().__init__(problem)
        self.key, self.problem = key, problem


def _shown(value: object) -> str:
    text = json.dumps(value) if not isinstance(value, float) else f"{value:g}"
    return text if len(text) <= 40 else text[:37] + "..."


def _what(value: object) -> str:
    for kind, word in ((bool, "true/false"), (str, "a string"), (list, "a list"),
                       (dict, "an object"), (type(None), "null")):
        if isinstance(value, kind):
            return word
    return "a number"


def _number(key: tuple, value: object, low: float, high: float, unit: str) -> float:
    """``value`` as a float in ``[low, high]``, else :class:`_Invalid` naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        shown = f" ({_shown(value)})" if isinstance(value, str) else ""
        raise _Invalid(key, f"expected a number, got {_what(value)}{shown}")
    v = float(value)
    if not math.isfinite(v):
        raise _Invalid(key, f"{value} is not a finite number")
    if not low <= v <= high:
        unit = f" ({unit})" if unit else ""
        raise _Invalid(key, f"{v:g} is outside the plausible range {low:.4g} to {high:.4g}{unit}")
    return v


def _numbers(key: tuple, value: object, size: int, low: float | tuple, high: float | tuple,
             unit: str) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != size:
        raise _Invalid(key, f"expected a list of {size} numbers, got {_shown(value)}")
    lows = low if isinstance(low, tuple) else (low,) * size
    highs = high if isinstance(high, tuple) else (high,) * size
    return tuple(_number((*key, i), v, lo, hi, unit)
                 for i, (v, lo, hi) in enumerate(zip(value, lows, highs, strict=True)))


def _names(key: tuple, value: object, choices: tuple) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise _Invalid(key, f"expected a list of names, got {_shown(value)}")
    wrong = [v for v in value if choices and v not in choices]
    if wrong:
        raise _Invalid(key, f"unknown name {wrong[0]!r} (expected some of {', '.join(choices)})")
    return tuple(value)


def _params(key: tuple, value: object) -> dict:
    if not isinstance(value, dict):
        raise _Invalid(key, f"expected an object of the model's parameters, got {_what(value)}")
    _no_unknown(key, value, PARAMS)
    missing = [name for name in PARAMS if name not in value]
    if missing:
        raise _Invalid(key, f"missing parameter {', '.join(missing)}")
    out = {}
    for name, (shape, low, high, unit) in PARAMS.items():
        if shape:
            out[name] = list(_numbers((*key, name), value[name], shape[0], low, high, unit))
        else:
            out[name] = _number((*key, name), value[name], low, high, unit)
    return out


def _no_unknown(key: tuple, value: Mapping, known: Mapping) -> None:
    for name in value:
        if name not in known:
            near = difflib.get_close_matches(str(name), list(known), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise _Invalid((*key, name), f"unknown field{hint}")


def _checked(name: str, spec: Field, value: object) -> object:
    """The value of field ``name`` as the record keeps it, or :class:`_Invalid`."""
    key = (name,)
    kind = spec.kind
    if kind == "text":
        if not isinstance(value, str) or not value.strip() or any(c in value for c in "/\\\n"):
            raise _Invalid(key, f"expected a subject name, got {_shown(value)}")
        return value
    if kind == "choice":
        if value not in spec.choices:
            raise _Invalid(key, f"expected one of {', '.join(spec.choices)}, got {_shown(value)}")
        return value
    if kind == "flag":
        if not isinstance(value, bool):
            raise _Invalid(key, f"expected true or false, got {_shown(value)}")
        return value
    if kind == "number":
        return _number(key, value, spec.low, spec.high, spec.unit)
    if kind == "numbers":
        return _numbers(key, value, spec.size, spec.low, spec.high, spec.unit)
    if kind == "names":
        return _names(key, value, spec.choices)
    if kind == "lines":
        if not isinstance(value, list) or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value):
            raise _Invalid(key, f"expected a list of line numbers (from 1), got {_shown(value)}")
        return tuple(value)
    if kind == "table":
        if not isinstance(value, dict):
            raise _Invalid(key, f"expected an object of numbers, got {_what(value)}")
        return {k: _number((name, k), v, spec.low, spec.high, spec.unit) for k, v in value.items()}
    if kind == "observed":
        if not isinstance(value, dict) or not all(isinstance(v, list) for v in value.values()):
            raise _Invalid(key, "expected an object of lists")
        return {k: [None if x is None else _number((name, k, i), x, -100.0, 100.0, "mm")
                    for i, x in enumerate(v)] for k, v in value.items()}
    return _params(key, value)


def _consistent(data: dict, given: Mapping) -> None:
    """The entries that describe one thing twice agree (``given``: the file's entries)."""
    if len(data["first_lines"]) != len(data["recordings"]):
        raise _Invalid(("first_lines",), f"{len(data['first_lines'])} line numbers for "
                       f"{len(data['recordings'])} recordings")
    if "unconverged" in given and data["converged"] == bool(data["unconverged"]):
        raise _Invalid(("converged",), f"{str(data['converged']).lower()} disagrees with "
                       f"unconverged {list(data['unconverged'])}")
    bias = data["lower_lip_bias"]
    if len(bias) == 2 and bias[0] > bias[1]:
        raise _Invalid(("lower_lip_bias",), "low above high")
    # the face is drawn from params: a measure edited alone would not change it
    for name in ("face_width", "mouth_width"):
        implied = data["params"][name] * getattr(_OWN, name) / data["scale"]
        given = data[name]
        if math.isfinite(given) and abs(given - implied) > 0.01 * implied:
            raise _Invalid((name,), f"{given:g} mm disagrees with params.{name} "
                           f"{data['params'][name]:.4g}, which draws {implied:.1f} mm at scale "
                           f"{data['scale']:.4g} (the face is drawn from params: edit both, or "
                           "re-run cassi calibrate)")


def validate(data: object, path: str | os.PathLike | None = None, text: str = "") -> Calibration:
    """The :class:`Calibration` a parsed calibration file ``data`` (JSON's Python
    objects) holds; ``DataFormatError`` naming ``path``, the line of the field in
    ``text`` (the file's text, when given) and the field, for the first entry that
    breaks :data:`SCHEMA`, :data:`PARAMS` or their agreement."""
    if not isinstance(data, dict) or data.get("format") not in FORMATS:
        found = data.get("format") if isinstance(data, dict) else None
        got = f", found {_shown(found)}" if found is not None else ""
        raise DataFormatError(path, None, f"not a calibration file (format {FORMAT!r}{got})")
    version = FORMATS.index(data["format"]) + 1
    try:
        _no_unknown((), data, SCHEMA)
        missing = [k for k, spec in SCHEMA.items() if k not in data and spec.since <= version]
        if missing:
            raise _Invalid((), f"missing {', '.join(missing)}")
        checked = {k: _checked(k, spec, data[k]) for k, spec in SCHEMA.items() if k in data}
        for k, v in _DEFAULTS.items():
            checked.setdefault(k, v)
        _consistent(checked, data)
    except _Invalid as exc:
        line = _key_lines(text).get(exc.key) if text else None
        where = ".".join(str(k) for k in exc.key)
        raise DataFormatError(path, line, f"{where}: {exc.problem}" if where else exc.problem
                              ) from None
    known = {f.name for f in fields(Calibration)}
    return Calibration(**{k: (tuple(v) if isinstance(v, list) else v)
                          for k, v in checked.items() if k in known})


def _key_lines(text: str) -> dict[tuple, int]:
    """Line (1-based) of every object key of the JSON ``text`` and of every list element,
    by its path (keys and list indices from the top). ``text`` is valid JSON."""
    lines: dict[tuple, int] = {}
    stack: list[list] = []  # [opening bracket, current key or index]

    def here() -> tuple:
        return tuple(k for _, k in stack)

    line, i, expect_key = 1, 0, False
    while i < len(text):
        c = text[i]
        if c == "\n":
            line += 1
        elif not c.isspace():
            if stack and stack[-1][0] == "[" and c not in ",]":
                lines.setdefault(here(), line)
            if c == '"':
                j = i + 1
                while text[j] != '"':
                    j += 2 if text[j] == "\\" else 1
                if stack and stack[-1][0] == "{" and expect_key:
                    stack[-1][1], expect_key = json.loads(text[i:j + 1]), False
                    lines[here()] = line
                i = j
            elif c in "{[":
                stack.append([c, None if c == "{" else 0])
                expect_key = c == "{"
            elif c in "}]":
                stack.pop()
            elif c == "," and stack:
                if stack[-1][0] == "{":
                    expect_key = True
                else:
                    stack[-1][1] += 1
        i += 1
    return lines


# ------------------------------------------------------------------------- the files


def calibration_path(folder: str | os.PathLike, subject: str) -> Path:
    """``folder/SUBJECT.calibration.json``."""
    return Path(folder) / f"{subject.upper()}.calibration.json"


def write_calibration(
    path: str | os.PathLike, calibration: Calibration, *, overwrite: bool = False
) -> Path:
    """Write one subject's calibration as JSON (atomically; an existing file only with
    ``overwrite``); its problems and convergence are recorded in it, so that whoever
    reads it back is told (:func:`read_calibration`). ``CassiError`` naming the file for
    a calibration that breaks the schema (:func:`implausible`), which could not be read
    back."""
    from ._io import atomic_write

    wrong = implausible(calibration)
    if wrong is not None:
        raise CassiError(f"{path}: not written, the calibration of {calibration.subject} is "
                         f"implausible: {wrong}")
    return atomic_write(Path(path), calibration.to_json(), overwrite=overwrite)


def read_calibration(path: str | os.PathLike, *, warn: bool = True) -> Calibration:
    """Read a ``<SUBJECT>.calibration.json`` (UTF-8 with or without a byte-order mark, or
    UTF-16 with one) and check it against the schema (:func:`validate`): one-line
    ``DataFormatError`` naming the file, the line and the field, ``MissingDataError`` if
    there is no such file. A file that records a problem (:meth:`Calibration.problems`)
    gives one :class:`CalibrationWarning` per problem, naming the file, unless ``warn``
    is false."""
    from ._io import parse_json, read_text

    path = Path(path)
    text = read_text(path, "calibration file")
    calibration = validate(parse_json(path, text), path, text)
    if warn:
        warn_problems(calibration, path, stacklevel=2)
    return calibration


def load_calibrations(folder: str | os.PathLike, *, warn: bool = True) -> dict[str, Calibration]:
    """All ``*.calibration.json`` in ``folder``: subject (upper case) -> Calibration
    (:func:`read_calibration`). ``MissingDataError`` for a missing folder or one without
    such files; ``DataFormatError`` for two files of one subject."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingDataError(f"{folder}: calibration folder not found")
    out: dict[str, Calibration] = {}
    for path in sorted(folder.glob("*.calibration.json")):
        cal = read_calibration(path, warn=warn)
        subject = cal.subject.upper()
        if subject in out:
            raise DataFormatError(path, None, f"a second calibration of subject {subject}")
        out[subject] = cal
    if not out:
        raise MissingDataError(f"{folder}: no *.calibration.json files")
    return out


def calibration_records(calibrations: Mapping[str, Calibration]) -> list[dict[str, Any]]:
    """One row per subject for ``calibration_summary.csv`` (``tables.write_table``):
    scale, the calibrated measures (mm), convergence, bounds hit, the lower lip's possible
    bias (mm) and the residuals (mm)."""
    res_keys = sorted({k for c in calibrations.values() for k in c.residuals})
    rows = []
    for name, c in calibrations.items():
        low, high = c.lower_lip_bias if len(c.lower_lip_bias) == 2 else (math.nan, math.nan)
        row = {"subject": name, "method": c.method, "scale": c.scale,
               "upper_lip_thickness_mm": c.upper_lip_thickness,
               "lower_lip_thickness_mm": c.lower_lip_thickness,
               "lower_lip_bias_low_mm": low, "lower_lip_bias_high_mm": high,
               "face_width_mm": c.face_width, "converged": c.converged,
               "unconverged": ";".join(c.unconverged), "bounds_hit": ";".join(c.bounds_hit)}
        row.update({f"residual_{k}_mm": c.residuals.get(k, math.nan) for k in res_keys})
        rows.append(row)
    return rows
