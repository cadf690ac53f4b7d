"""The pen itself: its protocol, the host's links to it, and a simulated pen.

- :mod:`~realpen.device.protocol` — the frames and messages, byte by byte (``docs/protocol.md``);
  pure Python that also runs on the pen under MicroPython (it imports nothing of RealPen).
- :mod:`~realpen.device.transport` — byte pipes to a pen: a serial port (USB CDC, a
  pseudo-terminal) through pyserial, or Bluetooth LE through bleak (``ble:NAME``).
- :mod:`~realpen.device.client` — :class:`~realpen.device.client.PenClient`: HELLO, pattern
  upload, SET_STATE, PING, the pen's events and its accelerometer's SAMPLES blocks over a
  transport, with one-line errors (:class:`~realpen.device.transport.DeviceError`).
- :mod:`~realpen.device.capture` — accelerometer captures: the blocks placed on the sensor's
  grid in m/s², its true rate from the pen's clock, gaps, clipping, a live level
  (:class:`~realpen.device.capture.CaptureAssembler`), :func:`~realpen.device.capture.record`
  and :func:`~realpen.device.capture.write_capture` (WAV, NPZ, CSV).
- :mod:`~realpen.device.pattern` — a profile's tactile pattern as the int16 samples a pen plays.
- :mod:`~realpen.device.sim` — :class:`~realpen.device.sim.SimPen`: the real firmware under the
  MicroPython Unix port on a pseudo-terminal.

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.profile`, :mod:`realpen.exports` (resampling a loop),
:mod:`realpen.display` and every layer below them; never :mod:`realpen.pens`, its sibling.
pyserial and bleak only inside the functions that open a link. This ``__init__`` imports
nothing, so the protocol module loads alone.
"""

from __future__ import annotations

from realpen._lazy import lazy_attributes

__all__ = ["DeviceError", "DeviceDisconnected", "Transport", "SerialTransport", "BleTransport",
           "open_transport", "PenClient", "PenInfo", "PenEvent", "SampleBlock", "pen_pattern",
           "check_fits", "Capture", "CaptureAssembler", "record", "write_capture",
           "measure_actuator", "verify_actuator"]

_HOMES = {
    "DeviceError": "transport", "DeviceDisconnected": "transport", "Transport": "transport",
    "SerialTransport": "transport", "BleTransport": "transport", "open_transport": "transport",
    "PenClient": "client", "PenInfo": "client", "PenEvent": "client", "SampleBlock": "client",
    "Capture": "capture", "CaptureAssembler": "capture", "record": "capture",
    "write_capture": "capture",
    "measure_actuator": "measure_actuator", "verify_actuator": "measure_actuator",
    "pen_pattern": "pattern", "check_fits": "pattern",
}

__getattr__, __dir__ = lazy_attributes(__name__, _HOMES, __all__)
