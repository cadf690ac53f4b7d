"""Cutting a capture made while the pen looped a pattern into whole loops of the pattern.

The pen plays the pattern and samples its accelerometer on one clock, so a loop of an
``N``-sample pattern at ``rate_hz`` lasts exactly ``N / rate_hz`` s of capture time; the capture's
rate (≈1344 Hz, a few per cent off nominal) is known only as an estimate. A capture is read at
a whole number of samples per loop with a band-limited (Kaiser-windowed sinc) resampler, so each
loop's DFT bins fall on the pattern's harmonics. Shared by :mod:`realpen.tactile.measure` (the
swept-sine response) and :mod:`realpen.tactile.multisine` (the equalised check).

numpy and scipy only.
"""

from __future__ import annotations

import numpy as np

from realpen.checks import require_number
from realpen.errors import ParameterError

__all__ = ["LOST", "as_capture", "resample", "whole_loops", "check_loop_options", "require_loops",
           "pattern_int16", "INTERP_HALF_WIDTH", "MAX_PATTERN_SAMPLES", "MAX_FILLED"]

MAX_PATTERN_SAMPLES = 16384
"""The most samples a test pattern has by default: 32768 bytes of int16, what the Pico holds."""
INTERP_HALF_WIDTH = 32
"""Input samples each side of the resampling kernel (a loop needs them whole on both sides)."""
LOST = "samples were lost on the way, where no other loop could stand in"
"""Why loops are not whole, for :func:`require_loops`."""
MAX_FILLED = 0.2
"""The largest share of a loop taken from the other loops (where its own samples are missing)."""
_KAISER_BETA = 8.0
_TOUCHED = 1e-6  # a resampled sample whose kernel put this much weight on a missing one


def pattern_int16(samples: np.ndarray) -> np.ndarray:
    """Samples in [−1, 1] as int16 pattern samples (full scale 32767)."""
    return np.round(np.clip(samples, -1.0, 1.0) * 32767).astype(np.int16)


def as_capture(capture: np.ndarray) -> np.ndarray:
    """A capture as float64 (n, axes) about its mean, NaN rows where a sample is missing.

    Raises:
        ParameterError: (``capture``) another shape, infinite values, or no sample at all.
    """
    capture = np.array(capture, dtype=np.float64)
    if capture.ndim == 1:
        capture = capture[:, None]
    if capture.ndim != 2 or not 1 <= capture.shape[1] <= 3 or capture.shape[0] == 0:
        raise ParameterError("capture", f"must be samples of shape (n,) or (n, 1…3), got shape "
                                        f"{capture.shape}")
    if np.any(np.isinf(capture)):
        raise ParameterError("capture", "holds infinite values")
    missing = np.isnan(capture)
    if missing.all():
        raise ParameterError("capture", "holds no samples (all NaN)")
    if missing.any():  # gaps: a missing sample on one axis is missing on all
        capture[np.any(missing, axis=1)] = np.nan
    return capture - np.nanmean(capture, axis=0)


