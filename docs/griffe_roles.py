"""Griffe extension of the API reference (mkdocs.yml): the docstrings cite other objects
with Sphinx roles (``:func:`~cassi_fit.animate.animate```), which Markdown would show as
":func:~cassi_fit..."; each becomes a code span with the name as the role's tilde asks
(``~a.b.c`` -> ``c``, ``a.b.c`` -> ``a.b.c``)."""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|obj|exc|const|ref):`(~?)([^`]+)`")


def plain(text: str) -> str:
    """``text`` with every Sphinx role written as a Markdown code span."""
    return ROLE.sub(lambda m: f"`{m[2].rsplit('.', 1)[-1] if m[1] else m[2]}`", text)


class SphinxRoles(griffe.Extension):
    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = plain(obj.docstring.value)
