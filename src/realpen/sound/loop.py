"""Friction sound: loading, the one :class:`SoundLoop` type, the seamless loop unit, the seam.

The method plays each pen's recorded friction sound in a loop while the pen writes. The loop
unit (300 ms by default) is the window of the recording whose head and tail match best, is
steady, and is not near silence. Its wrap is made seamless with a crossfade that is read *past*
the window: the first ``crossfade_ms`` of the unit fade from the recording's natural
continuation after the tail into the unit's own head. At the wrap the loop therefore plays
exactly what followed the tail in the recording, and the blend lies inside the unit.

The crossfade is equal-power (sin/cos) for uncorrelated material, as friction noise is.
Correlated material (a tone whose cycles fit the unit) gains up to +3 dB under sin/cos, so the
gains are divided by √(1 + ρ·sin 2θ), with ρ the measured correlation of the two blended
segments: the power stays constant for any ρ, and ρ = 1 becomes an equal-gain fade. A tone in
anti-phase at the wrap (ρ near −1) cannot be blended at a fixed unit length without a dip;
ρ is reported so that case is visible.

Scores, all in dB, lower is better (``scores`` in the JSON):

* ``level_jump_db``: |level of the last 20 ms − level of the first 20 ms after the crossfade|.
* ``spectral_db``: RMS difference of the mean-removed log-band spectra (24 log-spaced bands,
  100 Hz–16 kHz) of the same two 20 ms frames, i.e. the pattern apart from the level.
* ``stationarity_db``: standard deviation of the 20 ms frame levels inside the window.
* ``quietness_db``: how far the window's level lies below the median window level.

``cost = 3·level_jump + spectral + stationarity + quietness``. The level jump weighs three times
because a step in loudness is the most audible seam, while two 20 ms frames of the same noise
already differ by 3–5 dB per band by chance. Windows whose level, head or tail lies more than
``SILENCE_DB`` below the recording's loud frames (95th percentile) are rejected as near silence.
The scan measures head and tail exactly as :func:`seam_report` measures the finished loop, so
the chosen window's ``level_jump_db`` is the seam's.

One type. A :class:`SoundLoop` is every sound unit RealPen plays: a unit found by
:func:`find_loop` (``mode="loop"``), a granular texture made by
:func:`realpen.sound.granular.granular_loop` (``mode="granular"``), or a ready loop read from a
WAV file that declares its loop in a ``smpl`` chunk (as ``realpen sound loop`` writes it; see
:func:`load_sound`). Stroke rendering, profiles and exports all take it.

Limits, checked wherever a value is taken (:mod:`realpen.checks`): rates from
:data:`~realpen.checks.MIN_SOUND_RATE_HZ` (8 kHz: the bands need room between 100 Hz and
0.45 × rate) to :data:`~realpen.checks.MAX_RATE_HZ` (384 kHz); lengths in ms finite, positive
and at most :data:`~realpen.checks.MAX_MS` (a minute); a
loop level (RMS, dBFS) finite and at most 0 dBFS. A bad argument raises
:class:`~realpen.errors.ParameterError` naming the Python parameter (``unit_ms``, ``rate``,
``level_dbfs``, ...); bad data (a file, a recording that is silent — digital silence or a
constant (DC) value, RMS below :data:`~realpen.sound.unit.SILENT_DBFS` with its mean
removed — or too short) raises :class:`~realpen.errors.RealPenError` naming the source.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from realpen._version import __version__
from realpen.checks import check_level, check_ms, check_sound_rate, is_number, sound_rate_problem
from realpen.defaults import (
    SOUND_CROSSFADE_MS,
    SOUND_MODES,
    SOUND_RATE_HZ,
    SOUND_REFERENCE_DBFS,
    SOUND_UNIT_MS,
)
from realpen.dsp.filters import resample
from realpen.errors import ParameterError, fail
from realpen.io.files import read_smpl_loop, wav_bytes, write_wav
from realpen.io.recording import Recording, load_recording
from realpen.sound.unit import (
    SteadyPart,
    check_source_rate,
    level_db,
    mono_signal,
    require_sound,
    samples_for,
)

__all__ = [
    "SoundLoop", "Seam", "Scan", "find_loop", "find_loop_unit", "load_sound", "seam_report",
    "scan_windows", "make_loop", "crossfade_gains", "band_levels_db", "normalise",
    "ProgressCallback", "DEFAULT_RATE", "UNIT_MS", "CROSSFADE_MS", "EDGE_MS", "HOP_MS",
    "SILENCE_DB", "REFERENCE_DBFS", "FLOOR_DB", "BANDS", "WEIGHTS", "MODES",
]

DEFAULT_RATE = SOUND_RATE_HZ
UNIT_MS = SOUND_UNIT_MS
CROSSFADE_MS = SOUND_CROSSFADE_MS
EDGE_MS = 20.0          # head/tail length for level and spectrum
HOP_MS = 5.0            # scan step; the issue asks for ≤ 5 ms
SILENCE_DB = 30.0       # below the recording's loud frames: near silence
REFERENCE_DBFS = SOUND_REFERENCE_DBFS  # RMS of a normalised loop: coupling gain 1 plays at it
FLOOR_DB = 80.0         # band levels further below the loud frames are treated as equal
BANDS = (24, 100.0, 16000.0)
WEIGHTS = {"level_jump_db": 3.0, "spectral_db": 1.0, "stationarity_db": 1.0,
           "quietness_db": 1.0}
MODES = SOUND_MODES
NOT_AUDIO = (".csv", ".npz", ".json", ".txt")
_CHUNK = 2048  # frames per FFT block, to bound memory on long recordings

ProgressCallback = Callable[[int, int], None]  # (windows done, windows in all)


def load_sound(path: str | os.PathLike, rate: float | None = DEFAULT_RATE
               ) -> Recording | SoundLoop:
    """Load a friction sound: WAV/FLAC/OGG at any rate, mixed down to mono.

    A WAV whose ``smpl`` chunk declares a loop (as ``realpen sound loop`` writes it, or a
    sampler or audio editor) is a ready loop: its loop (the frames from the loop's start to its
    end, inclusive) comes back as a :class:`SoundLoop`, which every command and function that
    takes a sound plays as it is. Resampling a ready loop is circular (FFT), so it stays
    seamless; its length is rounded to whole samples at the new rate.

    Args:
        path: the audio file.
        rate: resample to this rate in Hz (default 48 kHz); None keeps the file's rate. Either
            must lie between 8 kHz and 384 kHz.

    Returns:
        A one-axis :class:`~realpen.io.recording.Recording` (axis ``"mono"``, full scale ±1),
        or a :class:`SoundLoop` for a WAV that declares its loop.

    Raises:
        ParameterError: ``rate`` out of range.
        RealPenError: missing, empty, truncated or non-audio files, NaN/inf, a file's rate out
            of range, silence or a constant (DC) signal, a ``smpl`` loop outside the file.

    Example:
        >>> import tempfile, pathlib, numpy as np
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "loop.wav"
        >>> noise = np.random.default_rng(0).normal(0, 0.1, 48000)
        >>> find_loop(noise, rate=48000).save(path)
        >>> load_sound(path).mode, len(load_sound(path).samples)
        ('loop', 14400)
    """
    path = Path(path)
    if rate is not None:
        check_sound_rate(rate)
    if path.suffix.lower() in NOT_AUDIO:
        raise fail(path, "not an audio file (give a WAV, FLAC or OGG recording)")
    loaded = load_recording(path)
    channels = loaded.samples.shape[1]
    mono = loaded.samples.mean(axis=1)
    step = f"mixdown:{channels}ch" if channels > 1 else "mono"
    points = read_smpl_loop(path)
    if points is not None:
        return _ready_loop(loaded, mono, step, points, rate, path)
    # Judged before resampling too: the filter's edge transients would give a constant (DC)
    # recording an AC part of its own.
    require_sound(mono, path)
    sound = loaded.with_samples(mono[:, None], step, axes=("mono",))
    if rate is None:
        check_source_rate(sound.rate, path)
    else:
        sound = resample(sound, float(rate))
    require_sound(sound.mono, path)
    return sound


def _ready_loop(loaded: Recording, mono: np.ndarray, step: str, points: tuple[int, int],
                rate: float | None, path: Path) -> SoundLoop:
    """The loop a WAV's ``smpl`` chunk declares, as a :class:`SoundLoop`."""
    start, end = points
    if end >= len(mono):
        raise fail(path, f"the smpl chunk's loop ({start}–{end}) lies outside the file's "
                         f"{len(mono)} frames")
    check_source_rate(loaded.rate, path)
    samples = np.array(mono[start:end + 1], dtype=np.float64)
    require_sound(samples, path)
    history = loaded.history + (step, f"smpl-loop:{start}-{end}")
    own_rate = float(loaded.rate)
    if rate is not None and abs(float(rate) - own_rate) > 1e-9:
        from scipy.signal import resample as fft_resample

        frames = max(1, int(round(len(samples) * float(rate) / own_rate)))
        samples = fft_resample(samples, frames)  # periodic: the wrap stays seamless
        history += (f"resample-circular:{float(rate):g}Hz",)
        own_rate = float(rate)
    return SoundLoop.from_samples(samples, own_rate, start_s=start / loaded.rate,
                                  source=str(path), source_sha256=loaded.sha256, history=history)


