"""What every sound unit is made of: mono samples at a checked rate, heard above silence.

The loop search (:mod:`realpen.sound.loop`), the granular texture
(:mod:`realpen.sound.granular`) and the stroke render (:mod:`realpen.sound.stroke`) all take a
sound the same way — a recording mixed down to mono and resampled, or an array with its rate —
and refuse silence the same way; that shared ground lives here, together with
:class:`SteadyPart`, the record of where a granular texture's grains came from (which a
:class:`~realpen.sound.loop.SoundLoop` keeps). The range checks themselves (rates, lengths,
levels) are :mod:`realpen.checks`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from realpen.checks import check_sound_rate, sound_rate_problem
from realpen.dsp.filters import resample
from realpen.errors import ParameterError, fail
from realpen.io.recording import Recording

__all__ = ["SILENT_DBFS", "SteadyPart", "samples_for", "level_db", "require_sound",
           "check_source_rate", "mono_signal", "loop_rate"]

SILENT_DBFS = -90.0
"""A whole recording quieter than this (RMS with its mean removed, dBFS) is silence (a 16-bit
LSB is about −96 dBFS)."""


@dataclass(frozen=True, repr=False, eq=False)
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

    def __repr__(self) -> str:
        return (f"SteadyPart({len(self.starts)} grain starts in {len(self.stretches)} "
                f"stretch(es), span {self.span} samples, rms {self.rms:.4g})")


class _HasRate(Protocol):
    rate: float


def samples_for(ms: float, rate: float) -> int:
    """Number of samples in ``ms`` milliseconds at ``rate`` Hz (rounded).

    >>> samples_for(300, 48000)
    14400
    """
    return int(round(ms * rate / 1000.0))


def level_db(x: np.ndarray) -> float:
    """RMS level of ``x`` (full scale ±1) in dB re full scale, i.e. dBFS (−inf for silence)."""
    power = float(np.mean(np.square(x))) if len(x) else 0.0
    return float(10 * np.log10(power)) if power > 0 else float("-inf")


def require_sound(x: np.ndarray, source: object) -> None:
    """Raise :class:`~realpen.errors.RealPenError` when ``x`` is silent: its RMS with its mean
    removed lies below :data:`SILENT_DBFS` dBFS.

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


def check_source_rate(rate: float, source: object) -> float:
    """Like :func:`realpen.checks.check_sound_rate` for a rate (Hz) that a file or a recording
    carries: a data problem, so a :class:`~realpen.errors.RealPenError` naming ``source``."""
    problem = sound_rate_problem(rate)
    if problem is not None:
        raise fail(source, problem if not problem.startswith("must") else f"rate {problem}")
    return float(rate)


def mono_signal(sound: Recording | np.ndarray, rate: float | None, source: object | None
                ) -> tuple[np.ndarray, float, Recording | None, object]:
    """A recording or an array as mono samples at a checked rate.

    A recording is mixed down and, when ``rate`` differs from its own, resampled; an array of
    shape (frames,) or (frames, channels) is averaged over its channels and needs ``rate``.

    Args:
        sound: a :class:`~realpen.io.recording.Recording` or an array of samples.
        rate: the array's rate in Hz, or the rate to resample a recording to (None: its own).
        source: names the sound in messages (default: the recording's file, or ``"signal"``).

    Returns:
        (mono samples, rate in Hz, the recording if any, the source's name).

    Raises:
        ParameterError: a bad rate, an array of another shape, or an array without ``rate``.
        RealPenError: a recording whose own rate is out of range.
    """
    if isinstance(sound, Recording):
        recording = sound
        channels = recording.samples.shape[1]
        if channels > 1:
            recording = recording.with_samples(recording.samples.mean(axis=1)[:, None],
                                               f"mixdown:{channels}ch", axes=("mono",))
        if rate is not None:
            check_sound_rate(rate)
            recording = resample(recording, float(rate))
        name = recording.source if source is None else source
        check_source_rate(recording.rate, name)
        return recording.mono, float(recording.rate), recording, name
    x = np.asarray(sound, dtype=np.float64)
    if x.ndim == 2:
        x = x.mean(axis=1)
    if x.ndim != 1:
        raise ParameterError("sound", f"must be samples of shape (frames,) or (frames, "
                                      f"channels), got shape {x.shape}")
    if rate is None:
        raise ParameterError("rate", "needed in Hz for an array of samples")
    return x, check_sound_rate(rate), None, "signal" if source is None else source


def loop_rate(loop: _HasRate, rate: float | None) -> float:
    """The rate (Hz) of a sound loop, which plays at its own rate: ``rate``, if given, must be
    it.

    Raises:
        ParameterError: (parameter ``rate``) another rate, or a loop whose rate is out of range.
    """
    if rate is not None and abs(float(rate) - loop.rate) > 1e-9:
        raise ParameterError("rate", f"a sound loop plays at its own rate ({loop.rate:g} Hz), "
                                     f"got {rate:g}")
    return check_sound_rate(loop.rate)
