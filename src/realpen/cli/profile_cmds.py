"""``realpen profile build | list | show``.

Only typer and the standard library are imported here; the library (numpy, scipy, soundfile,
matplotlib) is imported inside the commands, so ``realpen --help`` stays fast.
"""

import sys
from pathlib import Path

import typer

from realpen.cli.common import (
    PROGRESS_AFTER_S,
    check_outputs,
    command_group,
    console,
    force_option,
    print_line,
    progress_bar,
)
from realpen.cli.recording_options import even_grid_option, max_interpolated_option, read_recording
from realpen.cli.sound_cmds import CROSSFADE_MS, UNIT_MS
from realpen.cli.tactile_cmds import model_option, model_options
from realpen.errors import RealPenError

__all__ = ["profile_app", "register"]

profile_app = command_group("Pen profiles: build, list and show.")


@profile_app.command("build")
def build(
    name: str = typer.Option(..., "--name", help="Profile name (letters, digits, - _ .)."),
    vibration: Path | None = typer.Option(None, "--vibration",
                                          help="Vibration recording (WAV/CSV/NPZ)."),
    vibration_grid: Path | None = typer.Option(
        None, "--vibration-grid", metavar="GRID.csv",
        help="Instead of --vibration, for a feel that follows the pen: a CSV with the header "
             "speed_mm_s,force_n,path and one recording per row (paths relative to the CSV)."),
    hatt: Path | None = typer.Option(
        None, "--hatt", metavar="MODEL.xml",
        help="Instead of --vibration: a HaTT texture model; a pattern at every model vertex "
             "(those at speed 0 or force 0 are left out)."),
    sound: Path | None = typer.Option(
        None, "--sound", help="Friction-sound recording (WAV/FLAC/OGG). Without a vibration "
                              "source: a sound-only pen; without --sound: a tactile-only pen."),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="Bundle folder, or a .zip file (or --install)."),
    install: bool = typer.Option(
        False, "--install", help="Write the bundle into your profiles folder ($REALPEN_HOME/"
                                 "profiles, else ~/.local/share/realpen/profiles), where "
                                 "'profile list', 'export' and the live app find it by name."),
    actuator: str = typer.Option("lra:f0=175,q=8", "--actuator",
                                 help="lra:f0=..,q=.. | piezo:f0=..,q=.. | flat | measured.csv"),
    tool: str = typer.Option("pen", "--tool", help="Tool type (pencil, ballpoint, marker, ...)."),
    description: str = typer.Option("", "--description", help="A sentence about the pen."),
    condition: str | None = typer.Option(None, "--condition", help="Study-1 preset A–F."),
    top: int | None = typer.Option(None, "--top", help="Principal frequencies per sub-pattern."),
    subpatterns: int | None = typer.Option(None, "--subpatterns", help="Sub-patterns (K)."),
    unit_ms: float | None = typer.Option(None, "--unit-ms", help="Sub-pattern length in ms."),
    rate: int = typer.Option(8000, "--rate", help="Tactile output rate in Hz."),
    boundary: str = typer.Option("crossfade", "--boundary", help="crossfade | hard."),
    seed: int = typer.Option(0, "--seed", help="Seed of the random phases."),
    cap_db: float = typer.Option(20.0, "--cap-db", help="Cap of the actuator weighting in dB."),
    axis: str | None = typer.Option(None, "--axis", help="dft321 | magnitude | x | y | z."),
    input_rate: float | None = typer.Option(None, "--input-rate",
                                            help="Rate in Hz of a vibration CSV without time."),
    even_grid: str | None = even_grid_option(),
    max_interpolated_pct: float = max_interpolated_option(),
    analysis_rate: float | None = typer.Option(None, "--analysis-rate",
                                               help="Resample the vibration to this rate first."),
    sound_unit_ms: float = typer.Option(UNIT_MS, "--sound-unit-ms", help="Sound loop unit in ms."),
    sound_crossfade_ms: float = typer.Option(CROSSFADE_MS, "--sound-crossfade-ms",
                                             help="Crossfade at the sound loop's wrap in ms."),
    coupling: Path | None = typer.Option(None, "--coupling",
                                         help="Coupling JSON (Eq. 1); default constants if absent."),
    model: str | None = model_option(),
    force: bool = force_option(),
) -> None:
    """Run the tactile and auditory pipelines and write a profile bundle atomically.

    The vibration is one recording (--vibration), recordings at several (speed, force) points
    (--vibration-grid) or a HaTT texture model (--hatt). Either part alone makes a pen: only
    --sound, a sound-only pen (its vibration is silence); only a vibration source, a
    tactile-only pen (its sound is silence). Says where the bundle went. With --install it goes
    into your profiles folder, named after the profile.
    """
    from realpen.io.paths import user_profiles_dir
    from realpen.motion.coupling import Coupling
    from realpen.profile import build_profile, save_profile
    from realpen.profile.build import check_name, read_grid_csv
    from realpen.sound.loop import load_sound
    from realpen.tactile.actuator import parse_actuator
    from realpen.tactile.conditions import TactileParams

    if install == (output is not None):
        raise RealPenError("profile build: give either -o/--output or --install")
    sources = sum(given is not None for given in (vibration, vibration_grid, hatt))
    if sources > 1:
        raise RealPenError("profile build: give exactly one of --vibration, --vibration-grid "
                           "and --hatt (or none of them, with --sound, for a sound-only pen)")
    if sources == 0 and sound is None:
        raise RealPenError("profile build: give --sound, a vibration source (--vibration, "
                           "--vibration-grid or --hatt), or both")
    if install:
        # The name becomes the folder's name: a valid name holds no path, checked before any work.
        output = user_profiles_dir() / check_name(name)
    inputs = {"vibration recording": vibration, "vibration grid": vibration_grid,
              "HaTT model": hatt, "sound recording": sound, "coupling": coupling}
    check_outputs(output, force=force, folders=True, inputs=inputs)
    params = TactileParams.resolve(condition, top, subpatterns, unit_ms, rate=rate,
                                   boundary=boundary, seed=seed, cap_db=cap_db, axis=axis,
                                   analysis_rate=analysis_rate, **model_options(model, condition))
    response = parse_actuator(actuator)
    constants = Coupling.load(coupling) if coupling is not None else Coupling()
    if vibration_grid is not None:
        rows = read_grid_csv(vibration_grid)
        check_outputs(output, force=force, folders=True, inputs={
            **inputs, **{f"grid recording {n + 1}": path for n, (_, _, path) in
                         enumerate(rows)}})
        shake = [(speed, force_n, read_recording(path, input_rate, even_grid,
                                                 max_interpolated_pct, stream=False))
                 for speed, force_n, path in rows]
        long = True
    elif hatt is not None:
        from realpen.datasets.hatt import load_hatt  # scipy.signal: only for a HaTT model

        shake, long = load_hatt(hatt), True
    elif vibration is not None:
        # Streamed: flat memory at any length (a CSV put on an even grid is loaded whole).
        shake = read_recording(vibration, input_rate, even_grid, max_interpolated_pct,
                               stream=even_grid is None)
        long = (getattr(shake, "duration_hint", None) or shake.duration) > PROGRESS_AFTER_S
    else:
        shake, long = None, False
    noise = load_sound(sound) if sound is not None else None
    with progress_bar("building", long) as progress:
        profile = build_profile(name, tool, shake, noise, response, params, sound_unit_ms,
                                sound_crossfade_ms, constants, description, progress=progress)
    written = Path(save_profile(profile, output)).resolve()
    console.print(f"wrote {written}: {profile.summary()}")
    for note in profile.meta.provenance.notes:
        console.print(f"note: {note}")


