"""What a stroke sounds like: a pen trajectory through Eq. 1 onto the friction sound.

The rendering follows the live app so that it can be heard (and tested) offline. Each
trajectory row is a pen event. Its target gain is Eq. 1 of its pressure and speed, and its
target playback rate comes from its speed. Both are held until the next event and smoothed per
audio sample by the coupling's one-pole filter (see :mod:`realpen.coupling`). The speed of an
event is causal: the distance from the previous event over the time between them, and 0 when
either event has the pen lifted (pressure 0), because a touch-down has not slid yet. After the
last event the target gain is 0, and the render runs on for five time constants so the gain can
settle.

The sound is either a loop unit read cyclically at the playback rate (``mode="loop"``) or grains
from the recording's steady part (``mode="granular"``). Either is scaled so the steady sound has
an RMS of ``level_dbfs`` (gain 1 plays at that level).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .coupling import Coupling
from .csvtable import read_columns
from .errors import RealPenError, fail
from .granular import GRAIN_MS, SteadyPart, granular, grain_samples, steady_part
from .sound import (CROSSFADE_MS, REFERENCE_DBFS, UNIT_MS, LoopUnit, ProgressCallback,
                    find_loop_unit, normalise, require_sound, samples_for)

MODES = ("loop", "granular")
MAX_DURATION_S = 600.0  # longer usually means t was given in ms


@dataclass(frozen=True)
class Trajectory:
    """A pen trajectory: one row per pen event.

    Attributes:
        t: time in s, strictly increasing.
        x, y: position in mm.
        pressure: normalised pressure 0–1; 0 means the pen is lifted.
        source: where it came from.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    pressure: np.ndarray
    source: str = "trajectory"

    @classmethod
    def checked(cls, t, x, y, pressure, source: object = "trajectory") -> "Trajectory":
        """Build a trajectory, raising :class:`RealPenError` naming ``source`` on bad data."""
        t, x, y, pressure = (np.asarray(a, dtype=np.float64).ravel() for a in (t, x, y, pressure))
        if not len(t) == len(x) == len(y) == len(pressure):
            raise fail(source, "t, x, y and pressure differ in length")
        if len(t) < 2:
            raise fail(source, f"a trajectory needs at least 2 rows, has {len(t)}")
        for name, values in (("t", t), ("x", x), ("y", y), ("pressure", pressure)):
            if not np.all(np.isfinite(values)):
                raise fail(source, f"{name} holds NaN or infinite values")
        steps = np.flatnonzero(np.diff(t) <= 0)
        if len(steps):
            raise fail(source, f"t must increase strictly; data row {steps[0] + 2} has t = "
                               f"{t[steps[0] + 1]:g} after {t[steps[0]]:g}")
        outside = np.flatnonzero((pressure < 0) | (pressure > 1))
        if len(outside):
            raise fail(source, f"data row {outside[0] + 1}: pressure "
                               f"{pressure[outside[0]]:g} must be between 0 and 1")
        if t[-1] - t[0] > MAX_DURATION_S:
            raise fail(source, f"lasts {t[-1] - t[0]:g} s, more than {MAX_DURATION_S:g} s "
                               f"(t must be in seconds)")
        return cls(t, x, y, pressure, str(source))

    @property
    def duration_s(self) -> float:
        """Time from the first to the last event, in s."""
        return float(self.t[-1] - self.t[0])

    def speed(self) -> np.ndarray:
        """Causal pen speed at each event in mm/s (0 at the first event and at touch-downs)."""
        distance = np.hypot(np.diff(self.x), np.diff(self.y))
        sliding = (self.pressure[1:] > 0) & (self.pressure[:-1] > 0)
        return np.concatenate([[0.0], np.where(sliding, distance / np.diff(self.t), 0.0)])


def load_trajectory(path: str | os.PathLike) -> Trajectory:
    """Load a trajectory CSV with the header ``t,x,y,pressure`` (s, mm, mm, 0–1).

    Raises:
        RealPenError: any problem with the file (see :meth:`Trajectory.checked`).
    """
    columns = read_columns(path, ("t", "x", "y", "pressure"), min_rows=2)
    return Trajectory.checked(columns["t"], columns["x"], columns["y"], columns["pressure"], path)


