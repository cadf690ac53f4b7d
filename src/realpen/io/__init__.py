"""Reading and writing: recordings (WAV/FLAC/OGG, CSV, NPZ), CSV tables, atomic writes, paths.

Lives here: :mod:`~realpen.io.recording` (the :class:`Recording` type and its loaders),
:mod:`~realpen.io.blocks` (recordings read block by block, whatever their length),
:mod:`~realpen.io.csvtable` (the one CSV reader of numeric tables), :mod:`~realpen.io.files`
(atomic, all-or-nothing outputs and WAV bytes), :mod:`~realpen.io.paths` (the user's folders).

May import: :mod:`realpen.errors` only (and numpy, soundfile, scipy). The bottom layer; nothing
here imports another RealPen package. This ``__init__`` imports nothing, so that light modules
(the WebSocket schema) can use a part of ``io`` without loading scipy.
"""
