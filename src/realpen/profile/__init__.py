"""Pen profiles: one pen's tactile pattern, sound loop, actuator and coupling, as a bundle.

Lives here: :mod:`~realpen.profile.schema` (the versioned ``profile.json``),
:mod:`~realpen.profile.bundle` (reading and writing folders and zips),
:mod:`~realpen.profile.build` (recordings → profile), :mod:`~realpen.profile.registry` (the
bundled and installed profiles), :mod:`~realpen.profile.compare` (distances between pens).

May import: :mod:`realpen.errors`, :mod:`realpen.io`, :mod:`realpen.dsp`,
:mod:`realpen.tactile`, :mod:`realpen.sound`, :mod:`realpen.pens` (bundled data only).
"""
