"""Preprocessing of vibration recordings: DFT321, polyphase resampling, zero-phase high-pass.

The method's chain is axes → one signal (DFT321) → optional resampling → 30 Hz high-pass;
:func:`prepare` runs it and refuses a result that is silence.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ, require_choice, require_number
from realpen.errors import ParameterError, fail
from realpen.io.limits import MAX_FRAMES
from realpen.io.recording import AXIS_CHOICES, Recording

__all__ = ["dft321", "combine_axes", "resample", "highpass", "prepare", "SILENCE_DB"]


def dft321(samples: np.ndarray) -> np.ndarray:
    """Combine axes into one signal by DFT321 (Landin et al., 2010).

    Per frequency bin the result has magnitude √Σ|U_i|² and the phase of ΣU_i, so the summed
    spectral energy of the axes is kept exactly.

    Args:
        samples: shape (frames, axes).

    Returns:
        shape (frames,), same unit as the input.
    """
    from scipy import fft as sp_fft  # scipy is slow to import; loaded where it is used

    axes = np.ascontiguousarray(np.asarray(samples, dtype=np.float64).T)
    frames = axes.shape[1]
    spectra = sp_fft.rfft(axes, axis=1)
    magnitude = np.sqrt(np.sum(spectra.real ** 2 + spectra.imag ** 2, axis=0))
    summed = spectra.sum(axis=0)
    summed_magnitude = np.abs(summed)
    # Where the axes cancel exactly the phase is undefined; take zero phase there.
    direction = np.divide(summed, summed_magnitude, out=np.ones_like(summed),
                          where=summed_magnitude > 0)
    return sp_fft.irfft(magnitude * direction, n=frames)


def combine_axes(recording: Recording, axis: str | None = None) -> Recording:
    """Reduce a recording to one axis.

    Args:
        axis: ``"dft321"`` (default for more than one axis), ``"magnitude"`` (Euclidean norm
            per frame, mean removed), or an axis name; ``"x"``, ``"y"``, ``"z"`` also pick the
            first, second and third column when no column has that name.
    """
    count = recording.samples.shape[1]
    if axis is None:
        axis = "dft321" if count > 1 else recording.axes[0]
    if axis == "dft321":
        combined = dft321(recording.samples) if count > 1 else recording.samples[:, 0]
    elif axis == "magnitude":
        combined = np.linalg.norm(recording.samples, axis=1)
        combined = combined - combined.mean()
    elif axis in recording.axes:
        combined = recording.samples[:, recording.axes.index(axis)]
    elif axis in ("x", "y", "z") and "xyz".index(axis) < count:
        # Columns named otherwise (ax, acc_y, ...) are taken in order: x first, then y, z.
        combined = recording.samples[:, "xyz".index(axis)]
    else:
        raise fail(recording.source, f"no axis '{axis}' (axes: {', '.join(recording.axes)}; "
                                     f"or dft321, magnitude)")
    return recording.with_samples(combined[:, None], f"axis:{axis}", axes=(axis,))


def resample(recording: Recording, rate: float, *, parameter: str = "rate") -> Recording:
    """Resample to ``rate`` Hz with a polyphase filter (scipy.signal.resample_poly).

    The ratio is approximated to a fraction with a denominator ≤ 1000; the exact rate reached is
    the returned recording's ``rate``.

    Args:
        recording: any number of axes, at ``recording.rate`` Hz.
        rate: the new rate in Hz, from :data:`~realpen.checks.MIN_RATE_HZ` to
            :data:`~realpen.checks.MAX_RATE_HZ`.
        parameter: the name the caller gave ``rate`` (e.g. ``"analysis_rate"``), for messages.

    Raises:
        ParameterError: ``rate`` out of range, too low a fraction of the recording's rate, or
            one that would make more than :data:`~realpen.io.limits.MAX_FRAMES` samples
            (checked before resampling).
    """
    require_number(parameter, rate, minimum=0.0, inclusive=False)  # "> 0" for 0 and below
    require_number(parameter, rate, minimum=MIN_RATE_HZ, maximum=MAX_RATE_HZ)
    if abs(rate - recording.rate) < 1e-9:
        return recording
    ratio = Fraction(rate / recording.rate).limit_denominator(1000)
    if ratio.numerator == 0:
        raise ParameterError(parameter, f"{rate:g} Hz is too low to resample "
                                        f"{recording.rate:g} Hz to")
    frames, axes = recording.samples.shape
    made = -(-frames * ratio.numerator // ratio.denominator) * axes
    if made > MAX_FRAMES:
        raise ParameterError(parameter, f"{rate:g} Hz would make {made:,} samples of "
                                        f"{recording.source}; at most {MAX_FRAMES:,} are "
                                        f"allowed (a lower rate or a shorter recording)")
    from scipy import signal  # scipy.signal alone costs more than a second to import

    out = signal.resample_poly(recording.samples, ratio.numerator, ratio.denominator, axis=0)
    actual = recording.rate * ratio.numerator / ratio.denominator
    return recording.with_samples(out, f"resample:{actual:g}Hz", rate=actual)


def highpass(recording: Recording, cutoff_hz: float = 30.0, order: int = 4) -> Recording:
    """Zero-phase Butterworth high-pass (forward-backward, so the effective order is doubled).

    Args:
        recording: samples at ``recording.rate`` Hz.
        cutoff_hz: -3 dB point of one pass in Hz (0: no filter).
        order: Butterworth order of one pass.

    Raises:
        ParameterError: ``cutoff_hz`` is negative, not a number, or at or above the Nyquist
            frequency of the recording (the message names the recording and its rate).
    """
    require_number("cutoff_hz", cutoff_hz, minimum=0.0)
    nyquist = recording.rate / 2
    if cutoff_hz == 0:
        return recording
    if cutoff_hz >= nyquist:
        # The cutoff is what the user chose; the recording's rate is a fact.
        raise ParameterError("cutoff_hz", f"a {cutoff_hz:g} Hz high-pass needs a rate above "
                                          f"{2 * cutoff_hz:g} Hz; {recording.source} is at "
                                          f"{recording.rate:g} Hz here (after any resampling), "
                                          f"so its rate is too low (Nyquist {nyquist:g} Hz)")
    from scipy import signal

    sos = signal.butter(order, cutoff_hz, btype="highpass", fs=recording.rate, output="sos")
    padlen = min(3 * (2 * len(sos) + 1), recording.samples.shape[0] - 1)
    filtered = signal.sosfiltfilt(sos, recording.samples, axis=0, padlen=max(padlen, 0))
    return recording.with_samples(filtered, f"highpass:{cutoff_hz:g}Hz")


def prepare(recording: Recording, axis: str | None = None, analysis_rate: float | None = None,
            highpass_hz: float = 30.0) -> Recording:
    """The method's preprocessing: axes to one, optional resampling, zero-phase high-pass.

    Args:
        recording: one to three (or more) axes at ``recording.rate`` Hz.
        axis: see :func:`combine_axes` (None: DFT321 for several axes).
        analysis_rate: rate in Hz to resample to (None: keep the recording's rate).
        highpass_hz: high-pass cutoff in Hz (0: none).

    Returns:
        A one-axis recording at the analysis rate.

    Raises:
        ParameterError: an unknown ``axis``, a bad ``analysis_rate`` or ``highpass_hz``.
        RealPenError: the result is silence.
    """
    if axis is not None and axis not in recording.axes:
        require_choice("axis", axis, AXIS_CHOICES)
    require_number("highpass_hz", highpass_hz, minimum=0.0)  # before the slow steps
    one = combine_axes(recording, axis)
    if analysis_rate is not None:
        one = resample(one, analysis_rate, parameter="analysis_rate")
    filtered = highpass(one, highpass_hz)
    _check_not_silent(recording, filtered)
    return filtered


SILENCE_DB = -80.0  # vibration this far below the input's peak (offset included) is no signal


def _check_not_silent(raw: Recording, filtered: Recording) -> None:
    """Refuse input whose filtered part is silence: zeros, a constant, or quantisation noise.

    Judged relative to the input's own peak, so an accelerometer's gravity offset does not
    hide a silent pen, and ±1 LSB of noise on a constant is not mistaken for vibration.
    """
    peak = float(np.max(np.abs(raw.samples)))
    level = float(np.sqrt(np.mean(filtered.samples ** 2)))
    if peak == 0 or level <= peak * 10 ** (SILENCE_DB / 20):
        raise fail(raw.source, "signal is silent or constant (no vibration above "
                               f"{SILENCE_DB:g} dB of its peak after the high-pass)")
