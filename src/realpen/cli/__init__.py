"""The ``realpen`` command: a thin shell over the library.

Every subcommand lives in its own module and registers itself on :data:`app`. Problems with the
user's input surface as :class:`realpen.errors.RealPenError` and are printed as one line on
stderr with exit code 2.
"""

from __future__ import annotations

import sys

import typer

try:  # recent typer releases carry their own copy of click
    from typer._click import exceptions as click_errors
except ImportError:  # older typer uses click itself
    from click import exceptions as click_errors

from realpen.errors import RealPenError

app = typer.Typer(
    name="realpen",
    help="RealPen: the feel and sound of a real pen on paper, for touch screens.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def main() -> None:
    """Entry point of the ``realpen`` console script: every failure is one line on stderr."""
    try:
        code = app(prog_name="realpen", standalone_mode=False)
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
    sys.exit(code if isinstance(code, int) else 0)


def _fail(message: str, code: int) -> None:
    print(f"realpen: error: {' '.join(message.split())}", file=sys.stderr)
    sys.exit(code)


# Subcommand modules register themselves on `app` when imported.
from realpen.cli import tactile_cmds  # noqa: E402,F401
from realpen.cli import sound_cmds  # noqa: E402,F401
from realpen.cli import profile_cmds  # noqa: E402,F401
from realpen.cli import serve_cmds  # noqa: E402,F401
from realpen.cli import export_cmds  # noqa: E402,F401
