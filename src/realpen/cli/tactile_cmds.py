"""``realpen analyze`` and ``realpen tactile [build] | render``.

``realpen tactile RECORDING ...`` is short for ``realpen tactile build RECORDING ...``. Only
typer and the standard library are imported here; the library (numpy, scipy, soundfile) is
imported inside the commands, so ``realpen --help`` stays fast.
"""

from pathlib import Path

import typer

from realpen.cli.common import (
    PROGRESS_AFTER_S,
    DefaultCommandGroup,
    check_outputs,
    command_group,
    console,
    force_option,
    progress_bar,
    whole_number,
)
from realpen.cli.recording_options import even_grid_option, max_interpolated_option, read_recording

AXIS_HELP = "How axes become one: dft321 (default for several axes), magnitude, or x|y|z."
# The study-1 conditions (principal frequencies × sub-patterns × unit length) and the model,
# from the numpy-free defaults: help stays fast.
from realpen.defaults import CONDITIONS, RECOMMENDED_MODEL  # noqa: E402

__all__ = ["tactile_app", "model_option", "model_options", "analyze", "tactile", "render", "register"]

CONDITION_HELP = "Study-1 preset: " + ", ".join(
    f"{key}={top}×{subpatterns}×{unit_ms:g}ms"
    for key, (top, subpatterns, unit_ms) in CONDITIONS.items()) + " (default B)."
MODEL_HELP = ("sines+residual (the default: the method's principal frequencies plus the noise "
              "floor between them, as shaped noise; a felt spectrum 2.3× closer to real paper "
              "in bench_fidelity) | sines (the method exactly; the default with --condition, "
              "whose A–F are the study's stimuli).")


def model_option():
    """The ``--model`` option of the commands that build patterns (default: sines+residual,
    or sines with a study condition)."""
    return typer.Option(None, "--model", help=MODEL_HELP, show_default=False)


def model_options(model: str | None, condition: str | None) -> dict:
    """``model=`` for :class:`~realpen.tactile.conditions.TactileParams`: the one given, else
    the method's sines for a study condition (A–F are the study's stimuli) and the
    recommended model otherwise."""
    if model is None:
        model = "sines" if condition is not None else RECOMMENDED_MODEL
    return {"model": model}


class _BuildByDefault(DefaultCommandGroup):
    """``realpen tactile RECORDING ...`` runs ``tactile build``."""

    default_command = "build"


tactile_app = command_group(
    "Tactile patterns: `realpen tactile RECORDING -o pattern.wav` (build, the default) makes a "
    "recording's looping pattern; `realpen tactile render PROFILE --trajectory STROKE.csv -o "
    "out.wav` gives the feel along a stroke.", cls=_BuildByDefault)


