"""Comparing pens: the distance between their tactile spectra."""

from __future__ import annotations

import numpy as np
from scipy import signal

from realpen.profile.bundle import PenProfile

__all__ = ["BAND_HZ", "tactile_spectrum_db", "spectral_distance_db"]

BAND_HZ = (30.0, 700.0)


def tactile_spectrum_db(profile: PenProfile, resolution_hz: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Welch power spectrum of the tactile pattern in the tactile band, in dB re its own mean.

    Returns:
        (frequencies in Hz, level in dB with the band mean removed, so only the shape counts).
    """
    rate = profile.meta.tactile.rate
    nperseg = int(rate / resolution_hz)
    freqs, psd = signal.welch(profile.tactile.astype(np.float64), rate, nperseg=nperseg)
    keep = (freqs >= BAND_HZ[0]) & (freqs <= BAND_HZ[1])
    level = 10 * np.log10(psd[keep] + 1e-20)
    return freqs[keep], level - level.mean()


def spectral_distance_db(a: PenProfile, b: PenProfile) -> float:
    """RMS difference in dB between two pens' tactile spectrum shapes (30–700 Hz)."""
    _, level_a = tactile_spectrum_db(a)
    _, level_b = tactile_spectrum_db(b)
    return float(np.sqrt(np.mean((level_a - level_b) ** 2)))
