"""The seam for the pen's own hardware: what the server tells the pen, and what drives it.

The server tells the pen's actuator three things, in the order the page sent them:

``pen_down``  a stroke starts with a profile (whose tactile pattern the actuator loops) and
              whether the modality includes touch. A profile with a vibration grid
              (``profile.grid``) is passed whole, but the commands carry no speed or force, so
              a device cannot follow the grid from them: it plays the reference pattern
              (``tactile.wav``);
``gain``      a new target gain (Eq. 1 before smoothing; the device smooths with the profile's
              ``coupling.smoothing_ms`` and scales ``a_max`` to its full drive). Sent only
              while a stroke whose modality includes touch is down;
``pen_up``    the stroke ends: silence.

A :class:`PenDevice` is called on the server's event loop, so each call must return at once
(well under a millisecond): a hardware driver hands the command to its own thread or queue.

Two devices exist:

- :class:`CommandLog` (no pen): it only keeps an ordered, thread-safe log of the commands with
  their arrival times, which tests and ``GET /api/device/log`` read. Nothing is played.
- :class:`realpen.device.bridge.PenBridge` (a real pen over USB serial or Bluetooth, or the
  simulated pen, the real firmware under the MicroPython Unix port): the commands become the pen
  protocol's ``SET_STATE`` frames and pattern uploads on a worker thread; it keeps a
  :class:`CommandLog` too. :func:`open_device` builds one from a device string.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Literal, Protocol

from realpen.errors import ParameterError, RealPenError
from realpen.profile.bundle import PenProfile

__all__ = ["LOG_LIMIT", "DEVICE_KINDS", "Origin", "PenDevice", "DeviceCommand", "CommandLog",
           "parse_device", "open_device", "sim_connector", "device_status"]

LOG_LIMIT = 100_000  # entries kept; older ones are dropped (their indices stay counted)
DEVICE_KINDS = ("sim", "serial", "ble")
DEVICE_FORMS = "sim, serial:PORT or ble:NAME"


@dataclass(frozen=True)
class Origin:
    """Which page message caused a command: the connection, the page's stroke number, seq."""

    session: str
    stroke: int
    seq: int | None = None


class PenDevice(Protocol):
    """What the server drives. Implementations must not block (see the module doc).

    A device may also have ``status() -> dict`` (``GET /api/device``) and the log's
    ``entries(since, limit)`` and ``count`` (``GET /api/device/log``).
    """

    name: str

    def pen_down(self, origin: Origin, profile: PenProfile, tactile: bool) -> None:
        """A stroke starts with ``profile``'s pattern; ``tactile``: the modality includes touch."""

    def gain(self, origin: Origin, value: float) -> None:
        """A new target gain (Eq. 1 before smoothing, 0 … ``a_max``, linear)."""

    def pen_up(self, origin: Origin) -> None:
        """The stroke ends: silence."""

    def close(self) -> None:
        """The server stops: release the hardware."""


@dataclass(frozen=True)
class DeviceCommand:
    """One command as the device received it.

    Attributes:
        index: position in the device's log (0, 1, 2, … over the device's life).
        kind: ``pen_down``, ``gain`` or ``pen_up``.
        at_ns: ``time.monotonic_ns()`` on arrival (comparable across processes on one machine).
        session, stroke, seq: the :class:`Origin`.
        value: the target gain of a ``gain`` command.
        detail: for ``pen_down``: pen, profile version, tactile, a_max, smoothing_ms.
    """

    index: int
    kind: Literal["pen_down", "gain", "pen_up"]
    at_ns: int
    session: str
    stroke: int
    seq: int | None
    value: float | None = None
    detail: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """Every field, JSON-ready (``GET /api/device/log``)."""
        return asdict(self)


class CommandLog:
    """The device when there is no pen: an ordered, thread-safe record of every command.

    Nothing is played. A :class:`~realpen.device.bridge.PenBridge` keeps one as well, so the
    log reads the same whatever drives the pen.
    """

    name = "log"
    kind = "log"

    def __init__(self, limit: int = LOG_LIMIT):
        self._lock = threading.Lock()
        self._log: deque[DeviceCommand] = deque(maxlen=limit)
        self._count = 0
        self.closed = False

    def _record(self, kind: str, origin: Origin, value: float | None = None,
                detail: dict | None = None) -> None:
        now = time.monotonic_ns()
        with self._lock:
            self._log.append(DeviceCommand(self._count, kind, now, origin.session, origin.stroke,
                                           origin.seq, value, detail or {}))
            self._count += 1

    def pen_down(self, origin: Origin, profile: PenProfile, tactile: bool) -> None:
        """Log ``pen_down`` with the pen, its profile version, ``a_max`` and the smoothing."""
        coupling = profile.meta.coupling
        self._record("pen_down", origin, detail={
            "pen": profile.name, "profile_version": profile.version, "tactile": tactile,
            "a_max": coupling.a_max, "smoothing_ms": coupling.smoothing_ms})

    def gain(self, origin: Origin, value: float) -> None:
        """Log a target gain (linear)."""
        self._record("gain", origin, value=float(value))

    def pen_up(self, origin: Origin) -> None:
        """Log ``pen_up``."""
        self._record("pen_up", origin)

    def close(self) -> None:
        """Mark the log closed."""
        self.closed = True

    def status(self) -> dict:
        """``GET /api/device``: no pen is driven; the commands are only logged."""
        return {"name": self.name, "kind": self.kind, "connected": False,
                "message": "no pen device: the commands are only logged (GET /api/device/log)",
                "info": None}

    @property
    def count(self) -> int:
        """Commands received so far (including any dropped from the front of the log)."""
        with self._lock:
            return self._count

    def entries(self, since: int = 0, limit: int | None = None) -> list[DeviceCommand]:
        """Logged commands with ``index >= since``, oldest first (at most ``limit``)."""
        with self._lock:
            first = self._count - len(self._log)
            start = max(since - first, 0)
            stop = len(self._log) if limit is None else min(len(self._log), start + limit)
            return list(itertools.islice(self._log, start, stop))  # deque[i] is O(n) each