@profile_app.command("list")
def list_command(
    profiles: list[Path] = typer.Option([], "--profiles", help="Another folder of profiles."),
) -> None:
    """List the bundled and the user's profiles, one line each.

    A bundle that does not load is left out and named in one warning line on stderr,
    ``realpen: warning: skipped profile <bundle>: <problem>``; the others are listed.
    """
    from realpen.profile import list_profiles, load_profile

    found = list_profiles(profiles)
    for where, path in found:
        try:
            profile = load_profile(path)
        except RealPenError as error:  # a broken bundle is named, not fatal
            # print, not rich: rich wraps long lines, and the warning must stay one line.
            print(f"realpen: warning: skipped profile {' '.join(str(error).split())}",
                  file=sys.stderr, flush=True)
            continue
        print_line(f"{profile.summary()} ({where}, version {profile.version})")
    if not found:
        print_line("no profiles found")


@profile_app.command("show")
def show(
    profile_ref: str = typer.Argument(..., metavar="NAME_OR_DIR", help="Profile name, folder or .zip."),
    plot: Path | None = typer.Option(None, "--plot", help="Draw the pattern and sound to a PNG."),
    force: bool = force_option(),
) -> None:
    """Show a profile's components; optionally plot it like the method's Figure 8."""
    from rich.table import Table

    from realpen.profile import resolve_profile

    check_outputs(plot, force=force)
    profile = resolve_profile(profile_ref)
    meta = profile.meta
    console.print(f"{profile.summary()}  (version {profile.version})")
    if meta.description:
        console.print(meta.description)
    c = meta.coupling
    console.print(f"coupling: A_s = {c.c_p:g}·(P − {c.c_op:g}) + {c.c_x:g}·(v − {c.c_ov:g}), "
                  f"clamped to [0, {c.a_max:g}], smoothing {c.smoothing_ms:g} ms")
    if profile.has_tactile:
        table = Table("sub-pattern", "frequencies Hz (amplitude)")
        for index, sub in enumerate(meta.tactile.subpatterns):
            table.add_row(str(index), "  ".join(f"{comp.frequency_hz:.1f} "
                                                f"({comp.amplitude:.3f})" for comp in sub))
        console.print(table)
        for line in profile_lines(profile):
            console.print(line)
    else:
        console.print("tactile: none (a sound-only pen: its tactile pattern is silence)")
    if profile.has_sound:
        console.print(f"sound unit: {meta.sound.unit_ms:g} ms from {meta.sound.start_s} s, seam "
                      f"level jump {meta.sound.seam.get('level_jump_db', float('nan')):.2f} dB")
    else:
        console.print("sound: none (a tactile-only pen: its sound unit is silence)")
    if plot is not None:
        from realpen.display.profile import save_profile_plot  # matplotlib is slow to import; only when asked

        save_profile_plot(profile, plot)
        console.print(f"wrote {plot}")


