"""Lazy package attributes: a name is imported from its home module on first use.

Packages keep their ``__init__`` free of imports so that a light module (the WebSocket schema,
the help of the ``realpen`` command) never pays for numpy, scipy or soundfile it does not use.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping

__all__ = ["lazy_attributes"]


def lazy_attributes(package: str, homes: Mapping[str, str], public: list[str]
                    ) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """Module-level ``__getattr__`` and ``__dir__`` for ``package``.

    Args:
        package: the package's ``__name__``.
        homes: public name → the sub-module (relative to ``package``) that defines it.
        public: the package's ``__all__``.

    >>> getattr_, dir_ = lazy_attributes("realpen.tactile", {"CONDITIONS": "conditions"},
    ...                                  ["CONDITIONS"])
    >>> sorted(getattr_("CONDITIONS"))
    ['A', 'B', 'C', 'D', 'E', 'F']
    """

    def __getattr__(name: str) -> object:
        if name in homes:
            return getattr(importlib.import_module(f"{package}.{homes[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(public)

    return __getattr__, __dir__
