"""``realpen export``: a pen profile in the formats haptic platforms read.

Only typer and the standard library are imported here; the exports (numpy, scipy) are imported
inside the command, so ``realpen --help`` stays fast.
"""

from __future__ import annotations

from pathlib import Path

import typer

from realpen.cli.common import check_outputs, console, force_option, whole_number

# realpen.exports.FORMATS' names, from the numpy-free defaults: help stays fast.
from realpen.defaults import EXPORT_FORMATS as FORMAT_NAMES  # noqa: E402

__all__ = ["export", "register"]


def export(
    profile: str = typer.Argument(..., help="Profile name (pencil, ballpoint, marker, …) or a "
                                            "bundle folder or .zip."),
    fmt: str = typer.Option(..., "--format", "-f", help=f"One of: {', '.join(FORMAT_NAMES)}."),
    output: Path = typer.Option(..., "-o", "--output", help="File to write. For android, a "
                                                           ".kt name writes the Kotlin alone."),
    stereo: bool | None = typer.Option(None, "--stereo",
                                       help="wav: sound left, tactile pattern right."),
    rate: int | None = typer.Option(None, "--rate",
                                    help="wav, c-header: output rate in Hz (polyphase).",
                                    callback=whole_number),
    repeats: int | None = typer.Option(None, "--repeats",
                                       help="Periods to write, for formats without a loop "
                                            "flag (and wav, android).", callback=whole_number),
    force: bool = force_option(),
) -> None:
    """Export a pen profile: wav, c-header, ahap, haptic, android or hjif.

    An existing output (or a companion file, e.g. an AHAP's sound) is replaced only with --force.
    """
    from realpen.exports import companion_paths, export_profile
    from realpen.profile import resolve_profile

    outputs = (output, *companion_paths(fmt, output))
    given = Path(profile) if profile.strip() else None  # Path("") would be the current folder
    check_outputs(*outputs, force=force,
                  inputs={"profile": given if given is not None and given.exists() else None})
    loaded = resolve_profile(profile)
    # A profile found by name lives in a folder too (bundled, or the user's): never write there.
    check_outputs(*outputs, force=force, inputs={"profile": loaded.path})
    written = export_profile(loaded, fmt, output, stereo=stereo or None, rate=rate,
                             repeats=repeats)
    console.print(f"wrote {written.path}: {written.export.summary}")
    for companion in written.companions:
        console.print(f"wrote {companion}")
    for limit in written.export.limits:
        console.print(f"note: {fmt} cannot carry: {limit}")


def register(app: typer.Typer) -> None:
    """Add ``realpen export`` to the root command."""
    app.command()(export)
