"""The control signals of a stroke: Eq. 1's gain and the playback rate, per output sample.

Each trajectory row is a pen event. Its target gain is Eq. 1 of its pressure and speed
(:class:`~realpen.motion.coupling.Coupling`), and its target playback rate comes from its
speed. Both are held until the next event and smoothed per output sample by the coupling's
one-pole filter. After the last event the target gain is 0, and the render runs on for five
time constants so the gain can settle. The sound's render (:mod:`realpen.sound.stroke`) plays
its carrier through these; the tactile render (:mod:`realpen.tactile.stroke`) gates its loop
with the same gain, as the live page does.
"""

from __future__ import annotations

import numpy as np

from realpen.motion.coupling import Coupling
from realpen.motion.trajectory import Trajectory

__all__ = ["render_frames", "control_signals"]


def render_frames(trajectory: Trajectory, coupling: Coupling, rate: float) -> int:
    """Samples of a stroke's render at ``rate`` Hz: the stroke plus five smoothing time
    constants (at least one sample)."""
    tail = int(np.ceil(5 * coupling.smoothing_ms / 1000 * rate))
    return int(np.floor(trajectory.duration_s * rate)) + 1 + max(tail, 1)


def control_signals(trajectory: Trajectory, coupling: Coupling,
                    rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-sample gain and playback rate of a stroke, as the live app computes them.

    Args:
        trajectory: the stroke (t in s, x and y in mm, pressure 0–1).
        coupling: Eq. 1 constants, smoother and playback-rate law.
        rate: audio sample rate in Hz: one control value per audio sample.

    Returns:
        (target gain before smoothing, smoothed gain, smoothed playback rate), each of shape
        (frames,) at ``rate`` Hz, covering the stroke plus five smoothing time constants. Gains
        are linear (1 plays the steady sound at its reference level); the playback rate is in
        source samples per output sample (1 = as recorded).
    """
    times = trajectory.t - trajectory.t[0]
    frames = render_frames(trajectory, coupling, rate)
    clock = np.arange(frames) / rate
    event = np.searchsorted(times, clock, side="right") - 1
    ended = clock > times[-1]
    speed = trajectory.speed()
    target = np.where(ended, 0.0, coupling.gain_raw(trajectory.pressure, speed)[event])
    rates = coupling.playback_rate(speed)[event]
    return (target, coupling.smooth(target, rate),
            coupling.smooth(rates, rate, initial=float(rates[0])))