def normalise(x: np.ndarray, level_dbfs: float = REFERENCE_DBFS) -> tuple[np.ndarray, float]:
    """Scale ``x`` to an RMS of ``level_dbfs`` dB re full scale (dBFS); returns (scaled, gain).

    Args:
        x: samples, full scale ±1.
        level_dbfs: the RMS to reach in dBFS (finite, at most 0).

    Raises:
        ParameterError: ``level_dbfs`` not finite or above :data:`~realpen.checks.MAX_LEVEL_DBFS` (0 dBFS).
    """
    check_level(level_dbfs)
    level = level_db(x)
    if not np.isfinite(level):
        return np.array(x, dtype=np.float64), 1.0
    gain = 10 ** ((level_dbfs - level) / 20)
    return np.asarray(x, dtype=np.float64) * gain, float(gain)


def crossfade_gains(length: int, correlation: np.ndarray | float = 0.0,
                    compensate: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Fade-in and fade-out gains of an equal-power crossfade of ``length`` samples.

    Args:
        length: fade length in samples.
        correlation: correlation ρ of the two blended segments (scalar, or one per row).
        compensate: divide by √(1 + ρ sin 2θ) so power stays constant for correlated segments;
            False gives the plain sin/cos law.

    Returns:
        (fade_in, fade_out), each of shape (length,) or (rows, length).
    """
    theta = 0.5 * np.pi * (np.arange(length) + 0.5) / max(length, 1)
    fade_in, fade_out = np.sin(theta), np.cos(theta)
    # Below −0.5 the boost would pass +3 dB to chase a cancellation no fade can avoid.
    rho = np.clip(np.asarray(correlation, dtype=np.float64), -0.5, 1.0) if compensate else 0.0
    rho = np.asarray(rho)[..., None]
    scale = 1.0 / np.sqrt(1.0 + rho * np.sin(2 * theta))
    return fade_in * scale, fade_out * scale


def make_loop(x: np.ndarray, start: int, length: int, fade: int,
              compensate: bool = True) -> tuple[np.ndarray, float]:
    """Cut ``x[start:start+length]`` and blend its first ``fade`` samples with what follows it.

    ``start``, ``length`` and ``fade`` are in samples; ``x`` must hold ``start + length + fade``
    samples. Returns (loop, correlation ρ of the blended segments, −1 to 1).
    """
    unit = np.array(x[start:start + length], dtype=np.float64)
    if fade == 0:
        return unit, 0.0
    head, after = unit[:fade], np.asarray(x[start + length:start + length + fade], dtype=float)
    rho = _correlation(float(head @ after), float(head @ head), float(after @ after))
    fade_in, fade_out = crossfade_gains(fade, rho, compensate)
    unit[:fade] = fade_in * head + fade_out * after
    return unit, rho


def _correlation(dot, energy_a, energy_b):
    denominator = np.sqrt(np.multiply(energy_a, energy_b))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(denominator > 0, dot / np.where(denominator > 0, denominator, 1), 0.0)


def band_levels_db(frames: np.ndarray, rate: float, floor_power: float) -> np.ndarray:
    """Log-band spectra of frames: (frames, bands) in dB re full scale, floored.

    Bands are log-spaced between ``BANDS`` edges (Hz, the top one at most 0.45 × rate); each
    holds at least one FFT bin. Powers are scaled so the bands of a frame add up to its mean
    square (Hann window).

    Args:
        frames: one frame per row (samples, full scale ±1).
        rate: their rate in Hz.
        floor_power: lowest band power kept (linear, full scale² per sample).
    """
    frames = np.atleast_2d(frames)
    width = frames.shape[1]
    window = np.hanning(width)
    count, low, high = BANDS
    power = np.abs(np.fft.rfft(frames * window, axis=1)) ** 2 * 2 / (width * np.sum(window ** 2))
    edges = np.round(np.geomspace(low, min(high, 0.45 * rate), count + 1) * width / rate)
    edges = np.unique(np.clip(edges.astype(int), 1, power.shape[1] - 1))
    bands = np.add.reduceat(power[:, edges[0]:edges[-1]], edges[:-1] - edges[0], axis=1)
    return 10 * np.log10(np.maximum(bands, floor_power))


def _flux(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((a - b) ** 2, axis=-1))


def _shape(levels: np.ndarray) -> np.ndarray:
    return levels - levels.mean(axis=-1, keepdims=True)


@dataclass(frozen=True)
class Seam:
    """How a looping signal behaves at its wrap (all figures in dB).

    Attributes:
        level_jump_db: |RMS level of the first 20 ms − RMS level of the last 20 ms|.
        flux_wrap_db: log-band spectral flux between the last and the first 20 ms frame.
        flux_inside_median_db, flux_inside_p95_db: median and 95th percentile of the flux
            between adjacent 20 ms frames inside the loop (every 5 ms).
        flux_wrap_percentile: share of inside flux values below the wrap's, in percent.
        level_inside_p95_db: 95th percentile of the level step between the same inside pairs.
        pairs: how many inside frame pairs the distributions hold.
    """

    level_jump_db: float
    level_inside_p95_db: float
    flux_wrap_db: float
    flux_inside_median_db: float
    flux_inside_p95_db: float
    flux_wrap_percentile: float
    pairs: int

    def to_json(self) -> dict:
        """The figures, rounded to 0.1 mdB, for a JSON report."""
        return {key: round(value, 4) if isinstance(value, float) else value
                for key, value in self.__dict__.items()}

    def __repr__(self) -> str:
        return (f"Seam(level_jump_db={self.level_jump_db:.3g}, flux_wrap_db="
                f"{self.flux_wrap_db:.3g} (inside median {self.flux_inside_median_db:.3g}, p95 "
                f"{self.flux_inside_p95_db:.3g}; percentile {self.flux_wrap_percentile:.0f}), "
                f"pairs={self.pairs})")


def seam_report(loop: np.ndarray, rate: float, edge_ms: float = EDGE_MS,
                hop_ms: float = HOP_MS, source: object = "loop") -> Seam:
    """Measure the wrap of a loop: level jump and spectral flux against the loop's own flux.

    Args:
        loop: the looping signal, shape (frames,), full scale ±1.
        rate: its rate in Hz (8 kHz to 384 kHz).
        edge_ms: frame length in ms for levels and spectra.
        hop_ms: step in ms between the inside frame pairs.
        source: names the loop in error messages.

    Returns:
        The :class:`Seam` (figures in dB, the percentile in percent).

    Raises:
        ParameterError: a rate out of range or bad lengths.
        RealPenError: a loop shorter than three frames.
    """
    loop = np.asarray(loop, dtype=np.float64)
    check_sound_rate(rate)
    check_ms("edge_ms", edge_ms)
    check_ms("hop_ms", hop_ms)
    edge, hop = samples_for(edge_ms, rate), max(1, int(hop_ms * rate / 1000))
    if len(loop) < 3 * edge:
        raise fail(source, f"a loop of {len(loop) / rate * 1000:.0f} ms is too short to judge "
                           f"its seam with {edge_ms:g} ms frames")
    floor = 10 ** ((level_db(loop) - FLOOR_DB) / 10) if level_db(loop) > -np.inf else 1e-30
    frames = sliding_window_view(loop, edge)
    positions = np.arange(0, len(loop) - 2 * edge + 1, hop)
    first = band_levels_db(frames[positions], rate, floor)
    second = band_levels_db(frames[positions + edge], rate, floor)
    inside = _flux(first, second)
    powers = np.mean(frames[positions] ** 2, axis=1), np.mean(frames[positions + edge] ** 2, axis=1)
    steps = np.abs(10 * np.log10(np.maximum(powers[1], 1e-30) / np.maximum(powers[0], 1e-30)))
    tail, head = loop[-edge:], loop[:edge]
    wrap = float(_flux(band_levels_db(tail, rate, floor), band_levels_db(head, rate, floor))[0])
    jump = abs(level_db(head) - level_db(tail))
    return Seam(level_jump_db=float(jump) if np.isfinite(jump) else 0.0,
                level_inside_p95_db=float(np.percentile(steps, 95)),
                flux_wrap_db=wrap,
                flux_inside_median_db=float(np.median(inside)),
                flux_inside_p95_db=float(np.percentile(inside, 95)),
                flux_wrap_percentile=float(100 * np.mean(inside < wrap)),
                pairs=int(len(inside)))


@dataclass(frozen=True, repr=False, eq=False)
class Scan:
    """Scores of every candidate window (arrays of shape (windows,), dB).

    ``cost`` is +inf for windows rejected as near silence (``rejected``).
    """

    starts: np.ndarray
    level_jump_db: np.ndarray
    spectral_db: np.ndarray
    stationarity_db: np.ndarray
    quietness_db: np.ndarray
    correlation: np.ndarray
    rejected: np.ndarray
    cost: np.ndarray

    def __repr__(self) -> str:
        return (f"Scan({len(self.starts)} windows, {int(self.rejected.sum())} near silence, "
                f"best cost {float(np.min(self.cost)):.3g} dB)")


def scan_windows(x: np.ndarray, rate: float, unit_ms: float = UNIT_MS,
                 crossfade_ms: float = CROSSFADE_MS, hop_ms: float = HOP_MS,
                 edge_ms: float = EDGE_MS, compensate: bool = True,
                 weights: dict[str, float] | None = None, source: object = "signal",
                 progress: ProgressCallback | None = None) -> Scan:
    """Score every window of ``unit_ms`` (every ``hop_ms``) as a loop unit; see the module doc.

    Args:
        x: the recording, shape (frames,), full scale ±1.
        rate: its rate in Hz (8 kHz to 384 kHz).
        unit_ms, crossfade_ms, hop_ms, edge_ms: unit, wrap crossfade, scan step and head/tail
            frame lengths in ms, each finite and positive.
        compensate: correlation-compensated crossfade (see the module doc).
        weights: overrides entries of ``WEIGHTS`` (dimensionless factors on dB scores).
        source: names the signal in error messages.
        progress: called as ``progress(done, total)`` (windows) after each block of windows
            (about a second of work per 130 s of recording at 48 kHz).

    Raises:
        ParameterError: a rate out of range or bad lengths.
        RealPenError: a signal shorter than unit + crossfade, silence, or no window clear of
            near-silence.
    """
    x = np.asarray(x, dtype=np.float64)
    check_sound_rate(rate)
    for name, value in (("unit_ms", unit_ms), ("crossfade_ms", crossfade_ms),
                        ("hop_ms", hop_ms), ("edge_ms", edge_ms)):
        check_ms(name, value)
    length, fade, edge = (samples_for(unit_ms, rate), samples_for(crossfade_ms, rate),
                          samples_for(edge_ms, rate))
    hop = max(1, int(hop_ms * rate / 1000))
    _check_lengths(unit_ms, crossfade_ms, edge_ms, length, fade, edge)
    if len(x) < length + fade:
        raise fail(source, f"recording lasts {len(x) / rate * 1000:.0f} ms, shorter than the "
                           f"{unit_ms:g} ms unit plus the {crossfade_ms:g} ms crossfade")
    require_sound(x, source)
    starts = np.arange(0, len(x) - length - fade + 1, hop)
    energy = np.concatenate([[0.0], np.cumsum(x * x)])
    lagged = np.concatenate([[0.0], np.cumsum(x[:len(x) - length] * x[length:])])
    rho = _correlation(lagged[starts + fade] - lagged[starts],
                       energy[starts + fade] - energy[starts],
                       energy[starts + length + fade] - energy[starts + length])

    def mean_db(first: np.ndarray, count: int) -> np.ndarray:
        power = (energy[first + count] - energy[first]) / count
        return 10 * np.log10(np.maximum(power, 1e-30))

    frame_levels = mean_db(np.arange(0, len(x) - edge + 1, hop), edge)
    loud = float(np.percentile(frame_levels, 95))
    floor = 10 ** ((loud - FLOOR_DB) / 10)
    head_db, head_levels, tail_db = _edges(x, rate, starts, length, fade, edge, rho,
                                           compensate, floor, progress)
    tail_levels = mean_db(starts + length - edge, edge)
    window_levels = mean_db(starts, length)
    inside = (length - edge) // hop + 1
    sums = np.concatenate([[0.0], np.cumsum(frame_levels)])
    squares = np.concatenate([[0.0], np.cumsum(frame_levels ** 2)])
    index = starts // hop
    mean = (sums[index + inside] - sums[index]) / inside
    spread = np.sqrt(np.maximum((squares[index + inside] - squares[index]) / inside - mean ** 2,
                                0.0))
    gate = loud - SILENCE_DB
    rejected = (window_levels < gate) | (head_levels < gate) | (tail_levels < gate)
    if rejected.all():
        raise fail(source, f"no {unit_ms:g} ms window is clear of near-silence (every one lies "
                           f"more than {SILENCE_DB:g} dB below the loudest frames)")
    typical = float(np.median(window_levels[~rejected]))
    scores = {"level_jump_db": np.abs(head_levels - tail_levels),
              "spectral_db": _flux(_shape(head_db), _shape(tail_db)),
              "stationarity_db": spread,
              "quietness_db": np.maximum(typical - window_levels, 0.0)}
    weights = {**WEIGHTS, **(weights or {})}
    cost = sum(weights[name] * value for name, value in scores.items())
    cost = np.where(rejected, np.inf, cost)
    return Scan(starts=starts, correlation=rho, rejected=rejected, cost=cost, **scores)


def _check_lengths(unit_ms, crossfade_ms, edge_ms, length, fade, edge) -> None:
    if length <= 0:
        raise ParameterError("unit_ms", f"must last at least one sample, got {unit_ms:g}")
    if fade <= 0:
        raise ParameterError("crossfade_ms", f"must last at least one sample, got "
                                             f"{crossfade_ms:g}")
    # The unit's own floor first: a crossfade longer than a unit that is too short anyway is
    # not what the user should change.
    if 3 * edge > length:
        raise ParameterError("unit_ms", f"must be at least {3 * edge_ms:g} ms so head and tail "
                                        f"({edge_ms:g} ms each) can be compared, got {unit_ms:g}")
    if fade >= length:
        raise ParameterError("crossfade_ms", f"must be between 0 and the unit length "
                                             f"({unit_ms:g} ms), got {crossfade_ms:g}")


def _edges(x, rate, starts, length, fade, edge, rho, compensate, floor, progress):
    """Band spectra and levels of each window's head (after the crossfade) and tail."""
    frames = sliding_window_view(x, edge)
    after = sliding_window_view(x, fade) if fade else None
    head_db, head_levels, tail_db = [], [], []
    for block in range(0, len(starts), _CHUNK):
        chosen = starts[block:block + _CHUNK]
        head = frames[chosen].copy()
        if fade:
            fade_in, fade_out = crossfade_gains(fade, rho[block:block + _CHUNK], compensate)
            head[:, :fade] = fade_in * head[:, :fade] + fade_out * after[chosen + length]
        head_levels.append(10 * np.log10(np.maximum(np.mean(head ** 2, axis=1), 1e-30)))
        head_db.append(band_levels_db(head, rate, floor))
        tail_db.append(band_levels_db(frames[chosen + length - edge], rate, floor))
        if progress is not None:
            progress(min(block + _CHUNK, len(starts)), len(starts))
    return np.concatenate(head_db), np.concatenate(head_levels), np.concatenate(tail_db)


# --- the one sound-loop type --------------------------------------------------------------------

@dataclass(frozen=True, repr=False, eq=False)
class SoundLoop:
    """A sound unit that loops without a seam, and how it was made.

    Attributes:
        samples: the loop, shape (frames,), mono, full scale ±1; it loops from its last sample
            straight into its first.
        rate: sample rate in Hz.
        mode: how it was made: ``"loop"`` (a unit cut from a recording by :func:`find_loop`,
            or a ready loop read from a file) or ``"granular"`` (a texture of grains,
            :func:`realpen.sound.granular.granular_loop`).
        start_s: where the material starts in the recording, in s (the unit's window; the
            first steady stretch of a texture; a file's ``smpl`` loop start), if known.
        unit_ms: the unit length asked for in ms (loop mode).
        crossfade_ms: the wrap crossfade in ms (loop mode; None for a ready loop, whose
            crossfade is unknown).
        seam: the finished loop's :class:`Seam` report (None for a loop too short to judge).
        scores, weights, correlation, windows, rejected: the loop-unit search (loop mode): the
            chosen window's scores in dB and ``cost``, the weights of the scores, the
            correlation ρ of the blended segments, windows scanned and near silence.
        part, grain_ms, seed: granular mode: the steady part the grains came from, the grain
            length in ms, the seed of the grain offsets.
        gain: linear gain applied to the recording's samples (1 before :meth:`normalised`).
        source, source_sha256, history: the recording (path, SHA-256, processing steps).

    Example:
        >>> import numpy as np
        >>> loop = SoundLoop.from_samples(np.random.default_rng(0).normal(0, 0.1, 4800), 48000)
        >>> loop.mode, loop.length_ms, round(loop.normalised(-20.0).rms_dbfs, 6)
        ('loop', 100.0, -20.0)
    """

    samples: np.ndarray
    rate: float
    mode: str = "loop"
    start_s: float | None = None
    unit_ms: float | None = None
    crossfade_ms: float | None = None
    seam: Seam | None = None
    scores: dict[str, float] | None = None
    weights: dict[str, float] | None = None
    correlation: float | None = None
    windows: int | None = None
    rejected: int | None = None
    part: SteadyPart | None = None
    grain_ms: float | None = None
    seed: int | None = None
    gain: float = 1.0
    source: str | None = None
    source_sha256: str | None = None
    history: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        samples = np.asarray(self.samples, dtype=np.float64)
        if samples.ndim != 1 or len(samples) == 0:
            raise ParameterError("samples", f"must be a non-empty mono array of shape (frames,), "
                                            f"got shape {samples.shape}")
        if not is_number(self.rate) or not np.isfinite(self.rate) or self.rate <= 0:
            raise ParameterError("rate", f"must be a positive number of Hz, got {self.rate!r}")
        if self.mode not in MODES:
            raise ParameterError("mode", f"unknown value {self.mode!r} (choose from "
                                         f"{', '.join(MODES)})")
        object.__setattr__(self, "samples", samples)
        object.__setattr__(self, "rate", float(self.rate))
        object.__setattr__(self, "history", tuple(self.history))

    @classmethod
    def from_samples(cls, samples: np.ndarray, rate: float, *, start_s: float | None = None,
                     source: str | None = None, source_sha256: str | None = None,
                     history: tuple[str, ...] = ()) -> SoundLoop:
        """A ready loop: ``samples`` (mono, full scale ±1) at ``rate`` Hz, played as they are.

        Its seam is measured when it lasts at least three 20 ms frames (60 ms).

        Args:
            samples: the loop, shape (frames,).
            rate: its rate in Hz.
            start_s: where it starts in its source, in s, if known.
            source, source_sha256, history: where it came from.
        """
        samples = np.asarray(samples, dtype=np.float64)
        seam = None
        if sound_rate_problem(rate) is None and len(samples) >= 3 * samples_for(EDGE_MS, rate):
            seam = seam_report(samples, rate, source=source or "loop")
        return cls(samples=samples, rate=rate, mode="loop", start_s=start_s,
                   unit_ms=len(samples) / float(rate) * 1000, seam=seam, source=source,
                   source_sha256=source_sha256, history=history)

    @property
    def frames(self) -> int:
        """Length in samples."""
        return int(len(self.samples))

    @property
    def duration(self) -> float:
        """Length in s."""
        return len(self.samples) / self.rate

    @property
    def length_ms(self) -> float:
        """Length in ms."""
        return len(self.samples) / self.rate * 1000

    @property
    def rms_dbfs(self) -> float:
        """RMS level in dBFS."""
        return level_db(self.samples)

    @property
    def searched(self) -> bool:
        """Whether the loop was found by the loop-unit search (it has scores)."""
        return self.scores is not None

    def normalised(self, level_dbfs: float = REFERENCE_DBFS) -> SoundLoop:
        """A copy scaled to an RMS of ``level_dbfs`` dBFS (finite, at most 0 dBFS)."""
        scaled, gain = normalise(self.samples, level_dbfs)
        return replace(self, samples=scaled, gain=self.gain * gain)

    def wav_bytes(self) -> bytes:
        """The loop as a 32-bit float WAV whose ``smpl`` chunk declares it one forward loop."""
        return wav_bytes(self.samples, int(round(self.rate)), loop=True)

    def save(self, path: str | os.PathLike) -> None:
        """Write :meth:`wav_bytes` to ``path`` atomically."""
        write_wav(path, self.samples, int(round(self.rate)), loop=True)

    def to_json(self) -> dict:
        """The JSON report of ``realpen sound loop`` (times in s, lengths in ms, levels in dB).

        Both modes give ``mode``, ``source``, ``rate``, ``frames``, ``length_ms``, ``start_s``,
        ``end_s``, ``seam``, ``gain`` and ``rms_dbfs``; loop mode adds the unit, the crossfade
        and the search's scores (None for a ready loop), granular mode the steady stretches,
        the grain length and the seed.
        """
        document = {
            "realpen_version": __version__,
            "mode": self.mode,
            "source": {"path": self.source, "sha256": self.source_sha256,
                       "history": list(self.history)},
            "rate": self.rate,
            "frames": self.frames,
            "length_ms": round(self.length_ms, 3),
        }
        if self.mode == "granular" and self.part is not None:
            stretches = [[round(a / self.rate, 6), round(b / self.rate, 6)]
                         for a, b in self.part.stretches]
            document.update({
                "start_s": stretches[0][0],
                "end_s": stretches[-1][1],
                "steady_stretches_s": stretches,
                "steady_s": round(sum(b - a for a, b in self.part.stretches) / self.rate, 6),
                "grain_ms": self.grain_ms,
                "seed": self.seed,
            })
        else:
            start = None if self.start_s is None else round(self.start_s, 6)
            unit_ms = self.unit_ms if self.unit_ms is not None else self.length_ms
            document.update({
                "start_s": start,
                "end_s": None if start is None else round(self.start_s + unit_ms / 1000, 6),
                "unit_ms": unit_ms,
                "crossfade_ms": self.crossfade_ms,
                "crossfade_correlation": (None if self.correlation is None
                                          else round(self.correlation, 4)),
                "scores": (None if self.scores is None
                           else {key: round(value, 4) for key, value in self.scores.items()}),
                "weights": self.weights,
                "windows_scanned": self.windows,
                "windows_near_silence": self.rejected,
            })
            if self.mode == "granular":  # a texture built elsewhere, without its steady part
                document.update({"grain_ms": self.grain_ms, "seed": self.seed})
        document.update({
            "seam": None if self.seam is None else self.seam.to_json(),
            "gain": self.gain,
            "rms_dbfs": round(self.rms_dbfs, 3),
        })
        return document

    def __repr__(self) -> str:
        where = "" if self.start_s is None else f", start_s={self.start_s:.3f}"
        seam = "" if self.seam is None else f", seam jump {self.seam.level_jump_db:.2f} dB"
        name = Path(self.source).name if self.source else None
        source = "" if name is None else f", source={name[:40]!r}"
        return (f"SoundLoop(mode={self.mode!r}, {self.length_ms:.1f} ms at {self.rate:g} Hz"
                f"{where}, rms {self.rms_dbfs:.1f} dBFS{seam}{source})")






def find_loop_unit(x: np.ndarray, rate: float, unit_ms: float = UNIT_MS,
                   crossfade_ms: float = CROSSFADE_MS, hop_ms: float = HOP_MS,
                   compensate: bool = True, source: object = "signal",
                   recording: Recording | None = None,
                   progress: ProgressCallback | None = None) -> SoundLoop:
    """Find the best loop unit of a mono signal and make its wrap seamless (the search itself;
    :func:`find_loop` is the friendlier entry).

    Args:
        x: the recording, shape (frames,), full scale ±1.
        rate: its rate in Hz.
        unit_ms: loop length in ms (default 300).
        crossfade_ms: crossfade length in ms at the wrap (default 10).
        hop_ms: scan step in ms (default 5).
        compensate: correlation-compensated crossfade (see the module doc).
        source: names the signal in error messages.
        recording: the loaded recording, for provenance in the JSON.
        progress: called as ``progress(done, total)`` while windows are scored.

    Returns:
        The :class:`SoundLoop` (``mode="loop"``; not normalised, see
        :meth:`SoundLoop.normalised`).
    """
    scan = scan_windows(x, rate, unit_ms, crossfade_ms, hop_ms, compensate=compensate,
                        source=source, progress=progress)
    best = int(np.argmin(scan.cost))
    start = int(scan.starts[best])
    loop, rho = make_loop(x, start, samples_for(unit_ms, rate), samples_for(crossfade_ms, rate),
                          compensate)
    names = ("level_jump_db", "spectral_db", "stationarity_db", "quietness_db", "cost")
    scores = {name: float(getattr(scan, name)[best]) for name in names}
    return SoundLoop(samples=loop, rate=float(rate), mode="loop", start_s=start / rate,
                     unit_ms=float(unit_ms), crossfade_ms=float(crossfade_ms), scores=scores,
                     weights=dict(WEIGHTS), correlation=float(rho),
                     seam=seam_report(loop, rate, source=source),
                     windows=int(len(scan.starts)), rejected=int(scan.rejected.sum()),
                     source=recording.source if recording else None,
                     source_sha256=recording.sha256 if recording else None,
                     history=recording.history if recording else ())


def find_loop(sound: Recording | np.ndarray | SoundLoop | str | os.PathLike, *,
              rate: float | None = None, unit_ms: float = UNIT_MS,
              crossfade_ms: float = CROSSFADE_MS, hop_ms: float = HOP_MS,
              compensate: bool = True, level_dbfs: float | None = None,
              source: object | None = None,
              progress: ProgressCallback | None = None) -> SoundLoop:
    """The seamless loop unit of a friction sound; see the module doc for how it is chosen.

    Args:
        sound: a recording (:class:`~realpen.io.recording.Recording`, mixed down when it has
            several channels), an array of samples (frames,) or (frames, channels) with
            ``rate``, or the path of an audio file (read by :func:`load_sound`). A
            :class:`SoundLoop`, or a file that declares its loop in a ``smpl`` chunk, is
            already a loop and comes back as it is.
        rate: the array's rate in Hz; for a recording, resample to this rate first (None keeps
            its own); for a path, the rate to load at (None: 48 kHz). 8 kHz to 384 kHz.
        unit_ms: loop length in ms (default 300).
        crossfade_ms: crossfade at the wrap in ms (default 10), shorter than the unit.
        hop_ms: scan step in ms (default 5).
        compensate: correlation-compensated crossfade (see the module doc).
        level_dbfs: scale the loop to this RMS in dBFS (at most 0); None keeps the recording's
            level.
        source: names the sound in error messages (default: the recording's file).
        progress: called as ``progress(done, total)`` while windows are scored.

    Returns:
        The :class:`SoundLoop` (``mode="loop"``) with its scores and seam.

    Raises:
        ParameterError: a bad rate, length or level.
        RealPenError: a recording that is silent, too short for the unit plus the crossfade,
            or has no window clear of near silence.

    Example:
        >>> import numpy as np
        >>> noise = np.random.default_rng(0).normal(0, 0.1, 48000)
        >>> loop = find_loop(noise, rate=48000)
        >>> loop.frames, loop.seam.level_jump_db < 1
        (14400, True)
    """
    if level_dbfs is not None:
        check_level(level_dbfs)
    if isinstance(sound, (str, os.PathLike)):
        sound = load_sound(sound, DEFAULT_RATE if rate is None else rate)
        rate = None
    if isinstance(sound, SoundLoop):
        return sound if level_dbfs is None else sound.normalised(level_dbfs)
    x, rate, recording, name = mono_signal(sound, rate, source)
    loop = find_loop_unit(x, rate, unit_ms, crossfade_ms, hop_ms, compensate, source=name,
                          recording=recording, progress=progress)
    return loop if level_dbfs is None else loop.normalised(level_dbfs)
