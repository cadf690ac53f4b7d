"""The analysis of a recording streamed in blocks: every unit's DFT321 spectrum from its axes.

:func:`realpen.dsp.spectrum.analyze` works on a prepared signal: the axes combined by a DFT321
of the *whole* recording, a zero-phase high-pass over the whole of it, then each unit's padded
spectrum. Here each 100 ms unit is analysed on its own, in blocks, so memory does not grow with
the recording (only the per-unit results do) and the work is one short FFT per unit and axis:

1. per unit and axis: remove the unit's trend up to a parabola (its mean, and the slow hand
   motion the whole-signal high-pass would have removed before any window), apply the Hann
   window, ``rfft`` zero-padded to :func:`unit_fft_size` (the power of two ≥ 1.5 times the
   unit: 256 points for 134 samples). The trend's removal is linear, so it is folded into the
   windowing: the windowed samples, less the windowed polynomials weighted by the trend's
   coefficients (one matrix product for a whole batch of units and axes), are written straight
   into the zero-padded FFT input; the window carries the power scale;
2. DFT321: the unit's power spectrum is the sum over the axes of ``|U_i(f)|²`` — exactly the
   spectral energy the DFT321 signal keeps (Landin et al., 2010), without its phase, which no
   power spectrum uses (squared and summed over the axes in one pass);
3. the 30 Hz high-pass as its power response: a 4th-order Butterworth run forward and backward
   (:func:`realpen.dsp.filters.highpass`) scales a tone's power by ``|H(f)|⁴`` at its own
   frequency. Peaks are found in the unfiltered unit spectrum, ranked by their filtered power
   and weighted at their interpolated frequency; the band levels and the silence check use the
   weighted spectrum;
4. the same peak picking (:func:`realpen.dsp.spectrum.top_peaks`), the same band levels and
   the same choice of units as :func:`realpen.dsp.spectrum.principal_frequencies` and
   :func:`realpen.dsp.spectrum.select_units` (the stationary run found as the units stream
   past, with the same arithmetic).

How far this is from the whole-signal method (``tests/test_stream_analysis.py`` holds the
measurements): a tone's peak within 0.6 Hz and 0.75 dB on weak noise, 0.2 Hz and 0.2 dB just
above the cutoff; on the bundled example 98.5 % of the top five peaks within 2 Hz, their powers
0.05 dB apart in the median and 1 dB at the 99th percentile. Noise-like parts of a unit differ
more, because the two are different estimates: the whole-signal DFT321 gives one noise
realisation per unit, the sum of the axes' powers averages three. The padding alone finds a pure
tone within 0.003 of an unpadded bin and 0.02 dB.

Which units are selected must not depend on how a recording is read: judged on the two
estimates, a recording stationary throughout could have its steadiest run a few units apart
(the bundled example: units 97–111 in memory, 100–114 streamed). So the stationary run is
always judged here: the in-memory analyses (:func:`realpen.analyze`, and
:func:`realpen.tactile.stretch.locate` for :func:`realpen.tactile_pattern`) keep the
whole-signal method's peaks and take their selection from :func:`streamed_selection`, so
``realpen analyze``, ``realpen tactile`` and ``rp.analyze`` select the same units.

``axis="magnitude"`` is done per unit too: the Euclidean norm of each frame is a per-frame
quantity, and the unit's own trend replaces the recording's mean (the high-pass removes both).

Per-unit results are stored as float32 by default (``dtype``): a day at 1344 Hz is 867 k units,
whose frequencies, powers and band levels take 150 MB so, twice that as float64.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from realpen.checks import MAX_SUBPATTERNS, MAX_TOP, MAX_UNIT_MS, MAX_UNITS, require_choice, require_number
from realpen.dsp.spectrum import (
    FEATURE_BANDS,
    SELECTIONS,
    Analysis,
    ProgressCallback,
    band_edges_for,
    check_unit_count,
    require_count,
    top_peaks,
    unit_band_levels_db,
    unit_samples_for,
)
from realpen.errors import ParameterError, RealPenError, fail
from realpen.io.blocks import ArrayStream, RecordingStream
from realpen.io.recording import AXIS_CHOICES, Recording

__all__ = ["analyze_stream", "analyze_units", "streamed_selection", "combined_name",
           "unit_fft_size", "UNIT_BATCH", "SILENCE_DB", "TREND_ORDER"]

UNIT_BATCH = 512
"""Units transformed together: large enough to amortise numpy's per-call cost (some thirty
calls a batch), small enough that a batch's work space stays a few megabytes (512 × 3 axes ×
256 points), allocated once per analysis."""

SILENCE_DB = -80.0  # as realpen.dsp.filters.SILENCE_DB: vibration this far below the peak is none
_HIGHPASS_ORDER = 4  # one pass of realpen.dsp.filters.highpass (gain squares thrice)
TREND_ORDER = 2
"""Degree of the polynomial trend removed from each unit with a high-pass (2: a parabola);
without one (``highpass_hz=0``) only the mean is removed."""


def unit_fft_size(unit_samples: int) -> int:
    """FFT length of a unit: the power of two ≥ 1.5 times its samples (at least 16); 256 for
    the method's 134 samples.

    With at least 1.5 bins per unpadded bin, the parabola through the log powers of the three
    highest bins of a Hann-windowed tone locates it within 0.005 of an unpadded bin and its
    power within 0.05 dB (0.003 bins and 0.02 dB at 134 samples in 256 points, 0.03 Hz at
    1344 Hz); more padding gains nothing the method can use (the tone's own image at negative
    frequency already limits it to 0.0015 bins), less loses it quickly (0.02 bins and 0.4 dB
    without padding; 0.0047 bins and 0.058 dB at 192 points).

    The power of two is also the fastest length that keeps this accuracy: numpy's FFT costs
    about as much at 256 points as at any other length from 1.5 units up (216, 225, 240 and
    250 measured within the noise of a shared machine, 201 three times as long), and a tenth
    of the streamed analysis's time at most separates any of them.
    """
    return max(16, 1 << int(np.ceil(np.log2(1.5 * unit_samples))))


class _Plan:
    """Everything the unit spectra need that depends only on the rate, the unit and the band."""

    def __init__(self, rate: float, unit_samples: int, unit_ms: float, top: int, fmin: float,
                 fmax: float, highpass_hz: float, min_separation_hz: float | None,
                 combine: str | int, axes: int = 1):
        self.unit_samples, self.top, self.combine = unit_samples, top, combine
        self.fmin, self.fmax = fmin, fmax
        self.nfft = unit_fft_size(unit_samples)
        freqs = np.fft.rfftfreq(self.nfft, 1.0 / rate)
        self.bin_hz = float(freqs[1])
        separation = 1000.0 / unit_ms if min_separation_hz is None else min_separation_hz
        self.half_width = max(1, int(round(separation / self.bin_hz)))
        self.in_band = (freqs >= fmin) & (freqs <= fmax)
        self.band_edges = band_edges_for(freqs, fmin, fmax)
        # The periodic Hann window of scipy.signal.get_window("hann"), and (in gain) the
        # power response of scipy.signal.butter's high-pass in closed form: the same numbers
        # to 1e-14 without importing scipy.signal, 50 MB of resident memory. The window carries
        # the square root of the power scale (|X|² → mean-square power of a sinusoid, A²/2), so
        # that the spectra come out as powers.
        window = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(unit_samples) / unit_samples)
        self.window = window * np.sqrt(2.0) / window.sum()
        self.rate, self.highpass_hz = rate, highpass_hz
        self.response = self.gain(freqs)
        # The unit's trend up to a parabola is removed, not only its mean: slow hand motion
        # (metres per second squared at a few Hz, which the whole-signal high-pass removes
        # before any window) would otherwise leak through the window into the lowest bins.
        # Without a high-pass (highpass_hz = 0) the low frequencies are wanted as they are: only
        # the mean goes, as in the whole-signal path.
        trend = _orthonormal_polynomials(unit_samples, TREND_ORDER if highpass_hz > 0 else 0)
        # Removing the trend is linear: the window times (samples minus their projection on
        # the polynomials) is the windowed samples minus the windowed polynomials weighted by
        # the projection's coefficients. Both products are one product over a whole batch of
        # units and axes, through numpy's own loops (einsum), not BLAS: a product that large
        # would be shared among BLAS threads, which on a busy machine spin for ten times longer
        # than the product takes (and one BLAS call per unit costs a fifth more).
        self.axes = axes if combine == "dft321" else 1
        self.trend = trend
        self.windowed_trend = trend * self.window
        # Parseval for the one-sided padded spectrum, divided by the window's energy: the
        # mean square of the (filtered) unit, for the silence check.
        parseval = np.full(len(freqs), 2.0)
        parseval[0] = 1.0
        if self.nfft % 2 == 0:
            parseval[-1] = 1.0
        self.mean_square = parseval / (self.nfft * np.sum(self.window ** 2))
        # Work space reused by every batch: fresh arrays of a few megabytes each time would be
        # mapped and faulted in anew (as costly as the FFT itself).
        self.padded = np.zeros((0, self.axes, self.nfft))
        self.spectrum = np.zeros((0, self.axes, len(freqs)), dtype=complex)

    def power(self, units: np.ndarray) -> np.ndarray:
        """Power spectra (units, bins) of units (units, unit_samples, axes), detrended and
        windowed, before the high-pass (see :meth:`peaks`)."""
        count, samples = len(units), self.unit_samples
        if self.combine == "magnitude":
            units = np.sqrt(np.einsum("nsa,nsa->ns", units, units))[:, :, None]
        elif self.combine != "dft321":
            units = units[:, :, self.combine:self.combine + 1]
        if len(self.padded) < count:  # zeros past the unit stay zeros: written once
            self.padded = np.zeros((count, self.axes, self.nfft))
            self.spectrum = np.empty((count,) + self.spectrum.shape[1:], dtype=complex)
        padded = self.padded[:count]
        windowed = padded[:, :, :samples]
        # One row per unit and axis (a copy, in the order the FFT wants): each product is then
        # one product over the whole batch.
        rows = units.transpose(0, 2, 1).reshape(-1, samples)
        coefficients = np.einsum("rs,ps->rp", rows, self.trend)  # (rows, polynomials)
        np.multiply(rows.reshape(windowed.shape), self.window, out=windowed)
        windowed -= np.einsum("rp,ps->rs", coefficients,
                              self.windowed_trend).reshape(windowed.shape)
        spectrum = np.fft.rfft(padded, axis=-1, out=self.spectrum[:count])
        # DFT321: the axes' powers add; real and imaginary parts squared and summed over the
        # axes in one pass, then the two parts of each bin added.
        parts = spectrum.view(np.float64)
        squares = np.einsum("nap,nap->np", parts, parts)
        return squares[:, 0::2] + squares[:, 1::2]

    def gain(self, freqs_hz: np.ndarray) -> np.ndarray:
        """The high-pass's power response at any frequencies (Hz): a Butterworth through the
        bilinear transform has |H|² = 1 / (1 + (tan(π fc / fs) / tan(π f / fs))^(2 order)),
        and forward and backward it acts twice."""
        if self.highpass_hz == 0:
            return np.ones_like(freqs_hz)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            ratio = np.tan(np.pi * self.highpass_hz / self.rate) / \
                np.tan(np.pi * freqs_hz / self.rate)
            # ratio ** (2 × 4th order) by squaring thrice: half the time of a general power,
            # the same numbers to 1e-15.
            power = ratio * ratio
            power *= power
            power *= power
        return (1.0 / (1.0 + power)) ** 2

    def peaks(self, power: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(frequencies, powers, band levels in dB, mean squares) of each row of ``power``, as
        principal_frequencies finds them in the high-passed signal.

        A filtered signal holds each tone at its own frequency, scaled by the filter's power
        response there: the peaks are found in the unfiltered unit spectrum and weighted at
        their interpolated frequency, not found in the weighted spectrum, whose steep slope
        near the cutoff would move a 32 Hz tone's peak by 4 Hz. Band levels and mean squares
        are those of the weighted spectrum.
        """
        weighted = power * self.response
        freqs, powers = top_peaks(power, self.in_band, self.half_width, self.top, self.bin_hz,
                                  weighted=weighted)
        # Sub-bin interpolation may step a hair past a band edge; the peak is still in band.
        freqs = np.clip(freqs, self.fmin, self.fmax)
        powers = powers * self.gain(freqs)
        # The order was judged at the peaks' bins; weighted at their own frequencies, two
        # peaks near the cutoff may swap.
        order = np.argsort(-np.where(np.isnan(powers), -np.inf, powers), axis=1, kind="stable")
        freqs = np.take_along_axis(freqs, order, axis=1)
        powers = np.take_along_axis(powers, order, axis=1)
        return (freqs, powers, unit_band_levels_db(weighted, self.in_band, self.band_edges),
                np.einsum("ub,b->u", weighted, self.mean_square))


