"""Granular friction sound: overlapping windowed grains from random offsets in the steady part.

A frozen 300 ms loop repeats 3.3 times a second, which the ear can catch. Grains (50 ms by
default) taken from random offsets in the steady part of the recording, overlapped by half with
a sine window, never repeat. Successive grains are uncorrelated noise, so the sine window's
sin² + cos² = 1 keeps the power constant (the equal-power rule of the loop crossfade).

The steady part: 5 ms blocks whose level smoothed over 100 ms lies within ``STEADY_DB`` of the
median, and whose own level is neither near silence (``SILENCE_DB`` below the loud blocks) nor a
burst (more than 2 × ``STEADY_DB`` above the median). A grain may start wherever every block it
reads is steady.

Each grain can be read at its own playback rate (``r`` source samples per output sample, by
linear interpolation): the grain keeps its length and its spectrum shifts by ``r``, which is how
faster strokes are made brighter.
"""

from __future__ import annotations

import os

import numpy as np
from scipy.ndimage import uniform_filter1d

from realpen.checks import MAX_MS, check_level, check_ms, check_seed, check_sound_rate
from realpen.defaults import GRAIN_MS, TEXTURE_LENGTH_MS
from realpen.errors import ParameterError, fail
from realpen.io.recording import Recording
from realpen.sound.loop import (
    DEFAULT_RATE,
    EDGE_MS,
    HOP_MS,
    REFERENCE_DBFS,
    SILENCE_DB,
    SoundLoop,
    load_sound,
    seam_report,
)
from realpen.sound.unit import SteadyPart, loop_rate, mono_signal, require_sound, samples_for

__all__ = ["steady_part", "grain_samples", "granular", "granular_loop",
           "GRAIN_MS", "LENGTH_MS", "MAX_LENGTH_MS", "STEADY_DB", "LEVEL_SMOOTH_MS"]

LENGTH_MS = TEXTURE_LENGTH_MS
MAX_LENGTH_MS = MAX_MS  # longest texture: 60 s (23 MB at 48 kHz); a loop need not be longer
STEADY_DB = 6.0
LEVEL_SMOOTH_MS = 100.0
_BLOCK = 1024  # grains rendered at once, at most
_BLOCK_VALUES = 2**22  # grain samples rendered at once (32 MiB per array), however long a grain




