"""What every export returns, and the pieces the formats share: option checks, the sound
loop's samples, loop-preserving resampling."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ
from realpen.errors import ParameterError, fail
from realpen.tactile.pattern import TactilePattern

__all__ = ["Export", "MAX_REPEATS", "MAX_EXPORT_S", "MAX_EXPORT_FRAMES", "check_repeats",
           "check_span", "check_frames", "check_pattern", "sound_samples", "resample_loop",
           "title", "residual_limits", "RESIDUAL_IN_ENVELOPE", "RESIDUAL_NOT_CARRIED"]

MAX_REPEATS = 100  # 150 s of a 1.5 s pattern; players loop, files need not
MAX_EXPORT_S = 600.0
"""The longest stretch of time one export holds (s): ``repeats`` periods of the pattern (of the
stereo WAV's common length). Ten minutes; the method's pattern is 1.5 s and players loop. The
envelope formats hold a point every 10 ms of it, :mod:`~realpen.exports.hjif` an effect per
component and sub-pattern."""
MAX_EXPORT_FRAMES = 2**25
"""The most frames a sample-based export (WAV, C header) holds: 33 554 432 (87 s at 384 kHz,
11.6 min at 48 kHz; 128 MiB as float32 mono)."""


@dataclass
class Export:
    """One rendered export, not yet written.

    Attributes:
        data: the bytes of the main file.
        summary: one line saying what is in it.
        companions: further files to write beside the main one, by file name (e.g. the sound
            an AHAP refers to).
        limits: what the format could not carry, one sentence each.
    """

    data: bytes
    summary: str
    companions: dict[str, bytes] = field(default_factory=dict)
    limits: tuple[str, ...] = ()

    def __repr__(self) -> str:
        extra = f", companions {sorted(self.companions)}" if self.companions else ""
        return f"Export({len(self.data)} bytes{extra}: {self.summary[:120]})"


RESIDUAL_IN_ENVELOPE = ("the residual noise ({bands} bands, {low:g}–{high:.0f} Hz) is felt only "
                        "through the envelope: intensity and sharpness are measured from the "
                        "samples, sines and noise together; the noise itself is not carried")
RESIDUAL_NOT_CARRIED = ("the residual noise ({bands} bands, {low:g}–{high:.0f} Hz, {share:.0f} % "
                        "of the pattern's power) is not carried: the file holds the sines only "
                        "(the WAV and C-header exports carry the whole pattern)")


def residual_limits(pattern: TactilePattern, template: str) -> tuple[str, ...]:
    """The limit a format states about the pattern's residual noise (see
    :mod:`realpen.tactile.residual`): ``template`` (:data:`RESIDUAL_IN_ENVELOPE` or
    :data:`RESIDUAL_NOT_CARRIED`) filled in, or nothing when the pattern has no residual.
    Formats built from the samples (WAV, C header) carry it and say nothing."""
    residual = pattern.residual
    if residual is None:
        return ()
    noise = float(residual.powers.sum())
    sines = sum(c.amplitude ** 2 / 2 for c in pattern.components)
    share = 100 * noise / (noise + sines) if noise + sines > 0 else 0.0
    return (template.format(bands=residual.bands, low=residual.band_edges_hz[0],
                            high=residual.band_edges_hz[-1], share=share),)


def title(name: str, tool: str = "") -> str:
    """``"name (tool)"``, or the name alone when there is no tool."""
    return f"{name} ({tool})" if tool else name


def check_pattern(pattern: object) -> TactilePattern:
    """``pattern`` if it is a :class:`~realpen.tactile.pattern.TactilePattern`.

    Raises:
        ParameterError: (parameter ``pattern``) otherwise.
    """
    if not isinstance(pattern, TactilePattern):
        raise ParameterError("pattern", f"must be a TactilePattern (or a PenProfile for "
                                        f"realpen.exports.render), got {type(pattern).__name__}")
    return pattern


def check_repeats(repeats: int) -> int:
    """``repeats`` as an int in 1 … :data:`MAX_REPEATS`.

    Raises:
        ParameterError: (parameter ``repeats``) otherwise.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, (int, float, np.integer)) \
            or int(repeats) != repeats or not 1 <= repeats <= MAX_REPEATS:
        raise ParameterError("repeats", f"must be a whole number from 1 to {MAX_REPEATS}, "
                                        f"got {repeats}")
    return int(repeats)


def check_span(pattern: TactilePattern, repeats: int, name: str = "pattern") -> int:
    """``repeats`` checked (:func:`check_repeats`), and ``repeats`` periods of ``pattern``
    checked against :data:`MAX_EXPORT_S`, before anything is measured or rendered.

    Raises:
        ParameterError: (parameter ``repeats``) a bad count, or too many periods.
        RealPenError: one period alone is longer than :data:`MAX_EXPORT_S` (naming ``name``).
    """
    repeats = check_repeats(repeats)
    period = check_pattern(pattern).duration_s
    if period > MAX_EXPORT_S:
        raise fail(name, f"the tactile pattern lasts {period:g} s; an export holds at most "
                         f"{MAX_EXPORT_S:g} s")
    if period * repeats > MAX_EXPORT_S:
        raise ParameterError("repeats", f"{repeats} periods of {period:g} s last "
                                        f"{period * repeats:g} s; an export holds at most "
                                        f"{MAX_EXPORT_S:g} s")
    return repeats


