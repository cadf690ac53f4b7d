"""The root ``realpen`` command: its options, and every group of subcommands registered on it.

Each command module defines its own commands and groups and registers them with
``register(app)``; none of them imports this module, so the command tree is built without an
import cycle. A new group goes into a module of its own with a ``register`` function, listed in
:data:`COMMAND_MODULES` in the order ``realpen --help`` lists it, and its top-level names in
:data:`COMMANDS`.

:data:`app` is the whole command (built on first use). A run whose first word names a command
needs only that command's module: :func:`app_for` builds the root with it alone, so that
``realpen analyze`` neither imports nor builds the thirty-odd other commands (their help, usage
lines and errors are the same either way).
"""

import importlib
from collections.abc import Sequence

import typer

from realpen.cli.coercion import FastCoercionGroup
from realpen.cli.common import CONTEXT_SETTINGS

__all__ = ["app", "build_app", "app_for", "COMMAND_MODULES", "COMMANDS"]

COMMAND_MODULES = ("tactile_cmds", "sound_cmds", "profile_cmds", "serve_cmds", "export_cmds",
                   "hatt_cmds", "study_cmds", "stats_cmds", "device_cmds", "record_cmds",
                   "actuator_cmds")
"""The modules of :mod:`realpen.cli` whose ``register(app)`` adds their commands, in the order
of ``--help``."""

COMMANDS = {"analyze": "tactile_cmds", "tactile": "tactile_cmds", "sound": "sound_cmds",
            "profile": "profile_cmds", "serve": "serve_cmds", "strokes": "serve_cmds",
            "export": "export_cmds", "hatt": "hatt_cmds", "study": "study_cmds",
            "stats": "stats_cmds", "device": "device_cmds", "record": "record_cmds",
            "actuator": "actuator_cmds"}
"""Each top-level command or group → the module that registers it."""


def _show_version(value: bool) -> None:
    if value:
        from realpen._version import __version__

        print(f"realpen {__version__}")
        raise typer.Exit()


def _root(
    version: bool = typer.Option(False, "--version", callback=_show_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """RealPen: the feel and sound of a real pen on paper, for touch screens."""


def build_app(modules: Sequence[str] = COMMAND_MODULES) -> typer.Typer:
    """The root command with the commands of ``modules`` (names in :data:`COMMAND_MODULES`)."""
    root = typer.Typer(
        name="realpen",
        help="RealPen: the feel and sound of a real pen on paper, for touch screens.",
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
        context_settings=CONTEXT_SETTINGS,
        cls=FastCoercionGroup,  # plain option values are read without pydantic
    )
    root.callback()(_root)
    for name in modules:
        importlib.import_module(f"realpen.cli.{name}").register(root)
    return root


def app_for(args: Sequence[str]) -> typer.Typer:
    """The root command that runs ``args`` (the arguments after ``realpen``): with only the
    module of the command its first word names, else (an option, no word, a word that names
    no command) the whole :data:`app`."""
    module = COMMANDS.get(args[0]) if args else None
    return _whole() if module is None else build_app((module,))


app: typer.Typer
"""The whole ``realpen`` command (every module's commands), built on first use."""


def _whole() -> typer.Typer:
    whole = globals().get("app")
    if whole is None:  # built once, when first asked for
        whole = globals()["app"] = build_app()
    return whole


def __getattr__(name: str) -> typer.Typer:
    if name == "app":
        return _whole()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
