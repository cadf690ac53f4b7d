"""The ``realpen`` command: a thin shell over the library.

Every subcommand lives in its own module and registers itself on :data:`app`. Problems with the
user's input surface as :class:`realpen.errors.RealPenError` and are printed as one line on
stderr with exit code 2.
"""

from __future__ import annotations

import sys

import typer

from ..errors import RealPenError

app = typer.Typer(
    name="realpen",
    help="RealPen: the feel and sound of a real pen on paper, for touch screens.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def main() -> None:
    """Entry point of the ``realpen`` console script."""
    try:
        app(prog_name="realpen")
    except RealPenError as error:
        print(f"realpen: error: {error}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("realpen: interrupted", file=sys.stderr)
        sys.exit(130)


# Subcommand modules register themselves on `app` when imported.
from . import tactile_cmds  # noqa: E402,F401
from . import sound_cmds  # noqa: E402,F401
from . import profile_cmds  # noqa: E402,F401
from . import serve_cmds  # noqa: E402,F401
from . import export_cmds  # noqa: E402,F401
