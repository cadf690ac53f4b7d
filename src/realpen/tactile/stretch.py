"""The stretch of a recording a pattern is made of, found in memory or by streaming the file.

A pattern needs two things from its recording: which consecutive units to use (the analysis
chooses them) and the prepared samples of those units (their peaks, and for
``model="sines+residual"`` their residual). :func:`locate` gives both as a :class:`Stretch`:

- **In memory** (a :class:`~realpen.io.recording.Recording` or an array): the whole recording is
  prepared (:func:`realpen.dsp.filters.prepare`: DFT321, optional resampling, high-pass) and
  analysed (:func:`realpen.dsp.spectrum.analyze`), as the method describes. Memory grows with
  the recording (about 700 MiB an hour of 3-axis 1344 Hz data) and the in-memory sample limit
  applies.
- **From a file** (a path or a :class:`~realpen.io.blocks.RecordingStream`): the recording is
  analysed as it streams past (:func:`realpen.dsp.stream.analyze_stream`), which chooses the
  stretch holding one block and the per-unit results; then only the stretch and
  :data:`MARGIN_S` on each side are read and prepared as in memory, so the filters' edges and
  the excerpt's DFT321 wrap-around stay outside the units used, and each selected unit's peaks
  are found in those prepared samples by the same arithmetic as in memory
  (:func:`realpen.dsp.spectrum.principal_frequencies`). Memory is flat in the recording's
  length (a day: about 100 MB of per-unit results); resampling (``analysis_rate``) is the one
  case still done in memory, because the streamed analysis works at the file's rate.

Both choose the same units: the stationary run is judged on the streamed analysis's estimate
(the axes' summed unit spectra) in memory too (:func:`realpen.dsp.stream.streamed_selection`),
so a recording gives the same stretch read either way. Given the same stretch, the peaks differ
only by the DFT321 of an excerpt against that of the whole recording
(``tests/test_tactile_stream.py`` measures it).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from realpen.dsp.spectrum import Analysis, ProgressCallback, analyze, principal_frequencies
from realpen.io.blocks import ArrayStream, RecordingStream, open_stream
from realpen.io.recording import Recording, as_recording, load_recording
from realpen.tactile.conditions import TactileParams

__all__ = ["Stretch", "locate", "MARGIN_S"]

MARGIN_S = 1.0
"""Seconds read on each side of a streamed stretch: they keep the edges of the zero-phase
high-pass (which settles within tens of ms) and the seam of the excerpt's DFT321 (which is
circular) away from the units used. The DFT321 of an excerpt still differs from that of the
whole recording throughout (see the module doc)."""


@dataclass(frozen=True)
class Stretch:
    """The analysis of a recording and the prepared samples around its selected units.

    Attributes:
        analysis: per-unit results of the whole recording and the selected units (unit
            indices count from the recording's first frame).
        mono: the prepared one-axis signal from frame ``offset`` of the (prepared) recording on,
            covering at least the selected units.
        rate: the prepared signal's rate in Hz (the analysis rate).
        offset: the frame of the prepared recording where ``mono`` starts.
        source: the recording's name in messages.
        provenance: ``path``, ``sha256``, ``rate_hz``, ``axes``, ``units``, ``frames`` (of the
            whole recording) and ``history`` (the steps that made ``mono``).
        unit_peaks: for a streamed stretch of one unit per sub-pattern, (frequencies in Hz,
            powers) of each selected unit found in ``mono`` (float64); empty in memory, where the
            analysis holds them. These are the peaks the pattern is made of; a streamed
            ``analysis`` keeps its own estimate for every unit (the axes' powers summed, float32),
            which for the selected units differs slightly from them.
    """

    analysis: Analysis
    mono: np.ndarray
    rate: float
    offset: int
    source: str
    provenance: dict
    unit_peaks: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    @property
    def unit_samples(self) -> int:
        """Samples per analysis unit."""
        return int(round(self.analysis.unit_ms * self.rate / 1000.0))

    def peaks(self, unit: int) -> tuple[np.ndarray, np.ndarray]:
        """(frequencies in Hz, powers) of one selected unit, strongest first, NaN dropped."""
        if unit in self.unit_peaks:
            return self.unit_peaks[unit]
        return self.analysis.unit(unit)

    def samples(self, first_unit: int, last_unit: int) -> np.ndarray:
        """The prepared samples of units ``first_unit`` to ``last_unit`` (inclusive)."""
        size = self.unit_samples
        return self.mono[first_unit * size - self.offset:(last_unit + 1) * size - self.offset]


def locate(recording, params: TactileParams, *, input_rate: float | None = None,
           progress: ProgressCallback | None = None) -> Stretch:
    """Analyse a recording and prepare the samples of the stretch its pattern is made of.

    Args:
        recording: a :class:`~realpen.io.recording.Recording` or an array (with
            ``input_rate``) — analysed in memory — or a path or a
            :class:`~realpen.io.blocks.RecordingStream` — streamed (see the module doc; in
            memory when ``params.analysis_rate`` asks for resampling).
        params: the pattern's parameters (axis, high-pass, unit and counts, selection).
        input_rate: sampling rate in Hz of an array, or of a CSV with no time column.
        progress: called as ``progress(units_done, units_total)`` during the analysis.

    Raises:
        ParameterError: a bad parameter.
        RealPenError: a problem with the recording (damaged, too short, silent, …), naming it.
    """
    count = params.subpatterns * params.units_per_subpattern
    if isinstance(recording, (str, os.PathLike)) and params.analysis_rate is None:
        recording = open_stream(recording, rate=input_rate)
    if isinstance(recording, RecordingStream) and params.analysis_rate is None:
        return _streamed(recording, params, count, progress)
    if isinstance(recording, ArrayStream):
        recording = Recording(recording.samples, recording.rate, recording.axes, recording.units,
                              recording.source)
    elif isinstance(recording, RecordingStream):
        recording = replace(load_recording(recording.source, rate=recording.rate),
                            units=recording.units)
    elif isinstance(recording, (str, os.PathLike)):
        recording = load_recording(recording, rate=input_rate)
    recording = as_recording(recording, input_rate, rate_parameter="input_rate",
                             data_parameter="recording")
    return _in_memory(recording, params, count, progress)


def _in_memory(recording: Recording, params: TactileParams, count: int,
               progress: ProgressCallback | None) -> Stretch:
    from realpen.dsp.filters import prepare
    from realpen.dsp.stream import streamed_selection

    prepared = prepare(recording, params.axis, params.analysis_rate, params.highpass_hz)
    analysis = analyze(prepared.mono, prepared.rate, params.selection_unit_ms, params.top, count,
                       params.selection, fmin=params.highpass_hz, fmax=params.fmax_hz,
                       source=recording.source, progress=progress)
    # The units a streamed file selects (realpen.dsp.stream): in memory or not, the same pattern.
    analysis = streamed_selection(recording, analysis, axis=params.axis,
                                  analysis_rate=params.analysis_rate,
                                  highpass_hz=params.highpass_hz, fmin=params.highpass_hz,
                                  fmax=params.fmax_hz)
    return Stretch(analysis, prepared.mono, prepared.rate, 0, recording.source,
                   _provenance(recording, int(recording.samples.shape[0]), prepared.history))


def _streamed(stream: RecordingStream, params: TactileParams, count: int,
              progress: ProgressCallback | None) -> Stretch:
    from realpen.dsp.filters import prepare
    from realpen.dsp.stream import analyze_stream
    from realpen.io.files import sha256_of

    analysis = analyze_stream(stream, unit_ms=params.selection_unit_ms, top=params.top,
                              count=count, selection=params.selection, fmin=params.highpass_hz,
                              fmax=params.fmax_hz, highpass_hz=params.highpass_hz,
                              axis=params.axis, keep_bands=False, progress=progress)
    rate, size = stream.rate, int(round(params.selection_unit_ms * stream.rate / 1000.0))
    first, last = int(analysis.selected[0]), int(analysis.selected[-1])
    margin = math.ceil(MARGIN_S * 1000.0 / params.selection_unit_ms)
    lead = min(margin, first)
    start, stop = (first - lead) * size, min((last + 1 + margin) * size, int(stream.frames))
    excerpt = Recording(stream.read(start, stop), rate, stream.axes, stream.units,
                        str(stream.source))
    prepared = prepare(excerpt, params.axis, None, params.highpass_hz)
    unit_peaks = {}
    if params.units_per_subpattern == 1:  # (D–F find their peaks in the joined units instead)
        # The selected units' peaks by the in-memory arithmetic, on the prepared excerpt's units.
        units = (stop - start) // size
        _, freqs, powers, _ = principal_frequencies(
            prepared.mono[:units * size], rate, params.selection_unit_ms, params.top,
            params.highpass_hz, params.fmax_hz, source=excerpt.source)
        for unit in range(first, last + 1):
            row = unit - first + lead
            keep = np.isfinite(freqs[row])
            unit_peaks[unit] = (freqs[row][keep], powers[row][keep])
    path = str(stream.source)
    history = (f"stretch:{start / rate:.6f}-{stop / rate:.6f}s", *prepared.history)
    provenance = _provenance(excerpt, int(stream.frames), history)
    provenance["sha256"] = None if isinstance(stream, ArrayStream) else sha256_of(path)
    return Stretch(analysis, prepared.mono, rate, start, path, provenance, unit_peaks)


def _provenance(recording: Recording, frames: int, history) -> dict:
    return {"path": recording.source, "sha256": recording.sha256, "rate_hz": recording.rate,
            "axes": list(recording.axes), "units": recording.units, "frames": frames,
            "history": list(history)}
