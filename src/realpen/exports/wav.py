"""WAV for actuators driven from an audio output.

- mono: the tactile pattern, at its own rate or resampled (``rate``);
- stereo: the friction sound on the left, the tactile pattern on the right, both at the sound's
  rate (or ``rate``); the tactile pattern is resampled with a polyphase filter.

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
from realpen.io.files import wav_bytes
from realpen.profile.bundle import PenProfile
from realpen.exports.base import Export, check_repeats, resample_loop

SUFFIX = ".wav"
MAX_COMMON_S = 60.0
LIMITS = (
    "no loop flag: the file is whole periods, loop the whole file",
    "the sound's coupling to pressure and speed (Eq. 1) is not applied: constant level",
)


def mono_samples(profile: PenProfile, rate: int | None = None, repeats: int = 1
                 ) -> tuple[np.ndarray, int]:
    """The tactile pattern, ``repeats`` periods, at ``rate`` Hz (default: its own rate).

    Returns:
        ``(samples, rate)``: float32, shape (frames,), full scale ±1.
    """
    own = profile.meta.tactile.rate
    rate = own if rate is None else rate
    period = resample_loop(profile.tactile, own, rate, "tactile pattern")
    return np.tile(period, check_repeats(repeats)).astype(np.float32), int(rate)


def stereo_samples(profile: PenProfile, rate: int | None = None, repeats: int = 1
           ) -> tuple[np.ndarray, int]:
    """Sound left, tactile pattern right, over a length both loops fit, ``repeats`` times.

    Args:
        rate: output rate in Hz (default: the sound's rate, 48 kHz for bundled pens).

    Returns:
        ``(samples, rate)``: float32, shape (frames, 2), full scale ±1.

    Raises:
        RealPenError: the two loops have no common length under :data:`MAX_COMMON_S`.
    """
    repeats = check_repeats(repeats)
    rate = profile.meta.sound.rate if rate is None else rate
    tactile = resample_loop(profile.tactile, profile.meta.tactile.rate, rate, "tactile pattern")
    sound = resample_loop(profile.sound, profile.meta.sound.rate, rate, "sound loop")
    common = math.lcm(len(tactile), len(sound))
    if common / rate > MAX_COMMON_S:
        raise RealPenError(
            f"{profile.name}: the sound loop ({len(sound) / rate * 1000:g} ms) and the tactile "
            f"loop ({len(tactile) / rate * 1000:g} ms) have no common length under "
            f"{MAX_COMMON_S:g} s, so a stereo file could not loop seamlessly")
    both = np.column_stack([np.tile(sound, common // len(sound)),
                            np.tile(tactile, common // len(tactile))])
    return np.tile(both, (repeats, 1)).astype(np.float32), int(rate)


def export(profile: PenProfile, stereo: bool = False, rate: int | None = None,
           repeats: int = 1) -> Export:
    """Render the WAV (32-bit float) of a profile; see the module docstring."""
    render = stereo_samples if stereo else mono_samples
    samples, out_rate = render(profile, rate, repeats)
    seconds = len(samples) / out_rate
    layout = "sound left, tactile right" if stereo else "tactile pattern, mono"
    limits = LIMITS if stereo else LIMITS[:1]
    return Export(wav_bytes(samples, out_rate),
                  f"{layout}, {seconds * 1000:.0f} ms at {out_rate} Hz, loops seamlessly",
                  limits=limits)

