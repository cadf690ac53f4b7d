"""Unit sequences, their power spectra, principal frequencies, and the choice of units to use.

The method splits the (one-axis, high-passed) vibration into unit sequences of 100 ms and keeps
the top-N principal frequencies of each. Here a principal frequency is a spectral *peak*: a
local maximum that is also the largest value within ± ``min_separation_hz``, located to a
fraction of a bin by parabolic interpolation of the log power, so one broad peak never fills
several of the N places.
"""

from __future__ import annotations

import json
import textwrap
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from realpen.checks import (
    MAX_SUBPATTERNS,
    MAX_TOP,
    MAX_UNIT_MS,
    MAX_UNIT_SAMPLES,
    MAX_UNITS,
    MIN_UNIT_SAMPLES,
    require_choice,
    require_number,
)
from realpen.errors import ParameterError, RealPenError

__all__ = ["Analysis", "analyze", "principal_frequencies", "select_units", "fft_size",
           "require_count", "unit_samples_for", "band_edges_for", "unit_band_levels_db",
           "check_unit_count", "top_peaks", "ProgressCallback", "SELECTIONS", "FEATURE_BANDS",
           "PEAK_FLOOR_DB"]

ProgressCallback = Callable[[int, int], None]
SELECTIONS = ("stationary", "middle")
FEATURE_BANDS = 24
PEAK_FLOOR_DB = -80.0  # relative to the strongest peak of the unit; below is numerical noise
_TINY = 1e-30


