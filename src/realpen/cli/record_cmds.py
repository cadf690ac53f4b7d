"""``realpen record``: capture the pen's accelerometer into a WAV, NPZ or CSV file.

The work is :func:`realpen.device.capture.record` and :func:`~realpen.device.capture.write_capture`;
this module parses the options, shows the live meter and prints the summary. Only typer, rich
(when drawing) and the standard library are imported at module level.
"""

import contextlib
import math
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import typer

from realpen.cli.common import check_outputs, console, err_console, force_option, whole_number
from realpen.cli.device_cmds import DEFAULT_TIMEOUT_S, MAX_TIMEOUT_S, PORT_ENV, PORT_HELP
from realpen.cli.device_cmds import _check_writable_folder as check_writable_folder
from realpen.errors import RealPenError, fail

__all__ = ["record", "register", "StopOnSignal"]

RANGES = (2, 4, 8, 16)  # realpen.device.protocol.CAPTURE_RANGES (checked again by the library)
REFRESH_S = 0.25  # the live meter's redraw interval
BAR_WIDTH = 24


class StopOnSignal:
    """Within the block the first SIGINT, SIGTERM or SIGHUP sets :attr:`stop` (the capture ends
    at its next block and what it holds is written); later ones only print ``note`` on stderr.
    The previous handlers come back at the end.

    Args:
        note: what a later signal prints, e.g. ``"still writing rec.wav, one moment"``.
    """

    def __init__(self, note: str) -> None:
        self.note = note
        self.stop = threading.Event()
        self._previous: dict = {}

    def _signal(self, signum, frame) -> None:
        if not self.stop.is_set():
            self.stop.set()
            return
        with contextlib.suppress(OSError, RuntimeError, ValueError):  # stderr gone or busy
            print(self.note, file=sys.stderr, flush=True)

    def __enter__(self) -> "StopOnSignal":
        wanted = [sig for sig in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None))
                  if sig is not None]
        try:
            for sig in wanted:
                self._previous[sig] = signal.signal(sig, self._signal)
        except ValueError:  # not the main thread (an embedding program): leave signals alone
            self.__exit__()
        return self

    def __exit__(self, *exc_info) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()


def record(
    output: Path = typer.Option(..., "--output", "-o", metavar="FILE",
                                help="Where to write the capture: .wav (float32, the exact rate "
                                     "and provenance in its metadata), .npz or .csv (time_s,x,y,z)."),
    seconds: float = typer.Option(..., "--seconds", metavar="S",
                                  help="How long to record (Ctrl-C stops sooner and keeps what "
                                       "was captured)."),
    range_g: int = typer.Option(2, "--range", metavar="G", callback=whole_number,
                                help="Full-scale range in g: 2, 4, 8 or 16 (larger clips less, "
                                     "resolves less)."),
    port: str | None = typer.Option(None, "--port", "-p", envvar=PORT_ENV, metavar="PORT",
                                    help=PORT_HELP),
    timeout: float = typer.Option(DEFAULT_TIMEOUT_S, "--timeout", metavar="S",
                                  help="Seconds to wait for each reply of the pen."),
    force: bool = force_option(),
) -> None:
    """Record the pen's accelerometer (LIS3DH, 1344 Hz) into a file.

    A live meter shows the level and clipping per axis while it runs. The
    file's rate is the sensor's true rate, estimated from the pen's clock;
    gaps (blocks lost on the link, sensor overruns) are reported with where
    they are and written as 0. Ctrl-C stops early and writes what was
    captured. The file is written whole or not at all.
    """
    from realpen.device.capture import CAPTURE_SUFFIXES, MAX_RECORD_S

    if output.suffix.lower() not in CAPTURE_SUFFIXES:
        raise fail(output, f"record writes {', '.join(CAPTURE_SUFFIXES[:-1])} or "
                           f"{CAPTURE_SUFFIXES[-1]}; give a name ending in one of them")
    if not (math.isfinite(seconds) and 0 < seconds <= MAX_RECORD_S):
        raise RealPenError(f"--seconds: must be > 0 and at most {MAX_RECORD_S:g} s, got "
                           f"{seconds:g}")
    if range_g not in RANGES:
        raise RealPenError(f"--range: must be one of {', '.join(map(str, RANGES))} g, got "
                           f"{range_g}")
    if not (math.isfinite(timeout) and 0 < timeout <= MAX_TIMEOUT_S):
        raise RealPenError(f"--timeout: must be > 0 and at most {MAX_TIMEOUT_S:g} s, got "
                           f"{timeout:g}")
    if port is None or not port.strip():
        raise RealPenError(f"--port: give the pen's port, a serial device (/dev/ttyACM0, COM3) or "
                           f"ble:NAME (or set {PORT_ENV}); 'realpen device list' shows them")
    check_outputs(output, force=force)
    # The file is written after the take: a place that takes no file is refused before it.
    check_writable_folder("--output", output)

    from realpen.device.capture import record as record_capture
    from realpen.device.capture import write_capture
    from realpen.device.client import PenClient
    from realpen.device.transport import open_transport

    with StopOnSignal(f"still stopping the capture and writing {output}, one moment") as signals:
        with PenClient(open_transport(port), timeout=timeout) as client:
            pen = client.hello()
            if signals.stop.is_set():  # Ctrl-C while connecting
                raise KeyboardInterrupt
            with _live_meter(pen.name or "the pen", port, seconds, range_g) as on_block:
                capture = record_capture(client, seconds, range_g=range_g, on_block=on_block,
                                         stop_event=signals.stop)
        if capture.frames == 0:
            raise KeyboardInterrupt  # stopped before the first block: nothing to write
        write_capture(capture, output)
    console.print("\n".join(_summary(capture, pen.name or "the pen", port, output)))


