"""Auditory feedback: seamless loop units, granular textures, Eq. 1 coupling, stroke rendering.

Lives here: :mod:`~realpen.sound.loop` (the one :class:`SoundLoop` type, loop-unit search and
seam measures), :mod:`~realpen.sound.granular` (textures from grains), :mod:`~realpen.sound.coupling`
(Eq. 1, its smoother and its fit), :mod:`~realpen.sound.stroke` (what a stroke sounds like).

May import: :mod:`realpen.errors`, :mod:`realpen.io`, :mod:`realpen.dsp`.
"""
