"""The status vocabulary: per-frame and per-recording results, solvers, the files beside a
recording, labelled segments. Every status word a table or a report prints is a member's
``.label`` here.

Jaw fits, animation frames and evaluation rows report what happened as a :class:`Status`
(an ``IntEnum``: arrays carry the integer, tables print :attr:`Status.label`, the one home
of the words). Where a result cannot be computed at all, the library raises a
:class:`~cassi_fit.errors.CassiError` instead; inside traced code a status value is
returned, never an exception. How an iterative solve ended is a :class:`SolverResult`
(optimistix's ``RESULTS``, and jaxopt's state, mapped to a few values of our own), so a fit
that did not converge says why.
"""

from __future__ import annotations

import enum


class _Labelled(enum.IntEnum):
    @property
    def label(self) -> str:
        """The word written in tables: ``"ok"``, ``"pivot-undefined"``, ..."""
        return self.name.lower().replace("_", "-")


class Status(_Labelled):
    """What happened to one frame (or one recording)."""

    OK = 0
    #: jaw: theta == 0 exactly, pure translation, the pivot is at infinity.
    PIVOT_UNDEFINED = 1
    #: jaw: the two jaw pellets coincide in the reference or the current frame.
    DEGENERATE = 2
    #: a NaN or infinite coordinate (an untracked pellet that was not repaired).
    NON_FINITE = 3
    #: jaw fits: a frame excluded by ``valid``; its values are interpolated.
    INVALID_FRAME = 4
    #: a solver did not report success.
    NOT_CONVERGED = 5
    #: animation: an untracked value was held at its last good value.
    HELD = 6
    #: animation: an untracked value was interpolated between good neighbours.
    INTERPOLATED = 7
    #: a value flagged by the mistrack detector (``mistracks.detect_mistracks``), not used.
    MISTRACKED = 8
    #: a whole recording that could not be processed (its one-line error is kept beside).
    FAILED = 9


class LengthFit(_Labelled):
    """How a file beside a recording (its sound, its labels) fits the recording's length
    (``sound.check_sound``, ``labels.check_labels``; their ``status`` is the label)."""

    OK = 0
    #: labels: a unit mix-up explains their span (ms for s, samples for s, ...).
    UNITS = 1
    #: labels: intervals start after the recording ends.
    PAST_END = 2
    #: sound: the header's sample rate is likely wrong.
    RATE = 3
    #: sound: shorter than the pellets (cut).
    SHORTER = 4
    #: sound: longer than the pellets.
    LONGER = 5


class SegmentStatus(_Labelled):
    """What a labelled segment's row measured (``labels.segment_summary``)."""

    OK = 0
    #: no frame of the recording lies inside the segment.
    NO_FRAMES = 1
    #: no frame inside has a fitted jaw.
    JAW_UNTRACKED = 2
    #: no frame inside has both lips tracked.
    LIPS_UNTRACKED = 3


#: The statuses of a frame whose motion was fitted from its own data (the jaw fits'
#: usable frames): every other frame's values are interpolated or held.
FITTED = (Status.OK, Status.PIVOT_UNDEFINED)


def fitted(status):
    """Where ``status`` (an array of :class:`Status` values) is one of :data:`FITTED`."""
    import numpy as np

    return np.isin(np.asarray(status), [int(s) for s in FITTED])


class SolverResult(_Labelled):
    """How an iterative least-squares solve ended (arrays carry the integer; ``.label`` is
    the table word). A frame or recording whose solve was not SUCCESSFUL gets the status
    NOT_CONVERGED; this says which failure it was."""

    #: converged: the solver's own test, or a Gauss-Newton step from the answer would gain
    #: less than the cost can resolve
    SUCCESSFUL = 0
    #: the step budget (``max_steps``) ran out first
    MAX_STEPS_REACHED = 1
    #: the iteration diverged (optimistix's ``nonlinear_divergence``)
    NONLINEAR_DIVERGENCE = 2
    #: a linear solve inside the iteration failed (a singular or ill-posed system)
    SINGULAR = 3
    #: a NaN or infinite value appeared in the iteration
    NON_FINITE = 4
