"""Pen profiles: one pen's tactile pattern, sound loop, actuator and coupling, as a bundle.

Lives here: :mod:`~realpen.profile.schema` (the versioned ``profile.json``; pydantic and numpy
only), :mod:`~realpen.profile.bundle` (the in-memory :class:`PenProfile`; reading and writing
folders and zips), :mod:`~realpen.profile.build` (recordings → profile),
:mod:`~realpen.profile.registry` (the bundled and installed profiles),
:mod:`~realpen.profile.compare` (distances between pens).

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.sound`, :mod:`realpen.tactile`, :mod:`realpen.motion`,
:mod:`realpen.datasets`, :mod:`realpen.dsp`, :mod:`realpen.io`, :mod:`realpen.checks` and the
stdlib-only modules (:mod:`realpen.errors`, :mod:`realpen.validation`, :mod:`realpen.defaults`,
``realpen._version``, ``realpen._lazy``, :mod:`realpen.examples`); never :mod:`realpen.exports`
or :mod:`realpen.display`, its siblings, nor :mod:`realpen.pens` (the bundled pens are found as
package data by the package's name). This ``__init__`` imports nothing until a name is used, so
``realpen.profile.schema`` stays light.
"""

from __future__ import annotations

from realpen._lazy import lazy_attributes

__all__ = ["PenProfile", "load_profile", "save_profile", "build_profile", "list_profiles",
           "resolve_profile", "profile_locations", "ProfileMeta", "NAME_PATTERN"]

_HOMES = {"PenProfile": "bundle", "load_profile": "registry", "save_profile": "bundle",
          "build_profile": "build", "list_profiles": "registry", "resolve_profile": "registry",
          "profile_locations": "registry", "ProfileMeta": "schema", "NAME_PATTERN": "schema"}


__getattr__, __dir__ = lazy_attributes(__name__, _HOMES, __all__)
