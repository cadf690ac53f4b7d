"""``realpen hatt list | synth``: Penn Haptic Texture Toolkit (HaTT) texture models.

Only typer and the standard library are imported here; the reader and the synthesis
(:mod:`realpen.datasets.hatt`, numpy, scipy) are imported inside the commands.
"""

from pathlib import Path

import typer

from realpen.cli.common import check_outputs, command_group, console, force_option, whole_number
from realpen.errors import fail

__all__ = ["hatt_app", "register"]

hatt_app = command_group("HaTT texture models (Models_<texture>.xml): the (speed, force) grid, "
                         "and stylus vibration synthesised from it.")

MODEL_HELP = "A HaTT model file, e.g. 'Models_Book.xml'."
SUFFIXES = (".wav", ".npz")


@hatt_app.command("list")
def list_models(
    model_file: Path = typer.Argument(..., metavar="MODEL.xml", help=MODEL_HELP),
) -> None:
    """Print the (speed mm/s, force N) grid of a model file, one row per ARMA model."""
    import math

    from rich.table import Table

    from realpen.datasets.hatt import load_hatt

    models = load_hatt(model_file)
    low, high = models.vertices.min(axis=0), models.vertices.max(axis=0)
    console.print(f"{model_file}: '{models.material}', {len(models.models)} models at "
                  f"{models.rate:g} Hz, speed {low[0]:g}–{high[0]:g} mm/s, force "
                  f"{low[1]:g}–{high[1]:g} N, μ = {models.mu:g}")
    table = Table("model", "speed mm/s", "force N", "AR/MA order", "rms m/s²")
    order = sorted(range(len(models.models)), key=lambda k: tuple(models.vertices[k]))
    for index in order:  # by speed, then force: the grid reads row by row
        model = models.models[index]
        table.add_row(str(index + 1), f"{model.speed:.1f}", f"{model.force:.3f}",
                      f"{len(model.ar) - 1}/{len(model.ma) - 1}",
                      f"{math.sqrt(model.output_variance()):.3g}")
    console.print(table)


@hatt_app.command("synth")
def synth(
    model_file: Path = typer.Argument(..., metavar="MODEL.xml", help=MODEL_HELP),
    speed: float = typer.Option(..., "--speed", metavar="MM_S",
                                help="Tangential speed of the stylus in mm/s."),
    force_n: float = typer.Option(..., "--force", metavar="N",
                                  help="Normal force of the stylus in N."),
    seconds: float = typer.Option(..., "--seconds", metavar="S",
                                  help="Length of the recording in seconds."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="Recording to write: .wav (32-bit float, in m/s²) or .npz "
                                     "(samples, rate, axes, units)."),
    rate: int | None = typer.Option(None, "--rate", metavar="HZ",
                                    help="Resample to this rate in Hz (polyphase; default: "
                                         "the model's own, 1000 Hz in HaTT).",
                                    callback=whole_number),
    seed: int = typer.Option(0, "--seed", help="Seed of the white-noise excitation.",
                             callback=whole_number),
    overwrite: bool = force_option("--overwrite"),
) -> None:
    """Synthesise stylus vibration on a texture at one speed and force, as a recording.

    Speeds and forces outside the modelled range use the model at its edge (a note says so).
    The result is a one-axis recording (DFT321, m/s²) that 'realpen analyze' and 'realpen
    tactile' read. --force is the normal force here; --overwrite replaces an existing output.
    """
    import numpy as np

    from realpen.datasets.hatt import load_hatt, synthesize
    from realpen.io.files import wav_bytes, write_files
    from realpen.io.recording import save_npz

    check_outputs(output, force=overwrite, force_flag="--overwrite",
                  inputs={"model file": model_file})
    suffix = output.suffix.lower()
    if suffix not in SUFFIXES:
        raise fail(output, f"write a {' or '.join(SUFFIXES)} file")
    models = load_hatt(model_file)
    recording = synthesize(models, speed, force_n, seconds, seed=seed)
    if rate is not None:
        from realpen.dsp.filters import resample

        recording = resample(recording, rate)
    if suffix == ".npz":
        save_npz(recording, output)
    else:
        write_files({output: wav_bytes(recording.mono, int(round(recording.rate)))})
    rms = float(np.sqrt(np.mean(recording.mono ** 2)))
    console.print(f"wrote {output}: {recording.duration:.2f} s at {recording.rate:g} Hz, "
                  f"{recording.source}, seed {seed}, rms {rms:.3g} m/s²")
    low, high = models.vertices.min(axis=0), models.vertices.max(axis=0)
    for name, value, unit, lo, hi in (("speed", speed, "mm/s", low[0], high[0]),
                                      ("force", force_n, "N", low[1], high[1])):
        if not lo <= value <= hi:
            console.print(f"note: {name} {value:g} {unit} is outside the modelled "
                          f"{lo:g}–{hi:g} {unit}; the model at the edge was used")


def register(app: typer.Typer) -> None:
    """Add ``realpen hatt`` to the root command."""
    app.add_typer(hatt_app, name="hatt")
