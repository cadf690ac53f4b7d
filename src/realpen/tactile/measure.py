"""Measuring an actuator with its own pen: the swept-sine response and its resonance.

The pen loops a pattern through its actuator while its accelerometer records. Both run on the
pen's clock, so one loop of an ``N``-sample pattern at ``rate_hz`` lasts exactly
``N / rate_hz`` seconds of capture time; the capture's own rate is only estimated (the
sensor's oscillator is off by up to a few per cent), and the analysis can refine that estimate
from the sweep itself.

- :func:`sweep_pattern` — a synchronised exponential sine sweep (Novak et al. 2015) whose
  phase ends on a whole number of cycles, so the looped pattern is continuous and the
  excitation periodic.
- :func:`analyse_sweep` — the capture cut into whole loops (:mod:`realpen.tactile.loops`),
  each loop deconvolved circularly with the sweep (Farina 2000: the linear impulse response
  separates from the harmonic ones, which come earlier, at −L·ln k), the linear part
  windowed; returns a :class:`Response`: |H(f)| over 20–500 Hz with the axes combined as
  √(Σ power) (the DFT321 idea), coherence γ² between the repeated loops, 2nd + 3rd harmonic
  distortion with its noise floor, and the SNR. Loops the pen's playback slipped in or
  between (underruns) are left out or shifted back.
- :func:`fit_resonance` — f0, Q and gain of |H| = g / √(1 + Q²(f/f0 − f0/f)²), fitted on
  log magnitude.
- :func:`write_response_csv` — the CSV :func:`realpen.tactile.actuator.load_measured` reads
  (:func:`realpen.tactile.actuator.load_measured`).

The check that the measured response equalises the actuator is
:mod:`realpen.tactile.multisine`.

References:
    A. Farina, "Simultaneous measurement of impulse response and distortion with a
    swept-sine technique", 108th AES Convention, preprint 5093, 2000.
    A. Novak, L. Simon, P. Lotton, "Synchronized swept-sine: theory, application, and
    implementation", J. Audio Eng. Soc. 63(10), 2015, doi:10.17743/jaes.2015.0071.

numpy and scipy only; no device code.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from realpen.checks import require_number
from realpen.errors import ParameterError, fail
from realpen.io.files import atomic_path
from realpen.tactile.actuator import Actuator, parse_actuator
from realpen.tactile.loops import (
    LOST,
    MAX_PATTERN_SAMPLES,
    as_capture,
    check_loop_options,
    pattern_int16,
    require_loops,
    whole_loops,
)

__all__ = ["Sweep", "Response", "ResonanceFit", "sweep_pattern", "analyse_sweep",
           "fit_resonance", "write_response_csv", "BAND_HZ", "CSV_HEADER"]

BAND_HZ = (20.0, 500.0)
"""The band :func:`analyse_sweep` reports, Hz (the method's tactile range)."""
CSV_HEADER = ("frequency_hz", "response_db", "coherence", "distortion_db")
"""Columns :func:`write_response_csv` writes; :func:`~realpen.tactile.actuator.load_measured`
reads the first two."""

_POINTS_PER_OCTAVE = 48
_LINEAR_PRE_S = 0.05  # kept before the linear impulse response's peak (band-limited pre-ringing)
_LINEAR_POST_S = 0.4  # kept after it at most: 5 time constants Q/(π f0) of a Q 25 resonance
_LINEAR_MIN_POST_S = 0.08  # … and at least (a response that hardly rings)
_MEASURABLE_NYQUIST = 0.9  # harmonics are read up to this share of the capture's Nyquist
_DISAGREEMENT = 0.5  # a loop whose response differs by this share of the power is left out
_DETECTION = 10.0  # a harmonic counts when its power is this many times its noise power
_TINY = 1e-30


@dataclass(frozen=True, eq=False)
class Sweep:
    """A looped exponential sine sweep (see :func:`sweep_pattern`).

    Attributes:
        samples: one loop, float64 in [−1, 1], shape (n,).
        rate_hz: the pattern's rate, Hz.
        f1_hz, f2_hz: the sweep's start and end frequencies, Hz (adjusted so the loop is
            continuous).
        sweep_rate_s: L, the time the instantaneous frequency takes to grow e-fold, s; the
            k-th harmonic's impulse response comes L·ln k before the linear one.
        fade_ms: the half-Hann fade at each end, ms.
    """

    samples: np.ndarray
    rate_hz: int
    f1_hz: float
    f2_hz: float
    sweep_rate_s: float
    fade_ms: float

    @property
    def n_samples(self) -> int:
        """Samples in one loop."""
        return int(self.samples.size)

    @property
    def period_s(self) -> float:
        """One loop, s."""
        return self.samples.size / self.rate_hz

    def to_int16(self) -> np.ndarray:
        """The loop as int16 pattern samples (full scale 32767), for
        :meth:`realpen.device.client.PenClient.upload`."""
        return pattern_int16(self.samples)


@dataclass(frozen=True, eq=False)
class Response:
    """An actuator's measured response (see :func:`analyse_sweep`).

    Attributes:
        frequency_hz: the grid, Hz (log-spaced, 48 points an octave).
        magnitude: |H(f)|, the capture's unit per pattern full scale (at the gain played),
            power-averaged over loops, the axes combined as √(Σ power).
        coherence: γ² = Σ|mean H|² / Σ mean|H|² over the repeated loops, 0 … 1 (1: every loop
            gave the same response; noise lowers it).
        distortion_db: 2nd + 3rd harmonic level relative to the linear response, dB, where
            the 2nd harmonic is measurable (within the sweep and below 0.9 of the capture's
            Nyquist frequency) and above its noise floor; NaN elsewhere.
        distortion_floor_db: the noise floor of that estimate (noise left in the harmonics'
            mean over loops, relative to the linear response), dB; NaN where not measurable.
        periods: loops analysed.
        periods_incomplete: loops left out because samples are missing in them (a gap in the
            capture) that no other loop could stand in for, or too many of them.
        periods_slipped: loops left out because their response differs from the others' (the
            pen's playback slipped while it played them).
        slip_ms: the largest shift of a loop used against the others' timing (its own rate
            line with ``refine_rate``), ms: the pen's playback slipped before that loop (an
            underrun), which the analysis undid; 0 for a clean capture.
        snr_db: band power of the response over one loop's noise (its loop-to-loop
            variation), dB.
        capture_rate_hz: the capture's rate, Hz, as refined from the loops' drift.
        sweep: the :class:`Sweep` the pen played.
    """

    frequency_hz: np.ndarray
    magnitude: np.ndarray
    coherence: np.ndarray
    distortion_db: np.ndarray
    distortion_floor_db: np.ndarray
    periods: int
    periods_incomplete: int
    periods_slipped: int
    slip_ms: float
    snr_db: float
    capture_rate_hz: float
    sweep: Sweep

    @property
    def magnitude_db(self) -> np.ndarray:
        """20·log10 |H|, dB."""
        return 20 * np.log10(np.maximum(self.magnitude, _TINY))

    @property
    def normalised(self) -> np.ndarray:
        """|H| over its peak (peak 1)."""
        return self.magnitude / np.max(self.magnitude)

    @property
    def peak_hz(self) -> float:
        """The grid frequency of the largest |H|, Hz."""
        return float(self.frequency_hz[int(np.argmax(self.magnitude))])

    def to_actuator(self, spec: str = "measured response") -> Actuator:
        """The response as a measured :class:`~realpen.tactile.actuator.Actuator`
        (normalised to peak 1), as :func:`write_response_csv` and
        :func:`~realpen.tactile.actuator.load_measured` would give
        it; ``spec`` names it (the CSV's path, usually)."""
        return Actuator(spec, "measured", {}, self.frequency_hz.copy(), self.normalised)


@dataclass(frozen=True)
class ResonanceFit:
    """A resonance fitted to a response (see :func:`fit_resonance`).

    Attributes:
        f0_hz: resonance frequency, Hz.
        q: quality factor (dimensionless).
        gain: |H| at f0 (the response's unit).
        residual_db: RMS difference of the fit from the data, dB.
    """

    f0_hz: float
    q: float
    gain: float
    residual_db: float

    def response(self, frequency_hz: np.ndarray | float) -> np.ndarray:
        """The fitted |H| at ``frequency_hz`` (Hz)."""
        f = np.maximum(np.asarray(frequency_hz, dtype=np.float64), 1e-6)
        return self.gain / np.sqrt(1 + self.q ** 2 * (f / self.f0_hz - self.f0_hz / f) ** 2)

    @property
    def actuator(self) -> Actuator:
        """The model actuator ``lra:f0=…,q=…`` with these f0 and Q."""
        return parse_actuator(f"lra:f0={self.f0_hz:.6g},q={self.q:.6g}")


def _half_hann_fades(n: int, fade: int) -> np.ndarray:
    envelope = np.ones(n)
    if fade > 0:
        ramp = 0.5 - 0.5 * np.cos(np.pi * (np.arange(fade) + 0.5) / fade)
        envelope[:fade] = ramp
        envelope[n - fade:] = ramp[::-1]
    return envelope


def sweep_pattern(rate_hz: int = 8000, f1_hz: float = 15.0, f2_hz: float = 600.0,
                  duration_s: float = 2.0, *, max_samples: int = MAX_PATTERN_SAMPLES,
                  level: float = 0.9, fade_ms: float = 5.0) -> Sweep:
    """A synchronised exponential sine sweep that loops without a jump.

    x(t) = level · sin(2π k (e^(t/L) − 1)) with k = L·f1 a whole number (Novak et al. 2015:
    the harmonics' responses then keep their phase) and f2/f1 = 1 + m/k with m whole, so the
    phase at the loop's end is 2π m: the loop restarts where it ended. f1 and f2 move a little
    from the requested values to meet both; go a little wider than the band to measure
    (15–600 Hz for 20–500 Hz), since the half-Hann fades at the ends take a few ms of each.

    Args:
        rate_hz: the pen's playback rate, Hz.
        f1_hz, f2_hz: start and end frequency, Hz (f2 below 0.45 of ``rate_hz``).
        duration_s: one loop, s (shortened to ``max_samples``).
        max_samples: the most samples the pen holds (16384 = 32768 bytes).
        level: peak amplitude, 0 … 1 of full scale.
        fade_ms: half-Hann fade in and out, ms.

    Returns:
        The :class:`Sweep`.

    Raises:
        ParameterError: a value out of range.

    Example:
        >>> sweep = sweep_pattern()
        >>> sweep.n_samples, round(sweep.f1_hz, 2), round(sweep.f2_hz, 1)
        (16000, 14.76, 590.2)
    """
    require_number("rate_hz", rate_hz, minimum=100, maximum=192_000)
    require_number("f1_hz", f1_hz, minimum=0.0, inclusive=False)
    require_number("f2_hz", f2_hz, minimum=f1_hz * 1.5, maximum=0.45 * rate_hz)
    require_number("duration_s", duration_s, minimum=0.0, inclusive=False)
    require_number("max_samples", max_samples, minimum=16)
    require_number("level", level, minimum=0.0, maximum=1.0, inclusive=False)
    require_number("fade_ms", fade_ms, minimum=0.0, maximum=1000 * duration_s / 4)
    n = int(min(round(duration_s * rate_hz), max_samples))
    ratio = f2_hz / f1_hz
    cycles_start = max(1, round(f1_hz * n / (rate_hz * np.log(ratio))))  # k = L·f1
    extra_cycles = max(1, round(cycles_start * (ratio - 1)))  # m: the loop ends on 2π m
    exact_ratio = 1 + extra_cycles / cycles_start
    f1 = cycles_start * rate_hz * np.log(exact_ratio) / n
    f2 = f1 * exact_ratio
    if f2 > 0.45 * rate_hz:
        raise ParameterError("f2_hz", f"{f2_hz:g} Hz leaves no room below the pen's Nyquist "
                                      f"frequency in a {n}-sample loop")
    sweep_rate = cycles_start / f1
    t = np.arange(n) / rate_hz
    phase = 2 * np.pi * cycles_start * np.expm1(t / sweep_rate)
    fade = int(round(fade_ms * rate_hz / 1000))
    samples = level * np.sin(phase) * _half_hann_fades(n, fade)
    return Sweep(samples, int(rate_hz), float(f1), float(f2), float(sweep_rate), float(fade_ms))


# -- the sweep's analysis -------------------------------------------------------------------

def _inverse_sweep(sweep: Sweep, samples: int) -> np.ndarray:
    """The regularised inverse of the sweep's spectrum on the bins of an ``samples``-point loop,
    tapered to 0 outside the sweep (where the deconvolution would only lift noise)."""
    spectrum = np.fft.rfft(sweep.samples)[: samples // 2 + 1] / sweep.n_samples
    if len(spectrum) < samples // 2 + 1:  # a capture faster than the pattern: nothing above
        spectrum = np.concatenate([spectrum, np.zeros(samples // 2 + 1 - len(spectrum))])
    freqs = np.arange(samples // 2 + 1) / sweep.period_s
    power = np.abs(spectrum) ** 2
    inverse = np.conj(spectrum) / (power + 1e-8 * power.max())
    low, high = sweep.f1_hz, min(sweep.f2_hz, 0.95 * samples / sweep.period_s / 2)
    taper = np.ones_like(freqs)
    below = freqs < low
    taper[below] = 0.5 - 0.5 * np.cos(np.pi * np.clip(
        (freqs[below] - low / 1.5) / (low - low / 1.5), 0, 1))
    above = freqs > high
    edge = min(high * 1.1, samples / sweep.period_s / 2)
    taper[above] = 0.5 + 0.5 * np.cos(np.pi * np.clip(
        (freqs[above] - high) / max(edge - high, 1e-9), 0, 1))
    return inverse * taper / samples


def _window(length: int, pre: int, post: int) -> tuple[np.ndarray, np.ndarray]:
    """Offsets −pre … post−1 around a peak and a window that rises (half-Hann) over ``pre`` and
    falls over the last quarter of ``post``."""
    offsets = np.arange(-pre, post)
    window = np.ones(len(offsets))
    if pre > 0:
        window[:pre] = 0.5 - 0.5 * np.cos(np.pi * (np.arange(pre) + 0.5) / pre)
    fall = max(1, post // 4)
    window[len(offsets) - fall:] = 0.5 + 0.5 * np.cos(np.pi * (np.arange(fall) + 0.5) / fall)
    return offsets % length, window


def _spectrum_at(segments: np.ndarray, offsets: np.ndarray, frequency_hz: np.ndarray,
                 rate: float) -> np.ndarray:
    """DTFT of windowed impulse-response segments (..., taps, axes) at ``frequency_hz``; the
    taps sit at ``offsets`` samples from the segment's centre."""
    kernel = np.exp(-2j * np.pi * np.outer(frequency_hz, offsets) / rate)
    return np.einsum("ft,...ta->...fa", kernel, segments)


def _loop_lags(responses: np.ndarray, whole: np.ndarray) -> np.ndarray:
    """Each loop's lag behind the first whole loop's response, in whole samples: the peak of
    their circular cross-correlation (a resonance rings for many cycles, so the largest
    sample of each response can sit a cycle early or late; their correlation cannot)."""
    samples = responses.shape[1]
    spectra = np.fft.rfft(responses, axis=1)
    reference = spectra[int(np.flatnonzero(whole)[0])]
    correlation = np.fft.irfft(np.sum(spectra * np.conj(reference)[None], axis=-1), n=samples,
                               axis=1)
    lags = np.argmax(correlation, axis=1)
    return np.where(lags > samples // 2, lags - samples, lags).astype(np.float64)


def _agreeing(linear: np.ndarray, kept: np.ndarray, frequency_hz: np.ndarray) -> np.ndarray:
    """``kept`` without the loops whose response, in any third of an octave of the grid,
    differs from the mean of the other kept loops by more than :data:`_DISAGREEMENT` of its
    power (the worst first, one at a time, while three or more are kept; two that disagree
    are refused)."""
    kept = kept.copy()
    octave = np.floor(3 * np.log2(frequency_hz / frequency_hz[0])).astype(np.int64)
    while True:
        index = np.flatnonzero(kept)
        total = linear[index].sum(axis=0)
        worst, worst_error = -1, _DISAGREEMENT
        for position, loop in enumerate(index):
            others = (total - linear[loop]) / (len(index) - 1)
            error = np.bincount(octave, np.sum(np.abs(linear[loop] - others) ** 2, axis=-1))
            power = np.bincount(octave, np.sum(np.abs(others) ** 2, axis=-1))
            relative = float(np.max(error / np.maximum(power, _TINY)))
            if relative > worst_error:
                worst, worst_error = position, relative
        if worst < 0:
            return kept
        if len(index) == 2:
            raise ParameterError("capture", "the 2 loops left disagree: the pen's playback "
                                            "slipped (underruns?) while it played them; "
                                            "measure again, with more loops")
        kept[index[worst]] = False


def _loop_delays_s(linear: np.ndarray, frequency_hz: np.ndarray) -> np.ndarray:
    """How much later each loop's linear response comes than the loops' mean, s: the slope of
    the cross-spectrum's phase against frequency (valid for delays well under a period of the
    highest frequency; the coarse step has removed larger ones)."""
    reference = linear.mean(axis=0)
    cross = np.sum(linear * np.conj(reference)[None], axis=-1)  # (loops, freqs)
    weight = np.abs(cross)
    omega = 2 * np.pi * frequency_hz
    return -np.sum(weight * omega * np.angle(cross), axis=1) / np.maximum(
        np.sum(weight * omega ** 2, axis=1), _TINY)


def _line(values: np.ndarray, used: np.ndarray, fit_slope: bool = True
          ) -> tuple[float, np.ndarray]:
    """Slope of a robust line through the ``used`` ``values`` against their index (Theil–Sen:
    the median of the pairwise slopes, so one loop that slipped does not tilt it; 0 when not
    ``fit_slope``), and every value's residual from it."""
    index = np.arange(len(values), dtype=np.float64)
    x, y = index[used], values[used]
    slope = 0.0
    if fit_slope:
        pairs = np.triu_indices(len(x), 1)
        slope = float(np.median((y[pairs[1]] - y[pairs[0]]) / (x[pairs[1]] - x[pairs[0]])))
    intercept = float(np.median(y - slope * x))
    return slope, values - (intercept + slope * index)


def _frequency_grid(band_hz: tuple[float, float], capture_rate_hz: float, sweep: Sweep
                    ) -> np.ndarray:
    low = max(band_hz[0], sweep.f1_hz * 1.05)
    high = min(band_hz[1], 0.45 * capture_rate_hz, sweep.f2_hz / 1.05)
    if not low < high:
        raise ParameterError("capture_rate_hz", f"{capture_rate_hz:g} Hz leaves no band to "
                                                f"measure within {band_hz[0]:g}–{band_hz[1]:g} Hz")
    count = int(np.ceil(np.log2(high / low) * _POINTS_PER_OCTAVE)) + 1
    return np.geomspace(low, high, count)


def analyse_sweep(capture: np.ndarray, capture_rate_hz: float, sweep: Sweep, *,
                  periods_to_skip: int = 1, periods: int | None = None,
                  refine_rate: bool = True, band_hz: tuple[float, float] = BAND_HZ
                  ) -> Response:
    """The actuator's response from a capture made while the pen looped ``sweep``.

    The capture (any start within the loop) is resampled to a whole number of samples per
    loop, the first ``periods_to_skip`` loops dropped (the actuator settling), each further
    whole loop deconvolved circularly with the sweep, the linear impulse response found (its
    peak) and windowed (50 ms before; after, 8 time constants Q/(π f0) of its resonance, 80 to
    400 ms); the 2nd and 3rd harmonic responses, which
    come L·ln 2 and L·ln 3 earlier, are windowed likewise. A rate estimate that is slightly off
    shows as each loop's response drifting against the last; with ``refine_rate`` the drift
    is measured (first in whole samples from the responses' peaks, then to µs from their
    phase) and the loops cut again at the corrected rate. A loop shifted as a whole against
    the others (the pen's playback slipped before it) is shifted back; a loop whose response
    differs from the others' mean by half its power in any third of an octave is left out (the
    playback slipped while it played it).

    Args:
        capture: acceleration, shape (n,) or (n, 1…3) (any unit; m/s² from the pen); NaN
            where samples are missing (taken from the other loops there; see
            :func:`realpen.tactile.loops.whole_loops`).
        capture_rate_hz: its estimated rate, Hz (≈1344 from the pen's timestamps).
        sweep: the :class:`Sweep` the pen looped (:func:`sweep_pattern`).
        periods_to_skip: whole loops to drop at the start.
        periods: the most loops to analyse after them (None: every whole one).
        refine_rate: correct ``capture_rate_hz`` from the loops' drift. Leave it on for a
            rate known to a few per cent; turn it off for one the pen's timestamps gave to a
            few ppm, so that a playback that slipped (an underrun moves every later loop) is
            undone loop by loop rather than taken for a rate.
        band_hz: (low, high) of the frequency grid, Hz.

    Returns:
        The :class:`Response`.

    Raises:
        ParameterError: (``capture``) a capture with fewer than 2 whole loops after the skip
            (or 2 that agree in timing), a malformed capture, or a value out of range.
    """
    check_loop_options(capture_rate_hz, periods_to_skip, periods)
    if not isinstance(sweep, Sweep):
        raise ParameterError("sweep", f"must be a Sweep (sweep_pattern), got "
                                      f"{type(sweep).__name__}")
    capture = as_capture(capture)
    rate = float(capture_rate_hz)
    grid = _frequency_grid(band_hz, rate, sweep)
    passes = 6  # the drift corrections converge in two or three
    for attempt in range(passes):
        loops, samples, whole = whole_loops(capture, rate, sweep.period_s,
                                            int(periods_to_skip), "sweep", periods)
        require_loops(whole, "are whole", LOST)
        loop_rate = samples / sweep.period_s
        responses = np.fft.irfft(np.fft.rfft(loops, axis=1)
                                 * _inverse_sweep(sweep, samples)[None, :, None],
                                 n=samples, axis=1)
        # Coarse: each loop's lag in whole samples (a rate off by per cents moves it by tens).
        lags = _loop_lags(responses, whole)
        slope = _line(lags, whole, refine_rate)[0]
        if abs(slope) > 0.5 and attempt < passes - 1:
            rate *= 1 + slope / samples
            continue
        # Each loop is read where its own response is: the pen's playback may have slipped
        # between loops (an underrun delays every later loop), which moves a loop whole.
        shifted = (np.arange(samples)[None, :] + lags[:, None].astype(np.int64)) % samples
        responses = np.take_along_axis(responses, shifted[:, :, None], axis=1)
        peak = int(np.argmax(np.sum(responses[whole].mean(axis=0) ** 2, axis=-1)))
        pre = int(round(_LINEAR_PRE_S * loop_rate))
        post = int(round(min(_LINEAR_POST_S, sweep.period_s / 2 - _LINEAR_PRE_S) * loop_rate))
        offsets, window = _window(samples, pre, post)
        segments = responses[:, (peak + offsets) % samples, :] * window[None, :, None]
        linear = _spectrum_at(segments, np.arange(-pre, post), grid, loop_rate)
        # Fine: what is left of each loop's delay, to a µs, from its response's phase.
        delays = np.zeros(len(whole))
        delays[whole] = _loop_delays_s(linear[whole], grid)
        drift, slips = _line(lags / loop_rate + delays, whole, refine_rate)
        if abs(drift) < 0.02 / loop_rate or attempt == passes - 1:
            break  # below 2 % of a sample a loop: nothing to gain
        # The loops come later by `drift` each: they last longer than the rate assumed says.
        rate *= 1 + drift / sweep.period_s
    # The window need be no longer than the response rings: 8 time constants Q/(π f0) of its
    # resonance (e⁻⁸, −70 dB); what lies beyond is noise only.
    fit = fit_resonance(grid, np.sqrt(np.sum(np.abs(linear[whole].mean(axis=0)) ** 2, axis=-1)))
    rings_s = 8 * fit.q / (np.pi * fit.f0_hz)
    shorter = int(round(np.clip(rings_s, _LINEAR_MIN_POST_S, _LINEAR_POST_S) * loop_rate))
    if shorter < post:
        offsets, window = _window(samples, pre, shorter)
        segments = responses[:, (peak + offsets) % samples, :] * window[None, :, None]
        linear = _spectrum_at(segments, np.arange(-pre, shorter), grid, loop_rate)
    linear = linear * np.exp(2j * np.pi * np.outer(delays, grid))[:, :, None]
    # A slip inside a loop moves only what the sweep played after it: compare each loop's
    # response with the others' a third of an octave at a time.
    kept = _agreeing(linear, whole, grid)
    linear = linear[kept]
    used = int(kept.sum())
    mean_power, noise_power = _mean_and_noise(linear)
    power = np.mean(np.sum(np.abs(linear) ** 2, axis=-1), axis=0)
    coherence = mean_power / np.maximum(power, _TINY)
    # The mean over loops still holds 1/loops of one loop's noise power: take it out.
    magnitude = np.sqrt(np.maximum(mean_power - noise_power, 0.01 * mean_power))
    snr_db = float(10 * np.log10(np.sum(mean_power) / max(float(np.sum(noise_power)) * used,
                                                           _TINY)))
    distortion_db, floor_db = _distortion_db(responses[kept], peak, grid, sweep, loop_rate,
                                             magnitude ** 2)
    return Response(grid, magnitude, np.clip(coherence, 0.0, 1.0), distortion_db, floor_db,
                    used, int((~whole).sum()), int((whole & ~kept).sum()),
                    float(np.max(np.abs(slips[kept]))) * 1000, snr_db, rate, sweep)


def _mean_and_noise(per_loop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Power of the mean over loops of complex spectra (loops, freqs, axes), summed over
    axes, and the noise power left in that mean (the loop-to-loop variance over loops)."""
    loops = per_loop.shape[0]
    mean = per_loop.mean(axis=0)
    variance = np.sum(np.abs(per_loop - mean[None]) ** 2, axis=(0, -1)) / (loops - 1)
    return np.sum(np.abs(mean) ** 2, axis=-1), variance / loops


def _distortion_db(responses: np.ndarray, peak: int, grid: np.ndarray, sweep: Sweep,
                   loop_rate: float, linear_power: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """2nd + 3rd harmonic level over the linear response, dB, per input frequency, and the
    noise floor of that estimate, dB. Each harmonic's window reaches half-way to its
    neighbours (100 ms before it at most, 400 ms after). NaN where the 2nd harmonic lies outside the sweep or
    above 0.9 of the Nyquist frequency, and (the level only) where the harmonics do not rise
    more than 10 dB above their noise floor."""
    samples = responses.shape[1]
    ceiling = min(sweep.f2_hz, _MEASURABLE_NYQUIST * loop_rate / 2)
    harmonic_power = np.zeros(len(grid))
    noise_power = np.zeros(len(grid))
    measurable = 2 * grid <= ceiling
    for order in (2, 3):
        lag = sweep.sweep_rate_s * np.log(order)
        # Half the distance to each neighbouring harmonic: the windows never overlap.
        pre = int(min(_LINEAR_PRE_S * 2, 0.5 * sweep.sweep_rate_s * np.log((order + 1) / order))
                  * loop_rate)
        post = int(min(_LINEAR_POST_S, 0.5 * sweep.sweep_rate_s * np.log(order / (order - 1)))
                   * loop_rate)
        centre = int(round(peak - lag * loop_rate))
        offsets, window = _window(samples, pre, post)
        segments = responses[:, (centre + offsets) % samples, :] * window[None, :, None]
        inside = order * grid <= ceiling
        spectra = _spectrum_at(segments, np.arange(-pre, post), order * grid[inside], loop_rate)
        mean_power, noise = _mean_and_noise(spectra)
        harmonic_power[inside] += np.maximum(mean_power - noise, 0.0)
        noise_power[inside] += noise
    linear_power = np.maximum(linear_power, _TINY)
    floor_db = 10 * np.log10(np.maximum(noise_power / linear_power, _TINY))
    level_db = 10 * np.log10(np.maximum(harmonic_power / linear_power, _TINY))
    # Less than 10 dB above its noise floor an estimate says only "under the floor": the
    # floor itself comes from a few loops and wanders by a few dB, and of a hundred
    # frequencies of noise alone one would pass a 5 dB bar.
    detected = harmonic_power > _DETECTION * noise_power
    return (np.where(measurable & detected, level_db, np.nan),
            np.where(measurable, floor_db, np.nan))


# -- the model fit --------------------------------------------------------------------------

def fit_resonance(frequency_hz: np.ndarray, magnitude: np.ndarray, *,
                  weights: np.ndarray | None = None) -> ResonanceFit:
    """Fit |H| = g / √(1 + Q²(f/f0 − f0/f)²) to a measured response, on log magnitude.

    Started from the peak (f0, g) and its −3 dB width (Q), solved by
    :func:`scipy.optimize.least_squares` in log f0, log Q, log g.

    Args:
        frequency_hz: frequencies, Hz (positive, at least 4).
        magnitude: |H| there (linear, positive).
        weights: per-frequency weights ≥ 0 (e.g. the coherence); default equal.

    Returns:
        The :class:`ResonanceFit` (f0 in Hz, Q, g, RMS residual in dB).

    Raises:
        ParameterError: mismatched, too few, non-positive or non-finite values.

    Example:
        >>> f = np.geomspace(20, 500, 100)
        >>> fit = fit_resonance(f, 2 / np.sqrt(1 + 64 * (f / 175 - 175 / f) ** 2))
        >>> round(fit.f0_hz, 3), round(fit.q, 3), round(fit.gain, 3)
        (175.0, 8.0, 2.0)
    """
    from scipy.optimize import least_squares

    freqs = np.asarray(frequency_hz, dtype=np.float64)
    mags = np.asarray(magnitude, dtype=np.float64)
    if freqs.ndim != 1 or freqs.shape != mags.shape or len(freqs) < 4:
        raise ParameterError("frequency_hz", "and magnitude must be two equally long lists of "
                                             "at least 4 values")
    if not (np.all(np.isfinite(freqs)) and np.all(np.isfinite(mags)) and np.all(freqs > 0)
            and np.all(mags > 0)):
        raise ParameterError("magnitude", "needs positive finite frequencies and magnitudes")
    w = np.ones_like(freqs) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != freqs.shape or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ParameterError("weights", "must be one finite weight >= 0 per frequency, not all 0")
    root_w = np.sqrt(w / w.sum())
    log_mag = np.log(mags)
    top = int(np.argmax(mags))
    above_half = freqs[mags >= mags[top] / np.sqrt(2)]
    width = max(float(above_half.max() - above_half.min()), freqs[top] * 1e-3)
    start = np.log([freqs[top], max(freqs[top] / width, 0.1), mags[top]])

    def residuals(params: np.ndarray) -> np.ndarray:
        f0, q, g = np.exp(params)
        model = np.log(g) - 0.5 * np.log1p(q ** 2 * (freqs / f0 - f0 / freqs) ** 2)
        return root_w * (model - log_mag)

    # Bounded, so a response with no resonance in it (noise) cannot send f0 or Q off to
    # infinity: f0 within an octave of the data, Q 0.05 … 1000.
    lower = np.log([freqs.min() / 2, 0.05, mags.min() / 10])
    upper = np.log([freqs.max() * 2, 1000.0, mags.max() * 1e3])
    solution = least_squares(residuals, np.clip(start, lower + 1e-9, upper - 1e-9),
                             bounds=(lower, upper), method="trf")
    f0, q, g = (float(v) for v in np.exp(solution.x))
    residual_db = 20 / np.log(10) * float(np.sqrt(np.sum(solution.fun ** 2)))
    return ResonanceFit(f0, q, g, residual_db)


# -- the CSV --------------------------------------------------------------------------------

def write_response_csv(path: str | os.PathLike, response: Response) -> None:
    """Write ``response`` as the CSV :func:`~realpen.tactile.actuator.load_measured` reads, atomically.

    Columns (:data:`CSV_HEADER`): ``frequency_hz``, ``response_db`` (normalised to 0 dB at
    the peak), ``coherence`` (γ²) and ``distortion_db`` (empty where not measurable).
    :func:`realpen.tactile.actuator.load_measured` reads the first two (the header's "db"
    says the response is in dB) and ignores the others.

    Raises:
        RealPenError: the file cannot be written (naming it).
    """
    levels = 20 * np.log10(np.maximum(response.normalised, _TINY))
    rows = [",".join(CSV_HEADER)]
    for freq, level, gamma, distortion in zip(response.frequency_hz, levels, response.coherence,
                                              response.distortion_db):
        shown = "" if not np.isfinite(distortion) else f"{distortion:.2f}"
        rows.append(f"{freq:.4f},{level:.4f},{gamma:.4f},{shown}")
    with atomic_path(path) as tmp:
        try:
            tmp.write_text("\n".join(rows) + "\n", encoding="utf-8")
        except OSError as error:
            raise fail(path, f"cannot write ({error.strerror or error})") from None


