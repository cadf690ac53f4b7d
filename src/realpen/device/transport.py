"""Byte pipes to a pen: a serial port (USB CDC, a pseudo-terminal) or Bluetooth LE.

A :class:`Transport` carries the protocol's byte stream and knows nothing of frames: ``write``
sends bytes, ``read`` returns whatever arrived (any split; the protocol's
:class:`~realpen.device.protocol.FrameDecoder` reassembles the frames). Over Bluetooth the
stream rides on two characteristics of the pen's service: the host writes pieces of at most
ATT MTU − 3 bytes, without response, to ``BLE_RX``, and the pen notifies ``BLE_TX``.

:func:`open_transport` picks the link from the port's text: ``ble:NAME`` (a pen's advertised
name or its address) is Bluetooth, anything else a serial device (``/dev/ttyACM0``, ``COM3``,
``/dev/pts/5``).

Every failure is a :class:`DeviceError` (a :class:`~realpen.errors.RealPenError`) whose one line
names the port; a link that goes away while open is a :class:`DeviceDisconnected`.

pyserial and bleak are imported only when a link of their kind opens (or ports are listed).
"""

from __future__ import annotations

import asyncio
import errno
import os
import re
import threading
import time

from realpen.errors import RealPenError

__all__ = ["DeviceError", "DeviceDisconnected", "Transport", "SerialTransport", "BleTransport",
           "open_transport", "BLE_PREFIX", "BAUD_RATE", "SerialPortInfo", "BlePenInfo",
           "list_serial_ports", "scan_ble", "BluetoothUnavailable", "WRITE_TIMEOUT_S",
           "UPLOAD_WINDOW", "BLE_UPLOAD_WINDOW"]

BLE_PREFIX = "ble:"
BAUD_RATE = 115200  # USB CDC ignores it; a UART bridge (or the Due's programming port) needs it
_POLL_S = 0.02  # how long one serial read waits at most: the reader thread's reaction time
_ADDRESS = re.compile(r"^([0-9A-Fa-f]{2}[:-]){5}[0-9A-Fa-f]{2}$|^[0-9A-Fa-f]{8}-([0-9A-Fa-f]{4}-){3}"
                      r"[0-9A-Fa-f]{12}$")  # a MAC address, or the UUID macOS gives a device
DEFAULT_BLE_WRITE = 20  # bytes a write may carry before the MTU is known (23 − 3)
WRITE_TIMEOUT_S = 2.0  # a serial write the pen does not take within this long: it stopped reading
UPLOAD_WINDOW = 16  # pattern chunks an upload may send before waiting for the pen (≈ 2.9 KB)
BLE_UPLOAD_WINDOW = 4  # over Bluetooth: the pen's receive buffer is small (4 KB on the Pico W)
# and it decodes slowly, and writes without response have no flow control to hold the host back


class DeviceError(RealPenError):
    """A pen could not be reached, or refused or garbled a request; the message is one line
    that names the port."""


class DeviceDisconnected(DeviceError):
    """The link to the pen went away while it was open (unplugged, out of range, rebooted)."""


class BluetoothUnavailable(DeviceError):
    """This machine cannot scan or connect over Bluetooth LE (no adapter, no BlueZ)."""


class Transport:
    """A byte pipe to a pen. Subclasses implement :meth:`write`, :meth:`read` and
    :meth:`close`; ``name`` is the port as the user gave it (for messages)."""

    name: str = ""
    #: How many pattern chunks (each a frame of up to 190 bytes) an upload sends before it waits
    #: for the pen to have handled them (a PING round trip): what the link lets run ahead.
    upload_window: int = UPLOAD_WINDOW

    def write(self, data: bytes) -> None:
        """Send ``data`` (blocks until it is handed to the link).

        Raises:
            DeviceDisconnected: the link is gone.
        """
        raise NotImplementedError

    def read(self, timeout: float) -> bytes:
        """The bytes that arrived, waiting up to ``timeout`` seconds for the first one.

        Returns:
            Some bytes, or ``b""`` when none came within ``timeout``.

        Raises:
            DeviceDisconnected: the link is gone (and nothing is left to read).
        """
        raise NotImplementedError

    def close(self) -> None:
        """Release the link (again: nothing happens)."""
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


