"""A package's names imported on first use (PEP 562): the ``__getattr__`` and ``__dir__``
of a package whose ``__init__`` maps each public name to the submodule that defines it,
so that importing the package imports none of them (``cassi_fit.corpus``,
``cassi_fit.ema``)."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, MutableMapping


def lazy_names(package: str, names: Mapping[str, str],
               namespace: MutableMapping[str, object]
               ) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the package ``package`` (its ``__name__``):
    ``names`` maps each public name to its submodule (relative, ``"._items"``), and a name
    read is imported from it once and kept in ``namespace`` (the package's ``globals()``)."""

    def __getattr__(name: str) -> object:
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module, package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(names))

    return __getattr__, __dir__
