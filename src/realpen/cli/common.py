"""Shared pieces of the command line: command groups, console output, progress bars, and the
output check."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from realpen.errors import RealPenError, fail

if TYPE_CHECKING:
    from rich.console import Console

try:  # recent typer releases carry their own copy of click
    from typer.core import TyperGroup
except ImportError:  # pragma: no cover - every supported typer has it
    from typer.main import TyperGroup

__all__ = ["CONTEXT_SETTINGS", "command_group", "LazyConsole", "console", "err_console",
           "print_line", "PROGRESS_AFTER_S", "progress_bar", "force_option", "check_outputs",
           "same_file", "whole_number", "design_input", "working", "terminate_as_interrupt",
           "InterruptOnce", "DefaultCommandGroup"]


class LazyConsole:
    """A rich ``Console`` made on its first use (every attribute is the console's).

    Importing rich and making a console costs about 0.03 s of CPU at each start: a command
    whose output is plain lines (:func:`print_line`) never makes one.

    Args:
        options: the ``Console`` keyword arguments.
    """

    def __init__(self, **options: Any) -> None:
        self._options = options
        self._console: Console | None = None

    @property
    def rich(self) -> Console:
        """The console itself (made now if it was not yet)."""
        if self._console is None:
            from rich.console import Console

            self._console = Console(**self._options)
        return self._console

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):  # our own state, never the console's (copies, pickling)
            raise AttributeError(name)
        return getattr(self.rich, name)


# Markup and emoji codes off: paths, tool names and descriptions are the user's text, not rich
# markup (a file named "a:pencil:b.wav" is printed as named, not with an emoji in it).
console = LazyConsole(soft_wrap=True, markup=False, highlight=False, emoji=False)
err_console = LazyConsole(stderr=True, markup=False, highlight=False, emoji=False)


def print_line(text: str) -> None:
    """Print ``text`` and a newline on stdout, byte for byte as ``console.print(text)`` does.

    Printable text (no tab, newline, control code, undecodable byte or invisible format
    character) is what rich writes unchanged with markup, emoji codes and highlighting off and
    lines never wrapped: it is written directly, without importing rich. Anything else goes
    through the console, which expands tabs and drops control codes.
    """
    if text.isprintable():
        sys.stdout.write(text + "\n")
        sys.stdout.flush()  # as rich does: the order with stderr's lines stays the same
    else:
        console.print(text)


PROGRESS_AFTER_S = 5.0  # recordings longer than this get a progress bar
# -h works wherever --help does; child contexts inherit it, each group repeats it to be plain.
CONTEXT_SETTINGS = {"help_option_names": ["-h", "--help"]}


class DefaultCommandGroup(TyperGroup):
    """A group whose first word is a command only when it names one: otherwise the words are
    :attr:`default_command`'s (``realpen stats DESIGN ...`` runs ``stats report``, ``realpen
    tactile RECORDING ...`` runs ``tactile build``). Subclasses set ``default_command``;
    :func:`realpen.cli.command_path` reads it too."""

    default_command: str = ""

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and args[0] not in ("-h", "--help"):
            args = [self.default_command, *args]
        return super().parse_args(ctx, args)


def command_group(help: str, cls: type[TyperGroup] | None = None) -> typer.Typer:
    """A group of subcommands (``realpen NAME ...``) that prints its help when given no
    subcommand. It is not registered anywhere: its module's ``register(app)`` adds it to the
    root command (:mod:`realpen.cli.root`).

    Args:
        help: the group's help text.
        cls: the click group class (a :class:`DefaultCommandGroup` to run a default command).
    """
    options = {} if cls is None else {"cls": cls}
    return typer.Typer(help=help, no_args_is_help=True, context_settings=CONTEXT_SETTINGS,
                       **options)


def force_option(*names: str) -> bool:
    """The typer option that allows replacing existing outputs (``--force``, ``--overwrite``)."""
    return typer.Option(False, *(names or ("--force", "--overwrite")),
                        help="Replace output files that already exist (refused otherwise).")


LARGEST_WHOLE_NUMBER = 2**63 - 1
"""The largest integer an option takes (64 bits): larger ones mean nothing to any parameter,
and past about 309 digits they cannot even be compared with a float limit."""


def whole_number(value: int | None) -> int | None:
    """Typer callback of integer options: refuse a number beyond 64 bits while reading it.

    click reads any number of digits into a Python int; the parameter's own limit (checked by
    the library, named by its flag) then says what is allowed.

    Raises:
        typer.BadParameter: beyond ±:data:`LARGEST_WHOLE_NUMBER` (one line naming the flag).
    """
    if value is not None and not -LARGEST_WHOLE_NUMBER - 1 <= value <= LARGEST_WHOLE_NUMBER:
        digits = len(str(abs(value)))
        raise typer.BadParameter(f"a {digits}-digit number is too large (at most "
                                 f"{LARGEST_WHOLE_NUMBER})")
    return value


def check_outputs(*outputs: Path | None, force: bool, force_flag: str = "--force",
                  folders: bool = False, inputs: Mapping[str, Path | None] | None = None) -> None:
    """Refuse outputs that would silently replace something, before any work is done.

    Args:
        outputs: the files the command will write, side files included (None: not asked for).
        force: the user passed ``force_flag``: existing files may be replaced.
        force_flag: how the command names that option, for the message.
        folders: an output may be a folder (a profile bundle); otherwise an existing folder
            given as an output is refused, with or without ``force``.
        inputs: files (or bundle folders) the command reads, by what they are
            (``{"recording": path}``). An output that is one of them — by path, through a
            symbolic link or as a hard link —, lies inside an input folder, or (with
            ``folders``) is a folder holding an input is refused, with or without ``force``.

    Raises:
        RealPenError: one line naming the path: ``"<path>: exists; pass --force to replace
            it"``, an output given twice, an output that is an input, or a folder.
    """
    given = [Path(out) for out in outputs if out is not None]
    sources = {label: Path(source) for label, source in (inputs or {}).items()
               if source is not None}
    for index, out in enumerate(given):
        for label, source in sources.items():
            if same_file(out, source):
                raise fail(out, f"would replace the {label} itself; name another file to write")
            if source.is_dir() and resolved(out).is_relative_to(resolved(source)):
                raise fail(out, f"lies inside the {label} {source}; write it elsewhere")
            if folders and resolved(source).is_relative_to(resolved(out)):
                # A bundle folder is replaced whole, with whatever it holds.
                raise fail(out, f"holds the {label} {source}; write the output elsewhere")
        if any(same_file(out, other) for other in given[:index]):
            raise fail(out, "given for two outputs; name a different file for each")
        if out.is_dir() and not folders:
            raise fail(out, "is a folder; give the file to write")
        if (out.exists() or out.is_symlink()) and not force:
            raise RealPenError(f"{out}: exists; pass {force_flag} to replace it")


def resolved(path: Path) -> Path:
    """``path`` with symbolic links followed.

    Raises:
        RealPenError: the links loop (Python 3.11 raises RuntimeError there, later ones OSError).
    """
    try:
        return path.resolve()
    except (RuntimeError, OSError):
        raise fail(path, "cannot be followed: its symbolic links form a loop") from None


def same_file(first: Path, second: Path) -> bool:
    """Whether two paths name one file: the same resolved path (symbolic links followed), or,
    when both exist, the same file on disk (hard links, bind mounts, case-insensitive file
    systems)."""
    if resolved(first) == resolved(second):
        return True
    try:
        return first.exists() and second.exists() and os.path.samefile(first, second)
    except OSError:  # unreadable: then the paths were compared above
        return False


@contextlib.contextmanager
def progress_bar(label: str, enabled: bool = True) -> Iterator:
    """Yield a ``progress(done, total)`` callback that drives a rich progress bar on stderr.

    With ``enabled`` false the callback does nothing (short jobs need no bar).
    """
    if not enabled or not err_console.is_terminal:  # a bar is for people, not for logs
        yield None
        return
    from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeRemainingColumn

    columns = (TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
               TimeRemainingColumn())
    with Progress(*columns, console=err_console.rich, transient=True) as progress:
        task = progress.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        yield update


def design_input(design: str) -> dict[str, Path | None]:
    """A DESIGN argument as an input no output may replace (a built-in name is none)."""
    path = Path(design) if design.strip() else None
    return {"design": path if path is not None and path.exists() else None}


@contextlib.contextmanager
def working(label: str) -> Iterator[None]:
    """A spinner with ``label`` on stderr while a long step runs (only on a terminal)."""
    if not err_console.is_terminal:
        yield
        return
    with err_console.rich.status(label):
        yield


def _interrupt(signum, frame):
    raise KeyboardInterrupt


@contextlib.contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP end the block as Ctrl-C does (KeyboardInterrupt), so its clean-up
    (temporary files, a half-made folder) runs before the process ends."""
    wanted = [sig for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)) if sig is not None]
    try:
        previous = {sig: signal.signal(sig, _interrupt) for sig in wanted}
    except ValueError:  # not the main thread (an embedding program): leave signals alone
        yield
        return
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


