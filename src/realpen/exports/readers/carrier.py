"""How the envelope formats (``.ahap``, ``.haptic``, the Android JSON) become a vibration.

These formats carry an intensity and a sharpness (or a frequency) over time, not a waveform;
the player's actuator makes the waveform. RealPen's model of that actuator, shared by their
readers:

- **Carrier.** A phase-continuous sine whose amplitude is the intensity (linear, 0 … 1 is
  silence … full scale) and whose frequency follows the sharpness mapped to Hz by
  :func:`realpen.exports.envelope.sharpness_to_hz` (log 30–500 Hz, the inverse of the mapping
  the exports write); the phase is the running sum of ``2π·f/rate``. Values between
  breakpoints are linear (:func:`linear`).
- **Transient.** A burst of :data:`TRANSIENT_S` at the sharpness frequency whose amplitude
  decays exponentially with time constant :data:`TRANSIENT_DECAY_S` from the transient's
  intensity (:func:`burst`); Core Haptics and Lofelt publish no transient waveform.
- **Pattern.** :class:`Pattern` holds Core Haptics events and dynamic-parameter timelines with
  Apple's semantics (intensity control multiplies, sharpness control adds, results clipped to
  0 … 1) and renders them; the ``.haptic`` reader fills one the way Lofelt's converter does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from realpen.exports.envelope import sharpness_to_hz

__all__ = ["TRANSIENT_S", "TRANSIENT_DECAY_S", "CARRIER_NOTE", "TRANSIENT_NOTE", "sample_times",
           "linear", "carrier", "burst", "Control", "Pattern"]

TRANSIENT_S = 0.020  # s: about the length of a phone actuator's click
TRANSIENT_DECAY_S = 0.005  # s: the burst falls to 2 % by its end
CARRIER_NOTE = ("rendered as a phase-continuous sine whose amplitude is the intensity (linear "
                "0–1) and whose frequency is the sharpness mapped log-wise to 30–500 Hz")
TRANSIENT_NOTE = (f"each transient rendered as a {TRANSIENT_S * 1000:g} ms sine burst at its "
                  f"sharpness frequency, decaying with a {TRANSIENT_DECAY_S * 1000:g} ms time "
                  f"constant from its intensity")


def sample_times(duration_s: float, rate: int) -> np.ndarray:
    """The sample instants (s) of ``duration_s`` at ``rate`` Hz: ``round(duration·rate)`` of them."""
    return np.arange(int(round(duration_s * rate))) / rate


def linear(times: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Breakpoints ``(times, values)`` joined linearly, read at ``at``; held beyond the ends.

    Breakpoints sharing a time make a step there.
    """
    return np.interp(at, times, values) if len(times) else np.zeros(len(at))


def carrier(intensity: np.ndarray, hz: np.ndarray, rate: int) -> np.ndarray:
    """A sine of amplitude ``intensity`` and instantaneous frequency ``hz``, sample by sample.

    Args:
        intensity: amplitude per sample, 0 … 1.
        hz: frequency per sample in Hz.
        rate: samples per second.

    Returns:
        float64 samples; the phase starts at 0 and never jumps.
    """
    steps = 2 * np.pi * np.asarray(hz, dtype=np.float64) / rate
    phase = np.concatenate([[0.0], np.cumsum(steps[:-1])]) if len(steps) else steps
    return np.asarray(intensity, dtype=np.float64) * np.sin(phase)


def burst(intensity: float, sharpness: float, rate: int) -> np.ndarray:
    """One transient: :data:`TRANSIENT_S` of sine at the sharpness frequency, decaying.

    Args:
        intensity: 0 … 1, the burst's initial amplitude.
        sharpness: 0 … 1, mapped to Hz by :func:`~realpen.exports.envelope.sharpness_to_hz`.
        rate: samples per second.
    """
    t = np.arange(max(1, int(round(TRANSIENT_S * rate)))) / rate
    hz = float(sharpness_to_hz(sharpness))
    return intensity * np.exp(-t / TRANSIENT_DECAY_S) * np.sin(2 * np.pi * hz * t)


