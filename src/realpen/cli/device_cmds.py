"""``realpen device list | info | upload | play | stop | ping | monitor | sim``: the pen itself.

Only typer and the standard library are imported here; the protocol client, pyserial, bleak,
numpy and the simulated pen (:mod:`realpen.device`) are imported inside the commands.
"""

import contextlib
import errno
import os
import statistics
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import typer

from realpen.checks import require_number
from realpen.cli.common import (
    InterruptOnce,
    check_outputs,
    command_group,
    console,
    force_option,
    progress_bar,
    terminate_as_interrupt,
    whole_number,
)
from realpen.defaults import DEVICE_TIMEOUT_S
from realpen.errors import ParameterError, RealPenError, fail

__all__ = ["device_app", "register"]

device_app = command_group(
    "The pen: find it, show what it is, upload a profile's pattern, play, stop, ping and watch "
    "it; 'device sim' runs the pen's real firmware on a pseudo-terminal.")

PORT_ENV = "REALPEN_PORT"
PORT_HELP = (f"The pen: a serial device (/dev/ttyACM0, COM3, a /dev/pts/N of 'realpen device "
             f"sim') or ble:NAME (its Bluetooth name or address). Default: ${PORT_ENV}.")
MAX_PINGS = 100_000
MAX_SECONDS = 7 * 24 * 3600.0  # a week: longer is a mistake, not a measurement
PING_EVERY_S = 1.0  # monitor: one PING a second shows the link is alive and how fast it is
SCAN_S = 3.0
DEFAULT_TIMEOUT_S = DEVICE_TIMEOUT_S  # realpen.device.client's, from the numpy-free defaults
MAX_TIMEOUT_S = 3600.0


@device_app.callback()
def _device(ctx: typer.Context,
            port: str | None = typer.Option(None, "--port", "-p", envvar=PORT_ENV,
                                            metavar="PORT", help=PORT_HELP),
            timeout: float = typer.Option(DEFAULT_TIMEOUT_S, "--timeout", metavar="S",
                                          help="Seconds to wait for each reply of the pen.")
            ) -> None:
    """The pen: find it, show what it is, upload a profile's pattern, play, stop, ping and
    watch it; 'device sim' runs the pen's real firmware on a pseudo-terminal."""
    _seconds("--timeout", timeout, maximum=MAX_TIMEOUT_S)
    ctx.ensure_object(dict).update(port=port, timeout=timeout)


def port_option() -> str | None:
    """The ``--port`` a subcommand also takes (``realpen device info --port P``)."""
    return typer.Option(None, "--port", "-p", metavar="PORT", help=PORT_HELP)


def _port(ctx: typer.Context, port: str | None) -> str:
    chosen = port if port is not None else (ctx.obj or {}).get("port")
    if chosen is None:
        raise RealPenError(f"--port: give the pen's port, a serial device (/dev/ttyACM0, COM3) or "
                           f"ble:NAME (or set {PORT_ENV}); 'realpen device list' shows them")
    if not chosen.strip():
        raise RealPenError("--port: empty; give a serial device (/dev/ttyACM0, COM3) or ble:NAME")
    return chosen


@contextlib.contextmanager
def _connected(ctx: typer.Context, port: str) -> Iterator:
    """A :class:`~realpen.device.client.PenClient` on ``port`` that has said HELLO."""
    from realpen.device.client import PenClient
    from realpen.device.transport import open_transport

    timeout = (ctx.obj or {}).get("timeout", DEFAULT_TIMEOUT_S)
    client = PenClient(open_transport(port), timeout=timeout)
    try:
        client.hello()
        yield client
    finally:
        client.close()


def _seconds(flag: str, value: float | None, *, maximum: float = MAX_SECONDS) -> None:
    """Refuse a duration that is not a positive, finite number of seconds up to ``maximum``."""
    if value is None:
        return
    if not (value == value) or value in (float("inf"), float("-inf")):  # NaN, ±inf
        raise RealPenError(f"{flag}: must be a finite number of seconds, got {value:g}")
    if value <= 0 or value > maximum:
        raise RealPenError(f"{flag}: must be > 0 and at most {maximum:g} s, got {value:g}")