def open_transport(port: str, *, timeout: float = 5.0) -> Transport:
    """Open the link a port names: ``ble:NAME`` over Bluetooth LE, else a serial device.

    Args:
        port: ``/dev/ttyACM0``, ``COM3``, a pseudo-terminal (``/dev/pts/5``), or ``ble:NAME``
            with a pen's advertised name or its Bluetooth address.
        timeout: for Bluetooth, seconds to find the pen by name (connecting may take 10 s).

    Raises:
        DeviceError: the port is empty, cannot be opened, or no such pen answers.
    """
    port = str(port)
    if not port.strip():
        raise DeviceError("port: empty; give a serial device (e.g. /dev/ttyACM0) or ble:NAME")
    if port.lower().startswith(BLE_PREFIX):
        return BleTransport(port[len(BLE_PREFIX):], scan_timeout=timeout)
    return SerialTransport(port)


# --- serial ------------------------------------------------------------------------------------

class SerialTransport(Transport):
    """A serial port through pyserial: 115200 baud, 8N1, no flow control.

    Args:
        port: the device (``/dev/ttyACM0``, ``COM3``, ``/dev/pts/5``).
        write_timeout: seconds a write may wait for the pen to take the bytes; longer, and the
            pen is taken to have stopped reading (a hung firmware, a port nobody serves).

    Raises:
        DeviceError: the port does not exist, is busy, or is not a serial device.
    """

    def __init__(self, port: str, *, write_timeout: float = WRITE_TIMEOUT_S):
        import serial

        self.name = str(port)
        self._write_timeout = float(write_timeout)
        try:
            # exclusive (POSIX: flock): a second host on the same port would take half of
            # the pen's bytes each; it is told the port is busy instead.
            options = {"exclusive": True} if os.name == "posix" else {}
            self._serial = serial.Serial(self.name, BAUD_RATE, bytesize=8, parity="N", stopbits=1,
                                         timeout=_POLL_S, write_timeout=self._write_timeout,
                                         xonxoff=False, rtscts=False, dsrdtr=False, **options)
        except (serial.SerialException, OSError, ValueError) as error:
            raise DeviceError(f"{self.name}: cannot open this serial port ({_why(error)})") \
                from None
        self._closed = False

    def write(self, data: bytes) -> None:
        import serial

        if self._closed:
            raise DeviceDisconnected(f"{self.name}: the port is closed")
        try:
            # A bounded wait: a pen that stops reading would otherwise block this write, and
            # every writer queued behind it, for ever.
            self._serial.write(bytes(data))
        except serial.SerialTimeoutException:
            if self._closed:
                raise DeviceDisconnected(f"{self.name}: the port is closed") from None
            raise DeviceDisconnected(f"{self.name}: the pen stopped reading (a write waited "
                                     f"{self._write_timeout:g} s for it)") from None
        except (serial.SerialException, OSError, TypeError, AttributeError, ValueError) as error:
            # TypeError/AttributeError/ValueError: pyserial's write on a port closed by another
            # thread.
            if self._closed:
                raise DeviceDisconnected(f"{self.name}: the port is closed") from None
            raise DeviceDisconnected(f"{self.name}: the pen went away ({_why(error)})") from None
        if self._closed:  # close() woke a blocked write before all of it went out
            raise DeviceDisconnected(f"{self.name}: the port is closed")

    def read(self, timeout: float) -> bytes:
        import serial

        deadline = time.monotonic() + max(0.0, timeout)
        while not self._closed:
            try:
                # One byte or what is waiting: returns as soon as anything came, else after
                # _POLL_S, so the loop notices a deadline or a close quickly.
                data = self._serial.read(max(1, self._serial.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError) as error:
                # TypeError/AttributeError: pyserial's read on a port closed by another thread.
                if self._closed:
                    break
                raise DeviceDisconnected(f"{self.name}: the pen went away ({_why(error)})") \
                    from None
            if data:
                return bytes(data)
            if time.monotonic() >= deadline:
                return b""
        raise DeviceDisconnected(f"{self.name}: the port is closed")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            # Wake a write blocked on a pen that stopped reading (pyserial's abort pipe), so
            # it returns instead of waiting out its timeout on a closed port.
            self._serial.cancel_write()
        except Exception:  # not offered on this platform, or the port vanished
            pass
        try:
            self._serial.close()
        except Exception:  # closing a port that vanished: nothing left to release
            pass


_ERRNO_WORDS = {
    errno.ENOENT: "no such device",
    errno.ENOTTY: "not a serial device",
    errno.EACCES: "permission denied; on Linux, join the group that owns it (often dialout)",
    errno.EBUSY: "busy: another program has it open",
    errno.EAGAIN: "busy: another program has it open",  # the exclusive lock is taken
    errno.EIO: "input/output error",
    errno.ENXIO: "no such device (unplugged?)",
    errno.EISDIR: "a folder, not a serial device",
}


def _why(error: BaseException) -> str:
    """The system's reason in an OS or pyserial error, in a few words, without pyserial's
    repetition of the port's name."""
    text = " ".join(str(error).split())
    if "readiness to read but returned no data" in text:
        # pyserial's guess "(device disconnected or multiple access on port?)": the port is
        # held exclusively, so it is the former.
        return "disconnected"
    code = getattr(error, "errno", None)
    # pyserial wraps the OS error in its text: "[Errno 2] ...", or "(25, 'Inappropriate ...')".
    found = re.search(r"\[Errno (\d+)\] ([^:'\]]+)", text) or \
        re.search(r"\((\d+), '([^']+)'\)", text)
    if found:
        code = int(found.group(1))
    if code in _ERRNO_WORDS:
        return _ERRNO_WORDS[code]
    if found:
        return found.group(2).strip()
    return getattr(error, "strerror", None) or text or type(error).__name__


class SerialPortInfo:
    """A serial port :func:`list_serial_ports` found: its device and what it says it is."""

    def __init__(self, device: str, description: str, hwid: str):
        self.device, self.description, self.hwid = device, description, hwid

    def __repr__(self) -> str:
        return f"SerialPortInfo({self.device!r}, {self.description!r})"


def list_serial_ports() -> list[SerialPortInfo]:
    """The serial ports of this machine (pyserial's ``list_ports``), sorted by device."""
    from serial.tools import list_ports

    found = [SerialPortInfo(p.device, p.description or "", p.hwid or "")
             for p in list_ports.comports()]
    return sorted(found, key=lambda p: p.device)


# --- Bluetooth LE ------------------------------------------------------------------------------

class BlePenInfo:
    """A pen :func:`scan_ble` found: its advertised name, address and signal strength (dBm)."""

    def __init__(self, name: str, address: str, rssi: int | None):
        self.name, self.address, self.rssi = name, address, rssi

    def __repr__(self) -> str:
        return f"BlePenInfo({self.name!r}, {self.address!r}, rssi={self.rssi})"


def _bluetooth_problem(error: BaseException) -> str:
    """Why Bluetooth is not usable here, in plain words."""
    if isinstance(error, FileNotFoundError):
        return "no Bluetooth service on this machine (BlueZ's D-Bus socket is missing)"
    text = " ".join(str(error).split()) or type(error).__name__
    if "adapter" in text.lower():
        return f"no Bluetooth adapter ({text})"
    return text


def _bluetooth_errors() -> tuple[type[BaseException], ...]:
    from bleak.exc import BleakError

    return (BleakError, OSError)


def scan_ble(timeout: float = 3.0, *, backend=None) -> list[BlePenInfo]:
    """The pens advertising RealPen's service within ``timeout`` seconds.

    Args:
        timeout: how long to listen, in seconds.
        backend: a bleak scanner backend class (tests); None: the platform's.

    Raises:
        BluetoothUnavailable: no Bluetooth adapter or service on this machine.
    """
    from realpen.device.protocol import BLE_SERVICE

    async def scan():
        from bleak import BleakScanner

        kwargs = {"backend": backend} if backend is not None else {}
        found = await BleakScanner.discover(timeout=timeout, return_adv=True,
                                            service_uuids=[BLE_SERVICE], **kwargs)
        return found

    try:
        found = asyncio.run(scan())
    except _bluetooth_errors() as error:
        raise BluetoothUnavailable(f"Bluetooth: {_bluetooth_problem(error)}") from None
    pens = []
    for device, advert in found.values():
        uuids = [u.lower() for u in (advert.service_uuids or [])]
        if uuids and BLE_SERVICE not in uuids:  # a backend that ignores the filter
            continue
        pens.append(BlePenInfo(advert.local_name or device.name or "", device.address,
                               advert.rssi))
    return sorted(pens, key=lambda p: (p.name, p.address))


class BleTransport(Transport):
    """A pen over Bluetooth LE through bleak, run on an asyncio loop of its own thread.

    Args:
        target: the pen's advertised name, its address (``AA:BB:CC:DD:EE:FF``, or the UUID
            macOS gives it), or a ``bleak.backends.device.BLEDevice`` already found.
        backend: a bleak client backend class (``BaseBleakClient`` subclass) to connect
            through — tests pass one over a virtual link; None: the platform's. With a backend
            and no ``scanner_backend``, a name is handed to the backend as it is (no scan).
        scanner_backend: a bleak scanner backend class for finding the pen by name.
        scan_timeout: seconds to look for a pen by name.
        connect_timeout: seconds to connect and discover its services.

    Raises:
        BluetoothUnavailable: no Bluetooth here.
        DeviceError: no pen of that name, or it does not offer RealPen's service.
    """

    def __init__(self, target, *, backend=None, scanner_backend=None, scan_timeout: float = 5.0,
                 connect_timeout: float = 10.0):
        shown = target if isinstance(target, str) else (getattr(target, "name", None)
                                                        or getattr(target, "address", "?"))
        self.name = f"{BLE_PREFIX}{shown}"
        self._backend, self._scanner_backend = backend, scanner_backend
        self._buffer = bytearray()
        self._arrived = threading.Condition()
        self._connected = False
        self._closed = False
        self._lost = ""
        self._client = None
        self._rx = None  # the BLE_RX characteristic, once connected
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name=f"realpen {self.name}",
                                        daemon=True)
        self._thread.start()
        try:
            self._call(self._connect(target, scan_timeout, connect_timeout),
                       scan_timeout + connect_timeout + 5.0)
        except BaseException:
            self.close()
            raise

    # -- running coroutines on the loop thread --

    def _call(self, coroutine, timeout: float):
        future = asyncio.run_coroutine_threadsafe(coroutine, self._loop)
        try:
            return future.result(timeout)
        except TimeoutError:
            future.cancel()
            raise DeviceError(f"{self.name}: no answer within {timeout:g} s") from None

    async def _connect(self, target, scan_timeout: float, connect_timeout: float) -> None:
        from bleak import BleakClient, BleakScanner

        from realpen.device.protocol import BLE_RX, BLE_SERVICE, BLE_TX

        errors = _bluetooth_errors()
        device = target
        try:
            if isinstance(target, str) and not _ADDRESS.match(target) and \
                    (self._backend is None or self._scanner_backend is not None):
                kwargs = {"backend": self._scanner_backend} if self._scanner_backend else {}
                device = await BleakScanner.find_device_by_filter(
                    lambda d, adv: target in (adv.local_name, d.name), timeout=scan_timeout,
                    service_uuids=[BLE_SERVICE], **kwargs)
                if device is None:
                    raise DeviceError(f"{self.name}: no pen of that name answered within "
                                      f"{scan_timeout:g} s (is it on, near and not connected "
                                      f"elsewhere? `realpen device list` shows the pens seen)")
            kwargs = {"backend": self._backend} if self._backend is not None else {}
            client = BleakClient(device, disconnected_callback=self._on_disconnect,
                                 timeout=connect_timeout, **kwargs)
            await client.connect()
        except DeviceError:
            raise
        except TimeoutError:
            raise DeviceError(f"{self.name}: could not connect within {connect_timeout:g} s") \
                from None
        except errors as error:
            if isinstance(error, FileNotFoundError) or "adapter" in str(error).lower():
                raise BluetoothUnavailable(f"{self.name}: {_bluetooth_problem(error)}") from None
            raise DeviceError(f"{self.name}: cannot connect ({_bluetooth_problem(error)})") \
                from None
        self._client = client
        try:
            rx = client.services.get_characteristic(BLE_RX)
            if rx is None or client.services.get_characteristic(BLE_TX) is None:
                raise DeviceError(f"{self.name}: this device does not offer RealPen's service "
                                  f"({BLE_SERVICE})")
            self._rx = rx
            await client.start_notify(BLE_TX, self._on_notify)
        except DeviceError:
            await _quietly(client.disconnect())
            raise
        except errors as error:
            await _quietly(client.disconnect())
            raise DeviceError(f"{self.name}: cannot subscribe to the pen's notifications "
                              f"({_bluetooth_problem(error)})") from None
        self._connected = True

    # -- callbacks (on the loop thread) --

    def _on_notify(self, characteristic, data: bytearray) -> None:
        with self._arrived:
            self._buffer += data
            self._arrived.notify_all()

    def _on_disconnect(self, client) -> None:
        with self._arrived:
            self._connected = False
            self._lost = "the pen disconnected"
            self._arrived.notify_all()

    # -- the pipe --

    upload_window = BLE_UPLOAD_WINDOW  # the Pico W's receive buffer: 4 KB, decoded slowly

    @property
    def write_size(self) -> int:
        """The largest piece one Bluetooth write carries (ATT MTU − 3), in bytes.

        Asked of the RX characteristic at each write: bleak's ``mtu_size`` says 23 on BlueZ
        (with a warning) unless the MTU is fetched separately, and a stack may learn the
        negotiated MTU only after connecting. 20 (the minimum MTU's) when it cannot say."""
        try:
            size = int(self._rx.max_write_without_response_size)
        except (AttributeError, TypeError, ValueError):  # not connected, or an older backend
            return DEFAULT_BLE_WRITE
        return max(DEFAULT_BLE_WRITE, size)

    def write(self, data: bytes) -> None:
        from realpen.device.protocol import BLE_RX

        if self._closed or not self._connected:
            raise DeviceDisconnected(f"{self.name}: {self._lost or 'not connected'}")
        data = bytes(data)
        client, step = self._client, self.write_size
        target = self._rx if self._rx is not None else BLE_RX
        for start in range(0, len(data), step):
            piece = data[start:start + step]
            try:
                self._call(client.write_gatt_char(target, piece, response=False), 10.0)
            except DeviceError:
                raise
            except _bluetooth_errors() as error:
                raise DeviceDisconnected(f"{self.name}: the pen went away "
                                         f"({_bluetooth_problem(error)})") from None

    def read(self, timeout: float) -> bytes:
        deadline = time.monotonic() + max(0.0, timeout)
        with self._arrived:
            while not self._buffer:
                if self._closed or not self._connected:
                    raise DeviceDisconnected(f"{self.name}: {self._lost or 'not connected'}")
                left = deadline - time.monotonic()
                if left <= 0:
                    return b""
                self._arrived.wait(left)
            data = bytes(self._buffer)
            self._buffer.clear()
            return data

    def read_characteristic(self, uuid: str, timeout: float = 5.0) -> bytes:
        """Read a characteristic of the pen (e.g. ``BLE_INFO``, or the battery level 0x2A19).

        Raises:
            DeviceError: it cannot be read.
        """
        if self._client is None or not self._connected:
            raise DeviceDisconnected(f"{self.name}: {self._lost or 'not connected'}")
        try:
            return bytes(self._call(self._client.read_gatt_char(uuid), timeout))
        except DeviceError:
            raise
        except _bluetooth_errors() as error:
            raise DeviceError(f"{self.name}: cannot read {uuid} ({_bluetooth_problem(error)})") \
                from None

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        with self._arrived:
            self._arrived.notify_all()
        client, self._client = self._client, None
        if client is not None and self._loop.is_running():
            try:
                self._call(_quietly(client.disconnect()), 5.0)
            except DeviceError:
                pass
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(5.0)
        if not self._thread.is_alive():
            self._loop.close()


async def _quietly(coroutine) -> None:
    """Await ``coroutine`` and ignore its failure (a disconnect while tearing down)."""
    try:
        await coroutine
    except Exception:
        pass