@dataclass
class Control:
    """A dynamic parameter over time: segments that each take over from their start time.

    A segment is a parameter curve (breakpoints joined linearly, held after its last point
    until the next segment) or a single dynamic parameter (one point: a step).

    Attributes:
        neutral: the value before the first segment (1 for intensity, 0 for sharpness).
        low, high: the parameter's range; values are clipped to it.
        segments: ``(start_s, times_s, values)``, ``times_s`` absolute and ascending.
    """

    neutral: float
    low: float
    high: float
    segments: list[tuple[float, np.ndarray, np.ndarray]] = field(default_factory=list)

    def add(self, start_s: float, times_s, values) -> None:
        """Add a segment starting at ``start_s`` with absolute breakpoint times."""
        self.segments.append((float(start_s), np.asarray(times_s, dtype=np.float64),
                              np.clip(np.asarray(values, dtype=np.float64), self.low, self.high)))

    def at(self, t: np.ndarray) -> np.ndarray:
        """The parameter's value at ascending instants ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        out = np.full(len(t), self.neutral)
        ordered = sorted(self.segments, key=lambda segment: segment[0])  # stable: file order
        starts = np.searchsorted(t, [segment[0] for segment in ordered], side="left")
        ends = np.append(starts[1:], len(t))
        for (_, times, values), first, last in zip(ordered, starts, ends):
            if last > first:
                out[first:last] = linear(times, values, t[first:last])
        return out


@dataclass
class Pattern:
    """Core Haptics haptic events with their intensity and sharpness controls.

    Attributes:
        continuous: ``(time_s, duration_s, intensity, sharpness)`` of each continuous event.
        transients: ``(time_s, intensity, sharpness)`` of each transient event.
        intensity: the ``HapticIntensityControl`` timeline (multiplies event intensities).
        sharpness: the ``HapticSharpnessControl`` timeline (adds to event sharpnesses).

    The controls apply to transients too, at their start (Apple: parameter curves "apply to
    all events in a pattern").
    """

    continuous: list[tuple[float, float, float, float]] = field(default_factory=list)
    transients: list[tuple[float, float, float]] = field(default_factory=list)
    intensity: Control = field(default_factory=lambda: Control(1.0, 0.0, 1.0))
    sharpness: Control = field(default_factory=lambda: Control(0.0, -1.0, 1.0))

    @property
    def duration_s(self) -> float:
        """The end of the last event (a transient ends after :data:`TRANSIENT_S`), in s."""
        ends = [time + length for time, length, _, _ in self.continuous]
        ends += [time + TRANSIENT_S for time, _, _ in self.transients]
        return max(ends, default=0.0)

    def render(self, rate: int) -> np.ndarray:
        """The vibration at ``rate`` Hz over :attr:`duration_s`, clipped to ±1.

        Continuous events that overlap add their intensities (their sharpness is the
        intensity-weighted mean) and drive one carrier, so the phase never jumps between
        consecutive events; transients add their bursts.
        """
        t = sample_times(self.duration_s, rate)
        # Each event adds its level from its first sample to its last: steps summed once, so
        # the work grows with the events plus the samples, however the events overlap.
        level_steps, weighted_steps = np.zeros(len(t) + 1), np.zeros(len(t) + 1)
        if self.continuous:
            events = np.array(self.continuous, dtype=np.float64)
            first = np.searchsorted(t, events[:, 0], side="left")
            last = np.searchsorted(t, events[:, 0] + events[:, 1], side="left")
            for steps, amount in ((level_steps, events[:, 2]),
                                  (weighted_steps, events[:, 2] * events[:, 3])):
                np.add.at(steps, first, amount)
                np.add.at(steps, last, -amount)
        level = np.cumsum(level_steps)[:len(t)]
        weighted = np.cumsum(weighted_steps)[:len(t)]
        level[np.abs(level) < 1e-12] = 0.0  # what the running sum leaves of events that ended
        sharp = np.divide(weighted, level, out=np.zeros(len(t)), where=level > 0)
        gain, shift = self.intensity.at(t), self.sharpness.at(t)
        out = carrier(np.clip(level * gain, 0.0, 1.0),
                      sharpness_to_hz(np.clip(sharp + shift, 0.0, 1.0)), rate)
        if self.transients:
            times = np.array([time for time, _, _ in self.transients])
            order = np.argsort(times, kind="stable")
            gains, shifts = np.empty(len(times)), np.empty(len(times))
            gains[order] = self.intensity.at(times[order])
            shifts[order] = self.sharpness.at(times[order])
            for (time, intensity, sharpness), gain, shift in zip(self.transients, gains, shifts):
                wave = burst(float(np.clip(intensity * gain, 0.0, 1.0)),
                             float(np.clip(sharpness + shift, 0.0, 1.0)), rate)
                first = int(round(time * rate))
                part = wave[:max(0, len(out) - first)]
                out[first:first + len(part)] += part
        return np.clip(out, -1.0, 1.0)
