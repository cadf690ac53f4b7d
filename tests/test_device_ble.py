"""The host's Bluetooth LE path against a virtual pen: no radio, real GATT.

The pen is :class:`ble_virtual.VirtualPen`: the firmware's protocol core (``firmware/pico``
rp_pen + rp_player under CPython) behind a bumble GATT server on bumble's in-process link; the
host side is RealPen's own :class:`~realpen.device.transport.BleTransport` and
:class:`~realpen.device.client.PenClient`, with a bleak client backend over a second bumble
device on the same link. Every byte crosses bumble's ATT/L2CAP/HCI stack.
"""

from __future__ import annotations

import asyncio
import time
import zlib

import numpy as np
import pytest
from ble_virtual import VirtualPen
from bleak import BleakClient

from realpen.device import protocol
from realpen.device.client import PenClient
from realpen.device.transport import BleTransport, DeviceDisconnected, DeviceError, scan_ble

DIS_MANUFACTURER = "00002a29-0000-1000-8000-00805f9b34fb"
DIS_MODEL = "00002a24-0000-1000-8000-00805f9b34fb"
DIS_FIRMWARE = "00002a26-0000-1000-8000-00805f9b34fb"
BATTERY_LEVEL = "00002a19-0000-1000-8000-00805f9b34fb"


