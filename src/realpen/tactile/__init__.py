"""Tactile feedback: the actuator, the tactile pattern, its synthesis and the study conditions.

Lives here:

- :mod:`~realpen.tactile.actuator` — the one :class:`Actuator` type (model or measured
  response |H(f)|) and the equalising weighting w(f) ∝ 1/|H(f)|;
- :mod:`~realpen.tactile.pattern` — the one :class:`TactilePattern` type and its
  :class:`Component` sinusoids (what ``profile.json`` stores and every export reads);
- :mod:`~realpen.tactile.synthesis` — superposition per sub-pattern and the crossfades;
- :mod:`~realpen.tactile.conditions` — :class:`TactileParams` and the study conditions A–F;
- :mod:`~realpen.tactile.build` — the pipeline from a recording to a pattern
  (:func:`build_pattern`, :func:`tactile_pattern`).

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.motion`, :mod:`realpen.datasets`, :mod:`realpen.dsp`,
:mod:`realpen.io`, :mod:`realpen.checks` and the stdlib-only modules (:mod:`realpen.errors`,
:mod:`realpen.validation`, :mod:`realpen.defaults`, ``realpen._version``, ``realpen._lazy``,
:mod:`realpen.examples`); never :mod:`realpen.sound`, its sibling (what both need is
:mod:`realpen.motion`'s). The types, synthesis and conditions need numpy alone, so the profile
schema stays light. This ``__init__`` imports nothing until a name is used.
"""

from __future__ import annotations

from realpen._lazy import lazy_attributes

__all__ = ["Actuator", "parse_actuator", "weighting", "Component", "TactilePattern",
           "synthesize", "TactileParams", "CONDITIONS", "build_pattern", "tactile_pattern"]

_HOMES = {"Actuator": "actuator", "parse_actuator": "actuator", "weighting": "actuator",
          "Component": "pattern", "TactilePattern": "pattern", "synthesize": "synthesis",
          "TactileParams": "conditions", "CONDITIONS": "conditions",
          "build_pattern": "build", "tactile_pattern": "build"}


__getattr__, __dir__ = lazy_attributes(__name__, _HOMES, __all__)
