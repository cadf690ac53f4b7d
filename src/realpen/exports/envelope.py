"""What the envelope formats keep of a tactile pattern: frame RMS and spectral centroid.

AHAP, ``.haptic`` and Android cannot carry a superposition of sinusoids; they carry one
intensity and one frequency (or "sharpness") at a time. This module measures both on the
pattern itself (not on its component list, so any pattern works): the RMS of short frames and
the power-weighted spectral centroid of a Hann window centred on each frame. The pattern loops,
so frames and windows wrap around its end.

A looping pattern becomes a curve over one period, ``0 … T``, with one point per frame centre
and a point at each end holding the value interpolated across the wrap, so that the curve's end
meets its start; ``repeats`` lays several periods end to end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realpen.errors import fail

__all__ = ["FRAME_MS", "WINDOW_MS", "SHARPNESS_RANGE_HZ", "Envelope", "measure", "sharpness",
           "sharpness_to_hz", "loop_curve"]

FRAME_MS = 10.0  # short enough for the beating between components, long enough to average
WINDOW_MS = 40.0  # centroid window: 25 Hz resolution before zero padding
SHARPNESS_RANGE_HZ = (30.0, 500.0)  # high-pass of the method … upper edge of touch
_BLOCK_VALUES = 2**22  # spectrum bins computed at once (64 MiB as complex)


@dataclass(frozen=True)
class Envelope:
    """Frame-wise measures of one period of a looping pattern.

    Attributes:
        edges_s: frame edges in s, ascending, from 0 to the period (one more than frames).
        rms: frame RMS, full scale (a full-scale sine has RMS 1/√2).
        centroid_hz: power-weighted spectral centroid of each frame in Hz.
    """

    edges_s: np.ndarray
    rms: np.ndarray
    centroid_hz: np.ndarray

    @property
    def period_s(self) -> float:
        """The pattern's length in s."""
        return float(self.edges_s[-1])

    @property
    def centres_s(self) -> np.ndarray:
        """Frame centres in s."""
        return (self.edges_s[:-1] + self.edges_s[1:]) / 2

    @property
    def intensity(self) -> np.ndarray:
        """Frame RMS relative to the loudest frame, 0 … 1."""
        return self.rms / float(self.rms.max())

    def segments(self, count: int) -> Envelope:
        """The envelope averaged over ``count`` equal segments of the period.

        RMS is averaged as power; the centroid is weighted by frame power. Used where a
        platform takes few control points. Intensity stays relative to the loudest segment.
        """
        edges = np.linspace(0.0, self.period_s, count + 1)
        which = np.clip(np.searchsorted(edges, self.centres_s, side="right") - 1, 0, count - 1)
        power = self.rms ** 2
        frames = np.maximum(np.bincount(which, None, count), 1)
        centroid = (np.bincount(which, power * self.centroid_hz, count)
                    / np.maximum(np.bincount(which, power, count), 1e-30))
        return Envelope(edges, np.sqrt(np.bincount(which, power, count) / frames), centroid)