def _described(description: str) -> str:
    return "" if description in ("n/a", "") else description


@device_app.command("list")
def list_pens(
    seconds: float = typer.Option(SCAN_S, "--seconds", metavar="S",
                                  help="How long to listen for Bluetooth pens."),
    ble: bool = typer.Option(True, "--ble/--no-ble", help="Also scan for Bluetooth LE pens."),
) -> None:
    """List the serial ports and the Bluetooth LE pens in reach (RealPen's service)."""
    from realpen.device.transport import BLE_PREFIX, BluetoothUnavailable, list_serial_ports, scan_ble

    _seconds("--seconds", seconds)
    ports = list_serial_ports()
    lines = ["serial ports:"]
    lines += [f"  {item.device}  {_described(item.description)}".rstrip()
              for item in ports] or ["  none"]
    if ble:
        try:
            pens = scan_ble(seconds)
        except BluetoothUnavailable as error:
            lines.append(f"Bluetooth LE: unavailable ({str(error).removeprefix('Bluetooth: ')})")
        else:
            lines.append(f"Bluetooth LE pens ({seconds:g} s scan):")
            lines += [f"  {BLE_PREFIX}{pen.name or pen.address}  {pen.address}"
                      + (f"  {pen.rssi} dBm" if pen.rssi is not None else "")
                      for pen in pens] or ["  none"]
    console.print("\n".join(lines))


@device_app.command("info")
def info(ctx: typer.Context, port: str | None = port_option()) -> None:
    """Show what the pen says of itself: name, firmware, protocol, rate, largest pattern."""
    port = _port(ctx, port)
    with _connected(ctx, port) as client:
        pen = client.info
        round_trip = client.sync()
    console.print("\n".join([
        f"pen: {pen.name or '(no name)'}",
        f"port: {port}",
        f"firmware: {pen.firmware_version}",
        f"protocol: {pen.protocol}",
        f"sample rate: {pen.sample_rate} Hz",
        f"largest pattern: {pen.max_pattern_bytes} bytes ({pen.max_pattern_s:g} s at "
        f"{pen.sample_rate} Hz)",
        f"features: {', '.join(pen.feature_names) or 'none'}",
        f"round trip: {round_trip * 1000:.2f} ms",
    ]))


@device_app.command("upload")
def upload(
    ctx: typer.Context,
    profile: str = typer.Argument(..., metavar="PROFILE",
                                  help="A pen's name (pencil, ballpoint, marker, or one "
                                       "installed) or a profile bundle (folder or .zip)."),
    port: str | None = port_option(),
) -> None:
    """Upload a profile's tactile pattern, rendered at the pen's rate.

    The pen swaps to it at its next loop; a failed upload leaves it
    playing its last good pattern.
    """
    from realpen.device.pattern import check_fits, pen_pattern
    from realpen.profile.registry import resolve_profile

    pen_profile = resolve_profile(profile)  # a bad profile is refused before the port opens
    port = _port(ctx, port)
    with _connected(ctx, port) as client:
        pen = client.info
        try:
            samples = pen_pattern(pen_profile, pen.sample_rate)
        except ParameterError as error:  # the rate is the pen's, not a flag of this command
            raise fail(profile, f"cannot be played at the pen's {pen.sample_rate} Hz: "
                                f"{error.problem}") from None
        check_fits(samples.nbytes, pen, port=port)
        start = time.perf_counter()
        with progress_bar(f"uploading {pen_profile.name}") as progress:
            pattern_id = client.upload(samples, pen.sample_rate, progress=progress)
        elapsed = time.perf_counter() - start
    console.print(f"uploaded {pen_profile.name} to {pen.name or 'the pen'} on {port}: "
                  f"{samples.nbytes} bytes ({samples.size / pen.sample_rate:g} s at "
                  f"{pen.sample_rate} Hz) in {elapsed:.2f} s "
                  f"({samples.nbytes / max(elapsed, 1e-9) / 1000:.1f} kB/s), pattern id "
                  f"{pattern_id}")


