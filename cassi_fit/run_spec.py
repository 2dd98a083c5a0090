"""One run's every choice, validated once: :class:`RunSpec`.

A run of one recording (``cassi animate``, ``export``, ``evaluate``, ``demo``, the corpus
forms and the Python API) is described by one frozen :class:`RunSpec`: the reproduction
mode, the subject's conformation or calibration, the tongue's shape and back anchors, the
jaw's region weights and method (an object of :mod:`cassi_fit.jaw_fit`), lip rounding,
collisions, the stride and the gap policy. It is checked once, when it is made (a bad
choice is an :class:`~cassi_fit.errors.InvalidChoiceError`; the paper's mode with a fitted
calibration or with collisions is a :class:`~cassi_fit.errors.CassiError`), and every stage
reads its fields instead of checking its own keywords.

Two presets (docs/CASSI_MODE.md gives each choice against the paper):

* :data:`IMPROVED`, the toolkit's defaults: a thick tongue whose back follows T4, lip
  rounding, the subject's conformation from Headmeasures and the first valid line;
* :data:`CASSI`, the paper's choices: a flat tongue of zero thickness (section 5) anchored
  behind and below T4 (section 4), Parke's regions x 1.11111 (section 3.1), only the jaw
  shape adjusted (section 3), the closed form per frame (Eqs 1-7), no collisions and no
  lip rounding (both future work). ``stride=10`` gives the Indigo's rate (section 2).

:func:`run_spec` makes a spec from a preset's name and the choices to change;
``spec.replace(...)`` varies one. The subject's calibration is resolved in one place,
:meth:`RunSpec.calibration_for`.
"""

from __future__ import annotations

import dataclasses
import numbers
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

from .errors import CassiError, InvalidChoiceError, MissingDataError
from .options import (
    COLLISION_MODES,
    CONFORMATIONS,
    GAP_POLICIES,
    JAW_WEIGHTS,
    MODES,
    TONGUE_ANCHORS,
    TONGUE_SHAPES,
    check_choice,
)


@dataclass(frozen=True)
class CalibrationFiles:
    """Calibrations on disk (``cassi calibrate``'s output): a folder of
    ``SUBJECT.calibration.json`` files, or one such file. Resolved per subject by
    :meth:`RunSpec.calibration_for`."""

    path: Path

    def __post_init__(self):
        object.__setattr__(self, "path", Path(self.path).absolute())

    def __str__(self) -> str:
        return str(self.path)


#: What initialization builds the subject's shape from: ``None`` or ``"measures"`` (the
#: subject's Headmeasures and first valid line), ``"cassi"`` (only what the paper did: the
#: jaw shape), a fitted ``calibration.Calibration``, a mapping subject ->
#: ``Calibration`` (``calibrate_dataset``'s result), or :class:`CalibrationFiles`.
CalibrationChoice = Union[None, str, "Calibration", CalibrationFiles]  # noqa: F821


def _jaw_method(jaw: Any) -> Any:
    from .jaw_fit import JawMethod, jaw_method

    if jaw is None or isinstance(jaw, JawMethod):
        return jaw
    if isinstance(jaw, str):
        return jaw_method(jaw)
    raise InvalidChoiceError(f"jaw must be a jaw method object or its name, not {jaw!r}")


def _calibration(value: Any) -> Any:
    # None and the names first: the calibration module is imported only for what may be a
    # fitted calibration (cassi jaw, and this module's presets, never need it)
    if value is None or isinstance(value, CalibrationFiles):
        return value
    if isinstance(value, str):
        if value in CONFORMATIONS:
            return None if value == "measures" else value
        return CalibrationFiles(Path(value))
    from .calibration import Calibration

    if isinstance(value, Calibration):
        return value
    if isinstance(value, Mapping):
        if not all(isinstance(v, Calibration) for v in value.values()):
            raise InvalidChoiceError("a calibration mapping must map subjects to Calibration")
        return {str(k).upper(): v for k, v in value.items()}
    if isinstance(value, os.PathLike):
        return CalibrationFiles(Path(value))
    raise InvalidChoiceError(
        f"calibration must be None, one of {', '.join(CONFORMATIONS)}, a Calibration or a "
        f"path to calibration files, not {value!r}")


