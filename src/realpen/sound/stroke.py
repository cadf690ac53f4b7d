"""What a stroke sounds like: a pen trajectory through Eq. 1 onto the friction sound.

The rendering follows the live app so that it can be heard (and tested) offline. Each
trajectory row is a pen event. Its target gain is Eq. 1 of its pressure and speed, and its
target playback rate comes from its speed. Both are held until the next event and smoothed per
audio sample by the coupling's one-pole filter (see :mod:`realpen.coupling`). After the last
event the target gain is 0, and the render runs on for five time constants so the gain can
settle.

Speed is the live page's (``SpeedMeter`` in ``live/static/pen.js``), event by event: the path
length travelled since the newest earlier event at least ``SPEED_WINDOW_MS`` (20 ms) before
this one, divided by the time between the two, in mm/s. While the stroke is younger than
20 ms the window reaches back to its first event, and it always spans at least one step. A row
with pressure 0 is the pen lifted: its speed is 0, and the next row with pressure > 0 is a
touch-down, where the page's meter restarts (speed 0: the pen has not slid yet). A single
step's distance would be mostly rounding on a touch screen, hence the window. (The page restarts
its meter only at pointer-down: if a pen reports pressure 0 in the middle of a stroke, the page
keeps measuring through it while this reading restarts. The gain there is 0 either way; only
the speed of the next 20 ms after it can differ.)

The sound is either a loop read cyclically at the playback rate (``mode="loop"``) or grains
from the recording's steady part (``mode="granular"``). Either is scaled so the steady sound has
an RMS of ``level_dbfs`` (gain 1 plays at that level). In loop mode a recording is searched for
its loop unit (it must last at least the unit plus the crossfade); a
:class:`~realpen.sound.loop.SoundLoop` (e.g. a WAV whose ``smpl`` chunk declares its loop, read
by :func:`~realpen.sound.loop.load_sound`) is played as it is, and so is any sound declared a
ready loop with ``find_unit=False``.

A trajectory's columns and value ranges are those of the one stroke-sample definition,
:class:`realpen.io.strokes.StrokeSample` (``t`` s, ``x`` and ``y`` mm, ``pressure`` 0–1, tilt in
degrees); :class:`Trajectory` is its columnar form, and converts to and from a list of samples.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from realpen.errors import ParameterError, fail
from realpen.io.csvtable import read_csv
from realpen.io.recording import Recording
from realpen.io.strokes import (
    POSITION_RANGE_MM,
    PRESSURE_RANGE,
    TILT_RANGE_DEG,
    TRAJECTORY_FIELDS,
    StrokeSample,
)
from realpen.sound.coupling import Coupling
from realpen.sound.granular import (
    GRAIN_MS,
    SteadyPart,
    check_seed,
    grain_samples,
    granular,
    steady_part,
)
from realpen.sound.loop import (
    CROSSFADE_MS,
    MODES,
    REFERENCE_DBFS,
    UNIT_MS,
    ProgressCallback,
    SoundLoop,
    _mono,
    _own_rate,
    check_level,
    check_ms,
    check_rate,
    find_loop_unit,
    normalise,
    require_sound,
    samples_for,
)

__all__ = ["Trajectory", "Rendered", "load_trajectory", "control_signals", "render_frames",
           "render_stroke", "MODES", "MAX_DURATION_S", "MAX_RENDER_FRAMES", "SPEED_WINDOW_MS",
           "TILT_FIELDS"]

MAX_DURATION_S = 600.0  # longer usually means t was given in ms
MAX_RENDER_FRAMES = 2**25
"""The most samples a rendered stroke may have (33 554 432: 11.6 min at 48 kHz, 87 s at
384 kHz). The render holds about eight arrays of that length (268 MB each as float64), so it
is checked before any of them is made."""
SPEED_WINDOW_MS = 20.0  # the live page's speed window (SPEED_WINDOW_MS in live/static/pen.js)
TILT_FIELDS = ("tilt_x", "tilt_y")  # optional trajectory columns, degrees


@dataclass(frozen=True, repr=False, eq=False)
class Trajectory:
    """A pen trajectory: one row per pen event, the columnar form of
    :class:`~realpen.io.strokes.StrokeSample` rows.

    Attributes:
        t: time in s, strictly increasing.
        x, y: position in mm.
        pressure: normalised pressure 0–1; 0 means the pen is lifted.
        source: where it came from.
        tilt_x, tilt_y: tilt in degrees (−90–90), when known (None: not recorded).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    pressure: np.ndarray
    source: str = "trajectory"
    tilt_x: np.ndarray | None = None
    tilt_y: np.ndarray | None = None

    @classmethod
    def checked(cls, t, x, y, pressure, source: object = "trajectory",
                lines: Sequence[int] | None = None, *, tilt_x=None, tilt_y=None) -> Trajectory:
        """Build a trajectory, raising :class:`RealPenError` naming ``source`` on bad data.

        The value ranges are the stroke sample's (:mod:`realpen.io.strokes`).

        Args:
            t: time in s; x, y: position in mm; pressure: normalised, 0–1.
            source: names the data in error messages.
            lines: the file line of each row (1-based), when the rows come from a file:
                errors then name the line; otherwise they name the row (1-based).
            tilt_x, tilt_y: tilt in degrees (−90–90), optional.
        """
        t, x, y, pressure = (np.asarray(a, dtype=np.float64).ravel() for a in (t, x, y, pressure))
        tilts = {name: None if value is None else np.asarray(value, dtype=np.float64).ravel()
                 for name, value in zip(TILT_FIELDS, (tilt_x, tilt_y))}
        columns = {"t": t, "x": x, "y": y, "pressure": pressure,
                   **{name: value for name, value in tilts.items() if value is not None}}
        if len({len(values) for values in columns.values()}) > 1:
            raise fail(source, f"{', '.join(columns)} differ in length")
        if lines is not None and len(lines) != len(t):
            raise ParameterError("lines", "one line number per row is needed")

        def where(row: int) -> str:
            return f"line {lines[row]}" if lines is not None else f"row {row + 1}"

        if len(t) < 2:
            raise fail(source, f"a trajectory needs at least 2 rows, has {len(t)}")
        for name, values in columns.items():
            bad = np.flatnonzero(~np.isfinite(values))
            if len(bad):
                raise fail(source, f"{where(bad[0])}: {name} is {values[bad[0]]:g} (NaN or "
                                   f"infinite)")
        steps = np.flatnonzero(np.diff(t) <= 0)
        if len(steps):
            row = steps[0] + 1
            raise fail(source, f"{where(row)}: t = {t[row]:g} s comes after {t[row - 1]:g} s "
                               f"({where(row - 1)}); t must increase strictly")
        low, high = PRESSURE_RANGE
        outside = np.flatnonzero((pressure < low) | (pressure > high))
        if len(outside):
            raise fail(source, f"{where(outside[0])}: pressure {pressure[outside[0]]:g} must be "
                               f"between {low:g} and {high:g}")
        ranges = [("x", POSITION_RANGE_MM, "mm"), ("y", POSITION_RANGE_MM, "mm")]
        ranges += [(name, TILT_RANGE_DEG, "degrees") for name in tilts if tilts[name] is not None]
        for name, (low, high), unit in ranges:
            values = columns[name]
            outside = np.flatnonzero((values < low) | (values > high))
            if len(outside):
                raise fail(source, f"{where(outside[0])}: {name} = {values[outside[0]]:g} {unit} "
                                   f"must be between {low:g} and {high:g}")
        if t[-1] - t[0] > MAX_DURATION_S:
            raise fail(source, f"lasts {t[-1] - t[0]:g} s, more than {MAX_DURATION_S:g} s "
                               f"(t must be in seconds)")
        return cls(t, x, y, pressure, str(source), tilts["tilt_x"], tilts["tilt_y"])

    @classmethod
    def from_samples(cls, samples: Iterable[StrokeSample],
                     source: object = "samples") -> Trajectory:
        """The trajectory of stroke samples (their ``t``, ``x``, ``y``, ``pressure`` and tilt;
        speed is measured again by :meth:`speed`).

        Args:
            samples: :class:`~realpen.io.strokes.StrokeSample` rows, ``t`` in s increasing.
            source: names them in error messages.
        """
        rows = np.array([sample.as_row() for sample in samples], dtype=np.float64)
        if rows.size == 0:
            raise fail(source, "a trajectory needs at least 2 rows, has 0")
        t, x, y, pressure, tilt_x, tilt_y, _ = rows.T
        return cls.checked(t, x, y, pressure, source, tilt_x=tilt_x, tilt_y=tilt_y)

    def to_samples(self, window_ms: float = SPEED_WINDOW_MS) -> list[StrokeSample]:
        """The rows as :class:`~realpen.io.strokes.StrokeSample` (speed in mm/s from
        :meth:`speed` over ``window_ms`` ms; tilt 0 degrees where not recorded)."""
        speed = self.speed(window_ms)
        zeros = np.zeros(len(self.t))
        tilt_x = self.tilt_x if self.tilt_x is not None else zeros
        tilt_y = self.tilt_y if self.tilt_y is not None else zeros
        return [StrokeSample(t=float(a), x=float(b), y=float(c), pressure=float(p),
                             tilt_x=float(tx), tilt_y=float(ty), speed=float(v))
                for a, b, c, p, tx, ty, v in zip(self.t, self.x, self.y, self.pressure,
                                                 tilt_x, tilt_y, speed)]

    @property
    def duration_s(self) -> float:
        """Time from the first to the last event, in s."""
        return float(self.t[-1] - self.t[0])

    def __len__(self) -> int:
        return len(self.t)

    def __repr__(self) -> str:
        down = float(np.mean(self.pressure > 0)) * 100 if len(self.t) else 0.0
        name = Path(self.source).name[:40]
        return (f"Trajectory({len(self.t)} events over {self.duration_s:.3g} s, pen down "
                f"{down:.0f} %, source={name!r})")

    def speed(self, window_ms: float = SPEED_WINDOW_MS) -> np.ndarray:
        """Causal pen speed at each event in mm/s, as the live page measures it.

        The path length since the newest earlier event at least ``window_ms`` ms back (the
        stroke's first event while the stroke is younger), over the time between the two. 0 at
        lifted rows (pressure 0) and at touch-downs (the first row, and a row with pressure > 0
        after a lifted one), where the page's meter restarts. See the module doc.

        Args:
            window_ms: the window in ms (default the page's 20 ms).
        """
        window = check_ms("window_ms", window_ms) / 1000.0
        speed = np.zeros(len(self.t))
        down = self.pressure > 0
        edges = np.flatnonzero(np.diff(np.concatenate([[0], down.astype(np.int8), [0]])))
        for first, stop in zip(edges[::2], edges[1::2]):  # each pen-down run is one stroke
            t = self.t[first:stop]
            steps = np.hypot(np.diff(self.x[first:stop]), np.diff(self.y[first:stop]))
            travelled = np.concatenate([[0.0], np.cumsum(steps)])
            # pen.js keeps the newest point whose successor is not older than t − window:
            # the newest earlier point with time ≤ t − window, else the stroke's first point.
            back = np.maximum(np.searchsorted(t, t - window, side="right") - 1, 0)
            span = t - t[back]
            moving = span > 0
            speed[first:stop][moving] = (travelled[moving] - travelled[back[moving]]) \
                / span[moving]
        return speed


