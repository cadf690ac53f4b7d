"""Auditory feedback: seamless loop units, granular textures, Eq. 1 coupling, stroke rendering.

Lives here: :mod:`~realpen.sound.loop` (the one :class:`~realpen.sound.loop.SoundLoop` type,
:func:`~realpen.sound.loop.find_loop`, :func:`~realpen.sound.loop.load_sound` and the seam
measures), :mod:`~realpen.sound.granular` (textures from grains,
:func:`~realpen.sound.granular.granular_loop`), :mod:`~realpen.sound.coupling` (Eq. 1, its
smoother and its fit), :mod:`~realpen.sound.stroke` (what a stroke sounds like; the columnar
:class:`~realpen.sound.stroke.Trajectory` of :class:`realpen.io.strokes.StrokeSample` rows).

May import: :mod:`realpen.errors`, :mod:`realpen.io`, :mod:`realpen.dsp`. This ``__init__``
imports nothing, so that importing one submodule does not load the others.
"""

__all__ = ["loop", "granular", "coupling", "stroke"]
