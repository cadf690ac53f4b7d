"""Waveform measures: how well a stage that must keep the waveform kept it.

The fidelity measures (:mod:`realpen.tactile.fidelity`) judge a texture: they ignore phase and
level, as the fingers do. A stage that must hand the waveform on unchanged — an export read back,
a resampling, the pen firmware's playback — is judged sample against sample instead, the decoded
signal against its reference at the same rate:

- :func:`mpeg_psnr`: MPEG's objective measure for haptics (ISO/IEC 23090-31 conformance),
  signals in [−1, 1], peak-to-peak 2: ``PSNR = 10·log10(4 / MSE)`` in dB.
- :func:`snr_db`: reference energy over error energy, in dB.
- :func:`st_sim` and :func:`spqi`: two perceptual measures as the ``vibromaf`` package (MIT;
  Noll, Hofbauer et al., IEEE Haptics Symposium 2022, doi:10.1109/HAPTICS52432.2022.9765599)
  implements them: ST-SIM (spectral-temporal similarity, 0 … 1) and SPQI (spectral perceptual
  quality index, 0 … 1), 1 for identical signals.

vibromaf's perceptual threshold and block length (512 samples) assume signals at 8 kHz, the rate
its measures were fitted at. Both signals are resampled to 8 kHz first
(``scipy.signal.resample_poly``) rather than the threshold recomputed for their own rate: at
another rate a 512-sample block would span another length of time and another frequency
resolution, and the fitted mappings would no longer hold. Touch reaches up to about 1 kHz, far
below the 4 kHz that 8 kHz keeps, so nothing felt is lost. vibromaf is imported only when these
two are computed (it pulls scipy.stats), so ``import realpen`` stays light.

May import: numpy, scipy, vibromaf, :mod:`realpen.checks` and :mod:`realpen.errors`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from realpen.checks import require_rate, shown_value
from realpen.errors import ParameterError

__all__ = ["MPEG_PEAK_TO_PEAK", "METRIC_RATE_HZ", "METRIC_BLOCK_SAMPLES", "STSIM_ETA",
           "WaveformMeasures", "mpeg_psnr", "snr_db", "st_sim", "spqi", "measure_waveform"]

MPEG_PEAK_TO_PEAK = 2.0
"""The peak-to-peak range of MPEG's PSNR: signals in [−1, 1]."""
METRIC_RATE_HZ = 8000
"""The rate (Hz) ST-SIM and SPQI are computed at: the one vibromaf's threshold assumes."""
METRIC_BLOCK_SAMPLES = 512
"""vibromaf's block length at :data:`METRIC_RATE_HZ` (64 ms): the shortest signal it measures."""
STSIM_ETA = 2 / 3
"""vibromaf's default weight of the temporal similarity in ST-SIM (the spectral one gets 1/3)."""


@dataclass(frozen=True)
class WaveformMeasures:
    """The four waveform measures of a decoded signal against its reference.

    Attributes:
        psnr: MPEG PSNR in dB (peak-to-peak 2); ``inf`` for identical signals.
        snr: signal-to-noise ratio in dB; ``inf`` for identical signals.
        st_sim: ST-SIM, 0 … 1 (1: identical).
        spqi: SPQI, 0 … 1 (1: identical spectra).
    """

    psnr: float
    snr: float
    st_sim: float
    spqi: float

    def __str__(self) -> str:
        return (f"PSNR {self.psnr:.1f} dB, SNR {self.snr:.1f} dB, ST-SIM {self.st_sim:.3f}, "
                f"SPQI {self.spqi:.3f}")


def mpeg_psnr(decoded: np.ndarray, reference: np.ndarray) -> float:
    """MPEG's PSNR of ``decoded`` against ``reference``: ``10·log10(4 / MSE)`` in dB.

    The peak-to-peak range is 2 (:data:`MPEG_PEAK_TO_PEAK`): both signals are full scale ±1.
    Samples beyond ±1 (a decoder's overshoot) are measured as they are, not clipped.

    Args:
        decoded: the signal the stage produced, shape (frames,), full scale ±1.
        reference: what it should have produced, the same shape and rate.

    Returns:
        PSNR in dB; ``inf`` when the two are identical.

    Raises:
        ParameterError: not two one-dimensional signals of the same length with finite values.

    Example:
        >>> round(mpeg_psnr(np.full(4, 0.1), np.zeros(4)), 6)  # MSE 0.01: 10·log10(400)
        26.0206
    """
    decoded, reference = _pair(decoded, reference)
    mse = float(np.mean(np.square(decoded - reference)))
    if mse == 0.0:
        return math.inf
    return 10.0 * math.log10(MPEG_PEAK_TO_PEAK ** 2 / mse)


