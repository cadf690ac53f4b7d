"""Reading and writing: recordings (WAV/FLAC/OGG, CSV, NPZ), CSV tables, atomic writes, paths.

Lives here: :mod:`~realpen.io.recording` (the :class:`Recording` type and its loaders),
:mod:`~realpen.io.blocks` (recordings read block by block, whatever their length),
:mod:`~realpen.io.timegrid` (timestamped samples with dropped ones put on an even grid),
:mod:`~realpen.io.csvtable` (the one CSV reader of numeric tables), :mod:`~realpen.io.files`
(atomic, all-or-nothing outputs and WAV bytes), :mod:`~realpen.io.paths` (the user's folders).

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.checks` and the stdlib-only modules (:mod:`realpen.errors`,
:mod:`realpen.validation`, :mod:`realpen.defaults`, ``realpen._version``, ``realpen._lazy``,
:mod:`realpen.examples`) only (and numpy, soundfile, scipy). The lowest package: it imports no
other RealPen package. This ``__init__`` imports nothing, so that light modules (the
WebSocket schema) can use a part of ``io`` without loading scipy.
"""
