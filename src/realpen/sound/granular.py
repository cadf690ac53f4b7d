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

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from realpen import __version__
from realpen.errors import RealPenError, fail
from realpen.io.recording import Recording
from realpen.sound.loop import (EDGE_MS, HOP_MS, REFERENCE_DBFS, SILENCE_DB, Seam, check_level, check_ms,
                    check_rate, level_db, require_sound, samples_for, seam_report)

GRAIN_MS = 50.0
LENGTH_MS = 3000.0
MAX_LENGTH_MS = 60000.0  # longest texture: 60 s (23 MB at 48 kHz); a loop need not be longer
STEADY_DB = 6.0
LEVEL_SMOOTH_MS = 100.0
_BLOCK = 1024  # grains rendered at once


@dataclass(frozen=True)
class SteadyPart:
    """Where grains may come from.

    Attributes:
        starts: allowed first samples of a grain, ascending.
        span: samples a grain may read from its start.
        stretches: contiguous steady stretches as (start, stop) samples.
        rms: RMS of the recording over those stretches (linear, full scale).
    """

    starts: np.ndarray
    span: int
    stretches: list[tuple[int, int]]
    rms: float


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
        RealPenError: a rate out of range, silence, or no steady stretch as long as ``span_ms``.
    """
    x = np.asarray(x, dtype=np.float64)
    check_rate(rate)
    check_ms("span_ms", span_ms)
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
    """
    x = np.asarray(x, dtype=np.float64)
    grain = grain_samples(grain_ms, rate)
    hop = grain // 2
    if circular and frames % hop:
        raise ValueError(f"a circular texture needs a multiple of {hop} frames, got {frames}")
    first = 0 if circular else -1
    positions = np.arange(first, -(-frames // hop)) * hop
    if playback_rate is None:
        rates = np.ones(len(positions))
    else:
        centres = np.clip(positions + hop, 0, frames - 1)
        rates = np.asarray(playback_rate, dtype=np.float64)[centres]
    if np.any(rates * (grain - 1) + 1 >= part.span):
        raise ValueError("playback rate too high for the steady part's span")
    if seed < 0:
        raise RealPenError(f"--seed must be ≥ 0, got {seed}")
    rng = np.random.default_rng(seed)
    offsets = rng.choice(part.starts, size=len(positions))
    window = np.sin(np.pi * (np.arange(grain) + 0.5) / grain)
    out = np.zeros(frames + 2 * grain)
    steps = np.arange(grain)
    for block in range(0, len(positions), _BLOCK):
        chunk = slice(block, block + _BLOCK)
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


@dataclass(frozen=True)
class GranularTexture:
    """A seamless granular loop and where its grains came from.

    Attributes:
        samples: the texture, shape (frames,), full scale ±1.
        rate: its rate in Hz.
        part: the steady part the grains came from (positions in samples).
        grain_ms: grain length in ms; seed: seed of the grain offsets.
        seam: the texture's seam report (dB).
        gain: linear gain applied to the grains (steady RMS → the requested dBFS).
        source, source_sha256, history: the recording.
    """

    samples: np.ndarray
    rate: float
    part: SteadyPart
    grain_ms: float
    seed: int
    seam: Seam
    gain: float = 1.0
    source: str | None = None
    source_sha256: str | None = None
    history: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """The ``realpen sound loop --mode granular --json`` document."""
        stretches = [[round(a / self.rate, 6), round(b / self.rate, 6)]
                     for a, b in self.part.stretches]
        return {
            "realpen_version": __version__,
            "mode": "granular",
            "source": {"path": self.source, "sha256": self.source_sha256,
                       "history": list(self.history)},
            "rate": self.rate,
            "frames": int(len(self.samples)),
            "length_ms": round(len(self.samples) / self.rate * 1000, 3),
            "start_s": stretches[0][0],
            "end_s": stretches[-1][1],
            "steady_stretches_s": stretches,
            "steady_s": round(sum(b - a for a, b in self.part.stretches) / self.rate, 6),
            "grain_ms": self.grain_ms,
            "seed": self.seed,
            "seam": self.seam.to_json(),
            "gain": self.gain,
            "rms_dbfs": round(level_db(self.samples), 3),
        }


def granular_loop(x: np.ndarray, rate: float, length_ms: float = LENGTH_MS,
                  grain_ms: float = GRAIN_MS, seed: int = 0, rms_dbfs: float = REFERENCE_DBFS,
                  source: object = "signal", recording: Recording | None = None
                  ) -> GranularTexture:
    """A granular texture of ``length_ms`` (rounded to half grains) that loops without a seam.

    The texture is scaled so the steady material has an RMS of ``rms_dbfs`` dB re full scale.

    Args:
        x: the recording, shape (frames,), full scale ±1.
        rate: its rate in Hz (also the texture's).
        length_ms: texture length in ms, from 60 ms (and two grains) up to ``MAX_LENGTH_MS``
            (60 s).
        grain_ms: grain length in ms (finite, positive).
        seed: seed of the random grain offsets (≥ 0).
        rms_dbfs: RMS of the steady material in dBFS, finite and at most 0.
        source: names the recording in error messages.
        recording: the loaded recording, for provenance in the JSON.

    Raises:
        RealPenError: a rate out of range, bad lengths or level, silence, or no steady stretch
            as long as a grain.
    """
    check_rate(rate)
    check_ms("--grain-ms", grain_ms)
    check_ms("--length-ms", length_ms)
    check_level(rms_dbfs)
    hop = grain_samples(grain_ms, rate) // 2
    shortest = max(3 * EDGE_MS, 2 * grain_ms)
    if length_ms < shortest:
        raise RealPenError(f"--length-ms must be at least {shortest:g} ms, got {length_ms:g}")
    if length_ms > MAX_LENGTH_MS:
        raise RealPenError(f"--length-ms must be at most {MAX_LENGTH_MS:g} ms "
                           f"({MAX_LENGTH_MS / 1000:g} s), got {length_ms:g}")
    frames = max(1, int(round(length_ms * rate / 1000 / hop))) * hop
    part = steady_part(x, rate, (grain_samples(grain_ms, rate) + 2) * 1000 / rate, source=source)
    texture = granular(x, rate, frames, part, grain_ms, seed, circular=True)
    gain = 10 ** (rms_dbfs / 20) / part.rms
    texture = texture * gain
    return GranularTexture(samples=texture, rate=float(rate), part=part, grain_ms=float(grain_ms),
                           seed=int(seed), seam=seam_report(texture, rate, source=source),
                           gain=float(gain), source=recording.source if recording else None,
                           source_sha256=recording.sha256 if recording else None,
                           history=recording.history if recording else ())