def check_frames(period_frames: int, repeats: int, rate: int) -> None:
    """Refuse a sample-based export of ``repeats`` × ``period_frames`` frames at ``rate`` Hz
    that holds more than :data:`MAX_EXPORT_FRAMES` frames or lasts more than
    :data:`MAX_EXPORT_S`, before it is tiled.

    Raises:
        ParameterError: naming ``repeats`` when more than one period is asked for, else
            ``rate``.
    """
    frames = period_frames * repeats
    if frames > MAX_EXPORT_FRAMES or frames / rate > MAX_EXPORT_S:
        raise ParameterError("repeats" if repeats > 1 else "rate",
                             f"{repeats} × {period_frames:,} frames at {rate} Hz make "
                             f"{frames:,} frames ({frames / rate:g} s); an export holds at "
                             f"most {MAX_EXPORT_FRAMES:,} frames and {MAX_EXPORT_S:g} s")


def sound_samples(sound: object, needed_for: str) -> tuple[np.ndarray, int]:
    """The samples (float64, mono) and rate (Hz) of a sound loop.

    Args:
        sound: a :class:`realpen.sound.loop.SoundLoop` or any object with ``samples`` (one
            loop, full scale ±1) and ``rate`` (Hz); ``is_loop``, when present, must be true.
        needed_for: what needs the sound, for the message when it is missing.

    Raises:
        ParameterError: (parameter ``sound``) no sound, not a loop, or not mono samples.
    """
    if sound is None:
        raise ParameterError("sound", f"{needed_for} needs the sound: give a sound loop "
                                      f"(sound=..., an object with samples and rate)")
    if not (hasattr(sound, "samples") and hasattr(sound, "rate")):
        raise ParameterError("sound", f"must have samples and rate (a SoundLoop), got "
                                      f"{type(sound).__name__}")
    if getattr(sound, "is_loop", True) is False:
        raise ParameterError("sound", "is not a loop (make one with realpen.sound.loop first)")
    samples = np.asarray(sound.samples, dtype=np.float64)
    if samples.ndim == 2 and samples.shape[1] == 1:
        samples = samples[:, 0]
    if samples.ndim != 1 or not len(samples):
        raise ParameterError("sound", f"must be mono samples, got shape {samples.shape}")
    rate = float(sound.rate)
    if rate <= 0 or int(rate) != rate:
        raise ParameterError("sound", f"rate must be a positive whole number of Hz, got {rate:g}")
    return samples, int(rate)


def resample_loop(x: np.ndarray, rate: int, new_rate: int, what: str = "pattern") -> np.ndarray:
    """Resample one period of a looping signal (polyphase), keeping it a seamless loop.

    The period is resampled with a copy of itself on either side, so the anti-aliasing filter
    sees the wrap as it sounds, and the middle copy is kept.

    Args:
        x: one period, shape (frames,) or (frames, channels).
        rate, new_rate: sampling rates in Hz.
        what: how to name the signal in an error.

    Raises:
        ParameterError: (parameter ``rate``) ``new_rate`` is not a whole number of Hz from
            :data:`~realpen.checks.MIN_RATE_HZ` to
            :data:`~realpen.checks.MAX_RATE_HZ`, the period would exceed
            :data:`MAX_EXPORT_FRAMES` at it, or the period is not a whole number of samples at
            ``new_rate`` (the loop would drift by a fraction of a sample each time).
    """
    from scipy.signal import resample_poly

    if isinstance(new_rate, bool) or not isinstance(new_rate, (int, float, np.integer)) \
            or not np.isfinite(new_rate) or int(new_rate) != new_rate \
            or not MIN_RATE_HZ <= new_rate <= MAX_RATE_HZ:
        raise ParameterError("rate", f"must be a whole number of Hz from {MIN_RATE_HZ:g} to "
                                     f"{MAX_RATE_HZ:g}, got {new_rate}")
    new_rate = int(new_rate)
    if new_rate == rate:
        return np.asarray(x)
    x = np.asarray(x, dtype=np.float64)
    frames = len(x) * new_rate / rate
    if frames > MAX_EXPORT_FRAMES:
        raise ParameterError("rate", f"the {what} ({len(x) / rate:g} s) would be "
                                     f"{frames:,.0f} samples at {new_rate} Hz; an export holds "
                                     f"at most {MAX_EXPORT_FRAMES:,}")
    if abs(frames - round(frames)) > 1e-9:
        raise ParameterError("rate", f"the {what} ({len(x)} samples at {rate} Hz) is not a whole "
                                     f"number of samples at {new_rate} Hz; choose a rate that "
                                     f"makes {len(x) / rate * 1000:g} ms a whole number of "
                                     f"samples")
    gcd = np.gcd(int(rate), new_rate)
    tripled = np.concatenate([x, x, x])
    out = resample_poly(tripled, new_rate // gcd, int(rate) // gcd, axis=0)
    count = int(round(frames))
    return out[count:2 * count]
