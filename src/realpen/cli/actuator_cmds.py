"""``realpen actuator measure | verify``: the pen's actuator, measured by the pen's accelerometer.

The work is :func:`realpen.device.measure_actuator.measure_actuator` and
:func:`~realpen.device.measure_actuator.verify_actuator`; this module parses the options, shows
the progress and prints the summary. Only typer and the standard library are imported at module
level.
"""

import math
from pathlib import Path

import typer

from realpen.cli.common import (
    check_outputs,
    command_group,
    console,
    force_option,
    progress_bar,
    whole_number,
)
from realpen.cli.device_cmds import DEFAULT_TIMEOUT_S, MAX_TIMEOUT_S, PORT_ENV, PORT_HELP
from realpen.errors import RealPenError, fail

__all__ = ["actuator_app", "register"]

actuator_app = command_group(
    "The pen's actuator: measure its response with the pen's own accelerometer (a swept sine), "
    "and check that the equalisation makes a multisine arrive flat.")

RANGES = (2, 4, 8, 16)  # realpen.device.protocol.CAPTURE_RANGES (checked again by the library)
MAX_REPEATS = 100  # realpen.device.measure_actuator.MAX_REPEATS


def _port_option():
    return typer.Option(None, "--port", "-p", envvar=PORT_ENV, metavar="PORT", help=PORT_HELP)


def _timeout_option():
    return typer.Option(DEFAULT_TIMEOUT_S, "--timeout", metavar="S",
                        help="Seconds to wait for each reply of the pen.")


def _repeats_option(loop: str):
    return typer.Option(4, "--repeats", metavar="N", callback=whole_number,
                        help=f"{loop} loops analysed (after one skipped while the actuator "
                             f"settles), 2 … {MAX_REPEATS}.")


def _gain_option():
    return typer.Option(0.8, "--gain", metavar="G",
                        help="Drive, 0 … 1 of the pen's capped full drive (lower it when the "
                             "accelerometer clips).")


def _range_option():
    return typer.Option(2, "--range", metavar="G",
                        help="The accelerometer's full-scale range in g: 2, 4, 8 or 16.")


def _check(port: str | None, repeats: int, gain: float, range_g: int, timeout: float) -> str:
    """Refuse bad options before the port opens; the port to open."""
    if not 2 <= repeats <= MAX_REPEATS:
        raise RealPenError(f"--repeats: must be 2 … {MAX_REPEATS}, got {repeats}")
    if not (math.isfinite(gain) and 0 < gain <= 1):
        raise RealPenError(f"--gain: must be > 0 and at most 1, got {gain:g}")
    if range_g not in RANGES:
        raise RealPenError(f"--range: must be one of {', '.join(map(str, RANGES))} g, got "
                           f"{range_g}")
    if not (math.isfinite(timeout) and 0 < timeout <= MAX_TIMEOUT_S):
        raise RealPenError(f"--timeout: must be > 0 and at most {MAX_TIMEOUT_S:g} s, got "
                           f"{timeout:g}")
    if port is None or not port.strip():
        raise RealPenError(f"--port: give the pen's port, a serial device (/dev/ttyACM0, COM3) or "
                           f"ble:NAME (or set {PORT_ENV}); 'realpen device list' shows them")
    return port


def _check_plot(plot: Path | None) -> None:
    if plot is not None:
        from realpen.display.images import image_kind

        image_kind(plot)  # an image type matplotlib cannot write is refused now, not after


def _connected(port: str, timeout: float):
    from realpen.device.client import PenClient
    from realpen.device.transport import open_transport

    return PenClient(open_transport(port), timeout=timeout)


def _print_notes(notes) -> None:
    for note in notes:
        console.print(f"note: {note}")