def _orthonormal_polynomials(length: int, order: int) -> np.ndarray:
    """Rows: orthonormal polynomials of degree 0 to ``order`` over ``length`` samples."""
    n = np.arange(length) - (length - 1) / 2
    basis, _ = np.linalg.qr(np.vander(n / max(1.0, n[-1]), order + 1, increasing=True))
    return np.ascontiguousarray(basis.T)


class _Rows:
    """Rows appended in order into an array that grows when the first guess was short."""

    def __init__(self, capacity: int, width: int | None, dtype, unit_ms: float, source: object):
        shape = (max(capacity, 1),) if width is None else (max(capacity, 1), width)
        self.data = np.empty(shape, dtype=dtype)
        self.size = 0
        self.unit_ms, self.source = unit_ms, source

    def extend(self, rows: np.ndarray) -> None:
        need = self.size + len(rows)
        if need > len(self.data):
            check_unit_count(need, self.unit_ms, self.source)
            grown = np.empty((max(need, min(2 * len(self.data), MAX_UNITS)),)
                             + self.data.shape[1:], dtype=self.data.dtype)
            grown[:self.size] = self.data[:self.size]
            self.data = grown
        self.data[self.size:need] = rows
        self.size = need

    def result(self) -> np.ndarray:
        if self.size < len(self.data) // 2:  # do not keep a wrong guess's space alive
            return self.data[:self.size].copy()
        return self.data[:self.size]