def snr_db(decoded: np.ndarray, reference: np.ndarray) -> float:
    """Signal-to-noise ratio: the reference's energy over the error's, in dB.

    Args:
        decoded: the signal the stage produced, shape (frames,).
        reference: what it should have produced, the same shape and rate.

    Returns:
        SNR in dB; ``inf`` when the two are identical, ``-inf`` when the reference is silent
        and the decoded signal is not.

    Raises:
        ParameterError: not two one-dimensional signals of the same length with finite values.

    Example:
        >>> round(snr_db(np.array([1.1, -1.1]), np.array([1.0, -1.0])), 6)
        20.0
    """
    decoded, reference = _pair(decoded, reference)
    error = float(np.sum(np.square(decoded - reference)))
    if error == 0.0:
        return math.inf
    signal = float(np.sum(np.square(reference)))
    if signal == 0.0:
        return -math.inf
    return 10.0 * math.log10(signal / error)


def st_sim(decoded: np.ndarray, reference: np.ndarray, rate: float) -> float:
    """ST-SIM (vibromaf): spectral-temporal similarity of ``decoded`` to ``reference``, 0 … 1.

    vibromaf's ``temporal^η · spectral^(1−η)`` (η = :data:`STSIM_ETA`) with both signals at
    8 kHz (see the module docstring), computed from vibromaf's own building blocks with each
    similarity held to [0, 1] first:

    - The temporal similarity is the mean correlation of the 64 ms blocks, −1 … 1. vibromaf
      raises it to the power 2/3 as it is, which for an anti-correlated signal (an inverted
      waveform) gives a complex number. A waveform-preserving stage that inverts the waveform
      has kept nothing of its shape, so a negative similarity counts as 0 (no similarity) and
      ST-SIM is then 0: always a real number.
    - The spectral similarity exceeds 1 when the decoded signal has more perceptible spectral
      support than the reference (it is louder, or has content the reference lacks); being
      more than the reference is not being closer, so it counts as 1.

    Where both similarities already lie in [0, 1] the result is vibromaf's exactly.

    Args:
        decoded: the signal the stage produced, shape (frames,).
        reference: what it should have produced, the same shape.
        rate: the sample rate of both, in whole Hz.

    Returns:
        ST-SIM, a float 0 … 1; 1.0 for identical signals.

    Raises:
        ParameterError: not two one-dimensional signals of the same length with finite values,
            a rate that is not a whole number of Hz in range, or signals shorter than one
            64 ms block.
    """
    decoded, reference = _at_metric_rate(decoded, reference, rate)
    return _st_sim_at_metric_rate(decoded, reference)


def spqi(decoded: np.ndarray, reference: np.ndarray, rate: float) -> float:
    """SPQI (vibromaf): spectral perceptual quality index of ``decoded`` against ``reference``.

    vibromaf's SPQI with its default mapping (η 0.3, threshold −2), both signals at 8 kHz (see
    the module docstring). It compares perceptual magnitude spectra only, so an inverted or
    shifted waveform scores as the original does: pair it with :func:`mpeg_psnr` or
    :func:`st_sim` where the waveform itself matters.

    Args:
        decoded: the signal the stage produced, shape (frames,).
        reference: what it should have produced, the same shape.
        rate: the sample rate of both, in whole Hz.

    Returns:
        SPQI, a float 0 … 1; 1.0 for identical signals.

    Raises:
        ParameterError: as :func:`st_sim`.
    """
    decoded, reference = _at_metric_rate(decoded, reference, rate)
    return _spqi_at_metric_rate(decoded, reference)


