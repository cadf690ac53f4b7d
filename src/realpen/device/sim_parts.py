"""What the simulated pen's sensor feels and how its actuator moves: prepared on the host.

The simulated pen (:class:`realpen.device.sim.SimPen`) runs the firmware under the MicroPython
Unix port against a register-level LIS3DH model (``firmware/pico/sim_lis3dh.py``). The model
reads what the pen feels while writing from a file made here (:func:`write_sensor_source`:
a recording put on the sensor's true sample grid, in g, with sensor noise added), and moves the
sensor with the pen's physical actuator, a biquad at the player's rate whose coefficients come
from :func:`actuator_biquad`. The firmware and any host see neither: they must measure them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from realpen.errors import RealPenError

__all__ = ["STANDARD_GRAVITY", "actuator_biquad", "biquad_response", "write_sensor_source",
           "SENSOR_RATE_HZ"]

STANDARD_GRAVITY = 9.80665  # m/s² per g
SENSOR_RATE_HZ = 1344  # the LIS3DH's nominal rate that the firmware asks for
_NOISE_LOOP_S = 7.31  # a noise-only source's loop: not a multiple of any pattern's length


def actuator_biquad(spec: str, rate_hz: int) -> tuple[float, float, float, float, float]:
    """Coefficients ``(b0, b1, b2, a1, a2)`` (a0 = 1) of the simulated actuator at the player's
    rate.

    ``lra:f0=…,q=…`` is the band-pass whose analogue response is the LRA model of
    :mod:`realpen.tactile.actuator`, 1/√(1 + Q²(f/f0 − f0/f)²), made digital by the bilinear
    transform prewarped at f0 (peak exactly 1 at f0); ``piezo:…`` the high-pass likewise;
    ``flat`` passes samples unchanged. A measured response (a CSV) cannot drive the simulator.

    Raises:
        RealPenError: a spec that is not a model.
    """
    from realpen.tactile.actuator import parse_actuator

    actuator = parse_actuator(spec)
    if actuator.kind == "flat":
        return (1.0, 0.0, 0.0, 0.0, 0.0)
    if actuator.kind not in ("lra", "piezo"):
        raise RealPenError(f"{spec}: the simulated pen's actuator must be a model (lra:f0=…,q=…, "
                           "piezo:f0=…,q=… or flat), not a measured response")
    f0 = float(actuator.params["f0"])
    q = float(actuator.params["q"])
    if not 0 < f0 < rate_hz / 2:
        raise RealPenError(f"{spec}: f0 must lie below half the pen's rate ({rate_hz / 2:g} Hz)")
    w0 = 2 * math.pi * f0 / rate_hz
    alpha = math.sin(w0) / (2 * q)
    cos_w0 = math.cos(w0)
    a0 = 1 + alpha
    if actuator.kind == "lra":  # RBJ band-pass, 0 dB peak
        b = (alpha, 0.0, -alpha)
    else:  # RBJ high-pass
        b = ((1 + cos_w0) / 2, -(1 + cos_w0), (1 + cos_w0) / 2)
    return (b[0] / a0, b[1] / a0, b[2] / a0, -2 * cos_w0 / a0, (1 - alpha) / a0)


def biquad_response(coefficients, frequency_hz, rate_hz: float) -> np.ndarray:
    """|H(f)| of a biquad ``(b0, b1, b2, a1, a2)`` at ``frequency_hz`` (Hz) for ``rate_hz``."""
    b0, b1, b2, a1, a2 = coefficients
    z = np.exp(-2j * np.pi * np.asarray(frequency_hz, dtype=float) / rate_hz)
    return np.abs((b0 + b1 * z + b2 * z * z) / (1 + a1 * z + a2 * z * z))


def write_sensor_source(path: Path, recording_path: Path | None, true_rate_hz: float, *,
                        noise_g: float = 0.005, seed: int = 0) -> int:
    """Write what the simulated sensor feels: float32 x, y, z in g at ``true_rate_hz``, looped.

    ``recording_path``: a 1–3 axis recording (any format :func:`realpen.load_recording`
    reads; m/s² are turned into g, other units taken as g): one axis drives x, two drive x and
    y. It is resampled over its whole length (FFT), so a recording that loops seamlessly still
    does. None: noise only (a pen held still). ``noise_g``: sensor noise, RMS per axis.

    Returns:
        the source's length in samples.
    Raises:
        RealPenError: the recording cannot be read, has more than 3 axes, or is shorter than
            0.1 s.
    """
    from realpen.io.recording import load_recording

    rng = np.random.default_rng(seed)
    if recording_path is None:
        frames = round(_NOISE_LOOP_S * true_rate_hz)
        samples = np.zeros((frames, 3))
    else:
        from scipy.signal import resample

        recording = load_recording(recording_path)
        data = np.asarray(recording.samples, dtype=float)
        if data.ndim == 1:
            data = data[:, None]
        if data.shape[1] > 3:
            raise RealPenError(f"{recording_path}: {data.shape[1]} axes; the simulated sensor "
                               "takes a recording of 1 to 3 axes")
        if recording.duration < 0.1:
            raise RealPenError(f"{recording_path}: {recording.duration:.3f} s; the simulated "
                               "sensor needs at least 0.1 s to loop")
        if recording.units in ("m/s^2", "m/s²"):
            data = data / STANDARD_GRAVITY
        frames = max(2, round(data.shape[0] * true_rate_hz / recording.rate))
        data = resample(data, frames, axis=0)
        samples = np.zeros((frames, 3))
        samples[:, :data.shape[1]] = data
    samples += noise_g * rng.standard_normal(samples.shape)
    Path(path).write_bytes(samples.astype("<f4").tobytes())
    return frames