def analyze(
    recording: Path = typer.Argument(..., help="Vibration recording: WAV/FLAC, CSV or NPZ."),
    unit_ms: float = typer.Option(100.0, "--unit-ms", help="Unit sequence length in ms."),
    top: int = typer.Option(10, "--top", help="Principal frequencies per unit.",
                            callback=whole_number),
    subpatterns: int = typer.Option(15, "--subpatterns", help="Consecutive units to select.",
                                    callback=whole_number),
    highpass_hz: float = typer.Option(30.0, "--highpass", help="High-pass cutoff in Hz."),
    axis: str | None = typer.Option(None, "--axis", help=AXIS_HELP),
    select: str = typer.Option("stationary", "--select",
                               help="Which units: stationary (most stationary run) or middle."),
    rate: float | None = typer.Option(None, "--rate",
                                      help="Sampling rate in Hz of a CSV with no time column."),
    even_grid: str | None = even_grid_option(),
    max_interpolated_pct: float = max_interpolated_option(),
    analysis_rate: float | None = typer.Option(
        None, "--analysis-rate", help="Resample to this rate in Hz first (reads the whole "
                                      "recording into memory, within the in-memory limits)."),
    json_out: Path | None = typer.Option(None, "--json",
                                         help="Write the analysis of every unit as JSON."),
    every_unit: bool = typer.Option(False, "--all", help="Print every unit, not only the "
                                                         "selected ones."),
    force: bool = force_option(),
) -> None:
    """Print the principal frequencies of the selected unit sequences (--all: of every unit).

    The recording is read in blocks: memory grows only with the per-unit results (about 7 MB
    an hour of recording; --all prints a table of every unit, which takes more).
    Each unit's DFT321 power spectrum is the sum of its axes' unit spectra.
    --analysis-rate resamples the whole recording in memory first.
    """
    from rich.table import Table

    from realpen.dsp.filters import resample
    from realpen.dsp.stream import analyze_stream, combined_name
    from realpen.io.blocks import ArrayStream
    from realpen.io.files import atomic_path
    from realpen.io.recording import Recording, load_recording

    check_outputs(json_out, force=force, inputs={"recording": recording})
    stream = read_recording(recording, rate, even_grid, max_interpolated_pct)
    rate_in, axes_in = stream.rate, stream.axes
    source = stream
    if analysis_rate is not None:
        # Resampling needs the whole signal: the in-memory path, with its limits.
        whole = (Recording(stream.samples, stream.rate, stream.axes, stream.units, str(recording))
                 if isinstance(stream, ArrayStream) else load_recording(recording, rate=rate))
        loaded = resample(whole, analysis_rate, parameter="analysis_rate")
        source = ArrayStream(loaded.samples, loaded.rate, loaded.axes, source=str(recording))
    with progress_bar("analysing", stream.duration_hint > PROGRESS_AFTER_S) as progress:
        result = analyze_stream(source, unit_ms=unit_ms, top=top, count=subpatterns,
                                selection=select, fmin=highpass_hz, highpass_hz=highpass_hz,
                                axis=axis, progress=progress)
    duration = source.frames / source.rate  # known once the whole recording has been read
    if json_out is not None:
        # A unit at a time: a day's report as one document would take gigabytes.
        with atomic_path(json_out) as tmp, open(tmp, "w", encoding="utf-8") as handle:
            handle.writelines(result.json_chunks())
    first, last = int(result.selected[0]), int(result.selected[-1])
    console.print(f"{recording}: {duration:.2f} s, {len(axes_in)} axis(es) "
                  f"({', '.join(axes_in)}) at {rate_in:g} Hz → "
                  f"{combined_name(axes_in, axis)}, high-pass {highpass_hz:g} Hz")
    console.print(f"{len(result.starts_s)} units of {unit_ms:g} ms; selected units {first}–{last} "
                  f"({result.starts_s[first]:.2f}–{result.starts_s[last] + unit_ms / 1000:.2f} s, "
                  f"{select})")
    shown = range(len(result.starts_s)) if every_unit else result.selected
    chosen = set(int(i) for i in result.selected)
    table = Table("unit", "start s", f"principal frequencies, Hz (strongest first, top {top})")
    for index in shown:
        freqs, _ = result.unit(int(index))
        # With --all, a star marks the units the pattern would use.
        label = f"{int(index)}{'*' if every_unit and int(index) in chosen else ''}"
        table.add_row(label, f"{result.starts_s[index]:.2f}", " ".join(f"{f:.1f}" for f in freqs))
    console.print(table)
    if json_out is not None:
        console.print(f"wrote {json_out}")


