"""WAV for actuators driven from an audio output.

- mono: the tactile pattern, at its own rate or resampled (``rate``);
- stereo: the friction sound on the left, the tactile pattern on the right, both at the sound's
  rate (or ``rate``); the tactile pattern is resampled with a polyphase filter. Needs the sound.

Both loops must fit a common length for the stereo file to loop seamlessly. The method's
lengths do: 1500 ms is exactly 5 × 300 ms, so one tactile period holds five sound units and the
file is 1500 ms long. In general the file is the least common multiple of the two loops (in
samples at the output rate); where that exceeds :data:`MAX_COMMON_S` the export is refused
rather than cut with a seam.

What it cannot carry: a WAV has no portable loop flag (the file is exactly ``repeats`` periods,
so a player looping the whole file loops seamlessly); nothing of the coupling of the sound to
pressure and speed (Eq. 1) — the sound is at its reference level throughout; the pattern's
components, only their sum.
"""

from __future__ import annotations

import math

import numpy as np

from realpen.errors import RealPenError
from realpen.exports.base import (
    Export,
    check_frames,
    check_pattern,
    check_span,
    resample_loop,
    sound_samples,
)
from realpen.io.files import wav_bytes
from realpen.tactile.pattern import TactilePattern

__all__ = ["SUFFIX", "MAX_COMMON_S", "LIMITS", "mono_samples", "stereo_samples", "export"]

SUFFIX = ".wav"
MAX_COMMON_S = 60.0
LIMITS = (
    "no loop flag: the file is whole periods, loop the whole file",
    "the sound's coupling to pressure and speed (Eq. 1) is not applied: constant level",
)


def mono_samples(pattern: TactilePattern, rate: int | None = None, repeats: int = 1,
                 name: str = "pattern") -> tuple[np.ndarray, int]:
    """The tactile pattern, ``repeats`` periods, at ``rate`` Hz (default: its own rate);
    ``name`` names the pen in an error.

    Returns:
        ``(samples, rate)``: float32, shape (frames,), full scale ±1.
    """
    pattern = check_pattern(pattern)
    repeats = check_span(pattern, repeats, name)
    own = pattern.rate
    rate = own if rate is None else rate
    period = resample_loop(pattern.samples, own, rate, "tactile pattern")
    check_frames(len(period), repeats, int(rate))
    return np.tile(period, repeats).astype(np.float32), int(rate)


def stereo_samples(pattern: TactilePattern, sound, rate: int | None = None, repeats: int = 1,
                   name: str = "pattern") -> tuple[np.ndarray, int]:
    """Sound left, tactile pattern right, over a length both loops fit, ``repeats`` times.

    Args:
        pattern: the tactile pattern.
        sound: the sound loop (``samples``, ``rate`` in Hz).
        rate: output rate in Hz (default: the sound's rate, 48 kHz for bundled pens).
        repeats: how many times the common length is written.
        name: names the pen in an error.

    Returns:
        ``(samples, rate)``: float32, shape (frames, 2), full scale ±1.

    Raises:
        ParameterError: no sound (parameter ``sound``) or a bad ``rate`` or ``repeats``.
        RealPenError: the two loops have no common length under :data:`MAX_COMMON_S`.
    """
    pattern = check_pattern(pattern)
    repeats = check_span(pattern, repeats, name)
    loop, sound_rate = sound_samples(sound, "a stereo WAV (sound left, tactile right)")
    rate = sound_rate if rate is None else rate
    tactile = resample_loop(pattern.samples, pattern.rate, rate, "tactile pattern")
    loop = resample_loop(loop, sound_rate, rate, "sound loop")
    common = math.lcm(len(tactile), len(loop))
    if common / rate > MAX_COMMON_S:
        raise RealPenError(
            f"{name}: the sound loop ({len(loop) / rate * 1000:g} ms) and the tactile "
            f"loop ({len(tactile) / rate * 1000:g} ms) have no common length under "
            f"{MAX_COMMON_S:g} s, so a stereo file could not loop seamlessly")
    check_frames(common, repeats, int(rate))
    both = np.column_stack([np.tile(loop, common // len(loop)),
                            np.tile(tactile, common // len(tactile))])
    return np.tile(both, (repeats, 1)).astype(np.float32), int(rate)


def export(pattern: TactilePattern, sound=None, coupling=None, *, name: str = "pattern",
           tool: str = "", version: str | None = None, stereo: bool = False,
           rate: int | None = None, repeats: int = 1) -> Export:
    """Render the WAV (32-bit float); see the module docstring.

    Args:
        pattern: the tactile pattern.
        sound: the sound loop; needed with ``stereo``.
        coupling: not carried (the sound plays at its reference level).
        name, tool, version: not written (a WAV has no metadata here).
        stereo: sound left, tactile right.
        rate: output rate in Hz (default: the pattern's, or with ``stereo`` the sound's).
        repeats: periods written.
    """
    if stereo:
        samples, out_rate = stereo_samples(pattern, sound, rate, repeats, name)
    else:
        samples, out_rate = mono_samples(pattern, rate, repeats, name)
    seconds = len(samples) / out_rate
    layout = "sound left, tactile right" if stereo else "tactile pattern, mono"
    limits = LIMITS if stereo else LIMITS[:1]
    return Export(wav_bytes(samples, out_rate),
                  f"{layout}, {seconds * 1000:.0f} ms at {out_rate} Hz, loops seamlessly",
                  limits=limits)
