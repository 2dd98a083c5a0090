"""One status vocabulary for per-frame and per-recording results.

Jaw fits, animation frames and evaluation rows report what happened as a :class:`Status`
(an ``IntEnum``: arrays carry the integer, tables print :attr:`Status.label`). Where a
result cannot be computed at all, the library raises a :class:`~cassi_fit.errors.CassiError`
instead; inside traced code a status value is returned, never an exception.
"""

from __future__ import annotations

import enum


class Status(enum.IntEnum):
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
    #: a value flagged by the mistrack detector (``quality.detect_mistracks``), not used.
    MISTRACKED = 8
    #: a whole recording that could not be processed (its one-line error is kept beside).
    FAILED = 9

    @property
    def label(self) -> str:
        """The word written in tables: ``"ok"``, ``"pivot-undefined"``, ..."""
        return self.name.lower().replace("_", "-")


#: ``int -> label`` for every status, for tables written from integer arrays.
STATUS_LABELS = {int(s): s.label for s in Status}
