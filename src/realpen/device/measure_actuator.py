"""Measure the pen's actuator with the pen's own accelerometer, and check the equalisation.

:func:`measure_actuator` uploads a looped exponential sine sweep
(:func:`realpen.tactile.measure.sweep_pattern`), plays it while the accelerometer records
(:func:`realpen.device.capture.record`), and analyses the capture
(:func:`realpen.tactile.measure.analyse_sweep`, :func:`~realpen.tactile.measure.fit_resonance`).
:func:`verify_actuator` plays a multisine equalised by a measured response
(:func:`realpen.tactile.multisine.equalised_multisine`) and says how flat it arrives
(:func:`~realpen.tactile.multisine.flatness`). Both take an open
:class:`~realpen.device.client.PenClient`; the pen is left silent, holding the test pattern
(upload a profile's pattern again to write with it).

Example (a simulated pen whose actuator is hidden from the host)::

    from realpen.device.sim import SimPen
    from realpen.device.transport import open_transport

    with SimPen(actuator="lra:f0=160,q=6") as pen, \\
            PenClient(open_transport(pen.port)) as client:
        measured = measure_actuator(client, repeats=3)
        print(measured.fit.f0_hz, measured.fit.q)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from realpen.checks import require_number
from realpen.device import protocol as p
from realpen.device.capture import Capture, record
from realpen.device.client import PenClient, PenInfo
from realpen.device.transport import DeviceError
from realpen.errors import ParameterError
from realpen.tactile.actuator import Actuator, as_actuator
from realpen.tactile.measure import (
    ResonanceFit,
    Response,
    Sweep,
    analyse_sweep,
    fit_resonance,
    sweep_pattern,
)
from realpen.tactile.multisine import (
    VERIFY_BAND_HZ,
    Flatness,
    Multisine,
    equalised_multisine,
    flatness,
)

__all__ = ["ActuatorMeasurement", "ActuatorCheck", "measure_actuator", "verify_actuator",
           "DEFAULT_GAIN", "DEFAULT_REPEATS", "MAX_REPEATS", "WEAK_SNR_DB"]

DEFAULT_GAIN = 0.8  # of the capped full drive: well above the sensor noise at 500 Hz, short of 2 g
DEFAULT_REPEATS = 4
MAX_REPEATS = 100
WEAK_SNR_DB = 20.0  # below this the measurement is noisy enough to say so
_TRUSTED_RATE = 2e-5  # a rate known to this (relative standard error) is not refined
_MARGIN_S = 0.2  # captured beyond the loops analysed: the resampler's context at either end

Progress = Callable[[float, float], None]
"""Called as ``progress(seconds_captured, seconds_wanted)`` while the capture runs."""


@dataclass(frozen=True, eq=False)
class ActuatorMeasurement:
    """What :func:`measure_actuator` found.

    Attributes:
        response: the measured response (:class:`~realpen.tactile.measure.Response`).
        fit: the resonance fitted to it (:class:`~realpen.tactile.measure.ResonanceFit`).
        capture: the accelerometer capture it came from.
        pen: the pen's name.
        gain: the drive it was measured at, 0 … 1.
        notes: what the user should know (clipping, gaps, a weak response).
    """

    response: Response
    fit: ResonanceFit
    capture: Capture
    pen: str
    gain: float
    notes: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class ActuatorCheck:
    """What :func:`verify_actuator` found.

    Attributes:
        flatness: how flat the multisine arrived (:class:`~realpen.tactile.multisine.Flatness`).
        multisine: what the pen played.
        capture: the accelerometer capture.
        pen: the pen's name.
        notes: what the user should know.
    """

    flatness: Flatness
    multisine: Multisine
    capture: Capture
    pen: str
    notes: tuple[str, ...] = ()


def _check_options(repeats: int, periods_to_skip: int, gain: float) -> None:
    for name, value, least in (("repeats", repeats, 2), ("periods_to_skip", periods_to_skip, 0)):
        require_number(name, value, minimum=least, maximum=MAX_REPEATS)
        if int(value) != value:
            raise ParameterError(name, f"must be a whole number, got {value}")
    require_number("gain", gain, minimum=0.0, maximum=1.0, inclusive=False)


def _pen_with_sensor(client: PenClient) -> PenInfo:
    info = client.info or client.hello()
    if not info.features & p.FEATURE_ACCEL:
        pen = f"the pen {info.name!r}" if info.name else "the pen"
        raise DeviceError(f"{client.name}: {pen} has no accelerometer, so it cannot measure "
                          f"its actuator (a LIS3DH beside the actuator is needed; see "
                          f"docs/recording.md)")
    return info


def _play_and_capture(client: PenClient, pattern: np.ndarray, rate: int, seconds: float, *,
                      gain: float, range_g: int, progress: Progress | None) -> Capture:
    """Upload ``pattern``, loop it at ``gain`` and capture ``seconds`` of the accelerometer
    meanwhile; the pen is silent again afterwards, whatever happened."""
    client.set_state(False, 0.0)  # a pattern playing now would swap only at its next wrap
    client.upload(pattern, rate)
    on_block = None if progress is None else \
        (lambda block, assembler: progress(min(assembler.duration_s, seconds), seconds))
    try:
        # Playing before capturing: the loops skipped at the start cover the actuator settling.
        client.set_state(True, gain)
        capture = record(client, seconds, range_g=range_g, on_block=on_block)
    except BaseException:
        try:
            client.set_state(False, 0.0)
        except DeviceError:
            pass  # the failure that brought us here is the one to report
        raise
    client.set_state(False, 0.0)
    client.sync()  # the pen has the stop, and refused nothing meanwhile
    if capture.interrupted:
        raise KeyboardInterrupt
    return capture


def _capture_notes(capture: Capture, gain: float) -> list[str]:
    notes = list(capture.notes)
    if capture.gaps:
        notes.append(f"{capture.samples_lost} samples were lost in {len(capture.gaps)} gap(s) "
                     f"(overruns, blocks dropped); the other loops stood in for them")
    if any(capture.clipped):
        notes.append(f"{sum(capture.clipped)} samples reached the ±{capture.range_g} g limit: "
                     f"the response is distorted there; measure with a lower gain (now "
                     f"{gain:g}) or a larger range")
    return notes


def measure_actuator(client: PenClient, *, repeats: int = DEFAULT_REPEATS,
                     periods_to_skip: int = 1, gain: float = DEFAULT_GAIN, range_g: int = 2,
                     sweep: Sweep | None = None, progress: Progress | None = None
                     ) -> ActuatorMeasurement:
    """Measure the pen's actuator through its own accelerometer.

    Uploads a looped sweep (15–600 Hz, as long as the pen holds up to 2 s), plays it at
    ``gain``, captures ``periods_to_skip + repeats`` loops at 1344 Hz, stops, analyses the
    ``repeats`` loops after the skipped ones and fits a resonance to the response.

    Args:
        client: a client of the pen (it says HELLO first when it has not yet).
        repeats: loops analysed, 2 … 100.
        periods_to_skip: loops dropped at the start (the actuator settling).
        gain: drive, 0 … 1 of the pen's capped full drive.
        range_g: the accelerometer's range: 2, 4, 8 or 16 g.
        sweep: the sweep to play (default :func:`~realpen.tactile.measure.sweep_pattern` at
            the pen's rate and size).
        progress: called as ``progress(seconds_captured, seconds_wanted)``.

    Returns:
        The :class:`ActuatorMeasurement`.

    Raises:
        ParameterError: an option out of range.
        DeviceError: the pen has no accelerometer, refused the pattern or the capture, or the
            link failed.
        RealPenError: the capture was too short to analyse (samples lost).
        KeyboardInterrupt: interrupted (the pen is silent again).
    """
    _check_options(repeats, periods_to_skip, gain)
    info = _pen_with_sensor(client)
    if sweep is None:
        sweep = sweep_pattern(info.sample_rate, max_samples=info.max_pattern_bytes // 2)
    seconds = (periods_to_skip + repeats) * sweep.period_s + _MARGIN_S
    capture = _play_and_capture(client, sweep.to_int16(), sweep.rate_hz, seconds, gain=gain,
                                range_g=range_g, progress=progress)
    # The sweep and the timestamps run on the pen's one crystal: a rate the timestamps give
    # to a few ppm is the loops' true rate, and loops drifting against it mean the playback
    # slipped. Only a rate they could not pin down is refined from the sweep.
    trusted = capture.rate_sd_hz / capture.rate_hz < _TRUSTED_RATE  # False for NaN
    response = analyse_sweep(capture.samples, capture.rate_hz, sweep,
                             periods_to_skip=periods_to_skip, periods=repeats,
                             refine_rate=not trusted)
    fit = fit_resonance(response.frequency_hz, response.magnitude, weights=response.coherence)
    notes = _capture_notes(capture, gain)
    if not trusted:
        notes.append(f"the pen's timestamps gave the accelerometer's rate only to "
                     f"±{capture.rate_sd_hz:g} Hz; the sweep's loops gave "
                     f"{response.capture_rate_hz:.3f} Hz")
    if response.periods_slipped:
        notes.append(f"{response.periods_slipped} loop(s) were left out: the pen's playback "
                     f"slipped while it played them (underruns; 'realpen device monitor' "
                     f"counts them)")
    if response.slip_ms * response.capture_rate_hz / 1000 >= 1:  # a sample or more
        notes.append(f"the pen's playback slipped by up to {response.slip_ms:.1f} ms between "
                     f"loops (underruns); the loops were aligned again")
    if response.snr_db < WEAK_SNR_DB:
        notes.append(f"the response stands only {response.snr_db:.0f} dB above the noise: "
                     f"raise the gain or the repeats")
    return ActuatorMeasurement(response, fit, capture, info.name, float(gain), tuple(notes))


def verify_actuator(client: PenClient, actuator: Actuator | str, *,
                    repeats: int = DEFAULT_REPEATS, periods_to_skip: int = 1,
                    gain: float = DEFAULT_GAIN, range_g: int = 2,
                    band_hz: tuple[float, float] = VERIFY_BAND_HZ, cap_db: float = 30.0,
                    progress: Progress | None = None) -> ActuatorCheck:
    """Play a multisine equalised by ``actuator`` and measure how flat it arrives.

    Args:
        client: a client of the pen.
        actuator: the measured response (``load_measured``, a CSV path or any actuator spec).
        repeats: loops analysed (1 s each), 2 … 100.
        periods_to_skip: loops dropped at the start.
        gain: drive, 0 … 1.
        range_g: the accelerometer's range in g.
        band_hz: (low, high) of the multisine, Hz.
        cap_db: the largest boost of the equalisation, dB.
        progress: called as ``progress(seconds_captured, seconds_wanted)``.

    Returns:
        The :class:`ActuatorCheck`.

    Raises:
        ParameterError: an option out of range.
        DeviceError: as :func:`measure_actuator`.
        RealPenError: a malformed actuator CSV (naming it), or too few loops captured.
        KeyboardInterrupt: interrupted (the pen is silent again).
    """
    _check_options(repeats, periods_to_skip, gain)
    actuator = as_actuator(actuator)
    info = _pen_with_sensor(client)
    multisine = equalised_multisine(actuator, info.sample_rate, band_hz=band_hz, cap_db=cap_db,
                                    max_samples=info.max_pattern_bytes // 2)
    seconds = (periods_to_skip + repeats) * multisine.period_s + _MARGIN_S
    capture = _play_and_capture(client, multisine.to_int16(), multisine.rate_hz, seconds,
                                gain=gain, range_g=range_g, progress=progress)
    result = flatness(capture.samples, capture.rate_hz, multisine,
                      periods_to_skip=periods_to_skip, periods=repeats)
    notes = _capture_notes(capture, gain)
    if multisine.clipped.any():
        notes.append(f"{int(multisine.clipped.sum())} of {len(multisine.clipped)} components "
                     f"needed more than the {cap_db:g} dB cap: they arrive weaker")
    return ActuatorCheck(result, multisine, capture, info.name, tuple(notes))