@device_app.command("play")
def play(
    ctx: typer.Context,
    gain: float = typer.Option(1.0, "--gain", metavar="G",
                               help="0 … 1 of the pen's capped full drive."),
    rate: float = typer.Option(1.0, "--rate", metavar="R",
                               help="Playback-rate factor, 0.25 … 4 (1: the pattern as stored)."),
    fade_ms: int = typer.Option(5, "--fade-ms", metavar="MS", callback=whole_number,
                                help="Ramp to the new gain over this many ms (at least 5)."),
    port: str | None = port_option(),
) -> None:
    """Loop the pen's pattern until 'realpen device stop'.

    A pen that holds no pattern yet stays silent ('realpen device upload').
    """
    from realpen.device.client import state_payload

    state_payload(True, gain, rate, fade_ms)  # bad values are refused before the port opens
    port = _port(ctx, port)
    with _connected(ctx, port) as client:
        client.set_state(True, gain, rate, fade_ms)
        client.sync()  # the pen has it, and refused nothing
        name = client.info.name or "the pen"
    console.print(f"playing on {name} ({port}): gain {gain:g}, rate {rate:g}")


@device_app.command("stop")
def stop(
    ctx: typer.Context,
    fade_ms: int = typer.Option(5, "--fade-ms", metavar="MS", callback=whole_number,
                                help="Fade out over this many ms (at least 5)."),
    port: str | None = port_option(),
) -> None:
    """Fade the pen to silence (the next play starts at the pattern's start)."""
    from realpen.device.client import state_payload

    state_payload(False, 0.0, 1.0, fade_ms)
    port = _port(ctx, port)
    with _connected(ctx, port) as client:
        client.set_state(False, 0.0, 1.0, fade_ms)
        client.sync()
        name = client.info.name or "the pen"
    console.print(f"stopped {name} ({port})")


@device_app.command("ping")
def ping(
    ctx: typer.Context,
    count: int = typer.Option(4, "--count", "-n", metavar="N", callback=whole_number,
                              help="How many PINGs to send, one after another."),
    port: str | None = port_option(),
) -> None:
    """PING the pen: the round trip of each and the pen's clock."""
    require_number("count", count, 1, MAX_PINGS)
    port = _port(ctx, port)
    trips = []
    with _connected(ctx, port) as client:
        name = client.info.name or "the pen"
        for _ in range(count):
            trip, device_us = client.ping()
            trips.append(trip)
            console.print(f"PONG from {name}: {trip * 1000:.2f} ms round trip, pen clock "
                          f"{device_us / 1e6:.6f} s")
    console.print(f"{count} PING{'s' if count > 1 else ''} over {port}: round trip min "
                  f"{min(trips) * 1000:.2f} / median {statistics.median(trips) * 1000:.2f} / "
                  f"max {max(trips) * 1000:.2f} ms")


