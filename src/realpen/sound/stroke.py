"""What a stroke sounds like: a pen trajectory through Eq. 1 onto the friction sound.

The rendering follows the live app so that it can be heard (and tested) offline. The
trajectory (:class:`~realpen.motion.trajectory.Trajectory`, with the live page's speed meter)
gives, through the coupling (:class:`~realpen.motion.coupling.Coupling`, Eq. 1), a gain and a
playback rate per audio sample (:func:`~realpen.motion.control.control_signals`: held between
events, smoothed by the coupling's one-pole, running on for five time constants after the last
event). Those live in :mod:`realpen.motion` because the tactile render follows the same
stroke; they are re-exported here under their old names.

The sound is either a loop read cyclically at the playback rate (``mode="loop"``) or grains
from the recording's steady part (``mode="granular"``). Either is scaled so the steady sound has
an RMS of ``level_dbfs`` (gain 1 plays at that level). In loop mode a recording is searched for
its loop unit (it must last at least the unit plus the crossfade); a
:class:`~realpen.sound.loop.SoundLoop` (e.g. a WAV whose ``smpl`` chunk declares its loop, read
by :func:`~realpen.sound.loop.load_sound`) is played as it is, and so is any sound declared a
ready loop with ``find_unit=False``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realpen.checks import (
    MAX_DURATION_S,
    MAX_RENDER_FRAMES,
    check_level,
    check_ms,
    check_seed,
    check_sound_rate,
)
from realpen.errors import ParameterError
from realpen.io.recording import Recording
from realpen.motion.control import control_signals, render_frames
from realpen.motion.coupling import Coupling
from realpen.motion.trajectory import SPEED_WINDOW_MS, TILT_FIELDS, Trajectory, load_trajectory
from realpen.sound.granular import GRAIN_MS, grain_samples, granular, steady_part
from realpen.sound.loop import (
    CROSSFADE_MS,
    MODES,
    REFERENCE_DBFS,
    UNIT_MS,
    ProgressCallback,
    SoundLoop,
    find_loop_unit,
    normalise,
)
from realpen.sound.unit import SteadyPart, loop_rate, mono_signal, require_sound, samples_for

__all__ = ["Rendered", "render_stroke", "MODES",
           # the trajectory and its control signals (realpen.motion), under their old names
           "Trajectory", "load_trajectory", "control_signals", "render_frames",
           "MAX_DURATION_S", "MAX_RENDER_FRAMES", "SPEED_WINDOW_MS", "TILT_FIELDS"]


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
        check_sound_rate(rate)
    for name, value in (("unit_ms", unit_ms), ("crossfade_ms", crossfade_ms),
                        ("grain_ms", grain_ms)):
        check_ms(name, value)
    check_level(level_dbfs)
    check_seed(seed)
    ready = None
    if isinstance(sound, SoundLoop):
        rate = loop_rate(sound, rate)
        source = source if source is not None else sound.source or "sound loop"
        ready = sound
        sound = sound.samples
    else:
        sound, rate, _, source = mono_signal(sound, rate, source)
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
