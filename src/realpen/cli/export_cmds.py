"""``realpen export``: a pen profile in the formats haptic platforms read."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from realpen.exports import export_profile, format_names
from realpen.profile.bundle import resolve_profile
from realpen.cli import app
from realpen.cli.common import console


@app.command()
def export(
    profile: str = typer.Argument(..., help="Profile name (pencil, ballpoint, marker, …) or a "
                                            "bundle folder or .zip."),
    fmt: str = typer.Option(..., "--format", "-f", help=f"One of: {format_names()}."),
    output: Path = typer.Option(..., "-o", "--output", help="File to write. For android, a "
                                                           ".kt name writes the Kotlin alone."),
    stereo: Optional[bool] = typer.Option(None, "--stereo",
                                          help="wav: sound left, tactile pattern right."),
    rate: Optional[int] = typer.Option(None, "--rate",
                                       help="wav, c-header: output rate in Hz (polyphase)."),
    repeats: Optional[int] = typer.Option(None, "--repeats",
                                          help="Periods to write, for formats without a loop "
                                               "flag (and wav, android)."),
) -> None:
    """Export a pen profile: wav, c-header, ahap, haptic, android or hjif."""
    loaded = resolve_profile(profile)
    written = export_profile(loaded, fmt, output, stereo=stereo or None, rate=rate,
                             repeats=repeats)
    console.print(f"wrote {written.path}: {written.export.summary}")
    for companion in written.companions:
        console.print(f"wrote {companion}")
    for limit in written.export.limits:
        console.print(f"note: {fmt} cannot carry: {limit}")