@dataclass(frozen=True)
class RunSpec:
    """Every choice of one run (see the module docstring). Fields:

    mode: the preset's name (``options.MODES``); calibration: a :data:`CalibrationChoice`
    (``None``: the subject's conformation from Headmeasures; the cassi mode's is
    ``"cassi"``); tongue_shape, tongue_anchor, jaw_weights, lip_rounding: as
    ``deform.deform``; collisions: ``options.COLLISION_MODES``; jaw: a jaw method object
    (``jaw_fit.ClosedForm()``, ...; a name is converted), or None (the default): the
    paper's closed form with two jaw sensors, ``CoupledRotation`` with one
    (:meth:`jaw_method_for`); stride: every Nth data line from the first valid one
    (>= 1); gap_policy: ``options.GAP_POLICIES``; jaw_sensors: None (every jaw pellet the
    recording tracks) or the jaw sensors to use (``("MNI",)``: the other is left out, as
    if absent); x64: compute in float64 for this run only (``jax.enable_x64`` around the
    runner's stages, never process-wide; ``cassi jaw``: its pivots to a micrometre are
    quotients by ``sin(theta / 2)``); lip_closure: for an articulograph recording without
    a fitted calibration, the model's lips touching where its lip sensors are nearest
    (``lips.lips_touching``) instead of at rest on its first valid line: off by default, as
    on the one real recording it was tried on it did not improve the formants overall
    (docs/ACOUSTICS.md).
    """

    mode: str = "improved"
    calibration: Any = None
    tongue_shape: str = "thick"
    tongue_anchor: str = "follow"
    jaw_weights: str = "cassi"
    lip_rounding: bool = True
    collisions: str = "off"
    jaw: Any = None
    stride: int = 1
    gap_policy: str = "hold"
    jaw_sensors: Any = None
    x64: bool = False
    lip_closure: bool = False

    def __post_init__(self):
        check_choice("mode", self.mode, MODES)
        check_choice("tongue shape", self.tongue_shape, TONGUE_SHAPES)
        check_choice("tongue anchor", self.tongue_anchor, TONGUE_ANCHORS)
        check_choice("jaw weights", self.jaw_weights, JAW_WEIGHTS)
        check_choice("collisions", self.collisions, COLLISION_MODES)
        check_choice("gap policy", self.gap_policy, GAP_POLICIES)
        stride = self.stride
        if isinstance(stride, bool) or not isinstance(stride, numbers.Integral) or stride < 1:
            raise InvalidChoiceError(f"stride must be a whole number of at least 1, got "
                                     f"{stride!r}")
        object.__setattr__(self, "stride", int(stride))
        object.__setattr__(self, "lip_rounding", bool(self.lip_rounding))
        object.__setattr__(self, "x64", bool(self.x64))
        object.__setattr__(self, "lip_closure", bool(self.lip_closure))
        object.__setattr__(self, "jaw", _jaw_method(self.jaw))
        if self.jaw_sensors is not None:
            from .jaw_fit import check_sensors, jaw_sensor_set

            object.__setattr__(self, "jaw_sensors", jaw_sensor_set(self.jaw_sensors))
            if self.jaw is not None:  # refused here, before any recording is read
                check_sensors(self.jaw, self.jaw_sensors)
        object.__setattr__(self, "calibration", _calibration(self.calibration))
        if isinstance(self.calibration, CalibrationFiles) and not self.calibration.path.exists():
            raise CassiError(f"{self.calibration.path}: no such calibration file or folder")
        if self.mode == "cassi":
            if self.calibration not in (None, "cassi"):
                raise CassiError("the cassi mode (--mode cassi, --cassi) and a fitted "
                                 "calibration (--calibration) exclude each other: the cassi "
                                 "mode uses the paper's conformation")
            if self.collisions != "off":
                raise CassiError("the cassi mode (--mode cassi, --cassi) means no collision "
                                 "handling; drop --collisions project")
            object.__setattr__(self, "calibration", "cassi")

    def replace(self, **changes: Any) -> RunSpec:
        """This spec with ``changes`` (fields; those given as None are left as they are),
        checked again."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})

    @property
    def deform_style(self) -> dict[str, Any]:
        """The ``deform.deform`` keywords of this run."""
        return {"jaw_weights": self.jaw_weights, "tongue_anchor": self.tongue_anchor,
                "tongue_shape": self.tongue_shape, "lip_rounding": self.lip_rounding}

    @property
    def jaw_name(self) -> str:
        """The jaw method's name (``options.ALL_JAW_METHODS``) as tables print it;
        ``"auto"`` for the default (:meth:`jaw_method_for`)."""
        return "auto" if self.jaw is None else self.jaw.name

    def jaw_method_for(self, sensors: tuple[str, ...]) -> Any:
        """The jaw method object for a recording whose jaw ``sensors`` are those given
        (``("MNI", "MNM")`` or one): the spec's own, or by default the paper's closed form
        with two and ``CoupledRotation`` (rotation coupled to the incisor's displacement,
        learned from two-sensor recordings; docs/JAW.md) with one. A method that cannot run
        with those sensors is refused with its reason (``InvalidChoiceError``)."""
        from .jaw_fit import method_for_sensors

        return method_for_sensors(self.jaw, tuple(sensors))

    def calibration_for(self, subject: str) -> Any:
        """The calibration for ``subject``'s recordings, as ``initialize`` takes it: None
        (the subject's conformation from Headmeasures), ``"cassi"``, or a fitted
        ``Calibration``; the one resolver of a calibration choice. :class:`CalibrationFiles`:
        a file is read (it must be the subject's); from a folder the subject's
        ``SUBJECT.calibration.json``. A folder or a mapping without the subject is one
        ``MissingDataError`` naming the subject and the folder (and the subjects it has):
        a single recording stops, a corpus run records a failed row. Errors name the
        file."""
        from .calibration import Calibration, calibration_path, read_calibration

        cal, subject = self.calibration, str(subject).upper()
        if isinstance(cal, Mapping):
            if subject not in cal:
                raise MissingDataError(f"no calibration of subject {subject} among those "
                                       f"given ({', '.join(sorted(cal)) or 'none'})")
            return cal[subject]
        if not isinstance(cal, CalibrationFiles):
            if isinstance(cal, Calibration) and cal.subject.upper() != subject:
                raise CassiError(f"the calibration is of subject {cal.subject}, not {subject}")
            return cal
        path = cal.path
        if path.is_dir():
            own = calibration_path(path, subject)
            if not own.is_file():
                have = sorted(p.name.split(".")[0] for p in path.glob("*.calibration.json"))
                raise MissingDataError(
                    f"{path}: no calibration of subject {subject} ({own.name}; "
                    f"{'it has ' + ', '.join(have) if have else 'it has no *.calibration.json'})")
            path = own
        elif not path.is_file():
            raise CassiError(f"{path}: no such calibration file or folder")
        found = read_calibration(path)
        if found.subject.upper() != subject:
            raise CassiError(f"{path}: the calibration is of subject {found.subject}, not "
                             f"{subject}")
        return found

    def calibration_label(self, resolved: Any = "spec") -> str:
        """The word tables print for the calibration: ``"cassi mode"``, ``"default"``,
        ``"calibrated"``, or a conformation's name. ``resolved``: what
        :meth:`calibration_for` gave for a subject (default: this spec's own choice)."""
        cal = self.calibration if isinstance(resolved, str) and resolved == "spec" else resolved
        if self.mode == "cassi":
            return "cassi mode"
        if cal is None:
            return "default"
        return cal if isinstance(cal, str) else "calibrated"


#: The toolkit's defaults.
IMPROVED = RunSpec()
#: The paper's choices (see the module docstring).
CASSI = RunSpec(mode="cassi", calibration="cassi", tongue_shape="flat", tongue_anchor="fixed",
                lip_rounding=False)
_PRESETS = {"improved": IMPROVED, "cassi": CASSI}


def run_spec(mode: str | RunSpec | None = None, **changes: Any) -> RunSpec:
    """The :class:`RunSpec` of ``mode`` (a name of ``options.MODES``, a spec, or None for
    ``"improved"``) with the fields in ``changes`` that are not None replaced, checked
    once. ``run_spec("cassi", stride=10)`` is the paper's run at the Indigo's rate."""
    if mode is None:
        spec = IMPROVED
    elif isinstance(mode, RunSpec):
        spec = mode
    else:
        spec = _PRESETS[check_choice("mode", mode, MODES)]
    unknown = set(changes) - {f.name for f in dataclasses.fields(RunSpec)}
    if unknown:
        raise InvalidChoiceError(f"unknown run option(s) {', '.join(sorted(unknown))}")
    return spec.replace(**changes)