def profile_lines(profile) -> list[str]:
    """What ``profile show`` says of the tactile model (sines, residual) and of the grid."""
    meta = profile.meta
    pattern = meta.tactile
    residual = getattr(pattern, "residual", None)
    model = meta.provenance.tactile_parameters.get("model")
    model = model or ("sines+residual" if residual is not None else "sines")
    lines = [f"tactile model: {model}" + ("" if residual is None else
                                           f" (residual in {len(residual.band_edges_hz) - 1} "
                                           f"bands)")]
    source = meta.provenance.model or {}
    if meta.grid is None:
        lines.append("grid: none (one pattern, whatever the speed and force)")
        return lines
    grid = meta.grid
    xy = grid.coordinates
    made = f", from HaTT '{source['hatt']}'" if "hatt" in source else ""
    lines.append(f"grid: {len(grid.points)} points{made}, speed {xy[:, 0].min():.4g}–"
                 f"{xy[:, 0].max():.4g} mm/s, force {xy[:, 1].min():.3g}–{xy[:, 1].max():.3g} N "
                 f"({grid.full_pressure_force_n:g} N at full pressure), {len(grid.triangles)} "
                 f"triangles; the table is point {grid.reference} at "
                 f"{xy[grid.reference, 0]:.4g} mm/s, {xy[grid.reference, 1]:.3g} N")
    return lines


def register(app: typer.Typer) -> None:
    """Add ``realpen profile`` to the root command."""
    app.add_typer(profile_app, name="profile")
