"""Tactile feedback: the actuator, the tactile pattern, its synthesis and the study conditions.

Lives here: :mod:`~realpen.tactile.actuator` (the one :class:`Actuator` type and the weighting
w(f) ∝ 1/|H(f)|), :mod:`~realpen.tactile.pattern` (the one :class:`TactilePattern` type, its
parameters, the study conditions A–F and the pipeline that builds it).

May import: :mod:`realpen.errors`, :mod:`realpen.io`, :mod:`realpen.dsp`.
"""
