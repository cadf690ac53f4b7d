"""The pen's Bluetooth LE link (Pico W / Pico 2 W, MicroPython's ``bluetooth`` module).

One GATT service carries the protocol's byte stream (docs/protocol.md, "BLE service"): the host
writes pieces to RX (write without response), the pen notifies pieces of at most ATT MTU − 3
bytes on TX, and INFO holds the INFO payload to read. Beside it the standard Device
Information (0x180A) and Battery (0x180F) services. The pen advertises the service's UUID, and
its name in the scan response.

A thin layer: frames are decoded and answered by ``rp_pen`` exactly as over USB. Writes pile up
in RX's buffer (append mode) and the main loop hands them to the pen in :meth:`BlePen.poll`, so
the pen's state is never touched from the Bluetooth interrupt.
"""

import time

import bluetooth
import rp_protocol as P
from micropython import const

_IRQ_CENTRAL_CONNECT = const(1)
_IRQ_CENTRAL_DISCONNECT = const(2)
_IRQ_GATTS_WRITE = const(3)
_IRQ_MTU_EXCHANGED = const(21)

_FLAG_READ = const(0x0002)
_FLAG_WRITE_NO_RESPONSE = const(0x0004)
_FLAG_NOTIFY = const(0x0010)

_ADV_INTERVAL_US = const(100000)  # 100 ms: found quickly, little power
# Bytes of host writes held until the main loop reads them. In append mode BTstack copies each
# write after what is there and silently cuts what does not fit (micropython
# extmod/btstack/modbluetooth_btstack.c:943-948): a host that sent 16 chunk frames (~3 KB)
# before waiting lost the end of them with 1024. 4096 holds more than RealPen's host ever has
# in flight (it waits for a PONG after at most 4 chunks over BLE, docs/protocol.md), with room
# for a main loop held up meanwhile (an upload's COMMIT, a garbage collection).
_RX_BUFFER = const(4096)
_DEFAULT_PIECE = const(20)  # ATT MTU 23 − 3, until the host negotiates a larger MTU
_PREFERRED_MTU = const(247)  # a whole pattern chunk frame in one write (docs/protocol.md)

_SERVICE = (
    bluetooth.UUID(P.BLE_SERVICE),
    (
        (bluetooth.UUID(P.BLE_RX), _FLAG_WRITE_NO_RESPONSE),
        (bluetooth.UUID(P.BLE_TX), _FLAG_NOTIFY),
        (bluetooth.UUID(P.BLE_INFO), _FLAG_READ),
    ),
)
_DEVICE_INFORMATION = (
    bluetooth.UUID(0x180A),
    (
        (bluetooth.UUID(0x2A29), _FLAG_READ),  # manufacturer name
        (bluetooth.UUID(0x2A24), _FLAG_READ),  # model number
        (bluetooth.UUID(0x2A26), _FLAG_READ),  # firmware revision
    ),
)
_BATTERY = (
    bluetooth.UUID(0x180F),
    ((bluetooth.UUID(0x2A19), _FLAG_READ | _FLAG_NOTIFY),),  # battery level, %
)


def advertising_data():
    """Flags (general discoverable, no BR/EDR) and the service's 128-bit UUID."""
    uuid = bytes(bluetooth.UUID(P.BLE_SERVICE))  # the byte order advertising uses
    return bytes((2, 0x01, 0x06, len(uuid) + 1, 0x07)) + uuid


def scan_response(name):
    """The complete local name (at most 29 bytes fit)."""
    encoded = name.encode()[:29]
    return bytes((len(encoded) + 1, 0x09)) + encoded


class BlePen:
    """Serves ``pen`` (an ``rp_pen.Pen``) over BLE. ``battery``: an object with ``percent()``
    or None. Call :meth:`poll` from the main loop."""

    def __init__(self, pen, name, manufacturer, model, battery=None):
        self.pen = pen
        self.name = name
        self.battery = battery
        self.ble = bluetooth.BLE()
        self.ble.active(True)
        self.ble.config(gap_name=name, mtu=_PREFERRED_MTU)
        handles = self.ble.gatts_register_services((_SERVICE, _DEVICE_INFORMATION, _BATTERY))
        (self.rx, self.tx, self.info), (maker, number, revision), (self.level,) = handles
        self.ble.gatts_set_buffer(self.rx, _RX_BUFFER, True)
        self.ble.gatts_write(self.info, pen.info_payload())
        self.ble.gatts_write(maker, manufacturer.encode())
        self.ble.gatts_write(number, model.encode())
        self.ble.gatts_write(revision, "{}.{}.{}".format(*pen.firmware).encode())
        self.ble.gatts_write(self.level, bytes((self._percent(),)))
        self.pieces = {}  # connection handle → bytes a notification may carry
        self.written = False
        self.ble.irq(self._irq)
        self.link = pen.add_link(self._send, "ble")
        self._level_at = time.ticks_ms()
        self.advertise()

    def advertise(self):
        """Advertise (again): after boot and after a host disconnects."""
        self.ble.gap_advertise(_ADV_INTERVAL_US, adv_data=advertising_data(),
                               resp_data=scan_response(self.name), connectable=True)

    def _irq(self, event, data):
        # Runs as a scheduled callback: only bookkeeping here, the pen is served in poll().
        if event == _IRQ_CENTRAL_CONNECT:
            self.pieces[data[0]] = _DEFAULT_PIECE
        elif event == _IRQ_CENTRAL_DISCONNECT:
            self.pieces.pop(data[0], None)
            self.advertise()
        elif event == _IRQ_GATTS_WRITE:
            if data[1] == self.rx:
                self.written = True
        elif event == _IRQ_MTU_EXCHANGED:
            self.pieces[data[0]] = data[1] - 3

    def poll(self):
        """Hand the bytes hosts wrote to the pen; refresh the battery level once a minute."""
        if self.written:
            self.written = False
            data = self.ble.gatts_read(self.rx)  # reading clears the append buffer
            if data:
                self.link.feed(data)
        if self.battery is not None and time.ticks_diff(time.ticks_ms(),
                                                        self._level_at) >= 60000:
            self._level_at = time.ticks_ms()
            self.ble.gatts_write(self.level, bytes((self._percent(),)))
            for connection in list(self.pieces):  # a copy, as in _send
                self._notify(connection, self.level, None)

    def _percent(self):
        return self.battery.percent() if self.battery is not None else 100

    def _send(self, data):
        # Over a copy: _irq (a connect, a disconnect, an MTU exchange) may change self.pieces
        # while a notification waits, and a dict changed during iteration raises.
        for connection, size in list(self.pieces.items()):
            for at in range(0, len(data), size):
                if connection not in self.pieces:
                    break  # the host left meanwhile: the rest of the frame is for nobody
                self._notify(connection, self.tx, data[at:at + size])

    def _notify(self, connection, handle, piece):
        # The stack refuses a notification while its queue is full; wait briefly, then drop
        # (the host's decoder resynchronises at the next frame).
        for _ in range(25):
            try:
                if piece is None:
                    self.ble.gatts_notify(connection, handle)
                else:
                    self.ble.gatts_notify(connection, handle, piece)
                return
            except OSError:
                time.sleep_ms(2)