def steady_part(x: np.ndarray, rate: float, span_ms: float, tolerance_db: float = STEADY_DB,
                source: object = "signal") -> SteadyPart:
    """Find the grain starts whose next ``span_ms`` lie in the steady part of ``x``.

    Args:
        x: the recording, shape (frames,), full scale ±1.
        rate: its rate in Hz (``MIN_RATE`` to ``MAX_RATE`` of :mod:`realpen.sound`).
        span_ms: how much a grain reads, in ms (grain length × the highest playback rate).
        tolerance_db: allowed distance of the smoothed level from its median, in dB.
        source: names the recording in error messages.

    Raises:
        ParameterError: a rate out of range or a bad ``span_ms``.
        RealPenError: silence, or no steady stretch as long as ``span_ms``.
    """
    x = np.asarray(x, dtype=np.float64)
    check_sound_rate(rate)
    check_ms("span_ms", span_ms, maximum=None)  # from a checked grain: up to rate_max × grain
    require_sound(x, source)
    block = max(1, int(HOP_MS * rate / 1000))
    span = int(np.ceil(span_ms * rate / 1000))
    if len(x) < max(span, block):
        raise fail(source, f"recording lasts {len(x) / rate * 1000:.0f} ms, shorter than one "
                           f"{span_ms:.0f} ms grain")
    count = len(x) // block
    power = np.mean(x[:count * block].reshape(count, block) ** 2, axis=1)
    levels = 10 * np.log10(np.maximum(power, 1e-30))
    smooth_blocks = max(1, int(round(LEVEL_SMOOTH_MS / HOP_MS)))
    smoothed = 10 * np.log10(np.maximum(uniform_filter1d(power, smooth_blocks, mode="nearest"),
                                        1e-30))
    gate = float(np.percentile(levels, 95)) - SILENCE_DB
    typical = float(np.median(smoothed[levels >= gate]))
    # Blocks are judged one by one as well, so a grain never reads into a dropout or a burst
    # that the 100 ms smoothing blurs at its edges.
    steady = ((np.abs(smoothed - typical) <= tolerance_db) & (levels >= gate)
              & (levels <= typical + 2 * tolerance_db))
    needed = -(-span // block)
    bad = np.concatenate([[0], np.cumsum(~steady)])
    grid = np.arange(0, count - needed + 1)
    allowed = grid[bad[grid + needed] - bad[grid] == 0]
    if len(allowed) == 0:
        raise fail(source, f"no steady stretch of {span_ms:.0f} ms (level within "
                           f"±{tolerance_db:g} dB of its median) to take grains from")
    breaks = np.flatnonzero(np.diff(allowed) > 1)
    run_starts = np.concatenate([[allowed[0]], allowed[breaks + 1]])
    run_ends = np.concatenate([allowed[breaks], [allowed[-1]]])
    stretches = [(int(a * block), int(b * block + span)) for a, b in zip(run_starts, run_ends)]
    covered = np.concatenate([x[a:b] for a, b in stretches])
    return SteadyPart(starts=allowed * block, span=span, stretches=stretches,
                      rms=float(np.sqrt(np.mean(covered ** 2))))




def grain_samples(grain_ms: float, rate: float) -> int:
    """Length in samples of a ``grain_ms`` ms grain at ``rate`` Hz: even, at least 4."""
    grain = samples_for(grain_ms, rate)
    return max(4, grain - grain % 2)


def granular(x: np.ndarray, rate: float, frames: int, part: SteadyPart,
             grain_ms: float = GRAIN_MS, seed: int = 0,
             playback_rate: np.ndarray | None = None, circular: bool = False,
             even: bool = True) -> np.ndarray:
    """Overlap-add sine-windowed grains (hop = half a grain) from random steady offsets.

    Args:
        x: the recording the grains come from.
        rate: its rate in Hz (also the output rate).
        frames: output length in samples (a multiple of half a grain when ``circular``).
        part: where grains may start (:func:`steady_part` with a span ≥ grain × max rate).
        grain_ms: grain length in ms.
        seed: seed of the random offsets.
        playback_rate: per output sample, source samples read per output sample (default 1);
            each grain uses the value at its centre.
        circular: wrap the last grains onto the start, so the output loops without a seam.
        even: scale every grain to the steady part's RMS. The hand's own swell between
            strokes (up to ±``STEADY_DB``) is then left out; Eq. 1 supplies the dynamics.

    Returns:
        shape (frames,), with the power of the steady material.

    Raises:
        ParameterError: ``frames`` not a multiple of half a grain for a circular texture, a
            playback rate reading past the steady part's span, or a negative ``seed``.
    """
    x = np.asarray(x, dtype=np.float64)
    grain = grain_samples(grain_ms, rate)
    hop = grain // 2
    if circular and frames % hop:
        raise ParameterError("frames", f"a circular texture needs a multiple of {hop} frames, "
                                       f"got {frames}")
    first = 0 if circular else -1
    positions = np.arange(first, -(-frames // hop)) * hop
    if playback_rate is None:
        rates = np.ones(len(positions))
    else:
        centres = np.clip(positions + hop, 0, frames - 1)
        rates = np.asarray(playback_rate, dtype=np.float64)[centres]
    if np.any(rates * (grain - 1) + 1 >= part.span):
        raise ParameterError("playback_rate", "too high for the steady part's span")
    check_seed(seed)
    rng = np.random.default_rng(seed)
    offsets = rng.choice(part.starts, size=len(positions))
    window = np.sin(np.pi * (np.arange(grain) + 0.5) / grain)
    out = np.zeros(frames + 2 * grain)
    steps = np.arange(grain)
    per_block = max(1, min(_BLOCK, _BLOCK_VALUES // grain))
    for block in range(0, len(positions), per_block):
        chunk = slice(block, block + per_block)
        read = offsets[chunk, None] + rates[chunk, None] * steps
        whole = np.floor(read).astype(np.int64)
        frac = read - whole
        grains = x[whole] * (1 - frac) + x[whole + 1] * frac
        if even:
            rms = np.sqrt(np.mean(grains ** 2, axis=1, keepdims=True))
            grains = grains * np.where(rms > 0, part.rms / np.where(rms > 0, rms, 1), 0.0)
        grains = grains * window
        where = positions[chunk, None] + steps + grain
        np.add.at(out, where.ravel(), grains.ravel())
    body = out[grain:grain + frames]
    if circular:
        body = body.copy()
        body[:grain] += out[grain + frames:]
    return body


def granular_loop(sound: Recording | np.ndarray | SoundLoop | str | os.PathLike,
                  rate: float | None = None, *, length_ms: float = LENGTH_MS,
                  grain_ms: float = GRAIN_MS, seed: int = 0,
                  level_dbfs: float = REFERENCE_DBFS, source: object | None = None
                  ) -> SoundLoop:
    """A granular texture of ``length_ms`` (rounded to half grains) that loops without a seam.

    The texture is scaled so the steady material has an RMS of ``level_dbfs`` dB re full scale
    (dBFS).

    Args:
        sound: a recording (mixed down when it has several channels), an array of samples
            (frames,) with ``rate``, a :class:`~realpen.sound.loop.SoundLoop` (its samples are
            the material) or the path of an audio file (read by
            :func:`~realpen.sound.loop.load_sound`).
        rate: the array's rate in Hz (also the texture's); for a recording, resample to this
            rate first (None keeps its own); for a path, the rate to load at (None: 48 kHz).
        length_ms: texture length in ms, from 60 ms (and two grains) up to ``MAX_LENGTH_MS``
            (60 s).
        grain_ms: grain length in ms (finite, positive).
        seed: seed of the random grain offsets (≥ 0).
        level_dbfs: RMS of the steady material in dBFS, finite and at most 0.
        source: names the recording in error messages (default: the recording's file).

    Returns:
        The :class:`~realpen.sound.loop.SoundLoop` (``mode="granular"``).

    Raises:
        ParameterError: a rate out of range, bad lengths, level or seed.
        RealPenError: silence, or no steady stretch as long as a grain.

    Example:
        >>> import numpy as np
        >>> noise = np.random.default_rng(0).normal(0, 0.1, 3 * 48000)
        >>> texture = granular_loop(noise, 48000, length_ms=1000)
        >>> texture.mode, texture.frames, round(texture.rms_dbfs)
        ('granular', 48000, -20)
    """
    if isinstance(sound, (str, os.PathLike)):
        sound = load_sound(sound, DEFAULT_RATE if rate is None else rate)
        rate = None
    if isinstance(sound, SoundLoop):
        x, rate = sound.samples, loop_rate(sound, rate)
        name = source or sound.source or "loop"
        provenance = (sound.source, sound.source_sha256, sound.history)
    else:
        x, rate, recording, name = mono_signal(sound, rate, source)
        provenance = ((recording.source, recording.sha256, recording.history) if recording
                      else (None, None, ()))
    check_ms("grain_ms", grain_ms)
    check_ms("length_ms", length_ms)
    check_level(level_dbfs)
    hop = grain_samples(grain_ms, rate) // 2
    if 2 * grain_ms > MAX_LENGTH_MS:  # no texture could hold two grains: the grain is wrong
        raise ParameterError("grain_ms", f"must be at most {MAX_LENGTH_MS / 2:g} ms (a texture "
                                         f"holds two grains or more, and lasts at most "
                                         f"{MAX_LENGTH_MS:g} ms), got {grain_ms:g}")
    shortest = max(3 * EDGE_MS, 2 * grain_ms)
    if length_ms < shortest:
        raise ParameterError("length_ms", f"must be at least {shortest:g} ms (two "
                                          f"{grain_ms:g} ms grains, and three {EDGE_MS:g} ms "
                                          f"frames to judge the seam), got {length_ms:g}")
    if length_ms > MAX_LENGTH_MS:
        raise ParameterError("length_ms", f"must be at most {MAX_LENGTH_MS:g} ms "
                                          f"({MAX_LENGTH_MS / 1000:g} s), got {length_ms:g}")
    check_seed(seed)
    frames = max(1, int(round(length_ms * rate / 1000 / hop))) * hop
    part = steady_part(x, rate, (grain_samples(grain_ms, rate) + 2) * 1000 / rate, source=name)
    texture = granular(x, rate, frames, part, grain_ms, seed, circular=True)
    gain = 10 ** (level_dbfs / 20) / part.rms
    texture = texture * gain
    return SoundLoop(samples=texture, rate=float(rate), mode="granular",
                     start_s=part.stretches[0][0] / rate, seam=seam_report(texture, rate,
                                                                           source=name),
                     part=part, grain_ms=float(grain_ms), seed=int(seed), gain=float(gain),
                     source=provenance[0], source_sha256=provenance[1], history=provenance[2])