def load_trajectory(path: str | os.PathLike) -> Trajectory:
    """Load a trajectory CSV with the header ``t,x,y,pressure`` (s, mm, mm, 0–1).

    Other columns are allowed (e.g. those of ``realpen strokes export``); ``tilt_x`` and
    ``tilt_y`` (degrees), when present, are read too.

    Raises:
        RealPenError: any problem with the file (see :meth:`Trajectory.checked`).
    """
    table = read_csv(path, TRAJECTORY_FIELDS, min_rows=2, optional=TILT_FIELDS)
    columns = table.columns
    return Trajectory.checked(columns["t"], columns["x"], columns["y"], columns["pressure"], path,
                              lines=table.lines, tilt_x=columns.get("tilt_x"),
                              tilt_y=columns.get("tilt_y"))


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


@dataclass(frozen=True, repr=False, eq=False)
class Rendered:
    """A rendered stroke.

    Attributes:
        samples: the sound, shape (frames,), full scale ±1 (float; may exceed 1 at high gain).
        rate: rate in Hz.
        mode: ``"loop"`` or ``"granular"``.
        target_gain, gain, playback_rate: the control signals (per sample; gains linear,
            playback rate in source samples per output sample).
        unit: the loop unit found in the recording, if one was searched for.
        part: the steady part the grains came from (granular mode).
        loop: the loop that was played (loop mode): the unit found, or the ready loop.
    """

    samples: np.ndarray
    rate: float
    mode: str
    target_gain: np.ndarray
    gain: np.ndarray
    playback_rate: np.ndarray
    unit: SoundLoop | None = None
    part: SteadyPart | None = None
    loop: SoundLoop | None = None

    def __repr__(self) -> str:
        return (f"Rendered({len(self.samples) / self.rate:.3g} s at {self.rate:g} Hz, "
                f"mode={self.mode!r}, peak gain {float(np.max(self.gain, initial=0)):.3g})")


