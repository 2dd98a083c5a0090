"""The toolkit's own error types.

Every problem with a user's input surfaces as a :class:`CassiError` (or a subclass) whose
message names the file and, where there is one, the line. The command line prints that
message as one line and exits non-zero; library users can catch ``CassiError``.
"""

from __future__ import annotations

from os import PathLike


class CassiError(Exception):
    """Base class of every error the toolkit raises on purpose."""


class DataFormatError(CassiError, ValueError):
    """A data file that does not follow its format.

    ``path`` and ``line`` (1-based, or ``None`` for a whole-file problem) are kept as
    attributes; the message reads ``path:line: what is wrong``.
    """

    def __init__(self, path: str | PathLike | None, line: int | None, message: str):
        self.path = None if path is None else str(path)
        self.line = line
        self.reason = message
        where = self.path if self.path is not None else "<input>"
        if line is not None:
            where = f"{where}:{line}"
        super().__init__(f"{where}: {message}")


class MissingDataError(CassiError):
    """Data the requested computation needs is absent (e.g. jaw pellets never tracked)."""


class DegenerateGeometryError(CassiError, ValueError):
    """Geometry for which the requested quantity does not exist (coincident points, ...)."""


class OutputExistsError(CassiError, FileExistsError):
    """Refusal to overwrite a file: an input file, or an existing output without overwrite."""


class RenderingUnavailableError(CassiError):
    """No offscreen OpenGL (EGL or OSMesa) could be initialised."""


class InvalidChoiceError(CassiError, ValueError):
    """An option value outside its vocabulary (:mod:`cassi_fit.options`); one type wherever
    the choice is checked, library or command line."""
