"""The pens that ship with RealPen (pencil, ballpoint, marker) and the model that makes them.

The bundled profiles are *modelled*, not recorded: see :mod:`realpen.pens.model` and
``docs/pen-model.md``. ``scripts/make_bundled_pens.py`` regenerates them; on another machine
the floats may differ in their last bits, so they regenerate equal within tolerances and with
the same canonical version (see ``tests/test_profile.py``).

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.profile`, :mod:`realpen.exports`, :mod:`realpen.display` and
every layer below them; never :mod:`realpen.device`, its sibling. This ``__init__`` imports
nothing of RealPen (the profile registry finds the bundled folder by this package's name).
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

__all__ = ["BUNDLED_PENS", "BUNDLE_ACTUATOR", "bundled_dir"]

BUNDLED_PENS = ("pencil", "ballpoint", "marker")
BUNDLE_ACTUATOR = "lra:f0=175,q=8"  # a common LRA; rebuild for your own actuator


def bundled_dir() -> Path:
    """Folder holding the bundled profiles, one sub-folder per pen."""
    return Path(str(files(__name__) / "bundled"))
