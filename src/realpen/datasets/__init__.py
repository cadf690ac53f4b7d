"""Importers for public data formats: read other people's measurements without copying them.

- :mod:`realpen.datasets.hatt`: Penn Haptic Texture Toolkit (HaTT) ARMA texture models.

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.dsp`, :mod:`realpen.io`, :mod:`realpen.checks` and the
stdlib-only modules (:mod:`realpen.errors`, :mod:`realpen.validation`, :mod:`realpen.defaults`,
``realpen._version``, ``realpen._lazy``, :mod:`realpen.examples`) (and numpy, scipy); not
:mod:`realpen.motion`, its sibling. Never a higher layer: a dataset reader gives a
:class:`~realpen.io.recording.Recording`.
"""
