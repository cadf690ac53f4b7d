"""Signals of known content for the tests."""

from __future__ import annotations

import numpy as np


def sines(frequencies_hz, amplitudes, rate: float, duration_s: float, phases=None,
          noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """Sum of sinusoids (plus optional white noise of the given standard deviation)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration_s * rate))) / rate
    phases = rng.uniform(0, 2 * np.pi, len(frequencies_hz)) if phases is None else phases
    x = sum(a * np.sin(2 * np.pi * f * t + p)
            for f, a, p in zip(frequencies_hz, amplitudes, phases))
    return x + noise * rng.standard_normal(len(t))


def fit_amplitudes(x: np.ndarray, rate: float, frequencies_hz) -> np.ndarray:
    """Least-squares amplitudes of sinusoids at known frequencies in ``x``."""
    t = np.arange(len(x)) / rate
    basis = np.hstack([np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
                       for f in frequencies_hz])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    return np.hypot(coef[0::2], coef[1::2])