@actuator_app.command("measure")
def measure(
    output: Path = typer.Option(..., "--output", "-o", metavar="FILE.csv",
                                help="Where to write the measured response: the CSV that "
                                     "--actuator reads (frequency_hz, response_db normalised to "
                                     "0 dB at the peak, coherence, distortion_db)."),
    plot: Path | None = typer.Option(None, "--plot", metavar="FILE.png",
                                     help="Also draw the method's Figure 2c: the response with "
                                          "its fitted resonance, coherence, distortion and the "
                                          "equalising weighting."),
    repeats: int = _repeats_option("Sweep"),
    gain: float = _gain_option(),
    range_g: int = _range_option(),
    cap_db: float = typer.Option(20.0, "--cap-db", metavar="DB",
                                 help="The weighting's cap drawn in --plot, dB."),
    port: str | None = _port_option(),
    timeout: float = _timeout_option(),
    force: bool = force_option(),
) -> None:
    """Measure the pen's actuator with the pen's own accelerometer.

    The pen loops an exponential sine sweep (15–600 Hz, 2 s) through its
    actuator while its accelerometer records at 1344 Hz. Each loop is
    deconvolved with the sweep, so harmonic distortion separates from the
    linear response; |H(f)| over 20–500 Hz is averaged over the loops, with
    the coherence between them and the distortion per frequency. Prints the
    fitted resonance (f0, Q) and writes the CSV that --actuator accepts.
    """
    port = _check(port, repeats, gain, range_g, timeout)
    if output.suffix.lower() != ".csv":
        raise fail(output, "the measured response is written as CSV; give a name ending in .csv")
    if not (math.isfinite(cap_db) and 0 <= cap_db <= 60):
        raise RealPenError(f"--cap-db: must be 0 … 60 dB, got {cap_db:g}")
    _check_plot(plot)
    check_outputs(output, plot, force=force)

    from realpen.device.measure_actuator import measure_actuator
    from realpen.tactile.measure import write_response_csv

    with _connected(port, timeout) as client:
        pen = client.hello()
        with progress_bar(f"sweeping {pen.name or 'the pen'}") as progress:
            measured = measure_actuator(client, repeats=repeats, gain=gain, range_g=range_g,
                                        progress=progress)
    write_response_csv(output, measured.response)
    if plot is not None:
        _save_measure_plot(measured, plot, cap_db)
    console.print("\n".join(_measure_summary(measured, port, output, plot)))
    _print_notes(measured.notes)


def _save_measure_plot(measured, plot: Path, cap_db: float) -> None:
    from realpen.display.actuator import plot_measured_actuator
    from realpen.display.images import save_figure

    axes = plot_measured_actuator(measured.response, fit=measured.fit, cap_db=cap_db)
    axes[0].figure.suptitle(f"{measured.pen or 'the pen'}: actuator measured by its "
                            f"accelerometer (gain {measured.gain:g})")
    save_figure(axes[0].figure, plot)


def _measure_summary(measured, port: str, output: Path, plot: Path | None) -> list[str]:
    import numpy as np

    response, fit, capture = measured.response, measured.fit, measured.capture
    freqs = response.frequency_hz
    dropped = response.periods_incomplete + response.periods_slipped
    lines = [
        f"measured the actuator of {measured.pen or 'the pen'} on {port}: {response.periods} "
        f"sweeps of {response.sweep.period_s:g} s at gain {measured.gain:g}"
        + (f" ({dropped} more left out)" if dropped else "")
        + f", accelerometer at {response.capture_rate_hz:.3f} Hz (timestamps: "
          f"{capture.rate_hz:.3f} ± {capture.rate_sd_hz:.3f} Hz)",
        f"resonance: f0 {fit.f0_hz:.1f} Hz, Q {fit.q:.2f} (the model fits within "
        f"{fit.residual_db:.1f} dB RMS)",
        f"coherence over {freqs[0]:.0f}–{freqs[-1]:.0f} Hz: min {response.coherence.min():.3f}, "
        f"median {float(np.median(response.coherence)):.3f}; SNR {response.snr_db:.0f} dB",
        _distortion_line(response),
        f"wrote {output} ({len(freqs)} frequencies; use it as --actuator {output})",
    ]
    if plot is not None:
        lines.append(f"wrote {plot}")
    return lines


