"""Importers for public data formats: read other people's measurements without copying them.

- :mod:`realpen.datasets.hatt`: Penn Haptic Texture Toolkit (HaTT) ARMA texture models.

May import: :mod:`realpen.errors`, :mod:`realpen.io`, :mod:`realpen.dsp` (and numpy, scipy).
Never a higher layer: a dataset reader gives a :class:`~realpen.io.recording.Recording`.
"""
