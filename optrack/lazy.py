"""Names a package exports but imports only on first use (PEP 562).

A package whose ``__init__`` would otherwise import heavy modules (open3d, scipy)
declares where each exported name lives; importing a light module of the package,
such as its ``cli.py`` for ``optrack --help``, then loads nothing else.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(package: str, homes: Mapping[str, str]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package``: each name of ``homes`` is imported
    from its module (``{"PeopleDetector": "optrack.detection.pipeline"}``) when first used."""

    def __getattr__(name: str) -> Any:
        try:
            module = homes[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        return getattr(importlib.import_module(module), name)

    return __getattr__
