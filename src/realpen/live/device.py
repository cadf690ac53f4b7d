"""The seam for the pen's own hardware, and the built-in simulated device.

The server tells the pen's actuator three things, in the order the page sent them:

``pen_down``  a stroke starts with a profile (whose tactile pattern the actuator loops) and
              whether the modality includes touch. A profile with a vibration grid
              (``profile.grid``) is passed whole, but the commands carry no speed or force, so
              a device cannot follow the grid from them: it plays the reference pattern
              (``tactile.wav``). :class:`SimulatedDevice` logs the pen and ignores the grid;
``gain``      a new target gain (Eq. 1 before smoothing; the device smooths with the profile's
              ``coupling.smoothing_ms`` and scales ``a_max`` to its full drive). Sent only
              while a stroke whose modality includes touch is down;
``pen_up``    the stroke ends: silence.

A :class:`PenDevice` is called on the server's event loop, so each call must return at once
(well under a millisecond): a hardware driver hands the command to its own thread or queue.
:class:`SimulatedDevice` is the built-in one: it keeps an ordered, thread-safe log of the
commands with their arrival times, which tests and ``GET /api/device/log`` read.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from typing import Literal, Protocol

from realpen.profile.bundle import PenProfile

__all__ = ["LOG_LIMIT", "Origin", "PenDevice", "DeviceCommand", "SimulatedDevice"]

LOG_LIMIT = 100_000  # entries kept; older ones are dropped (their indices stay counted)


@dataclass(frozen=True)
class Origin:
    """Which page message caused a command: the connection, the page's stroke number, seq."""

    session: str
    stroke: int
    seq: int | None = None


class PenDevice(Protocol):
    """What the server drives. Implementations must not block (see the module doc)."""

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
    """One command as the simulated device received it.

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


class SimulatedDevice:
    """A device that only logs: an ordered, thread-safe record of every command."""

    name = "simulated"

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
        """Mark the device closed."""
        self.closed = True

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
