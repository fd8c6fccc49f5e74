"""Names of a package loaded when first used (as scikit-image's subpackages do).

A package's ``__init__`` says where each of its public names lives::

    __getattr__, __dir__, __all__ = attach(__name__, {"Progress": "gnomon.util.progress", ...})

and the module holding a name is imported the first time the name is asked for, so that importing
the package costs nothing until then (the command line starts without numpy; a scan never loads
Dask). Type checkers read the names from the package's ``if TYPE_CHECKING:`` imports.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def attach(package: str, where: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """``(__getattr__, __dir__, __all__)`` for ``package``, whose names ``where`` maps to their modules."""
    table = dict(where)

    def __getattr__(name: str) -> Any:
        if name in table:
            return getattr(importlib.import_module(table[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        import sys

        return sorted(set(vars(sys.modules[package])) | set(table))

    return __getattr__, __dir__, sorted(table)
