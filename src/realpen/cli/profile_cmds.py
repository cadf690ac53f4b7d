"""``realpen profile build | list | show``.

Only typer and the standard library are imported here; the library (numpy, scipy, soundfile,
matplotlib) is imported inside the commands, so ``realpen --help`` stays fast.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from realpen.cli import sub_app
from realpen.cli.common import PROGRESS_AFTER_S, check_outputs, console, force_option, progress_bar
from realpen.cli.sound_cmds import CROSSFADE_MS, UNIT_MS
from realpen.errors import RealPenError

profile_app = sub_app("profile", "Pen profiles: build, list and show.")


@profile_app.command("build")
def build(
    name: str = typer.Option(..., "--name", help="Profile name (letters, digits, - _ .)."),
    vibration: Path = typer.Option(..., "--vibration", help="Vibration recording (WAV/CSV/NPZ)."),
    sound: Path = typer.Option(..., "--sound", help="Friction-sound recording (WAV/FLAC/OGG)."),
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
    analysis_rate: float | None = typer.Option(None, "--analysis-rate",
                                               help="Resample the vibration to this rate first."),
    sound_unit_ms: float = typer.Option(UNIT_MS, "--sound-unit-ms", help="Sound loop unit in ms."),
    sound_crossfade_ms: float = typer.Option(CROSSFADE_MS, "--sound-crossfade-ms",
                                             help="Crossfade at the sound loop's wrap in ms."),
    coupling: Path | None = typer.Option(None, "--coupling",
                                         help="Coupling JSON (Eq. 1); default constants if absent."),
    force: bool = force_option(),
) -> None:
    """Run the tactile and auditory pipelines and write a profile bundle atomically.

    Says where the bundle went. With --install it goes into your profiles folder, named after
    the profile.
    """
    from realpen.io.paths import user_profiles_dir
    from realpen.io.recording import load_recording
    from realpen.profile import build_profile, save_profile
    from realpen.profile.build import check_name
    from realpen.sound.coupling import Coupling
    from realpen.sound.loop import load_sound
    from realpen.tactile.actuator import parse_actuator
    from realpen.tactile.conditions import TactileParams

    if install == (output is not None):
        raise RealPenError("profile build: give either -o/--output or --install")
    if install:
        # The name becomes the folder's name: a valid name holds no path, checked before any work.
        output = user_profiles_dir() / check_name(name)
    check_outputs(output, force=force, folders=True,
                  inputs={"vibration recording": vibration, "sound recording": sound})
    params = TactileParams.resolve(condition, top, subpatterns, unit_ms, rate=rate,
                                   boundary=boundary, seed=seed, cap_db=cap_db, axis=axis,
                                   analysis_rate=analysis_rate)
    response = parse_actuator(actuator)
    constants = Coupling.load(coupling) if coupling is not None else Coupling()
    shake = load_recording(vibration, rate=input_rate)
    noise = load_sound(sound)
    with progress_bar("building", shake.duration > PROGRESS_AFTER_S) as progress:
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
        console.print(f"{profile.summary()} ({where}, version {profile.version})")
    if not found:
        console.print("no profiles found")


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
    table = Table("sub-pattern", "frequencies Hz (amplitude)")
    for index, sub in enumerate(meta.tactile.subpatterns):
        table.add_row(str(index), "  ".join(f"{comp.frequency_hz:.1f} ({comp.amplitude:.3f})"
                                            for comp in sub))
    console.print(table)
    console.print(f"sound unit: {meta.sound.unit_ms:g} ms from {meta.sound.start_s} s, seam level "
                  f"jump {meta.sound.seam.get('level_jump_db', float('nan')):.2f} dB")
    if plot is not None:
        from realpen.display.profile import save_profile_plot  # matplotlib is slow to import; only when asked

        save_profile_plot(profile, plot)
        console.print(f"wrote {plot}")