class _StationaryRuns:
    """The band-level variance of every run of ``count`` consecutive units, as the units stream
    past: the arithmetic of :func:`realpen.dsp.spectrum.select_units` (cumulative sums over the
    units after the first, the same order of additions), holding ``count`` rows of sums."""

    def __init__(self, count: int, capacity: int, unit_ms: float, source: object):
        self.count = count
        self.started = False
        self.sums = np.zeros((1, FEATURE_BANDS))  # the last ≤ count cumulative sums
        self.squares = np.zeros((1, FEATURE_BANDS))
        self.variance = _Rows(capacity, None, np.float64, unit_ms, source)

    def feed(self, bands: np.ndarray) -> None:
        """Band levels (units, bands) in dB of the next units, in order, as float64."""
        if not self.started:
            bands = bands[1:]  # the first unit is never selected
            self.started = True
        if not len(bands):
            return
        sums = np.cumsum(np.vstack([self.sums[-1:], bands]), axis=0)[1:]
        squares = np.cumsum(np.vstack([self.squares[-1:], bands ** 2]), axis=0)[1:]
        sums, squares = np.vstack([self.sums, sums]), np.vstack([self.squares, squares])
        count = self.count
        if len(sums) > count:
            mean = (sums[count:] - sums[:-count]) / count
            mean_sq = (squares[count:] - squares[:-count]) / count
            self.variance.extend(np.maximum(mean_sq - mean ** 2, 0.0).sum(axis=1))
        self.sums, self.squares = sums[-count:], squares[-count:]

    def first(self, units: int) -> int:
        """The first unit of the steadiest run that leaves out the last of ``units`` units."""
        variance = self.variance.data[:units - 1 - self.count]
        return 1 + int(np.argmin(variance))