def parse_device(spec: str) -> tuple[str, str]:
    """Split a device string into (kind, target).

    ``"sim"`` → ``("sim", "")``; ``"serial:/dev/ttyACM0"`` → ``("serial", "/dev/ttyACM0")``;
    ``"ble:RealPen"`` → ``("ble", "RealPen")`` (a name or an address).

    Raises:
        ParameterError: (``device``) any other form, or an empty port or name.
    """
    kind, colon, target = str(spec).partition(":")
    if kind == "sim" and not colon:
        return "sim", ""
    if kind in ("serial", "ble") and colon and target.strip():
        return kind, target.strip()
    if kind in ("serial", "ble"):
        what = "port" if kind == "serial" else "name or address"
        raise ParameterError("device", f"{spec!r} names no {what} (expected {DEVICE_FORMS})")
    raise ParameterError("device", f"unknown device {spec!r} (expected {DEVICE_FORMS})")


def open_device(spec: str | None, *, trace=None, record=None) -> PenDevice:
    """The device a server drives, from a device string (see :func:`parse_device`).

    ``None`` gives a :class:`CommandLog`. ``"sim"`` starts the simulated pen
    (:class:`realpen.device.sim.SimPen`, the firmware under the MicroPython Unix port on a
    pseudo-terminal), ``"serial:PORT"`` and ``"ble:NAME"`` connect to a real pen; each gives a
    :class:`~realpen.device.bridge.PenBridge`, which connects on its own thread and keeps
    trying: a pen that is not there yet is not an error (this returns at once, after starting
    the simulated pen's firmware for ``"sim"``, which is started again if it exits:
    :func:`sim_connector`).

    Args:
        spec: the device string, or None.
        trace, record: for ``"sim"`` only: the firmware's JSON-lines trace and the WAV of
            what it played (written when the device closes).

    Raises:
        ParameterError: (``device``) a malformed string.
        RealPenError: the simulated pen cannot start (the MicroPython Unix port is missing).
    """
    if spec is None:
        return CommandLog()
    kind, target = parse_device(spec)
    from realpen.device.bridge import PenBridge, port_connector

    if kind != "sim":
        return PenBridge(port_connector(spec if kind == "ble" else target), name=spec,
                         kind=kind, log=CommandLog())
    from realpen.device.sim import SimPen

    sim = SimPen(trace=trace, record=record).start()
    try:
        bridge = PenBridge(sim_connector(sim, port_connector(lambda: sim.port)), name="sim",
                           kind="sim", log=CommandLog(), on_close=[sim.stop])
    except BaseException:
        sim.stop()
        raise
    bridge.sim = sim  # so a test (or a caller) can reboot the simulated pen
    return bridge


def sim_connector(sim, connect: Callable[[], object]) -> Callable[[], object]:
    """A ``connect`` for the simulated pen that brings its firmware back when it died.

    A real pen that crashes reboots by itself; the simulated one's process just exits, and its
    pseudo-terminal vanishes with it. So an attempt that finds the firmware dead restarts it
    (:meth:`realpen.device.sim.SimPen.restart`) and fails once with a line that says so (the
    bridge shows it and tries again, within its shortest wait); otherwise it is ``connect()``.

    Args:
        sim: a started :class:`realpen.device.sim.SimPen`.
        connect: what opens a client on the simulated pen's current port.
    """

    def connect_sim():
        if not sim.alive:
            code = sim.returncode
            sim.restart()  # a RealPenError (it did not boot) becomes the status, tried again
            raise RealPenError(f"the simulated pen's firmware exited (code {code}); restarted")
        return connect()

    return connect_sim


def device_status(device: PenDevice) -> dict:
    """``GET /api/device`` for any device: its own ``status()``, or what can be said without."""
    status = getattr(device, "status", None)
    if status is not None:
        return status()
    return {"name": device.name, "kind": "custom", "connected": None,
            "message": f"the {device.name} device reports no status", "info": None}
