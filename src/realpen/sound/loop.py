"""Friction sound: loading, the seamless loop unit, and the seam report.

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

Limits, checked wherever a value is taken (one-line :class:`~realpen.errors.RealPenError`):
rates from ``MIN_RATE`` (8 kHz: the bands need room between 100 Hz and 0.45 × rate) to
``MAX_RATE`` (384 kHz); lengths in ms finite and positive; a loop level (RMS, dBFS) finite and
at most 0 dBFS; a recording whose level with its mean removed lies below ``SILENT_DBFS`` —
digital silence, or a constant (DC) value — is refused as silent.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from realpen import __version__
from realpen.errors import RealPenError, fail
from realpen.io.recording import Recording, load_recording
from realpen.dsp.filters import resample

DEFAULT_RATE = 48000
UNIT_MS = 300.0
CROSSFADE_MS = 10.0
EDGE_MS = 20.0          # head/tail length for level and spectrum
HOP_MS = 5.0            # scan step; the issue asks for ≤ 5 ms
SILENCE_DB = 30.0       # below the recording's loud frames: near silence
SILENT_DBFS = -90.0     # a whole recording quieter than this is silence (16-bit LSB ≈ −96 dBFS)
REFERENCE_DBFS = -20.0  # RMS of a normalised loop: the level that coupling gain 1 plays at
MAX_LEVEL_DBFS = 0.0    # highest loop level (RMS) accepted
MIN_RATE = 8000.0       # Hz; below it the 100 Hz–0.45·rate bands of the seam measures collapse
MAX_RATE = 384000.0     # Hz; the highest common audio rate
FLOOR_DB = 80.0         # band levels further below the loud frames are treated as equal
BANDS = (24, 100.0, 16000.0)
WEIGHTS = {"level_jump_db": 3.0, "spectral_db": 1.0, "stationarity_db": 1.0,
           "quietness_db": 1.0}
NOT_AUDIO = (".csv", ".npz", ".json", ".txt")
_CHUNK = 2048  # frames per FFT block, to bound memory on long recordings

ProgressCallback = Callable[[int, int], None]  # (windows done, windows in all)


def samples_for(ms: float, rate: float) -> int:
    """Number of samples in ``ms`` milliseconds at ``rate`` Hz (rounded)."""
    return int(round(ms * rate / 1000.0))


def check_ms(name: str, value: float) -> float:
    """Return ``value`` (a length in ms) as float; :class:`RealPenError` unless finite and > 0.

    Args:
        name: the option that gave it, e.g. ``"--unit-ms"``, for the message.
        value: the length in ms.
    """
    if not np.isfinite(value) or value <= 0:
        raise RealPenError(f"{name} must be a finite number of ms above 0, got {value:g}")
    return float(value)


def check_rate(rate: float, name: object = "--rate") -> float:
    """Return a sample rate in Hz as float, between ``MIN_RATE`` and ``MAX_RATE`` Hz.

    Args:
        rate: sample rate in Hz.
        name: the option or the file that gave it, for the message.

    Raises:
        RealPenError: a rate that is not finite, or outside 8 kHz – 384 kHz.
    """
    if not np.isfinite(rate) or rate <= 0:
        raise RealPenError(f"{name} must be a positive number of Hz, got {rate:g}")
    if rate < MIN_RATE:
        raise RealPenError(f"{name}: {rate:g} Hz is too low for friction sound; the minimum is "
                           f"{MIN_RATE:g} Hz (the seam is judged on bands from 100 Hz up to "
                           f"0.45 × rate)")
    if rate > MAX_RATE:
        raise RealPenError(f"{name}: {rate:g} Hz is too high; the maximum is {MAX_RATE:g} Hz")
    return float(rate)


def check_level(level_dbfs: float, name: str = "--level-dbfs") -> float:
    """Return a loop level (RMS in dB re full scale) as float; finite and ≤ ``MAX_LEVEL_DBFS``.

    Args:
        level_dbfs: RMS level in dBFS.
        name: the option that gave it, for the message.
    """
    if not np.isfinite(level_dbfs) or level_dbfs > MAX_LEVEL_DBFS:
        raise RealPenError(f"{name} must be a finite level of at most {MAX_LEVEL_DBFS:g} dBFS, "
                           f"got {level_dbfs:g}")
    return float(level_dbfs)


def level_db(x: np.ndarray) -> float:
    """RMS level of ``x`` (full scale ±1) in dB re full scale, i.e. dBFS (−inf for silence)."""
    power = float(np.mean(np.square(x))) if len(x) else 0.0
    return 10 * np.log10(power) if power > 0 else -np.inf


def require_sound(x: np.ndarray, source: object) -> None:
    """Raise :class:`RealPenError` when ``x`` is silent: its RMS with its mean removed lies below
    ``SILENT_DBFS`` dBFS.

    The mean is removed so that a constant (DC) signal, which holds no sound however large its
    value, counts as silence too.
    """
    x = np.asarray(x, dtype=np.float64)
    level = level_db(x - np.mean(x)) if len(x) else -np.inf
    if level < SILENT_DBFS:
        if len(x) and np.ptp(x) == 0 and x[0] != 0:
            shown = f"a constant value of {x[0]:g}: a DC offset, no sound"
        elif not np.any(x):
            shown = "digital silence"
        else:
            shown = f"RMS {level:.0f} dBFS with the DC offset removed"
        raise fail(source, f"recording is silent ({shown})")


def load_sound(path: str | os.PathLike, rate: float | None = DEFAULT_RATE) -> Recording:
    """Load a friction-sound recording: WAV/FLAC/OGG at any rate, mixed down to mono.

    Args:
        path: the audio file.
        rate: resample to this rate in Hz (default 48 kHz); None keeps the file's rate. Either
            must lie between ``MIN_RATE`` (8 kHz) and ``MAX_RATE`` (384 kHz).

    Returns:
        A one-axis :class:`~realpen.recording.Recording` (axis ``"mono"``, full scale ±1).

    Raises:
        RealPenError: missing, empty, truncated or non-audio files, NaN/inf, a rate out of
            range, silence or a constant (DC) signal.
    """
    path = Path(path)
    if rate is not None:
        check_rate(rate)
    if path.suffix.lower() in NOT_AUDIO:
        raise fail(path, "not an audio file (give a WAV, FLAC or OGG recording)")
    loaded = load_recording(path)
    channels = loaded.samples.shape[1]
    mono = loaded.samples.mean(axis=1)
    step = f"mixdown:{channels}ch" if channels > 1 else "mono"
    # Judged before resampling too: the filter's edge transients would give a constant (DC)
    # recording an AC part of its own.
    require_sound(mono, path)
    sound = loaded.with_samples(mono[:, None], step, axes=("mono",))
    if rate is None:
        check_rate(sound.rate, path)
    else:
        sound = resample(sound, float(rate))
    require_sound(sound.mono, path)
    return sound


def normalise(x: np.ndarray, rms_dbfs: float = REFERENCE_DBFS) -> tuple[np.ndarray, float]:
    """Scale ``x`` to an RMS of ``rms_dbfs`` dB re full scale; returns (scaled, linear gain).

    Raises:
        RealPenError: ``rms_dbfs`` not finite or above ``MAX_LEVEL_DBFS`` (0 dBFS).
    """
    check_level(rms_dbfs)
    level = level_db(x)
    if not np.isfinite(level):
        return np.array(x, dtype=np.float64), 1.0
    gain = 10 ** ((rms_dbfs - level) / 20)
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


def seam_report(loop: np.ndarray, rate: float, edge_ms: float = EDGE_MS,
                hop_ms: float = HOP_MS, source: object = "loop") -> Seam:
    """Measure the wrap of a loop: level jump and spectral flux against the loop's own flux.

    Args:
        loop: the looping signal, shape (frames,), full scale ±1.
        rate: its rate in Hz (``MIN_RATE`` to ``MAX_RATE``).
        edge_ms: frame length in ms for levels and spectra.
        hop_ms: step in ms between the inside frame pairs.
        source: names the loop in error messages.

    Returns:
        The :class:`Seam` (figures in dB, the percentile in percent).

    Raises:
        RealPenError: a rate out of range, bad lengths, or a loop shorter than three frames.
    """
    loop = np.asarray(loop, dtype=np.float64)
    check_rate(rate)
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


@dataclass(frozen=True)
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


def scan_windows(x: np.ndarray, rate: float, unit_ms: float = UNIT_MS,
                 crossfade_ms: float = CROSSFADE_MS, hop_ms: float = HOP_MS,
                 edge_ms: float = EDGE_MS, compensate: bool = True,
                 weights: dict[str, float] | None = None, source: object = "signal",
                 progress: ProgressCallback | None = None) -> Scan:
    """Score every window of ``unit_ms`` (every ``hop_ms``) as a loop unit; see the module doc.

    Args:
        x: the recording, shape (frames,), full scale ±1.
        rate: its rate in Hz (``MIN_RATE`` to ``MAX_RATE``).
        unit_ms, crossfade_ms, hop_ms, edge_ms: unit, wrap crossfade, scan step and head/tail
            frame lengths in ms, each finite and positive.
        compensate: correlation-compensated crossfade (see the module doc).
        weights: overrides entries of ``WEIGHTS`` (dimensionless factors on dB scores).
        source: names the signal in error messages.
        progress: called as ``progress(done, total)`` (windows) after each block of windows
            (about a second of work per 130 s of recording at 48 kHz).

    Raises:
        RealPenError: a rate out of range, bad lengths, a signal shorter than unit + crossfade,
            silence, or no window clear of near-silence.
    """
    x = np.asarray(x, dtype=np.float64)
    check_rate(rate)
    for name, value in (("--unit-ms", unit_ms), ("--crossfade-ms", crossfade_ms),
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
        raise RealPenError(f"--unit-ms must be positive, got {unit_ms:g}")
    if fade <= 0:
        raise RealPenError(f"--crossfade-ms must last at least one sample, got {crossfade_ms:g}")
    if fade >= length:
        raise RealPenError(f"--crossfade-ms must be between 0 and the unit length "
                           f"({unit_ms:g} ms), got {crossfade_ms:g}")
    if 3 * edge > length:
        raise RealPenError(f"--unit-ms must be at least {3 * edge_ms:g} ms so head and tail "
                           f"({edge_ms:g} ms each) can be compared, got {unit_ms:g}")


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


@dataclass(frozen=True)
class LoopUnit:
    """A seamless loop unit cut from a recording.

    Attributes:
        samples: the loop, shape (frames,); loops without a seam.
        rate: rate in Hz.
        start_s: where the window starts in the recording, in seconds.
        unit_ms, crossfade_ms: lengths used.
        scores: the chosen window's scores (dB) and ``cost``.
        weights: weights of the scores in the cost.
        correlation: correlation ρ of the two segments blended by the crossfade.
        seam: the finished loop's seam report.
        windows: how many windows were scanned; rejected: how many were near silence.
        gain: linear gain applied to the recording's samples (1 before :meth:`normalised`).
        source, source_sha256: the recording.
    """

    samples: np.ndarray
    rate: float
    start_s: float
    unit_ms: float
    crossfade_ms: float
    scores: dict[str, float]
    weights: dict[str, float]
    correlation: float
    seam: Seam
    windows: int
    rejected: int
    gain: float = 1.0
    source: str | None = None
    source_sha256: str | None = None
    history: tuple[str, ...] = field(default_factory=tuple)

    def normalised(self, rms_dbfs: float = REFERENCE_DBFS) -> "LoopUnit":
        """A copy scaled to an RMS of ``rms_dbfs`` dBFS (finite, at most 0 dBFS)."""
        scaled, gain = normalise(self.samples, rms_dbfs)
        return replace(self, samples=scaled, gain=self.gain * gain)

    def to_json(self) -> dict:
        """The ``realpen sound loop --json`` document."""
        return {
            "realpen_version": __version__,
            "mode": "loop",
            "source": {"path": self.source, "sha256": self.source_sha256,
                       "history": list(self.history)},
            "rate": self.rate,
            "frames": int(len(self.samples)),
            "start_s": round(self.start_s, 6),
            "end_s": round(self.start_s + self.unit_ms / 1000, 6),
            "unit_ms": self.unit_ms,
            "crossfade_ms": self.crossfade_ms,
            "crossfade_correlation": round(self.correlation, 4),
            "scores": {key: round(value, 4) for key, value in self.scores.items()},
            "weights": self.weights,
            "windows_scanned": self.windows,
            "windows_near_silence": self.rejected,
            "seam": self.seam.to_json(),
            "gain": self.gain,
            "rms_dbfs": round(level_db(self.samples), 3),
        }


def find_loop_unit(x: np.ndarray, rate: float, unit_ms: float = UNIT_MS,
                   crossfade_ms: float = CROSSFADE_MS, hop_ms: float = HOP_MS,
                   compensate: bool = True, source: object = "signal",
                   recording: Recording | None = None,
                   progress: ProgressCallback | None = None) -> LoopUnit:
    """Find the best loop unit of a mono signal and make its wrap seamless.

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
        The :class:`LoopUnit` (not normalised; see :meth:`LoopUnit.normalised`).

    Example:
        >>> unit = find_loop_unit(load_sound("rough_paper.wav").mono, 48000)
        >>> unit.seam.level_jump_db < 1
        True
    """
    scan = scan_windows(x, rate, unit_ms, crossfade_ms, hop_ms, compensate=compensate,
                        source=source, progress=progress)
    best = int(np.argmin(scan.cost))
    start = int(scan.starts[best])
    loop, rho = make_loop(x, start, samples_for(unit_ms, rate), samples_for(crossfade_ms, rate),
                          compensate)
    names = ("level_jump_db", "spectral_db", "stationarity_db", "quietness_db", "cost")
    scores = {name: float(getattr(scan, name)[best]) for name in names}
    return LoopUnit(samples=loop, rate=float(rate), start_s=start / rate, unit_ms=float(unit_ms),
                    crossfade_ms=float(crossfade_ms), scores=scores, weights=dict(WEIGHTS),
                    correlation=float(rho), seam=seam_report(loop, rate, source=source),
                    windows=int(len(scan.starts)), rejected=int(scan.rejected.sum()),
                    source=recording.source if recording else None,
                    source_sha256=recording.sha256 if recording else None,
                    history=recording.history if recording else ())
