"""``realpen sound loop | render | fit``: friction sound, Eq. 1 coupling, stroke rendering.

Only typer and the standard library are imported here; the library (numpy, scipy, soundfile)
is imported inside the commands, so ``realpen --help`` stays fast.
"""

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
from realpen.errors import RealPenError

sound_app = command_group("Friction sound: seamless loop units, the pressure/speed coupling "
                          "(Eq. 1), and what a stroke sounds like.")

# The library's own defaults and limits, from its numpy-free modules: help stays fast.
from realpen.checks import MAX_MS as MAX_LENGTH_MS  # noqa: E402
from realpen.checks import MAX_RATE_HZ as MAX_RATE  # noqa: E402
from realpen.checks import MIN_SOUND_RATE_HZ as MIN_RATE  # noqa: E402
from realpen.defaults import GRAIN_MS  # noqa: E402
from realpen.defaults import SOUND_CROSSFADE_MS as CROSSFADE_MS  # noqa: E402
from realpen.defaults import SOUND_MODES as MODES  # noqa: E402
from realpen.defaults import SOUND_RATE_HZ as DEFAULT_RATE  # noqa: E402
from realpen.defaults import SOUND_REFERENCE_DBFS as REFERENCE_DBFS  # noqa: E402
from realpen.defaults import SOUND_UNIT_MS as UNIT_MS  # noqa: E402
from realpen.defaults import TEXTURE_LENGTH_MS as LENGTH_MS  # noqa: E402

__all__ = ["sound_app", "loop", "render", "fit", "register"]

MODE_HELP = "loop (one seamless unit) | granular (overlapping grains, no repetition)."
RATE_HELP = (f"Resample the sound to this rate in Hz ({MIN_RATE:g} to {MAX_RATE:g}; lower rates "
             f"leave too little band to judge the seam).")
LEVEL_HELP = ("RMS in dBFS of the steady sound (the level coupling gain 1 plays at); finite, at "
              "most 0.")
UNIT_HELP = ("Loop unit length in ms (positive); the recording must last the unit plus the "
             "crossfade.")
CROSSFADE_HELP = "Crossfade at the wrap in ms (positive, shorter than the unit)."
GRAIN_HELP = "Granular mode: grain length in ms (positive)."
PROGRESS_AFTER_S = 60.0  # the scan takes about a second per 130 s of recording


def _json_bytes(data: object, target: Path) -> bytes:
    """Indented UTF-8 JSON of ``data``, built before anything is written; NaN or infinity is a
    one-line error naming ``target`` (``json.dumps(allow_nan=False)`` in :func:`json_text`)."""
    from realpen.io.files import json_text

    return json_text(data, target).encode("utf-8")


