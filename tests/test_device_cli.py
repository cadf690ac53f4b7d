"""``realpen device …`` against the real firmware (a SimPen on a pseudo-terminal).

In-process through :func:`conftest.run_cli`: list, info, upload, play, stop, ping, monitor, the
port from ``--port`` before or after the subcommand or from ``REALPEN_PORT``, and each failure
as one line with exit code 2. One subprocess: ``realpen device sim`` prints its port, serves a
client, and writes its WAV when interrupted.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli

from realpen.device import protocol as p
from realpen.device.client import PenClient
from realpen.device.sim import SimPen
from realpen.device.transport import BlePenInfo, BluetoothUnavailable, SerialPortInfo, open_transport


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    trace = tmp_path_factory.mktemp("sim") / "trace.jsonl"
    with SimPen(trace=trace) as pen:
        pen.trace_path = trace
        yield pen


def states(trace) -> list[tuple[int, int, int]]:
    """(playing, gain, rate) of each SET_STATE the pen took, from its trace."""
    lines = trace.read_text().split("\n")[:-1]  # whole lines: the pen may be writing one
    events = [json.loads(line) for line in lines if line.strip()]
    return [(e["playing"], e["gain"], e["rate"]) for e in events if e["event"] == "set_state"]


@pytest.mark.firmware
def test_info_with_the_port_before_or_after_the_subcommand(sim, monkeypatch):
    first = run_cli("device", "--port", sim.port, "info")
    assert first.returncode == 0, first.stderr
    assert f"port: {sim.port}" in first.stdout
    assert "sample rate: 8000 Hz" in first.stdout and "protocol: 1" in first.stdout
    assert "largest pattern: 32768 bytes (2.048 s at 8000 Hz)" in first.stdout
    assert re.search(r"firmware: \d+\.\d+\.\d+", first.stdout)
    second = run_cli("device", "info", "-p", sim.port)
    assert second.returncode == 0 and second.stdout.splitlines()[:-1] == \
        first.stdout.splitlines()[:-1]  # all but the round trip
    monkeypatch.setenv("REALPEN_PORT", sim.port)
    assert run_cli("device", "info").returncode == 0


@pytest.mark.firmware
def test_upload_play_stop(sim):
    done = run_cli("device", "upload", "pencil", "--port", sim.port)
    assert done.returncode == 0, done.stderr
    assert re.search(r"uploaded pencil to .* 24000 bytes \(1\.5 s at 8000 Hz\) in \d+\.\d\d s "
                     r"\([\d.]+ kB/s\), pattern id \d+", done.stdout), done.stdout
    before = len(states(sim.trace_path))
    played = run_cli("device", "play", "--gain", "0.5", "--rate", "2", "--port", sim.port)
    assert played.returncode == 0, played.stderr
    assert "gain 0.5, rate 2" in played.stdout
    stopped = run_cli("device", "stop", "--port", sim.port)
    assert stopped.returncode == 0, stopped.stderr
    # The trace is written when the player applies the state, a block after the frame came.
    deadline = time.monotonic() + 5.0
    while len(states(sim.trace_path)) < before + 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert states(sim.trace_path)[before:] == [(1, round(0.5 * p.GAIN_ONE), 2 * p.RATE_ONE),
                                               (0, 0, p.RATE_ONE)]


@pytest.mark.firmware
def test_ping_and_monitor(sim):
    pinged = run_cli("device", "ping", "--count", "3", "--port", sim.port)
    assert pinged.returncode == 0, pinged.stderr
    lines = pinged.stdout.splitlines()
    assert len(lines) == 4 and all("ms round trip, pen clock" in line for line in lines[:3])
    assert lines[3].startswith(f"3 PINGs over {sim.port}: round trip min ")
    with PenClient(open_transport(sim.port)) as client:  # something to see: a pattern swap
        client.upload(np.arange(400, dtype=np.int16), 8000, pattern_id=77)
    watched = run_cli("device", "monitor", "--seconds", "1.2", "--port", sim.port)
    assert watched.returncode == 0, watched.stderr
    assert watched.stdout.startswith("monitoring ")
    pings = len(re.findall(r" s  ping \d+\.\d\d ms", watched.stdout))
    assert 1 <= pings <= 2, watched.stdout  # one a second, from the start (a loaded machine: 1)
    summary = re.search(r"stopped after (\d+\.\d) s: \d+ events?, (\d+) pings?, round trip "
                        r"median", watched.stdout)
    assert summary and int(summary[2]) == pings, watched.stdout
    assert 1.2 <= float(summary[1]) + 0.05 and float(summary[1]) < 3, watched.stdout


@pytest.mark.firmware
def test_a_half_frame_left_in_the_pen_does_not_eat_the_hello(sim):
    # An interrupted command (Ctrl-C in an upload) leaves the start of a frame in the pen's
    # decoder; the next command's HELLO must still be heard.
    fd = os.open(sim.port, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(fd, bytes(range(1, 41)))  # 40 bytes, no 0x00: a frame that never ends
    finally:
        os.close(fd)
    done = run_cli("device", "--timeout", "1", "info", "--port", sim.port)
    assert done.returncode == 0, done.stderr
    assert "protocol: 1" in done.stdout


def test_list_says_plainly_when_bluetooth_is_unavailable(monkeypatch):
    from realpen.device import transport

    monkeypatch.setattr(transport, "list_serial_ports", lambda: [
        SerialPortInfo("/dev/ttyACM0", "Board in FS mode", "USB VID:PID=2E8A:0005"),
        SerialPortInfo("/dev/ttyS0", "n/a", "n/a")])

    def no_bluetooth(seconds, **kwargs):
        raise BluetoothUnavailable("Bluetooth: no Bluetooth adapter (No Bluetooth adapters found.)")

    monkeypatch.setattr(transport, "scan_ble", no_bluetooth)
    done = run_cli("device", "list")
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "serial ports:", "  /dev/ttyACM0  Board in FS mode", "  /dev/ttyS0",
        "Bluetooth LE: unavailable (no Bluetooth adapter (No Bluetooth adapters found.))"]
    monkeypatch.setattr(transport, "scan_ble", lambda seconds, **kwargs: [
        BlePenInfo("RealPen-7", "AA:BB:CC:DD:EE:FF", -61)])
    monkeypatch.setattr(transport, "list_serial_ports", lambda: [])
    done = run_cli("device", "list", "--seconds", "0.5")
    assert done.stdout.splitlines() == [
        "serial ports:", "  none", "Bluetooth LE pens (0.5 s scan):",
        "  ble:RealPen-7  AA:BB:CC:DD:EE:FF  -61 dBm"]
    assert run_cli("device", "list", "--no-ble").stdout.splitlines() == ["serial ports:", "  none"]


def test_list_on_this_machine_never_fails():
    done = run_cli("device", "list", "--seconds", "0.2")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("serial ports:\n") and "Bluetooth LE" in done.stdout


def test_failures_are_one_line(tmp_path, monkeypatch):
    monkeypatch.delenv("REALPEN_PORT", raising=False)
    assert_clean_failure(run_cli("device", "info"), "--port")
    assert_clean_failure(run_cli("device", "ping", "--port", str(tmp_path / "none")),
                         f"{tmp_path / 'none'}: cannot open this serial port (no such device)")
    master, slave = os.openpty()  # nobody answers there
    try:
        path = os.ttyname(slave)
        started = time.monotonic()
        assert_clean_failure(run_cli("device", "--timeout", "0.3", "stop", "--port", path),
                             f"{path}: no reply to HELLO within 0.3 s")
        assert time.monotonic() - started < 5  # 0.3 s and the command's own time: not stuck
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.firmware
def test_a_pen_that_cannot_take_the_request():
    with SimPen(protocol_version=2) as other:
        result = run_cli("device", "info", "--port", other.port)
        assert_clean_failure(result, f"{other.port}: the pen")
        assert "this host speaks 1" in result.stderr
    with SimPen(max_pattern_bytes=16000) as small:
        result = run_cli("device", "upload", "pencil", "--port", small.port)
        assert_clean_failure(result, f"{small.port}: the pattern (24000 bytes")
        assert "at most 16000 bytes" in result.stderr


FULL_SCALE_8000 = (8000 * 32767) >> 15  # a pattern sample of 8000 played at full gain


def wait_until_played(sim_pid: int, value: int, count: float, timeout: float = 60.0) -> None:
    """Wait until the firmware under ``realpen device sim`` (process ``sim_pid``) has recorded
    more than ``count`` samples equal to ``value``.

    The sink plays in real time, so how much it plays in a given sleep depends on the machine's
    load; the test waits for the samples instead. The firmware is sim's only child, and its
    command line names the raw recording (``record=…/played.raw``) it appends to as it plays.
    """
    with open(f"/proc/{sim_pid}/task/{sim_pid}/children") as listing:
        children = listing.read().split()
    assert len(children) == 1, children  # the firmware (MicroPython)
    with open(f"/proc/{children[0]}/cmdline") as command_line:
        arguments = command_line.read().split("\0")
    raw = next(arg.split("=", 1)[1] for arg in arguments if arg.startswith("record="))
    deadline = time.monotonic() + timeout
    while True:
        with open(raw, "rb") as recording:
            data = recording.read()
        played = np.frombuffer(data[: len(data) // 2 * 2], dtype="<i2")
        if (played == value).sum() > count:
            return
        assert time.monotonic() < deadline, f"{(played == value).sum()} samples in {timeout} s"
        time.sleep(0.02)


@pytest.mark.firmware
def test_sim_prints_its_port_and_writes_the_wav_when_interrupted(tmp_path):
    record, trace = tmp_path / "pen.wav", tmp_path / "trace.jsonl"
    process = subprocess.Popen([sys.executable, "-m", "realpen", "device", "sim", "--record",
                                str(record), "--trace", str(trace)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline()
        assert re.fullmatch(r"port: /dev/pts/\d+\n", line), (line, process.stderr.read()
                                                            if process.poll() is not None else "")
        with PenClient(open_transport(line.split(": ", 1)[1].strip())) as client:
            assert client.hello().sample_rate == 8000
            client.upload(np.full(800, 8000, np.int16), 8000)
            client.set_state(True, 1.0)
            client.sync()
            wait_until_played(process.pid, FULL_SCALE_8000, 0.1 * 8000 + 1)
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=10)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, err
    assert "Traceback" not in err and f"wrote {record}" in out
    samples, rate = sf.read(record, dtype="int16")
    assert rate == 8000 and (samples == FULL_SCALE_8000).sum() > 0.1 * 8000
    assert any(json.loads(line)["event"] == "set_state" for line in trace.read_text().splitlines())


@pytest.mark.firmware
def test_sim_says_when_its_firmware_dies_and_still_writes_the_wav(tmp_path):
    record = tmp_path / "pen.wav"
    process = subprocess.Popen([sys.executable, "-m", "realpen", "device", "sim", "--record",
                                str(record)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        port = process.stdout.readline().split(": ", 1)[1].strip()
        sensor = process.stdout.readline()
        assert "accelerometer: LIS3DH" in sensor, sensor
        hint = process.stdout.readline()
        assert f"--device serial:{port}" in hint and f"--port {port}" in hint, hint
        children = open(f"/proc/{process.pid}/task/{process.pid}/children").read().split()
        assert len(children) == 1  # the firmware (MicroPython)
        os.kill(int(children[0]), signal.SIGKILL)  # it dies by itself, as far as sim knows
        out, err = process.communicate(timeout=10)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert_clean_failure(subprocess.CompletedProcess([], process.returncode, out, err),
                         f"{port}: the simulated pen's firmware exited by itself (code -9); "
                         f"wrote {record}: ")
    assert sf.info(str(record)).samplerate == 8000


def _process_status(pid: int) -> dict[str, str]:
    """The fields of ``/proc/PID/status`` (State, SigPnd, ShdPnd, …)."""
    with open(f"/proc/{pid}/status") as status:
        return {key: value.strip() for key, value in
                (line.split(":", 1) for line in status if ":" in line)}


def _wait_for(condition, what: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"no {what} within {timeout} s"
        time.sleep(0.01)


def _stderr_line(process: subprocess.Popen, timeout: float = 30.0) -> str:
    """The next line ``process`` writes on stderr ('' at its end or after ``timeout`` s)."""
    import selectors

    with selectors.DefaultSelector() as selector:
        selector.register(process.stderr, selectors.EVENT_READ)
        if not selector.select(timeout):
            return ""
    return process.stderr.readline()


@pytest.mark.firmware
@pytest.mark.slow
def test_a_second_ctrl_c_while_sim_stops_still_writes_the_wav(tmp_path):
    # The firmware is held (SIGSTOP) so that sim's stop waits for it: the second Ctrl-C then
    # certainly comes while the recording is being stopped and written, not before or after.
    record, temporary = tmp_path / "pen.wav", tmp_path / "tmp"
    temporary.mkdir()  # sim's working folder goes here: what it leaves behind can be seen
    process = subprocess.Popen([sys.executable, "-m", "realpen", "device", "sim", "--record",
                                str(record)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env={**os.environ, "TMPDIR": str(temporary)})
    firmware = None
    try:
        port = process.stdout.readline().split(": ", 1)[1].strip()
        with PenClient(open_transport(port)) as client:
            client.upload(np.full(800, 8000, np.int16), 8000)
            client.set_state(True, 1.0)
            client.sync()
            wait_until_played(process.pid, FULL_SCALE_8000, 0.05 * 8000)
        firmware = int(open(f"/proc/{process.pid}/task/{process.pid}/children").read().split()[0])
        os.kill(firmware, signal.SIGSTOP)
        _wait_for(lambda: _process_status(firmware)["State"].startswith("T"), "stopped firmware")
        process.send_signal(signal.SIGINT)
        # sim's stop has sent the firmware its SIGINT: it waits for the firmware to close.
        _wait_for(lambda: int(_process_status(firmware)["ShdPnd"], 16) & 1 << signal.SIGINT - 1
                  or process.poll() is not None, "SIGINT for the firmware")
        process.send_signal(signal.SIGINT)
        said = _stderr_line(process)
        os.kill(firmware, signal.SIGCONT)
        out, err = process.communicate(timeout=30)
    finally:
        if firmware is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(firmware, signal.SIGCONT)
        if process.poll() is None:
            process.kill()
            process.wait()
    assert said == f"still writing {record}, one moment\n", (said, err)
    assert process.returncode == 0, err
    assert "Traceback" not in err and f"wrote {record}" in out
    samples, rate = sf.read(record, dtype="int16")
    assert rate == 8000 and (samples == FULL_SCALE_8000).sum() > 0.05 * 8000
    assert sorted(path.name for path in tmp_path.rglob("*")) == ["pen.wav", "tmp"]
