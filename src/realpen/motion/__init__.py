"""The pen's motion and what it drives: trajectories, Eq. 1, the per-sample control signals.

Both feedbacks follow the same stroke: the sound (:mod:`realpen.sound.stroke`) and the tactile
loop (:mod:`realpen.tactile.stroke`) are rendered along one trajectory, through one coupling,
with one speed meter — the live page's. That shared ground lives here, below both.

Lives here: :mod:`~realpen.motion.trajectory` (:class:`~realpen.motion.trajectory.Trajectory`,
the columnar form of :class:`realpen.io.strokes.StrokeSample` rows, and the page's speed),
:mod:`~realpen.motion.coupling` (Eq. 1, its one-pole smoother and its fit:
:class:`~realpen.motion.coupling.Coupling`), :mod:`~realpen.motion.control` (a stroke's gain and
playback rate per output sample).

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.dsp`, :mod:`realpen.io`, :mod:`realpen.checks` and the
stdlib-only modules (:mod:`realpen.errors`, :mod:`realpen.validation`, :mod:`realpen.defaults`,
``realpen._version``, ``realpen._lazy``, :mod:`realpen.examples`) (and numpy, scipy, pydantic);
not :mod:`realpen.datasets`, its sibling. This ``__init__`` imports nothing, so that importing
one submodule does not load the others.
"""

__all__ = ["trajectory", "coupling", "control"]
