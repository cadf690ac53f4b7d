"""Signal processing: DFT321, resampling and filters, unit spectra, peaks, tracks, waveform measures.

Lives here: :mod:`~realpen.dsp.filters` (axes to one, resampling, zero-phase high-pass,
:func:`prepare`), :mod:`~realpen.dsp.spectrum` (unit sequences, principal frequencies, the
choice of units), :mod:`~realpen.dsp.stream` (the same analysis streamed block by block, each
unit's DFT321 from its axes' unit spectra), :mod:`~realpen.dsp.tracks` (frequency tracks
across sub-patterns), :mod:`~realpen.dsp.waveform_measures` (MPEG PSNR, SNR, ST-SIM and SPQI of
a stage that must keep the waveform: export round trips, resampling, the pen's playback).

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.io`, :mod:`realpen.checks` and the stdlib-only modules
(:mod:`realpen.errors`, :mod:`realpen.validation`, :mod:`realpen.defaults`,
``realpen._version``, ``realpen._lazy``, :mod:`realpen.examples`). Never a higher layer.
"""
