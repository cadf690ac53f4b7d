"""``realpen sound loop | render | fit``: friction sound, Eq. 1 coupling, stroke rendering."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..coupling import FIXABLE, Coupling, fit_coupling, load_measurements
from ..errors import RealPenError
from ..fileio import write_json, write_wav
from ..granular import GRAIN_MS, LENGTH_MS, granular_loop
from ..sound import CROSSFADE_MS, DEFAULT_RATE, REFERENCE_DBFS, UNIT_MS, find_loop_unit, load_sound
from ..stroke import MODES, load_trajectory, render_stroke
from . import app
from .common import console, progress_bar

sound_app = typer.Typer(
    help="Friction sound: seamless loop units, the pressure/speed coupling (Eq. 1), and what a "
         "stroke sounds like.",
    no_args_is_help=True,
)
app.add_typer(sound_app, name="sound")

MODE_HELP = "loop (one seamless unit) | granular (overlapping grains, no repetition)."
RATE_HELP = "Resample the sound to this rate in Hz."
LEVEL_HELP = "RMS in dBFS of the steady sound (the level coupling gain 1 plays at)."
PROGRESS_AFTER_S = 60.0  # the scan takes about a second per 130 s of recording


def _check_mode(mode: str) -> str:
    if mode not in MODES:
        raise RealPenError(f"--mode: unknown mode '{mode}' (choose from {', '.join(MODES)})")
    return mode


@sound_app.command("loop")
def loop(
    recording: Path = typer.Argument(..., help="Friction-sound recording: WAV, FLAC or OGG."),
    output: Path = typer.Option(..., "-o", "--output", help="Loop WAV to write."),
    unit_ms: float = typer.Option(UNIT_MS, "--unit-ms", help="Loop unit length in ms."),
    crossfade_ms: float = typer.Option(CROSSFADE_MS, "--crossfade-ms",
                                       help="Crossfade at the wrap in ms."),
    mode: str = typer.Option("loop", "--mode", help=MODE_HELP),
    length_ms: float = typer.Option(LENGTH_MS, "--length-ms",
                                    help="Granular mode: length of the looping texture in ms."),
    grain_ms: float = typer.Option(GRAIN_MS, "--grain-ms", help="Granular mode: grain in ms."),
    seed: int = typer.Option(0, "--seed", help="Granular mode: seed of the grain offsets."),
    rate: float = typer.Option(DEFAULT_RATE, "--rate", help=RATE_HELP),
    level_dbfs: float = typer.Option(REFERENCE_DBFS, "--level-dbfs", help=LEVEL_HELP),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the report as JSON."),
) -> None:
    """Cut the most seamless loop unit from a recording (or build a granular texture)."""
    _check_mode(mode)
    sound = load_sound(recording, rate)
    if mode == "loop":
        with progress_bar("scanning", sound.duration > PROGRESS_AFTER_S) as progress:
            result = find_loop_unit(sound.mono, sound.rate, unit_ms, crossfade_ms,
                                    source=recording, recording=sound, progress=progress)
        result = result.normalised(level_dbfs)
        where = f"unit at {result.start_s:.3f} s"
    else:
        result = granular_loop(sound.mono, sound.rate, length_ms, grain_ms, seed, level_dbfs,
                               source=recording, recording=sound)
        steady = sum(b - a for a, b in result.part.stretches) / sound.rate
        where = f"grains from {steady:.2f} s of steady sound"
    report = result.to_json()
    write_wav(output, result.samples, int(round(result.rate)))
    if json_out is not None:
        write_json(json_out, report)
    seam = result.seam
    console.print(f"wrote {output}: {len(result.samples) / result.rate * 1000:.0f} ms {mode} at "
                  f"{result.rate:g} Hz, {where}; seam: level jump {seam.level_jump_db:.2f} dB, "
                  f"flux {seam.flux_wrap_db:.1f} dB (inside p95 {seam.flux_inside_p95_db:.1f} dB, "
                  f"percentile {seam.flux_wrap_percentile:.0f})")
    if json_out is not None:
        console.print(f"wrote {json_out}")


@sound_app.command("render")
def render(
    sound_path: Path = typer.Option(..., "--sound", help="Loop WAV or recording (WAV/FLAC/OGG)."),
    trajectory_path: Path = typer.Option(..., "--trajectory",
                                         help="Stroke CSV: t,x,y,pressure (s, mm, mm, 0–1)."),
    output: Path = typer.Option(..., "-o", "--output", help="WAV to write."),
    coupling_path: Optional[Path] = typer.Option(
        None, "--coupling", help="Coupling JSON (default constants if absent)."),
    mode: str = typer.Option("loop", "--mode", help=MODE_HELP),
    find_unit: Optional[bool] = typer.Option(
        None, "--find-unit/--as-loop",
        help="Loop mode: search the unit first, or play the file as a ready loop "
             "(default: search when the file is longer than two units)."),
    unit_ms: float = typer.Option(UNIT_MS, "--unit-ms", help="Loop unit length in ms."),
    crossfade_ms: float = typer.Option(CROSSFADE_MS, "--crossfade-ms",
                                       help="Crossfade at the wrap in ms."),
    grain_ms: float = typer.Option(GRAIN_MS, "--grain-ms", help="Granular mode: grain in ms."),
    seed: int = typer.Option(0, "--seed", help="Granular mode: seed of the grain offsets."),
    rate: float = typer.Option(DEFAULT_RATE, "--rate", help=RATE_HELP),
    level_dbfs: float = typer.Option(REFERENCE_DBFS, "--level-dbfs", help=LEVEL_HELP),
) -> None:
    """Render what a stroke sounds like, with the pressure/speed coupling."""
    _check_mode(mode)
    coupling = Coupling.load(coupling_path) if coupling_path is not None else Coupling()
    trajectory = load_trajectory(trajectory_path)
    sound = load_sound(sound_path, rate)
    with progress_bar("scanning", sound.duration > PROGRESS_AFTER_S) as progress:
        rendered = render_stroke(sound.mono, sound.rate, trajectory, coupling, mode,
                                 find_unit=find_unit, unit_ms=unit_ms, crossfade_ms=crossfade_ms,
                                 grain_ms=grain_ms, seed=seed, level_dbfs=level_dbfs,
                                 source=sound_path, progress=progress)
    write_wav(output, rendered.samples, int(round(rendered.rate)))
    source = (f"unit at {rendered.unit.start_s:.3f} s" if rendered.unit is not None
              else "grains" if mode == "granular" else "the file as a loop")
    console.print(f"wrote {output}: {len(rendered.samples) / rendered.rate:.2f} s at "
                  f"{rendered.rate:g} Hz ({mode}, {source}), peak gain "
                  f"{float(rendered.gain.max()):.2f}")


@sound_app.command("fit")
def fit(
    measurements: Path = typer.Argument(..., help="CSV with pressure (0–1), speed (mm/s), "
                                                  "amplitude (linear gain)."),
    output: Path = typer.Option(..., "-o", "--output", help="Coupling JSON to write."),
    fix: str = typer.Option("c_ov", "--fix", help="Threshold held fixed: c_ov or c_op "
                                                  "(only their weighted sum is identifiable)."),
    value: Optional[float] = typer.Option(None, "--value",
                                          help="Its value (default: the default constant)."),
    base_path: Optional[Path] = typer.Option(None, "--base", help="Coupling JSON supplying "
                                             "a_max, smoothing and playback rate."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write a fit report as JSON."),
) -> None:
    """Fit c_p, c_op, c_x, c_ov of Eq. 1 to measurements by least squares."""
    if fix not in FIXABLE:
        raise RealPenError(f"--fix: choose from {', '.join(FIXABLE)}, got '{fix}'")
    base = Coupling.load(base_path) if base_path is not None else Coupling()
    pressure, speed, amplitude = load_measurements(measurements)
    result = fit_coupling(pressure, speed, amplitude, fix, value, base, source=measurements)
    report = result.to_json()
    result.coupling.save(output)
    if json_out is not None:
        write_json(json_out, report)
    c = result.coupling
    console.print(f"wrote {output}: c_p={c.c_p:.4g}, c_op={c.c_op:.4g}, c_x={c.c_x:.4g} per mm/s, "
                  f"c_ov={c.c_ov:.4g} mm/s ({fix} held); {result.rows} rows, rmse "
                  f"{result.rmse:.4g}, R² {result.r2:.4f}")
    if json_out is not None:
        console.print(f"wrote {json_out}")