def render_stroke(sound: np.ndarray | Recording | SoundLoop, rate: float | None,
                  trajectory: Trajectory, coupling: Coupling | None = None, mode: str = "loop",
                  *, find_unit: bool = True, unit_ms: float = UNIT_MS,
                  crossfade_ms: float = CROSSFADE_MS, grain_ms: float = GRAIN_MS,
                  seed: int = 0, level_dbfs: float = REFERENCE_DBFS,
                  source: object | None = None,
                  progress: ProgressCallback | None = None) -> Rendered:
    """Render the friction sound of a stroke.

    Args:
        sound: a recording (an array, mono or (frames, channels), full scale ±1, at ``rate``
            Hz, or a :class:`~realpen.io.recording.Recording`), or a
            :class:`~realpen.sound.loop.SoundLoop`, which loop mode plays as it is.
        rate: the array's rate in Hz (also the output rate), 8 kHz to 384 kHz; for a
            recording or a sound loop None (their own rate) or that same rate.
        trajectory: the stroke.
        coupling: Eq. 1 parameters (default :class:`Coupling`).
        mode: ``"loop"`` or ``"granular"``.
        find_unit: loop mode with a recording: search it for its loop unit (default; the
            recording must last at least ``unit_ms + crossfade_ms``), or False to play it as
            it is as a ready loop. A :class:`~realpen.sound.loop.SoundLoop` is always played
            as it is.
        unit_ms, crossfade_ms: loop-unit length and wrap crossfade in ms (finite, positive).
        grain_ms: granular grain length in ms (finite, positive); seed: seed of its offsets.
        level_dbfs: RMS in dB re full scale (dBFS) that gain 1 plays the steady sound at
            (finite, at most 0 dBFS).
        source: names the sound in error messages (default: its file, or ``"sound"``).
        progress: passed to the loop-unit search.

    Raises:
        ParameterError: a bad mode, rate, length, level or seed; ``find_unit`` for a recording
            shorter than the unit plus the crossfade (the message names the sound); a render
            longer than :data:`MAX_RENDER_FRAMES` samples (parameter ``rate``).
        RealPenError: silence, or a sound too short for the grains.
    """
    coupling = coupling or Coupling()
    if mode not in MODES:
        raise ParameterError("mode", f"unknown value {mode!r} (choose from {', '.join(MODES)})")
    if rate is not None:
        check_rate(rate)
    for name, value in (("unit_ms", unit_ms), ("crossfade_ms", crossfade_ms),
                        ("grain_ms", grain_ms)):
        check_ms(name, value)
    check_level(level_dbfs)
    check_seed(seed)
    ready = None
    if isinstance(sound, SoundLoop):
        rate = _own_rate(sound, rate)
        source = source if source is not None else sound.source or "sound loop"
        ready = sound
        sound = sound.samples
    else:
        sound, rate, _, source = _mono(sound, rate, source)
        if source == "signal":
            source = "sound"
    frames = render_frames(trajectory, coupling, rate)
    if frames > MAX_RENDER_FRAMES:
        raise ParameterError("rate", f"a {trajectory.duration_s:g} s stroke at {rate:g} Hz is "
                                     f"{frames:,} samples; a render holds at most "
                                     f"{MAX_RENDER_FRAMES:,} (a lower rate or a shorter stroke)")
    require_sound(sound, source)
    needed = samples_for(unit_ms, rate) + samples_for(crossfade_ms, rate)
    search = mode == "loop" and ready is None and find_unit
    if search and len(sound) < needed:
        # find_unit=True asks for a search this sound cannot hold: the argument is what to change
        raise ParameterError("find_unit", f"{source} lasts {len(sound) / rate * 1000:.0f} ms, "
                                          f"shorter than the {unit_ms:g} ms unit plus the "
                                          f"{crossfade_ms:g} ms crossfade it is searched for; "
                                          f"play it as it is, as a ready loop")
    target, gain, playback = control_signals(trajectory, coupling, rate)
    unit = part = played = None
    if mode == "loop":
        if search:
            unit = find_loop_unit(sound, rate, unit_ms, crossfade_ms, source=source,
                                  progress=progress)
        played = unit or ready or SoundLoop(samples=sound, rate=rate, source=str(source))
        loop, _ = normalise(played.samples, level_dbfs)
        carrier = _read_cyclic(loop, playback)
    else:
        grain = grain_samples(grain_ms, rate)
        span_ms = (np.ceil(grain * coupling.rate_max) + 2) * 1000 / rate
        part = steady_part(sound, rate, span_ms, source=source)
        carrier = granular(sound, rate, len(gain), part, grain_ms, seed, playback_rate=playback)
        carrier *= 10 ** (level_dbfs / 20) / part.rms
    return Rendered(samples=gain * carrier, rate=float(rate), mode=mode, target_gain=target,
                    gain=gain, playback_rate=playback, unit=unit, part=part, loop=played)


def _read_cyclic(loop: np.ndarray, playback: np.ndarray) -> np.ndarray:
    """Read ``loop`` cyclically, advancing ``playback[n]`` samples per output sample."""
    position = np.mod(np.cumsum(playback) - playback[0], len(loop))
    whole = np.floor(position).astype(np.int64) % len(loop)
    frac = position - np.floor(position)
    return loop[whole] * (1 - frac) + loop[(whole + 1) % len(loop)] * frac