@device_app.command("monitor")
def monitor(
    ctx: typer.Context,
    seconds: float | None = typer.Option(None, "--seconds", metavar="S",
                                         help="Stop after this many seconds (default: at "
                                              "Ctrl-C)."),
    port: str | None = port_option(),
) -> None:
    """Print the pen's events as they come, and a PING a second.

    Until Ctrl-C or --seconds. Events: boot, underruns, battery voltage,
    pattern swaps, frames the pen could not decode.
    """
    from realpen.device.transport import DeviceDisconnected

    _seconds("--seconds", seconds)
    port = _port(ctx, port)
    events, trips = 0, []
    with _connected(ctx, port) as client:
        pen = client.info
        console.print(f"monitoring {pen.name or 'the pen'} on {port} "
                      f"({'Ctrl-C stops' if seconds is None else f'for {seconds:g} s'})")
        start = time.monotonic()
        end = None if seconds is None else start + seconds
        next_ping = start
        try:
            with terminate_as_interrupt():
                while end is None or time.monotonic() < end:
                    now = time.monotonic()
                    if now >= next_ping:
                        trip, _ = client.ping()
                        trips.append(trip)
                        console.print(f"{now - start:8.2f} s  ping {trip * 1000:.2f} ms")
                        next_ping += PING_EVERY_S
                    wait = next_ping - time.monotonic()
                    if end is not None:
                        wait = min(wait, end - time.monotonic())
                    event = client.read_event(max(0.0, wait))
                    if event is not None:
                        events += 1
                        console.print(f"{event.at - start:8.2f} s  event {event}")
        except KeyboardInterrupt:
            pass
        except DeviceDisconnected as error:
            raise DeviceDisconnected(f"{error} (after {time.monotonic() - start:.1f} s of "
                                     f"monitoring)") from None
        elapsed = time.monotonic() - start
        garbled = client.decode_errors
    median = f", round trip median {statistics.median(trips) * 1000:.2f} ms" if trips else ""
    console.print(f"stopped after {elapsed:.1f} s: {events} event{'' if events == 1 else 's'}, "
                  f"{len(trips)} ping{'' if len(trips) == 1 else 's'}{median}, {garbled} "
                  f"garbled frame{'' if garbled == 1 else 's'} from the pen")