def _pattern(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(-30000, 30000, n).astype(np.int16)


def _wait_for(condition, timeout: float = 2.0) -> bool:
    """Poll ``condition()`` until it is true or ``timeout`` seconds pass (the pen's render
    task applies states and swaps within a few ms)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.005)
    return condition()


def test_client_over_ble_hello_upload_play_ping():
    pen = VirtualPen("RealPen-ble-test")
    transport = BleTransport(pen.name, backend=pen.client_backend(), scan_timeout=3,
                             connect_timeout=3)
    with PenClient(transport) as client:
        assert transport.write_size == pen.mtu - 3  # MTU exchanged: 247 → 244-byte writes

        info = client.hello()
        assert (info.name, info.sample_rate, info.protocol) == (pen.name, 8000, 1)
        assert info.features & protocol.FEATURE_BLE
        # The INFO characteristic holds exactly what the pen sent in reply to HELLO.
        replies = [payload for ftype, _, payload in pen.sent_frames() if ftype == protocol.INFO]
        assert replies and transport.read_characteristic(protocol.BLE_INFO) == replies[-1]

        samples = _pattern(1500, seed=1)  # 3000 bytes: 17 chunks, one sync in the middle
        pattern_id = client.upload(samples, info.sample_rate)
        assert pattern_id == ((zlib.crc32(samples.astype("<i2").tobytes()) & 0xFFFF) or 1)
        assert _wait_for(lambda: pen.playing_pattern()[0] == pattern_id)
        assert pen.playing_pattern()[1] == samples.tolist()
        event = client.read_event(2.0)  # the pen's tick announces the swap
        assert (event.kind, event.value) == (protocol.EV_PATTERN, pattern_id)
        # A chunk frame (180 pattern bytes) went in one write; nothing exceeded MTU − 3.
        assert max(pen.rx_pieces) <= pen.mtu - 3 and max(pen.rx_pieces) > protocol.MAX_CHUNK
        assert max(pen.tx_pieces) <= pen.mtu - 3

        client.set_state(True, 0.5, fade_ms=20)
        # gain 0.5 → u16 32768 (32767 would give the same): Q15 amp = gain * cap // 65535.
        target = round(0.5 * protocol.GAIN_ONE) * pen.pen.player.gain_cap // protocol.GAIN_ONE
        assert _wait_for(lambda: pen.player_state()["amp"] == target)
        assert pen.player_state()["playing"] == 1

        round_trip, device_us = client.ping()
        assert 0 < round_trip < 1.0 and device_us > 0

        client.set_state(False, 0.0)
        assert _wait_for(lambda: pen.player_state()["amp"] == 0)
        assert pen.player_state()["playing"] == 0
    assert pen.connections == 1 and pen.errors == []


def test_small_mtu_splits_both_ways():
    # A host stuck at the default ATT MTU of 23: every write and notification is ≤ 20 bytes,
    # frames arrive in pieces on both sides and are reassembled by the decoders.
    pen = VirtualPen("RealPen-mtu23", mtu=23)
    transport = BleTransport(pen.name, backend=pen.client_backend(), scan_timeout=3,
                             connect_timeout=3)
    with PenClient(transport) as client:
        assert transport.write_size == 20
        info = client.hello()
        samples = _pattern(400, seed=2)
        pattern_id = client.upload(samples, info.sample_rate, pattern_id=7)
        assert _wait_for(lambda: pen.playing_pattern() == (pattern_id, samples.tolist()))
        assert max(pen.rx_pieces) == 20 and max(pen.tx_pieces) == 20
        assert len(pen.tx_pieces) > len(pen.sent_frames())  # the INFO reply went in pieces
        client.ping()
    assert pen.errors == []


def test_standard_services_and_info_characteristic():
    pen = VirtualPen("RealPen-gatt", battery_percent=64)

    async def session():
        async with BleakClient(pen.name, backend=pen.client_backend(), timeout=3) as client:
            values = {uuid: bytes(await client.read_gatt_char(uuid))
                      for uuid in (DIS_MANUFACTURER, DIS_MODEL, DIS_FIRMWARE, BATTERY_LEVEL,
                                   protocol.BLE_INFO)}
            service = client.services.get_service(protocol.BLE_SERVICE)
            properties = {c.uuid: sorted(c.properties) for c in service.characteristics}
            received = bytearray()
            await client.start_notify(protocol.BLE_TX, lambda _c, data: received.extend(data))
            await client.write_gatt_char(
                protocol.BLE_RX, protocol.encode_frame(protocol.HELLO, 9, protocol.pack_hello(1)),
                response=False)
            for _ in range(200):
                if protocol.FrameDecoder().feed(bytes(received)):
                    break
                await asyncio.sleep(0.005)
            return values, properties, protocol.FrameDecoder().feed(bytes(received))

    values, properties, frames = asyncio.run(session())
    assert values[DIS_MANUFACTURER] == b"RealPen"
    assert values[DIS_FIRMWARE] == ".".join(map(str, pen.pen.firmware)).encode()
    assert values[DIS_MODEL]
    assert values[BATTERY_LEVEL] == bytes([64])
    assert properties == {protocol.BLE_RX: ["write-without-response"],
                          protocol.BLE_TX: ["notify"], protocol.BLE_INFO: ["read"]}
    assert frames == [(protocol.INFO, 9, values[protocol.BLE_INFO])]
    assert protocol.unpack_info(values[protocol.BLE_INFO])[-1] == "RealPen-gatt"


def test_scan_and_connect_through_a_scanned_device():
    pen = VirtualPen("RealPen-scan")
    found = scan_ble(0.5, backend=pen.scanner_backend())  # ~25 advertisements
    assert [(p.name, p.address) for p in found] == [("RealPen-scan", pen.address)]
    transport = BleTransport(pen.name, backend=pen.client_backend(),
                             scanner_backend=pen.scanner_backend(), scan_timeout=3,
                             connect_timeout=3)
    with PenClient(transport) as client:
        assert client.hello().name == "RealPen-scan"


def test_no_such_pen_and_version_mismatch_and_drop():
    pen = VirtualPen("RealPen-other", protocol_version=2)
    with pytest.raises(DeviceError, match="ble:nobody"):
        BleTransport("nobody", backend=pen.client_backend(), scan_timeout=0.3,
                     connect_timeout=0.3)
    transport = BleTransport(pen.name, backend=pen.client_backend(), scan_timeout=3,
                             connect_timeout=3)
    with PenClient(transport) as client:
        with pytest.raises(DeviceError, match="speaks protocol 2, this host speaks 1"):
            client.hello()
        pen.drop_connection()  # the pen walks out of range
        with pytest.raises(DeviceDisconnected):
            for _ in range(100):
                client.ping()
                time.sleep(0.01)


def test_backend_refuses_writes_longer_than_the_mtu():
    pen = VirtualPen("RealPen-long", mtu=23)

    async def session():
        async with BleakClient(pen.address, backend=pen.client_backend(), timeout=3) as client:
            assert client.mtu_size == 23
            with pytest.raises(Exception, match="exceeds ATT MTU"):
                await client.write_gatt_char(protocol.BLE_RX, bytes(21), response=False)

    asyncio.run(session())


def _burst_upload(pen: VirtualPen) -> tuple[list, int]:
    """Write a whole 1500-sample upload (BEGIN, 17 chunk frames, COMMIT: ~3.3 KB) to RX as write
    commands while the pen's main loop is busy, then let it read; the pen's replies."""
    samples = _pattern(1500, seed=3)
    data = samples.astype("<i2").tobytes()
    frames = [protocol.encode_frame(protocol.PATTERN_BEGIN, 1, protocol.pack_pattern_begin(
        5, samples.size, 8000, protocol.FORMAT_S16LE, zlib.crc32(data)))]
    frames += [protocol.encode_frame(protocol.PATTERN_CHUNK, 2, protocol.pack_pattern_chunk(
        at, data[at:at + protocol.MAX_CHUNK])) for at in range(0, len(data), protocol.MAX_CHUNK)]
    frames.append(protocol.encode_frame(protocol.PATTERN_COMMIT, 3,
                                        protocol.pack_pattern_commit(5)))
    stream = b"".join(frames)

    async def session():
        async with BleakClient(pen.name, backend=pen.client_backend(), timeout=3) as client:
            received = bytearray()
            await client.start_notify(protocol.BLE_TX, lambda _c, piece: received.extend(piece))
            with pen.hold_main_loop():
                before = sum(pen.rx_pieces)
                for frame in frames:  # one frame a write: each fits the 244-byte MTU
                    await client.write_gatt_char(protocol.BLE_RX, frame, response=False)
                # Every write has reached the pen's RX buffer (kept or cut): waited for, not
                # slept for, as a loaded machine delivers write commands late.
                deadline = time.monotonic() + 10
                while sum(pen.rx_pieces) - before < len(stream) and time.monotonic() < deadline:
                    await asyncio.sleep(0.002)
            for _ in range(60):  # the COMMIT's reply comes within milliseconds, if at all
                replies = protocol.FrameDecoder().feed(bytes(received))
                if any(seq == 3 for _, seq, _ in replies):
                    break
                await asyncio.sleep(0.005)
            return replies

    replies = asyncio.run(session())
    return [(ftype, seq) for ftype, seq, _ in replies if ftype != protocol.EVENT], len(stream)


def test_rx_buffer_holds_a_burst_that_a_1024_byte_buffer_would_cut():
    """BTstack cuts RX writes that do not fit the buffer, silently. With the firmware's buffer
    (ble_pico._RX_BUFFER) a 3.3 KB burst written while the main loop is busy arrives whole and
    commits; with the 1024 bytes it had, the same burst loses its end and nothing commits."""
    pen = VirtualPen("RealPen-rx")
    assert pen.rx_buffer >= 4096
    replies, sent = _burst_upload(pen)
    assert sent > 3000 and pen.rx_dropped == 0 and pen.errors == []
    assert replies == [(protocol.ACK, 1), (protocol.ACK, 3)]
    assert pen.playing_pattern()[0] == 5 or _wait_for(lambda: pen.playing_pattern()[0] == 5)
    small = VirtualPen("RealPen-rx-small", rx_buffer=1024)
    replies, _ = _burst_upload(small)
    assert small.rx_dropped == sent - 1024
    assert (protocol.ACK, 3) not in replies and small.playing_pattern()[0] == -1