def measure_waveform(decoded: np.ndarray, reference: np.ndarray, rate: float) -> WaveformMeasures:
    """All four waveform measures of ``decoded`` against ``reference`` (resampled once).

    Args:
        decoded: the signal the stage produced, shape (frames,), full scale ±1.
        reference: what it should have produced, the same shape, at the same rate.
        rate: the sample rate of both, in whole Hz.

    Returns:
        :class:`WaveformMeasures`: MPEG PSNR and SNR in dB, ST-SIM and SPQI 0 … 1.

    Raises:
        ParameterError: as :func:`st_sim`.
    """
    decoded, reference = _pair(decoded, reference)
    low_decoded, low_reference = _at_metric_rate(decoded, reference, rate)
    return WaveformMeasures(psnr=mpeg_psnr(decoded, reference),
                            snr=snr_db(decoded, reference),
                            st_sim=_st_sim_at_metric_rate(low_decoded, low_reference),
                            spqi=_spqi_at_metric_rate(low_decoded, low_reference))


# --- checks and the 8 kHz pair ---------------------------------------------------------------

def _pair(decoded: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two signals as float64 after the shape, length and value checks."""
    arrays = []
    for name, value in (("decoded", decoded), ("reference", reference)):
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(name, f"must be an array of numbers, got "
                                       f"{shown_value(value)}") from None
        if array.ndim != 1:
            raise ParameterError(name, f"must be one-dimensional (one channel of samples), got "
                                       f"shape {array.shape}")
        if array.size == 0:
            raise ParameterError(name, "must hold at least one sample, got none")
        if not np.all(np.isfinite(array)):
            raise ParameterError(name, "must hold finite samples, got NaN or infinity")
        arrays.append(array)
    decoded, reference = arrays
    if decoded.size != reference.size:
        raise ParameterError("decoded", f"must have as many samples as reference "
                                        f"({reference.size:,}), got {decoded.size:,}")
    return decoded, reference


def _at_metric_rate(decoded: np.ndarray, reference: np.ndarray, rate: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Both signals checked and resampled from ``rate`` to :data:`METRIC_RATE_HZ`."""
    from scipy.signal import resample_poly

    decoded, reference = _pair(decoded, reference)
    require_rate("rate", rate)
    if int(rate) != rate:
        raise ParameterError("rate", f"must be a whole number of Hz, got {shown_value(rate)}")
    rate = int(rate)
    frames = reference.size * METRIC_RATE_HZ // rate
    if frames < METRIC_BLOCK_SAMPLES:
        raise ParameterError("reference", f"must last at least "
                                          f"{1000 * METRIC_BLOCK_SAMPLES / METRIC_RATE_HZ:g} ms "
                                          f"(one ST-SIM/SPQI block), got "
                                          f"{1000 * reference.size / rate:g} ms")
    if rate == METRIC_RATE_HZ:
        return decoded, reference
    common = math.gcd(rate, METRIC_RATE_HZ)
    up, down = METRIC_RATE_HZ // common, rate // common
    return resample_poly(decoded, up, down), resample_poly(reference, up, down)


def _st_sim_at_metric_rate(decoded: np.ndarray, reference: np.ndarray) -> float:
    from vibromaf.metrics.stsim import STSIM
    from vibromaf.signal.spectrum import compute_spectral_support

    if np.array_equal(decoded, reference):
        return 1.0
    metric = STSIM(STSIM_ETA)
    builder = metric.perceptual_spectrum_builder
    # A silent block has a spectrum of −inf dB: vibromaf handles it (its support is 0) but
    # numpy warns on the way.
    with np.errstate(divide="ignore", invalid="ignore"):
        spectral = STSIM.compute_sim(
            compute_spectral_support(builder.compute_perceptual_spectrum(reference)),
            compute_spectral_support(builder.compute_perceptual_spectrum(decoded)))
        temporal = STSIM.compute_sim(builder.block_builder.divide_and_normalize(reference),
                                     builder.block_builder.divide_and_normalize(decoded))
    temporal = min(max(float(temporal), 0.0), 1.0)
    spectral = min(max(float(spectral), 0.0), 1.0)
    return float(temporal ** STSIM_ETA * spectral ** (1.0 - STSIM_ETA))


def _spqi_at_metric_rate(decoded: np.ndarray, reference: np.ndarray) -> float:
    from vibromaf.metrics.spqi import spqi as vibromaf_spqi

    with np.errstate(divide="ignore", invalid="ignore"):
        return float(vibromaf_spqi(decoded, reference))