@device_app.command("sim")
def sim(
    record: Path | None = typer.Option(None, "--record", metavar="FILE.wav",
                                       help="When stopped, write what the actuator would have "
                                            "been driven with (int16 WAV at the pen's rate)."),
    trace: Path | None = typer.Option(None, "--trace", metavar="FILE.jsonl",
                                      help="Write the firmware's trace, JSON lines (SET_STATE "
                                           "receipts with the sample they affect, swaps, "
                                           "underruns)."),
    accelerometer: Path | None = typer.Option(
        None, "--accelerometer", metavar="SOURCE",
        help="A 1-3 axis recording (WAV, CSV, NPZ) the pen's simulated LIS3DH feels, looped, "
             "as while writing. Without it the sensor feels only its noise and the actuator."),
    actuator: str = typer.Option(
        "lra:f0=175,q=8", "--actuator", metavar="SPEC",
        help="The simulated pen's physical actuator (lra:f0=…,q=…, piezo:…, flat): what the "
             "firmware plays reaches the sensor through it. Hidden from hosts: "
             "'realpen actuator measure' finds it."),
    mount_g: float = typer.Option(1.0, "--mount-g", min=0.0, max=16.0,
                                  help="The actuator's acceleration at the sensor at full scale "
                                       "and resonance, in g."),
    noise_mg: float = typer.Option(5.0, "--noise-mg", min=0.0, max=1000.0,
                                   help="Sensor noise, RMS per axis, in mg."),
    rate_error: float = typer.Option(1.3, "--rate-error", min=-9.0, max=9.0,
                                     help="The sensor's true rate is 1344 Hz × (1 + this/100): "
                                          "a real LIS3DH is off by up to a few per cent."),
    no_accelerometer: bool = typer.Option(False, "--no-accelerometer",
                                          help="A pen without a sensor (CAPTURE_START is "
                                               "refused)."),
    force: bool = force_option(),
) -> None:
    """Run the pen's real firmware on a pseudo-terminal, until Ctrl-C.

    The firmware runs under the MicroPython Unix port, with a simulated
    LIS3DH accelerometer on a simulated I2C bus (register by register, as
    the real part) and a simulated actuator between what the pen plays and
    what the sensor feels. The first line printed is 'port: /dev/pts/N':
    the other device commands take it as --port ('realpen record', 'realpen
    actuator measure'), and 'realpen serve --device serial:/dev/pts/N'
    drives it from the live page. Ctrl-C or SIGTERM stops it and writes
    --record.
    """
    if record is not None and record.suffix.lower() != ".wav":
        raise fail(record, "--record writes a WAV file; give a name ending in .wav")
    if accelerometer is not None and no_accelerometer:
        raise RealPenError("--accelerometer and --no-accelerometer: give one of them")
    if accelerometer is not None and not accelerometer.is_file():
        raise fail(accelerometer, "no such file (--accelerometer)")
    check_outputs(record, trace, force=force)
    # --record is written when the pen stops: a place that takes no file must be refused now,
    # not after the session it would have recorded.
    for flag, path in (("--record", record), ("--trace", trace)):
        if path is not None:
            _check_writable_folder(flag, path)
    from realpen.device.sim import SimPen
    from realpen.device.sim_parts import actuator_biquad

    actuator_biquad(actuator, 8000)  # a spec the simulator cannot use is refused now
    pen = SimPen(record=record, trace=trace, sensor=not no_accelerometer,
                 accelerometer=accelerometer, actuator=actuator, mount_g=mount_g,
                 noise_g=noise_mg / 1000, rate_error=rate_error / 100)
    port = None
    interrupted = False
    # The first Ctrl-C (or SIGTERM) stops the pen; one more while the recording is written
    # only says so: the WAV is still written and the temporary files removed. A shell starts
    # a background job (`realpen device sim &`) with SIGINT ignored; a script that stops it
    # with SIGINT must still get the recording, so SIGINT is taken in any case.
    interrupts = InterruptOnce(f"still writing {record}, one moment" if record is not None
                               else "still stopping the simulated pen, one moment")
    with interrupts:
        try:
            pen.start()
            port = pen.port
            print(f"port: {port}", flush=True)  # the line a script reads: first, whole
            if pen.sensor:
                felt = accelerometer if accelerometer is not None else "its noise only"
                print(f"  accelerometer: LIS3DH at {pen.sensor_rate_hz:.1f} Hz true rate "
                      f"(1344 nominal), feeling {felt}; actuator {actuator}", flush=True)
            print(f"  the pen's firmware runs there ('realpen device --port {port} info'; "
                  f"the live app: 'realpen serve --device serial:{port}'); Ctrl-C stops it"
                  f"{f' and writes {record}' if record else ''}", flush=True)
            while pen.alive:
                time.sleep(0.1)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            interrupts.hold()
            pen.stop()  # also after a failure: the firmware never outlives the command
    if not interrupted:  # it died (stop() has written the recording of what it played)
        wrote = f"; {_wrote(record)}" if record is not None else ""
        raise RealPenError(f"{port}: the simulated pen's firmware exited by itself (code "
                           f"{pen.returncode}){wrote}")
    if record is not None:
        console.print(_wrote(record))


def _wrote(record: Path) -> str:
    """What the WAV just written holds, in words."""
    import soundfile as sf

    written = sf.info(str(record))
    return (f"wrote {record}: {written.frames} samples at {written.samplerate} Hz "
            f"({written.frames / written.samplerate:.2f} s)")


def _check_writable_folder(flag: str, path: Path) -> None:
    """Refuse ``path`` unless its folder exists and takes a new file (one is made and removed).

    Raises:
        RealPenError: one line naming ``path`` and the folder.
    """
    folder = Path(os.path.abspath(path)).parent
    if not folder.is_dir():
        what = "does not exist" if not folder.exists() else "is not a folder"
        raise fail(path, f"{flag}: {folder} {what}")
    try:
        handle, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    except OSError as error:  # /proc says ENOENT for a folder that is there: say it plainly
        why = "it takes no new files" if error.errno == errno.ENOENT else error.strerror or error
        raise fail(path, f"{flag}: cannot create a file in {folder} ({why})") from None
    os.close(handle)
    os.unlink(probe)


def register(app: typer.Typer) -> None:
    """Add ``realpen device`` to the root command."""
    app.add_typer(device_app, name="device")
