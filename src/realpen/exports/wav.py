"""WAV for actuators driven from an audio output, and for the players that loop it.

- mono: the tactile pattern, at its own rate or resampled (``rate``);
- stereo: the friction sound on the left, the tactile pattern on the right, both at the sound's
  rate (or ``rate``); the tactile pattern is resampled with a polyphase filter. Needs the sound.

Both loops must fit a common length for the stereo file to loop seamlessly. The method's
lengths do: 1500 ms is exactly 5 × 300 ms, so one tactile period holds five sound units and the
file is 1500 ms long. In general the file is the least common multiple of the two loops (in
samples at the output rate); where that exceeds :data:`MAX_COMMON_S` the export is refused
rather than cut with a seam.

The loop. Every file carries a RIFF ``smpl`` chunk declaring the whole file one forward loop
(frames 0 … last, played forever; see :func:`realpen.io.files.add_smpl_loop`), where samplers,
game engines and libsndfile (``SFC_GET_INSTRUMENT``) look for loop points. The file is exactly
``repeats`` periods, so a player that ignores the chunk and loops the whole file loops
seamlessly too.

Sample format (``subtype``):

- ``pcm16`` (the default): 16-bit integer PCM, the one WAV every player reads — Android's
  ``SoundPool`` and ``MediaPlayer``, game engines' importers, the audio path that drives an
  actuator. Its 96 dB of range is far more than a vibrotactile actuator renders (a few tens
  of dB above threshold), so the rounding (half a step, 1.5·10⁻⁵ of full scale) is never
  felt;
- ``pcm24``: 24-bit integer PCM, for audio tools that keep more;
- ``float``: 32-bit float, the samples exactly (bit for bit those of the pattern or its
  resampling), for round trips and analysis; not every player reads it.

Integer samples are rounded here, not by the audio library, so the same samples always give the
same bytes: code ``round(x·2ᵇ⁻¹)`` clipped to ``−2ᵇ⁻¹ … 2ᵇ⁻¹ − 1``, the scale readers divide by
(libsndfile, soundfile, most engines), so a sample reads back within half a step
(``2⁻ᵇ``), full scale +1 within one.

What it cannot carry: the pattern's components, only their sum; in mono, the sound; the coupling
of the sound to pressure and speed (Eq. 1) — the sound is at its reference level throughout;
with ``pcm16``/``pcm24``, the exact samples.
"""

from __future__ import annotations

import io
import math

import numpy as np

from realpen.errors import ParameterError, RealPenError
from realpen.exports.base import (
    Export,
    check_frames,
    check_pattern,
    check_span,
    resample_loop,
    sound_samples,
)
from realpen.io.files import add_smpl_loop, wav_bytes
from realpen.tactile.pattern import TactilePattern

__all__ = ["SUFFIX", "MAX_COMMON_S", "SUBTYPES", "DEFAULT_SUBTYPE", "LIMITS", "mono_samples",
           "stereo_samples", "encode", "export"]

SUFFIX = ".wav"
MAX_COMMON_S = 60.0
SUBTYPES = ("pcm16", "pcm24", "float")
"""The sample formats of the export (see the module docstring)."""
DEFAULT_SUBTYPE = "pcm16"
_BITS = {"pcm16": 16, "pcm24": 24}
LIMITS = (
    "the pattern's components: only their sum",
    "the sound: this file is the tactile pattern alone (stereo puts the sound on the left)",
    "the sound's coupling to pressure and speed (Eq. 1) is not applied: constant level",
)
QUANTISED = ("the exact samples: rounded to {bits} bits (half a step, {step:.1e} of full "
             "scale); subtype float keeps them")


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


def check_subtype(subtype: str) -> str:
    """``subtype`` if it is one of :data:`SUBTYPES`.

    Raises:
        ParameterError: (parameter ``subtype``) otherwise.
    """
    if subtype not in SUBTYPES:
        raise ParameterError("subtype", f"must be one of {', '.join(SUBTYPES)}, got {subtype!r}")
    return subtype


def encode(samples: np.ndarray, rate: int, subtype: str = DEFAULT_SUBTYPE) -> bytes:
    """A WAV of ``samples`` (frames, or frames × channels; full scale ±1) at ``rate`` Hz in
    ``subtype``, with a ``smpl`` chunk declaring the whole file one forward loop.

    The same samples always give the same bytes.

    Raises:
        ParameterError: an unknown ``subtype``.
    """
    subtype = check_subtype(subtype)
    if subtype == "float":
        return wav_bytes(samples, rate, loop=True)
    import soundfile as sf

    scale = 2 ** (_BITS[subtype] - 1)
    # float32 rounds exactly here (scaling by a power of two keeps a float32's 24-bit mantissa)
    # and holds half the memory of float64: a stereo export may be 2²⁵ frames.
    codes = np.asarray(samples, dtype=np.float32) * np.float32(scale)
    np.rint(codes, out=codes)
    np.clip(codes, -scale, scale - 1, out=codes)
    if scale == 2 ** 15:
        data, written = codes.astype(np.int16), "PCM_16"
    else:  # libsndfile writes the top 24 bits of 32-bit integers: nothing is rounded there
        data, written = codes.astype(np.int32) << 8, "PCM_24"
    buffer = io.BytesIO()
    sf.write(buffer, data, int(rate), subtype=written, format="WAV")
    return add_smpl_loop(buffer.getvalue())


def export(pattern: TactilePattern, sound=None, coupling=None, *, name: str = "pattern",
           tool: str = "", version: str | None = None, stereo: bool = False,
           rate: int | None = None, repeats: int = 1, subtype: str = DEFAULT_SUBTYPE) -> Export:
    """Render the WAV, with its ``smpl`` loop; see the module docstring.

    Args:
        pattern: the tactile pattern.
        sound: the sound loop; needed with ``stereo``.
        coupling: not carried (the sound plays at its reference level).
        name, tool, version: not written (a WAV has no metadata here).
        stereo: sound left, tactile right.
        rate: output rate in Hz (default: the pattern's, or with ``stereo`` the sound's).
        repeats: periods written.
        subtype: ``pcm16`` (default), ``pcm24`` or ``float`` (:data:`SUBTYPES`).

    Raises:
        ParameterError: an unknown ``subtype`` (before anything is rendered), a bad ``rate`` or
            ``repeats``, or no sound with ``stereo``.
    """
    subtype = check_subtype(subtype)
    if stereo:
        samples, out_rate = stereo_samples(pattern, sound, rate, repeats, name)
    else:
        samples, out_rate = mono_samples(pattern, rate, repeats, name)
    seconds = len(samples) / out_rate
    layout = "sound left, tactile right" if stereo else "tactile pattern, mono"
    limits = (LIMITS[0], LIMITS[2]) if stereo else LIMITS[:2]
    if subtype in _BITS:
        bits = _BITS[subtype]
        limits += (QUANTISED.format(bits=bits, step=2.0 ** -bits),)
    kind = "32-bit float" if subtype == "float" else f"{_BITS[subtype]}-bit PCM"
    return Export(encode(samples, out_rate, subtype),
                  f"{layout}, {kind}, {seconds * 1000:.0f} ms at {out_rate} Hz, smpl loop over "
                  f"the whole file (loops seamlessly)",
                  limits=limits)
