"""The options of the commands that read a vibration recording, and opening it as they ask.

``--even-grid median|HZ`` puts a CSV whose time column has gaps (a phone's sensor drops
samples) on an even grid, ``--max-interpolated PCT`` bounds the share of samples interpolated
(:mod:`realpen.io.timegrid`). Without ``--even-grid`` a recording is streamed as ever; with it,
the CSV is loaded whole (the grid needs its timestamps) and what was done is printed as a note.
Only typer and the standard library are imported here; the library is imported when a command
runs.
"""

from __future__ import annotations

from pathlib import Path

import typer

from realpen.cli.common import console

__all__ = ["even_grid_option", "max_interpolated_option", "read_recording"]

DEFAULT_MAX_INTERPOLATED_PCT = 5.0  # as realpen.io.timegrid (numpy-free here: help stays fast)


def even_grid_option():
    """``--even-grid median|HZ``: put a CSV with dropped samples on an even grid."""
    return typer.Option(
        None, "--even-grid", metavar="median|HZ",
        help="A CSV whose time column has gaps (a phone's sensor drops samples): interpolate "
             "it onto an even grid at its median rate (median) or at HZ, reporting the share "
             "interpolated and the longest gap. Without it such a file is refused.")


def max_interpolated_option():
    """``--max-interpolated PCT``: the most of a recording ``--even-grid`` may interpolate."""
    return typer.Option(
        DEFAULT_MAX_INTERPOLATED_PCT, "--max-interpolated", metavar="PCT",
        help="With --even-grid: refuse the file when more than PCT % of its samples are "
             "missing.")


def read_recording(path: Path, rate: float | None, even_grid: str | None,
                   max_interpolated_pct: float, *, stream: bool = True):
    """The recording at ``path`` as a command reads it: streamed (``stream=True``: a
    :class:`~realpen.io.blocks.RecordingStream`) or loaded, or, with ``even_grid``, loaded whole
    onto the grid (a :class:`~realpen.io.recording.Recording`, or an
    :class:`~realpen.io.blocks.ArrayStream` of it when a stream is asked for), with a note
    saying how much was interpolated.

    Args:
        path: the recording.
        rate: the rate in Hz of a CSV with no time column (the command's ``--rate`` or
            ``--input-rate``).
        even_grid: ``--even-grid`` as typed (None: not given).
        max_interpolated_pct: ``--max-interpolated``.
        stream: a stream for :func:`realpen.dsp.stream.analyze_stream` (else a recording,
            which the tactile pipeline analyses in memory).
    """
    if even_grid is None:
        if stream:
            from realpen.io.blocks import open_stream

            return open_stream(path, rate=rate)
        from realpen.io.recording import load_recording

        return load_recording(path, rate=rate)
    from realpen.io.recording import load_recording

    recording = load_recording(path, rate=rate, even_grid=even_grid,
                               max_interpolated_pct=max_interpolated_pct)
    console.print(f"note: {path}: {recording.history[-1]}")
    if not stream:
        return recording
    from realpen.io.blocks import ArrayStream

    return ArrayStream(recording.samples, recording.rate, recording.axes, source=str(path),
                       units=recording.units)