def resample(capture: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """``capture`` (n, axes) read at fractional sample ``positions`` with a Kaiser-windowed
    sinc: flat within 0.1 dB to about 0.45 of the rate, so 500 Hz at 1344 Hz is exact."""
    from scipy.special import i0  # numpy's i0 is ten times slower

    width = INTERP_HALF_WIDTH
    base = np.floor(positions).astype(np.int64)
    taps = np.arange(-width + 1, width + 1)
    index = base[:, None] + taps[None, :]
    distance = positions[:, None] - index
    taper = i0(_KAISER_BETA * np.sqrt(np.clip(1 - (distance / width) ** 2, 0, 1)))
    kernel = np.sinc(distance) * taper / i0(_KAISER_BETA)
    inside = (index >= 0) & (index < len(capture))
    kernel = np.where(inside, kernel, 0.0)
    return np.einsum("jt,jta->ja", kernel, capture[np.clip(index, 0, len(capture) - 1)])


def whole_loops(capture: np.ndarray, capture_rate_hz: float, period_s: float,
                periods_to_skip: int, what: str, limit: int | None = None
                ) -> tuple[np.ndarray, int, np.ndarray]:
    """The capture after ``periods_to_skip`` loops, cut into whole loops (at most ``limit``).

    Samples missing from the capture (NaN: a gap) are taken from the other loops at the same
    place: the pen played the same pattern there, so only the noise differs. A loop whose gap
    no other loop can fill (or that misses more than :data:`MAX_FILLED` of itself) is not
    whole.

    Args:
        capture: from :func:`as_capture`.
        capture_rate_hz: its rate, Hz.
        period_s: one loop of the pattern, s.
        periods_to_skip: loops dropped at the start.
        what: the pattern, for the message (``"sweep"``).
        limit: the most loops returned (None: all).

    Returns:
        (loops of ``m`` samples each, m = round(period · rate), resampled: array
        (loops, m, axes); m; which loops are whole).

    Raises:
        ParameterError: (``capture``) fewer than 2 whole loops after the skip.
    """
    per_period = period_s * capture_rate_hz
    samples = int(round(per_period))
    start = periods_to_skip * per_period + INTERP_HALF_WIDTH
    last = len(capture) - INTERP_HALF_WIDTH - 1  # the kernel needs whole context
    count = int(np.floor((last - start) / per_period + 1e-9)) if last > start else 0
    if count < 2:
        needed = (periods_to_skip + 2) * period_s + 2 * INTERP_HALF_WIDTH / capture_rate_hz
        raise ParameterError("capture", f"holds {max(count, 0)} whole {what} loop(s) of "
                                        f"{period_s:g} s after skipping {periods_to_skip}; "
                                        f"needs at least 2 (record at least {needed:.1f} s, "
                                        f"got {len(capture) / capture_rate_hz:.1f} s)")
    count = count if limit is None else min(count, limit)
    positions = start + np.arange(count * samples) * (per_period / samples)
    missing = np.isnan(capture[:, :1])
    loops = resample(np.nan_to_num(capture, nan=0.0), positions)
    loops = loops.reshape(count, samples, capture.shape[1])
    if not missing.any():
        return loops, samples, np.ones(count, dtype=bool)
    # Every resampled sample the kernel took a missing one into (its weight is never 0 within
    # the kernel's reach).
    touched = np.abs(resample(missing.astype(np.float64), positions)).reshape(count, samples)
    touched = touched > _TOUCHED
    donors = ~touched
    fillable = touched & donors.any(axis=0)[None, :]
    for loop in np.flatnonzero(fillable.any(axis=1)):
        where = fillable[loop]
        others = donors[:, where]
        loops[loop, where] = np.sum(loops[:, where] * others[:, :, None], axis=0) \
            / others.sum(axis=0)[:, None]
    whole = ~np.any(touched & ~fillable, axis=1) & (touched.mean(axis=1) <= MAX_FILLED)
    return loops, samples, whole


def check_loop_options(capture_rate_hz: float, periods_to_skip: int, periods: int | None
                       ) -> None:
    """Refuse a rate outside 10 … 100 000 Hz, or loop counts that are not whole numbers
    (``periods_to_skip`` ≥ 0, ``periods`` ≥ 2 or None).

    Raises:
        ParameterError: naming the parameter.
    """
    require_number("capture_rate_hz", capture_rate_hz, minimum=10.0, maximum=100_000.0)
    for name, value, least in (("periods_to_skip", periods_to_skip, 0), ("periods", periods, 2)):
        if value is None:
            continue
        require_number(name, value, minimum=least, maximum=100_000)
        if int(value) != value:
            raise ParameterError(name, f"must be a whole number, got {value}")


def require_loops(kept: np.ndarray, what: str, cause: str) -> None:
    """Refuse fewer than 2 ``kept`` loops, saying what the kept ones are (``"are whole"``) and
    why the others were lost.

    Raises:
        ParameterError: (``capture``) one line.
    """
    if kept.sum() < 2:
        raise ParameterError("capture", f"only {int(kept.sum())} of {len(kept)} loops {what}: "
                                        f"{cause}; measure again")