@contextlib.contextmanager
def _live_meter(pen: str, port: str, seconds: float, range_g: int) -> Iterator:
    """Yield the ``on_block`` callback that redraws the live meter on stderr (only on a
    terminal; elsewhere None)."""
    if not err_console.is_terminal:
        yield None
        return
    from rich.live import Live

    started = time.monotonic()
    with Live(console=err_console.rich, auto_refresh=False, transient=True) as live:
        drawn = [0.0]

        def on_block(block, assembler) -> None:
            now = time.monotonic()
            if now - drawn[0] >= REFRESH_S:
                drawn[0] = now
                live.update(_meter(assembler, pen, port, seconds, range_g, now - started),
                            refresh=True)

        yield on_block


def _meter(assembler, pen: str, port: str, seconds: float, range_g: int, elapsed: float):
    """The live meter: a level bar per axis, clipping, progress, blocks, rate and gaps."""
    from rich.console import Group
    from rich.progress_bar import ProgressBar
    from rich.table import Table
    from rich.text import Text

    level = assembler.level()
    table = Table.grid(padding=(0, 1))
    for name, rms, peak, clipped in zip("xyz", level.rms_g, level.peak_g, level.clipped,
                                        strict=True):
        hot = clipped or peak >= 0.95 * range_g
        style = "red" if hot else "green"
        table.add_row(Text(name), ProgressBar(total=range_g, completed=min(peak, range_g),
                                              width=BAR_WIDTH, complete_style=style,
                                              finished_style="red"),
                      Text(f"peak {peak:5.2f} g  rms {rms:6.3f} g  clipped {clipped}"))
    recorded = assembler.duration_s
    table.add_row(Text("time"), ProgressBar(total=seconds, completed=min(recorded, seconds),
                                            width=BAR_WIDTH, complete_style="cyan",
                                            finished_style="cyan"),
                  Text(f"{recorded:6.1f} / {seconds:g} s  ({elapsed:.1f} s elapsed)"))
    rate, sd = assembler.rate()
    rate_text = f"{rate:.2f} ± {sd:.2f} Hz" if math.isfinite(sd) else "estimating"
    gaps = assembler.gaps()
    return Group(Text(f"recording {pen} on {port}, ±{range_g} g; Ctrl-C stops and keeps what "
                      f"was captured"),
                 table,
                 Text(f"blocks {assembler.blocks}  rate {rate_text}  gaps {len(gaps)} "
                      f"({sum(g.samples_lost for g in gaps)} samples)"))


def _summary(capture, pen: str, port: str, output: Path) -> list[str]:
    """What was recorded, in lines: samples, duration, rate, gaps, clipping, the file."""
    stopped = ("stopped early (Ctrl-C): kept what was captured; " if capture.interrupted
               else "")
    lines = [f"{stopped}recorded {capture.frames:,} samples per axis ({capture.duration_s:.2f} s) "
             f"from {pen} on {port}, range ±{capture.range_g} g, {capture.blocks} blocks"]
    if math.isfinite(capture.rate_sd_hz):
        lines.append(f"rate: {capture.rate_hz:.3f} ± {capture.rate_sd_hz:.3f} Hz from the pen's "
                     f"clock (nominal {capture.nominal_rate_hz:g} Hz, "
                     f"{(capture.rate_hz / capture.nominal_rate_hz - 1) * 100:+.2f} %)")
    else:
        lines.append(f"rate: too few blocks to estimate it; written at the nominal "
                     f"{capture.nominal_rate_hz:g} Hz")
    if capture.gaps:
        lines.append(f"gaps: {len(capture.gaps)}, {capture.samples_lost:,} samples missing "
                     f"(written as 0):")
        for gap in capture.gaps[:20]:
            what = ("blocks not received" if gap.kind == "dropped"
                    else "sensor FIFO overrun, counted from the pen's clock")
            lines.append(f"  at {gap.at_s:.3f} s: {gap.samples_lost} samples ({what})")
        if len(capture.gaps) > 20:
            lines.append(f"  … and {len(capture.gaps) - 20} more")
    else:
        lines.append("gaps: none")
    if any(capture.clipped):
        counts = ", ".join(f"{axis} {count}" for axis, count in zip("xyz", capture.clipped,
                                                                     strict=True))
        larger = [g for g in RANGES if g > capture.range_g]
        advice = f"; try --range {larger[0]}" if larger else ""
        lines.append(f"clipping: samples at the ±{capture.range_g} g limit: {counts}{advice}")
    else:
        lines.append("clipping: none")
    lines += [f"note: {note}" for note in capture.notes]
    lines.append(f"wrote {output}: {_file_kind(output, capture.rate_hz)}")
    return lines


def _file_kind(output: Path, rate_hz: float) -> str:
    suffix = output.suffix.lower()
    if suffix == ".wav":
        return (f"float32 WAV, x, y, z in m/s², {round(rate_hz)} Hz in its header and the exact "
                f"rate with the provenance in its comment (RealPen reads the exact rate)")
    if suffix == ".npz":
        return "NPZ, x, y, z in m/s², the exact rate and the provenance"
    return "CSV time_s,x,y,z in m/s² (the rate in the time column; CSV holds no provenance)"


def register(app: typer.Typer) -> None:
    """Add ``realpen record`` to the root command."""
    app.command()(record)
