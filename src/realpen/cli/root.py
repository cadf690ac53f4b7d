"""The root ``realpen`` command: its options, and every group of subcommands registered on it.

Each command module defines its own commands and groups and registers them with
``register(app)``; none of them imports this module, so the command tree is built without an
import cycle. A new group goes into a module of its own with a ``register`` function, called
below in the order ``realpen --help`` lists it.
"""

from __future__ import annotations

import typer

from realpen.cli import (
    device_cmds,
    export_cmds,
    hatt_cmds,
    profile_cmds,
    serve_cmds,
    sound_cmds,
    stats_cmds,
    study_cmds,
    tactile_cmds,
)
from realpen.cli.common import CONTEXT_SETTINGS

__all__ = ["app", "COMMAND_MODULES"]

app = typer.Typer(
    name="realpen",
    help="RealPen: the feel and sound of a real pen on paper, for touch screens.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings=CONTEXT_SETTINGS,
)


def _show_version(value: bool) -> None:
    if value:
        from realpen._version import __version__

        print(f"realpen {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_show_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """RealPen: the feel and sound of a real pen on paper, for touch screens."""


COMMAND_MODULES = (tactile_cmds, sound_cmds, profile_cmds, serve_cmds, export_cmds, hatt_cmds,
                   study_cmds, stats_cmds, device_cmds)
"""The modules whose ``register(app)`` adds their commands, in the order of ``--help``."""

for _module in COMMAND_MODULES:
    _module.register(app)