class InterruptOnce:
    """Within the block the first SIGINT, SIGTERM or SIGHUP ends the work as Ctrl-C does
    (KeyboardInterrupt); once one has come, or :meth:`hold` was called, later ones only print
    ``note`` on stderr, so that the clean-up that follows (writing a recording, removing
    temporary files) is not itself cut short. The previous handlers come back at the end.

    Args:
        note: what a held signal prints, e.g. ``"still writing pen.wav, one moment"``.

    Example:
        >>> with InterruptOnce("still writing, one moment") as interrupts:
        ...     interrupts.hold()
        ...     os.kill(os.getpid(), signal.SIGINT)  # held (the note goes to stderr)
        ...     interrupts.held
        1
    """

    def __init__(self, note: str) -> None:
        self.note = note
        self.held = 0  # signals that came while holding
        self._holding = False
        self._previous: dict[int, Any] = {}

    def hold(self) -> None:
        """From now on a signal only prints the note."""
        self._holding = True

    def _signal(self, signum, frame) -> None:
        if not self._holding:
            # Switched before raising: a second signal, however soon, cannot interrupt what
            # the first one starts.
            self._holding = True
            raise KeyboardInterrupt
        self.held += 1
        with contextlib.suppress(OSError, RuntimeError, ValueError):  # stderr gone or busy
            print(self.note, file=sys.stderr, flush=True)

    def __enter__(self) -> InterruptOnce:
        wanted = [sig for sig in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None))
                  if sig is not None]
        try:
            for sig in wanted:  # SIGINT too where a shell ignored it (`realpen … &`)
                self._previous[sig] = signal.signal(sig, self._signal)
        except ValueError:  # not the main thread (an embedding program): leave signals alone
            self.__exit__()
        return self

    def __exit__(self, *exc_info) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()