def _combination(axes: tuple[str, ...], axis: str | None, source: object) -> str | int:
    """How the axes become one power spectrum: ``"dft321"``, ``"magnitude"`` or a column."""
    if axis is None:
        return "dft321" if len(axes) > 1 else 0
    if axis == "dft321":
        return "dft321" if len(axes) > 1 else 0
    if axis == "magnitude":
        return "magnitude"
    if axis in axes:
        return axes.index(axis)
    if axis in ("x", "y", "z") and "xyz".index(axis) < len(axes):
        # Columns named otherwise (ax, acc_y, ...) are taken in order: x first, then y, z.
        return "xyz".index(axis)
    raise fail(source, f"no axis '{axis}' (axes: {', '.join(axes)}; or dft321, magnitude)")


def combined_name(axes: tuple[str, ...], axis: str | None) -> str:
    """The name of the one signal the axes become (``dft321``, ``magnitude`` or an axis), as
    :func:`realpen.dsp.filters.combine_axes` names it."""
    if axis is None:
        return "dft321" if len(axes) > 1 else axes[0]
    return axis


def analyze_stream(stream: RecordingStream, *, unit_ms: float = 100.0, top: int = 10,
                   count: int = 15, selection: str = "stationary", fmin: float | None = None,
                   fmax: float | None = None, highpass_hz: float = 30.0, axis: str | None = None,
                   min_separation_hz: float | None = None, block_frames: int | None = None,
                   dtype=np.float32, keep_bands: bool = True,
                   progress: ProgressCallback | None = None) -> Analysis:
    """Principal frequencies of every unit of a streamed recording, and the units to use.

    The recording is read a block at a time (see the module doc for the method); memory holds
    one block and the per-unit results. Units are whole samples (100 ms at 1344 Hz is 134), the
    tail that does not fill one is ignored, and a unit may straddle two blocks.

    Args:
        stream: from :func:`realpen.io.blocks.open_stream` (or an
            :class:`~realpen.io.blocks.ArrayStream`).
        unit_ms: unit sequence length in ms.
        top: principal frequencies kept per unit.
        count: consecutive units to select (never the first or the last unit).
        selection: ``"stationary"`` (the steadiest run) or ``"middle"``.
        fmin, fmax: band in Hz where peaks count (fmin: ``highpass_hz``; fmax: Nyquist).
        highpass_hz: cutoff in Hz of the zero-phase high-pass applied as its power response
            (0: none).
        axis: ``"dft321"`` (default for several axes), ``"magnitude"``, or an axis name
            (``"x"``, ``"y"``, ``"z"`` also pick the first three columns by position).
        min_separation_hz: two peaks closer than this are one (default 1000 / unit_ms Hz).
        block_frames: frames read at a time (default: :data:`UNIT_BATCH` units).
        dtype: ``np.float32`` (default) or ``np.float64``, how the per-unit frequencies, powers
            and band levels are stored; everything is computed in float64.
        keep_bands: keep every unit's band levels in the result (False: they judge the
            stationary run as the units stream past, and the result's ``band_levels_db`` has no
            columns; a day of units then needs 80 MB less).
        progress: called as ``progress(units_done, units_expected)``.

    Returns:
        A :class:`realpen.dsp.spectrum.Analysis`.

    Raises:
        ParameterError: a bad option (Python names: ``unit_ms``, ``top``, ``count``,
            ``selection``, ``axis``, ``highpass_hz``, ``fmin``, ``fmax``, ``dtype``), or more
            than :data:`~realpen.checks.MAX_UNITS` units (``unit_ms``, naming the source).
        RealPenError: a damaged file or bad values (from the stream), no such axis, a silent
            or constant recording, one too short for ``count + 2`` units, or no peaks in the
            selected units.

    Example:
        >>> import numpy as np
        >>> from realpen.io.blocks import ArrayStream
        >>> t = np.arange(3 * 1344) / 1344
        >>> tone = np.column_stack([np.sin(2 * np.pi * 200 * t), 0.5 * np.cos(2 * np.pi * 200 * t)])
        >>> result = analyze_stream(ArrayStream(tone, 1344), top=1)
        >>> round(float(result.unit(5)[0][0]), 1)
        200.0
    """
    rate, source = stream.rate, stream.source
    require_number("unit_ms", unit_ms, minimum=0.0, inclusive=False, maximum=MAX_UNIT_MS)
    top = require_count("top", top, MAX_TOP)
    count = require_count("count", count, MAX_SUBPATTERNS)
    require_choice("selection", selection, SELECTIONS)
    if axis is not None and axis not in stream.axes:
        require_choice("axis", axis, AXIS_CHOICES)
    require_number("highpass_hz", highpass_hz, minimum=0.0)
    nyquist = rate / 2
    if highpass_hz >= nyquist:
        raise ParameterError("highpass_hz", f"a {highpass_hz:g} Hz high-pass needs a rate above "
                                            f"{2 * highpass_hz:g} Hz; {source} is at {rate:g} "
                                            f"Hz, so its rate is too low (Nyquist {nyquist:g} Hz)")
    fmin = highpass_hz if fmin is None else fmin
    require_number("fmin", fmin, minimum=0.0, maximum=nyquist)
    fmax = nyquist if fmax is None else fmax
    require_number("fmax", fmax, minimum=fmin)
    fmax = min(fmax, nyquist)
    if min_separation_hz is not None:
        require_number("min_separation_hz", min_separation_hz, minimum=0.0)
    if np.dtype(dtype) not in (np.float32, np.float64):
        raise ParameterError("dtype", f"must be float32 or float64, got {np.dtype(dtype)}")
    unit_samples = unit_samples_for(unit_ms, rate, source)
    combine = _combination(stream.axes, axis, source)
    plan = _Plan(rate, unit_samples, unit_ms, top, fmin, fmax, highpass_hz, min_separation_hz,
                 combine, len(stream.axes))
    expected = stream.frames_hint // unit_samples
    if stream.frames is not None:
        check_unit_count(expected, unit_ms, source)  # before the results are allocated
    freqs_out = _Rows(expected, top, dtype, unit_ms, source)
    powers_out = _Rows(expected, top, dtype, unit_ms, source)
    bands_out = _Rows(expected, FEATURE_BANDS if keep_bands else 0, dtype, unit_ms, source)
    runs = _StationaryRuns(count, expected, unit_ms, source) if selection == "stationary" else None
    mean_square = 0.0
    batch = UNIT_BATCH * unit_samples
    block_frames = batch if block_frames is None else block_frames
    for units, whole in _whole_units(stream, block_frames, unit_samples, batch):
        if not whole:  # the tail that fills no unit counts for the recording's peak only
            continue
        power = plan.power(units.reshape(-1, unit_samples, units.shape[1]))
        freqs, powers, bands, mean_squares = plan.peaks(power)
        mean_square += float(np.sum(mean_squares))
        freqs_out.extend(freqs)
        powers_out.extend(powers)
        bands_out.extend(bands if keep_bands else bands[:, :0])
        if runs is not None:
            runs.feed(bands)
        if progress is not None:
            progress(freqs_out.size, max(freqs_out.size, expected))
    total = freqs_out.size
    if total:
        level, peak = np.sqrt(mean_square / total), stream.peak  # the stream's whole pass
        if peak == 0 or level <= peak * 10 ** (SILENCE_DB / 20):
            raise fail(source, "signal is silent or constant (no vibration above "
                               f"{SILENCE_DB:g} dB of its peak after the high-pass)")
    if total < count + 2:
        frames = stream.frames if stream.frames is not None else total * unit_samples
        raise RealPenError(
            f"{source}: too short: {frames / rate:.3f} s holds {total} units of {unit_ms:g} ms; "
            f"{count} units plus the dropped first and last need {(count + 2) * unit_ms / 1000:g} s")
    if runs is not None:
        first = runs.first(total)
    else:
        first = 1 + (total - 2 - count) // 2
    selected = np.arange(first, first + count)
    freqs_all = freqs_out.result()
    if not np.isfinite(freqs_all[selected]).any():
        raise RealPenError(f"{source}: no spectral peaks between {fmin:g} Hz and {fmax:g} Hz in "
                           f"the selected units")
    starts = np.arange(total) * unit_samples / rate
    return Analysis(float(rate), float(unit_ms), top, starts, freqs_all, powers_out.result(),
                    bands_out.result(), selected, selection)


