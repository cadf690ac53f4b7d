"""Lazy package attributes: a name is imported from its home module on first use.

Packages keep their ``__init__`` free of imports so that a light module (the WebSocket schema,
the help of the ``realpen`` command) never pays for numpy, scipy or soundfile it does not use.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Collection, Mapping

__all__ = ["lazy_attributes"]


def lazy_attributes(package: str, homes: Mapping[str, str], public: list[str],
                    submodules: Collection[str] = ()
                    ) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """Module-level ``__getattr__`` and ``__dir__`` for ``package``.

    A name is imported once: it is then set on the package, so the next access is a plain
    attribute lookup.

    Args:
        package: the package's ``__name__``.
        homes: public name → the module (relative to ``package``, dotted) that defines it.
        public: the package's ``__all__``.
        submodules: sub-modules (relative names) that are attributes of the package on first
            use, without an import statement (``realpen.display``).

    >>> getattr_, dir_ = lazy_attributes("realpen.tactile", {"CONDITIONS": "conditions"},
    ...                                  ["CONDITIONS"])
    >>> sorted(getattr_("CONDITIONS"))
    ['A', 'B', 'C', 'D', 'E', 'F']
    """

    def __getattr__(name: str) -> object:
        if name in homes:
            value = getattr(importlib.import_module(f"{package}.{homes[name]}"), name)
            setattr(sys.modules[package], name, value)
            return value
        if name in submodules:
            return importlib.import_module(f"{package}.{name}")  # the import sets the attribute
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(public))

    return __getattr__, __dir__
