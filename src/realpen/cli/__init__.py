"""The ``realpen`` command: argument parsing and the flag map only, a thin shell over the library.

Every group of subcommands lives in a module of its own (``*_cmds.py``) with a
``register(app)`` function; :mod:`realpen.cli.root` builds the root :data:`app` and calls them,
and no command module imports the root or this package's names back. :func:`main`, the console
script, runs the app — only the part its first word names, so that a command imports and builds
no other command (:func:`realpen.cli.root.app_for`): problems with the user's input surface as
:class:`realpen.errors.RealPenError` and are printed as one line on stderr with exit code 2; a
:class:`realpen.errors.ParameterError` (worded with a Python parameter name) is shown with the
command's flag instead (:mod:`realpen.cli.flags`).

May import: at module level typer, rich, the standard library and the light modules that load
nothing heavy (:mod:`realpen.errors`, :mod:`realpen.io.paths`); every other layer of the
library (:mod:`realpen.live` included) with numpy, scipy, soundfile, matplotlib and FastAPI only
inside the command functions, so that ``realpen --help`` answers at once. No library layer
imports :mod:`realpen.cli` (only ``python -m realpen`` runs it).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

import typer

try:  # recent typer releases carry their own copy of click
    from typer._click import exceptions as click_errors
except ImportError:  # older typer uses click itself
    from click import exceptions as click_errors

from realpen.cli import root
from realpen.cli.common import CONTEXT_SETTINGS
from realpen.errors import ParameterError, RealPenError

__all__ = ["app", "main", "command_path", "CONTEXT_SETTINGS"]


def __getattr__(name: str):
    if name == "app":  # the whole command tree: built on first use (a run builds only its part)
        return root.app
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def command_path(args: Sequence[str]) -> str:
    """The subcommand that ``args`` (the arguments after ``realpen``) runs, e.g. ``"sound loop"``.

    Options are skipped, with the values of a group's options that take one
    (``device --port /dev/ttyACM0 play``); the walk stops at the first word that is not a
    subcommand (where a group runs a default subcommand then, that one is the path's last
    word). Empty for the top level.
    """
    command = typer.main.get_command(root.app)
    path: list[str] = []
    tokens = iter(args)
    for token in tokens:
        if token == "--":
            break
        if token.startswith("-"):
            for _ in range(_values_taken(command, token)):
                next(tokens, None)
            continue
        commands = getattr(command, "commands", None)
        if not commands or token not in commands:
            default = getattr(command, "default_command", None)  # `realpen stats DESIGN ...`
            if commands and default in commands:
                path.append(default)
            break
        command = commands[token]
        path.append(token)
    return " ".join(path)


def _values_taken(command, token: str) -> int:
    """How many of the next arguments are the value of ``command``'s option ``token`` (0 for
    a flag, an unknown option, or ``--name=value``)."""
    for param in getattr(command, "params", ()):
        if token in (*getattr(param, "opts", ()), *getattr(param, "secondary_opts", ())):
            if getattr(param, "is_flag", False) or getattr(param, "count", False):
                return 0
            return max(int(getattr(param, "nargs", 1)), 1)
    return 0


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the ``realpen`` console script: every failure is one line on stderr.

    Args:
        argv: the arguments after ``realpen`` (default: ``sys.argv[1:]``).

    Exits with 0 on success, 2 on bad input or usage, 1 when out of memory, 130 when
    interrupted.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    try:
        code = root.app_for(args)(args=args, prog_name="realpen", standalone_mode=False)
    except ParameterError as error:
        from realpen.cli.flags import describe

        _fail(describe(error, command_path(args)), 2)
    except RealPenError as error:
        _fail(str(error), 2)
    except click_errors.NoArgsIsHelpError:
        sys.exit(0)  # the help was printed while the error was made
    except click_errors.UsageError as error:
        where = error.ctx.command_path if error.ctx else "realpen"
        _fail(f"{where}: {error.format_message()} (see {where} --help)", 2)
    except click_errors.ClickException as error:
        _fail(error.format_message(), error.exit_code)
    except (KeyboardInterrupt, typer.Abort):
        _fail("interrupted", 130)
    except MemoryError:  # nothing was written: outputs are renamed into place only when done
        _fail("out of memory: this work needs more memory than the system allows this process",
              1)
    except OSError as error:  # a path the system refuses (too long, a link loop, no access)
        where = f"{error.filename}: " if error.filename else ""
        _fail(f"{where}{error.strerror or error}", 2)
    if code == 130:  # typer turns Ctrl-C into this exit code before our handler sees it
        _fail("interrupted", 130)
    sys.exit(code if isinstance(code, int) else 0)


def _fail(message: str, code: int) -> None:
    print(f"realpen: error: {' '.join(message.split())}", file=sys.stderr)
    sys.exit(code)