def _whole_units(stream: RecordingStream, block_frames: int, unit_samples: int, batch: int
                 ) -> Iterator[tuple[np.ndarray, bool]]:
    """(samples, True) for runs of whole units of at most ``batch`` frames, a unit that
    straddles two blocks joined; last, (the tail that fills no unit, False) if there is one."""
    carry = None
    for block in stream.iter_blocks(block_frames):
        if carry is not None:
            block = np.concatenate([carry, block])
        whole = len(block) - len(block) % unit_samples
        for start in range(0, whole, batch):
            yield block[start:min(start + batch, whole)], True
        carry = block[whole:] if whole < len(block) else None
    if carry is not None:
        yield carry, False


def analyze_units(samples: np.ndarray, rate: float, *, axes: tuple[str, ...] | None = None,
                  source: str = "array", **options) -> Analysis:
    """:func:`analyze_stream` of an array in memory: the same algorithm, the same results.

    Args:
        samples: shape (frames,) or (frames, axes), in the recording's unit.
        rate: sampling rate in Hz.
        axes: names of the columns (default x, y, z for up to three).
        source: names the array in messages.
        **options: as :func:`analyze_stream` (``unit_ms``, ``top``, ``count``, ...).

    Example:
        >>> import numpy as np
        >>> t = np.arange(3 * 1344) / 1344
        >>> result = analyze_units(np.sin(2 * np.pi * 200 * t), 1344, top=1)
        >>> round(float(result.unit(5)[0][0]), 1)
        200.0
    """
    return analyze_stream(ArrayStream(samples, rate, axes, source), **options)


