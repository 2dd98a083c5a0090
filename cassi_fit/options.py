"""Every option vocabulary of the toolkit, in one light module.

The command line imports this module to build its parsers without starting JAX; the library
checks a user's choice against the same tuples with :func:`check_choice`, so a bad choice
raises one error type (:class:`~cassi_fit.errors.InvalidChoiceError`, a ``ValueError`` and a
``CassiError``) wherever it is made. Strings here are the names users type; in Python the
jaw methods and solvers are objects (:mod:`cassi_fit.jaw_fit`) and these names are aliases.
"""

from __future__ import annotations

from collections.abc import Sequence

from .errors import InvalidChoiceError

#: Jaw-motion methods (docs/JAW.md): the paper's Eqs 1-7, a rigid fit per frame, Parke's
#: fixed pivot, and a pivot that moves smoothly in time.
JAW_METHODS = ("closed-form", "frame-fit", "fixed-pivot", "smooth-pivot")
#: Jaw methods for one jaw sensor only (docs/JAW.md): the rotation coupled to the sensor's
#: displacement by a prior learned from two-sensor recordings. ``cassi jaw`` and
#: ``jaw_fit.jaw_method`` accept them beside :data:`JAW_METHODS`.
ONE_SENSOR_JAW_METHODS = ("coupled-rotation",)
ALL_JAW_METHODS = JAW_METHODS + ONE_SENSOR_JAW_METHODS
#: The jaw sensors a jaw fit may use (``--jaw-sensors``): both XRMB jaw pellets (incisor MNI,
#: molar MNM), or one of them (most EMA corpora have only the lower incisor).
JAW_SENSOR_SETS = ("MNI,MNM", "MNI", "MNM")
#: Least-squares solvers for the fitted jaw methods; jaxopt's sit behind one adapter.
SOLVERS = ("optimistix-lm", "optimistix-gn", "optimistix-dogleg", "jaxopt-lm", "jaxopt-gn")
#: How an untracked or mistracked pellet value is replaced during animation.
GAP_POLICIES = ("hold", "interpolate")
#: Collision handling during animation.
COLLISION_MODES = ("off", "project")
#: Which subject conformation initialization builds: from Headmeasures, or the paper's.
CONFORMATIONS = ("measures", "cassi")
#: How the subject calibration is fitted (docs/CALIBRATION.md).
CALIBRATION_METHODS = ("separate", "joint")
#: Where the tongue's back anchor points go (CASSI anchored them behind and below T4).
TONGUE_ANCHORS = ("fixed", "follow", "none")
#: The tongue's cross-section: the model's thick tongue, or CASSI's flat surface of zero
#: thickness through the four tongue pellets (paper section 5: "a flat surface with no
#: thickness").
TONGUE_SHAPES = ("thick", "flat")
#: Whole reproduction modes (``run_spec.RunSpec`` presets; docs/CASSI_MODE.md): the toolkit's
#: improved defaults, or every choice the paper made.
MODES = ("improved", "cassi")
#: Jaw region weights: CASSI's percentages (Parke's times 1.11111) or Parke's own.
JAW_WEIGHTS = ("cassi", "parke")
#: The rendered views: the paper's four and the midsagittal section (the 2D tracing view).
VIEWS = ("front", "side", "inside", "top", "midsagittal")
#: The paper's four views (a Renderer's default; ``midsagittal`` is the toolkit's 2D section).
PAPER_VIEWS = ("front", "side", "inside", "top")
#: The vocal tract beside the face (the area function and the tube's spectrum, drawn in 2D
#: from ``acoustics.tract_panels``): asked for by name, never among the default views.
TRACT_VIEW = "tract"
#: Every view a renderer draws: :data:`VIEWS` and :data:`TRACT_VIEW`.
ALL_VIEWS = (*VIEWS, TRACT_VIEW)
#: Output kinds of ``cassi animate``.
ANIMATION_SUFFIXES = (".mp4", ".gif", ".png")
#: A video's frames per second unless ``--fps`` says otherwise (about what a screen shows;
#: ``recording_video.video_frames``).
DEFAULT_FPS = 60
#: Values of a cache folder's variable (``CASSI_COMPILE_CACHE``, ``CASSI_EXPORT_CACHE``)
#: that turn the cache off.
CACHE_OFF = ("", "0", "off", "no", "none", "false")


def check_choice(what: str, value: object, choices: Sequence[str]) -> str:
    """``value`` if it is one of ``choices``; else :class:`InvalidChoiceError` naming ``what``
    and the choices."""
    if not isinstance(value, str) or value not in choices:
        raise InvalidChoiceError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")
    return value
