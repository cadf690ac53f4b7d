"""``realpen export``: a pen profile in the formats haptic platforms read
(``realpen export PROFILE -o OUT``, the default ``export profile``), and a haptic file read back
(``realpen export read FILE``).

Only typer and the standard library are imported here; the exports (numpy, scipy) are
imported inside the command, so ``realpen --help`` stays fast.
"""

from pathlib import Path

import typer

from realpen.cli.common import (
    DefaultCommandGroup,
    check_outputs,
    command_group,
    console,
    force_option,
    print_line,
    whole_number,
)

# realpen.exports.FORMATS' names, from the numpy-free defaults: help stays fast.
from realpen.defaults import EXPORT_FORMATS as FORMAT_NAMES  # noqa: E402

__all__ = ["export_app", "export", "read", "register", "WAV_SUBTYPES"]

WAV_SUBTYPES = ("pcm16", "pcm24", "float")
""":data:`realpen.exports.wav.SUBTYPES`, spelt out so the help needs no numpy (a test checks
that they agree)."""


def _subtype(value: str | None) -> str | None:
    """Typer callback of ``--subtype``: one of :data:`WAV_SUBTYPES`, refused while reading it."""
    if value is not None and value not in WAV_SUBTYPES:
        raise typer.BadParameter(f"choose {', '.join(WAV_SUBTYPES)}, got {value!r}")
    return value


_SUFFIXES = ("wav .wav, c-header .h, ahap .ahap, haptic .haptic, android .json (.kt: the Kotlin "
             "alone), hjif .hjif")


class _ProfileByDefault(DefaultCommandGroup):
    """``realpen export PROFILE ...`` runs ``export profile``."""

    default_command = "profile"


export_app = command_group(
    "Exports: `realpen export PROFILE -o pencil.ahap` (profile, the default) writes a pen in a "
    "format haptic platforms read; `realpen export read FILE` reads a .hjif, .haptic, .ahap or "
    "Android .json back and renders what a player plays.", cls=_ProfileByDefault)


@export_app.command("profile")
def export(
    profile: str = typer.Argument(..., help="Profile name (pencil, ballpoint, marker, …) or a "
                                            "bundle folder or .zip."),
    fmt: str | None = typer.Option(None, "--format", "-f",
                                   help=f"One of: {', '.join(FORMAT_NAMES)}. Default: the one "
                                        f"the output's suffix names; a suffix that is not the "
                                        f"format's is refused."),
    output: Path = typer.Option(..., "-o", "--output",
                                help=f"File to write; its suffix names the format: {_SUFFIXES}."),
    stereo: bool | None = typer.Option(None, "--stereo",
                                       help="wav: sound left, tactile pattern right."),
    rate: int | None = typer.Option(None, "--rate",
                                    help="wav, c-header: output rate in Hz (polyphase).",
                                    callback=whole_number),
    repeats: int | None = typer.Option(None, "--repeats",
                                       help="Periods to write, for formats without a loop "
                                            "flag (and wav). android takes 1: its envelopes "
                                            "hold the 16 control points every device takes.",
                                       callback=whole_number),
    subtype: str | None = typer.Option(None, "--subtype",
                                       callback=_subtype,
                                       help="wav: sample format; pcm16 (the default, what "
                                            "SoundPool, game engines and audio-driven "
                                            "actuators read), pcm24 or float (exact)."),
    force: bool = force_option(),
) -> None:
    """Export a pen profile: wav, c-header, ahap, haptic, android or hjif.

    The format is --format, or the one the output's suffix names (pencil.ahap: ahap). An
    existing output (or a companion file, e.g. an AHAP's sound) is replaced only with --force.
    """
    from realpen.exports import check_suffix, companion_paths, export_profile, format_for_suffix
    from realpen.profile import resolve_profile

    if output.is_dir():
        check_outputs(output, force=force)  # "is a folder", before its missing suffix
    fmt = format_for_suffix(output) if fmt is None else fmt
    outputs = (output, *companion_paths(fmt, output))
    check_suffix(fmt, output)
    given = Path(profile) if profile.strip() else None  # Path("") would be the current folder
    check_outputs(*outputs, force=force,
                  inputs={"profile": given if given is not None and given.exists() else None})
    loaded = resolve_profile(profile)
    # A profile found by name lives in a folder too (bundled, or the user's): never write there.
    check_outputs(*outputs, force=force, inputs={"profile": loaded.path})
    written = export_profile(loaded, fmt, output, stereo=stereo or None, rate=rate,
                             repeats=repeats, subtype=subtype)
    print_line(f"wrote {written.path}: {written.export.summary}")
    for companion in written.companions:
        print_line(f"wrote {companion}")
    for limit in written.export.limits:
        print_line(f"note: {fmt} cannot carry: {limit}")


@export_app.command("read")
def read(
    file: Path = typer.Argument(..., help="A .hjif, .haptic, .ahap or Android .json file."),
    render: Path | None = typer.Option(None, "--render",
                                       help="Write what a player plays to this WAV (32-bit "
                                            "float, mono)."),
    rate: int = typer.Option(8000, "--rate", help="--render: sample rate in Hz.",
                             callback=whole_number),
    force: bool = force_option(),
) -> None:
    """Read a haptic file back: check its format's rules and say what it holds.

    --render writes the vibration a player would drive (see realpen.exports.readers for how
    each format is played).
    """
    from realpen.errors import fail
    from realpen.exports.reading import frame_rms, load_haptic
    from realpen.io.files import write_wav

    if render is not None:
        if render.suffix.lower() != ".wav":
            raise fail(render, f"--render writes a WAV file; name it {render.stem}.wav")
        check_outputs(render, force=force, inputs={"file": file})
    clip = load_haptic(file)
    console.print(f"{clip.path}: {clip.format}: {clip.summary}")
    for note in clip.notes:
        console.print(f"note: {note}")
    if render is not None:
        samples = clip.render(rate)
        write_wav(render, samples, rate)
        envelope = frame_rms(samples, rate)
        peak = float(abs(samples).max()) if len(samples) else 0.0
        console.print(f"wrote {render}: {len(samples)} samples at {rate} Hz, peak {peak:.3f}, "
                      f"10 ms RMS up to {float(envelope.max(initial=0.0)):.3f}")


def register(app: typer.Typer) -> None:
    """Add ``realpen export`` to the root command."""
    app.add_typer(export_app, name="export")
