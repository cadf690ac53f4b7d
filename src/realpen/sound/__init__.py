"""Auditory feedback: seamless loop units, granular textures, Eq. 1 coupling, stroke rendering.

Lives here: :mod:`~realpen.sound.unit` (what every sound unit shares: mono samples at a
checked rate, silence refused, :class:`~realpen.sound.unit.SteadyPart`),
:mod:`~realpen.sound.loop` (the one :class:`~realpen.sound.loop.SoundLoop` type,
:func:`~realpen.sound.loop.find_loop`, :func:`~realpen.sound.loop.load_sound` and the seam
measures), :mod:`~realpen.sound.granular` (textures from grains,
:func:`~realpen.sound.granular.granular_loop`), :mod:`~realpen.sound.stroke` (what a stroke
sounds like). Eq. 1 and the trajectory are :mod:`realpen.motion`'s, shared with the tactile
loop; :mod:`~realpen.sound.coupling` re-exports the coupling under its old name.

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.motion`, :mod:`realpen.datasets`, :mod:`realpen.dsp`,
:mod:`realpen.io`, :mod:`realpen.checks` and the stdlib-only modules (:mod:`realpen.errors`,
:mod:`realpen.validation`, :mod:`realpen.defaults`, ``realpen._version``, ``realpen._lazy``,
:mod:`realpen.examples`); never :mod:`realpen.tactile`, its sibling. This ``__init__`` imports
nothing, so that importing one submodule does not load the others.
"""

__all__ = ["unit", "loop", "granular", "coupling", "stroke"]