def measure(samples: np.ndarray, rate: float, frame_ms: float = FRAME_MS,
            window_ms: float = WINDOW_MS, source: object = "tactile pattern") -> Envelope:
    """Measure the RMS and spectral centroid of a looping pattern, frame by frame.

    Args:
        samples: one period of the pattern, full scale ±1.
        rate: its sampling rate in Hz.
        frame_ms: frame length in ms (frames tile the period; their lengths differ by at most
            one sample when the period is not a whole number of frames).
        window_ms: length in ms of the Hann window, centred on each frame, for the centroid.
        source: what to name in an error.

    Returns:
        An :class:`Envelope`, one value per frame.

    Raises:
        RealPenError: the pattern is silent (nothing to follow) or shorter than a frame.

    Example:
        >>> import numpy as np
        >>> t = np.arange(12000) / 8000
        >>> env = measure(np.sin(2 * np.pi * 200 * t) * (1 + t), 8000)
        >>> float(env.intensity.max()), round(float(np.median(env.centroid_hz)))
        (1.0, 200)
    """
    x = np.asarray(samples, dtype=np.float64)
    n = len(x)
    hop = frame_ms * rate / 1000.0
    if n < hop or hop < 1:
        raise fail(source, f"{n} samples is shorter than one {frame_ms:g} ms frame")
    if not np.any(x):
        raise fail(source, "the tactile pattern is silent; there is no envelope to export")
    count = max(1, int(round(n / hop)))
    edges = np.round(np.linspace(0, n, count + 1)).astype(int)
    squares = np.add.reduceat(x ** 2, edges[:-1])
    rms = np.sqrt(squares / np.diff(edges))
    centres = (edges[:-1] + edges[1:]) / 2.0

    width = max(4, int(round(window_ms * rate / 1000.0)))
    window = np.hanning(width + 2)[1:-1]
    nfft = 1 << int(np.ceil(np.log2(4 * width)))
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate)
    starts = np.round(centres).astype(int) - width // 2
    total, weighted = np.empty(count), np.empty(count)
    # Frames in blocks: memory stays bounded however long the pattern is.
    step = max(1, _BLOCK_VALUES // nfft)
    for first in range(0, count, step):
        index = (starts[first:first + step, None] + np.arange(width)[None, :]) % n
        power = np.abs(np.fft.rfft(x[index] * window, nfft, axis=1)) ** 2
        total[first:first + step] = power.sum(axis=1)
        weighted[first:first + step] = (power * freqs).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        centroid = weighted / total
    silent = ~(total > 0)
    if silent.any():
        # A silent window has no centroid; the pattern's overall one stands in for it.
        centroid[silent] = float(weighted[~silent].sum() / total[~silent].sum())
    return Envelope(edges / rate, rms, centroid)


def sharpness(centroid_hz: np.ndarray, range_hz: tuple[float, float] = SHARPNESS_RANGE_HZ
              ) -> np.ndarray:
    """Map frequencies in Hz to 0 … 1 on a log scale over ``range_hz`` (clipped at the ends).

    Core Haptics sharpness, Lofelt's normalised frequency and Android's basic-envelope
    sharpness are all 0 … 1 with no published mapping to Hz; a log scale spreads the octaves
    of the tactile band evenly.
    """
    low, high = range_hz
    value = np.log(np.asarray(centroid_hz, dtype=np.float64) / low) / np.log(high / low)
    return np.clip(value, 0.0, 1.0)


def sharpness_to_hz(value: np.ndarray, range_hz: tuple[float, float] = SHARPNESS_RANGE_HZ
                    ) -> np.ndarray:
    """The inverse of :func:`sharpness` inside ``range_hz``: 0 … 1 → Hz."""
    low, high = range_hz
    return low * (high / low) ** np.asarray(value, dtype=np.float64)


def loop_curve(envelope: Envelope, values: np.ndarray, repeats: int = 1
               ) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints of one value per frame over ``repeats`` periods, with the loop wrap closed.

    Args:
        envelope: gives the frame centres and the period.
        values: one value per frame (e.g. ``envelope.intensity``).
        repeats: periods laid end to end.

    Returns:
        ``(times_s, values)``: times ascending from 0 to ``repeats × period`` inclusive. Each
        period starts and ends on the value linearly interpolated across the wrap, between the
        last frame centre and the first.
    """
    values = np.asarray(values, dtype=np.float64)
    period = envelope.period_s
    head, tail = envelope.centres_s[0], period - envelope.centres_s[-1]
    wrap = values[-1] + (values[0] - values[-1]) * tail / (head + tail)
    times = [np.array([0.0])]
    points = [np.array([wrap])]
    for index in range(repeats):
        times += [index * period + envelope.centres_s, np.array([(index + 1) * period])]
        points += [values, np.array([wrap])]
    return np.concatenate(times), np.concatenate(points)