@sound_app.command("loop")
def loop(
    recording: Path = typer.Argument(..., help="Friction-sound recording: WAV, FLAC or OGG."),
    output: Path = typer.Option(..., "-o", "--output", help="Loop WAV to write."),
    unit_ms: float = typer.Option(UNIT_MS, "--unit-ms", help=UNIT_HELP),
    crossfade_ms: float = typer.Option(CROSSFADE_MS, "--crossfade-ms", help=CROSSFADE_HELP),
    mode: str = typer.Option("loop", "--mode", help=MODE_HELP),
    length_ms: float = typer.Option(
        LENGTH_MS, "--length-ms",
        help=f"Granular mode: length of the looping texture in ms (at most {MAX_LENGTH_MS:g}, "
             f"i.e. {MAX_LENGTH_MS / 1000:g} s)."),
    grain_ms: float = typer.Option(GRAIN_MS, "--grain-ms", help=GRAIN_HELP),
    seed: int = typer.Option(0, "--seed", help="Granular mode: seed of the grain offsets.",
                             callback=whole_number),
    rate: float = typer.Option(DEFAULT_RATE, "--rate", help=RATE_HELP),
    level_dbfs: float = typer.Option(REFERENCE_DBFS, "--level-dbfs", help=LEVEL_HELP),
    json_out: Path | None = typer.Option(None, "--json", help="Write the report as JSON."),
    force: bool = force_option(),
) -> None:
    """Cut the most seamless loop unit from a recording (or build a granular texture).

    Refuses a recording shorter than unit + crossfade; WAV and JSON are written both or neither.
    """
    from realpen.checks import require_choice
    from realpen.io.files import write_files
    from realpen.sound.loop import find_loop, load_sound

    require_choice("mode", mode, MODES)  # the command picks the function by mode
    check_outputs(output, json_out, force=force, inputs={"recording": recording})
    sound = load_sound(recording, rate)
    if mode == "loop":
        with progress_bar("scanning", sound.duration > PROGRESS_AFTER_S) as progress:
            result = find_loop(sound, unit_ms=unit_ms, crossfade_ms=crossfade_ms,
                               source=recording, progress=progress)
        result = result.normalised(level_dbfs)
        where = (f"unit at {result.start_s:.3f} s" if result.searched
                 else "the file's own smpl loop")
    else:
        from realpen.sound.granular import granular_loop  # scipy.ndimage: only for this mode

        result = granular_loop(sound, length_ms=length_ms, grain_ms=grain_ms, seed=seed,
                               level_dbfs=level_dbfs, source=recording)
        steady = sum(b - a for a, b in result.part.stretches) / result.rate
        where = f"grains from {steady:.2f} s of steady sound"
    files = {output: result.wav_bytes()}  # the WAV's smpl chunk declares the loop
    if json_out is not None:
        files[json_out] = _json_bytes(result.to_json(), json_out)
    write_files(files)
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
    coupling_path: Path | None = typer.Option(
        None, "--coupling", help="Coupling JSON (default constants if absent)."),
    mode: str = typer.Option("loop", "--mode", help=MODE_HELP),
    find_unit: bool | None = typer.Option(
        None, "--find-unit/--as-loop",
        help="Loop mode: search the recording for its loop unit (the default; a file shorter "
             "than the unit plus the crossfade is then refused), or play the file as it is as "
             "a ready loop (for loops made elsewhere: a WAV whose smpl chunk declares its "
             "loop, as 'realpen sound loop' writes it, is always played as a ready loop)."),
    unit_ms: float = typer.Option(UNIT_MS, "--unit-ms", help=UNIT_HELP),
    crossfade_ms: float = typer.Option(CROSSFADE_MS, "--crossfade-ms", help=CROSSFADE_HELP),
    grain_ms: float = typer.Option(GRAIN_MS, "--grain-ms", help=GRAIN_HELP),
    seed: int = typer.Option(0, "--seed", help="Granular mode: seed of the grain offsets.",
                             callback=whole_number),
    rate: float = typer.Option(DEFAULT_RATE, "--rate", help=RATE_HELP),
    level_dbfs: float = typer.Option(REFERENCE_DBFS, "--level-dbfs", help=LEVEL_HELP),
    force: bool = force_option(),
) -> None:
    """Render what a stroke sounds like, with the pressure/speed coupling.

    Loop mode searches the sound for its unit; a WAV that declares its loop (smpl chunk, as
    'realpen sound loop' writes it) and, with --as-loop, any file are played as ready loops.
    """
    import numpy as np

    from realpen.errors import fail
    from realpen.io.files import wav_bytes, write_files
    from realpen.motion.coupling import Coupling
    from realpen.motion.trajectory import load_trajectory
    from realpen.sound.loop import load_sound
    from realpen.sound.stroke import render_stroke

    if mode != "loop" and find_unit is not None:
        raise RealPenError("--find-unit/--as-loop: only for --mode loop")
    check_outputs(output, force=force, inputs={"sound": sound_path, "trajectory": trajectory_path,
                                               "coupling": coupling_path})
    coupling = Coupling.load(coupling_path) if coupling_path is not None else Coupling()
    trajectory = load_trajectory(trajectory_path)
    sound = load_sound(sound_path, rate)
    with progress_bar("scanning", sound.duration > PROGRESS_AFTER_S) as progress:
        rendered = render_stroke(sound, sound.rate, trajectory, coupling, mode,
                                 find_unit=find_unit is not False, unit_ms=unit_ms,
                                 crossfade_ms=crossfade_ms, grain_ms=grain_ms, seed=seed,
                                 level_dbfs=level_dbfs, source=sound_path, progress=progress)
    if not np.all(np.isfinite(rendered.samples)):
        raise fail(output, "the rendered sound holds NaN or infinite samples; not written")
    write_files({output: wav_bytes(rendered.samples, int(round(rendered.rate)))})
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
    value: float | None = typer.Option(
        None, "--value", help="Its value, finite (default: the base coupling's; c_ov in mm/s, "
                              "c_op in normalised pressure)."),
    base_path: Path | None = typer.Option(None, "--base", help="Coupling JSON supplying "
                                                               "a_max, smoothing and playback rate."),
    json_out: Path | None = typer.Option(None, "--json", help="Write a fit report as JSON."),
    force: bool = force_option(),
) -> None:
    """Fit c_p, c_op, c_x, c_ov of Eq. 1 to measurements by least squares.

    The coupling JSON and the report are written together or not at all.
    """
    from realpen.io.files import write_files
    from realpen.motion.coupling import Coupling, fit_coupling, load_measurements

    check_outputs(output, json_out, force=force,
                  inputs={"measurements": measurements, "base coupling": base_path})
    base = Coupling.load(base_path) if base_path is not None else Coupling()
    pressure, speed, amplitude = load_measurements(measurements)
    result = fit_coupling(pressure, speed, amplitude, fix, value, base, source=measurements)
    files = {output: _json_bytes(result.coupling.to_json(), output)}
    if json_out is not None:
        files[json_out] = _json_bytes(result.to_json(), json_out)
    write_files(files)
    c = result.coupling
    console.print(f"wrote {output}: c_p={c.c_p:.4g}, c_op={c.c_op:.4g}, c_x={c.c_x:.4g} per mm/s, "
                  f"c_ov={c.c_ov:.4g} mm/s ({fix} held); {result.rows} rows, rmse "
                  f"{result.rmse:.4g}, R² {result.r2:.4f}")
    if json_out is not None:
        console.print(f"wrote {json_out}")


def register(app: typer.Typer) -> None:
    """Add ``realpen sound`` to the root command."""
    app.add_typer(sound_app, name="sound")