def control_signals(trajectory: Trajectory, coupling: Coupling,
                    rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-sample gain and playback rate of a stroke, as the live app computes them.

    Returns:
        (target gain before smoothing, smoothed gain, smoothed playback rate), each of shape
        (frames,), covering the stroke plus five smoothing time constants.
    """
    times = trajectory.t - trajectory.t[0]
    tail = int(np.ceil(5 * coupling.smoothing_ms / 1000 * rate))
    frames = int(np.floor(times[-1] * rate)) + 1 + max(tail, 1)
    clock = np.arange(frames) / rate
    event = np.searchsorted(times, clock, side="right") - 1
    ended = clock > times[-1]
    speed = trajectory.speed()
    target = np.where(ended, 0.0, coupling.gain_raw(trajectory.pressure, speed)[event])
    rates = coupling.playback_rate(speed)[event]
    return (target, coupling.smooth(target, rate),
            coupling.smooth(rates, rate, initial=float(rates[0])))


@dataclass(frozen=True)
class Rendered:
    """A rendered stroke.

    Attributes:
        samples: the sound, shape (frames,), full scale ±1 (float; may exceed 1 at high gain).
        rate: rate in Hz.
        mode: ``"loop"`` or ``"granular"``.
        target_gain, gain, playback_rate: the control signals (per sample).
        unit: the loop unit found in the recording, if one was searched for.
        part: the steady part the grains came from (granular mode).
    """

    samples: np.ndarray
    rate: float
    mode: str
    target_gain: np.ndarray
    gain: np.ndarray
    playback_rate: np.ndarray
    unit: LoopUnit | None = None
    part: SteadyPart | None = None


def render_stroke(sound: np.ndarray, rate: float, trajectory: Trajectory,
                  coupling: Coupling | None = None, mode: str = "loop", *,
                  find_unit: bool | None = None, unit_ms: float = UNIT_MS,
                  crossfade_ms: float = CROSSFADE_MS, grain_ms: float = GRAIN_MS,
                  seed: int = 0, level_dbfs: float = REFERENCE_DBFS,
                  source: object = "sound", progress: ProgressCallback | None = None) -> Rendered:
    """Render the friction sound of a stroke.

    Args:
        sound: a loop unit or a recording, mono, at ``rate`` Hz.
        rate: its rate in Hz (also the output rate).
        trajectory: the stroke.
        coupling: Eq. 1 parameters (default :class:`Coupling`).
        mode: ``"loop"`` or ``"granular"``.
        find_unit: loop mode: search the loop unit first (True) or play ``sound`` as a ready
            loop (False); None decides by length (longer than two units: a recording).
        unit_ms, crossfade_ms: loop-unit search parameters.
        grain_ms, seed: granular parameters.
        level_dbfs: RMS in dB re full scale that gain 1 plays the steady sound at.
        source: names the sound in error messages.
        progress: passed to the loop-unit search.

    Raises:
        RealPenError: a bad mode, silence, or a sound too short for the unit or the grains.
    """
    coupling = coupling or Coupling()
    if mode not in MODES:
        raise RealPenError(f"--mode: unknown mode '{mode}' (choose from {', '.join(MODES)})")
    sound = np.asarray(sound, dtype=np.float64)
    require_sound(sound, source)
    target, gain, playback = control_signals(trajectory, coupling, rate)
    unit = part = None
    if mode == "loop":
        if find_unit is None:
            find_unit = np.isfinite(unit_ms) and len(sound) > 2 * samples_for(unit_ms, rate)
        if find_unit:
            unit = find_loop_unit(sound, rate, unit_ms, crossfade_ms, source=source,
                                  progress=progress)
        loop, _ = normalise(unit.samples if unit else sound, level_dbfs)
        carrier = _read_cyclic(loop, playback)
    else:
        if not np.isfinite(grain_ms) or grain_ms <= 0:
            raise RealPenError(f"--grain-ms must be positive, got {grain_ms:g}")
        grain = grain_samples(grain_ms, rate)
        span_ms = (np.ceil(grain * coupling.rate_max) + 2) * 1000 / rate
        part = steady_part(sound, rate, span_ms, source=source)
        carrier = granular(sound, rate, len(gain), part, grain_ms, seed, playback_rate=playback)
        carrier *= 10 ** (level_dbfs / 20) / part.rms
    return Rendered(samples=gain * carrier, rate=float(rate), mode=mode, target_gain=target,
                    gain=gain, playback_rate=playback, unit=unit, part=part)


def _read_cyclic(loop: np.ndarray, playback: np.ndarray) -> np.ndarray:
    """Read ``loop`` cyclically, advancing ``playback[n]`` samples per output sample."""
    position = np.mod(np.cumsum(playback) - playback[0], len(loop))
    whole = np.floor(position).astype(np.int64) % len(loop)
    frac = position - np.floor(position)
    return loop[whole] * (1 - frac) + loop[(whole + 1) % len(loop)] * frac