def _distortion_line(response) -> str:
    import numpy as np

    measurable = np.isfinite(response.distortion_floor_db)
    if not measurable.any():
        return "distortion: not measurable (the sensor's band holds no 2nd harmonic)"
    where = response.frequency_hz[measurable]
    span = f"{where[0]:.0f}–{where[-1]:.0f} Hz"
    found = np.isfinite(response.distortion_db)
    if not found.any():
        return f"distortion (2nd + 3rd harmonics): under the noise floor over {span}"
    worst = int(np.nanargmax(response.distortion_db))
    return (f"distortion (2nd + 3rd harmonics): at most {response.distortion_db[worst]:.1f} dB "
            f"({100 * 10 ** (response.distortion_db[worst] / 20):.1f} %) at "
            f"{response.frequency_hz[worst]:.0f} Hz; under the noise floor elsewhere in {span}")


@actuator_app.command("verify")
def verify(
    actuator: Path = typer.Option(..., "--actuator", metavar="FILE.csv",
                                  help="The measured response ('realpen actuator measure')."),
    plot: Path | None = typer.Option(None, "--plot", metavar="FILE.png",
                                     help="Also draw each component's arrived level."),
    max_spread_db: float | None = typer.Option(
        None, "--max-spread-db", metavar="DB",
        help="Exit with code 1 when the spread (max − min over the band) is larger."),
    repeats: int = _repeats_option("Multisine"),
    gain: float = _gain_option(),
    range_g: int = _range_option(),
    cap_db: float = typer.Option(30.0, "--cap-db", metavar="DB",
                                 help="The equalisation's largest boost, dB."),
    port: str | None = _port_option(),
    timeout: float = _timeout_option(),
    force: bool = force_option(),
) -> None:
    """Check a measured response: play a multisine equalised by it.

    The pen loops a multisine over 80–500 Hz (32 components, weighted by
    1/|H| of --actuator) while its accelerometer records; prints how flat it
    arrives: each component's level about the mean, the spread (max − min)
    and the largest deviation (± dB).
    """
    port = _check(port, repeats, gain, range_g, timeout)
    if max_spread_db is not None and not (math.isfinite(max_spread_db) and max_spread_db > 0):
        raise RealPenError(f"--max-spread-db: must be a positive number of dB, got "
                           f"{max_spread_db:g}")
    if not (math.isfinite(cap_db) and 0 <= cap_db <= 60):
        raise RealPenError(f"--cap-db: must be 0 … 60 dB, got {cap_db:g}")
    _check_plot(plot)
    check_outputs(plot, force=force, inputs={"actuator response": actuator})

    from realpen.device.measure_actuator import verify_actuator
    from realpen.tactile.actuator import load_measured

    response = load_measured(actuator)  # a bad CSV is refused before the port opens
    with _connected(port, timeout) as client:
        pen = client.hello()
        with progress_bar(f"playing the equalised multisine on {pen.name or 'the pen'}") \
                as progress:
            check = verify_actuator(client, response, repeats=repeats, gain=gain,
                                    range_g=range_g, cap_db=cap_db, progress=progress)
    if plot is not None:
        from realpen.display.actuator import plot_flatness
        from realpen.display.images import save_figure

        axis = plot_flatness(check.flatness)
        save_figure(axis.figure, plot)
    result = check.flatness
    band = f"{check.multisine.band_hz[0]:g}–{check.multisine.band_hz[1]:g} Hz"
    console.print("\n".join([
        f"equalised multisine ({len(result.frequency_hz)} components over {band}, equalised by "
        f"{actuator}) on {check.pen or 'the pen'} ({port}), {result.periods} loops:",
        f"arrived within ±{result.deviation_db:.1f} dB of its mean level (spread "
        f"{result.spread_db:.1f} dB)",
        *([f"wrote {plot}"] if plot is not None else []),
    ]))
    _print_notes(check.notes)
    if max_spread_db is not None and result.spread_db > max_spread_db:
        console.print(f"the spread {result.spread_db:.1f} dB exceeds --max-spread-db "
                      f"{max_spread_db:g}")
        raise typer.Exit(1)


def register(app: typer.Typer) -> None:
    """Add ``realpen actuator`` to the root command."""
    app.add_typer(actuator_app, name="actuator")