@dataclass(frozen=True)
class Analysis:
    """Principal frequencies of every unit sequence of a recording, and the units selected.

    Attributes:
        rate: analysis rate in Hz.
        unit_ms: unit length in milliseconds.
        top: how many principal frequencies were asked for per unit.
        starts_s: start time of each unit in seconds, shape (units,).
        frequencies_hz: shape (units, top), strongest first; NaN where a unit has fewer peaks.
            float64, or float32 from a streamed analysis (:mod:`realpen.dsp.stream`), as are
            ``powers`` and ``band_levels_db``.
        powers: mean-square power of each peak (signal unit squared), same shape; NaN likewise.
            A sinusoid of amplitude A has power A²/2.
        band_levels_db: levels of 24 equal-width bands between fmin and fmax per unit, in dB re
            1 (recording unit)², shape (units, 24); used to judge stationarity.
        selected: indices of the units chosen for the pattern, consecutive.
        selection: ``"stationary"`` or ``"middle"``.
    """

    rate: float
    unit_ms: float
    top: int
    starts_s: np.ndarray
    frequencies_hz: np.ndarray
    powers: np.ndarray
    band_levels_db: np.ndarray
    selected: np.ndarray
    selection: str

    def __repr__(self) -> str:
        chosen = (f"units {int(self.selected[0])}–{int(self.selected[-1])}"
                  if len(self.selected) else "no units")
        return (f"Analysis({len(self.starts_s)} units of {self.unit_ms:g} ms at {self.rate:g} Hz, "
                f"top {self.top}, selected {chosen} ({self.selection}))")

    def unit(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(frequencies in Hz, powers) of one unit, NaN entries dropped, strongest first."""
        keep = np.isfinite(self.frequencies_hz[index])
        return self.frequencies_hz[index][keep], self.powers[index][keep]

    def to_json(self) -> dict:
        """The JSON report of ``realpen analyze``."""
        return self._report([self._unit_report(index) for index in range(len(self.starts_s))])

    def json_chunks(self) -> Iterator[str]:
        """The text of :func:`realpen.io.files.json_text` of :meth:`to_json`, a unit at a time.

        A day of 100 ms units is 867 k of them: as one document of Python objects it would take
        over a gigabyte, written this way no more than one unit's.
        """
        head = json.dumps(self._report([]), indent=2, allow_nan=False)
        before, after = head.split('"units": []', 1)
        yield before + '"units": ['
        for index in range(len(self.starts_s)):
            unit = json.dumps(self._unit_report(index), indent=2, allow_nan=False)
            yield ("\n" if index == 0 else ",\n") + textwrap.indent(unit, "    ")
        yield ("\n  ]" if len(self.starts_s) else "]") + after + "\n"

    def _unit_report(self, index: int) -> dict:
        freqs, powers = self.unit(index)
        # A streamed analysis may keep its values as float32: written with the shortest digits
        # that read back as the same float32, not as the float64 that holds it.
        number = (lambda v: float(str(v))) if self.powers.dtype == np.float32 else float
        return {"start_s": round(float(self.starts_s[index]), 6),
                "frequencies_hz": [round(float(f), 4) for f in freqs],
                "powers": [number(p) for p in powers]}

    def _report(self, units: list) -> dict:
        unit_samples = int(round(self.unit_ms * self.rate / 1000.0))
        # Units are whole samples: 100 ms at 1344 Hz is 134 samples (99.70 ms).
        return {"rate": self.rate, "unit_ms": self.unit_ms, "unit_samples": unit_samples,
                "unit_s_exact": unit_samples / self.rate, "top": self.top,
                "selection": self.selection, "units": units,
                "selected": [int(i) for i in self.selected]}


def require_count(parameter: str, value: int, maximum: int) -> int:
    """``value`` as an int: a whole number from 1 to ``maximum``.

    Raises:
        ParameterError: (named ``parameter``) otherwise.
    """
    require_number(parameter, value, minimum=1, maximum=maximum)
    if int(value) != value:
        raise ParameterError(parameter, f"must be a whole number, got {value:g}")
    return int(value)


def unit_samples_for(unit_ms: float, rate: float, source: object = "signal") -> int:
    """Samples in one unit sequence of ``unit_ms`` ms at ``rate`` Hz (rounded), checked to lie
    between :data:`~realpen.checks.MIN_UNIT_SAMPLES` and
    :data:`~realpen.checks.MAX_UNIT_SAMPLES`.

    Raises:
        ParameterError: (parameter ``unit_ms``) too few or too many samples; the message names
            ``source``, whose rate it is.
    """
    unit_samples = int(round(unit_ms * rate / 1000.0))
    if unit_samples < MIN_UNIT_SAMPLES:
        raise ParameterError("unit_ms", f"{unit_ms:g} ms is only {unit_samples} samples at "
                                        f"{rate:g} Hz ({source}); a unit needs at least "
                                        f"{MIN_UNIT_SAMPLES}: use longer units")
    if unit_samples > MAX_UNIT_SAMPLES:
        raise ParameterError("unit_ms", f"{unit_ms:g} ms is {unit_samples:,} samples at "
                                        f"{rate:g} Hz ({source}); a unit holds at most "
                                        f"{MAX_UNIT_SAMPLES:,}: use shorter units")
    return unit_samples


def fft_size(unit_samples: int) -> int:
    """Zero-padded FFT length for a unit: the power of two ≥ 8 × its length (and ≥ 256)."""
    return max(256, 1 << int(np.ceil(np.log2(8 * unit_samples))))


def principal_frequencies(x: np.ndarray, rate: float, unit_ms: float = 100.0, top: int = 10,
                          fmin: float = 30.0, fmax: float | None = None,
                          min_separation_hz: float | None = None,
                          progress: ProgressCallback | None = None, source: str = "signal"
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Top-N spectral peaks of every unit sequence of a one-axis signal.

    Args:
        x: signal, shape (frames,).
        rate: sampling rate in Hz.
        unit_ms: unit length in ms; the tail that does not fill a unit is ignored.
        top: peaks kept per unit (N).
        fmin, fmax: band in Hz where peaks count (fmax defaults to Nyquist).
        min_separation_hz: two peaks closer than this are one peak (default: one bin of the
            unwindowed unit, 1000 / unit_ms Hz).
        progress: called as ``progress(units_done, units_total)``.
        source: names the signal in error messages.

    Returns:
        ``(starts_s, frequencies_hz, powers, band_levels_db)`` as described in :class:`Analysis`.

    Raises:
        ParameterError: a bad ``rate``, ``unit_ms`` or ``top`` (more than
            :data:`~realpen.checks.MAX_TOP`); units of fewer than 8 or more than
            :data:`~realpen.checks.MAX_UNIT_SAMPLES` samples at this rate, or more than
            :data:`~realpen.checks.MAX_UNITS` units (parameter ``unit_ms``, naming
            ``source``).
    """
    from scipy import signal  # here: the streamed analysis imports this module without it

    require_number("rate", rate, minimum=0.0, inclusive=False)
    require_number("unit_ms", unit_ms, minimum=0.0, inclusive=False)
    top = require_count("top", top, MAX_TOP)
    unit_samples = unit_samples_for(unit_ms, rate, source)
    count = len(x) // unit_samples
    check_unit_count(count, unit_ms, source)
    nyquist = rate / 2
    fmax = nyquist if fmax is None else min(fmax, nyquist)
    nfft = fft_size(unit_samples)
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate)
    bin_hz = freqs[1]
    separation = 1000.0 / unit_ms if min_separation_hz is None else min_separation_hz
    half_width = max(1, int(round(separation / bin_hz)))
    in_band = (freqs >= fmin) & (freqs <= fmax)
    band_edges = band_edges_for(freqs, fmin, fmax)
    window = signal.get_window("hann", unit_samples)
    scale = 2.0 / window.sum() ** 2  # |X|² → mean-square power of a sinusoid (A²/2)

    starts = np.arange(count) * unit_samples / rate
    out_freqs = np.full((count, top), np.nan)
    out_powers = np.full((count, top), np.nan)
    bands = np.zeros((count, FEATURE_BANDS))
    frames = x[:count * unit_samples].reshape(count, unit_samples)
    chunk = max(1, 4_000_000 // nfft)
    for first in range(0, count, chunk):
        block = frames[first:first + chunk]
        block = block - block.mean(axis=1, keepdims=True)
        spectrum = np.fft.rfft(block * window, n=nfft, axis=1)
        power = (spectrum.real ** 2 + spectrum.imag ** 2) * scale
        peaks_f, peaks_p = top_peaks(power, in_band, half_width, top, bin_hz)
        # Sub-bin interpolation may step a hair past a band edge; the peak is still in band.
        peaks_f = np.clip(peaks_f, fmin, fmax)
        out_freqs[first:first + len(block)] = peaks_f
        out_powers[first:first + len(block)] = peaks_p
        bands[first:first + len(block)] = unit_band_levels_db(power, in_band, band_edges)
        if progress is not None:
            progress(min(first + chunk, count), count)
    return starts, out_freqs, out_powers, bands


def band_edges_for(freqs: np.ndarray, fmin: float, fmax: float) -> np.ndarray:
    """The first bin of each of the :data:`FEATURE_BANDS` equal-width bands between ``fmin``
    and ``fmax`` (Hz) on the bin frequencies ``freqs``."""
    return np.searchsorted(freqs, np.linspace(fmin, fmax, FEATURE_BANDS + 1)[:-1])


def unit_band_levels_db(power: np.ndarray, in_band: np.ndarray, band_edges: np.ndarray
                    ) -> np.ndarray:
    """Band levels in dB of each row of ``power``: the sum of its bins from each band's first
    bin (``band_edges``) to the next band's (the last band: to the end of the row)."""
    if not in_band.any():
        return np.full((len(power), FEATURE_BANDS), 10 * np.log10(_TINY))
    first = int(in_band.argmax())
    band_power = np.add.reduceat(power[:, first:], band_edges - first, axis=1)
    return 10 * np.log10(band_power[:, :FEATURE_BANDS] + _TINY)


def check_unit_count(units: int, unit_ms: float, source: object) -> None:
    """Refuse more than :data:`~realpen.checks.MAX_UNITS` units, before their arrays are
    allocated."""
    if units > MAX_UNITS:
        raise ParameterError("unit_ms", f"{source} holds {units:,} units of {unit_ms:g} ms; an "
                                        f"analysis takes at most {MAX_UNITS:,}: use longer units "
                                        f"or a shorter recording")


def _peak_bins(power: np.ndarray, judged: np.ndarray, in_band: np.ndarray, half_width: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """(rows, flat indices into ``power``) of every row's peaks, row by row (see
    :func:`top_peaks`).

    A peak rises from its left neighbour and is at least its right one: such local maxima are
    few (one per window lobe at most), so the rest of the neighbourhood and the floor are
    checked at them only, one shift at a time, rather than over every bin. A neighbour past the
    row's end counts as zero (powers are ≥ 0): its index is clipped to the end, a bin that lies
    in the neighbourhood anyway.
    """
    bins = power.shape[1]
    band = np.flatnonzero(in_band[1:-1]) + 1  # never the first or the last bin
    if not len(band):
        return np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
    first, stop = int(band[0]), int(band[-1]) + 1
    core = power[:, first:stop]
    local = core > power[:, first - 1:stop - 1]
    local &= core >= power[:, first + 1:stop + 1]
    if len(band) < stop - first:
        local &= in_band[first:stop]
    span = stop - first
    index = np.flatnonzero(local)
    row_of = index // span
    column = index - row_of * span + first
    index = row_of * bins + column
    values = power.ravel()
    peak = values[index]
    for shift in range(2, half_width + 1):
        keep = peak >= values[index - np.minimum(column, shift)]
        keep &= peak >= values[index + np.minimum(bins - 1 - column, shift)]
        row_of, column, index, peak = row_of[keep], column[keep], index[keep], peak[keep]
    floor = np.maximum(judged.max(axis=1) * 10 ** (PEAK_FLOOR_DB / 10), _TINY)
    keep = judged.ravel()[index] > floor[row_of]
    return row_of[keep], index[keep]


def top_peaks(power: np.ndarray, in_band: np.ndarray, half_width: int, top: int,
              bin_hz: float, weight: np.ndarray | None = None,
              weighted: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Strongest ``top`` peaks per row with parabolic (log-power) sub-bin interpolation.

    ``power`` is (rows, bins) of non-negative powers. A peak is a bin that rises from its left
    neighbour, is the largest within ± ``half_width`` bins, lies in ``in_band`` (never the first
    or the last bin) and is above :data:`PEAK_FLOOR_DB` of the row's strongest bin. Returns
    (frequencies in Hz, powers), each (rows, top), strongest first, NaN where a row has fewer
    peaks.

    ``weight`` (bins,), when given, is a power response the peaks are judged by: the floor and
    the order use ``power × weight``, while the peaks are found and interpolated in ``power``
    and returned unweighted (the caller weights them at their interpolated frequency). A steep
    response (a high-pass near its cutoff) would otherwise tilt a tone's window lobe and move
    its peak. ``weighted``, when given, is ``power × weight`` already computed (the caller
    needs it too); ``weight`` is then not used.
    """
    rows, bins = power.shape
    if weighted is not None:
        judged = weighted
    else:
        judged = power if weight is None else power * weight
    power = np.ascontiguousarray(power)
    judged = np.ascontiguousarray(judged)
    row_of, index = _peak_bins(power, judged, in_band, half_width)
    # Peaks are sparse (at most one in half_width + 1 bins): each row's are packed to the left
    # so that the sort looks at a few dozen candidates instead of every bin.
    counts = np.bincount(row_of, minlength=rows)
    width = max(int(counts.max(initial=0)), 1)
    slot = row_of * width + np.arange(len(index)) - (np.cumsum(counts) - counts)[row_of]
    candidates = np.full(rows * width, -np.inf)
    candidates[slot] = judged.ravel()[index]
    where = np.zeros(rows * width, dtype=np.intp)
    where[slot] = index
    candidates, where = candidates.reshape(rows, width), where.reshape(rows, width)
    take = min(top, width)
    order = np.argsort(-candidates, axis=1)[:, :take]
    valid = np.isfinite(np.take_along_axis(candidates, order, axis=1))
    index = np.take_along_axis(where, order, axis=1)[valid]  # strongest first in each row
    # The parabola through the three log powers around each peak, in natural-log ratios to
    # the peak's own bin: the vertex's offset does not depend on the logarithm's base.
    values = power.ravel()
    centre = values[index] + _TINY
    below = np.log((values[index - 1] + _TINY) / centre)
    above = np.log((values[index + 1] + _TINY) / centre)
    curvature = below + above
    offset = np.where(curvature < 0, 0.5 * (below - above) / np.where(curvature < 0, curvature, -1),
                      0.0)
    offset = np.clip(offset, -0.5, 0.5)
    frequencies = np.full((rows, top), np.nan)
    powers = np.full((rows, top), np.nan)
    frequencies[:, :take][valid] = (index % bins + offset) * bin_hz
    powers[:, :take][valid] = centre * np.exp(-0.25 * (below - above) * offset)
    return frequencies, powers


def select_units(band_levels_db: np.ndarray, count: int, selection: str = "stationary"
                 ) -> np.ndarray:
    """Choose ``count`` consecutive units, never the first or the last.

    ``"stationary"`` takes the run whose band levels vary least around the run's own mean
    (sum over bands of the variance across units, in dB²); ``"middle"`` takes the run centred
    in the recording, as the method describes.

    Args:
        band_levels_db: band levels per unit in dB, shape (units, bands) (see :class:`Analysis`).
        count: consecutive units to choose.
        selection: ``"stationary"`` or ``"middle"``.

    Returns:
        The unit indices, ascending.

    Raises:
        ParameterError: an unknown ``selection`` or a ``count`` below 1 or above
            :data:`~realpen.checks.MAX_SUBPATTERNS`.
        RealPenError: fewer than ``count + 2`` units.
    """
    require_choice("selection", selection, SELECTIONS)
    count = require_count("count", count, MAX_SUBPATTERNS)
    total = band_levels_db.shape[0]
    usable = total - 2
    if usable < count:
        raise RealPenError(f"too short: {total} units, but {count} consecutive units plus the "
                           f"dropped first and last need {count + 2}")
    if selection == "middle":
        first = 1 + (usable - count) // 2
        return np.arange(first, first + count)
    inner = band_levels_db[1:-1]
    csum = np.vstack([np.zeros((1, inner.shape[1])), np.cumsum(inner, axis=0)])
    csum2 = np.vstack([np.zeros((1, inner.shape[1])), np.cumsum(inner ** 2, axis=0)])
    mean = (csum[count:] - csum[:-count]) / count
    mean_sq = (csum2[count:] - csum2[:-count]) / count
    variance = np.maximum(mean_sq - mean ** 2, 0.0).sum(axis=1)
    first = 1 + int(np.argmin(variance))
    return np.arange(first, first + count)


def analyze(x: np.ndarray, rate: float, unit_ms: float = 100.0, top: int = 10, count: int = 15,
            selection: str = "stationary", fmin: float = 30.0, fmax: float | None = None,
            min_separation_hz: float | None = None, source: str = "signal",
            progress: ProgressCallback | None = None) -> Analysis:
    """Principal frequencies of every unit, and the ``count`` consecutive units to use.

    ``x`` should already be one axis and high-passed (see :func:`realpen.dsp.filters.prepare`).

    Args:
        x: signal, shape (frames,), in the recording's unit.
        rate: its sampling rate in Hz.
        unit_ms: unit sequence length in ms.
        top: principal frequencies kept per unit.
        count: consecutive units to select (the first and last unit are never selected).
        selection: ``"stationary"`` or ``"middle"``.
        fmin, fmax: band in Hz where peaks count (fmax: Nyquist when None).
        min_separation_hz: see :func:`principal_frequencies`.
        source: names the signal in error messages.
        progress: called as ``progress(units_done, units_total)``.

    Raises:
        ParameterError: a bad ``rate``, ``unit_ms``, ``top``, ``count`` or ``selection``
            (worded with these names, e.g. ``"unit_ms: must be > 0, got -1"``), each checked
            against its limit in :mod:`realpen.checks` before anything is allocated.
        RealPenError: a silent or constant signal (no peaks), or a signal too short for
            ``count + 2`` units.

    Example:
        >>> import numpy as np
        >>> t = np.arange(3 * 1344) / 1344
        >>> result = analyze(np.sin(2 * np.pi * 200 * t), 1344, top=1)
        >>> round(float(result.unit(5)[0][0]))
        200
    """
    require_number("rate", rate, minimum=0.0, inclusive=False)
    require_number("unit_ms", unit_ms, minimum=0.0, inclusive=False, maximum=MAX_UNIT_MS)
    top = require_count("top", top, MAX_TOP)
    count = require_count("count", count, MAX_SUBPATTERNS)
    require_choice("selection", selection, SELECTIONS)
    unit_samples = unit_samples_for(unit_ms, rate, source)
    if not np.any(np.abs(x) > 1e-12 * max(1.0, float(np.max(np.abs(x), initial=0.0)))):
        raise RealPenError(f"{source}: signal is silent or constant (no spectral peaks)")
    units = len(x) // unit_samples
    if units < count + 2:
        raise RealPenError(
            f"{source}: too short: {len(x) / rate:.3f} s holds {units} units of {unit_ms:g} ms; "
            f"{count} units plus the dropped first and last need {(count + 2) * unit_ms / 1000:g} s")
    starts, freqs, powers, bands = principal_frequencies(
        x, rate, unit_ms, top, fmin, fmax, min_separation_hz, progress, source)
    selected = select_units(bands, count, selection)
    if not np.isfinite(freqs[selected]).any():
        raise RealPenError(f"{source}: no spectral peaks between {fmin:g} Hz and "
                           f"{fmax or rate / 2:g} Hz in the selected units")
    return Analysis(rate, unit_ms, top, starts, freqs, powers, bands, selected, selection)
