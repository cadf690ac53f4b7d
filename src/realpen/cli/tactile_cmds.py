"""``realpen analyze`` and ``realpen tactile``."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from realpen.tactile.actuator import parse_actuator
from realpen.io.files import json_text, wav_bytes, write_files, write_json
from realpen.io.recording import load_recording
from realpen.dsp.filters import prepare
from realpen.dsp.spectrum import analyze as analyze_signal
from realpen.tactile.pattern import CONDITIONS, TactileParams, build_pattern
from realpen.cli import app
from realpen.cli.common import PROGRESS_AFTER_S, console, progress_bar

AXIS_HELP = "How axes become one: dft321 (default for several axes), magnitude, or x|y|z."


@app.command()
def analyze(
    recording: Path = typer.Argument(..., help="Vibration recording: WAV/FLAC, CSV or NPZ."),
    unit_ms: float = typer.Option(100.0, "--unit-ms", help="Unit sequence length in ms."),
    top: int = typer.Option(10, "--top", help="Principal frequencies per unit."),
    subpatterns: int = typer.Option(15, "--subpatterns", help="Consecutive units to select."),
    highpass_hz: float = typer.Option(30.0, "--highpass", help="High-pass cutoff in Hz."),
    axis: Optional[str] = typer.Option(None, "--axis", help=AXIS_HELP),
    select: str = typer.Option("stationary", "--select",
                               help="Which units: stationary (most stationary run) or middle."),
    rate: Optional[float] = typer.Option(None, "--rate",
                                         help="Sampling rate in Hz of a CSV with no time column."),
    analysis_rate: Optional[float] = typer.Option(None, "--analysis-rate",
                                                  help="Resample to this rate in Hz first."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the analysis as JSON."),
) -> None:
    """Print the principal frequencies of every unit sequence of a recording."""
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
    table = Table("unit", "start s", f"principal frequencies, Hz (strongest first, top {top})")
    for index in result.selected:
        freqs, _ = result.unit(int(index))
        table.add_row(str(int(index)), f"{result.starts_s[index]:.2f}",
                      " ".join(f"{f:.1f}" for f in freqs))
    console.print(table)
    if json_out is not None:
        console.print(f"wrote {json_out}")


@app.command()
def tactile(
    recording: Path = typer.Argument(..., help="Vibration recording: WAV/FLAC, CSV or NPZ."),
    output: Path = typer.Option(..., "-o", "--output", help="Pattern WAV to write."),
    actuator: str = typer.Option("lra:f0=175,q=8", "--actuator",
                                 help="lra:f0=..,q=.. | piezo:f0=..,q=.. | flat | measured.csv"),
    condition: Optional[str] = typer.Option(
        None, "--condition", help="Study-1 preset: " + ", ".join(
            f"{k}={n}×{s}×{u:g}ms" for k, (n, s, u) in CONDITIONS.items()) + " (default B)."),
    top: Optional[int] = typer.Option(None, "--top", help="Principal frequencies per sub-pattern."),
    subpatterns: Optional[int] = typer.Option(None, "--subpatterns", help="Sub-patterns (K)."),
    unit_ms: Optional[float] = typer.Option(None, "--unit-ms", help="Sub-pattern length in ms."),
    rate: int = typer.Option(8000, "--rate", help="Output rate in Hz."),
    boundary: str = typer.Option("crossfade", "--boundary", help="crossfade | hard."),
    crossfade_ms: float = typer.Option(5.0, "--crossfade-ms", help="Crossfade length in ms."),
    amplitude: str = typer.Option("sqrt", "--amplitude",
                                  help="sqrt (∝ √power, energy-preserving) | power (literal)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the random phases."),
    cap_db: float = typer.Option(20.0, "--cap-db", help="Cap of the actuator weighting in dB."),
    select: str = typer.Option("stationary", "--select", help="stationary | middle."),
    highpass_hz: float = typer.Option(30.0, "--highpass", help="High-pass cutoff in Hz."),
    axis: Optional[str] = typer.Option(None, "--axis", help=AXIS_HELP),
    input_rate: Optional[float] = typer.Option(
        None, "--input-rate", help="Sampling rate in Hz of a CSV with no time column."),
    analysis_rate: Optional[float] = typer.Option(None, "--analysis-rate",
                                                  help="Resample to this rate in Hz first."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write components and parameters."),
) -> None:
    """Build the looping tactile pattern of a recording, equalised for an actuator."""
    params = TactileParams.resolve(condition, top, subpatterns, unit_ms, rate=rate, boundary=boundary,
                            crossfade_ms=crossfade_ms, amplitude=amplitude, seed=seed,
                            cap_db=cap_db, selection=select, highpass_hz=highpass_hz, axis=axis,
                            analysis_rate=analysis_rate)
    response = parse_actuator(actuator)
    loaded = load_recording(recording, rate=input_rate, rate_option="--input-rate")
    with progress_bar("analysing", loaded.duration > PROGRESS_AFTER_S) as progress:
        pattern = build_pattern(loaded, response, params, progress)
    outputs = {output: wav_bytes(pattern.samples, pattern.rate)}
    if json_out is not None:
        outputs[json_out] = json_text(pattern.to_json(), json_out).encode("utf-8")
    write_files(outputs)
    counts = [len(sub) for sub in pattern.subpatterns]
    console.print(f"wrote {output}: {pattern.duration_s * 1000:.0f} ms at {pattern.rate} Hz, "
                  f"{len(counts)} sub-pattern(s) × {max(counts)} components, {params.boundary} "
                  f"boundaries, actuator {response.spec}, peak {np.max(np.abs(pattern.samples)):.3f}")
    for note in pattern.notes:
        console.print(f"note: {note}")
    if json_out is not None:
        console.print(f"wrote {json_out}")

