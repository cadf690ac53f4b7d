"""How close a rendered tactile loop comes to a real pen's vibration: the fidelity measures.

A loop is judged by what the actuator makes of it: the loop is played through the actuator's
magnitude response |H(f)| (as a periodic signal, so the filtering is exact circular
convolution) and compared with the target vibration — the acceleration the real pen makes, which
is what the fingers should feel. Three measures, all insensitive to overall level (the user sets
the level, and Eq. 1 moves it with speed and pressure):

- :func:`weighted_lsd`: log-spectral distance over 30–500 Hz, each frequency weighted by
  vibrotactile sensitivity (:func:`sensitivity_weights`), the two matched in weighted power
  first; dB. Levels more than :data:`DYNAMIC_RANGE_DB` (50 dB) below a spectrum's
  strongest are counted at that floor.
- :func:`third_octave_distance`: RMS difference of 1/3-octave band levels (IEC 61260 nominal
  centres 31.5–400 Hz), the two matched in total power first; dB.
- :func:`modulation_difference`: difference of the envelope's fluctuation — the standard
  deviation of 10 ms frame levels — between the two signals; dB.

The sensitivity curve is an approximation of the Pacinian (vibrotactile) detection threshold for
sinusoidal displacement at the thenar eminence (Verrillo, J. Acoust. Soc. Am. 35(12), 1963,
doi:10.1121/1.1918868): a parabola in log-frequency with its minimum of −20 dB re 1 µm at
250 Hz, rising to about +10 dB at 40 Hz and −15 dB at 500 Hz. Sensitivity is its inverse in
linear amplitude, so 250 Hz counts about 30 times as much as 40 Hz.

numpy and scipy only.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from realpen.checks import require_number
from realpen.errors import ParameterError
from realpen.tactile.actuator import Actuator, as_actuator

__all__ = ["BAND_HZ", "THIRD_OCTAVE_CENTRES_HZ", "SENSITIVITY_SOURCE", "threshold_db",
           "sensitivity_weights", "through_actuator", "loop_psd", "signal_psd", "weighted_lsd",
           "third_octave_distance", "modulation_depth_db", "modulation_difference", "fidelity",
           "DYNAMIC_RANGE_DB", "smoothed"]

BAND_HZ = (30.0, 500.0)
THIRD_OCTAVE_CENTRES_HZ = (31.5, 40.0, 50.0, 63.0, 80.0, 100.0, 125.0, 160.0, 200.0, 250.0,
                           315.0, 400.0)
SENSITIVITY_SOURCE = ("Verrillo 1963 (thenar eminence, Pacinian channel), approximated by a "
                      "parabola in log2 frequency: -20 dB re 1 um at 250 Hz, about +10 dB at 40 Hz")
_THRESHOLD_MIN_DB, _THRESHOLD_BEST_HZ, _THRESHOLD_CURVATURE = -20.0, 250.0, 4.3
_RESOLUTION_HZ = 2.0
DYNAMIC_RANGE_DB = 50.0
"""Spectra are compared over at most this range below their strongest frequency (dB)."""
_TINY = 1e-30


def threshold_db(frequency_hz: np.ndarray | float) -> np.ndarray:
    """Approximate vibrotactile displacement threshold, dB re 1 µm (see the module docstring)."""
    octaves = np.log2(np.maximum(np.asarray(frequency_hz, dtype=np.float64), 1e-6)
                      / _THRESHOLD_BEST_HZ)
    return _THRESHOLD_MIN_DB + _THRESHOLD_CURVATURE * octaves ** 2


def sensitivity_weights(frequency_hz: np.ndarray) -> np.ndarray:
    """Weights ∝ 1 / threshold (linear amplitude), summing to 1 over ``frequency_hz``."""
    weights = 10 ** (-threshold_db(frequency_hz) / 20)
    return weights / weights.sum()


def through_actuator(loop: np.ndarray, rate: float, actuator: Actuator | str) -> np.ndarray:
    """One period of what the actuator delivers when it plays ``loop`` over and over.

    The loop is periodic, so filtering by the actuator's magnitude response |H(f)| is an exact
    circular convolution (zero phase: phase does not change a power spectrum).

    Args:
        loop: one period, shape (frames,), full scale ±1.
        rate: its rate in Hz.
        actuator: an :class:`~realpen.tactile.actuator.Actuator` or a spec (``"lra:f0=175,q=8"``).

    Returns:
        float64 array of the same shape (acceleration, arbitrary unit).
    """
    loop = np.asarray(loop, dtype=np.float64)
    spectrum = np.fft.rfft(loop)
    response = as_actuator(actuator).response(np.fft.rfftfreq(len(loop), 1.0 / rate))
    return np.fft.irfft(spectrum * response, n=len(loop))


def signal_psd(x: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch power spectral density of a (long) signal: Hann segments for a 2 Hz resolution,
    half overlap.

    Returns:
        (frequencies in Hz, PSD in unit²/Hz).
    """
    x = np.asarray(x, dtype=np.float64)
    segment = int(round(rate / _RESOLUTION_HZ))
    if len(x) < segment:
        raise ParameterError("x", f"{len(x)} samples at {rate:g} Hz is shorter than one "
                                  f"{1 / _RESOLUTION_HZ:g} s analysis segment")
    return signal.welch(x, rate, window="hann", nperseg=segment, noverlap=segment // 2)


def loop_psd(loop: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD of a loop played over and over (tiled to at least eight segments), so a loop
    shorter than one analysis segment is measured as it is felt."""
    loop = np.asarray(loop, dtype=np.float64)
    segment = int(round(rate / _RESOLUTION_HZ))
    repeats = max(2, int(np.ceil(8 * segment / len(loop))))
    return signal_psd(np.tile(loop, repeats), rate)


def _on_grid(freqs: np.ndarray, psd: np.ndarray, grid: np.ndarray) -> np.ndarray:
    return np.interp(grid, freqs, psd)


def _floored(psd: np.ndarray) -> np.ndarray:
    """Levels in dB, no lower than :data:`DYNAMIC_RANGE_DB` below the strongest: gaps deeper
    than that are not felt next to the peaks, and their exact depth (window leakage) is noise."""
    levels = 10 * np.log10(np.maximum(psd, _TINY))
    return np.maximum(levels, levels.max() - DYNAMIC_RANGE_DB)


def _grid(band_hz: tuple[float, float]) -> np.ndarray:
    return np.arange(band_hz[0], band_hz[1] + 1e-9, _RESOLUTION_HZ)


def smoothed(spectrum: tuple[np.ndarray, np.ndarray], octaves: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """A PSD averaged (in power) over ``octaves`` around each frequency: the spectral envelope,
    without the fine structure a short loop's line spectrum or a short estimate has."""
    require_number("octaves", octaves, minimum=0.0, maximum=2.0)
    freqs, psd = (np.asarray(a, dtype=np.float64) for a in spectrum)
    if octaves == 0:
        return freqs, psd
    cumulative = np.concatenate([[0.0], np.cumsum(psd)])
    low = np.searchsorted(freqs, freqs * 2 ** (-octaves / 2), side="left")
    high = np.searchsorted(freqs, freqs * 2 ** (octaves / 2), side="right")
    high = np.maximum(high, low + 1)
    return freqs, (cumulative[high] - cumulative[low]) / (high - low)


def weighted_lsd(rendered: tuple[np.ndarray, np.ndarray], target: tuple[np.ndarray, np.ndarray],
                 band_hz: tuple[float, float] = BAND_HZ, weighted: bool = True,
                 smooth_octaves: float = 0.0) -> float:
    """Sensitivity-weighted log-spectral distance, dB.

    ``sqrt(Σ w(f) d(f)²)`` with ``d(f) = 10 log10(S_rendered / S_target) − offset`` on a 2 Hz
    grid over ``band_hz``, ``w`` the :func:`sensitivity_weights` (uniform with
    ``weighted=False``), and the offset matching the two spectra's ``w``-weighted power (overall
    level does not count: a user sets the felt intensity).

    Args:
        rendered, target: (frequencies Hz, PSD) pairs, e.g. from :func:`loop_psd` and
            :func:`signal_psd`.
        band_hz: (low, high) in Hz; must lie within both spectra.
        smooth_octaves: compare the spectral envelopes (:func:`smoothed` over this many
            octaves) instead of the spectra (0: as they are).
    """
    rendered, target = smoothed(rendered, smooth_octaves), smoothed(target, smooth_octaves)
    grid = _grid(band_hz)
    for name, (freqs, _) in (("rendered", rendered), ("target", target)):
        if freqs[-1] < grid[-1] - 1e-9:
            raise ParameterError(name, f"its spectrum ends at {freqs[-1]:g} Hz, below the "
                                       f"{band_hz[1]:g} Hz band edge")
    weights = sensitivity_weights(grid) if weighted else np.full(len(grid), 1 / len(grid))
    spectra = [_on_grid(*spectrum, grid) for spectrum in (rendered, target)]
    # Matched in sensitivity-weighted power, as a user matches the felt intensity.
    offset = 10 * np.log10(np.sum(weights * spectra[0]) / max(np.sum(weights * spectra[1]), _TINY)
                           + _TINY)
    difference = _floored(spectra[0]) - _floored(spectra[1]) - offset
    return float(np.sqrt(np.sum(weights * difference ** 2)))


def third_octave_distance(rendered: tuple[np.ndarray, np.ndarray],
                          target: tuple[np.ndarray, np.ndarray],
                          centres_hz: tuple[float, ...] = THIRD_OCTAVE_CENTRES_HZ) -> float:
    """RMS difference of 1/3-octave band levels (edges centre·2^(±1/6)), the two matched in
    total band power first, dB."""
    levels = []
    for freqs, psd in (rendered, target):
        step = freqs[1] - freqs[0]
        bands = [psd[(freqs >= c * 2 ** (-1 / 6)) & (freqs < c * 2 ** (1 / 6))].sum() * step
                 for c in centres_hz]
        levels.append(np.asarray(bands))
    offset = 10 * np.log10(levels[0].sum() / max(levels[1].sum(), _TINY) + _TINY)
    difference = _floored(levels[0]) - _floored(levels[1]) - offset
    return float(np.sqrt(np.mean(difference ** 2)))


def modulation_depth_db(x: np.ndarray, rate: float, frame_ms: float = 10.0,
                        band_hz: tuple[float, float] = BAND_HZ) -> float:
    """Envelope fluctuation: the standard deviation, dB, of the levels of ``frame_ms`` frames of
    ``x`` band-limited to ``band_hz`` (a 4th-order Butterworth band-pass, zero phase)."""
    require_number("frame_ms", frame_ms, minimum=0.0, inclusive=False)
    high = min(band_hz[1], 0.45 * rate)
    sos = signal.butter(4, (band_hz[0], high), btype="bandpass", fs=rate, output="sos")
    filtered = signal.sosfiltfilt(sos, np.asarray(x, dtype=np.float64))
    frame = max(1, int(round(frame_ms * rate / 1000)))
    count = len(filtered) // frame
    if count < 2:
        raise ParameterError("x", f"needs at least two {frame_ms:g} ms frames")
    power = np.mean(filtered[:count * frame].reshape(count, frame) ** 2, axis=1)
    return float(np.std(10 * np.log10(power + _TINY)))


def modulation_difference(rendered: np.ndarray, rendered_rate: float, target: np.ndarray,
                          target_rate: float, frame_ms: float = 10.0) -> float:
    """|modulation depth of ``rendered`` − that of ``target``|, dB (:func:`modulation_depth_db`),
    both band-limited to the same band (30 Hz to 500 Hz or 0.45 × the lower rate)."""
    band = (BAND_HZ[0], min(BAND_HZ[1], 0.45 * min(rendered_rate, target_rate)))
    return abs(modulation_depth_db(rendered, rendered_rate, frame_ms, band)
               - modulation_depth_db(target, target_rate, frame_ms, band))


def fidelity(loop: np.ndarray, rate: float, target: np.ndarray, target_rate: float,
             actuator: Actuator | str = "lra:f0=175,q=8", *, loop_is_periodic: bool = True
             ) -> dict[str, float]:
    """All three measures of a rendered loop (played through ``actuator``) against a target.

    Args:
        loop: the rendered tactile signal, full scale ±1; one period when ``loop_is_periodic``
            (it is tiled as it would loop), else a stretch of output (e.g. part of a stroke).
        rate: its rate in Hz.
        target: the real pen's vibration (acceleration), at ``target_rate`` Hz.

    Returns:
        ``{"lsd_db", "third_octave_db", "modulation_db"}`` (see the module docstring).
    """
    if loop_is_periodic:
        delivered = through_actuator(loop, rate, actuator)
        rendered_psd = loop_psd(delivered, rate)
        segment = int(round(rate / _RESOLUTION_HZ))
        played = np.tile(delivered, max(2, int(np.ceil(4 * segment / len(delivered)))))
    else:
        played = through_actuator(loop, rate, actuator)  # long enough that the wrap is noise
        rendered_psd = signal_psd(played, rate)
    target_psd = signal_psd(target, target_rate)
    return {"lsd_db": weighted_lsd(rendered_psd, target_psd),
            "third_octave_db": third_octave_distance(rendered_psd, target_psd),
            "modulation_db": modulation_difference(played, rate, target, target_rate)}
