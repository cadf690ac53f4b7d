"""A virtual Bluetooth LE pen and a bleak backend that reaches it, all in-process (no radio).

Two bumble devices share one :class:`bumble.link.LocalLink`: each has its own
:class:`bumble.controller.Controller` (bumble's software link layer) and the real bumble host
stack above it (HCI, L2CAP, ATT, GATT). So every byte between host and pen goes through real
ATT PDUs — MTU exchange, service discovery, write commands, notifications — only not over the
air.

- :class:`VirtualPen` is the pen: a GATT server with the pen's service (RX write without
  response, TX notify, INFO read), Device Information (0x180A) and Battery (0x180F), advertising
  its name and service. RX bytes go to the firmware's own protocol core (``firmware/pico``:
  ``rp_pen.Pen`` with ``rp_player.Player``, imported under CPython), and the core's replies go
  back as TX notifications in pieces of at most ATT MTU − 3 bytes. As on the Pico
  (``firmware/pico/ble_pico.py``), RX writes pile up in a buffer of the firmware's size that a
  main-loop task empties every millisecond, and what does not fit is cut off silently, as
  BTstack does: a host that has more in flight than that loses bytes here too. A render task
  drives the player at the pen's sample rate, as the firmware's audio loop does.
- :meth:`VirtualPen.client_backend` returns a ``bleak`` client backend class (a
  :class:`bleak.backends.client.BaseBleakClient`) implemented over a second bumble device on the
  same link; :meth:`VirtualPen.scanner_backend` a scanner backend. Pass them as ``backend=`` to
  ``BleakClient`` / ``BleakScanner`` (or to ``BleTransport``).

Event loops: bumble's link delivers packets with ``asyncio.get_running_loop().call_soon``, so
both devices must live on one loop — the loop that bleak runs on (``BleTransport`` owns one on its
thread, a test may use ``asyncio.run``). The bumble stack is therefore built lazily, on the
running loop of the first backend call, and built again on a later loop once the earlier one is
closed (as when one transport is closed and another opened). The protocol core — the pattern the
pen holds, the player — outlives that: for the pen it is a Bluetooth reconnection, not a reboot.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import sys
import threading
import time
import uuid as uuid_module
from array import array
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bleak.backends.characteristic import BleakGATTCharacteristic
from bleak.backends.client import BaseBleakClient, NotifyCallback
from bleak.backends.descriptor import BleakGATTDescriptor
from bleak.backends.device import BLEDevice
from bleak.backends.scanner import AdvertisementData, BaseBleakScanner
from bleak.backends.service import BleakGATTService, BleakGATTServiceCollection
from bleak.exc import BleakDeviceNotFoundError, BleakError, BleakGATTProtocolError
from bumble import att, gatt
from bumble.controller import Controller
from bumble.core import UUID, AdvertisingData
from bumble.device import Connection, Device, Peer
from bumble.hci import Address
from bumble.host import Host
from bumble.link import LocalLink
from bumble.profiles.battery_service import BatteryService
from bumble.profiles.device_information_service import DeviceInformationService
from bumble.transport.common import AsyncPipeSink

from realpen.device import protocol

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware" / "pico"
if str(FIRMWARE) not in sys.path:
    # The pen's own modules, exactly as deployed (rp_protocol is a link to protocol.py).
    # Appended, not prepended: firmware/pico also holds main.py and config.py, which must not
    # shadow anything else this test process imports; the rp_* names are unique.
    sys.path.append(str(FIRMWARE))

import rp_pen  # noqa: E402  (needs the path above; rp_pen imports rp_player)

PEN_ADDRESS = "F0:F0:F0:F0:F0:01"  # a static random address (top two bits set)
PEN_MTU = 247  # the largest ATT MTU the pen accepts (the Pico W's BTstack default)
HOST_MTU = 517  # what the host asks for (BlueZ asks for the ATT maximum)
ADVERTISING_INTERVAL_MS = 20  # the shortest legal interval: a scan finds the pen in ~one interval
RENDER_PERIOD_S = 0.004  # how often the render task catches the player up with the clock
BLOCK_SAMPLES = 16  # samples the player renders per block (2 ms at 8 kHz, as on the Pico)
MAIN_LOOP_PERIOD_S = 0.001  # how often the pen's main loop reads RX (the Pico's loop naps 1 ms)


def firmware_rx_buffer() -> int:
    """The RX buffer the Pico firmware asks BTstack for (``_RX_BUFFER`` in ble_pico.py), bytes."""
    text = (FIRMWARE / "ble_pico.py").read_text()
    found = re.search(r"^_RX_BUFFER = const\((\d+)\)", text, re.MULTILINE)
    if found is None:
        raise RuntimeError(f"{FIRMWARE / 'ble_pico.py'}: no _RX_BUFFER = const(N) line")
    return int(found.group(1))
_ADDRESS_RE = re.compile(r"^[0-9A-Fa-f]{2}(:[0-9A-Fa-f]{2}){5}$")


def bleak_uuid(bumble_uuid: UUID) -> str:
    """A bumble UUID as bleak writes it: 128-bit, lower case, with dashes (bumble keeps the
    bytes little-endian, Python's uuid big-endian)."""
    return str(uuid_module.UUID(bytes=bytes(reversed(bumble_uuid.uuid_128_bytes))))


def _property_names(properties: int) -> list:
    # bleak's names for the characteristic property bits (bleak.assigned_numbers).
    names = {0x01: "broadcast", 0x02: "read", 0x04: "write-without-response", 0x08: "write",
             0x10: "notify", 0x20: "indicate", 0x40: "authenticated-signed-writes",
             0x80: "extended-properties"}
    return [name for bit, name in names.items() if properties & bit]


class VirtualPen:
    """A pen on bumble's virtual link, running the firmware's protocol core under CPython.

    Args:
        name: the advertised local name and GAP device name.
        address: the pen's Bluetooth address (a static random address).
        rate: the pen's sample rate, Hz (the player's and INFO's).
        max_pattern_bytes: the largest pattern the pen holds, bytes.
        battery_percent: the Battery Level characteristic's value, 0 … 100 %.
        manufacturer, model: the Device Information strings.
        mtu: the largest ATT MTU the pen accepts, bytes.
        rx_buffer: bytes of RX writes held until the main loop reads them (default: the Pico
            firmware's); the rest of a write that does not fit is dropped.

    Attributes:
        pen: the firmware's ``rp_pen.Pen`` (its player, pattern and state are inspectable).
        tx_log: every byte the pen notified on TX, in order (see :meth:`sent_frames`).
        tx_pieces: the length in bytes of every TX notification sent, in order.
        rx_pieces: the length in bytes of every RX write received, in order.
        rx_dropped: bytes of RX writes cut off because the RX buffer was full.
        connections: how many Bluetooth connections the pen has accepted.
        errors: exceptions the pen's code raised in bumble's callbacks or its render task
            (bumble only logs them; a test asserts this stays empty).
    """

    def __init__(self, name: str = "RealPen-virtual", *, address: str = PEN_ADDRESS,
                 rate: int = 8000, max_pattern_bytes: int = 32768, battery_percent: int = 87,
                 battery_mv: int = 3900, manufacturer: str = "RealPen",
                 model: str = "virtual pen (bumble)", mtu: int = PEN_MTU,
                 protocol_version: int = protocol.PROTOCOL_VERSION,
                 rx_buffer: int | None = None):
        self.name = name
        self.address = address
        self.rate = rate
        self.battery_percent = battery_percent
        self.manufacturer = manufacturer
        self.model = model
        self.mtu = mtu
        self.pen = rp_pen.Pen(
            name=name, sample_rate=rate, max_pattern_bytes=max_pattern_bytes,
            features=protocol.FEATURE_BLE | protocol.FEATURE_BATTERY | protocol.FEATURE_RATE,
            protocol_version=protocol_version, battery=lambda: battery_mv)
        self._pen_link = self.pen.add_link(self._send, "ble")
        self._block = array("h", bytes(2 * BLOCK_SAMPLES))
        self.tx_log = bytearray()
        self.tx_pieces: list[int] = []
        self.rx_pieces: list[int] = []
        self.rx_buffer = firmware_rx_buffer() if rx_buffer is None else rx_buffer
        self.rx_dropped = 0
        self._rx = bytearray()  # writes not yet read by the main loop
        self._held = False  # the main loop is busy (hold_main_loop): RX is not read
        self.connections = 0
        self.errors: list[BaseException] = []
        self._lock = threading.Lock()  # the core is fed on the loop, inspected from tests
        self._loop: asyncio.AbstractEventLoop | None = None
        self._bumble_link: LocalLink | None = None
        self._device: Device | None = None
        self._tx_char: gatt.Characteristic | None = None
        self._connection: Connection | None = None
        self._tasks: list[asyncio.Task] = []
        self._tx_queue: asyncio.Queue | None = None
        self._centrals = 0

    # --- the bumble side -------------------------------------------------------------------

    async def ensure_started(self) -> LocalLink:
        """Power the pen on, advertising, on the running loop (once per loop); return the link."""
        loop = asyncio.get_running_loop()
        if self._loop is loop:
            return self._bumble_link
        if self._loop is not None and not self._loop.is_closed():
            raise RuntimeError("the virtual pen already serves another event loop; "
                               "close that one (its transport) first")
        self._loop = loop
        self._connection = None
        self._tasks = []
        self._bumble_link = LocalLink()
        controller = Controller("pen", link=self._bumble_link, public_address=self.address)
        device = Device(name=self.name, address=Address(self.address),
                        host=Host(controller, AsyncPipeSink(controller)))
        device.gatt_server.max_mtu = self.mtu
        self._tx_char = gatt.Characteristic(
            protocol.BLE_TX, gatt.Characteristic.Properties.NOTIFY,
            gatt.Characteristic.READABLE, b"")
        rx = gatt.Characteristic(
            protocol.BLE_RX, gatt.Characteristic.Properties.WRITE_WITHOUT_RESPONSE,
            gatt.Characteristic.WRITEABLE, gatt.CharacteristicValue(write=self._on_rx))
        info = gatt.Characteristic(
            protocol.BLE_INFO, gatt.Characteristic.Properties.READ,
            gatt.Characteristic.READABLE, gatt.CharacteristicValue(read=self._read_info))
        device.add_service(gatt.Service(protocol.BLE_SERVICE, [rx, self._tx_char, info]))
        device.add_service(DeviceInformationService(
            manufacturer_name=self.manufacturer, model_number=self.model,
            firmware_revision=".".join(str(part) for part in self.pen.firmware)))
        device.add_service(BatteryService(lambda _connection: self.battery_percent))
        device.on(device.EVENT_CONNECTION, self._on_connection)
        await device.power_on()
        self._device = device
        await self._advertise()
        return self._bumble_link

    async def _advertise(self) -> None:
        # Connectable advertising with the name and the pen's service: what a host scans for.
        # Restarted by the pen itself after each disconnection (see _on_connection), so a
        # test can wait for it (settle) instead of leaving bumble's own restart task behind.
        advertising = AdvertisingData([
            (AdvertisingData.FLAGS, bytes([0x06])),  # LE general discoverable, no BR/EDR
            (AdvertisingData.COMPLETE_LIST_OF_128_BIT_SERVICE_CLASS_UUIDS,
             UUID(protocol.BLE_SERVICE).to_bytes()),
            (AdvertisingData.COMPLETE_LOCAL_NAME, self.name.encode()),
        ])
        await self._device.start_advertising(
            advertising_data=bytes(advertising),
            advertising_interval_min=ADVERTISING_INTERVAL_MS,
            advertising_interval_max=ADVERTISING_INTERVAL_MS)

    async def settle(self, timeout: float = 1.0) -> None:
        """After a disconnection: wait until the pen has noticed it, stopped its connection's
        tasks and is advertising again (on the running loop, the pen's)."""
        deadline = time.monotonic() + timeout
        while self._connection is not None and time.monotonic() < deadline:
            await asyncio.sleep(0.001)
        pending = [task for task in self._tasks if not task.done()]
        await asyncio.gather(*pending, return_exceptions=True)

    def new_central(self) -> Device:
        """A second bumble device (a host's adapter) on the pen's link (after ensure_started)."""
        self._centrals += 1
        address = f"F1:F0:F0:F0:F0:{self._centrals % 256:02X}"
        controller = Controller(f"host{self._centrals}", link=self._bumble_link,
                                public_address=address)
        return Device(name=f"host{self._centrals}", address=Address(address),
                      host=Host(controller, AsyncPipeSink(controller)))

    def _on_connection(self, connection: Connection) -> None:
        self.connections += 1
        self._connection = connection
        self._tx_queue = asyncio.Queue()
        loop = asyncio.get_running_loop()
        tasks = [loop.create_task(self._tx_pump(connection, self._tx_queue)),
                 loop.create_task(self._render()), loop.create_task(self._main_loop())]
        self._tasks = tasks

        def on_disconnection(_reason: int) -> None:
            for task in tasks:
                task.cancel()
            if self._connection is connection:
                self._connection = None
                self._tx_queue = None
            self._tasks = [*tasks, loop.create_task(self._advertise())]

        connection.on(connection.EVENT_DISCONNECTION, on_disconnection)

    def _on_rx(self, _connection: Connection, value: bytes) -> None:
        # A write command: one piece of the host's frame stream (any split), appended to the RX
        # buffer as BTstack does in append mode: what does not fit is cut off, silently.
        self.rx_pieces.append(len(value))
        room = self.rx_buffer - len(self._rx)
        self._rx += value[:room]
        self.rx_dropped += max(0, len(value) - room)

    async def _main_loop(self) -> None:
        # The firmware's main loop (ble_pico.BlePen.poll): read what RX holds, feed the core.
        while True:
            await asyncio.sleep(MAIN_LOOP_PERIOD_S)
            if self._held or not self._rx:
                continue
            data = bytes(self._rx)
            self._rx.clear()
            try:
                with self._lock:
                    self._pen_link.feed(data)
            except Exception as error:
                self.errors.append(error)
                raise

    def _send(self, frame: bytes) -> None:
        # The core's send function for this link: replies and EVENTs, whole frames.
        if self._tx_queue is None or self._connection is None:
            raise OSError("no host connected")  # the core drops the frame, as on the pen
        self._tx_queue.put_nowait(bytes(frame))

    def _read_info(self, _connection: Connection) -> bytes:
        with self._lock:
            return self.pen.info_payload()

    async def _tx_pump(self, connection: Connection, queue: asyncio.Queue) -> None:
        # One sender per connection keeps the pieces in order; each piece fits one notification.
        while True:
            data = await queue.get()
            step = connection.att_mtu - 3
            for start in range(0, len(data), step):
                piece = data[start:start + step]
                self.tx_pieces.append(len(piece))
                self.tx_log += piece
                await self._device.notify_subscriber(connection, self._tx_char, piece)

    async def _render(self) -> None:
        # The firmware's audio loop: keep the player rendered up to the wall clock, block by
        # block, so pattern swaps and gain ramps happen as they would on the pen; then the
        # main loop's tick (EVENTs that are due).
        start = time.monotonic()
        done = 0
        while True:
            await asyncio.sleep(RENDER_PERIOD_S)
            due = int((time.monotonic() - start) * self.rate)
            try:
                with self._lock:
                    while done + BLOCK_SAMPLES <= due:
                        self.pen.fill(self._block)
                        done += BLOCK_SAMPLES
                    self.pen.tick()
            except Exception as error:
                self.errors.append(error)
                raise

    # --- test helpers ----------------------------------------------------------------------

    def playing_pattern(self) -> tuple[int, list]:
        """(id, samples) of the pattern the pen's player plays now; (-1, []) before any."""
        with self._lock:
            player = self.pen.player
            # The player keeps two buffers and plays _bufs[_active] (rp_player.Player).
            samples = list(player._bufs[player._active][:player.length])
            return player.pattern_id, samples

    def player_state(self) -> dict:
        """The player's state now: playing (0/1), amp and its target (Q15), rate (Q12)."""
        with self._lock:
            player = self.pen.player
            return {"playing": player.playing, "amp": player.amp,
                    "amp_target": player._amp_target, "rate": player.rate,
                    "samples": self.pen.samples}

    def sent_frames(self) -> list:
        """Every frame the pen notified so far, decoded: ``[(ftype, seq, payload), ...]``."""
        return protocol.FrameDecoder().feed(bytes(self.tx_log))

    @contextlib.contextmanager
    def hold_main_loop(self):
        """Keep the pen's main loop from reading RX while in the block (busy: a long frame, a
        garbage collection), so that host writes pile up in the RX buffer."""
        self._held = True
        try:
            yield
        finally:
            self._held = False

    def run_on_loop(self, coroutine_function: Callable[[], Any], timeout: float = 5.0) -> Any:
        """Run ``coroutine_function()`` on the pen's loop from another thread; return its result."""
        if self._loop is None or self._loop.is_closed():
            raise RuntimeError("the virtual pen is not running on any loop")
        return asyncio.run_coroutine_threadsafe(coroutine_function(), self._loop).result(timeout)

    def drop_connection(self, timeout: float = 5.0) -> None:
        """Disconnect the host from the pen's side (a pen walking out of range), thread-safe."""
        async def drop() -> None:
            if self._connection is not None:
                await self._connection.disconnect()
        self.run_on_loop(drop, timeout)

    def client_backend(self) -> type[BaseBleakClient]:
        """A bleak client backend class bound to this pen (``BleakClient(..., backend=it)``)."""
        return type("VirtualBleakClient", (VirtualBleakClient,), {"pen": self})

    def scanner_backend(self) -> type[BaseBleakScanner]:
        """A bleak scanner backend class bound to this pen (``BleakScanner(..., backend=it)``)."""
        return type("VirtualBleakScanner", (VirtualBleakScanner,), {"pen": self})


class VirtualBleakScanner(BaseBleakScanner):
    """bleak's scanner over a bumble central on the virtual pen's link (see VirtualPen)."""

    pen: VirtualPen

    def __init__(self, detection_callback, service_uuids, scanning_mode="active", **_kwargs):
        super().__init__(detection_callback, service_uuids)
        self._device: Device | None = None

    async def start(self) -> None:
        """Start an active scan; each advertisement reaches the registered callbacks."""
        await self.pen.ensure_started()
        self.seen_devices = {}
        if self._device is None:
            self._device = self.pen.new_central()
            self._device.on(self._device.EVENT_ADVERTISEMENT, self._on_advertisement)
            await self._device.power_on()
        await self._device.start_scanning(filter_duplicates=False)

    async def stop(self) -> None:
        """Stop scanning."""
        if self._device is not None and self._device.is_scanning:
            await self._device.stop_scanning()

    def _on_advertisement(self, advertisement) -> None:
        name = _local_name(advertisement.data)
        uuids = [bleak_uuid(u) for u in _service_uuids(advertisement.data)]
        if not self.is_allowed_uuid(uuids):
            return
        data = AdvertisementData(local_name=name, manufacturer_data={}, service_data={},
                                 service_uuids=uuids, tx_power=None, rssi=advertisement.rssi,
                                 platform_data=(advertisement,))
        address = str(advertisement.address).split("/")[0]
        device = self.create_or_update_device(address, address, name, advertisement.address,
                                              data)
        self.call_detection_callbacks(device, data)


class VirtualBleakClient(BaseBleakClient):
    """bleak's client backend over a bumble central on the virtual pen's link (see VirtualPen).

    Connects by address, or by advertised name through a bumble scan; requests the MTU,
    discovers services, characteristics and descriptors and maps them into bleak's types.
    Write without response refuses data longer than ATT MTU − 3, as a real stack would.
    """

    pen: VirtualPen

    def __init__(self, address_or_ble_device, **kwargs):
        super().__init__(address_or_ble_device,
                         disconnected_callback=kwargs.get("disconnected_callback"),
                         timeout=kwargs.get("timeout", 10.0))
        self._target = address_or_ble_device
        self._device: Device | None = None
        self._connection: Connection | None = None
        self._peer: Peer | None = None
        self._name = None
        self._closing = False
        self._subscribers: dict[int, Callable[[bytes], None]] = {}

    @property
    def name(self) -> str:
        """The pen's advertised name (or its address before the connection)."""
        return self._name or self.address

    @property
    def mtu_size(self) -> int:
        """The negotiated ATT MTU, bytes."""
        return self._connection.att_mtu if self._connection is not None else att.ATT_DEFAULT_MTU

    @property
    def is_connected(self) -> bool:
        """Whether the Bluetooth connection is up."""
        return self._connection is not None

    async def connect(self, pair: bool = False, **kwargs: Any) -> None:
        """Find the pen (scan by name unless given an address), connect, MTU, discover."""
        await self.pen.ensure_started()
        timeout = kwargs.get("timeout", self._timeout)
        self._device = self.pen.new_central()
        await self._device.power_on()
        target = self._target
        if isinstance(target, BLEDevice):
            address = target.details if isinstance(target.details, Address) else target.address
            self._name = target.name
        elif _ADDRESS_RE.match(target):
            address = target
        else:
            address = await self._find_by_name(target, timeout)
        try:
            connection = await asyncio.wait_for(self._device.connect(address), timeout)
        except Exception as error:  # bumble's connection errors and TimeoutError
            raise BleakDeviceNotFoundError(str(self.address), f"cannot connect: {error}") from error
        self._connection = connection
        self.address = str(connection.peer_address).split("/")[0]
        connection.on(connection.EVENT_DISCONNECTION, self._on_disconnection)
        self._peer = Peer(connection)
        await self._peer.request_mtu(HOST_MTU)
        self.services = await self._discover()
        if self._name is None:
            self._name = self.pen.name

    async def _find_by_name(self, name: str, timeout: float) -> Address:
        found: asyncio.Future = asyncio.get_running_loop().create_future()

        def on_advertisement(advertisement) -> None:
            if not found.done() and _local_name(advertisement.data) == name:
                found.set_result(advertisement.address)

        self._device.on(self._device.EVENT_ADVERTISEMENT, on_advertisement)
        await self._device.start_scanning(filter_duplicates=True)
        try:
            address = await asyncio.wait_for(found, timeout)
        except TimeoutError:
            raise BleakDeviceNotFoundError(name, f"no device named {name!r} advertising") from None
        finally:
            self._device.remove_listener(self._device.EVENT_ADVERTISEMENT, on_advertisement)
            await self._device.stop_scanning()
        self._name = name
        return address

    async def _discover(self) -> BleakGATTServiceCollection:
        peer = self._peer
        collection = BleakGATTServiceCollection()
        for service in await peer.discover_services():
            bleak_service = BleakGATTService(service, service.handle, bleak_uuid(service.uuid))
            collection.add_service(bleak_service)
            for characteristic in await service.discover_characteristics():
                bleak_char = BleakGATTCharacteristic(
                    characteristic, characteristic.handle, bleak_uuid(characteristic.uuid),
                    _property_names(int(characteristic.properties)),
                    lambda: self.mtu_size - 3, bleak_service)
                collection.add_characteristic(bleak_char)
                for descriptor in await characteristic.discover_descriptors():
                    collection.add_descriptor(BleakGATTDescriptor(
                        descriptor, descriptor.handle, bleak_uuid(descriptor.type), bleak_char))
        return collection

    def _on_disconnection(self, _reason: int) -> None:
        self._connection = None
        if not self._closing and self._disconnected_callback is not None:
            self._disconnected_callback()

    async def disconnect(self) -> None:
        """Disconnect (no callback: this one was asked for)."""
        self._closing = True
        if self._connection is not None:
            connection = self._connection
            self._connection = None
            try:
                await connection.disconnect()
            except Exception:  # already gone: nothing left to close
                pass
        if self._device is not None:
            await self._device.power_off()
        await self.pen.settle()

    async def pair(self, *args: Any, **kwargs: Any) -> None:
        """The pen needs no pairing; nothing to do."""

    async def unpair(self) -> None:
        """The pen needs no pairing; nothing to do."""

    def _require_connection(self) -> Peer:
        if self._connection is None:
            raise BleakError(f"{self.address}: not connected")
        return self._peer

    async def read_gatt_char(self, characteristic: BleakGATTCharacteristic, *,
                             use_cached: bool = False, **kwargs: Any) -> bytearray:
        """Read a characteristic's value (ATT read, long values by blob reads)."""
        return await self._read(characteristic.handle)

    async def read_gatt_descriptor(self, descriptor: BleakGATTDescriptor, *,
                                   use_cached: bool = False, **kwargs: Any) -> bytearray:
        """Read a descriptor's value."""
        return await self._read(descriptor.handle)

    async def _read(self, handle: int) -> bytearray:
        peer = self._require_connection()
        try:
            return bytearray(await peer.read_value(handle))
        except att.ATT_Error as error:
            raise BleakGATTProtocolError(error.error_code) from error

    async def write_gatt_char(self, characteristic: BleakGATTCharacteristic, data,
                              response: bool) -> None:
        """Write a characteristic: a write request (``response``) or a write command."""
        peer = self._require_connection()
        data = bytes(data)
        if not response and len(data) > self.mtu_size - 3:
            raise BleakError(f"{self.address}: write without response of {len(data)} bytes "
                             f"exceeds ATT MTU {self.mtu_size} - 3")
        try:
            await peer.write_value(characteristic.handle, data, with_response=response)
        except att.ATT_Error as error:
            raise BleakGATTProtocolError(error.error_code) from error

    async def write_gatt_descriptor(self, descriptor: BleakGATTDescriptor, data) -> None:
        """Write a descriptor (a write request)."""
        peer = self._require_connection()
        try:
            await peer.write_value(descriptor.handle, bytes(data), with_response=True)
        except att.ATT_Error as error:
            raise BleakGATTProtocolError(error.error_code) from error

    async def start_notify(self, characteristic: BleakGATTCharacteristic,
                           callback: NotifyCallback, **kwargs: Any) -> None:
        """Subscribe (CCCD write) and hand every notification's bytes to ``callback``."""
        self._require_connection()

        def on_value(value: bytes) -> None:
            callback(bytearray(value))

        self._subscribers[characteristic.handle] = on_value
        await characteristic.obj.subscribe(on_value, prefer_notify=True)

    async def stop_notify(self, characteristic: BleakGATTCharacteristic) -> None:
        """Unsubscribe (CCCD write of 0)."""
        self._require_connection()
        on_value = self._subscribers.pop(characteristic.handle, None)
        await characteristic.obj.unsubscribe(on_value)


def _local_name(data: AdvertisingData) -> str | None:
    name = (data.get(AdvertisingData.COMPLETE_LOCAL_NAME)
            or data.get(AdvertisingData.SHORTENED_LOCAL_NAME))
    return name if isinstance(name, str) or name is None else bytes(name).decode("utf-8", "replace")


def _service_uuids(data: AdvertisingData) -> list:
    found = []
    for kind in (AdvertisingData.COMPLETE_LIST_OF_16_BIT_SERVICE_CLASS_UUIDS,
                 AdvertisingData.INCOMPLETE_LIST_OF_16_BIT_SERVICE_CLASS_UUIDS,
                 AdvertisingData.COMPLETE_LIST_OF_128_BIT_SERVICE_CLASS_UUIDS,
                 AdvertisingData.INCOMPLETE_LIST_OF_128_BIT_SERVICE_CLASS_UUIDS):
        found.extend(data.get(kind) or [])
    return found
