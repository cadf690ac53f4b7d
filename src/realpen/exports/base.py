"""What every export returns, and the checks of the options they share."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import resample_poly

from realpen.errors import RealPenError

MAX_REPEATS = 100  # 150 s of a 1.5 s pattern; players loop, files need not


@dataclass
class Export:
    """One rendered export, not yet written.

    Attributes:
        data: the bytes of the main file.
        summary: one line saying what is in it.
        companions: further files to write beside the main one, by file name (e.g. the sound
            an AHAP refers to).
        limits: what the format could not carry, one sentence each.
    """

    data: bytes
    summary: str
    companions: dict[str, bytes] = field(default_factory=dict)
    limits: tuple[str, ...] = ()


def check_repeats(repeats: int) -> int:
    """``repeats`` as an int in 1 … :data:`MAX_REPEATS`; else a one-line error naming it."""
    if int(repeats) != repeats or not 1 <= repeats <= MAX_REPEATS:
        raise RealPenError(f"--repeats: must be a whole number from 1 to {MAX_REPEATS}, "
                           f"got {repeats}")
    return int(repeats)


def resample_loop(x: np.ndarray, rate: int, new_rate: int, what: str = "pattern") -> np.ndarray:
    """Resample one period of a looping signal (polyphase), keeping it a seamless loop.

    The period is resampled with a copy of itself on either side, so the anti-aliasing filter
    sees the wrap as it sounds, and the middle copy is kept.

    Args:
        x: one period, shape (frames,) or (frames, channels).
        rate, new_rate: sampling rates in Hz.
        what: how to name the signal in an error.

    Raises:
        RealPenError: ``new_rate`` is not positive, or the period is not a whole number of
            samples at ``new_rate`` (the loop would drift by a fraction of a sample each time).
    """
    if int(new_rate) != new_rate or new_rate <= 0:
        raise RealPenError(f"--rate: must be a positive whole number of Hz, got {new_rate}")
    new_rate = int(new_rate)
    if new_rate == rate:
        return np.asarray(x)
    x = np.asarray(x, dtype=np.float64)
    frames = len(x) * new_rate / rate
    if abs(frames - round(frames)) > 1e-9:
        raise RealPenError(f"--rate: the {what} ({len(x)} samples at {rate} Hz) is not a whole "
                           f"number of samples at {new_rate} Hz; choose a rate that makes "
                           f"{len(x) / rate * 1000:g} ms a whole number of samples")
    gcd = np.gcd(int(rate), new_rate)
    tripled = np.concatenate([x, x, x])
    out = resample_poly(tripled, new_rate // gcd, int(rate) // gcd, axis=0)
    count = int(round(frames))
    return out[count:2 * count]
