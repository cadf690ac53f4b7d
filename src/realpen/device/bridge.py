"""The live app's pen: the page's pen-down, gain and pen-up as the pen protocol, on a thread.

:class:`PenBridge` is the :class:`realpen.live.device.PenDevice` that drives a real pen (USB
serial or Bluetooth) or the simulated one. The server calls it on its event loop, so every call
only queues the command and returns (microseconds); a worker thread talks to the pen:

- ``pen_down(origin, profile, tactile)``: the profile's pattern, rendered at the pen's rate
  (:func:`realpen.device.pattern.pen_pattern`), is uploaded unless the pen holds the same samples
  already (compared by content: length and CRC-32), then ``SET_STATE(playing=1, gain=0,
  fade=smoothing_ms)`` when the modality includes touch;
- ``gain(origin, value)``: ``SET_STATE(playing=1, gain=value / a_max)``. Gains waiting behind
  each other are coalesced, the latest wins (``SET_STATE`` carries the whole state, so nothing
  is lost): a slow link never builds a backlog;
- ``pen_up(origin)``: ``SET_STATE(playing=0, gain=0)``;
- ``capture(sink)``: the pen's accelerometer captured on the worker thread, every SAMPLES block
  and capture event handed to ``sink``, the commands above still applied between blocks, until
  the returned :class:`CaptureRun` is stopped (the live app's "Record a pen" page).

Commands keep their order. When the pen goes away (a write fails, the port hangs up, the
``PING`` sent after :data:`HEARTBEAT_S` idle gets no answer, or the pen reports a boot), the
bridge says so in :meth:`PenBridge.status` and keeps trying, the wait doubling from 50 ms up
to :data:`RETRY_MAX_S`; on reconnecting it says ``HELLO`` again, uploads the current pattern
again (a rebooted pen has lost it) and resends the current state, so a stroke that was down
when the pen went away is felt again. Nothing the pen or the link does raises into the server:
problems become the status message (the history keeps its changes, not every failed attempt).
The page's own sound never depends on the pen.

The connection is made by a ``connect`` callable (:func:`port_connector` for a port), so the
bridge can be tested with a fake client.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import threading
import time
import zlib
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable

import numpy as np

from realpen.device.protocol import EV_BOOT

__all__ = ["PenBridge", "CaptureRun", "port_connector", "RETRY_MIN_S", "RETRY_MAX_S", "HEARTBEAT_S",
           "LINK_CHECK_S", "CLOSE_WAIT_S", "gain_fraction", "fade_ms"]

log = logging.getLogger(__name__)

RETRY_MIN_S = 0.05  # first wait before reconnecting; doubles each failure
RETRY_MAX_S = 1.0  # the longest wait between attempts: a pen back is found within a second
# An idle link is PINGed this often, so a vanished pen is noticed unasked (within this plus the
# reply timeout). Not faster: each PING wakes a battery pen's radio over Bluetooth.
HEARTBEAT_S = 1.0
LINK_CHECK_S = 0.25  # an idle bridge looks this often whether its client saw the link go (no I/O)
CLOSE_WAIT_S = 3.0  # how long close() waits for the worker to silence the pen and stop
HISTORY = 20  # status changes kept for GET /api/device
PATTERN_CACHE = 8  # rendered patterns kept (by profile version and rate)
FADE_MIN_MS, FADE_MAX_MS = 5, 65535  # SET_STATE fade_ms is a u16; the firmware ramps >= 5 ms
CAPTURE_READ_S = 0.05  # a capture's read wait: how soon a stop or a page's command is handled


def gain_fraction(value: float, a_max: float) -> float:
    """The page's gain target (0 … ``a_max``, linear) as the pen's drive fraction 0 … 1."""
    if not a_max > 0 or not np.isfinite(value):
        return 0.0
    return float(min(max(value / a_max, 0.0), 1.0))


def fade_ms(smoothing_ms: float) -> int:
    """The profile's gain smoothing (ms) as SET_STATE's ``fade_ms`` (whole ms, 5 … 65535)."""
    if not np.isfinite(smoothing_ms):
        return FADE_MIN_MS
    return int(min(max(round(smoothing_ms), FADE_MIN_MS), FADE_MAX_MS))


def port_connector(port: str | Callable[[], str], **transport_options) -> Callable[[], object]:
    """A ``connect`` for :class:`PenBridge`: opens ``port`` and returns a
    :class:`realpen.device.client.PenClient` on it.

    Args:
        port: a serial device, ``ble:NAME``, or a callable giving one at each attempt (the
            simulated pen's pseudo-terminal changes when it restarts).
        transport_options: passed to :func:`realpen.device.transport.open_transport`.
    """

    def connect():
        from realpen.device.client import PenClient
        from realpen.device.transport import open_transport

        transport = open_transport(port() if callable(port) else port, **transport_options)
        try:
            return PenClient(transport)
        except BaseException:
            transport.close()
            raise

    return connect


@functools.cache
def _disconnect_errors() -> tuple[type[BaseException], ...]:
    """Errors that mean the link is gone (reconnect), as opposed to the pen refusing something."""
    errors: list[type[BaseException]] = [OSError, TimeoutError, EOFError]
    try:
        from realpen.device.transport import DeviceDisconnected
        errors.insert(0, DeviceDisconnected)
    except ImportError:  # the host side is not installed: only the built-in ones
        pass
    return tuple(errors)


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return text or type(error).__name__


def _info_json(info) -> dict | None:
    if info is None:
        return None
    if dataclasses.is_dataclass(info):
        return dataclasses.asdict(info)
    if isinstance(info, dict):
        return dict(info)
    return {key: value for key, value in vars(info).items() if not key.startswith("_")}


def _info_field(info, name: str, default=None):
    if isinstance(info, dict):
        return info.get(name, default)
    return getattr(info, name, default)


class CaptureRun:
    """An accelerometer capture the bridge runs for a caller (:meth:`PenBridge.capture`).

    Attributes:
        sink: called with each :class:`~realpen.device.client.SampleBlock`, on the bridge's
            thread; it must return quickly.
        range_g, rate_hz: what the capture asked the sensor for (g, Hz).
        error: why the capture could not start or ended early (one line), else None.
        info: the pen's INFO when the capture started (for the capture's provenance).
        host_dropped: blocks the host's client dropped, unread, during the capture.
    """

    def __init__(self, sink: Callable[[object], object], range_g: int, rate_hz: int):
        self.sink, self.range_g, self.rate_hz = sink, int(range_g), int(rate_hz)
        self.error: str | None = None
        self.info = None
        self.host_dropped = 0
        self.started = threading.Event()  # the pen acknowledged CAPTURE_START
        self._stop = threading.Event()
        self._done = threading.Event()

    @property
    def stopping(self) -> bool:
        """Whether :meth:`stop` was asked."""
        return self._stop.is_set()

    @property
    def done(self) -> bool:
        """Whether the capture is over (stopped, refused or failed)."""
        return self._done.is_set()

    def finish(self, error: str | None = None) -> None:
        """The capture is over (``error``: why, if it did not end as asked)."""
        if error and self.error is None:
            self.error = error
        self._done.set()

    def stop(self, timeout: float) -> str | None:
        """Ask the capture to stop and wait (at most ``timeout`` s) until the pen's last block
        has reached the sink. Returns :attr:`error` (None: all well)."""
        self._stop.set()
        if not self._done.wait(timeout):
            return self.error or f"the pen did not end the capture within {timeout:g} s"
        return self.error


class _Want:
    """What the pen should be doing now (the worker's view; resent after a reconnect)."""

    def __init__(self):
        self.profile = None  # the last pen-down's profile: its pattern belongs on the pen
        self.playing = False
        self.gain = 0.0  # 0 … 1
        self.a_max = 1.0
        self.fade_ms = FADE_MIN_MS


class PenBridge:
    """A pen driven from the live app (see the module doc). Every public call returns at once.

    Args:
        connect: makes a connected client (``hello()``, ``upload(samples, rate)``,
            ``set_state(playing, gain, rate, fade_ms)``, ``ping()``, ``close()``, optionally
            ``read_event(timeout)``); called on the worker thread, again after each failure.
        name: what the status calls the device (``"sim"``, ``"serial:/dev/ttyACM0"``, …).
        kind: ``"sim"``, ``"serial"``, ``"ble"`` (or anything, for tests).
        log: a :class:`realpen.live.device.CommandLog` (or anything with ``pen_down``,
            ``gain``, ``pen_up``, ``entries``, ``count``): every command is logged there first.
        pattern: renders a profile's pattern at a rate (default
            :func:`realpen.device.pattern.pen_pattern`), int16.
        on_close: called (in order) after the worker stopped, e.g. stopping a simulated pen.
        retry_max_s, heartbeat_s: the longest reconnect wait and the idle PING period, seconds.
        close_wait_s: how long :meth:`close` lets the worker finish before closing the link
            under it, seconds.
    """

    sim = None  # the SimPen it drives, when made by realpen.live.device.open_device("sim")

    def __init__(self, connect: Callable[[], object], *, name: str, kind: str, log=None,
                 pattern: Callable | None = None, on_close: Iterable[Callable[[], object]] = (),
                 retry_max_s: float = RETRY_MAX_S, heartbeat_s: float = HEARTBEAT_S,
                 close_wait_s: float = CLOSE_WAIT_S):
        self.name, self.kind = name, kind
        self.log = log
        self._connect = connect
        self._pattern = pattern
        self._on_close = list(on_close)
        self._retry_max_s = float(retry_max_s)
        self._heartbeat_s = float(heartbeat_s)
        self._close_wait_s = float(close_wait_s)
        self._cond = threading.Condition()
        self._ops: deque[tuple] = deque()  # ("down", profile, tactile) | ("gain", v) | ("up",)
        self._closing = False
        self._closed = False
        # Status (read by any thread under the condition's lock).
        self._connected = False
        self._message = f"connecting to {name}"
        self._info = None
        self._reconnects = 0
        self._history: deque[dict] = deque(maxlen=HISTORY)
        self._pattern_status: dict | None = None
        self._sent = 0  # SET_STATE frames sent
        self._attempted = threading.Event()  # the first connection attempt is over
        # Worker-only state.
        self._client = None
        self._rate: int | None = None
        self._held: tuple[int, int] | None = None  # (bytes, crc32) of the pattern the pen holds
        self._refused: dict[tuple[int, int], str] = {}  # patterns this connection refused
        self._rendered: OrderedDict[tuple, tuple] = OrderedDict()
        self._want = _Want()
        self._was_connected = False
        self._lost: str | None = None  # why the link went away (until it is back)
        self._hello_at = 0.0  # time.monotonic() when the last HELLO was answered
        self._ping_at = 0.0  # time.monotonic() of the next idle PING
        self._worker = threading.Thread(target=self._run, name=f"pen-bridge {name}", daemon=True)
        self._worker.start()

    # ---- the server's side: queue and return ---------------------------------------------

    def pen_down(self, origin, profile, tactile: bool) -> None:
        """Queue a stroke's start (pattern upload if needed, then ``SET_STATE`` playing)."""
        if self.log is not None:
            self.log.pen_down(origin, profile, tactile)
        self._queue(("down", profile, bool(tactile)))

    def gain(self, origin, value: float) -> None:
        """Queue a gain target (0 … ``a_max``); one still waiting is replaced (latest wins)."""
        if self.log is not None:
            self.log.gain(origin, value)
        with self._cond:
            if self._ops and self._ops[-1][0] == "gain":
                self._ops[-1] = ("gain", float(value))
            else:
                self._ops.append(("gain", float(value)))
            self._cond.notify_all()

    def pen_up(self, origin) -> None:
        """Queue the stroke's end (``SET_STATE`` not playing)."""
        if self.log is not None:
            self.log.pen_up(origin)
        self._queue(("up",))

    def capture(self, sink: Callable[[object], object], *, range_g: int = 2,
                rate_hz: int = 1344) -> CaptureRun:
        """Capture the pen's accelerometer on the bridge's thread until the run is stopped.

        Every SAMPLES block goes to ``sink`` as it arrives; meanwhile the page's commands still
        reach the pen (between blocks), so a capture may run while the pattern plays.

        Args:
            sink: called with each :class:`~realpen.device.client.SampleBlock` (quickly).
            range_g: the sensor's full-scale range in g (2, 4, 8, 16).
            rate_hz: its output rate in Hz (1344: the method's).

        Returns:
            The :class:`CaptureRun`; :meth:`CaptureRun.stop` ends it. A pen that is not
            connected, has no sensor or goes away ends it with its ``error`` set.
        """
        run = CaptureRun(sink, range_g, rate_hz)
        self._queue(("capture", run))
        return run

    def _queue(self, op: tuple) -> None:
        with self._cond:
            self._ops.append(op)
            self._cond.notify_all()

    # The command log, as GET /api/device/log reads it.
    @property
    def count(self) -> int:
        """Commands received so far (the log's count)."""
        return self.log.count if self.log is not None else 0

    def entries(self, since: int = 0, limit: int | None = None) -> list:
        """The logged commands (see :meth:`realpen.live.device.CommandLog.entries`)."""
        return self.log.entries(since, limit) if self.log is not None else []

    def status(self) -> dict:
        """``GET /api/device``: ``name``, ``kind``, ``connected``, ``message`` (one line),
        ``info`` (the pen's INFO once connected), ``reconnects``, ``pattern`` (what the pen
        holds: pen, bytes, id), ``set_states`` (frames sent) and ``history`` (the last status
        changes: ``t`` Unix time in s, ``connected``, ``message``)."""
        with self._cond:
            return {"name": self.name, "kind": self.kind, "connected": self._connected,
                    "message": self._message, "info": _info_json(self._info),
                    "reconnects": self._reconnects, "pattern": self._pattern_status,
                    "set_states": self._sent, "history": list(self._history)}

    def wait_attempted(self, timeout: float) -> bool:
        """Wait (at most ``timeout`` s) until the first connection attempt is over; True if so."""
        return self._attempted.wait(timeout)

    def close(self) -> None:
        """Stop: the queued commands are sent, the pen is silenced and the link closed (within
        ``close_wait_s``), then the ``on_close`` callables run. Idempotent."""
        with self._cond:
            if self._closed:
                return
            self._closed = self._closing = True
            self._cond.notify_all()
        self._worker.join(self._close_wait_s)
        if self._worker.is_alive():  # stuck on a dead link: closing the client unblocks it
            self._close_client(self._client)
            self._worker.join(1.0)
        for stop in self._on_close:
            try:
                stop()
            except Exception as error:  # noqa: BLE001 - a stop that fails must not stop others
                log.warning("%s: closing: %s", self.name, _one_line(error))
        with self._cond:
            self._connected = False
            self._set_message("closed")

    # ---- status ---------------------------------------------------------------------------

    def _set_message(self, message: str, connected: bool | None = None) -> None:
        """Set the status (call with the condition's lock held)."""
        changed = message != self._message or (connected is not None
                                               and connected != self._connected)
        if connected is not None:
            self._connected = connected
        self._message = message
        if changed:  # a retry that fails as the last one did is no news for the history
            self._history.append({"t": time.time(), "connected": self._connected,
                                  "message": message})

    def _status(self, message: str, connected: bool | None = None) -> None:
        with self._cond:
            self._set_message(message, connected)

    # ---- the worker -----------------------------------------------------------------------

    def _run(self) -> None:
        delay = RETRY_MIN_S
        try:
            while True:
                if self._client is None:
                    with self._cond:
                        if self._closing:
                            break
                    if self._open():
                        delay = RETRY_MIN_S
                        continue
                    self._attempted.set()
                    self._wait_disconnected(delay)
                    delay = min(delay * 2, self._retry_max_s)
                    continue
                with self._cond:
                    if not self._ops and not self._closing:
                        self._cond.wait(max(0.0, min(self._ping_at - time.monotonic(),
                                                     LINK_CHECK_S)))
                    op = self._ops.popleft() if self._ops else None
                    closing = self._closing
                if op is not None:
                    self._guard(self._apply, op)
                    self._ping_at = time.monotonic() + self._heartbeat_s
                elif closing:
                    break
                elif (time.monotonic() >= self._ping_at
                      or not getattr(self._client, "connected", True)):
                    # A link its client already knows is gone (the port hung up) fails the
                    # heartbeat at once, with the client's reason.
                    self._guard(self._heartbeat)
                    self._ping_at = time.monotonic() + self._heartbeat_s
        except Exception:  # a bug: said once, the server carries on without the pen
            log.exception("%s: the pen bridge stopped", self.name)
            self._status("stopped after an internal error (logged on the server)", False)
        finally:
            self._attempted.set()
            self._silence_and_close()

    def _wait_disconnected(self, delay: float) -> None:
        """Wait ``delay`` s for the next attempt; commands meanwhile only change what the pen
        should do (it hears the result when back)."""
        deadline = time.monotonic() + delay
        while True:
            with self._cond:
                while self._ops:
                    self._update(self._ops.popleft())
                left = deadline - time.monotonic()
                if self._closing or left <= 0:
                    return
                self._cond.wait(left)

    def _open(self) -> bool:
        """One connection attempt: connect, HELLO, re-upload, resend the state."""
        try:
            client = self._connect()
        except Exception as error:  # noqa: BLE001 - any failure: say it and try again
            self._not_connected(error)
            return False
        self._client = client
        try:
            self._hello()
            self._resync()
        except Exception as error:  # noqa: BLE001
            self._drop(error)
            return False
        return True

    def _hello(self) -> None:
        info = self._client.hello()
        # A boot EVENT received before INFO came is this boot's (a pen starting while the
        # HELLO waited); only a later one means the pen restarted since.
        self._hello_at = time.monotonic()
        self._ping_at = self._hello_at + self._heartbeat_s
        rate = _info_field(info, "sample_rate")
        self._rate = int(rate) if rate else None
        self._held = None  # what a pen holds after a HELLO is unknown: upload again
        self._refused.clear()
        pen = _info_field(info, "name") or self.name
        firmware = _info_field(info, "firmware_version") or ".".join(
            str(_info_field(info, key, "?")) for key in ("fw_major", "fw_minor", "fw_patch"))
        with self._cond:
            self._info = info
            if self._was_connected:
                self._reconnects += 1
            self._set_message(f"connected: {pen}, firmware {firmware}, "
                              f"{self._rate} Hz", True)
            self._pattern_status = None
        self._was_connected = True
        self._lost = None
        self._attempted.set()

    def _resync(self) -> None:
        """Put the pen back where it should be: its pattern, then the whole state."""
        want = self._want
        if want.profile is None:
            return
        self._ensure_pattern(want.profile)
        self._send_state()

    def _not_connected(self, error: BaseException) -> None:
        retry = f"trying again every {self._retry_max_s:g} s at most"
        if self._lost is not None:
            self._status(f"{self._lost_line()}; reconnecting (last attempt: "
                         f"{_one_line(error)}); {retry}", False)
        else:
            self._status(f"not connected ({_one_line(error)}); {retry}", False)

    def _lost_line(self) -> str:
        playing = " mid-stroke (the page keeps its sound)" if self._want.playing else ""
        return f"disconnected{playing}: {self._lost}"

    def _drop(self, error: BaseException) -> None:
        """The link failed: close it and say so (the loop reconnects)."""
        client, self._client = self._client, None
        self._close_client(client)
        self._lost = _one_line(error)
        self._status(f"{self._lost_line()}; reconnecting", False)

    @staticmethod
    def _close_client(client) -> None:
        if client is None:
            return
        try:
            client.close()
        except Exception:  # noqa: BLE001 - the link is already gone
            pass

    def _guard(self, action, *args) -> None:
        """Run a pen action; a failure of the link drops it (the loop reconnects)."""
        try:
            action(*args)
        except _disconnect_errors() as error:
            self._drop(error)
        except Exception as error:  # noqa: BLE001 - never into the server: reconnect instead
            from realpen.errors import RealPenError
            if not isinstance(error, RealPenError):  # not the pen's doing: a bug, logged
                log.exception("%s: unexpected error", self.name)
            self._drop(error)

    def _update(self, op: tuple) -> bool:
        """Apply ``op`` to what the pen should do; True if the pen must hear of it."""
        want = self._want
        if op[0] == "capture":  # reached here only when there is no link to capture on
            op[1].finish("the pen is not connected")
            return False
        if op[0] == "down":
            _, profile, tactile = op
            coupling = profile.meta.coupling
            want.profile = profile
            want.a_max = float(coupling.a_max)
            want.fade_ms = fade_ms(coupling.smoothing_ms)
            was_playing, want.playing, want.gain = want.playing, tactile, 0.0
            return tactile or was_playing
        if op[0] == "gain":
            if not want.playing:
                return False  # a late gain after the stroke ended: the pen stays silent
            want.gain = gain_fraction(op[1], want.a_max)
            return True
        was_playing, want.playing, want.gain = want.playing, False, 0.0
        return was_playing

    def _apply(self, op: tuple) -> None:
        if op[0] == "capture":
            self._capture(op[1])
            return
        send = self._update(op)
        if op[0] == "down":
            self._ensure_pattern(self._want.profile)
        if send:
            self._send_state()

    def _capture(self, run: CaptureRun) -> None:
        """Run a capture: start it, hand its blocks and the pen's events to the sink and apply
        the page's commands between blocks until it is stopped, then stop it and hand over the
        last blocks. A link that fails ends the capture and is dropped (the loop reconnects); a
        pen that restarts ends it and is set up again."""
        from realpen.errors import RealPenError

        client = self._client
        try:
            client.start_capture(run.range_g, run.rate_hz)
        except _disconnect_errors() as error:
            run.finish(_one_line(error))
            raise
        except RealPenError as error:  # no sensor, a range it lacks: the link is fine
            run.finish(_one_line(error))
            return
        run.info = self._info
        run.started.set()
        read_event = getattr(client, "read_event", None)
        try:
            while True:
                block = client.read_samples(CAPTURE_READ_S)
                if block is not None:
                    run.sink(block)
                while read_event is not None and (event := read_event(0)) is not None:
                    if getattr(event, "kind", None) == EV_BOOT \
                            and getattr(event, "at", 0) >= self._hello_at:
                        run.finish("the pen restarted during the capture")
                        self._status("the pen restarted; uploading its pattern again")
                        self._hello()
                        self._resync()
                        return
                    run.sink(event)  # overruns and dropped blocks, counted in the capture
                with self._cond:
                    ops = list(self._ops)
                    self._ops.clear()
                    closing = self._closing
                for op in ops:
                    if op[0] == "capture":  # one capture at a time
                        op[1].finish("another capture is running")
                    else:
                        self._apply(op)
                if run.stopping or closing:
                    break
            client.stop_capture()
            while (block := client.read_samples(0)) is not None:
                run.sink(block)
            while read_event is not None and (event := read_event(0)) is not None:
                run.sink(event)
            run.host_dropped = int(getattr(client, "blocks_dropped", 0))
        except BaseException as error:
            run.finish(_one_line(error))
            raise
        run.finish()
        self._ping_at = time.monotonic() + self._heartbeat_s

    def _send_state(self) -> None:
        want = self._want
        self._client.set_state(want.playing, want.gain if want.playing else 0.0, 1.0,
                               want.fade_ms)
        with self._cond:
            self._sent += 1

    def _render(self, profile) -> tuple[np.ndarray, tuple[int, int]]:
        """The profile's pattern at the pen's rate and its content key (bytes, CRC-32),
        rendered once per profile version and rate."""
        key = (profile.name, profile.version, self._rate)
        found = self._rendered.get(key)
        if found is None:
            render = self._pattern
            if render is None:
                from realpen.device.pattern import pen_pattern as render
            samples = np.ascontiguousarray(render(profile, self._rate), dtype="<i2")
            data = samples.tobytes()
            found = (samples, (len(data), zlib.crc32(data)))
            self._rendered[key] = found
            while len(self._rendered) > PATTERN_CACHE:
                self._rendered.popitem(last=False)
        else:
            self._rendered.move_to_end(key)
        return found

    def _ensure_pattern(self, profile) -> None:
        """Upload ``profile``'s pattern unless the pen holds the same samples (or refused
        them on this connection). A refusal leaves the pen's last good pattern playing."""
        from realpen.errors import RealPenError

        try:
            samples, content = self._render(profile)
        except RealPenError as error:  # e.g. a loop that is no whole number of samples there
            self._status(f"connected; {profile.name}'s pattern cannot be played at "
                         f"{self._rate} Hz ({_one_line(error)}); the pen keeps its last pattern")
            return
        if content == self._held or content in self._refused:
            return
        # Until this upload is committed, what the pen will play is unknown: a PATTERN_BEGIN
        # drops a pattern committed but not yet swapped in (the Pico's), and a failed upload
        # may leave either. Forgetting it makes the next pen-down upload again.
        self._held = None
        with self._cond:
            self._pattern_status = None
        try:
            pattern_id = self._client.upload(samples, self._rate)
        except _disconnect_errors():
            raise
        except Exception as error:  # noqa: BLE001 - the pen refused it (too large, CRC, NACK)
            if not isinstance(error, RealPenError):
                raise
            self._refused[content] = _one_line(error)
            self._status(f"connected; the pen refused {profile.name}'s pattern "
                         f"({_one_line(error)}); it keeps its last good pattern")
            return
        self._held = content
        with self._cond:
            self._pattern_status = {"pen": profile.name, "profile_version": profile.version,
                                    "bytes": content[0], "id": pattern_id}

    def _heartbeat(self) -> None:
        """An idle link: take the pen's events (a boot means it lost its pattern) and PING."""
        read_event = getattr(self._client, "read_event", None)
        rebooted = False
        if read_event is not None:
            while True:
                event = read_event(0)
                if event is None:
                    break
                kind = event[0] if isinstance(event, tuple) else getattr(event, "kind", None)
                at = getattr(event, "at", None)  # a boot from before the INFO is no news
                rebooted = rebooted or (kind == EV_BOOT and (at is None or at >= self._hello_at))
        if rebooted:
            self._status("the pen restarted; uploading its pattern again")
            self._was_connected = True
            self._hello()
            self._resync()
            return
        self._client.ping()

    def _silence_and_close(self) -> None:
        """On stop: the commands still queued, then silence, then the link closes."""
        client = self._client
        if client is not None:
            try:
                with self._cond:
                    ops = list(self._ops)
                    self._ops.clear()
                for op in ops:
                    if op[0] == "capture":
                        op[1].finish("the server is stopping")
                    else:
                        self._apply(op)
                if self._want.playing:
                    self._want.playing, self._want.gain = False, 0.0
                    self._send_state()
            except Exception as error:  # noqa: BLE001 - the pen may already be gone
                log.info("%s: could not silence the pen: %s", self.name, _one_line(error))
        self._client = None
        self._close_client(client)
