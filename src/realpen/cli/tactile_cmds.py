"""``realpen analyze`` and ``realpen tactile``.

Only typer and the standard library are imported here; the library (numpy, scipy, soundfile)
is imported inside the commands, so ``realpen --help`` stays fast.
"""

from __future__ import annotations

from pathlib import Path

import typer

from realpen.cli import app
from realpen.cli.common import (
    PROGRESS_AFTER_S,
    check_outputs,
    console,
    force_option,
    progress_bar,
    whole_number,
)

AXIS_HELP = "How axes become one: dft321 (default for several axes), magnitude, or x|y|z."
# The study-1 conditions as realpen.tactile.conditions.CONDITIONS defines them (principal
# frequencies × sub-patterns × unit length); written out so that help needs no numpy. A test
# checks that the two agree.
CONDITION_HELP = ("Study-1 preset: A=5×15×100ms, B=10×15×100ms, C=15×15×100ms, D=5×1×1500ms, "
                  "E=10×1×1500ms, F=15×1×1500ms (default B).")


@app.command()
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
    analysis_rate: float | None = typer.Option(None, "--analysis-rate",
                                               help="Resample to this rate in Hz first."),
    json_out: Path | None = typer.Option(None, "--json",
                                         help="Write the analysis of every unit as JSON."),
    every_unit: bool = typer.Option(False, "--all", help="Print every unit, not only the "
                                                         "selected ones."),
    force: bool = force_option(),
) -> None:
    """Print the principal frequencies of the selected unit sequences (--all: of every unit)."""
    from rich.table import Table

    from realpen.dsp.filters import prepare
    from realpen.dsp.spectrum import analyze as analyze_signal
    from realpen.io.files import write_json
    from realpen.io.recording import load_recording

    check_outputs(json_out, force=force, inputs={"recording": recording})
    loaded = load_recording(recording, rate=rate)
    prepared = prepare(loaded, axis, analysis_rate, highpass_hz)
    with progress_bar("analysing", loaded.duration > PROGRESS_AFTER_S) as progress:
        result = analyze_signal(prepared.mono, prepared.rate, unit_ms, top, subpatterns, select,
                                fmin=highpass_hz, source=str(recording), progress=progress)
    if json_out is not None:
        write_json(json_out, result.to_json())
    first, last = int(result.selected[0]), int(result.selected[-1])
    console.print(f"{recording}: {loaded.duration:.2f} s, {len(loaded.axes)} axis(es) "
                  f"({', '.join(loaded.axes)}) at {loaded.rate:g} Hz → "
                  f"{prepared.axes[0]}, high-pass {highpass_hz:g} Hz")
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


@app.command()
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
    analysis_rate: float | None = typer.Option(None, "--analysis-rate",
                                               help="Resample to this rate in Hz first."),
    json_out: Path | None = typer.Option(None, "--json", help="Write components and parameters."),
    force: bool = force_option(),
) -> None:
    """Build the looping tactile pattern of a recording, equalised for an actuator."""
    import numpy as np

    from realpen.io.files import json_text, wav_bytes, write_files
    from realpen.io.recording import load_recording
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
                                   analysis_rate=analysis_rate)
    loaded = load_recording(recording, rate=input_rate)
    with progress_bar("analysing", loaded.duration > PROGRESS_AFTER_S) as progress:
        pattern = build_pattern(loaded, response, params, progress)
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

