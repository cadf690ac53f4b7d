"""A multisine equalised by a measured actuator, and how flat it arrives: the check of
``realpen actuator verify``.

:func:`equalised_multisine` weights each component by 1/|H| of the actuator
(:func:`realpen.tactile.actuator.weighting`, capped), with Schroeder phases for a low crest
factor, on odd multiples of 1/loop so every 2nd-order product of two components falls between
them. The pen loops it while its accelerometer records; :func:`flatness` reads each component's
arrived level from the whole loops of the capture (:mod:`realpen.tactile.loops`).

References:
    M. R. Schroeder, "Synthesis of low-peak-factor signals and binary sequences with low
    autocorrelation", IEEE Trans. Inf. Theory 16(1), 1970, doi:10.1109/TIT.1970.1054411.

numpy and scipy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realpen.checks import MAX_CAP_DB, require_number
from realpen.errors import ParameterError
from realpen.tactile.actuator import Actuator, as_actuator, weighting
from realpen.tactile.loops import (
    LOST,
    MAX_PATTERN_SAMPLES,
    as_capture,
    check_loop_options,
    pattern_int16,
    require_loops,
    whole_loops,
)

__all__ = ["Multisine", "Flatness", "equalised_multisine", "flatness", "VERIFY_BAND_HZ"]

VERIFY_BAND_HZ = (80.0, 500.0)
"""The band :func:`equalised_multisine` covers by default, Hz."""
_TINY = 1e-30


@dataclass(frozen=True, eq=False)
class Multisine:
    """A looped sum of sines (see :func:`equalised_multisine`).

    Attributes:
        samples: one loop, float64 in [−1, 1].
        rate_hz: the pattern's rate, Hz.
        frequency_hz: the components, Hz (odd multiples of 1/period).
        amplitudes: their amplitudes in the loop (full scale 1).
        weights: the equalising weights (1 for a flat actuator).
        clipped: True where the cap limited the weight.
        band_hz: (low, high), Hz.
        cap_db: the weighting's cap, dB.
        actuator: the spec of the actuator it equalises.
    """

    samples: np.ndarray
    rate_hz: int
    frequency_hz: np.ndarray
    amplitudes: np.ndarray
    weights: np.ndarray
    clipped: np.ndarray
    band_hz: tuple[float, float]
    cap_db: float
    actuator: str

    @property
    def period_s(self) -> float:
        """One loop, s."""
        return self.samples.size / self.rate_hz

    def to_int16(self) -> np.ndarray:
        """The loop as int16 pattern samples."""
        return pattern_int16(self.samples)


@dataclass(frozen=True, eq=False)
class Flatness:
    """How flat a multisine arrived (see :func:`flatness`).

    Attributes:
        frequency_hz: the components, Hz.
        level_db: each component's arrived level relative to the mean level, dB.
        spread_db: max − min of ``level_db``, dB.
        deviation_db: the largest |level − mean|, dB (the "± dB" figure).
        periods: loops analysed.
        clipped: True where the multisine's cap limited the weight (such a component cannot
            arrive flat).
    """

    frequency_hz: np.ndarray
    level_db: np.ndarray
    spread_db: float
    deviation_db: float
    periods: int
    clipped: np.ndarray


def _schroeder_phases(power_shares: np.ndarray) -> np.ndarray:
    """Schroeder's low-crest phases for components of the given power shares (summing to 1):
    φ_n = −2π Σ_{l<n} (n − l) p_l."""
    n = len(power_shares)
    index = np.arange(n)
    lags = np.clip(index[:, None] - index[None, :], 0, None)
    return -2 * np.pi * (lags * power_shares[None, :]).sum(axis=1)


def equalised_multisine(actuator: Actuator | str, rate_hz: int = 8000, *,
                        band_hz: tuple[float, float] = VERIFY_BAND_HZ, duration_s: float = 1.0,
                        cap_db: float = 30.0, per_octave: int = 12, level: float = 0.9,
                        max_samples: int = MAX_PATTERN_SAMPLES) -> Multisine:
    """A looped multisine whose components are weighted by 1/|H| of ``actuator``, so they
    arrive equally strong when the actuator's response is what was measured.

    Components: about ``per_octave`` an octave, log-spaced over ``band_hz``, each on an odd
    multiple of 1/loop (every 2nd-order product of two components then falls between them);
    weights from :func:`realpen.tactile.actuator.weighting` (capped at ``cap_db``); Schroeder
    phases for a low crest factor; peak at ``level``.

    Args:
        actuator: the measured actuator (``load_measured``, or a spec; ``"flat"`` gives the
            unequalised multisine).
        rate_hz: the pen's playback rate, Hz.
        band_hz: (low, high), Hz.
        duration_s: one loop, s.
        cap_db: the largest boost, dB (the default 30 reaches 80–500 Hz of a Q 8 resonance).
        per_octave: components an octave.
        level: peak amplitude, 0 … 1.
        max_samples: the most samples the pen holds.

    Returns:
        The :class:`Multisine`.

    Raises:
        ParameterError: a value out of range.
    """
    actuator = as_actuator(actuator)
    require_number("rate_hz", rate_hz, minimum=100, maximum=192_000)
    low, high = (float(v) for v in band_hz)
    if not (np.isfinite(low) and np.isfinite(high) and 0 < low < high <= 0.45 * rate_hz):
        raise ParameterError("band_hz", f"must be (low, high) with 0 < low < high <= 0.45 of "
                                        f"the rate, got {band_hz!r}")
    require_number("duration_s", duration_s, minimum=0.0, inclusive=False)
    require_number("cap_db", cap_db, minimum=0.0, maximum=MAX_CAP_DB)
    require_number("per_octave", per_octave, minimum=1, maximum=96)
    require_number("level", level, minimum=0.0, maximum=1.0, inclusive=False)
    n = int(min(round(duration_s * rate_hz), max_samples))
    period_s = n / rate_hz
    wanted = np.geomspace(low, high, max(2, int(round(np.log2(high / low) * per_octave)) + 1))
    bins = np.unique(2 * np.round((wanted * period_s - 1) / 2) + 1).astype(np.int64)
    bins = bins[(bins / period_s >= low) & (bins / period_s <= high)]
    if len(bins) < 2:
        raise ParameterError("duration_s", f"a {period_s:g} s loop has fewer than 2 odd "
                                           f"frequencies within {low:g}–{high:g} Hz")
    freqs = bins / period_s
    equalising = weighting(actuator, freqs, (low, high), cap_db)
    amplitudes = equalising.weights
    phases = _schroeder_phases(amplitudes ** 2 / np.sum(amplitudes ** 2))
    spectrum = np.zeros(n // 2 + 1, dtype=np.complex128)
    spectrum[bins] = amplitudes * np.exp(1j * phases) * n / 2
    samples = np.fft.irfft(spectrum, n=n)
    scale = level / np.max(np.abs(samples))
    return Multisine(samples * scale, int(rate_hz), freqs, amplitudes * scale, equalising.weights,
                     equalising.clipped, (low, high), float(cap_db), actuator.spec)


def flatness(capture: np.ndarray, capture_rate_hz: float, multisine: Multisine, *,
             periods_to_skip: int = 1, periods: int | None = None) -> Flatness:
    """How flat ``multisine`` arrived: each component's level, power-averaged over the whole
    loops after ``periods_to_skip`` (the axes combined as √(Σ power)), relative to the mean
    level in dB; the spread (max − min) and the largest deviation from the mean.

    Args:
        capture: acceleration recorded while the pen looped ``multisine``, shape (n,) or
            (n, 1…3); NaN where samples are missing (taken from the other loops there).
        capture_rate_hz: its estimated rate, Hz.
        multisine: what the pen looped (:func:`equalised_multisine`).
        periods_to_skip: whole loops to drop at the start.
        periods: the most loops to analyse after them (None: every whole one).

    Returns:
        The :class:`Flatness`.

    Raises:
        ParameterError: (``capture``) fewer than 2 whole loops after the skip, a malformed
            capture, or a value out of range.
    """
    check_loop_options(capture_rate_hz, periods_to_skip, periods)
    if not isinstance(multisine, Multisine):
        raise ParameterError("multisine", f"must be a Multisine (equalised_multisine), got "
                                          f"{type(multisine).__name__}")
    capture = as_capture(capture)
    if np.max(multisine.frequency_hz) >= 0.45 * capture_rate_hz:
        raise ParameterError("capture_rate_hz", f"{capture_rate_hz:g} Hz is too slow for "
                                                f"components up to "
                                                f"{np.max(multisine.frequency_hz):g} Hz")
    loops, _, whole = whole_loops(capture, float(capture_rate_hz), multisine.period_s,
                                  int(periods_to_skip), "multisine", periods)
    require_loops(whole, "are whole", LOST)
    loops = loops[whole]
    bins = np.round(multisine.frequency_hz * multisine.period_s).astype(np.int64)
    spectra = np.fft.rfft(loops, axis=1)[:, bins, :]
    levels = 10 * np.log10(np.maximum(np.mean(np.sum(np.abs(spectra) ** 2, axis=-1), axis=0),
                                      _TINY))
    relative = levels - levels.mean()
    return Flatness(multisine.frequency_hz.copy(), relative, float(np.ptp(relative)),
                    float(np.max(np.abs(relative))), len(loops), multisine.clipped.copy())