@tactile_app.command("build")
def tactile(
    recording: Path = typer.Argument(..., help="Vibration recording: WAV/FLAC, CSV or NPZ."),
    output: Path = typer.Option(..., "-o", "--output", help="Pattern WAV to write."),
    actuator: str = typer.Option("lra:f0=175,q=8", "--actuator",
                                 help="lra:f0=..,q=.. | piezo:f0=..,q=.. | flat | measured.csv"),
    condition: str | None = typer.Option(None, "--condition", help=CONDITION_HELP),
    top: int | None = typer.Option(None, "--top", help="Principal frequencies per sub-pattern.",
                                   callback=whole_number),
    subpatterns: int | None = typer.Option(None, "--subpatterns", help="Sub-patterns (K).",
                                           callback=whole_number),
    unit_ms: float | None = typer.Option(None, "--unit-ms", help="Sub-pattern length in ms."),
    rate: int = typer.Option(8000, "--rate", help="Output rate in Hz.", callback=whole_number),
    boundary: str = typer.Option("crossfade", "--boundary", help="crossfade | hard."),
    crossfade_ms: float = typer.Option(5.0, "--crossfade-ms", help="Crossfade length in ms."),
    amplitude: str = typer.Option("sqrt", "--amplitude",
                                  help="sqrt (∝ √power, energy-preserving) | power (literal)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the random phases.",
                             callback=whole_number),
    cap_db: float = typer.Option(20.0, "--cap-db", help="Cap of the actuator weighting in dB."),
    select: str = typer.Option("stationary", "--select", help="stationary | middle."),
    highpass_hz: float = typer.Option(30.0, "--highpass", help="High-pass cutoff in Hz."),
    axis: str | None = typer.Option(None, "--axis", help=AXIS_HELP),
    input_rate: float | None = typer.Option(
        None, "--input-rate", help="Sampling rate in Hz of a CSV with no time column."),
    even_grid: str | None = even_grid_option(),
    max_interpolated_pct: float = max_interpolated_option(),
    analysis_rate: float | None = typer.Option(None, "--analysis-rate",
                                               help="Resample to this rate in Hz first."),
    model: str | None = model_option(),
    json_out: Path | None = typer.Option(None, "--json", help="Write components and parameters."),
    force: bool = force_option(),
) -> None:
    """Build the looping tactile pattern of a recording, equalised for an actuator.

    The default command: `realpen tactile RECORDING -o pattern.wav` is this one.
    """
    import numpy as np

    from realpen.io.files import json_text, wav_bytes, write_files
    from realpen.tactile.actuator import parse_actuator
    from realpen.tactile.build import build_pattern
    from realpen.tactile.conditions import TactileParams

    response = parse_actuator(actuator)  # a measured response is a file read, like the recording
    measured = Path(response.spec) if response.kind == "measured" else None
    check_outputs(output, json_out, force=force,
                  inputs={"recording": recording, "actuator response": measured})
    params = TactileParams.resolve(condition, top, subpatterns, unit_ms, rate=rate,
                                   boundary=boundary, crossfade_ms=crossfade_ms,
                                   amplitude=amplitude, seed=seed, cap_db=cap_db,
                                   selection=select, highpass_hz=highpass_hz, axis=axis,
                                   analysis_rate=analysis_rate, **model_options(model, condition))
    # Streamed: only the stretch the pattern is made of is ever held in memory (a CSV put on an
    # even grid is loaded whole: the grid needs all its timestamps).
    source = read_recording(recording, input_rate, even_grid, max_interpolated_pct,
                            stream=even_grid is None)
    seconds = getattr(source, "duration_hint", None) or source.duration
    with progress_bar("analysing", seconds > PROGRESS_AFTER_S) as progress:
        pattern = build_pattern(source, response, params, progress)
    outputs = {output: wav_bytes(pattern.samples, pattern.rate)}
    if json_out is not None:
        outputs[json_out] = json_text(pattern.report(), json_out).encode("utf-8")
    write_files(outputs)
    counts = [len(sub) for sub in pattern.subpatterns]
    console.print(f"wrote {output}: {pattern.duration_s * 1000:.0f} ms at {pattern.rate} Hz, "
                  f"{len(counts)} sub-pattern(s) × {max(counts)} components, {params.boundary} "
                  f"boundaries, actuator {response.spec}, peak {np.max(np.abs(pattern.samples)):.3f}")
    for note in pattern.notes:
        console.print(f"note: {note}")
    if json_out is not None:
        console.print(f"wrote {json_out}")


@tactile_app.command("render")
def render(
    profile_ref: str = typer.Argument(..., metavar="PROFILE",
                                      help="Profile name, folder or .zip."),
    trajectory_path: Path = typer.Option(..., "--trajectory",
                                         help="Stroke CSV: t,x,y,pressure (s, mm, mm, 0–1)."),
    output: Path = typer.Option(..., "-o", "--output", help="WAV to write (32-bit float)."),
    rate: int | None = typer.Option(None, "--rate", callback=whole_number,
                                    help="Output rate in Hz (default: the pattern's own)."),
    force: bool = force_option(),
) -> None:
    """Render what a stroke feels like: the tactile drive along a recorded stroke.

    The loop plays while the pen moves on the surface (the profile's coupling gates it, as
    the live page does); with a vibration grid the patterns follow the pen's speed and force.
    """
    import numpy as np

    from realpen.errors import fail
    from realpen.io.files import wav_bytes, write_files
    from realpen.motion.trajectory import load_trajectory
    from realpen.profile import resolve_profile
    from realpen.tactile.stroke import render_tactile_stroke

    given = Path(profile_ref) if profile_ref.strip() else None  # Path("") is the current folder
    check_outputs(output, force=force,
                  inputs={"profile": given if given is not None and given.exists() else None,
                          "trajectory": trajectory_path})
    profile = resolve_profile(profile_ref)
    # A profile found by name lives in a folder too (bundled, or the user's): never write there.
    check_outputs(output, force=force, inputs={"profile": profile.path})
    trajectory = load_trajectory(trajectory_path)
    grid = profile.grid
    rate = grid.rate if rate is None else rate
    samples = render_tactile_stroke(grid, trajectory, rate, coupling=profile.coupling)
    if not np.all(np.isfinite(samples)):
        raise fail(output, "the rendered drive holds NaN or infinite samples; not written")
    write_files({output: wav_bytes(samples, rate)})
    points = len(grid.points)
    console.print(f"wrote {output}: {len(samples) / rate:.2f} s at {rate} Hz, "
                  f"{points} pattern{'s' if points != 1 else ''} "
                  f"({'following speed and force' if points > 1 else 'one loop'}), peak "
                  f"{float(np.max(np.abs(samples), initial=0.0)):.3f}")


def register(app: typer.Typer) -> None:
    """Add ``realpen tactile`` and ``realpen analyze`` to the root command."""
    app.add_typer(tactile_app, name="tactile")
    app.command()(analyze)