def streamed_selection(recording: Recording, analysis: Analysis, *, axis: str | None = None,
                       analysis_rate: float | None = None, highpass_hz: float = 30.0,
                       fmin: float | None = None, fmax: float | None = None) -> Analysis:
    """``analysis`` with the units a streamed analysis of the same recording selects.

    The in-memory analysis (:func:`realpen.dsp.spectrum.analyze` of the prepared signal) and the
    streamed one (:func:`analyze_stream`) judge stationarity on different estimates of each
    unit's spectrum (see the module doc), so on a recording stationary throughout their
    steadiest runs may lie a few units apart. The streamed judgement is the one both can make
    (a file too long for memory is only ever streamed): here it is made on ``recording`` in
    memory (:func:`analyze_units`, resampled first as ``realpen analyze --analysis-rate``
    does), and ``analysis`` keeps its own peaks for every unit. ``"middle"`` needs nothing:
    it is arithmetic on the unit count, the same in both.

    Args:
        recording: the recording ``analysis`` was made from (all its axes, its own rate).
        analysis: its in-memory analysis, with the options below.
        axis, analysis_rate, highpass_hz, fmin, fmax: as given to the in-memory analysis
            (:func:`realpen.dsp.filters.prepare` and :func:`realpen.dsp.spectrum.analyze`).

    Returns:
        ``analysis`` with ``selected`` replaced (itself when nothing changes).

    Raises:
        RealPenError: no spectral peaks between ``fmin`` and ``fmax`` in the selected units.

    Example:
        >>> from realpen.dsp.filters import prepare
        >>> from realpen.dsp.spectrum import analyze
        >>> from realpen.examples import example_recording_path
        >>> from realpen.io.recording import load_recording
        >>> recording = load_recording(example_recording_path())
        >>> whole = analyze(prepare(recording).mono, recording.rate)
        >>> [int(i) for i in streamed_selection(recording, whole).selected[[0, -1]]]
        [100, 114]
    """
    if analysis.selection != "stationary":
        return analysis
    source = recording
    if analysis_rate is not None:
        from realpen.dsp.filters import resample  # only to resample first, as prepare does

        source = resample(recording, analysis_rate, parameter="analysis_rate")
    count = len(analysis.selected)
    streamed = analyze_units(source.samples, source.rate, axes=source.axes,
                             source=recording.source, unit_ms=analysis.unit_ms, top=analysis.top,
                             count=count, selection="stationary", fmin=fmin, fmax=fmax,
                             highpass_hz=highpass_hz, axis=axis, keep_bands=False)
    selected = streamed.selected
    if selected[-1] >= len(analysis.starts_s) - 1:  # never the last unit of either count
        selected = np.arange(len(analysis.starts_s) - 1 - count, len(analysis.starts_s) - 1)
    if np.array_equal(selected, analysis.selected):
        return analysis
    if not np.isfinite(analysis.frequencies_hz[selected]).any():
        raise RealPenError(f"{recording.source}: no spectral peaks between "
                           f"{fmin if fmin is not None else highpass_hz:g} Hz and "
                           f"{fmax or analysis.rate / 2:g} Hz in the selected units")
    return replace(analysis, selected=selected)
