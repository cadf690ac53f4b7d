"""A profile's tactile pattern as the pen plays it: int16 samples at the pen's rate.

The pen loops one pattern of signed 16-bit samples at its own rate (its INFO ``sample_rate``;
8000 Hz on the reference Pico). :func:`pen_pattern` renders the profile's pattern there —
resampled as a loop, so the wrap stays seamless — and scales full scale ±1 to ±32767
(clipped, rounded to the nearest step). :func:`check_fits` refuses, before any byte is sent, a
pattern larger than the pen holds.

A profile with a vibration grid plays its reference pattern (``tactile.wav``): the pen's
messages carry no speed or force to follow the grid with.
"""

from __future__ import annotations

import numpy as np

from realpen.device.transport import DeviceError

__all__ = ["FULL_SCALE", "pen_pattern", "check_fits", "pattern_bytes"]

FULL_SCALE = 32767  # the int16 step of a sample of +1 (−1 → −32767: symmetric, −32768 unused)


def pen_pattern(profile, rate: int) -> np.ndarray:
    """The profile's tactile pattern as int16 samples at ``rate`` Hz, one loop.

    Args:
        profile: a :class:`~realpen.profile.bundle.PenProfile`.
        rate: the pen's sample rate in Hz (its INFO ``sample_rate``).

    Returns:
        int16 array, shape (frames,): ``round(32767 · x)`` of the pattern resampled to ``rate``,
        clipped to ±32767.

    Raises:
        ParameterError: (parameter ``rate``) not a whole number of Hz in the range patterns
            take, or the loop is not a whole number of samples at ``rate``.

    Example:
        >>> from realpen.profile.registry import resolve_profile
        >>> samples = pen_pattern(resolve_profile("pencil"), 8000)
        >>> samples.dtype, samples.shape, samples.nbytes
        (dtype('int16'), (12000,), 24000)
    """
    from realpen.exports.base import resample_loop

    own = int(profile.pattern.rate)
    loop = resample_loop(np.asarray(profile.tactile, dtype=np.float64), own, rate,
                         "tactile pattern")
    scaled = np.rint(np.clip(np.asarray(loop, dtype=np.float64), -1.0, 1.0) * FULL_SCALE)
    return scaled.astype(np.int16)


def pattern_bytes(samples: np.ndarray) -> bytes:
    """The samples as the pen stores them: int16, little-endian (format S16LE)."""
    return np.ascontiguousarray(samples, dtype="<i2").tobytes()


def check_fits(n_bytes: int, info, *, port: str | None = None) -> None:
    """Refuse a pattern larger than the pen holds.

    Args:
        n_bytes: the pattern's size in bytes (2 per sample).
        info: the pen's :class:`~realpen.device.client.PenInfo` (``max_pattern_bytes``,
            ``sample_rate``, ``name``).
        port: the pen's port, to name in the message.

    Raises:
        DeviceError: one line with both sizes (and both durations at the pen's rate).
    """
    limit = int(info.max_pattern_bytes)
    if n_bytes <= limit:
        return
    rate = int(info.sample_rate) or 1
    where = f"{port}: " if port else ""
    raise DeviceError(f"{where}the pattern ({n_bytes} bytes, {n_bytes / 2 / rate:g} s at {rate} "
                      f"Hz) is too large for the pen {info.name!r}, which holds at most {limit} "
                      f"bytes ({limit / 2 / rate:g} s); use a shorter pattern")
