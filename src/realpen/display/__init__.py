"""Figures with matplotlib: analyses, actuators, patterns, sound loops and profiles.

Every function draws into a given ``ax`` (or makes its own figure when ``ax`` is None), returns
what it drew on, and changes no global matplotlib state: no backend switch, no ``pyplot``
figure closed that it did not open.

May import: every library layer (io, dsp, tactile, sound, profile); never live or cli.
"""
